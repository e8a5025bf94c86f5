"""The page in the machine and work frames (issue #29 point 3): `cam serve` keeps the machine state file, the page
shows machine and work position live, Zero per axis, Go To, the active offset; a job started from the page is
placed at the work zero, checked on the mock's decoded pin log."""
from __future__ import annotations

import time

import numpy as np
import pytest

import cam
from cam.drive.state import read_state
from cam.kinds.jobs import JobOptions, prepare_job
from cam.verify.pinlog import decode_pin_log
from conftest import SAMPLES
from test_web import FAST, Server, _load, _open, _wait_done, browser, page  # noqa: F401 (fixtures)

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_a_page_job_is_placed_at_the_work_zero_and_recorded', 'test_a_page_drill_file_placed_by_its_own_zero_is_planned_from_the_work_zero'}

MEDIUM = cam.MachineSettings().replace(delay_xy_ms=0.3, delay_z_ms=0.3, ramp="constant")


def test_routes_zero_goto_and_offsets_keep_the_state_file(tmp_path):
    state_file = tmp_path / "m.json"
    s = Server(tmp_path, settings=FAST, realtime=False, state_file=str(state_file))
    try:
        status, st = s.call("POST", "/api/goto", {"xyz": [2, 3, 0], "unit": "mm"})
        assert status == 200, st
        s.wait_idle()
        status, st = s.call("POST", "/api/zero", {"axes": "XY"})
        assert status == 200 and st["where"]["work_steps"] == [0, 0, 0], st
        machine = st["where"]["machine_steps"]
        assert read_state(state_file, FAST).offsets_steps["G54"] == (machine[0], machine[1], 0)
        status, st = s.call("POST", "/api/goto", {"xyz": [1, 1, 0], "unit": "mm"})
        s.wait_idle()
        status, st = s.call("GET", "/api/state")
        assert st["where"]["work_mm"][:2] == pytest.approx([1, 1], abs=FAST.mm_per_step_xy)
        status, st = s.call("POST", "/api/use-offset", {"offset": "G55"})
        assert status == 200 and st["where"]["active_offset"] == "G55"
        assert read_state(state_file, FAST).active_offset == "G55"
        for route, body, words in (("/api/zero", {"axes": "Q"}, "axes must be"),
                                   ("/api/goto", {"xyz": [1, "a", 0]}, "xyz Y must be a number"),
                                   ("/api/goto", {"xyz": [-1000, 0, 0], "machine": True}, "outside the X travel"),
                                   ("/api/use-offset", {"offset": "G99"}, "offset must be one of"),
                                   # found by the fuzzing: a 500 each before
                                   ("/api/zero", {"axes": "XY", "offset": {"a": {"b": 1}}}, "offset must be one of"),
                                   ("/api/goto", {"xyz": [1, 10 ** 400, 0]}, "xyz Y must be a finite number")):
            status, err = s.call("POST", route, body)
            assert 400 <= status < 500 and words in err["error"] and "\n" not in err["error"], (route, err)
    finally:
        s.close()


def test_a_page_job_is_placed_at_the_work_zero_and_recorded(tmp_path):
    state_file = tmp_path / "m.json"
    s = Server(tmp_path, settings=FAST, realtime=False, state_file=str(state_file))
    try:
        s.call("POST", "/api/goto", {"xyz": [40, 30, 0], "unit": "steps", "machine": True})
        s.wait_idle()
        s.call("POST", "/api/zero", {"axes": "XYZ"})
        s.call("POST", "/api/goto", {"xyz": [5, 5, 0], "unit": "mm"})  # away from the zero
        s.wait_idle()
        status, up = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
        assert status == 200, up
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"depth": [2]}})
        assert status == 200, planned
        status, st = s.call("POST", "/api/start", {"job": planned["job"]})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and st["last"]["activity"] == "job", st["last"]
        want = decode_pin_log(cam.run(prepare_job(SAMPLES / "ellipse.png", JobOptions(depth=(2,)), FAST).plan)
                              .pin_log(), FAST).position_steps
        assert np.array_equal(decode_pin_log(s.session.last_job_pin_log, FAST).position_steps, want)
        assert read_state(state_file, FAST).position_steps == (40, 30, 0)  # the drawing's home: the work zero
    finally:
        s.close()


@pytest.mark.browser
def test_page_zero_go_to_and_live_work_position(page, tmp_path):  # noqa: F811
    s = Server(tmp_path, settings=MEDIUM, realtime=True, state_file=str(tmp_path / "m.json"))
    try:
        _open(page, s)
        page.fill("#goto-x", "3")
        page.fill("#goto-y", "2")
        page.click("#goto")
        page.wait_for_function("document.getElementById('pos-mm').textContent.startsWith('3.0')")
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        page.click("button.zero[data-axes='X']")
        page.click("button.zero[data-axes='Y']")
        page.wait_for_function("document.getElementById('work-mm').textContent === '0.000, 0.000, 0.000'")
        assert page.text_content("#work-offset") == "G54" and "known" in page.text_content("#pos-known")
        _load(page, SAMPLES / "ellipse.png", depth="2")
        page.click("#start")
        seen = set()
        deadline = time.monotonic() + 60
        while s.session.busy and time.monotonic() < deadline:
            seen.add(page.text_content("#work-mm"))
            page.wait_for_timeout(100)
        assert len(seen) >= 3, seen  # the work position moves on the page during the job, not only at its end
        st = _wait_done(page, s)
        assert st["last"]["status"] == "finished"
        assert page.text_content("#work-mm") == "0.000, 0.000, 0.000"  # a drawing ends at its home: the zero
        page.select_option("#offset-select", "G55")
        page.wait_for_function("document.getElementById('work-offset').textContent === 'G55'")
    finally:
        s.close()


def test_a_page_drill_file_placed_by_its_own_zero_is_planned_from_the_work_zero(tmp_path):
    """A file whose own Y grows up (board coordinates) fits only below a work zero away from the home: the page
    plans it there (the session's machine state reaches the planner), and the holes are drilled at work zero +
    their own coordinates."""
    state_file = tmp_path / "m.json"
    s = Server(tmp_path, settings=FAST, realtime=False, state_file=str(state_file))
    try:
        s.call("POST", "/api/goto", {"xyz": [100, 600, 0], "unit": "steps", "machine": True})
        s.wait_idle()
        status, st = s.call("POST", "/api/zero", {"axes": "XYZ"})
        assert status == 200, st
        drl = "M48\nMETRIC\nT1C0.8\n%\nT1\nX2.0Y3.0\nX5.0Y12.0\nM30\n"
        status, up = s.upload("board.drl", drl.encode())
        assert status == 200, up
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"origin": "file"}})
        assert status == 200, planned
        status, st = s.call("POST", "/api/start", {"job": planned["job"]})
        assert status == 200, st
        deadline = time.monotonic() + 30
        while s.session.busy and time.monotonic() < deadline:  # the tool change prompt: go on
            st = s.session.state()
            if st["prompt"]:
                s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})
            time.sleep(0.02)
        st = s.wait_idle()
        assert st["last"]["status"] == "finished", st["last"]
        pos = decode_pin_log(s.session.last_job_pin_log, FAST).position_steps
        deepest = pos[:, 2].max()
        at_bottom = {tuple(int(v) for v in p[:2]) for p in pos if p[2] == deepest}
        mm = FAST.mm_per_step_xy
        want = {(round(2.0 / mm), -round(3.0 / mm)), (round(5.0 / mm), -round(12.0 / mm))}
        # the pin log is relative to where the job started: the work zero (its own zero) after the travel there
        assert at_bottom == want, (at_bottom, want)
    finally:
        s.close()
