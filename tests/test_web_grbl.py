"""The page on a grbl board (issue #30 point 2): `cam serve --port grbl:DEV` runs page jobs on the grbl emulator
(what it executed carves the same surface as the job on the mock), homes with $H, sets grbl's feed override, and
shows the position live from grbl's status reports; in Chromium too."""
from __future__ import annotations

import time

import numpy as np
import pytest

import cam
from cam.drive.grbl_machine import close_grbl_machines
from cam.drive.state import read_state
from cam.kinds.jobs import JobOptions, prepare_job
from cam.sim.grbl import start_emulator
from cam.verify.pinlog import decode_pin_log
from conftest import SAMPLES, assert_surface_equal
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from test_grbl_session import FAST as GRBL_FAST, HOMED_SETTINGS, HOMING, SETTINGS, executed_motion, known_at_home
from test_web import Server, _load, _open, _wait_done, browser, page  # noqa: F401 (fixtures)

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_a_page_job_on_grbl_cuts_what_the_mock_cuts'}




@pytest.fixture
def grbl(request):
    emu = start_emulator(**{"speed": 20.0, "settings": GRBL_FAST, **getattr(request, "param", {})})
    yield emu
    close_grbl_machines()
    emu.stop()
    assert emu.error is None


def test_a_page_job_on_grbl_cuts_what_the_mock_cuts(grbl, tmp_path):
    s = Server(tmp_path, settings=SETTINGS, machine_port=f"grbl:{grbl.device_path}",
               state_file=str(known_at_home(tmp_path / "m.json")))
    try:
        status, up = s.upload("two_curves.png", (SAMPLES / "two_curves.png").read_bytes())
        assert status == 200, up
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"depth": [2, 3]}})
        assert status == 200, planned
        status, st = s.call("POST", "/api/start", {"job": planned["job"]})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished", st["last"]
        prepared = prepare_job(SAMPLES / "two_curves.png", JobOptions(depth=(2, 3)), SETTINGS)
        job = prepared.toolpath
        mock = cam.carve(decode_pin_log(cam.run(prepared.plan).pin_log(), SETTINGS), (job.height_px, job.width_px),
                         SETTINGS, origin_px=job.origin_px)
        # the page placed the drawing at the work zero, where the session stood: carve from there
        got = cam.carve(executed_motion(grbl), (job.height_px, job.width_px), SETTINGS, origin_px=job.origin_px)
        assert_surface_equal(got, mock)
        assert np.count_nonzero(got) > 50
        assert st["grbl"]["feed_override_pct"] == 100 and st["where"]["position_known"]
    finally:
        s.close()


def test_feed_override_route(grbl, tmp_path):
    s = Server(tmp_path, settings=SETTINGS, machine_port=f"grbl:{grbl.device_path}")
    try:
        status, st = s.call("POST", "/api/feed-override", {"percent": 140})
        assert status == 200 and st["grbl"]["feed_override_pct"] == 140, st
        deadline = time.monotonic() + 5
        while grbl._feed_ov != 140 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert grbl._feed_ov == 140
        for body, words in (({"percent": "x"}, "percent must be"), ({"percent": 300}, "10..200"),
                            ({"percent": True}, "percent must be")):
            status, err = s.call("POST", "/api/feed-override", body)
            assert 400 <= status < 500 and words in err["error"], (body, err)
    finally:
        s.close()


def test_feed_override_is_refused_on_the_mock(tmp_path):
    s = Server(tmp_path, settings=SETTINGS)
    try:
        status, err = s.call("POST", "/api/feed-override", {"percent": 120})
        assert 400 <= status < 500 and "grbl" in err["error"], err
    finally:
        s.close()


@pytest.mark.parametrize("grbl", [{"settings": {**GRBL_FAST, **HOMING}}], indirect=True)
def test_home_route_on_grbl(grbl, tmp_path):
    state_file = known_at_home(tmp_path / "m.json")  # known: grbl's Alarm is what makes it unknown
    s = Server(tmp_path, settings=HOMED_SETTINGS, machine_port=f"grbl:{grbl.device_path}",
               state_file=str(state_file))
    try:
        status, st = s.call("GET", "/api/state")
        assert not st["where"]["position_known"] and "Alarm" in st["where"]["unknown_reason"]
        status, st = s.call("POST", "/api/goto", {"xyz": [0, 0, 0], "machine": True})
        assert 400 <= status < 500 and "home" in st["error"], st
        # a jog is allowed (issue #45 point 3: grbl's alarm unlocked for it), the position still unknown
        status, st = s.call("POST", "/api/jog", {"axis": "x", "steps": -10})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and not st["where"]["position_known"], st["last"]
        status, st = s.call("POST", "/api/home", {})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished", st["last"]
        assert st["where"]["homed"] and st["where"]["position_known"]
        assert read_state(state_file, HOMED_SETTINGS).homed
        status, st = s.call("POST", "/api/jog", {"axis": "x", "steps": -100})
        assert status == 200, st
        s.wait_idle()
    finally:
        s.close()


@pytest.mark.browser
@pytest.mark.parametrize("grbl", [{"settings": {**GRBL_FAST, **HOMING, 110: 300.0, 111: 300.0}, "speed": 1.0}],
                         indirect=True)
def test_page_homes_grbl_sets_the_feed_and_shows_the_position_live(grbl, page, tmp_path):  # noqa: F811
    s = Server(tmp_path, settings=HOMED_SETTINGS, machine_port=f"grbl:{grbl.device_path}", realtime=True,
               state_file=str(tmp_path / "m.json"))
    try:
        _open(page, s)
        assert page.is_visible("#home") and page.is_visible("#feed-override")
        page.click("#home")
        page.wait_for_function("document.getElementById('pos-known').textContent === 'position known, homed'",
                               timeout=60_000)
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        page.fill("#goto-x", "-20")
        page.fill("#goto-y", "10")
        page.check("#goto-machine")
        page.click("#goto")
        seen = set()
        deadline = time.monotonic() + 30
        page.wait_for_function("document.getElementById('state').dataset.state !== 'idle'")
        while s.session.busy and time.monotonic() < deadline:
            seen.add(page.text_content("#pos-mm"))
            page.wait_for_timeout(100)
        assert len(seen) >= 3, seen  # the position moves on the page during the move, from grbl's reports
        page.fill("#feed-override", "60")
        page.click("#feed-set")
        deadline = time.monotonic() + 5
        while grbl._feed_ov != 60 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert grbl._feed_ov == 60
    finally:
        s.close()

