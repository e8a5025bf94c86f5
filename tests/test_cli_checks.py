"""Every option is checked before anything moves: output paths, flags against the file kind, options against
the port.  A bad one is one line on stderr, exit code 2, and nothing was planned, written or sent."""
import json
import os
import re

import pytest

from cam.cli import main

from conftest import ROOT, SAMPLES, run_cli

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
NGC = "G21 G90\nG0 X1 Y-1\nG1 Z-0.2 F100\nG1 X5 Y-3 F300\nG0 Z2\nM2\n"


def cli(*args, timeout=120):
    """``cam ARGS`` in this process (conftest.run_cli): exit code, stdout, stderr, stdin empty."""
    return run_cli(*args, timeout=timeout)


def refused(proc, *fragments):
    """Exit 2, one line on stderr naming every fragment, no traceback, and no job ran."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    assert "job finished" not in proc.stdout


@pytest.fixture(scope="module")
def ngc(tmp_path_factory):
    path = tmp_path_factory.mktemp("g") / "part.ngc"
    path.write_text(NGC)
    return path


# -- output paths: every command, checked before anything is planned or sent ---------------------------------

BAD = "/nonexistent-folder/out"


@pytest.mark.parametrize("argv, flag", [
    (["drill", SAMPLES / "ellipse.png", "--depth", "5", "--report", BAD + ".json"], "--report"),
    (["drill", SAMPLES / "ellipse.png", "--depth", "5", "--preview", BAD + ".png"], "--preview"),
    (["drill", SAMPLES / "ellipse.png", "--depth", "5", "--save-digitized", BAD + ".txt"], "--save-digitized"),
    (["drill", SAMPLES / "board.drl", "--yes", "--report", BAD + ".json"], "--report"),
    (["drill", SAMPLES / "inkscape_star.plt", "--yes", "--report", BAD + ".json"], "--report"),
    (["export", SAMPLES / "gear.png", "-o", BAD + ".ngc"], "--output"),
    (["preview", SAMPLES / "board.drl", "-o", BAD + ".png"], "--output"),
    (["digitize", SAMPLES / "gear.png", "-o", BAD + ".txt"], "--output"),
    (["jog", "X+", "10", "--pin-log", BAD + ".csv"], "--pin-log"),
    (["goto", "3,4,0", "--pin-log", BAD + ".csv"], "--pin-log"),
])
def test_a_bad_output_path_is_refused_before_anything_runs(argv, flag, tmp_path):
    pins = tmp_path / "pins.csv"
    extra = ["--pin-log", pins] if argv[0] in ("drill",) else []
    proc = cli(*argv, *extra)
    refused(proc, flag, "/nonexistent-folder", "does not exist")
    assert not pins.exists(), "nothing may be sent (the mock's pin log would have been written)"


def test_wrong_suffixes_and_folders_are_refused(tmp_path):
    refused(cli("drill", SAMPLES / "ellipse.png", "--preview", tmp_path / "p.gif"), "--preview", ".png or .svg")
    refused(cli("drill", SAMPLES / "ellipse.png", "--report", tmp_path / "r.txt"), "--report", ".json")
    refused(cli("drill", SAMPLES / "ellipse.png", "--pin-log", tmp_path), "--pin-log", ".csv")
    (tmp_path / "dir.csv").mkdir()
    refused(cli("drill", SAMPLES / "ellipse.png", "--pin-log", tmp_path / "dir.csv"), "--pin-log", "is a folder")


def test_a_failed_check_keeps_earlier_outputs(tmp_path):
    report = tmp_path / "r.json"
    report.write_text('{"earlier": true}\n')
    refused(cli("drill", SAMPLES / "ellipse.png", "--report", report, "--preview", tmp_path / "no" / "p.png"),
            "--preview")
    assert json.loads(report.read_text()) == {"earlier": True}


# -- flags against the file kind: never silently ignored -----------------------------------------------------

@pytest.mark.parametrize("argv, flag, kind", [
    (["drill", SAMPLES / "board.drl", "--depth", "3"], "--depth", "excellon"),
    (["drill", SAMPLES / "board.drl", "--profile-expr", "k"], "--profile-expr", "excellon"),
    (["drill", SAMPLES / "ellipse.png", "--mirror-x"], "--mirror-x", "drawing"),
    (["drill", SAMPLES / "ellipse.png", "--travel-height", "3"], "--travel-height", "drawing"),
    (["drill", SAMPLES / "ellipse.png", "--flip-y"], "--flip-y", "drawing"),
    (["drill", SAMPLES / "inkscape_star.plt", "--drill-order", "file"], "--drill-order", "hpgl"),
    (["drill", SAMPLES / "inkscape_star.plt", "--excellon-units", "metric"], "--excellon-units", "hpgl"),
    (["preview", SAMPLES / "board.drl", "--surface", "-o", "x.png"], "--surface", "excellon"),
    (["info", SAMPLES / "gear.png", "--excellon-zeros", "LZ"], "--excellon-zeros", "drawing"),
])
def test_a_flag_that_does_not_apply_to_the_file_kind_is_an_error(argv, flag, kind):
    refused(cli(*argv), flag, kind, "does not apply")


def test_gcode_takes_no_cut_depth(ngc):
    refused(cli("drill", ngc, "--cut-depth", "1"), "--cut-depth", "gcode")


def test_depth_is_given_once():
    refused(cli("drill", SAMPLES / "ellipse.png", "--depth", "5", "--cut-depth", "0.1"), "--depth", "--cut-depth")


def test_old_flag_names_are_gone():
    for argv in (["export", SAMPLES / "board.drl", "-o", "b.ngc", "--safe-height", "5"],
                 ["drill", SAMPLES / "board.drl", "--drill-depth", "1"],
                 ["serve", "--machine-port", "mock"]):
        proc = cli(*argv)
        assert proc.returncode == 2 and "unrecognized arguments" in proc.stderr


# -- one name per setting -------------------------------------------------------------------------------------

def _z_values(text):
    """Every Z word of the program's motion lines (comments left out)."""
    return {float(m) for line in text.splitlines() if not line.startswith("(")
            for m in re.findall(r"\bZ(-?[0-9.]+)", line.split("(")[0])}


@pytest.mark.parametrize("name", ["board.drl", "gear.png", "inkscape_star.plt"])
def test_export_travels_at_travel_height_for_every_kind(name, tmp_path):
    out = tmp_path / "x.ngc"
    proc = cli("export", SAMPLES / name, "-o", out, "--travel-height", "5")
    assert proc.returncode == 0, proc.stderr
    zs = _z_values(out.read_text())
    assert max(zs) == 5.0, sorted(zs)[-3:]


def test_cut_depth_is_the_depth_of_drills_pens_and_drawings(tmp_path):
    for name, depth_mm in (("board.drl", 1.5), ("inkscape_star.plt", 0.4)):
        out = tmp_path / (name + ".ngc")
        assert cli("export", SAMPLES / name, "-o", out, "--cut-depth", str(depth_mm)).returncode == 0
        assert min(_z_values(out.read_text())) == pytest.approx(-depth_mm, abs=0.01)
    rep = tmp_path / "r.json"
    proc = cli("drill", SAMPLES / "ellipse.png", "--cut-depth", "0.0785", "--report", rep)  # 5 Z pixels of 0.0157 mm
    assert proc.returncode == 0, proc.stderr
    assert json.loads(rep.read_text())["depth_px"] == 5
    refused(cli("drill", SAMPLES / "ellipse.png", "--cut-depth", "0.001"), "less than one Z pixel")


@pytest.mark.parametrize("name", ["gear.png", "board.drl", "inkscape_star.plt", "part.ngc"])
def test_info_json_for_every_kind(name, ngc):
    path = ngc if name == "part.ngc" else SAMPLES / name
    proc = cli("info", path, "--json")
    assert proc.returncode == 0, proc.stderr
    rep = json.loads(proc.stdout)
    assert isinstance(rep, dict) and rep


def test_serve_names_its_tcp_port_http_port():
    out = cli("serve", "--help").stdout
    assert "--http-port" in out and "--machine-port" not in out
    refused(cli("serve", "--http-port", "70000"), "--http-port")


# -- options against the port: checked before planning, on every port ----------------------------------------

@pytest.mark.parametrize("port", ["/dev/parport7", "maximus:/dev/ttyS77"])
def test_a_pin_log_needs_the_mock(port, tmp_path):
    pins = tmp_path / "p.csv"
    for argv in (["drill", SAMPLES / "board.drl", "--yes"], ["jog", "X+", "5"], ["goto", "1,1,0"]):
        refused(cli(*argv, "--port", port, "--pin-log", pins), "pin log", "mock")
        assert not pins.exists()


def test_the_maximus_board_takes_drill_files_and_a_delay_its_delay_bytes_can_make(ngc, tmp_path):
    port = "maximus:/dev/ttyS77"  # no such device: the checks come first
    for path in (SAMPLES / "ellipse.png", SAMPLES / "inkscape_star.plt", ngc):
        refused(cli("drill", path, "--port", port), port, "Excellon")
    # --delay sets the board's Delay bytes (2 x Delay x 0.1 ms per pulse): 0.2..51 ms, else one line
    for delay in ("0.05,2", "2,60"):
        refused(cli("drill", SAMPLES / "board.drl", "--port", port, "--delay", delay), "--delay", "Delay 1..255")
    from cam.drive.state import MachineState, write_state

    known = tmp_path / "known.json"  # the position known (a missing state file on a real port is unknown: #43)
    write_state(known, MachineState())
    refused(cli("drill", SAMPLES / "board.drl", "--port", port, "--delay", "2,2", "--state", known),
            "cannot open MAXIMUS port")
    # flags that mean nothing to the board are refused, never ignored
    refused(cli("drill", SAMPLES / "board.drl", "--port", port, "--ramp", "linear40"), "--ramp", "constant speed")
    refused(cli("drill", SAMPLES / "board.drl", "--spindle", "on"), "--spindle", "MAXIMUS")
    machine = tmp_path / "maximus.toml"
    machine.write_text("[maximus]\ndrill_z_up_steps = 100\ndrill_z_down_steps = 600\n")
    refused(cli("drill", SAMPLES / "board.drl", "--port", port, "--machine", machine, "--cut-depth", "1"),
            "--cut-depth", "drill_z_down_steps")


def test_checks_run_in_process_too(tmp_path, capsys):
    """The Python entry point (the console script) checks the same way."""
    assert main(["drill", str(SAMPLES / "ellipse.png"), "--report", str(tmp_path / "no" / "r.json")]) == 2
    assert "--report" in capsys.readouterr().err


# -- every number is finite and in range before it is used (part of the safety issue) ------------------------

@pytest.mark.parametrize("argv, fragment", [
    (["drill", SAMPLES / "board.drl", "--cut-depth", "inf"], "--cut-depth"),
    (["drill", SAMPLES / "board.drl", "--travel-height", "inf"], "--travel-height"),
    (["export", SAMPLES / "gear.png", "-o", "g.ngc", "--travel-height", "nan"], "--travel-height"),
    (["drill", SAMPLES / "ellipse.png", "--depth", "99999999999999999999"], "--depth"),
    (["drill", SAMPLES / "ellipse.png", "--depth", "999999999"], "depth"),
    (["drill", SAMPLES / "ellipse.png", "--depth", "4611686018427387905", "--steps-per-pixel", "8,4"], "--depth"),
    (["goto", "99999999999999999999,0,0"], "X,Y,Z"),
    (["drill", SAMPLES / "ellipse.png", "--passes", "100000000"], "--passes"),
    (["drill", SAMPLES / "board.drl", "--offset", "inf,0"], "--offset"),
    (["drill", SAMPLES / "ellipse.png", "--delay", "nan,5"], "--delay"),
    (["drill", SAMPLES / "disc.png", "--profile-expr", "9**9**9"], "out of range"),
    (["drill", SAMPLES / "disc.png", "--profile-expr", "'a'*10**10"], "not allowed"),
])
def test_numbers_out_of_range_are_one_line_errors(argv, fragment):
    proc = cli(*argv, timeout=60)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and fragment in proc.stderr, proc.stderr
