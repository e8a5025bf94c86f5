"""The tool-change prompt offers probing the new tool (issue #46 point 1: "the tool-change prompt of a drill or G-code
job offers ``cam probe tool``").

While a drill job waits at a tool change, the new tool is probed on the plate where the tool that set the work Z
touched (:meth:`MachineSession.probe_tool_at_prompt`; the command line's answer ``p``; the page's Probe tool in the
tool-change dialog), the work Z shifts by the difference of the contacts and the job goes on from there: the holes
after the change are at the asked depth for the new tool.  The tool's length is simulated on the mock as the
probe tool tests do it: a tool L mm longer touches the surface with the carriage L mm higher, as if the surface were
L mm higher (``[mock] probe_surface`` raised by L).  The pin log decoded back into motion shows every hole's
bottom; the new tool's tip there (the carriage less its extra length) is at the asked depth below the surface within
one Z step.  Where it is not offered (no first probe, a machine that cannot probe) the prompt says why and the
answer is refused in one line."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.drive.ports import MockPort, SwitchSchedule
from cam.drive.session import MachineSession
from cam.drive.state import StateHold, read_state
from cam.errors import CapabilityError, PlanError
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import ok, run_cli

from test_probe import FLAT, LONGER_MM, _raised, machine_file, mock_settings

TWO_TOOLS = """M48
METRIC,LZ
T1C0.8
T2C1.0
%
T1
X5.0Y5.0
X12.0Y5.0
T2
X12.0Y12.0
X5.0Y9.0
M30
"""
"""Two holes of each tool; the board's upper-left corner (X5 Y12) goes to the work zero."""

DEPTH_MM = 1.5


def _holes_mm(settings) -> list[tuple[float, float]]:
    return [(5.0, 5.0), (12.0, 5.0), (12.0, 12.0), (5.0, 9.0)]


def _hole_bottoms(pos: np.ndarray, xy_steps: list[tuple[int, int]]) -> list[int]:
    """The deepest machine Z the decoded pin log reaches over each hole's X, Y."""
    out = []
    for x, y in xy_steps:
        at = np.flatnonzero((pos[:, 0] == x) & (pos[:, 1] == y))
        assert len(at), (x, y)
        out.append(int(pos[at, 2].max()))
    return out


def _hole_xy_steps(settings, zero_steps) -> list[tuple[int, int]]:
    """Each hole's machine X, Y in steps: the board's upper-left (X5, Y12) at the work zero, +Y toward the
    operator (board Y up is machine Y down)."""
    per = settings.mm_per_step_xy
    return [(int(zero_steps[0]) + round((x - 5.0) / per), int(zero_steps[1]) + round((12.0 - y) / per))
            for x, y in _holes_mm(settings)]


def test_tool_change_prompt_offers_probe_tool(tmp_path):
    """``cam drill`` with two tools on the mock: tool 1 set the work Z (``cam probe z`` on the plate), tool 2 is
    1.2 mm longer; at T2's prompt ``p`` probes it, prints the new work Z and asks again; Enter goes on.  The pin
    log: T1's holes at the asked depth for tool 1, T2's shifted up by the tool's extra length (within a step)."""
    machine, state, log, drl = (machine_file(tmp_path, FLAT), tmp_path / "state.json", tmp_path / "job.csv",
                                tmp_path / "two.drl")
    drl.write_text(TWO_TOOLS)
    ok(run_cli("probe", "z", "--machine", machine, "--state", state, "--depth", "3"))  # the plate at X0 Y0
    ok(run_cli("zero", "XY", "--at", "20,15,0", "--machine", machine, "--state", state))
    s = cam.load_settings(machine)
    per = s.mm_per_step_z
    first = read_state(state, s)
    zero1 = first.work_zero_steps()
    machine_file(tmp_path, _raised(FLAT, LONGER_MM))  # the longer tool 2 touches the plate that much higher
    proc = ok(run_cli("drill", drl, "--machine", machine, "--state", state, "--cut-depth", str(DEPTH_MM),
                      "--pin-log", log, "--machine-changed", stdin="\np\n\n"))
    err = proc.stderr
    assert err.count("or p and Enter to probe the new tool (cam probe tool)") == 2, err  # offered at both changes
    assert "or p and Enter to probe the new tool again" in err  # asked again after the probe
    after = read_state(state, s)
    zero2 = after.work_zero_steps()
    shift = zero2[2] - zero1[2]
    assert zero2[:2] == zero1[:2] and abs(-shift * per - LONGER_MM) <= per + 1e-9
    assert f"G54 Z zero moved {-shift * per:+.4g} mm up, to machine Z {zero2[2]} steps" in err  # the new work Z
    assert after.tool_probe is not None and after.tool_probe.contact_steps[:2] == first.tool_probe.contact_steps[:2]
    assert after.position_known and after.running is None
    # the pin log decoded: the probe's excursion in it, T1's holes for tool 1, T2's for the longer tool 2
    pos = decode_pin_log(read_pin_log(log), s).position_steps + np.asarray(first.position_steps, np.int64)
    assert tuple(int(v) for v in pos[-1]) == after.position_steps
    depth = round(DEPTH_MM / per)
    bottoms = _hole_bottoms(pos, _hole_xy_steps(s, zero1))
    assert bottoms[:2] == [zero1[2] + depth] * 2  # tool 1: at the work Z the first probe set
    assert bottoms[2:] == [zero2[2] + depth] * 2  # tool 2: at the new work Z
    for k, z in enumerate(bottoms):  # each tool's tip at the asked depth below the surface, within a step
        tip_mm = -z * per - (LONGER_MM if k >= 2 else 0.0)
        assert abs(tip_mm - (FLAT[0] - DEPTH_MM)) <= per + 1e-9, (k, tip_mm)
    # the probe went down on the plate where tool 1 touched, lifted (nothing below the travel height across)
    px, py, _ = first.tool_probe.contact_steps
    left = int(np.argmax(np.any(pos[:, :2] != (px, py), axis=1)))  # the command starts over the plate: not that
    on_plate = np.flatnonzero((pos[:, 0] == px) & (pos[:, 1] == py))
    on_plate = on_plate[on_plate > left]
    assert len(on_plate) and int(pos[on_plate, 2].max()) == after.tool_probe.contact_steps[2]
    arrive, leave = on_plate[0], on_plate[-1]  # across to the plate and back at the lift over it, never lower
    assert pos[arrive, 2] == pos[leave, 2] <= first.tool_probe.contact_steps[2] - round(5.0 / per)


def test_cli_tool_change_prompt_says_why_probing_is_not_offered(tmp_path):
    """No first probe: the prompt says why; ``p`` is refused in one line and the prompt asks again."""
    machine, state, drl = machine_file(tmp_path, FLAT), tmp_path / "state.json", tmp_path / "two.drl"
    drl.write_text(TWO_TOOLS)
    ok(run_cli("zero", "--at", "20,15,0", "--machine", machine, "--state", state))
    proc = ok(run_cli("drill", drl, "--machine", machine, "--state", state, stdin="p\n\n\n"))
    err = proc.stderr
    assert "(probing the new tool is not offered: no tool has set the work Z by probing" in err
    refusals = [line for line in err.splitlines() if line.startswith("cam: probing the new tool is not offered")]
    assert len(refusals) == 1 and "cam probe z" in refusals[0]
    assert "job two.drl" not in err or "stopping" not in err
    assert read_state(state, cam.load_settings(machine)).work_zero_steps()[2] == 0  # nothing shifted


# -- the library: the session's prompt and answer --------------------------------------------------------------

SHORTER_MM = 0.7


def _two_tool_job(tmp_path, settings, state):
    path = tmp_path / "two.drl"
    path.write_text(TWO_TOOLS)
    return cam.prepare_job(str(path), cam.JobOptions(cut_depth_mm=DEPTH_MM), settings, name="two.drl",
                           machine_state=state)


def _wait_prompt(session, after_id: int = 0, timeout_s: float = 60.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        p = session.state()["prompt"]
        if p is not None and p["id"] > after_id:
            return p
        assert session.busy, session.last_run
        session.wait_change(session.version, 0.2)
    raise AssertionError("no prompt came")


def test_session_probes_a_shorter_tool_at_the_tool_change_and_the_job_goes_on_at_the_new_work_z(tmp_path):
    """The page's way (no on_prompt): the prompt offers it, ``probe_tool_at_prompt`` probes a 0.7 mm shorter tool
    while the job waits, the prompt comes back saying so, the work Z moved down, and the holes after it are
    deeper by the shorter length (the new tool's tip at the asked depth)."""
    s = mock_settings(FLAT)
    per = s.mm_per_step_z
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        port = MockPort()
        session = MachineSession(port, s, state=hold)
        session.go_to((30, 30, 0), "mm")
        assert session.wait_idle(30)
        first = session.probe_work_z(0.0, max_depth_steps=300)
        session.go_to((20, 15, -2), "mm")
        assert session.wait_idle(30)
        session.zero("XY")
        zero1 = hold.state.work_zero_steps()
        session.start(_two_tool_job(tmp_path, s, hold.state))
        p = _wait_prompt(session)
        assert "T1" in p["note"] and p["probe_tool"] and p["probe_tool_why_not"] == "" and p["probed"] == ""
        session.answer(p["id"], "continue")
        p = _wait_prompt(session, p["id"])
        assert "T2" in p["note"] and p["probe_tool"]
        # the shorter tool 2: on the mock its tip reaches the plate only 0.7 mm lower
        port.switches = SwitchSchedule(mock_settings(_raised(FLAT, -SHORTER_MM)), tuple(p["position_steps"]))
        with pytest.raises(PlanError, match="plate"):
            session.probe_tool_at_prompt(p["id"], plate_mm=-1)
        session.probe_tool_at_prompt(p["id"])
        again = _wait_prompt(session, p["id"])
        assert again["note"] == p["note"] and again["probe_tool"]
        assert again["probed"].startswith("the new tool probed: G54 Z zero moved -")
        zero2 = hold.state.work_zero_steps()
        shift = zero2[2] - zero1[2]
        assert abs(shift * per - SHORTER_MM) <= per + 1e-9
        assert again["position_steps"][2] == p["position_steps"][2] + shift  # back where it waits, shifted
        assert hold.state.running is not None  # the job still runs: its marker kept in the file
        session.answer(again["id"], "continue")
        assert session.wait_idle(60) and session.last_run["status"] == "finished", session.last_run
        assert hold.state.tool_probe.contact_steps[:2] == first.contact_steps[:2]
    # the mock's log holds every write of the session (the state file's new machine: from 0, 0, 0)
    pos = decode_pin_log(port.pin_log(), s).position_steps
    assert tuple(int(v) for v in pos[-1]) == session.position_steps()
    depth = round(DEPTH_MM / per)
    bottoms = _hole_bottoms(pos, _hole_xy_steps(s, zero1))
    assert bottoms == [zero1[2] + depth] * 2 + [zero2[2] + depth] * 2
    for k, z in enumerate(bottoms):
        tip_mm = -z * per + (SHORTER_MM if k >= 2 else 0.0)  # a shorter tool's tip is above the carriage's mark
        assert abs(tip_mm - (FLAT[0] - DEPTH_MM)) <= per + 1e-9, (k, tip_mm)


def test_a_g_code_programs_m6_offers_probe_tool_and_cuts_at_the_new_work_z(tmp_path):
    """A G-code program's tool change (M6) offers it too: a 1.2 mm longer tool probed there, the program's second
    cut (the same G1 Z-0.5 at the same X, Y) is 1.2 mm higher within a step: the new tool's tip at the same depth."""
    program = tmp_path / "two-tools.nc"
    program.write_text("G21 G90\nG0 Z1\nG0 X5 Y5\nG1 Z-0.5 F100\nG0 Z1\nM6 T2\nG1 Z-0.5\nG0 Z1\nM30\n")
    s = mock_settings(FLAT)
    per = s.mm_per_step_z
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        port = MockPort()
        session = MachineSession(port, s, state=hold)
        session.go_to((20, 15, 0), "mm")
        assert session.wait_idle(30)
        session.probe_work_z(0.0, max_depth_steps=300)
        session.zero("XY")
        zero1 = hold.state.work_zero_steps()
        session.start(cam.prepare_job(str(program), cam.JobOptions(), s, name="two-tools.nc",
                                      machine_state=hold.state))
        p = _wait_prompt(session)
        assert p["note"].startswith("tool change: T2") and p["probe_tool"], p
        port.switches = SwitchSchedule(mock_settings(_raised(FLAT, LONGER_MM)), tuple(p["position_steps"]))
        session.probe_tool_at_prompt(p["id"])
        again = _wait_prompt(session, p["id"])
        session.answer(again["id"], "continue")
        assert session.wait_idle(60) and session.last_run["status"] == "finished", session.last_run
        zero2 = hold.state.work_zero_steps()
    assert abs((zero1[2] - zero2[2]) * per - LONGER_MM) <= per + 1e-9
    pos = decode_pin_log(port.pin_log(), s).position_steps
    x, y = zero1[0] + round(5 / s.mm_per_step_xy), zero1[1] - round(5 / s.mm_per_step_xy)  # G-code +Y: machine -Y
    at = np.flatnonzero((pos[:, 0] == x) & (pos[:, 1] == y))
    runs = np.split(at, np.flatnonzero(np.diff(at) > 1) + 1)  # over the cut before the change, and after it
    assert len(runs) == 2
    depth = round(0.5 / per)
    assert [int(pos[r, 2].max()) for r in runs] == [zero1[2] + depth, zero2[2] + depth]


@pytest.mark.realtime
def test_a_real_time_job_probes_the_new_tool_in_its_runner_process(tmp_path):
    """In real time the job runs in the runner process (cam.drive.apart), which holds the port: the probe runs
    there, asked over its socket; the pin log keeps one time line and the holes of the same tool stay at one
    depth."""
    s = PAGE_SETTINGS
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        session = MachineSession("mock", s, realtime=True, state=hold)
        session.go_to((20, 15, 0), "mm")
        assert session.wait_idle(30)
        session.probe_work_z(0.0, max_depth_steps=300)
        session.zero("XY")
        zero = hold.state.work_zero_steps()
        session.start(_two_tool_job(tmp_path, s, hold.state))
        p = _wait_prompt(session)
        session.probe_tool_at_prompt(p["id"])
        again = _wait_prompt(session, p["id"])
        assert again["probed"].startswith("the new tool probed"), again
        session.answer(again["id"], "continue")
        p = _wait_prompt(session, again["id"])
        session.answer(p["id"], "continue")
        assert session.wait_idle(60) and session.last_run["status"] == "finished", session.last_run
        assert abs(hold.state.work_zero_steps()[2] - zero[2]) <= 1
        log = session.last_pin_log
        assert np.all(np.diff(log.t_ns) >= 0)
        pos = decode_pin_log(log, s).position_steps + np.asarray(log.parts[0].start_steps, np.int64)
        assert tuple(int(v) for v in pos[-1]) == session.position_steps()
        depth = round(DEPTH_MM / s.mm_per_step_z)
        assert _hole_bottoms(pos, _hole_xy_steps(s, zero)) == [hold.state.work_zero_steps()[2] + depth] * 4


@pytest.mark.realtime
def test_the_e_stop_is_served_while_the_new_tool_is_probed(tmp_path):
    """The new tool's probe at a tool change takes seconds in real time (5 mm at the probe feed): the e-stop ends
    it and the job at once; the position is unknown after it and the work Z is not touched."""
    s = PAGE_SETTINGS
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        session = MachineSession("mock", s, realtime=True, state=hold)
        session.probe_work_z(0.0, max_depth_steps=300)
        zero = hold.state.work_zero_steps()
        session.start(_two_tool_job(tmp_path, s, hold.state))
        p = _wait_prompt(session)
        session.probe_tool_at_prompt(p["id"])
        deadline = time.monotonic() + 30
        while session.state()["detail"] != "probing the new tool":
            assert time.monotonic() < deadline and session.busy
            session.wait_change(session.version, 0.2)
        session.emergency_stop()
        assert session.wait_idle(10)
        assert session.last_run["status"] == "emergency-stopped", session.last_run
        assert not hold.state.position_known and hold.state.work_zero_steps() == zero


def test_session_refuses_probe_tool_where_it_is_not_offered(tmp_path):
    """Without a first probe the prompt says why and the answer is a one-line PlanError; on a machine that cannot
    probe (cmd:mock) the prompt says so and the answer is a CapabilityError; "continue" still goes on."""
    s = mock_settings(FLAT)
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        session = MachineSession(MockPort(), s, state=hold)
        session.start(_two_tool_job(tmp_path, s, hold.state))
        p = _wait_prompt(session)
        assert not p["probe_tool"] and "no tool has set the work Z by probing" in p["probe_tool_why_not"]
        with pytest.raises(PlanError, match="cam probe z") as e:
            session.probe_tool_at_prompt(p["id"])
        assert "\n" not in str(e.value)
        with pytest.raises(PlanError, match="probe-tool"):
            session.answer(p["id"], "probe")
        session.answer(p["id"], "continue")
        p = _wait_prompt(session, p["id"])
        session.answer(p["id"], "continue")
        assert session.wait_idle(60) and session.last_run["status"] == "finished"
    unit = cam.load_settings(Path(__file__).parent.parent / "profiles" / "seed004-controller.toml")
    session = MachineSession("cmd:mock", unit)
    session.start(_two_tool_job(tmp_path, unit, None))
    p = _wait_prompt(session)
    assert not p["probe_tool"] and "probe" in p["probe_tool_why_not"]
    with pytest.raises(CapabilityError) as e:
        session.answer(p["id"], "probe-tool")
    assert "\n" not in str(e.value)
    session.stop()
    assert session.wait_idle(60)


# -- the page: the tool-change dialog's Probe tool, and Forget height map ------------------------------------------

from test_web import Server, _open, browser, page  # noqa: E402,F401 (fixtures)

PAGE_SETTINGS = mock_settings(FLAT).replace(ramp="constant", delay_xy_ms=0.05, delay_z_ms=0.05)


def _page_server(tmp_path) -> Server:
    return Server(tmp_path, settings=PAGE_SETTINGS, realtime=False, state_file=str(tmp_path / "m.json"))


def _page_job(s: Server) -> str:
    status, up = s.upload("two.drl", TWO_TOOLS.encode())
    assert status == 200, up
    status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"cut_depth_mm": DEPTH_MM}})
    assert status == 200, planned
    return planned["job"]


def _page_prompt(s: Server, after_id: int = 0) -> dict:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        p = s.call("GET", "/api/state")[1]["prompt"]
        if p is not None and p["id"] > after_id:
            return p
        assert s.session.busy, s.session.last_run
        s.session.wait_change(s.session.version, 0.2)
    raise AssertionError("no prompt came")


def test_api_tool_change_answer_probe_tool_probes_the_new_tool_while_the_job_waits(tmp_path):
    """The dialog's Probe tool through the API: refused in one line (400) before Probe Z set the work Z, which the
    prompt says; after it, "probe-tool" probes, the prompt comes back with what it did, the job goes on and
    finishes with the work Z the probe kept (the same tool: within a step)."""
    s = _page_server(tmp_path)
    try:
        assert s.call("POST", "/api/goto", {"xyz": [20, 15, 0], "machine": True})[0] == 200
        s.wait_idle(60)
        assert s.call("POST", "/api/zero", {"axes": "XY"})[0] == 200
        job = _page_job(s)
        assert s.call("POST", "/api/start", {"job": job})[0] == 200
        p = _page_prompt(s)
        assert not p["probe_tool"] and "Probe Z" in p["probe_tool_why_not"]
        status, err = s.call("POST", "/api/answer", {"prompt": p["id"], "action": "probe-tool"})
        assert status == 400 and "cam probe z" in err["error"] and "\n" not in err["error"], err
        assert s.call("POST", "/api/stop", {})[0] == 200
        s.wait_idle(60)
        assert s.call("POST", "/api/probe-z", {"plate_mm": 0.2})[0] == 200
        s.wait_idle(60)
        zero = s.session.state_hold.state.work_zero_steps()
        assert s.call("POST", "/api/start", {"job": job})[0] == 200
        p = _page_prompt(s)
        assert p["probe_tool"] and p["probe_tool_why_not"] == ""
        status, st = s.call("POST", "/api/answer", {"prompt": p["id"], "action": "continue"})
        p = _page_prompt(s, p["id"])
        status, err = s.call("POST", "/api/answer", {"prompt": p["id"], "action": "probe-tool", "plate_mm": "x"})
        assert status == 400 and "plate_mm" in err["error"], err
        status, st = s.call("POST", "/api/answer", {"prompt": p["id"], "action": "probe-tool", "plate_mm": None})
        assert status == 200, st
        again = _page_prompt(s, p["id"])
        assert again["note"] == p["note"] and again["probed"].startswith("the new tool probed: G54 Z zero moved")
        assert abs(s.session.state_hold.state.work_zero_steps()[2] - zero[2]) <= 1
        assert any(line["text"].startswith("probing the new tool at") for line in s.session.state()["log"])
        assert s.call("POST", "/api/answer", {"prompt": again["id"], "action": "continue"})[0] == 200
        st = s.wait_idle(60)
        assert st["last"]["status"] == "finished", st["last"]
        assert s.session.state_hold.state.tool_probe.plate_mm == 0.2
    finally:
        s.close()


def test_api_forget_height_map(tmp_path):
    """Forget height map: the picture is gone (404), a job planned levelled to it is planned again without it when
    started, and the next plan is not levelled."""
    from test_web_probe import _prepared

    s = _page_server(tmp_path)
    try:
        assert s.call("POST", "/api/goto", {"xyz": [20, 20, 0], "machine": True})[0] == 200
        s.wait_idle(60)
        assert s.call("POST", "/api/zero", {"axes": "XY"})[0] == 200
        job = _page_job(s)
        assert s.call("POST", "/api/probe-area", {"job": job, "spacing_mm": 5})[0] == 200
        s.wait_idle(60)
        assert s.call("GET", "/api/height-map.png")[0] == 200
        status, planned = s.call("POST", "/api/plan", {"job": job, "options": {"cut_depth_mm": DEPTH_MM}})
        assert status == 200 and _prepared(s)[job].levelled_home_steps is not None
        status, st = s.call("POST", "/api/forget-height-map", {})
        assert status == 200 and s.session.last_map is None and s.session.last_map_path is None
        assert any("forgotten" in line["text"] for line in st["log"])
        status, err = s.call("GET", "/api/height-map.png")
        assert status == 404 and "Probe the job's area" in err["error"]
        status, st = s.call("POST", "/api/start", {"job": job})
        assert status == 200 and "planned" in st, st
        assert _prepared(s)[job].levelled_home_steps is None  # planned again, not levelled
        assert any("not levelled: the height map was forgotten" in line["text"] for line in st["log"])
        p = _page_prompt(s)  # its first tool change: stop there
        assert s.call("POST", "/api/answer", {"prompt": p["id"], "action": "stop"})[0] == 200
        s.wait_idle(60)
        status, planned = s.call("POST", "/api/plan", {"job": job, "options": {"cut_depth_mm": DEPTH_MM}})
        assert status == 200 and _prepared(s)[job].levelled_home_steps is None
        assert s.call("POST", "/api/forget-height-map", {})[0] == 200  # nothing to forget: said, no error
    finally:
        s.close()


@pytest.mark.browser
def test_page_tool_change_dialog_probe_tool_button(page, tmp_path):  # noqa: F811
    s = _page_server(tmp_path)
    try:
        _open(page, s)
        page.wait_for_function("!document.getElementById('probe-row').hidden")
        page.fill("#probe-plate", "0")
        page.click("#probe-z")
        page.wait_for_function("document.getElementById('work-mm').textContent !== '0.000, 0.000, 0.000'")
        s.wait_idle(60)
        job = _page_job(s)
        assert s.call("POST", "/api/start", {"job": job})[0] == 200
        page.wait_for_selector("#prompt-dialog[open]")
        page.wait_for_selector("#prompt-probe-tool:not([hidden])")
        page.click("#prompt-probe-tool")
        page.wait_for_function("document.getElementById('prompt-probed').textContent.startsWith('the new tool probed')")
        assert page.text_content("#prompt-probe-tool") == "Probe tool again"
        asked_again = s.session.state()["prompt"]["id"]
        page.click("#prompt-continue")
        p = _page_prompt(s, asked_again)  # T2's
        s.call("POST", "/api/answer", {"prompt": p["id"], "action": "continue"})
        st = s.wait_idle(60)
        assert st["last"]["status"] == "finished", st["last"]
    finally:
        s.close()
