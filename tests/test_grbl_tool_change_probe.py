"""The tool-change prompt of a job on grbl offers probing the new tool (issue #46 point 1: "the tool-change prompt of
a drill or G-code job offers ``cam probe tool``"), as on a step/dir machine (tests/test_tool_change_probe.py).

The job waits at the tool change with grbl idle and its planner empty; the new tool is probed there with ``G38.2``
on the plate where the tool that set the work Z touched (cam.drive.grbl_pause_probe), grbl's own work Z set
(``G10 L2``), and the job's lines after it (in machine coordinates, ``G53``) shifted by the difference of the
contacts.  The tool's length is simulated on the grbl emulator (cam.sim.grbl) as the mock's tests do it: a tool L mm
longer touches the plate with the carriage L mm higher, as if the surface were L mm higher (its ``probe_surface``
raised by L while the job waits).  The oracle is what the emulator executed: each hole's bottom, the new tool's tip
there (the carriage less its extra length) at the asked depth below the surface within one Z step.  The job's
journal books the shift, so a job stopped at the prompt after the probe resumes at the new tool's Z."""
from __future__ import annotations

import pytest

import cam
from cam.drive.grbl_machine import mpos_to_steps
from cam.drive.journal import read_journal
from cam.drive.session import MachineSession
from cam.drive.state import StateHold
from cam.errors import PlanError
from cam.kinds.jobs import resume_job
from cam.sim.grbl import start_emulator
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)

from test_probe import FAST, LONGER_MM
from test_tool_change_probe import DEPTH_MM, TWO_TOOLS, _hole_xy_steps, _wait_prompt

S = cam.MachineSettings()
SURFACE_MM = -0.8
"""A flat plate and work, in grbl's machine frame (up positive): machine Z +51 steps (0.8 mm down) from grbl's
zero."""


@pytest.fixture
def grbl():
    emu = start_emulator(speed=50.0, settings=FAST, probe_surface=(SURFACE_MM, 0, 0, 0, 0, 0))
    yield emu
    emu.stop()
    assert emu.error is None


def _raise_plate(emu, by_mm: float) -> None:
    """The next tool is ``by_mm`` longer: it touches the plate that much higher (the emulator's surface raised)."""
    with emu._lock:
        emu._probe_surface = (SURFACE_MM + by_mm, 0.0, 0.0, 0.0, 0.0, 0.0)


def _set_up(emu, tmp_path, hold: StateHold, *, probe: bool = True) -> tuple[MachineSession, tuple]:
    """The session on the emulator: the first tool probed on the plate at X30 Y30 mm (``probe``), the work zero's
    X, Y at X20 Y15 mm; returns the session and the work zero (machine steps)."""
    session = MachineSession(f"grbl:{emu.device_path}", S, state=hold)
    if not hold.state.position_known:
        session.set_position((0, 0, 0))
    session.go_to((30, 30, 0), "mm")
    assert session.wait_idle(60)
    if probe:
        session.probe_work_z(0.0, 60.0, 200)
        assert session.last_run["status"] == "finished", session.last_run
    session.go_to((20, 15, -2), "mm")
    assert session.wait_idle(60)
    session.zero("XY")
    return session, hold.state.work_zero_steps()


def _job(tmp_path, hold: StateHold):
    path = tmp_path / "two.drl"
    path.write_text(TWO_TOOLS)
    return cam.prepare_job(str(path), cam.JobOptions(cut_depth_mm=DEPTH_MM), S, name="two.drl",
                           machine_state=hold.state)


def _bottoms(emu, xy_steps, after_line: int = 0) -> list[int]:
    """The deepest machine Z (steps, +Z deeper) the emulator's executed G1 blocks reach over each hole's X, Y (only
    blocks of lines after ``after_line``); grbl's machine frame is cam's here (the base 0)."""
    out = []
    for x, y in xy_steps:
        ends = [mpos_to_steps(b.end_mm, S) for b in emu.executed() if b.kind == "G1" and b.line > after_line]
        zs = [z for ex, ey, z in ends if (ex, ey) == (x, y)]
        assert zs, (x, y)
        out.append(max(zs))
    return out


def test_grbl_tool_change_prompt_offers_probe_tool(grbl, tmp_path):
    """A drill job of two tools on grbl: tool 1 set the work Z (probe Z on the plate), tool 2 is 1.2 mm longer; at
    T2's prompt the probe is offered, the new tool probed with G38.2 while the job waits, grbl's G54 Z moved
    (G10 L2), the prompt asks again, and the job goes on: T1's holes at the asked depth for tool 1, T2's shifted up
    by the tool's extra length, within a step; the journal's home moved with the work Z."""
    per = S.mm_per_step_z
    journal_path = tmp_path / "two.journal.json"
    with StateHold(tmp_path / "state.json", S, "test", port=f"grbl:{grbl.device_path}") as hold:
        session, zero1 = _set_up(grbl, tmp_path, hold)
        first = hold.state.tool_probe
        assert first is not None
        session.start(_job(tmp_path, hold), journal=str(journal_path))
        p = _wait_prompt(session)
        assert "T1" in p["note"] and p["probe_tool"] and p["probe_tool_why_not"] == "", p
        session.answer(p["id"], "continue")
        p = _wait_prompt(session, p["id"])
        assert "T2" in p["note"] and p["probe_tool"], p
        assert grbl.state == "Idle" and grbl.planner_blocks == 0  # grbl waits idle, its planner empty
        lines_before = len(grbl.lines())
        _raise_plate(grbl, LONGER_MM)
        session.probe_tool_at_prompt(p["id"])
        again = _wait_prompt(session, p["id"])
        assert again["note"] == p["note"] and again["probe_tool"]
        zero2 = hold.state.work_zero_steps()
        shift = zero2[2] - zero1[2]
        assert zero2[:2] == zero1[:2] and abs(-shift * per - LONGER_MM) <= per + 1e-9
        assert again["probed"].startswith(f"the new tool probed: G54 Z zero moved {-shift * per:+.4g} mm up, to "
                                          f"machine Z {zero2[2]} steps"), again
        assert again["position_steps"][2] == p["position_steps"][2] + shift  # back where it waits, shifted
        assert session.position_steps() == tuple(again["position_steps"])
        sent = [text for _, text, _ in grbl.lines()[lines_before:]]
        assert sum("G38.2" in t for t in sent) == 1, sent
        assert f"G10L2P1Z{cam.kinds.gcode_export.format_mm(-zero2[2] * per)}" in sent, sent  # grbl's own G54
        session.answer(again["id"], "continue")
        assert session.wait_idle(60) and session.last_run["status"] == "finished", session.last_run
        assert hold.state.tool_probe.contact_steps[:2] == first.contact_steps[:2]
        assert session.position_steps() == mpos_to_steps(grbl.machine_position_mm, S)  # booked as grbl has it
        journal = read_journal(journal_path)
        assert journal.state == "finished" and journal.home_steps[2] - zero1[2] == shift  # moved with the work Z
    depth = round(DEPTH_MM / per)
    bottoms = _bottoms(grbl, _hole_xy_steps(S, zero1))
    assert bottoms == [zero1[2] + depth] * 2 + [zero2[2] + depth] * 2, (bottoms, zero1, zero2)
    for k, z in enumerate(bottoms):  # each tool's tip at the asked depth below the surface, within a step
        tip_mm = -z * per - (LONGER_MM if k >= 2 else 0.0)
        assert abs(tip_mm - (SURFACE_MM - DEPTH_MM)) <= per + 1e-9, (k, tip_mm)
    # every plunge at the job's feed, those after the probe too (its G38.2 F20 changed grbl's modal feed)
    probe_line = max(n for n, text, _ in grbl.lines() if "G38.2" in text)
    plunges = [b for b in grbl.executed() if b.kind == "G1" and b.end_mm[2] < b.start_mm[2]]
    before = {b.feed_mm_min for b in plunges if b.line < probe_line}
    assert len(before) == 1 and before != {20.0}
    assert {b.feed_mm_min for b in plunges if b.line > probe_line} == before


def test_grbl_tool_change_prompt_without_a_first_probe_says_why_in_one_line(grbl, tmp_path):
    """No tool set the work Z by probing: the prompt says why it does not offer the probe, ``probe-tool`` is refused
    in one line, the prompt still waits, and nothing was sent to grbl for it."""
    with StateHold(tmp_path / "state.json", S, "test", port=f"grbl:{grbl.device_path}") as hold:
        session, _ = _set_up(grbl, tmp_path, hold, probe=False)
        session.start(_job(tmp_path, hold))
        p = _wait_prompt(session)
        assert not p["probe_tool"] and p["probe_tool_why_not"].startswith("no tool has set the work Z by probing")
        lines_before = len(grbl.lines())
        with pytest.raises(PlanError) as err:
            session.probe_tool_at_prompt(p["id"])
        assert "\n" not in str(err.value) and "cam probe z" in str(err.value)
        assert session.state()["prompt"]["id"] == p["id"]  # still waiting
        assert not any("G38" in t for _, t, _ in grbl.lines()[lines_before:])
        session.answer(p["id"], "stop")
        assert session.wait_idle(60) and session.last_run["status"] == "stopped", session.last_run


def test_a_grbl_job_stopped_after_the_tool_probe_resumes_at_the_new_tool_z(grbl, tmp_path):
    """T2 (1.2 mm longer) probed at its tool change, then the job stopped at the prompt that asks again; resumed from
    its journal where the tool stands (the page's Resume job, cam drill --resume): T2's holes at the new work Z,
    not at tool 1's."""
    per = S.mm_per_step_z
    path = tmp_path / "two.journal.json"
    with StateHold(tmp_path / "state.json", S, "test", port=f"grbl:{grbl.device_path}") as hold:
        session, zero1 = _set_up(grbl, tmp_path, hold)
        job = _job(tmp_path, hold)
        session.start(job, journal=str(path))
        p = _wait_prompt(session)
        session.answer(p["id"], "continue")
        p = _wait_prompt(session, p["id"])
        _raise_plate(grbl, LONGER_MM)
        session.probe_tool_at_prompt(p["id"])
        p = _wait_prompt(session, p["id"])
        assert p["probed"].startswith("the new tool probed"), p
        session.answer(p["id"], "stop")
        assert session.wait_idle(60) and session.last_run["status"] == "stopped", session.last_run
        zero2 = hold.state.work_zero_steps()
        shift = zero2[2] - zero1[2]
        assert abs(-shift * per - LONGER_MM) <= per + 1e-9
        journal = read_journal(path)
        assert journal.state == "stopped" and journal.home_steps[2] - zero1[2] == shift  # moved with the work Z
        first_run = max(n for n, _, _ in grbl.lines())
        where = tuple(int(v) - int(h) for v, h in zip(session.position_steps(), journal.home_steps))
        session.start(resume_job(job, journal, position_steps=where, where=path.name), journal=str(path))
        answered = p["id"]
        while True:  # the resumed run asks again at T2's change: go on
            state = session.state()
            if state["prompt"] is not None and state["prompt"]["id"] > answered:
                answered = state["prompt"]["id"]
                session.answer(answered, "continue")
            elif not session.busy:
                break
            session.wait_change(state["version"], 0.2)
        assert session.last_run["status"] == "finished", session.last_run
    depth = round(DEPTH_MM / per)
    holes = _hole_xy_steps(S, zero1)
    assert _bottoms(grbl, holes[:2]) == [zero1[2] + depth] * 2
    assert _bottoms(grbl, holes[2:], after_line=first_run) == [zero2[2] + depth] * 2  # the resumed run's
    for x, y in holes[2:]:  # T2's holes drilled by the resumed run only
        assert not [b for b in grbl.executed() if b.line <= first_run and b.kind == "G1"
                    and mpos_to_steps(b.end_mm, S)[:2] == (x, y)]
