"""The page's live track, the job's own units and the hole table (issue #47 points 1-3): the API in-process (a
real server on a free port) on the mock, and the library's conversions with literal numbers."""
from __future__ import annotations

import time

import numpy as np
import pytest

import cam
from cam.drive.track import JobUnits, hole_states, job_units, start_at_hole, to_job_units
from cam.errors import PlanError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.verify.pinlog import decode_pin_log

from conftest import SAMPLES
from test_web import EXCELLON, FAST, Server

INCH_DRILL = """M48
INCH,LZ
T1C0.032
%
T1
X0.1000Y0.2000
X0.3000Y0.2000
M30
"""


def _wait(s: Server, cond, timeout_s: float = 30.0) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        status, st = s.call("GET", "/api/state")
        if st["prompt"]:  # a tool change: answered as the page's Continue
            s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})
        if cond(st):
            return st
        assert time.monotonic() < deadline, st
        time.sleep(0.02)


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path, settings=FAST, realtime=False)
    yield s
    s.close()


def _plan(s: Server, name: str, data: bytes, options=None) -> str:
    status, up = s.upload(name, data)
    assert status == 200, up
    status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": options or {}})
    assert status == 200, planned
    return planned["job"]


def test_to_job_units_literal():
    u = JobUnits("px", (80, 40, 0), (8, 8, 1))
    assert to_job_units((80 + 8 * 12, 40 + 8 * 3, 5), u) == {"unit": "px", "xyz": [12.0, 3.0, 5.0]}
    # a drill file in inches, Y up: 1 inch right and 0.5 inch up of the file's zero
    u = JobUnits("inch", (1000, 2000, 0), (254.0, -254.0, 254.0), (("mil", 1000.0),))
    assert to_job_units((1254, 1873, 0), u) == {"unit": "inch", "xyz": [1.0, 0.5, 0.0], "mil": [1000.0, 500.0, 0.0]}
    assert hole_states(4, first=2, done=1, drilling=True) == ["skipped", "skipped", "done", "drilling"]
    assert hole_states(3, done=3, drilling=True) == ["done"] * 3


def test_drawing_units_are_its_pixels():
    s = FAST
    job = prepare_job(SAMPLES / "word.png", JobOptions.from_mapping({"depth": "10", "start_at": "3,4,0"}), s)
    u = job_units(job, (100, 200, 0), s)
    k = job.toolpath.pixels.steps_per_px_xy
    # pixel (col 7, row 5) of the drawing, Start At (3, 4) included in the job's frame
    assert to_job_units((100 + (7 + 3) * k, 200 + (5 + 4) * k, 0), u)["xyz"] == [7.0, 5.0, 0.0]


def test_track_of_a_drill_job_and_its_hole_table(server, tmp_path):
    job_id = _plan(server, "inch.drl", INCH_DRILL.encode())
    status, track = server.call("GET", f"/api/track?job={job_id}")
    assert status == 200, track
    assert track["units"]["unit"] == "inch" and track["units"]["also"] == [["mil", 1000.0]]
    holes = np.array(track["holes_mm"])
    assert holes.shape == (2, 2) and abs(abs(holes[1, 0] - holes[0, 0]) - 5.08) < 0.05  # 0.2 inch apart
    status, table = server.call("GET", f"/api/holes?job={job_id}&unit=mil")
    assert status == 200 and table["file_units"] == "inch"
    assert sorted((round(h["x"]), round(h["y"])) for h in table["holes"]) == [(100, 200), (300, 200)]
    assert [h["state"] for h in table["holes"]] == ["to do", "to do"] and table["holes"][0]["tool"] == 1
    status, table = server.call("GET", f"/api/holes?job={job_id}&unit=inch")
    assert sorted(round(h["x"], 3) for h in table["holes"]) == [0.1, 0.3]
    assert server.call("GET", f"/api/holes?job={job_id}&unit=furlong")[0] == 400
    # the tool at the first hole: the snapshot says where, in the file's own inches
    status, st = server.call("POST", "/api/goto-hole", {"job": job_id, "hole": 1})
    assert status == 200, st
    st = _wait(server, lambda st: st["state"] == "idle")
    first = table["holes"][0]
    assert st["job_position"]["unit"] == "inch"
    assert st["job_position"]["xyz"][:2] == pytest.approx([first["x"], first["y"]], abs=0.002)
    assert st["position_mm"][:2] == pytest.approx(holes[0], abs=0.03)
    assert st["position_steps"][2] < 0  # above the surface (+Z deeper): the travel height
    # the job: every hole done, from the session's progress
    assert server.call("POST", "/api/start", {"job": job_id})[0] == 200
    st = _wait(server, lambda st: st["state"] == "idle" and st.get("holes"))
    assert st["last"]["status"] == "finished" and st["holes"]["states"] == ["done", "done"]
    status, table = server.call("GET", f"/api/holes?job={job_id}&unit=mm")
    assert [h["state"] for h in table["holes"]] == ["done", "done"]
    assert server.call("POST", "/api/goto-hole", {"job": job_id, "hole": 3})[0] == 400
    assert server.call("POST", "/api/goto-hole", {"job": job_id, "hole": "1"})[0] == 400


def test_start_at_skips_the_holes_before_and_drills_the_rest(server):
    job_id = _plan(server, "board.drl", (SAMPLES / "board.drl").read_bytes())
    status, track = server.call("GET", f"/api/track?job={job_id}")
    holes = np.array(track["holes_mm"])
    assert len(holes) == 44 and track["units"]["unit"] == "mm"
    start = np.array(server.session.position_steps())
    status, st = server.call("POST", "/api/start-at-hole", {"job": job_id, "hole": 40})
    assert status == 200, st
    deadline = time.monotonic() + 60
    while True:  # the run's tool-change prompts answered as the page does
        st = server.session.state()
        if st["prompt"]:
            server.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})
        if st["state"] == "idle":
            break
        assert time.monotonic() < deadline
        time.sleep(0.01)
    assert st["last"]["status"] == "finished", st["last"]
    st = server.call("GET", "/api/state")[1]
    assert st["holes"]["states"] == ["skipped"] * 39 + ["done"] * 5
    # the pin log: the tool went below the surface only at holes 40..44
    motion = decode_pin_log(server.session.last_job_pin_log, FAST).position_steps + start
    per = np.array(FAST.mm_per_step_axes[:2])
    bottoms = motion[motion[:, 2] == motion[:, 2].max()][:, :2] * per
    drilled = {tuple(np.round(p, 1)) for p in bottoms}
    assert drilled == {tuple(np.round(h, 1)) for h in holes[39:]}
    status, table = server.call("GET", f"/api/holes?job={job_id}")
    assert [h["state"] for h in table["holes"]][38:41] == ["skipped", "done", "done"]


def test_start_at_refusals_are_one_line():
    job = prepare_job(SAMPLES / "word.png", JobOptions.from_mapping({"depth": "10"}), FAST)
    with pytest.raises(PlanError, match="drill job"):
        start_at_hole(job, 1, (0, 0, 0), board=False)


def test_snapshots_while_a_job_runs_come_5_times_a_second(tmp_path):
    """The event stream gives a running job's position at least 5 times a second (issue #47 point 1)."""
    import json
    import urllib.request

    slow = cam.MachineSettings().replace(delay_xy_ms=0.5, delay_z_ms=0.5, ramp="constant")
    s = Server(tmp_path, settings=slow, realtime=True)
    try:
        job_id = _plan(s, "w.drl", EXCELLON.encode())
        assert s.call("POST", "/api/start", {"job": job_id})[0] == 200
        times, positions = [], []
        with urllib.request.urlopen(s.url + "/api/events", timeout=60) as resp:
            for line in resp:
                if not line.startswith(b"data: "):
                    continue
                snap = json.loads(line[6:])
                if snap["prompt"]:
                    s.call("POST", "/api/answer", {"prompt": snap["prompt"]["id"], "action": "continue"})
                if snap["activity"] == "job" and not snap["prompt"]:
                    times.append(time.monotonic())
                    positions.append(tuple(snap["position_steps"]))
                if snap["state"] == "idle" and times:
                    break
        gaps = np.diff(times)
        assert len(times) >= 5 and float(np.median(gaps)) <= 0.2, gaps
        assert len(set(positions)) >= 3  # the machine's reported position moves along
    finally:
        s.close()


# -- in Chromium (Playwright), with screenshots for docs/web.md (issue #47 point 8) --------------------------------

from test_web import MEDIUM, ROOT, browser  # noqa: E402,F401  (the browser fixture: Debian chromium)

DOCS = ROOT / "docs"
DESKTOP = {"width": 1280, "height": 900}
PHONE = {"width": 390, "height": 844}


def _page(browser, viewport):
    ctx = browser.new_context(viewport=viewport, bypass_csp=True)  # wait_for_function evals
    p = ctx.new_page()
    p.set_default_timeout(60_000)
    return ctx, p


def _open_and_plan(p, server, path) -> None:
    p.goto(server.url + "/")
    p.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
    p.set_input_files("#file", str(path))
    p.wait_for_function("!document.getElementById('track-box').hidden")


def _shot(p, selector: str, name: str, *more: str) -> None:
    """A screenshot of one section for docs/web.md (the sticky header bar out of its way); with more selectors, of
    the smallest rectangle around all those elements, a few pixels around it."""
    p.evaluate("document.querySelector('header.bar').style.position = 'static'")
    if not more:
        p.locator(selector).screenshot(path=str(DOCS / name))
        return
    boxes = [p.evaluate("(s) => { const r = document.querySelector(s).getBoundingClientRect();"
                        " return [r.left + scrollX, r.top + scrollY, r.right + scrollX, r.bottom + scrollY]; }", s)
             for s in (selector, *more)]
    x0, y0 = min(b[0] for b in boxes) - 4, min(b[1] for b in boxes) - 4
    x1, y1 = max(b[2] for b in boxes) + 4, max(b[3] for b in boxes) + 4
    p.screenshot(path=str(DOCS / name), full_page=True, clip={"x": x0, "y": y0, "width": x1 - x0, "height": y1 - y0})


def _answer_prompts_until_idle(p, server, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while server.session.busy or p.evaluate("document.getElementById('state').dataset.state") != "idle":
        assert time.monotonic() < deadline
        if p.is_visible("#prompt-continue"):
            p.click("#prompt-continue")
        p.wait_for_timeout(50)


@pytest.mark.browser
def test_page_track_of_a_drill_job_on_the_maximus_emulator(browser, tmp_path):
    """The drill job's picture on the MAXIMUS emulator: the tool where the board reports it, the holes marked done in
    the picture and the table as the board answers them; screenshots at desktop and phone sizes."""
    from cam.drive.maximus.board import MAXIMUS_SETTINGS
    from cam.sim.maximus import start_emulator

    emu = start_emulator(speed=None)
    s = Server(tmp_path, settings=MAXIMUS_SETTINGS, machine_port=f"maximus:{emu.device_path}", realtime=True)
    ctx, p = _page(browser, DESKTOP)
    try:
        _open_and_plan(p, s, SAMPLES / "board.drl")
        p.wait_for_function("document.querySelectorAll('#holes-table tbody tr').length === 44")
        assert p.is_visible("#holes-card")
        p.click("#start")
        tools = set()
        deadline = time.monotonic() + 120
        while True:  # the tool marker follows the board's reports; answer each tool change as the operator does
            tools.add(p.evaluate("document.getElementById('track').dataset.tool"))
            if p.is_visible("#prompt-continue"):
                p.click("#prompt-continue")
            done = p.evaluate("document.querySelectorAll('#holes-table tr[data-state=done]').length")
            if done == 44 and not s.session.busy:
                break
            assert time.monotonic() < deadline, done
            p.wait_for_timeout(30)
        assert len(tools - {""}) >= 3, tools
        p.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        assert p.evaluate("Array.from(document.querySelectorAll('#holes-table tbody tr')).every("
                          "(tr) => tr.dataset.state === 'done')")
        _shot(p, "#preview-card", "web-track-drill.png")
        assert p.is_visible("#spindle-row")  # the board's spindle switch (point 7)
        p.click("#spindle-on")
        p.wait_for_function("document.getElementById('spindle-state').textContent === 'spindle: on'")
        p.click("#spindle-off")
        p.wait_for_function("document.getElementById('spindle-state').textContent === 'spindle: off'")
        p.set_viewport_size(PHONE)
        p.locator("#holes-card").scroll_into_view_if_needed()
        p.screenshot(path=str(DOCS / "web-holes-phone.png"))
    finally:
        ctx.close()
        s.close()
        emu.stop()
    assert emu.error is None


@pytest.mark.browser
def test_page_track_of_a_drawing_on_the_mock_and_its_pixels(browser, tmp_path):
    """A drawing on the mock (real time): the trail of what is cut grows from the reported positions while the job
    runs, and the position shows in the drawing's pixels."""
    s = Server(tmp_path, settings=MEDIUM, realtime=True)
    ctx, p = _page(browser, PHONE)
    try:
        _open_and_plan(p, s, SAMPLES / "word.png")
        p.wait_for_function("document.getElementById('job-pos-unit').textContent.includes('pixels')")
        p.click("#start")
        p.wait_for_function("document.getElementById('state').dataset.state === 'running'")
        p.wait_for_function("Number(document.getElementById('track').dataset.trail) >= 5")
        seen = {p.evaluate("document.getElementById('track').dataset.tool")}
        p.wait_for_function("(t) => document.getElementById('track').dataset.tool !== t", arg=seen.pop())
        _shot(p, "#preview-card", "web-track-drawing-phone.png")
        _answer_prompts_until_idle(p, s)
        assert p.evaluate("Number(document.getElementById('track').dataset.trail)") >= 5
        px = p.evaluate("document.getElementById('job-pos').textContent")
        # the session's home is where the tool stood at the start, where the drawing ran from (no state file)
        units = job_units(prepare_job(SAMPLES / "word.png", JobOptions(), MEDIUM), (0, 0, 0), MEDIUM)
        want = to_job_units(s.session.position_steps(), units)
        assert [float(v) for v in px.split(",")] == pytest.approx(want["xyz"], abs=0.1)
    finally:
        ctx.close()
        s.close()


@pytest.mark.browser
def test_page_hole_table_start_at_and_go_to(browser, tmp_path):
    """The hole table on the mock: choose hole 40, Start At: holes 1-39 skipped, 40-44 done; Go To hole 2 moves
    the tool above it."""
    s = Server(tmp_path, settings=FAST, realtime=True)
    ctx, p = _page(browser, DESKTOP)
    try:
        _open_and_plan(p, s, SAMPLES / "board.drl")
        p.wait_for_function("document.querySelectorAll('#holes-table tbody tr').length === 44")
        p.click("#holes-table tbody tr[data-number='40']")
        assert p.inner_text("#hole-start") == "Start At hole 40"
        p.click("#hole-start")
        p.wait_for_function("document.getElementById('state').dataset.state !== 'idle'")
        _answer_prompts_until_idle(p, s)
        p.wait_for_function("document.querySelector('#holes-table tr[data-number=\"44\"]').dataset.state === 'done'")
        states = p.evaluate("Array.from(document.querySelectorAll('#holes-table tbody tr')).map((tr) => tr.dataset.state)")
        assert states == ["skipped"] * 39 + ["done"] * 5
        p.select_option("#holes-unit", "mil")
        p.wait_for_function("document.getElementById('holes-summary').textContent.includes('44 holes')")
        p.click("#holes-table tbody tr[data-number='2']")
        track = s.call("GET", f"/api/track?job={s.call('GET', '/api/state')[1]['holes']['job']}")[1]
        p.click("#hole-goto")
        deadline = time.monotonic() + 30  # the Go To ends above hole 2
        while s.session.busy or not np.allclose(s.session.state()["position_mm"][:2], track["holes_mm"][1], atol=0.05):
            assert time.monotonic() < deadline, s.session.state()["position_mm"]
            p.wait_for_timeout(20)
        assert s.session.state()["position_steps"][2] < 0  # at the travel height, above the surface
        _shot(p, "#holes-card", "web-holes.png")
    finally:
        ctx.close()
        s.close()


@pytest.mark.browser
def test_keyboard_jog_moves_the_mock(browser, tmp_path):
    """Arrow keys and Page Up / Down jog the mock by the chosen step; keys typed in a field do not; a screenshot of
    the position after the jogs, with the jog pad."""
    s = Server(tmp_path, settings=FAST, realtime=True)
    ctx, p = _page(browser, DESKTOP)
    try:
        p.goto(s.url + "/")
        p.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        p.select_option("#jog-steps", "100")
        start = s.session.position_steps()
        for key, axis, sign in (("ArrowRight", 0, 1), ("ArrowDown", 1, 1), ("PageDown", 2, 1), ("ArrowLeft", 0, -1),
                                ("PageUp", 2, -1)):
            before = s.session.position_steps()
            # the page has the jog's end: idle at the position reached (an idle seen before a late snapshot of the
            # jog running would have the key refused)
            p.wait_for_function("(t) => document.getElementById('state').dataset.state === 'idle'"
                                " && document.getElementById('pos-steps').textContent === t",
                                arg=", ".join(str(v) for v in before))
            p.locator("body").press(key)
            deadline = time.monotonic() + 20
            while s.session.position_steps()[axis] != before[axis] + sign * 100 or s.session.busy:
                assert time.monotonic() < deadline, (key, s.session.position_steps())
                p.wait_for_timeout(20)
        assert s.session.position_steps() == (start[0], start[1] + 100, start[2])
        moved = ", ".join(str(v) for v in (start[0], start[1] + 100, start[2]))
        p.wait_for_function("(t) => document.getElementById('pos-steps').textContent === t", arg=moved)
        # the position after the jogs (machine and work), the step size and the pad beside it (to its next row)
        _shot(p, "#run-card h2", "web-keyboard-jog.png", "#pos-known", "#jog-card .pad", "#set-offset")
        p.fill("#goto-x", "5")
        p.locator("#goto-x").press("ArrowUp")  # in a field: the field's own key, no jog
        p.wait_for_timeout(300)
        assert s.session.position_steps() == (start[0], start[1] + 100, start[2]) and not s.session.busy
    finally:
        ctx.close()
        s.close()


# -- point 7: the spindle switch, the time left at the feed override ---------------------------------------------

def test_spindle_switch_on_the_maximus_emulator(emu, tmp_path):
    """The page's spindle switch sets the board's spindle bit (RB2) on the emulator, and the snapshot says so;
    refused in one line on the mock and with a value that is not true or false."""
    from cam.drive.maximus.board import MAXIMUS_SETTINGS
    from cam.sim.maximus import SPINDLE_BIT

    s = Server(tmp_path, settings=MAXIMUS_SETTINGS, machine_port=f"maximus:{emu.device_path}", realtime=True)
    try:
        port, bit = SPINDLE_BIT
        for on in (True, False):
            status, st = s.call("POST", "/api/spindle", {"on": on})
            assert status == 200, st
            st = _wait(s, lambda st: st["state"] == "idle" and st["spindle"] is not None)
            assert st["spindle"] is on and st["last"]["status"] == "finished", st["last"]
            writes = [v for _, p, v in emu.port_log() if p in (port, chr(port) if isinstance(port, int) else port)]
            assert writes and (writes[-1] >> bit) & 1 == int(on), writes[-3:]
        status, err = s.call("POST", "/api/spindle", {"on": "yes"})
        assert status == 400 and "true or false" in err["error"]
    finally:
        s.close()
    m = Server(tmp_path, settings=FAST, realtime=False)
    try:
        status, err = m.call("POST", "/api/spindle", {"on": True})
        assert status == 409 and "spindle" in err["error"] and "\n" not in err["error"]
    finally:
        m.close()


def test_time_left_follows_the_feed_override_on_grbl(tmp_path):
    """At a 50 % feed override the page's time left is twice the machine time left (issue #47 point 7)."""
    from cam.drive.grbl_machine import close_grbl_machines
    from cam.sim.grbl import start_emulator
    from test_grbl_session import FAST as GRBL_FAST, SETTINGS as GRBL_SETTINGS

    emu = start_emulator(speed=2.0, settings=GRBL_FAST)
    s = Server(tmp_path, settings=GRBL_SETTINGS, machine_port=f"grbl:{emu.device_path}")
    try:
        assert s.call("POST", "/api/feed-override", {"percent": 50})[0] == 200
        job_id = _plan(s, "two_curves.png", (SAMPLES / "two_curves.png").read_bytes(), {"depth": [2, 3]})
        assert s.call("POST", "/api/start", {"job": job_id})[0] == 200
        checked = 0
        deadline = time.monotonic() + 120
        while checked < 3:
            assert time.monotonic() < deadline and s.session.busy, checked
            before = s.session.state()
            status, st = s.call("GET", "/api/state")
            after = s.session.state()
            if before["activity"] == after["activity"] == st["activity"] == "job" and after["remaining_s"] > 1:
                assert 2 * after["remaining_s"] - 0.05 <= st["remaining_s"] <= 2 * before["remaining_s"] + 0.05, \
                    (before["remaining_s"], st["remaining_s"], after["remaining_s"])
                checked += 1
            time.sleep(0.05)
        s.session.stop()
        s.wait_idle(60)
    finally:
        s.close()
        close_grbl_machines()
        emu.stop()
