"""A full disk is a clear error and loses nothing (issue #33 point 5): a pin log, journal or report write that fails
is one line naming the file and the cause, leaves no .part file, a job whose journal cannot be written does not
start, and a job that finished says so even when its report cannot be written."""
import os

import pytest

import cam.cli.drill
import cam.drive.journal
from cam.errors import CamError

from conftest import SAMPLES, run_cli

needs_dev_full = pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full to fill a disk with")


def _one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.startswith("cam: error: ")]
    assert len(lines) == 1 and "internal error" not in stderr and "Traceback" not in stderr, stderr
    return lines[0]


@needs_dev_full
def test_a_pin_log_on_a_full_disk_is_one_line_and_leaves_no_part_file(tmp_path):
    log = tmp_path / "job.csv"
    os.symlink("/dev/full", tmp_path / "job.csv.part")  # every write into the pin log: ENOSPC
    r = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--yes", "--pin-log", log)
    assert r.returncode == 2
    line = _one_error_line(r.stderr)
    assert f"{log}: cannot write the pin log (No space left on device)" in line
    assert not log.exists() and not os.path.lexists(tmp_path / "job.csv.part")


def _refuse_writes(monkeypatch, module, name_part: str) -> None:
    real = module.atomic_write_text

    def full(path, text):
        if name_part in str(path):
            raise CamError(f"{path}: cannot write (No space left on device)")
        return real(path, text)

    monkeypatch.setattr(module, "atomic_write_text", full)


def test_a_journal_that_cannot_be_written_stops_the_job_before_it_starts(tmp_path, monkeypatch):
    _refuse_writes(monkeypatch, cam.drive.journal, "journal")
    log, journal = tmp_path / "job.csv", tmp_path / "job.journal.json"
    r = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--yes", "--pin-log", log, "--journal", journal)
    assert r.returncode == 2 and "job finished" not in r.stdout
    line = _one_error_line(r.stderr)
    assert f"{journal}: cannot write (No space left on device)" in line and "the job was not started" in line
    assert not log.exists()  # nothing ran


def test_a_finished_job_whose_report_cannot_be_written_says_both(tmp_path, monkeypatch):
    _refuse_writes(monkeypatch, cam.cli.drill, "report.json")
    report = tmp_path / "report.json"
    report.write_text('{"status": "an earlier run"}\n')
    r = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--yes", "--report", report)
    assert r.returncode == 2
    assert r.stdout.startswith("job finished:")
    line = _one_error_line(r.stderr)
    assert f"the report was not written: {report}: cannot write (No space left on device)" in line
    assert report.read_text() == '{"status": "an earlier run"}\n'  # the earlier output is intact


@pytest.mark.realtime
def test_a_journal_write_that_fails_during_a_run_stops_the_job_there(tmp_path, monkeypatch):
    """The disk fills during the run: the job stops (tool lifted) at the first failed journal write instead of
    running on without a journal, and says why."""
    import numpy as np

    from cam.drive.ports import MockPort
    from cam.drive.session import MachineSession
    import dataclasses

    from cam.job.model import CUT, travel_job
    from cam.settings import DEFAULT_SETTINGS

    real, calls = cam.drive.journal.atomic_write_text, []

    def fills_up(path, text):
        calls.append(path)
        if len(calls) > 2:
            raise CamError(f"{path}: cannot write (No space left on device)")
        return real(path, text)

    monkeypatch.setattr(cam.drive.journal, "atomic_write_text", fills_up)
    session = MachineSession(MockPort(), DEFAULT_SETTINGS, realtime=True)
    try:
        line = travel_job(np.array([[0, 0, 2], [600, 0, 2], [600, 0, 0]]), DEFAULT_SETTINGS)
        job = dataclasses.replace(line, kind=np.full(3, CUT, np.uint8))  # a cut (a travel alone is a jog)
        session.start(job, journal=str(tmp_path / "j.json"))
        session.wait_idle(None)
    finally:
        session.shutdown()
    info = session.last_run
    assert info["status"] == "stopped" and 0 < info["writes"] < 1 + 2 * 604, info
    assert any("No space left on device" in m for m in info["messages"]), info["messages"]
