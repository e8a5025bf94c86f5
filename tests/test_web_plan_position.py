"""A plan is valid only for where it was made (issue #43 point 6).

A G-code program runs from where the tool stands, in the machine state's work offsets, as a G-code sender runs it:
``cam drill`` plans it there.  The page plans a job when asked and starts it later; a jog (or a new work zero) in
between used to run the old plan shifted by the jog.  Now the job records the state it was planned in, the session
refuses it from anywhere else in one line, and the page plans it again from where the tool stands when it starts:
the page's motion is the command line's, checked on both decoded pin logs.
"""
from __future__ import annotations

import numpy as np
import pytest

import cam
from cam.drive.session import MachineSession
from cam.drive.state import MachineState, read_state, write_state
from cam.errors import StalePlanError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import ROOT, run_cli
from test_web import Server

BOLT = ROOT / "samples" / "bolt_plate.ngc"
SETTINGS = cam.MachineSettings()  # the command line's machine: no machine file


def _cli_motion(state: MachineState, tmp_path, name: str) -> tuple[np.ndarray, tuple[int, int, int]]:
    """The command line's run of the bolt plate from ``state`` (a state file of its own): the positions after each
    write (machine frame) and where the state file says it ended."""
    state_file, pins = tmp_path / f"{name}.json", tmp_path / f"{name}.csv"
    write_state(state_file, state)
    r = run_cli("drill", BOLT, "--yes", "--state", state_file, "--pin-log", pins)
    assert r.returncode == 0, r.stderr
    motion = decode_pin_log(read_pin_log(pins), SETTINGS).position_steps + np.asarray(state.position_steps)
    return motion, read_state(state_file, SETTINGS).position_steps


def _page_run(s: Server, job_id: str) -> np.ndarray:
    """Start the planned job from the page, wait for its end; the positions after each write (machine frame)."""
    start = tuple(s.session.position_steps())
    status, st = s.call("POST", "/api/start", {"job": job_id})
    assert status == 200, st
    st = s.wait_idle(120)
    assert st["last"]["status"] == "finished" and st["last"]["activity"] == "job", st["last"]
    return decode_pin_log(s.session.last_job_pin_log, SETTINGS).position_steps + np.asarray(start)


def _jog(s: Server, axis: str, steps: int) -> None:
    status, st = s.call("POST", "/api/jog", {"axis": axis, "steps": steps, "unit": "steps"})
    assert status == 200, st
    st = s.wait_idle()
    assert st["last"]["status"] == "finished", st["last"]


def test_page_plan_jog_start_matches_cli(tmp_path):
    state_file = tmp_path / "page.json"
    s = Server(tmp_path, settings=SETTINGS, realtime=False, state_file=str(state_file))
    try:
        status, up = s.upload("bolt_plate.ngc", BOLT.read_bytes())
        assert status == 200, up
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        first = _page_run(s, planned["job"])
        end = tuple(int(v) for v in first[-1])
        assert s.session.where()["work_steps"] == [0, 0, -191] and end == (0, 0, -191)  # G54 X0 Y0, Z 3 mm up
        for axis, steps in (("x", 1000), ("z", 300)):
            _jog(s, axis, steps)  # the plan was made where the tool stood before this jog
            before = read_state(state_file, SETTINGS)
            page = _page_run(s, planned["job"])
            cli, cli_end = _cli_motion(before, tmp_path, f"cli-{axis}")
            assert tuple(int(v) for v in page[-1]) == cli_end == (0, 0, -191), (axis, page[-1], cli_end)
            assert page.shape == cli.shape and np.array_equal(page, cli), axis  # the same motion, write by write
            assert read_state(state_file, SETTINGS).position_steps == (0, 0, -191)
            assert page[:, 2].max() == cli[:, 2].max()  # never deeper than the program asks
        status, st = s.call("GET", "/api/state")
        assert any("planned again" in line["text"] for line in st["log"]), st["log"]
    finally:
        s.close()


def test_the_session_refuses_a_program_planned_elsewhere_in_one_line():
    """The library's own word, whatever the front end: a G-code program planned at one position is refused from
    another (nothing moves), and runs once planned again there."""
    job = prepare_job(BOLT, JobOptions(), SETTINGS, machine_state=MachineState(position_steps=(0, 0, 0)))
    session = MachineSession("mock", SETTINGS)
    try:
        session.set_position((1000, 0, 0))
        with pytest.raises(StalePlanError) as err:
            session.start(job)
        message = str(err.value)
        assert "\n" not in message and "[0, 0, 0]" in message and "[1000, 0, 0]" in message
        assert "plan" in message and not session.busy
        again = prepare_job(BOLT, JobOptions(), SETTINGS, machine_state=MachineState(position_steps=(1000, 0, 0)))
        session.start(again)
        session.wait_idle(None)
        assert session.last_run["status"] == "finished"
        assert session.position_steps() == (0, 0, -191)
    finally:
        session.shutdown()
