"""The page's probing (issue #46 point 5): Probe Z, Probe tool, Probe the job's area, the height map's picture.

The API endpoints are thin adapters over the session's probe methods (:meth:`MachineSession.probe_work_z`,
``probe_tool``, ``probe_map``); they run on the mock with a simulated probe surface (``[mock] probe_surface``), are
refused in one line on a machine without the ``probes`` capability, and the e-stop stops a probe.  One browser test
clicks Probe Z and reads the work Z the session set."""
from __future__ import annotations

import time

import numpy as np
import pytest

from cam.drive.state import read_state
from cam.job.heightmap_level import load_height_map

from test_probe import FLAT, assert_within_a_step, mock_settings
from test_web import EXCELLON, Server, _open, browser, page  # noqa: F401 (fixtures)

SETTINGS = mock_settings(FLAT).replace(ramp="constant", delay_xy_ms=0.05, delay_z_ms=0.05)


def _server(tmp_path, settings=SETTINGS, **config) -> Server:
    return Server(tmp_path, settings=settings, realtime=False, state_file=str(tmp_path / "m.json"), **config)


def _done(s: Server) -> dict:
    st = s.wait_idle(60)
    assert st["last"]["status"] == "finished", st["last"]
    return st


def _work_zero(s: Server) -> tuple:
    return s.session.state_hold.state.work_zero_steps()


def test_api_probe_z_sets_the_work_z_and_probe_tool_keeps_it(tmp_path):
    s = _server(tmp_path)
    try:
        assert "probes" in s.call("GET", "/api/state")[1]["capabilities"]
        status, err = s.call("POST", "/api/probe-tool", {})
        assert status == 400 and "Probe Z" in err["error"] and "\n" not in err["error"]
        status, st = s.call("POST", "/api/probe-z", {"plate_mm": 0.5})
        assert status == 200, st
        _done(s)
        per = SETTINGS.mm_per_step_z
        contact = s.session.last_probe[0].contact_steps
        assert_within_a_step(-contact[2] * per, FLAT[0], SETTINGS)
        assert _work_zero(s)[2] == contact[2] + round(0.5 / per)
        assert read_state(tmp_path / "m.json", SETTINGS).tool_probe.contact_steps == contact
        status, st = s.call("POST", "/api/probe-tool", {"plate_mm": None})  # the same tool, the recorded plate
        assert status == 200, st
        _done(s)
        assert _work_zero(s)[2] == contact[2] + round(0.5 / per)
        for body, fragment in (({"plate_mm": "thick"}, "plate_mm"), ({"plate_mm": -1}, "plate")):
            status, err = s.call("POST", "/api/probe-z", body)
            assert status == 400 and fragment in err["error"], err
    finally:
        s.close()


def test_api_probe_the_jobs_area_writes_the_map_the_next_job_levels_with(tmp_path):
    s = _server(tmp_path)
    try:
        status, err = s.call("GET", "/api/height-map.png")
        assert status == 404 and "Probe the job's area" in err["error"]
        assert s.call("POST", "/api/probe-area", {"job": "1"})[0] == 409  # nothing planned
        assert s.call("POST", "/api/goto", {"xyz": [20, 20, 0], "machine": True})[0] == 200
        _done(s)
        assert s.call("POST", "/api/zero", {"axes": "XY"})[0] == 200
        status, up = s.upload("two.drl", EXCELLON.encode())
        assert status == 200, up
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        status, st = s.call("POST", "/api/probe-area", {"job": planned["job"], "spacing_mm": 3})
        assert status == 200, st
        _done(s)
        path = s.session.last_map_path
        hmap = load_height_map(path)
        assert len(s.session.last_probe) == hmap.height_mm.size
        assert np.all(np.abs(hmap.height_mm - FLAT[0]) <= SETTINGS.mm_per_step_z + 1e-9)
        # the map covers where the drill job would drill its holes (the work zero at machine X 20, Y 20)
        from cam.drive.probing import job_area_mm
        x0, y0, x1, y1 = job_area_mm(_prepared(s)[planned["job"]], s.session.state_hold.state, SETTINGS)
        assert 19.9 <= x0 < x1 and hmap.x_mm[0] <= x0 + 1e-6 and hmap.x_mm[-1] >= x1 - 1e-6
        assert hmap.y_mm[0] <= y0 + 1e-6 and hmap.y_mm[-1] >= y1 - 1e-6
        status, png = s.call("GET", f"/api/height-map.png?job={planned['job']}")
        assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n"
        # the job planned before the map: Start plans it again, levelled to it, and that plan runs
        status, st = s.call("POST", "/api/start", {"job": planned["job"]})
        assert status == 200 and "planned" in st, st
        assert _prepared(s)[planned["job"]].levelled_home_steps is not None
        deadline = time.monotonic() + 60
        while s.session.busy:  # its tool change answered
            assert time.monotonic() < deadline
            if s.session.state()["prompt"] is not None:
                s.call("POST", "/api/answer", {"action": "continue"})
            time.sleep(0.02)
        assert s.session.last_run["status"] == "finished", s.session.last_run
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        job = [j for j in _prepared(s).values()][-1]
        assert job.levelled_home_steps is not None  # the next job is levelled to the page's map
        for body in ({"job": planned["job"], "spacing_mm": 0}, {"job": planned["job"], "spacing_mm": "x"}):
            status, err = s.call("POST", "/api/probe-area", body)
            assert status == 400 and "spacing" in err["error"] and "\n" not in err["error"], err
    finally:
        s.close()


def _prepared(s: Server) -> dict:
    """The server's planned jobs (its routes' shared state)."""
    import gc

    from cam.web import server as web

    states = [o for o in gc.get_objects() if isinstance(o, web._AppState) and o.session is s.session]
    return states[0].prepared


def test_probing_is_refused_in_one_line_without_the_probes_capability(tmp_path):
    s = Server(tmp_path, settings=SETTINGS, machine_port="cmd:mock", realtime=False)
    try:
        assert "probes" not in s.call("GET", "/api/state")[1]["capabilities"]
        for path in ("/api/probe-z", "/api/probe-tool"):
            status, err = s.call("POST", path, {})
            assert status == 409 and "prob" in err["error"] and "\n" not in err["error"], err
    finally:
        s.close()


def test_the_e_stop_is_served_while_probing(tmp_path):
    deep = mock_settings((-15.0, 0, 0, 0, 0, 0))  # far down: the probe takes seconds at its feed
    s = Server(tmp_path, settings=deep, realtime=True, state_file=str(tmp_path / "m.json"))
    try:
        status, st = s.call("POST", "/api/probe-z", {})
        assert status == 200, st
        time.sleep(0.3)
        assert s.session.busy
        assert s.call("POST", "/api/estop", {})[0] == 200
        st = s.wait_idle(10)
        assert st["last"]["status"] == "emergency-stopped", st["last"]
        assert _work_zero(s)[2] == 0  # nothing set
    finally:
        s.close()


@pytest.mark.browser
def test_page_probe_z_button_sets_the_work_z(page, tmp_path):  # noqa: F811
    s = _server(tmp_path)
    try:
        _open(page, s)
        page.wait_for_function("!document.getElementById('probe-row').hidden")
        assert _work_zero(s)[2] == 0
        page.fill("#probe-plate", "0")
        page.click("#probe-z")
        page.wait_for_function("document.getElementById('work-mm').textContent !== '0.000, 0.000, 0.000'")
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        s.wait_idle()
        z = _work_zero(s)[2]
        assert_within_a_step(-z * SETTINGS.mm_per_step_z, FLAT[0], SETTINGS)
        work_z = float(page.text_content("#work-mm").split(",")[2])
        assert abs(work_z + z * SETTINGS.mm_per_step_z) < 1e-3  # the tool back where it began, that far above (-Z)
    finally:
        s.close()


def test_the_probe_routes_take_any_json_value_without_a_500(tmp_path):
    from test_api_sweep import WEIRD_JSON, _checked, _post

    s = _server(tmp_path)
    try:
        status, up = s.upload("two.drl", EXCELLON.encode())
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        for path, names in (("/api/probe-z", ("plate_mm",)), ("/api/probe-tool", ("plate_mm",)),
                            ("/api/probe-area", ("job", "spacing_mm", "margin_mm"))):
            for value in WEIRD_JSON:
                _checked(*_post(s, path, value), (path, "body", value[:20]))
                s.session.wait_idle(60)
                for name in names:
                    body = {"job": planned["job"]} if path == "/api/probe-area" and name != "job" else {}
                    text = f'{{"{name}": {value}' + "".join(f', "{k}": "{v}"' for k, v in body.items()) + "}"
                    status, reply = _post(s, path, text)
                    _checked(status, reply, (path, name, value[:20]))
                    if status != 200:
                        assert not s.session.busy, (path, name, value)
                    s.session.wait_idle(60)
    finally:
        s.close()
