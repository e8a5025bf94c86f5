"""The command line, run as a user would run it: in this process (``run_cli``: ``cam.cli.main`` with its own
stdout and stderr), and as a real ``python -m cam`` process where only a process shows it (its start, a
terminal, signals, a missing package)."""
import argparse
import fcntl
import json
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time

import cv2
import numpy as np
import pytest

import cam
from cam import choices, kinds
from cam.cli.parser import build_parser

from conftest import wait_for_progress, ROOT, SAMPLES, run_cli

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def cli(*args, cwd=None, timeout=120):
    """``cam ARGS`` in this process (see conftest.run_cli)."""
    return run_cli(*args, cwd=cwd, timeout=timeout)


def cli_process(*args, cwd=None, timeout=120):
    """``python -m cam ARGS`` as a process of its own."""
    return subprocess.run(
        [sys.executable, "-m", "cam", *map(str, args)], capture_output=True, text=True, env=ENV, cwd=cwd,
        timeout=timeout, stdin=subprocess.DEVNULL,
    )


def test_python_m_cam_help_starts_a_process():
    """The entry point as a user starts it: ``python -m cam --help`` (the parser alone: no numpy, quick)."""
    proc = cli_process("--help")
    assert proc.returncode == 0 and "usage: cam" in proc.stdout and proc.stderr == ""


@pytest.mark.slow
def test_python_m_cam_exit_codes_and_a_real_run(tmp_path):
    """A process's exit codes: 2 and one line for a bad input, 0 and the report for a job on the mock."""
    proc = cli_process("drill", tmp_path / "nope.png")
    assert_one_line_error(proc, "nope.png", "not found")
    proc = cli_process("drill", SAMPLES / "ellipse.png", "--depth", "2", "--report", tmp_path / "r.json")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("job finished:") and json.loads((tmp_path / "r.json").read_text())["points"] > 0


@pytest.fixture(scope="module")
def drawing(tmp_path_factory):
    """Two short curves, 40x30 px."""
    folder = tmp_path_factory.mktemp("d")
    img = np.full((30, 40, 3), 255, np.uint8)
    img[5, 5:30] = 0
    img[20, 10:35] = 0
    path = folder / "two.png"
    cv2.imwrite(str(path), img)
    return path


def assert_one_line_error(proc, *fragments):
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


@pytest.mark.parametrize("command", [[], ["drill"], ["digitize"], ["info"], ["goto"]])
def test_help_everywhere(command):
    proc = cli(*command, "--help")
    assert proc.returncode == 0 and "usage: cam" in proc.stdout


def test_drill_writes_report_pin_log_and_matrix(tmp_path, drawing):
    proc = cli("drill", drawing, "--depth", "3,5", "--report", tmp_path / "r.json", "--pin-log", tmp_path / "p.csv",
               "--save-digitized", tmp_path / "m.txt", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("job finished:") and "total time" in proc.stdout
    rep = json.loads((tmp_path / "r.json").read_text())
    for key in ("objects", "width_px", "height_px", "width_mm", "height_mm", "depth_mm", "points", "retracts",
                "steps", "estimated_time_s", "warnings"):
        assert key in rep
    assert rep["objects"] == 2 and rep["points"] == 50 and rep["width_px"] == 30 and rep["height_px"] == 16
    assert rep["depth_mm"] == pytest.approx(5 * 0.0157)
    assert set(rep["steps"]) == {"x", "y", "z"} and rep["steps"]["z"] == 2 * (3 + 5)
    log = cam.read_pin_log(tmp_path / "p.csv")
    assert (tmp_path / "p.csv").read_text().splitlines()[0] == "t_ns,data,strobe"
    assert abs(log.t_ns[-1] / 1e9 - rep["estimated_time_s"]) <= 0.01 * rep["estimated_time_s"]
    assert cam.decode_pin_log(log).final_steps == (0, 0, 0)
    # reuse the saved matrix: same job
    proc2 = cli("drill", "--load-digitized", tmp_path / "m.txt", "--depth", "3,5", "--report", tmp_path / "r2.json",
                "--no-progress")
    assert proc2.returncode == 0, proc2.stderr
    rep2 = json.loads((tmp_path / "r2.json").read_text())
    assert rep2["steps"] == rep["steps"] and rep2["estimated_time_s"] == rep["estimated_time_s"]


def test_progress_bar_only_on_a_terminal_unless_asked(drawing):
    quiet = cli("drill", drawing)  # stderr is a pipe here: no bar, so a log stays readable
    assert quiet.returncode == 0, quiet.stderr
    assert "cutting" not in quiet.stderr and "%" not in quiet.stderr
    forced = cli("drill", drawing, "--progress")
    assert forced.returncode == 0, forced.stderr
    assert "cutting: 100%" in forced.stderr and "<" in forced.stderr  # tqdm: [elapsed<remaining]
    assert_one_line_error(cli("drill", drawing, "--progress", "--no-progress"), "--no-progress")


def _run_with_terminal_stderr(*args) -> tuple[int, str]:
    """Run ``python -m cam ARGS`` with stderr on a pseudo-terminal: (exit code, what it wrote there)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 120, 0, 0))  # 120 columns: room for the bar
    try:
        proc = subprocess.Popen([sys.executable, "-m", "cam", *map(str, args)], stdout=subprocess.DEVNULL,
                                stderr=slave, stdin=subprocess.DEVNULL, env=ENV)
        os.close(slave)
        out = b""
        while True:
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # EIO: the child closed its end
                    chunk = b""
                out += chunk
                if not chunk and proc.poll() is not None:
                    break
            elif proc.poll() is not None:
                break
        return proc.wait(timeout=120), out.decode(errors="replace")
    finally:
        os.close(master)


@pytest.mark.slow
def test_progress_bar_on_a_terminal_and_no_progress_turns_it_off(drawing):
    code, shown = _run_with_terminal_stderr("drill", drawing)
    assert code == 0 and "cutting: 100%" in shown
    code, hidden = _run_with_terminal_stderr("drill", drawing, "--no-progress")
    assert code == 0 and "cutting" not in hidden and "%" not in hidden


def test_no_command_is_one_usage_line_exit_2():
    proc = cli()
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("usage: cam "), proc.stderr


def _suffix_named(suffix: str, text: str) -> bool:
    return re.search(rf"(?<![\w.]){re.escape(suffix)}(?!\w)", text) is not None


def test_help_names_every_file_kind():
    info = cli("info", "--help")
    assert info.returncode == 0
    for kind, suffixes in kinds.suffixes().items():
        for suffix in suffixes:
            assert _suffix_named(suffix, info.stdout), (kind, suffix)
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for command in ("drill", "export", "preview", "info"):
        image = next(a for a in sub.choices[command]._actions if a.dest == "image")
        for words in ("drawing", "digitized matrix", "Excellon", "HPGL", "G-code"):
            assert words in image.help, (command, words)
        for suffix in sum(kinds.suffixes().values(), ()):
            assert _suffix_named(suffix, image.help), (command, suffix)


def test_info_and_digitize(tmp_path, drawing):
    proc = cli("info", drawing, "--json")
    rep = json.loads(proc.stdout)
    assert rep["objects"] == 2 and rep["width_mm"] == pytest.approx(30 * 8 * 0.0289, abs=1e-3)
    proc = cli("info", drawing)
    assert "objects:    2" in proc.stdout and "mm" in proc.stdout
    proc = cli("digitize", drawing, "-o", tmp_path / "m.txt")
    assert proc.returncode == 0
    assert len(cam.load_digitized(tmp_path / "m.txt").objects) == 2


def test_goto_reports_position():
    proc = cli("goto", "3,4,2", "--no-progress")
    assert proc.returncode == 0 and "X=24 Y=32 Z=2" in proc.stdout


def test_bad_inputs_one_line_exit_2(tmp_path, drawing):
    assert_one_line_error(cli("drill", tmp_path / "nope.png"), "nope.png", "not found")
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"\x89PNG but not really")
    assert_one_line_error(cli("drill", junk), "junk.png", "not a readable image")
    green = tmp_path / "green.png"
    img = np.full((10, 10, 3), 255, np.uint8)
    img[4, 2:8] = 0
    img[7, 7] = (0, 255, 0)
    cv2.imwrite(str(green), img)
    assert_one_line_error(cli("drill", green), "1 pixel(s)", "(x=7, y=7)")
    empty = tmp_path / "empty.png"
    cv2.imwrite(str(empty), np.full((10, 10, 3), 255, np.uint8))
    assert_one_line_error(cli("drill", empty), "empty")
    assert_one_line_error(cli("drill", drawing, "--depth", "4,", "--no-progress"), "--depth")
    assert_one_line_error(cli("drill", drawing, "--machine", tmp_path / "x.toml"),
                          "x.toml", "not found")
    short = cli("drill", drawing, "--depth", "3", "--no-progress")
    assert short.returncode == 0  # a single value is uniform
    bad_toml = tmp_path / "bad.toml"
    bad_toml.write_text("stepz_per_px = 3\n")
    assert_one_line_error(cli("drill", drawing, "--machine", bad_toml), "bad.toml", "'stepz_per_px'")
    assert_one_line_error(cli("drill", drawing, "--start-at", "5000,0,0"), "travel")
    matrix = tmp_path / "m.txt"
    cli("digitize", drawing, "-o", matrix)
    lines = matrix.read_text().splitlines()
    lines[6] = "1,2,oops,1"
    matrix.write_text("\n".join(lines) + "\n")
    assert_one_line_error(cli("drill", "--load-digitized", matrix), "m.txt:7:")
    assert_one_line_error(cli("drill", drawing, "--steps-per-pixel", "8"), "--steps-per-pixel")
    assert_one_line_error(cli("drill"), "IMAGE")


def test_depth_list_error_states_both_counts(tmp_path):
    img = np.full((20, 30, 3), 255, np.uint8)
    img[3, 3:10] = img[8, 3:10] = img[14, 3:10] = 0
    path = tmp_path / "three.png"
    cv2.imwrite(str(path), img)
    assert_one_line_error(cli("drill", path, "--depth", "3,4"), "2 depth value(s)", "3 objects")


def test_failed_run_keeps_earlier_outputs(tmp_path, drawing):
    report = tmp_path / "r.json"
    assert cli("drill", drawing, "--report", report, "--no-progress").returncode == 0
    before = report.read_bytes()
    assert cli("drill", drawing, "--report", report, "--start-at", "9999,0,0", "--no-progress").returncode == 2
    assert report.read_bytes() == before


@pytest.mark.realtime
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_ctrl_c_and_termination_signals_stop_cleanly_with_position(sig, tmp_path):
    img = np.full((20, 120, 3), 255, np.uint8)
    img[10, 5:115] = 0
    path = tmp_path / "line.png"
    cv2.imwrite(str(path), img)
    proc = subprocess.Popen(
        [sys.executable, "-m", "cam", "drill", str(path), "--realtime", "--delay", "5,5", "--progress",
         "--pin-log", str(tmp_path / "p.csv"), "--report", str(tmp_path / "r.json")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV,
    )
    chunks = wait_for_progress(proc, 20)  # the job takes about 4.5 s: well into it
    proc.send_signal(sig)
    proc.wait(60)
    wait_for_progress.reader.join(10)
    err = b"".join(chunks).decode(errors="replace")
    assert proc.returncode == 130, err
    assert "stopped at X=" in err and "Traceback" not in err
    motion = cam.decode_pin_log(tmp_path / "p.csv")
    assert motion.final_steps[2] == 0 and motion.final_steps[0] > 0  # lifted, and it had moved
    assert json.loads((tmp_path / "r.json").read_text())["status"] == "stopped"


@pytest.mark.slow
def test_ctrl_c_at_a_prompt_stops_at_once(tmp_path):
    img = np.full((10, 30, 3), 255, np.uint8)
    img[5, 5:25] = 0
    path = tmp_path / "line.png"
    cv2.imwrite(str(path), img)
    proc = subprocess.Popen(
        [sys.executable, "-m", "cam", "drill", str(path), "--pause-at", "10,5", "--no-progress"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
    )
    deadline = time.monotonic() + 60
    seen = ""
    while "press Enter" not in seen:  # stdin stays open: the prompt waits for an answer
        assert time.monotonic() < deadline, seen
        seen += os.read(proc.stderr.fileno(), 4096).decode()
    proc.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and time.monotonic() - t0 < 5, (proc.returncode, seen + err)
    assert "Traceback" not in seen + err


def cli_without(module: str, *args):
    """``cam ARGS`` in an interpreter where ``import MODULE`` fails, as if its package were not installed."""
    code = f"import sys; sys.modules[{module!r}] = None\nfrom cam.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, env=ENV,
                          timeout=120)


@pytest.mark.slow
def test_missing_extras_are_one_line_naming_the_extra(drawing, tmp_path):
    from cam.drive.state import MachineState, write_state

    known = tmp_path / "known.json"  # a machine whose position is known: the port itself is reached
    write_state(known, MachineState())
    proc = cli_without("parallel", "drill", drawing, "--port", "/dev/parport0", "--no-progress", "--state", known)
    assert_one_line_error(proc, "/dev/parport0", "pyparallel", "cam[parport]")
    proc = cli_without("uvicorn", "serve", "--http-port", "0")
    assert_one_line_error(proc, "uvicorn", "cam[web]")
    proc = cli_without("starlette", "serve", "--http-port", "0")
    assert_one_line_error(proc, "starlette", "cam[web]")


def test_missing_parallel_port_is_one_line_with_hint(drawing, tmp_path):
    from cam.drive.state import MachineState, write_state

    known = tmp_path / "known.json"  # the position known (a missing state file on a real port is unknown: #43)
    write_state(known, MachineState())
    proc = cli("drill", drawing, "--port", "/dev/parport-does-not-exist", "--no-progress", "--state", known)
    assert_one_line_error(proc, "/dev/parport-does-not-exist")
    assert "modprobe ppdev" in proc.stderr or "permission" in proc.stderr
    assert_one_line_error(cli("drill", drawing, "--port", "lpt1"), "unknown port 'lpt1'")


GCODE_JOB = "G21 G90\nG0 Z1\nG0 X1 Y-1\nG1 Z-0.5 F100\nG1 X5 Y-1\nG1 X5 Y-5\nG0 Z1\nM6 T2\nG1 Z-0.2\nG0 Z1\nM2\n"


def test_preview_export_and_info_take_every_file_kind(tmp_path):
    """Drill, HPGL and G-code files are jobs already: preview, export and info plan them like drill does."""
    import cv2

    root = ROOT
    ngc = tmp_path / "job.ngc"
    ngc.write_text(GCODE_JOB)
    for src, out in ((root / "samples" / "board.drl", "b.png"), (root / "samples" / "seed_tools.plt", "h.svg"),
                     (ngc, "g.png")):
        proc = cli("preview", src, "-o", tmp_path / out)
        assert proc.returncode == 0, proc.stderr
        if out.endswith(".png"):
            img = cv2.imread(str(tmp_path / out))
            assert img is not None and (img < 128).any()
        else:
            assert (tmp_path / out).read_text().lstrip().startswith("<svg")
    proc = cli("export", root / "samples" / "seed_tools.plt", "-o", tmp_path / "h.ngc")
    assert proc.returncode == 0, proc.stderr
    assert [ln.split()[0] for ln in (tmp_path / "h.ngc").read_text().splitlines() if " M6" in ln] == ["T1", "T2"]
    proc = cli("info", ngc)
    assert proc.returncode == 0, proc.stderr
    assert "moves" in proc.stdout and "depth 0.502 mm" in proc.stdout  # 0.5 mm to the nearest Z step
    assert "tool change" in proc.stdout
    assert_one_line_error(cli("export", ngc, "-o", tmp_path / "x.ngc"), "G-code already")
    assert_one_line_error(cli("preview", root / "samples" / "board.drl", "--surface", "-o", tmp_path / "s.png"),
                          "--surface")
    # a G-code job is a job in steps like any other: its toolpath is drawn as SVG too
    assert cli("preview", ngc, "-o", tmp_path / "g.svg").returncode == 0
    assert (tmp_path / "g.svg").read_text().startswith("<svg") and "<line" in (tmp_path / "g.svg").read_text()
    assert not (tmp_path / "x.ngc").exists() and not (tmp_path / "s.png").exists()


@pytest.mark.realtime
def test_an_interrupted_jog_says_how_far_it_moved():
    proc = subprocess.Popen([sys.executable, "-m", "cam", "jog", "X+", "2000", "--realtime", "--progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    chunks = wait_for_progress(proc, 5)  # 2000 steps at 5 ms take 10 s: stop it once it moves
    proc.send_signal(signal.SIGINT)
    proc.wait(60)
    wait_for_progress.reader.join(10)
    err = b"".join(chunks).decode(errors="replace")
    assert proc.returncode == 130, err
    moved = int(re.search(r"jog stopped: moved X=(\d+) Y=0 Z=0 steps", err).group(1))
    assert 0 < moved < 2000


def test_only_a_process_of_its_own_freezes_what_the_imports_made(monkeypatch, capsys):
    """``python -m cam`` and the ``cam`` script leave the objects of the imports to the garbage collector's
    permanent generation (a long job's send loop does not walk them again and again); a caller of ``main`` in
    its own process (a notebook, the tests) keeps its collector as it was."""
    import gc
    from cam import cli

    frozen = []
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append(True))
    assert cli.main(["info", str(SAMPLES / "board.drl")]) == 0
    assert frozen == []
    monkeypatch.setattr(cli, "main", lambda argv=None, *, own_process=False: frozen.append(own_process) or 0)
    assert cli.main_process() == 0
    assert frozen == [True]
    monkeypatch.undo()
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append("frozen"))
    assert cli.main(["info", str(SAMPLES / "board.drl")], own_process=True) == 0
    assert frozen == [True, "frozen"]
