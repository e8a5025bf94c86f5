"""The machine session keeps the machine state file as the command line does (issue #29 point 3): machine and
work frames, Zero and Go To, every file's job placed at the work zero, every end recorded, a move refused while
the position is unknown.  The web page and the Python API drive the machine through this session."""
from __future__ import annotations

import time

import numpy as np
import pytest

import cam
from cam.drive.session import MachineSession
from cam.drive.state import PositionUnknownError, StateHold, read_state
from cam.errors import PlanError, TravelError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.verify.pinlog import decode_pin_log
from conftest import SAMPLES

S = cam.MachineSettings()


@pytest.fixture(scope="module")
def ellipse():
    return prepare_job(SAMPLES / "ellipse.png", JobOptions(depth=(2,)), S)


@pytest.fixture(scope="module")
def wanted(ellipse):
    """The ellipse job's motion run from its own home (the reference every placed run must equal)."""
    return decode_pin_log(cam.run(ellipse.plan).pin_log(), S).position_steps


def _session(tmp_path):
    hold = StateHold(tmp_path / "m.json", S, "the test")
    return MachineSession("mock", S, state=hold), hold


def test_go_to_then_a_drawing_job_cuts_at_the_work_zero_and_the_file_keeps_the_end(tmp_path, ellipse, wanted):
    ses, hold = _session(tmp_path)
    try:
        ses.go_to((800, 400, 0), unit="steps")  # the case: a go-to, then a job
        assert ses.wait_idle(30) and ses.last_run["status"] == "finished"
        assert read_state(hold.path, S).position_steps == (800, 400, 0)
        info = ses.run(ellipse)  # travels back to the work zero (G54 at the home) first, then cuts
        assert info["status"] == "finished" and info["activity"] == "job", info
        assert np.array_equal(decode_pin_log(ses.last_job_pin_log, S).position_steps, wanted)
        s = read_state(hold.path, S)
        assert s.position_steps == (0, 0, 0) and s.position_known and s.running is None
        assert any("to the work zero" in e["text"] for e in ses.state()["log"])

        ses.go_to((800, 400, 3), unit="steps", machine_coords=True)
        ses.wait_idle(30)
        ses.zero()  # XYZ of G54 here: the job is cut from here, nothing to travel first
        assert ses.where()["work_steps"] == [0, 0, 0] and ses.where()["offsets_mm"]["G54"][0] == round(800 * S.mm_per_step_xy, 4)
        assert ses.run(ellipse)["status"] == "finished"
        assert np.array_equal(decode_pin_log(ses.last_job_pin_log, S).position_steps, wanted)
        assert read_state(hold.path, S).position_steps == (800, 400, 3)
    finally:
        hold.close()


def test_go_to_is_in_the_work_frame_and_lifts_first(tmp_path):
    ses, hold = _session(tmp_path)
    try:
        ses.go_to((80, 80, 16), unit="steps", machine_coords=True)
        ses.wait_idle(30)
        ses.zero("XY")
        ses.go_to((10, 20, 0), unit="steps")  # work frame: machine (90, 100, 0), up to the work zero's Z first
        ses.wait_idle(30)
        where = ses.where()
        assert where["machine_steps"] == [90, 100, 0] and where["work_steps"] == [10, 20, 0]
        moves = decode_pin_log(ses.last_result.pin_log(), S).position_steps
        first_xy = np.flatnonzero(np.any(moves[:, :2] != 0, axis=1))[0]
        assert moves[first_xy, 2] == -16  # Z was up at the work zero's surface before X or Y moved
        ses.go_to_origin()  # the page's "Origin": the active work zero
        ses.wait_idle(30)
        assert ses.where()["machine_steps"] == [80, 80, 0]
        with pytest.raises(TravelError, match="outside the X travel"):
            ses.go_to((-500, 0, 0))
        with pytest.raises(PlanError, match="xyz Y must be a finite number"):
            ses.go_to((1, float("nan"), 0))
    finally:
        hold.close()


def test_zero_in_another_offset_and_use_it(tmp_path):
    ses, hold = _session(tmp_path)
    try:
        ses.go_to((40, 24, 0), unit="steps")
        ses.wait_idle(30)
        ses.zero("XY", offset="G55")
        assert ses.where()["active_offset"] == "G54" and ses.where()["work_steps"] == [40, 24, 0]
        ses.use_offset("G55")
        assert ses.where()["work_steps"] == [0, 0, 0]
        assert read_state(hold.path, S).active_offset == "G55"
        with pytest.raises(PlanError, match="offset must be one of"):
            ses.use_offset("G60")
        with pytest.raises(PlanError, match="axes must be"):
            ses.zero("XX")
    finally:
        hold.close()


def test_a_job_placed_where_it_does_not_fit_moves_nothing(tmp_path, ellipse):
    ses, hold = _session(tmp_path)
    try:
        ses.go_to((9896, 9896, 0), unit="steps")
        ses.wait_idle(30)
        ses.zero("XY")
        before = read_state(hold.path, S)
        with pytest.raises(TravelError, match="leaves the X travel"):
            ses.start(ellipse)
        assert not ses.busy and read_state(hold.path, S) == before
    finally:
        hold.close()


def test_an_emergency_stop_makes_the_position_unknown_until_the_user_says_it(tmp_path, ellipse):
    ses, hold = _session(tmp_path)
    board = prepare_job(SAMPLES / "board.drl", JobOptions(), S)
    try:
        ses.start(board)  # holds at its first tool change: nobody answers
        deadline = time.monotonic() + 30
        while ses.state()["prompt"] is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert ses.state()["prompt"] is not None
        ses.emergency_stop()
        ses.wait_idle(30)
        assert ses.last_run["status"] == "emergency-stopped", ses.last_run
        s = read_state(hold.path, S)
        assert not s.position_known and "emergency stop" in s.unknown_reason
        # a jog is allowed (issue #45 point 3: test_recovery.py); go-tos, jobs and zeros are not
        for move in (lambda: ses.go_to((0, 0, 0)), lambda: ses.start(ellipse), lambda: ses.zero()):
            with pytest.raises(PositionUnknownError, match="unknown"):
                move()
        ses.set_position((0, 0, 0))  # the user's word, as cam where --set
        assert read_state(hold.path, S).position_known and not read_state(hold.path, S).homed
        ses.jog("x", 10)
        ses.wait_idle(30)
        assert read_state(hold.path, S).position_steps == (10, 0, 0)
    finally:
        hold.close()


def test_without_a_state_file_the_session_keeps_its_own_frame():
    ses = MachineSession("mock", S)
    ses.go_to((8, 8, 0), unit="steps")
    ses.wait_idle(30)
    ses.zero("X")
    assert ses.where()["machine_steps"] == [0, 8, 0] and ses.where()["state_file"] is None


@pytest.mark.realtime
def test_the_finished_line_of_a_real_time_run_gives_the_elapsed_time_and_lateness():
    """The page's log line (issue #32 point 6): how long the run took, the plan's machine time, and how late."""
    fast = cam.MachineSettings().replace(delay_xy_ms=0.05, delay_z_ms=0.05, ramp="constant")
    job = prepare_job(SAMPLES / "ellipse.png", JobOptions(depth=(1,)), fast)
    ses = MachineSession("mock", fast, realtime=True)
    info = ses.run(job)
    assert info["status"] == "finished"
    line = [e["text"] for e in ses.state()["log"] if "finished" in e["text"]][-1]
    assert "the run took 0:00:" in line and "s machine time planned, constant ramps" in line, line
    if info["stalls"]:
        assert f"{info['stalls']} stall" in line and "the longest" in line, line
    simulated = MachineSession("mock", fast)
    simulated.run(job)
    line = [e["text"] for e in simulated.state()["log"] if "finished" in e["text"]][-1]
    assert "total time 0:00:" in line and "simulated" in line, line
