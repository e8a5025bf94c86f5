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


def test_one_bounded_reader_names_the_file_in_each_one_line_failure(tmp_path, monkeypatch):
    """cam.fileio.read_bytes is the one bounded read (read_text and the height map's reader use it): not found, a
    folder, too big (by the open file's size, and a file that grew past the bound while it was read) and not
    readable are each one line naming the file; within the bound the bytes come back whole."""
    from cam.errors import ParseError
    from cam.fileio import read_bytes, read_text

    f = tmp_path / "a.bin"
    f.write_bytes(b"x" * 10)
    assert read_bytes(f, max_bytes=10) == (f, b"x" * 10) and read_bytes(f) == (f, b"x" * 10)
    cases = [(tmp_path / "none.bin", 10, f"{tmp_path / 'none.bin'}: file not found"),
             (tmp_path, 10, f"{tmp_path}: is a folder, not a thing"),
             (f, 9, f"{f}: 10 bytes, more than a thing may be (9)")]
    for path, most, want in cases:
        with pytest.raises(ParseError) as e:
            read_bytes(path, max_bytes=most, what="a thing")
        assert str(e.value) == want
    real_fstat = os.fstat
    monkeypatch.setattr(os, "fstat", lambda fd: os.stat_result((0,) * 6 + (3,) + (0,) * 3))  # stat said 3 bytes
    with pytest.raises(ParseError, match=r"a\.bin: 10 bytes, more than a file may be \(9\)$"):
        read_bytes(f, max_bytes=9)  # it grew: never read past the bound + 1
    monkeypatch.setattr(os, "fstat", real_fstat)
    if os.geteuid() != 0:  # root reads any file
        f.chmod(0)
        with pytest.raises(ParseError, match=r"a\.bin: cannot read \(Permission denied\)$"):
            read_bytes(f)
        f.chmod(0o644)
    t = tmp_path / "t.txt"
    t.write_bytes(b"a\r\nb\rc\n")
    assert read_text(t, not_text="not text") == (t, "a\nb\nc\n")  # line ends as Python's text files read them
    t.write_bytes(b"\xff")
    with pytest.raises(ParseError, match=r"t\.txt:1: not text$"):
        read_text(t, not_text="not text")
    with pytest.raises(ParseError, match=r": is a folder, not a file$"):
        read_text(tmp_path, not_text="not text")
