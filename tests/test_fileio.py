"""Outputs are written atomically and get the normal mode of a new file (0o666 less the umask)."""
import os
import stat
import subprocess
import sys

import cv2
import numpy as np
import pytest

from cam.fileio import atomic_write_bytes

from conftest import ROOT, run_cli

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


@pytest.fixture
def umask():
    """Set the process umask for one test; the old one comes back after it."""
    previous = os.umask(0o022)
    yield os.umask
    os.umask(previous)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_new_and_replaced_outputs_get_the_umask_mode(tmp_path, umask, mask, mode):
    umask(mask)
    target = tmp_path / "out.txt"
    atomic_write_bytes(target, b"one\n")
    assert _mode(target) == mode
    atomic_write_bytes(target, b"two\n")  # replaced through a new temporary file: same mode
    assert _mode(target) == mode and target.read_bytes() == b"two\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]  # no temporary file left behind


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600)])
def test_command_line_outputs_get_the_umask_mode(tmp_path, umask, mask, mode):
    src = tmp_path / "line.png"
    img = np.full((12, 16), 255, np.uint8)
    img[5, 3:12] = 0
    cv2.imwrite(str(src), img)
    umask(mask)  # the command runs in this process (run_cli): under this umask
    matrix, picture = tmp_path / "m.txt", tmp_path / "p.png"
    for args in (["digitize", src, "-o", matrix], ["preview", src, "-o", picture, "--depth", "2"]):
        proc = run_cli(*args)
        assert proc.returncode == 0, proc.stderr
    assert _mode(matrix) == mode and _mode(picture) == mode


def test_a_symbolic_link_writes_the_file_it_points_to(tmp_path):
    real = tmp_path / "real.json"
    real.write_text("old\n")
    link = tmp_path / "link.json"
    link.symlink_to(real)
    atomic_write_bytes(link, b"new\n")
    assert link.is_symlink() and real.read_text() == "new\n"


def test_temporaries_of_a_killed_run_are_removed_on_the_next_write(tmp_path):
    import os
    import time

    stale = tmp_path / ".out.png.deadbeef.tmp"
    stale.write_bytes(b"x" * 1000)
    old = time.time() - 3600
    os.utime(stale, (old, old))
    fresh = tmp_path / ".out.png.0123abcd.tmp"  # another run may be writing right now: left alone
    fresh.write_bytes(b"y")
    atomic_write_bytes(tmp_path / "out.png", b"png")
    assert not stale.exists() and fresh.exists() and (tmp_path / "out.png").read_bytes() == b"png"


@pytest.mark.realtime
def test_a_killed_or_failed_run_leaves_the_earlier_pin_log_and_report_intact(tmp_path):
    """Nothing lost: the outputs of the last good run survive a run that is killed mid-job or that fails."""
    import signal

    from conftest import SAMPLES, wait_for_progress

    env = ENV
    pins, report = tmp_path / "pins.csv", tmp_path / "report.json"
    ok = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--pin-log", pins, "--report", report,
                 "--no-progress")
    assert ok.returncode == 0, ok.stderr
    before = pins.read_bytes(), report.read_bytes()
    # killed in the middle of a real-time run
    proc = subprocess.Popen([sys.executable, "-m", "cam", "drill", str(SAMPLES / "ellipse.png"), "--depth", "2",
                             "--realtime", "--pin-log", str(pins), "--report", str(report), "--progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, start_new_session=True)
    wait_for_progress(proc, 2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(30)
    assert (pins.read_bytes(), report.read_bytes()) == before
    # a run that fails on its input
    bad = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--start-at", "99999,0,0", "--pin-log", pins,
                  "--report", report)
    assert bad.returncode == 2
    assert (pins.read_bytes(), report.read_bytes()) == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "no temporary file left behind"
