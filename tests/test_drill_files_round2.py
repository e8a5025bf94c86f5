"""Drill files of round two (issue #31 points 1-4), in the habits of each program (tests/data/drill_round2/, made
for these tests): Cadence Allegro (tool sizes in ';T01 Holesize' comments or nc_param.txt, R repeat codes), KiCad 7
with oval holes routed, PADS with leading-zero numbers and no zeros statement, VeriBest (inch tool table, metric
body), OrCAD Layout (THRUHOLE.TAP, an impossible tool), Altium's SlotHoles.TXT; the kind weighed from the content
or forced with --kind; slots and large holes milled, checked on the mock port with a decoded pin log."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cam
from cam.kinds import job_kind
from cam.cli import main
from cam.drive.runner import run
from cam.errors import ParseError
from cam.formats.excellon import load_excellon, parse_excellon, parse_nc_param
from cam.job.drill import milled_hole_path_mm, plan_drill
from cam.kinds.jobs import JobOptions, prepare_job
from cam.kinds import forced_kind, sniff_kind
from cam.verify.pinlog import decode_pin_log

DATA = Path(__file__).parent / "data" / "drill_round2"
FILES = {
    "allegro": DATA / "allegro" / "sensor-1-4.drl",
    "allegro_param": DATA / "allegro_param" / "sensor-1-4.drl",
    "kicad7": DATA / "kicad7" / "board-PTH.drl",
    "pads": DATA / "pads" / "pads_board.drl",
    "veribest": DATA / "veribest" / "board.drl",
    "orcad": DATA / "orcad" / "THRUHOLE.TAP",
    "altium_slots": DATA / "altium" / "Board1-SlotHoles.TXT",
}
SETTINGS = cam.MachineSettings().replace(delay_xy_ms=0.05, delay_z_ms=0.05)
MIL = 0.0254


def _size(holes) -> tuple[float, float]:
    x0, y0, x1, y1 = holes.extent_mm()
    return round(x1 - x0, 2), round(y1 - y0, 2)


# -- point 1: the kind -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(FILES))
def test_every_drill_file_is_excellon_by_its_content(name):
    path = FILES[name]
    assert sniff_kind(path.read_bytes()) == "excellon"
    warnings: list[str] = []
    assert job_kind(path, warnings) == "excellon"
    if path.suffix == ".TAP":  # a G-code suffix: the content wins, and says so
        assert len(warnings) == 1 and "says G-code but the content is an Excellon drill file" in warnings[0]


def test_programs_line_ends_are_kept():
    crlf = {n for n, p in FILES.items() if b"\r\n" in p.read_bytes()}
    assert crlf == set(FILES) - {"kicad7"}


def test_allegro_repeat_codes_and_kicad_routes_alone_are_excellon_not_gcode():
    allegro_body = b"%\r\nG90\r\nT01\r\nX30000Y30000\r\nR05X10000\r\nX30000Y60000\r\nR05X10000\r\nM30\r\n"
    routes = b"T5\nG00X40.0Y-25.0\nM15\nG01X43.0Y-25.0\nM16\nG05\nG00X40.0Y-30.0\nM15\nG01X40.0Y-33.0\nM16\n"
    assert sniff_kind(allegro_body) == "excellon"
    assert sniff_kind(routes) == "excellon"
    # real G-code stays G-code
    assert sniff_kind(b"G21\nG90\nG0 X1 Y1\nG1 Z-1 F100\nX2Y2\nM30\n") == "gcode"
    assert sniff_kind(b"G0X0Y0\nG1X10Y0F300\nG1X10Y10\nM30\n") == "gcode"


def test_kind_forced_on_the_command_line(tmp_path, capsys):
    # an incremental drill file (G91 before each move) whose content and suffix say G-code: --kind excellon, and
    # the --excellon-* flags then apply
    path = tmp_path / "holes.nc"
    path.write_text("G91\nT1C0.8\nT1\nX1000Y1000\nG91\nX1000\nG91\nX1000\nM30\n")
    assert sniff_kind(path.read_bytes()) == "gcode"
    assert main(["info", str(path), "--excellon-units", "metric"]) == 2  # a G-code file: the flag does not apply
    assert "--excellon-units does not apply" in capsys.readouterr().err
    assert main(["info", str(path), "--kind", "excellon", "--excellon-units", "metric", "--excellon-digits", "3:3",
                 "--excellon-zeros", "TZ"]) == 0
    out = capsys.readouterr().out
    assert "3 holes" in out and "X 1.000..3.000 mm" in out
    job = prepare_job(path, JobOptions(kind="excellon", excellon_units="metric", excellon_digits=(3, 3),
                                       excellon_zeros="TZ"), SETTINGS)
    assert job.kind == "excellon" and job.report["holes"] == 3
    assert forced_kind("matrix") == "digitized" and forced_kind("gcode") == "gcode"


# -- point 2: zeros, units, digits ---------------------------------------------------------------------------

def test_pads_leading_zero_numbers_read_by_plausibility_65_x_100_mm():
    h = load_excellon(FILES["pads"])
    assert _size(h) == pytest.approx((65.02, 100.08), abs=0.01)
    assert len(h.holes_mm) == 30
    np.testing.assert_allclose(h.holes_mm[0], [0.2 * 25.4, 0.5 * 25.4])
    (w,) = [w for w in h.warnings if "does not state" in w]
    assert "read as the most plausible: 2:4 LZ" in w and "runner-up" in w and "pads_board.drl:9:" in w
    # the built-in default (trailing zeros kept) would not have fitted: given as an option it is used
    tz = load_excellon(FILES["pads"], excellon_zeros="TZ")
    assert _size(tz) != _size(h)


def test_allegro_tool_sizes_from_holesize_comments_and_repeat_codes():
    h = load_excellon(FILES["allegro"])
    assert h.tools == pytest.approx({1: 12 * MIL, 2: 40 * MIL, 3: 125 * MIL})
    assert h.tool_table() == [(1, pytest.approx(12 * MIL), 12), (2, pytest.approx(40 * MIL), 8),
                              (3, pytest.approx(125 * MIL), 4)]
    row = h.holes_mm[h.tool_of_hole == 1][:6]
    np.testing.assert_allclose(row, [[(0.3 + 0.1 * i) * 25.4, 0.3 * 25.4] for i in range(6)], atol=1e-9)
    assert _size(h) == pytest.approx((45.72, 33.02))
    assert any("inch 2:5" in w and "runner-up" in w for w in h.warnings)


def test_allegro_nc_param_beside_the_file_gives_format_and_sizes(tmp_path):
    h = load_excellon(FILES["allegro_param"])
    assert h.warnings == []  # everything stated by nc_param.txt
    assert h.tools == pytest.approx({1: 12 * MIL, 2: 40 * MIL, 3: 125 * MIL})
    assert _size(h) == pytest.approx((45.72, 33.02))
    assert parse_nc_param((DATA / "allegro_param" / "nc_param.txt").read_text())["zeros"] == "TZ"
    # without it the tools are not defined: a one-line error naming the line
    alone = tmp_path / "sensor-1-4.drl"
    alone.write_bytes(FILES["allegro_param"].read_bytes())
    with pytest.raises(ParseError, match=r"sensor-1-4\.drl:3: tool T1 is selected but never defined"):
        load_excellon(alone)


def test_veribest_inch_tool_table_then_metric_body():
    h = load_excellon(FILES["veribest"])
    assert h.tools == pytest.approx({1: 0.889, 2: 1.016, 3: 3.175})
    np.testing.assert_allclose(h.holes_mm[:2], [[12.7, 25.4], [15.24, 25.4]])
    assert _size(h) == (57.0, 42.0)
    assert not any("not a usual drill" in w for w in h.warnings)


def test_a_still_implausible_file_is_a_one_line_error_naming_the_hole():
    with pytest.raises(ParseError) as info:
        parse_excellon("M48\nT1C0.8\n%\nT1\nX1.0Y1.0\nX900.0Y1.0\nM30\n", source="big.drl")
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("big.drl:6:") and "X900.000" in msg and "500 mm" in msg
    # an implausible tool that can still be drilled is a warning naming it
    h = parse_excellon("M48\nMETRIC\nT1C0.8\nT2C9.0\n%\nT1\nX1.0Y1.0\nT2\nX5.0Y5.0\nM30\n", source="t.drl")
    assert any(w.startswith("t.drl:9: tool T2 9.000 mm is not a usual drill") for w in h.warnings)


# -- point 3: a bad tool is not a bad file -------------------------------------------------------------------

def test_an_unused_t0_definition_does_not_refuse_2704_holes():
    lines = ["M48", "METRIC,TZ,000.000", "T0C0.000", "T1C0.800", "%", "T1"]
    lines += [f"X{2540 * (i % 52) + 1000}Y{2540 * (i // 52) + 1000}" for i in range(2704)]
    h = parse_excellon("\n".join(lines + ["M30"]) + "\n", source="big.drl")
    assert len(h.holes_mm) == 2704 and h.tools == {1: 0.8}
    assert [w for w in h.warnings] == ["big.drl: tool T0 0.000 mm (T0 unloads the tool) is defined but never used: "
                                       "ignored"]


def test_an_impossible_tool_leaves_its_holes_out_unless_strict(capsys):
    h = load_excellon(FILES["orcad"])
    assert len(h.holes_mm) == 11 and 5 not in h.tools and h.skipped == {5: 1}
    (w,) = [w for w in h.warnings if "cannot be drilled" in w]
    assert "THRUHOLE.TAP:17: tool T5 139.700 mm" in w and "lines 17" in w and "--strict" in w
    with pytest.raises(ParseError, match=r"THRUHOLE\.TAP:17: tool T5 139\.700 mm .*--strict"):
        load_excellon(FILES["orcad"], strict=True)
    assert main(["info", str(FILES["orcad"]), "--strict"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len([e for e in err if e.startswith("cam: error")]) == 1 and "T5 139.700 mm" in err[-1]
    # a zero-size tool that is used: its holes are left out, the rest drilled
    z = parse_excellon("M48\nMETRIC\nT1C0.8\nT2C0\n%\nT1\nX1.0Y1.0\nT2\nX2.0Y2.0\nX3.0Y3.0\nM30\n", source="z.drl")
    assert z.holes_mm.tolist() == [[1.0, 1.0]] and z.skipped == {2: 2}
    assert any("z.drl:9: tool T2 0.000 mm (zero size) cannot be drilled" in w for w in z.warnings)


def test_the_orcad_board_is_drilled_without_its_impossible_tool():
    job = prepare_job(FILES["orcad"], JobOptions(), SETTINGS)
    assert job.report["holes"] == 11
    with pytest.raises(ParseError):
        prepare_job(FILES["orcad"], JobOptions(strict=True), SETTINGS)


# -- point 4: slots and large holes milled, equal tools merged ---------------------------------------------

def _cuts(position_steps: np.ndarray, depth_steps: int) -> list[np.ndarray]:
    """Each stay below the surface, as the (x, y) steps it passes; every one reaches the drill depth."""
    z = position_steps[:, 2]
    below = z > 0
    starts = np.flatnonzero(below & ~np.r_[False, below[:-1]])
    ends = np.flatnonzero(below & ~np.r_[below[1:], False])
    out = []
    for a, b in zip(starts, ends):
        seg = position_steps[a:b + 1]
        assert seg[:, 2].max() == depth_steps
        # X/Y move only at the drill depth
        moving = np.r_[False, np.any(seg[1:, :2] != seg[:-1, :2], axis=1)]
        assert (seg[moving, 2] == depth_steps).all(), "X/Y moved above the drill depth in the work"
        out.append(seg[:, :2])
    return out


def _machine_steps(xy_mm, offset_mm) -> np.ndarray:
    xy = np.asarray(xy_mm, np.float64).reshape(-1, 2)
    return np.column_stack([offset_mm[0] + xy[:, 0], offset_mm[1] - xy[:, 1]]) / SETTINGS.mm_per_step_xy


def test_kicad_ovals_are_milled_along_the_slot_and_equal_tools_share_a_run():
    h = load_excellon(FILES["kicad7"])
    assert [p.tolist() for p in h.slot_paths_mm] == [[[40, -25], [43, -25]], [[40, -30], [40, -33]]]
    assert h.tool_of_slot.tolist() == [5, 5] and h.line_of_slot.tolist() == [39, 44]
    offset = (0.0, -5.0)
    dp = plan_drill(h, settings=SETTINGS, offset_mm=offset)
    assert [t for t, _, _ in dp.tool_sequence] == [1, 2, 3, 5]  # T3 and T4 (both 1.000 mm): one run
    assert dp.tool_sequence[2][2] == 4 and dp.n_slots == 2
    pauses = []
    result = run(dp.toolpath, "mock", on_pause=lambda pos, note: pauses.append(note))
    assert len(pauses) == 4 and pauses[2].startswith("tool change: T3 = T4 1.000 mm (4 holes)")
    assert pauses[3] == "tool change: T5 1.200 mm (0 holes, 2 slots milled)"
    motion = decode_pin_log(result.pin_log(), SETTINGS)
    depth = round(2.0 / SETTINGS.mm_per_step_z)
    cuts = _cuts(motion.position_steps, depth)
    assert len(cuts) == 11 + 2
    plunges = [c for c in cuts if (c == c[0]).all()]
    slots = [c for c in cuts if not (c == c[0]).all()]
    assert len(plunges) == 11 and len(slots) == 2
    expect = [_machine_steps(p, offset) for p in h.slot_paths_mm]
    for cut in slots:  # the tool passes from one end of a slot to the other at the drill depth
        ends = np.array([cut[0], cut[-1]], np.float64)
        match = [e for e in expect if np.abs(np.sort(ends, axis=0) - np.sort(e, axis=0)).max() <= 0.5 + 1e-9]
        assert len(match) == 1
        length = np.abs(np.diff(cut, axis=0)).max(axis=1).sum()
        assert length == pytest.approx(3.0 / SETTINGS.mm_per_step_xy, abs=2)
    assert tuple(motion.position_steps[-1]) == (0, 0, 0)


def test_altium_slot_holes_txt_is_a_job_milled_on_the_mock_port():
    job = prepare_job(FILES["altium_slots"], JobOptions(offset_mm=(0.0, 40.0)), SETTINGS)
    assert job.report["holes"] == 0 and job.report["slots"] == 3
    assert "3 slots" in job.summary
    motion = decode_pin_log(run(job.toolpath, "mock").pin_log(), SETTINGS)
    cuts = _cuts(motion.position_steps, round(2.0 / SETTINGS.mm_per_step_z))
    h = load_excellon(FILES["altium_slots"])
    expect = [_machine_steps(p, (0.0, 40.0)) for p in h.slot_paths_mm]
    assert len(cuts) == 3
    for cut in cuts:
        ends = np.sort(np.array([cut[0], cut[-1]], np.float64), axis=0)
        assert any(np.abs(ends - np.sort(e, axis=0)).max() <= 0.5 + 1e-9 for e in expect)


def test_holes_larger_than_the_bit_are_milled_within_their_circle(tmp_path):
    text = "M48\nMETRIC\nT1C1.0\nT2C3.2\nT3C6.0\n%\nT1\nX5.0Y5.0\nT2\nX10.0Y5.0\nT3\nX20.0Y8.0\nM30\n"
    h = parse_excellon(text, source="m.drl")
    offset = (2.0, 20.0)
    dp = plan_drill(h, settings=SETTINGS, offset_mm=offset, mill_holes_over_mm=1.0)
    assert dp.n_milled == 2 and [t for t, _, _ in dp.tool_sequence] == [1]  # one tool: the 1 mm bit
    motion = decode_pin_log(run(dp.toolpath, "mock").pin_log(), SETTINGS)
    cuts = _cuts(motion.position_steps, round(2.0 / SETTINGS.mm_per_step_z))
    assert len(cuts) == 3
    step = SETTINGS.mm_per_step_xy
    for (x, y), dia in (((10.0, 5.0), 3.2), ((20.0, 8.0), 6.0)):
        centre = _machine_steps([(x, y)], offset)[0]
        (cut,) = [c for c in cuts if np.abs(c[0] - centre).max() <= 0.5 + 1e-9]  # down at the centre
        r_steps = np.hypot(*(cut - centre).T)
        limit = (dia - 1.0) / 2 / step
        assert r_steps.max() <= limit, "the bit's cut leaves the hole"
        assert r_steps.max() >= limit - 2.5, "the hole is not milled out to its edge"
    # the path itself: centre first, rings no more than 0.8 bit apart
    p = milled_hole_path_mm((0.0, 0.0), 6.0, 1.0)
    radii = np.unique(np.round(np.hypot(*p[1:].T), 3))
    assert p[0].tolist() == [0.0, 0.0] and radii.max() == 2.5 and np.diff(np.r_[0, radii]).max() <= 0.8


def test_cli_drills_mills_and_reports(tmp_path, capsys):
    log = tmp_path / "pins.csv"
    assert main(["drill", str(FILES["kicad7"]), "--yes", "--no-progress", "--pin-log", str(log)]) == 0
    err = capsys.readouterr().err
    assert "T3 = T4 1.000 mm" in err and "2 slots" in err
    assert main(["drill", str(FILES["kicad7"]), "--yes", "--no-progress", "--mill-holes-over", "0.8"]) == 0
    assert "holes over 0.8 mm milled" in capsys.readouterr().err


def test_slots_are_exported_as_cuts_at_the_drill_depth(tmp_path, capsys):
    out = tmp_path / "k.ngc"
    assert main(["export", str(FILES["kicad7"]), "-o", str(out)]) == 0
    lines = out.read_text().splitlines()
    depth_lines = [i for i, ln in enumerate(lines) if ln.startswith("G1 Z-")]
    along = [lines[i + 1] for i in depth_lines if lines[i + 1].startswith("G1 X")]
    assert len(depth_lines) == 13 and len(along) == 2  # 11 holes drilled, 2 slots milled: down, along, up
    assert all(lines[i + 2].startswith("G0 Z") for i in depth_lines if lines[i + 1].startswith("G1 X"))
