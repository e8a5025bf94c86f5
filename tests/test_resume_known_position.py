"""Resume starts from a known position (issue #43 point 7).

A journal still ``running`` was left by a run that ended without its last write (killed, or its disk filled): it
may be behind what was sent, so ``cam drill --resume`` does not take its position: the run goes on from where the
machine state has the tool, refused in one line while that is unknown (until ``cam where --set`` or homing), and
the refusal says where the machine reported the stop when the state file recorded it.  A state file that cannot be
written at the end does not take the run's finished line, pin log or report with it.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import cam.drive.state
from cam.drive.journal import read_journal
from cam.drive.state import MachineState, read_state, steps_to_mm, write_state
from cam.errors import CamError
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import SAMPLES, run_cli
from test_resume import ENV, _check_union, _drill_args, _prepared

SETTINGS = cam.MachineSettings()


def _error_lines(stderr: str) -> list[str]:
    assert "Traceback" not in stderr and "internal error" not in stderr, stderr
    return [line for line in stderr.splitlines() if line.startswith("cam: error: ")]


def _wait_journal_progress(journal: Path, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    """Until the running job's journal has recorded writes sent (a write during the run, not only its first)."""
    deadline = time.monotonic() + timeout_s
    while True:
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.poll() else "timeout"
        try:
            values = json.loads(journal.read_text())
        except (OSError, ValueError):
            values = {}
        if values.get("state") == "running" and values.get("writes_done", 0) > 0:
            return
        time.sleep(0.02)


def _mm(steps) -> str:
    return ",".join(f"{v:g}" for v in steps_to_mm(steps, SETTINGS))


@pytest.mark.realtime
def test_resume_after_full_disk_journal_behind_needs_known_position(tmp_path):
    # the state file and the journal on one disk; the pin log and the report elsewhere.  The journal is written by
    # the real-time runner's own process, so the disk "fills" for every process at once: its folder goes away
    # (every write there fails, as on a full disk; a file of its name keeps it from being made again) and comes back
    # when the disk is freed
    disk = tmp_path / "disk"
    disk.mkdir()
    state, journal = disk / "machine.json", disk / "job.journal.json"
    first, report1 = tmp_path / "run1.csv", tmp_path / "run1.json"
    args = _drill_args("2d", tmp_path, "--state", str(state))
    proc = subprocess.Popen([sys.executable, "-m", "cam", *args, "--realtime", "--journal", str(journal),
                             "--pin-log", str(first), "--report", str(report1)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        _wait_journal_progress(journal, proc)
        full = tmp_path / "disk-full"
        disk.rename(full)  # the disk is full from here on: its folder is not there, nor can it be made
        disk.write_text("")
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    disk.unlink()
    full.rename(disk)  # freed
    # the run stopped at the first journal write that failed, and said where the tool stopped (machine frame)
    stop = tuple(int(v) for v in decode_pin_log(read_pin_log(first), SETTINGS).position_steps[-1])
    assert proc.returncode == 2, err
    lines = _error_lines(err)
    assert len(lines) == 1 and "the machine state was not recorded" in lines[0], err
    assert f"the tool stands at machine {list(stop)} steps" in lines[0], (stop, lines)
    assert json.loads(report1.read_text())["status"] == "stopped"  # the report and the pin log were written
    behind = read_journal(journal)
    assert behind.state == "running"  # its last write never came: it may be behind the stop
    assert read_state(state, SETTINGS).running is not None  # the stop was never recorded

    resume = _drill_args("2d", tmp_path, "--state", str(state), "--resume", str(journal))
    second = tmp_path / "run2.csv"
    r = run_cli(*resume, "--pin-log", second)
    lines = _error_lines(r.stderr)
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert "was not closed" in lines[0] and "may be behind" in lines[0] and "cam where --set" in lines[0]
    assert "position is unknown" in lines[0] and "reported" not in lines[0]  # nothing reported the stop
    assert not second.exists()  # nothing moved

    # where the state file recorded the machine's word at a stop (the position unknown): the refusal says it
    write_state(state, MachineState().lost("an emergency stop ended job ellipse.png (steps may have been lost)",
                                           stop))
    r = run_cli(*resume, "--pin-log", second)
    lines = _error_lines(r.stderr)
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert f"the machine reported the stop at machine {list(stop)} steps" in lines[0]
    assert not second.exists()

    # the user says where the tool is: the resume goes on from there, not from the journal's older position
    assert run_cli("where", "--state", state, "--set", _mm(stop)).returncode == 0
    report2 = tmp_path / "run2.json"
    r = run_cli(*resume, "--pin-log", second, "--report", report2)
    assert r.returncode == 0, r.stderr
    rep = json.loads(report2.read_text())
    assert rep["status"] == "finished" and rep["start_position_steps"] == list(stop)
    assert rep["start_position_steps"] != list(behind.position_steps) or behind.writes_done == 0
    job, _ = _prepared(_drill_args("2d", tmp_path))
    _check_union("2d", tmp_path, job, first, second, rep["start_position_steps"])  # carved as one run
    assert read_state(state, SETTINGS).position_known


def test_state_file_unwritable_keeps_finished_line_pin_log_and_report(tmp_path, monkeypatch):
    """Only the state file's disk is full when the job ends: the job's own outputs are all there and it says it
    finished; then one error line says the state was not recorded, with where the tool stands."""
    state, pins, report = tmp_path / "full" / "machine.json", tmp_path / "job.csv", tmp_path / "report.json"
    state.parent.mkdir()
    real = cam.drive.state.atomic_write_text

    def full(path, text):  # the running marker goes in before the run; the disk is full when it ends
        if Path(path) == state and '"running": null' in text:
            raise CamError(f"{path}: cannot write (No space left on device)")
        return real(path, text)

    monkeypatch.setattr(cam.drive.state, "atomic_write_text", full)
    r = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--yes", "--state", state, "--pin-log", pins,
                "--report", report)
    assert r.returncode == 2
    assert r.stdout.startswith("job finished:")
    lines = _error_lines(r.stderr)
    end = tuple(int(v) for v in decode_pin_log(read_pin_log(pins), SETTINGS).position_steps[-1])
    assert len(lines) == 1 and "the machine state was not recorded" in lines[0], r.stderr
    assert f"{state}: cannot write (No space left on device)" in lines[0]
    assert f"the tool stands at machine {list(end)} steps" in lines[0] and "cam where --set" in lines[0]
    rep = json.loads(report.read_text())
    assert rep["status"] == "finished"
    whole = decode_pin_log(cam.run(_prepared(["drill", str(SAMPLES / "ellipse.png"), "--depth", "2"])[0].plan)
                           .pin_log(), SETTINGS)
    assert np.array_equal(decode_pin_log(read_pin_log(pins), SETTINGS).position_steps, whole.position_steps)
    assert read_state(state, SETTINGS).running is not None  # the next command finds the position unknown
