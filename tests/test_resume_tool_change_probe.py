"""A job resumed after a stop that came after a tool probed at its tool change goes on at the new tool's work Z.

The tool probed at a tool change (:meth:`MachineSession.probe_tool_at_prompt`) shifts the job's later moves on Z by
the difference of the two tools' contacts; the job's journal books that shift (its home moves by as much,
:meth:`cam.drive.journal.JournalWriter.home_moved`), so a resume from where the tool stands (the page's Resume job,
``cam drill --resume``) cuts the holes left at the asked depth for the new tool, not at the old tool's Z.  Checked on
the mock's pin log decoded back into motion (the checker of tests/test_tool_change_probe.py).
"""
from __future__ import annotations

from cam.drive import runner
from cam.drive.journal import read_journal
from cam.drive.ports import MockPort, SwitchSchedule
from cam.drive.session import MachineSession
from cam.drive.state import StateHold
from cam.kinds.jobs import resume_job
from cam.verify.pinlog import decode_pin_log

from test_probe import FLAT, LONGER_MM, _raised, mock_settings
from test_tool_change_probe import DEPTH_MM, _hole_bottoms, _hole_xy_steps, _two_tool_job, _wait_prompt

FIRST_T2_HOLE_DONE = 9
"""The drill job's point at which the first hole of T2 is drilled and the tool is back up (the lift, T1's two holes
of three points each, then T2's first hole: above, down, up)."""


def test_a_resume_after_a_tool_probed_at_the_tool_change_cuts_at_the_new_work_z(tmp_path, monkeypatch):
    """Two tools, T2 1.2 mm longer, probed at its tool change; the job is stopped after T2's first hole and resumed
    from where the tool stands: every hole, those of the resumed run too, at the asked depth for its tool."""
    monkeypatch.setattr(runner._SimulatedClock, "batch", 32)  # the stop lands within 32 writes of its request
    s = mock_settings(FLAT)
    per = s.mm_per_step_z
    path = tmp_path / "two.journal.json"
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        port = MockPort()
        session = MachineSession(port, s, state=hold)
        session.go_to((30, 30, 0), "mm")
        assert session.wait_idle(120)
        session.probe_work_z(0.0, max_depth_steps=300)
        session.go_to((20, 15, -2), "mm")
        assert session.wait_idle(120)
        session.zero("XY")
        zero1 = hold.state.work_zero_steps()
        job = _two_tool_job(tmp_path, s, hold.state)
        after_write = int(job.plan.full_point_write()[FIRST_T2_HOLE_DONE])
        stopped: list[int] = []

        def stop_after_the_first_t2_hole(done: int, total: int, machine_ns: int) -> None:
            if not stopped and session.state()["label"].startswith("job") and done > after_write:
                stopped.append(done)
                session.stop()

        session.on_progress = stop_after_the_first_t2_hole
        session.start(job, journal=str(path))
        p = _wait_prompt(session)
        assert "T1" in p["note"]
        session.answer(p["id"], "continue")
        p = _wait_prompt(session, p["id"])
        assert "T2" in p["note"] and p["probe_tool"]
        port.switches = SwitchSchedule(mock_settings(_raised(FLAT, LONGER_MM)), tuple(p["position_steps"]))
        session.probe_tool_at_prompt(p["id"])
        again = _wait_prompt(session, p["id"])
        assert again["probed"].startswith("the new tool probed"), again
        session.answer(again["id"], "continue")
        assert session.wait_idle(60) and session.last_run["status"] == "stopped", session.last_run
        assert stopped and hold.state.position_known
        zero2 = hold.state.work_zero_steps()
        shift = zero2[2] - zero1[2]
        assert abs(-shift * per - LONGER_MM) <= per + 1e-9
        journal = read_journal(path)
        # stopped before T2's second hole's bottom (its point FIRST_T2_HOLE_DONE + 2): the resumed run drills it
        assert journal.state == "stopped" and FIRST_T2_HOLE_DONE <= journal.last_move < FIRST_T2_HOLE_DONE + 2
        assert journal.home_steps[2] - zero1[2] == shift  # the job's home moved with the work Z
        # the page's Resume job: from where the tool stands, the same library call as cam drill --resume
        where = tuple(int(v) - int(h) for v, h in zip(session.position_steps(), journal.home_steps))
        resumed = resume_job(job, journal, position_steps=where, where=path.name)
        session.start(resumed, journal=str(path))
        assert session.wait_idle(60) and session.last_run["status"] == "finished", session.last_run
    pos = decode_pin_log(port.pin_log(), s).position_steps
    assert tuple(int(v) for v in pos[-1]) == session.position_steps()
    depth = round(DEPTH_MM / per)
    bottoms = _hole_bottoms(pos, _hole_xy_steps(s, zero1))
    assert bottoms == [zero1[2] + depth] * 2 + [zero2[2] + depth] * 2, (bottoms, zero1, zero2)
    for k, z in enumerate(bottoms):  # each tool's tip at the asked depth below the surface, within a step
        tip_mm = -z * per - (LONGER_MM if k >= 2 else 0.0)
        assert abs(tip_mm - (FLAT[0] - DEPTH_MM)) <= per + 1e-9, (k, tip_mm)
