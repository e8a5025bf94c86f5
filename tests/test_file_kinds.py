"""File kinds by content (issue #16 point 1): drill files named by their PCB program's habit, and the rest.

The drill files are written here in each program's habits (headers, comments, units, names); the committed
generator (:mod:`excellon_gen`) supplies KiCad, Altium, Eagle and Fritzing bodies.
"""
import json

import numpy as np
import pytest

import cam
from cam.kinds import job_kind
from cam.kinds import sniff_kind
from cam.sniff import HEAD_BYTES
from cam.kinds.jobs import prepare_job

import excellon_gen
from conftest import SAMPLES
from test_cli import assert_one_line_error, cli

BOARD = excellon_gen.realistic_board(seed=3, n_vias=20)

EASYEDA = """M48
METRIC,LZ,000.000
;EasyEDA v6.5.22
;TYPE=PLATED
T01C0.610
T02C1.000
%
G05
G90
T01
X115.189Y-61.722
X120.269Y-61.722
T02
X100.000Y-50.000
M30
"""
DIPTRACE = """M48
;DipTrace 4.3.0.5
;Through hole drill file
METRIC,TZ
T1C0.8
T2C1.1
%
T1
X5080Y2540
X7620Y2540
T2
X10160Y5080
T0
M30
"""
PCAD = """%
T01
X1000Y1000
X1100Y1000
T02
X2000Y1500
M30
"""
PCB_RND = """M48
METRIC,000.000
T14C0.800
T15C1.000
%
T14
X12.700Y-25.400
X15.240Y-25.400
T15
X20.320Y-25.400
M30
"""
UPVERTER = """;Upverter drill file
;FILE_FORMAT=2:4
M48
INCH,TZ
T1C0.0315
T2C0.0394
%
T1
X010000Y010000
X011000Y010000
T2
X020000Y015000
M30
"""
GCODE = "(engrave)\nG21 G90\nG0 Z1\nG0 X1 Y-1\nG1 Z-0.2 F100\nG1 X5 Y-1\nG1 X5 Y-4\nG0 Z1\nM2\n"
HPGL = "IN;SP1;PU0,0;PD400,0,400,400,0,400,0,0;PU;SP0;"

PROGRAMS = {
    # program: (file name by its habit, text, holes)
    "kicad": ("board-PTH.drl", excellon_gen.kicad_metric_decimal(BOARD).text, len(BOARD.holes_mm)),
    "altium": ("NC Drill/board-RoundHoles.TXT", excellon_gen.altium_inch_2_5(BOARD).text, len(BOARD.holes_mm)),
    "fritzing": ("board_drill.txt", excellon_gen.fritzing_inch(BOARD).text, len(BOARD.holes_mm)),
    "eagle": ("board.xln", excellon_gen.eagle_inch_2_4(BOARD).text, len(BOARD.holes_mm)),
    "easyeda": ("Drill_PTH_Through.DRL", EASYEDA, 3),
    "diptrace": ("board_Through.txt", DIPTRACE, 3),
    "pcad": ("board.nc", PCAD, 3),
    "pcb-rnd": ("board.cnc", PCB_RND, 3),
    "upverter": ("upverter-drill", UPVERTER, 3),
}


def _write(tmp_path, name, data):
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


@pytest.mark.parametrize("program", sorted(PROGRAMS))
def test_drill_files_of_every_program_are_excellon_by_content(tmp_path, program):
    name, text, _ = PROGRAMS[program]
    path = _write(tmp_path, name, text)
    warnings = []
    assert sniff_kind(text.encode()) == "excellon"
    assert job_kind(path, warnings) == "excellon" and warnings == []


@pytest.mark.parametrize("program", ["altium", "fritzing", "easyeda", "diptrace", "pcb-rnd", "upverter", "kicad"])
def test_cam_info_reads_drill_files_named_by_habit(tmp_path, program):
    name, text, holes = PROGRAMS[program]
    path = _write(tmp_path, name, text)
    proc = cli("info", path, "--json")
    assert proc.returncode == 0, proc.stderr
    rep = json.loads(proc.stdout)
    assert rep["kind"] == "excellon" and rep["holes"] == holes
    assert "warning" not in proc.stderr


def test_drill_preview_and_export_of_altium_txt(tmp_path):
    path = _write(tmp_path, "NC Drill/board-RoundHoles.TXT", PROGRAMS["altium"][1])
    proc = cli("drill", path, "--pin-log", tmp_path / "p.csv", "--no-progress", "--cut-depth", "1.0", "--yes")
    assert proc.returncode == 0, proc.stderr
    motion = cam.decode_pin_log(tmp_path / "p.csv")
    z = motion.position_steps[:, 2]
    plunges = np.sum((z[1:] == z.max()) & (z[:-1] < z.max()))
    assert plunges == len(BOARD.holes_mm)
    assert cli("preview", path, "-o", tmp_path / "a.png").returncode == 0
    proc = cli("export", path, "-o", tmp_path / "a.ngc")
    assert proc.returncode == 0, proc.stderr
    assert "M6" in (tmp_path / "a.ngc").read_text()


def test_prepare_job_reads_fritzing_txt_like_its_drl(tmp_path):
    text = PROGRAMS["fritzing"][1]
    a = prepare_job(_write(tmp_path, "board_drill.txt", text))
    b = prepare_job(_write(tmp_path, "board.drl", text))
    assert a.kind == b.kind == "excellon" and np.array_equal(a.steps.data, b.steps.data)


@pytest.mark.parametrize("name, data, kind", [
    ("job.txt", GCODE, "gcode"),
    ("job", GCODE, "gcode"),
    ("job.nc", GCODE, "gcode"),
    ("job.cnc", GCODE, "gcode"),
    ("pen.txt", HPGL, "hpgl"),
    ("pen", HPGL, "hpgl"),
    ("logo.txt", '<?xml version="1.0"?>\n<svg xmlns="http://www.w3.org/2000/svg" width="10mm"></svg>\n', "svg"),
    ("logo", "<svg viewBox='0 0 10 10'><circle r='4'/></svg>", "svg"),
    ("scan", (SAMPLES / "ellipse.png").read_bytes(), "drawing"),
    ("scan.TXT", (SAMPLES / "ellipse.png").read_bytes(), "drawing"),
])
def test_generic_and_missing_suffixes_follow_the_content(tmp_path, name, data, kind):
    path = _write(tmp_path, name, data)
    warnings = []
    assert job_kind(path, warnings) == kind and warnings == []


def test_digitized_txt_stays_a_digitized_matrix(tmp_path):
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    cam.save_digitized(d, tmp_path / "m.txt")
    assert job_kind(tmp_path / "m.txt") == "digitized"


def test_a_contradicting_suffix_is_a_warning_and_the_content_wins(tmp_path):
    path = _write(tmp_path, "job.drl", GCODE)
    warnings = []
    assert job_kind(path, warnings) == "gcode"
    assert len(warnings) == 1 and ".drl says an Excellon drill file but the content is G-code" in warnings[0]
    job = prepare_job(path)
    assert job.kind == "gcode" and "content is G-code" in job.warnings[0]
    proc = cli("drill", path, "--no-progress", "--yes")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("the content is G-code") == 1
    # a picture named .plt
    path = _write(tmp_path, "gear.plt", (SAMPLES / "gear.png").read_bytes())
    proc = cli("info", path)
    assert proc.returncode == 0 and "content is an image" in proc.stderr and "object" in proc.stdout


def test_options_are_checked_against_the_kind_the_content_shows(tmp_path):
    path = _write(tmp_path, "board_drill.txt", PROGRAMS["fritzing"][1])
    assert_one_line_error(cli("drill", path, "--depth", "3"), "--depth does not apply", "excellon")


def test_unknown_content_with_no_suffix_is_one_line(tmp_path):
    path = _write(tmp_path, "notes", "just some words\n")
    assert_one_line_error(cli("info", path), "unknown file type")


def test_only_the_head_of_a_file_is_read(tmp_path):
    text = PROGRAMS["kicad"][1]
    big = text.replace("M30\n", "") + "X1.0Y1.0\n" * 200_000 + "M30\n"
    assert sniff_kind(big.encode()[:HEAD_BYTES]) == "excellon"
    assert len(big) > 100 * HEAD_BYTES


def test_web_upload_sniffs_the_content(servers):
    from test_web import FAST
    s = servers("kinds", settings=FAST, realtime=False)
    status, body = s.upload("board-RoundHoles.TXT", PROGRAMS["altium"][1].encode())
    assert status == 200 and body["kind"] == "excellon", body
    status, body = s.upload("job.drl", GCODE.encode())
    assert status == 200 and body["kind"] == "gcode", body
    status, plan = s.call("POST", "/api/plan", {"job": body["job"], "options": {}})
    assert status == 200 and any("content is G-code" in w for w in plan.get("warnings", [])), plan


from test_web import servers  # noqa: E402,F401  (the web server fixture)
