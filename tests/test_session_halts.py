"""A stop is never lost between two activities, and the stop's lift never leaves the travel (the safety rules:
stop and emergency stop halt within a step period; no move leaves the configured travel).

1. A session that keeps a state file travels to a job's work zero first, then starts the job when that travel
   ends (:meth:`MachineSession.finish` hands over).  A Stop or an emergency stop that arrives at that hand-over --
   the travel's last write sent but its end not booked yet, or booked and the job not begun yet -- stops the hand-over:
   the job never starts (nothing of it in the mock's pin log) and the session says so in one line.  The tests hold
   the worker exactly there with events (no sleeps), stop, then let it go.
2. A Stop while the new tool is probed at a tool change: the job's own stop lift (to its safe plane) runs from
   where the probe left the tool, above the plate; where that lift would go above the Z travel, it stops at the
   travel's top, said in one line.
"""
from __future__ import annotations

import signal
import threading
from dataclasses import replace

import numpy as np
import pytest

import cam
from cam.drive import pause_probe
from cam.drive.ports import MockPort
from cam.drive.session import MachineSession
from cam.drive.state import StateHold
from cam.settings import settings_from_mapping
from cam.verify.pinlog import decode_pin_log

from test_probe import FLAT, mock_settings
from test_tool_change_probe import _two_tool_job

TRAVEL_LABEL = "to the work zero"


def _placed_session(tmp_path):
    """A session on the mock with a state file, its G54 zero at X20 Y15 mm, the tool at the machine's home: a
    drill job started there travels to the work zero first."""
    s = mock_settings(FLAT)
    hold = StateHold(tmp_path / "state.json", s, "test")
    port = MockPort()
    session = MachineSession(port, s, state=hold)
    session.go_to((20, 15, 0), "mm")
    assert session.wait_idle(120)
    session.zero("XY")
    session.go_to((0, 0, 0), "mm", machine_coords=True)
    assert session.wait_idle(120)
    return s, hold, port, session


def _halt(session: MachineSession, how: str) -> None:
    if how == "stop":
        session.stop()
    else:
        session.emergency_stop()


def _assert_job_never_started(session: MachineSession, port: MockPort, s, writes_before: int, how: str) -> None:
    assert session.wait_idle(10), "the job started after the stop and waits at its prompt"
    info = session.last_run
    assert info["status"] == ("stopped" if how == "stop" else "emergency-stopped"), info
    assert len(info["messages"]) == 1 and "was not started" in info["messages"][0], info
    travel_writes = session.last_result.writes  # the travel's: the last run there was
    log = port.pin_log()
    assert len(log.t_ns) == writes_before + travel_writes  # not one write of the job
    pos = decode_pin_log(log, s).position_steps
    assert tuple(int(v) for v in pos[-1]) == session.position_steps()


@pytest.mark.parametrize("how", ["stop", "emergency-stop"])
def test_a_stop_as_the_travel_to_the_work_zero_ends_is_not_lost(tmp_path, monkeypatch, how):
    """The travel's runner has sent its last write; its end is not booked yet (the worker held on its way into
    ``finish``): the stop comes there, and the job is not started."""
    s, hold, port, session = _placed_session(tmp_path)
    with hold:
        at_end, go = threading.Event(), threading.Event()
        finish = session.finish

        def held_finish(info, moved_steps, **kw):
            if session._activity is not None and session._activity.label == TRAVEL_LABEL:
                at_end.set()
                assert go.wait(120)
            finish(info, moved_steps, **kw)

        monkeypatch.setattr(session, "finish", held_finish)
        writes_before = len(port.pin_log().t_ns)
        session.start(_two_tool_job(tmp_path, s, hold.state))
        assert at_end.wait(120)
        _halt(session, how)
        go.set()
        try:
            _assert_job_never_started(session, port, s, writes_before, how)
        finally:
            session.emergency_stop()
            session.wait_idle(10)


@pytest.mark.parametrize("how", ["stop", "emergency-stop"])
def test_a_stop_between_the_travels_end_and_the_jobs_start_is_not_lost(tmp_path, monkeypatch, how):
    """The travel's end booked and its activity cleared, the job not begun yet (the worker held in ``finish``, the
    session's lock held): a stop from another thread finds nothing running at first (the colleague's report: it was
    lost, the job then waited at its prompt); it still stops the hand-over."""
    s, hold, port, session = _placed_session(tmp_path)
    with hold:
        in_hand_over, go, read = threading.Event(), threading.Event(), threading.Event()
        record_state = session._record_state
        controller = session._controller
        stopper: list[threading.Thread] = []

        def held_record_state():
            record_state()
            a = session._last_activity
            if a is not None and a.label == TRAVEL_LABEL and not in_hand_over.is_set():
                in_hand_over.set()
                assert go.wait(120)

        def watched_controller():
            ctl = controller()
            if stopper and threading.current_thread() is stopper[0]:
                read.set()  # the stop has looked for the running activity (and found none)
            return ctl

        monkeypatch.setattr(session, "_record_state", held_record_state)
        monkeypatch.setattr(session, "_controller", watched_controller)
        writes_before = len(port.pin_log().t_ns)
        session.start(_two_tool_job(tmp_path, s, hold.state))
        assert in_hand_over.wait(120)
        assert session._activity is None  # held exactly between the two activities
        stopper.append(threading.Thread(target=_halt, args=(session, how)))
        stopper[0].start()
        assert read.wait(120)
        go.set()
        stopper[0].join(120)
        try:
            _assert_job_never_started(session, port, s, writes_before, how)
        finally:
            session.emergency_stop()
            session.wait_idle(10)


# -- a stop while the new tool is probed at a tool change ------------------------------------------------------

TOP_STEPS = -400
"""The top of the Z travel of the test's machine (steps, +Z deeper)."""


def _short_z_settings():
    return settings_from_mapping({"inputs": {"probe": "!13", "estop": "!15"},
                                  "travel": {"z_min_steps": TOP_STEPS, "z_max_steps": 2000},
                                  "mock": {"probe_surface": ",".join(str(v) for v in FLAT)}})


def test_a_stop_while_the_new_tool_is_probed_lifts_no_higher_than_the_travel(tmp_path, monkeypatch):
    """A G-code program changes tools (M6) with the tool 3 mm into the work; its stop lifts to its safe plane (where
    it started, the surface), 3 mm.  The new tool is probed there: the probe takes the tool up to 5 mm over the
    plate, and the Stop comes as it is about to go down.  The job's 3 mm lift from there would end 0.9 mm above the
    travel's top: it stops at the top instead, and says so; nobody is asked again after the stop; the decoded pin
    log never goes above the travel and ends where the session says the tool is."""
    s = _short_z_settings()
    per = s.mm_per_step_z
    program = tmp_path / "deep-change.nc"
    program.write_text("G21 G90\nG0 X5 Y5\nG1 Z-3 F100\nM6 T2\nG1 Z-3.5\nG0 Z0\nM30\n")
    asked: list[str] = []

    def on_prompt(prompt):
        asked.append(prompt.note)
        return "probe-tool" if len(asked) == 1 else "continue"

    with StateHold(tmp_path / "state.json", s, "test") as hold:
        port = MockPort()
        session = MachineSession(port, s, state=hold, on_prompt=on_prompt)
        session.go_to((20, 15, 0), "mm")
        assert session.wait_idle(120)
        first = session.probe_work_z(0.0, max_depth_steps=300)
        session.zero("XY")
        zero = hold.state.work_zero_steps()
        session.go_to((0, 0, 0), "mm")  # to the surface at the work zero: the program starts there
        assert session.wait_idle(120)
        probe = pause_probe._OnJobPort.probe

        def stopped_probe(self, depth_steps, feed_mm_min):
            session.stop()  # the Stop button, as the probe is about to go down
            return probe(self, depth_steps, feed_mm_min)

        monkeypatch.setattr(pause_probe._OnJobPort, "probe", stopped_probe)
        session.start(cam.prepare_job(str(program), cam.JobOptions(), s, name="deep-change.nc",
                                      machine_state=hold.state))
        assert session.wait_idle(120)
        info = session.last_run
        assert info["status"] == "stopped", info
        over_plate = int(first.contact_steps[2]) - round(5.0 / per)
        lift = round(3.0 / per)
        assert over_plate - lift < TOP_STEPS <= over_plate  # the job's whole lift would leave the travel
        said = [m for m in info["messages"] if "top of the Z travel" in m]
        assert len(said) == 1 and "\n" not in said[0], info["messages"]
        assert session.position_steps()[2] == TOP_STEPS
        assert hold.state.work_zero_steps() == zero  # the probe never touched: the work Z kept
        assert asked == [asked[0]] and asked[0].startswith("tool change: T2")  # not asked again after the stop
    pos = decode_pin_log(port.pin_log(), s).position_steps
    assert int(pos[:, 2].min()) == TOP_STEPS  # up to the travel's top, never beyond it
    assert tuple(int(v) for v in pos[-1]) == session.position_steps()


def test_cam_drill_ctrl_c_as_the_travel_to_the_work_zero_ends_does_not_start_the_job(tmp_path, monkeypatch):
    """``cam drill`` travels to the work zero in a session of its own, then starts the job in another: a Ctrl-C
    that comes as the travel's end is booked (raised there, before the job's session has anything to stop) is not
    lost: the job is not started, and the command says so in one line; the pin log holds the travel alone."""
    from cam.cli import execute
    from cam.drive.state import read_state
    from cam.verify.pinlog import read_pin_log
    from conftest import run_cli
    from test_probe import machine_file
    from test_tool_change_probe import TWO_TOOLS

    machine, state, drl, log = (machine_file(tmp_path, FLAT), tmp_path / "state.json", tmp_path / "two.drl",
                                tmp_path / "job.csv")
    drl.write_text(TWO_TOOLS)
    assert run_cli("zero", "--at", "20,15,0", "--machine", machine, "--state", state).returncode == 0
    approach = execute._approach

    def interrupted(*args, **kwargs):
        first = approach(*args, **kwargs)
        signal.raise_signal(signal.SIGINT)  # Ctrl-C: the handler runs here, the job not started yet
        return first

    monkeypatch.setattr(execute, "_approach", interrupted)
    proc = run_cli("drill", drl, "--machine", machine, "--state", state, "--pin-log", log, stdin="\n\n\n")
    said = [line for line in proc.stderr.splitlines() if "the job was not started" in line]
    assert len(said) == 1, proc.stderr
    s = cam.load_settings(machine)
    after = read_state(state, s)
    assert after.position_known and after.running is None
    pos = decode_pin_log(read_pin_log(log), s).position_steps
    assert tuple(int(v) for v in pos[-1]) == after.position_steps
    assert int(pos[:, 2].max()) <= 0  # nothing went down into the work: no hole was drilled


def test_a_shorter_tool_whose_shift_would_take_the_job_below_the_travel_is_not_shifted(tmp_path):
    """A drill job whose holes go 20 steps short of the bottom of the Z travel; T2 is 0.7 mm shorter (45 steps):
    probed at its tool change, the shift would take T2's holes 25 steps below the travel, while where the job waits
    (at its travel height) would still be inside it.  The work Z is not shifted (one line at the prompt, saying
    why), the tool is back where the job waits; stopped there, nothing in the decoded pin log leaves the travel."""
    from test_tool_change_probe import SHORTER_MM, _wait_prompt
    from test_probe import _raised
    from cam.drive.ports import SwitchSchedule

    s = mock_settings(FLAT)
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        port = MockPort()
        session = MachineSession(port, s, state=hold)
        session.go_to((30, 30, 0), "mm")
        assert session.wait_idle(120)
        session.probe_work_z(0.0, max_depth_steps=300)
        session.go_to((20, 15, -1), "mm")
        assert session.wait_idle(120)
        session.zero("XY")
        zero = hold.state.work_zero_steps()
        job = _two_tool_job(tmp_path, s, hold.state)
        bottom = zero[2] + int(job.plan.motion_extent()[0][2][1]) + 20  # the Z travel's bottom: 20 below the holes
        s = s.replace(travel=replace(s.travel, z_max_steps=bottom))
        session.settings = s
        session.start(_two_tool_job(tmp_path, s, hold.state))
        p = _wait_prompt(session)
        session.answer(p["id"], "continue")
        p = _wait_prompt(session, p["id"])
        port.switches = SwitchSchedule(mock_settings(_raised(FLAT, -SHORTER_MM)), tuple(p["position_steps"]))
        session.probe_tool_at_prompt(p["id"], clearance_mm=1.0)  # its deepest probe inside the travel
        again = _wait_prompt(session, p["id"])
        assert again["probed"].startswith("the new tool was not probed: the work Z was not shifted: the job's moves")
        assert "beyond the Z travel" in again["probed"] and "\n" not in again["probed"], again
        assert again["position_steps"] == p["position_steps"]  # back where it waits, not shifted
        assert hold.state.work_zero_steps() == zero  # the work Z kept
        session.answer(again["id"], "stop")
        assert session.wait_idle(60) and session.last_run["status"] == "stopped", session.last_run
    pos = decode_pin_log(port.pin_log(), s).position_steps
    assert int(pos[:, 2].max()) <= bottom  # never below the travel
    assert tuple(int(v) for v in pos[-1]) == session.position_steps()
