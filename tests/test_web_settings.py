"""The page's machine settings and tool table (issue #47 points 4 and 5): GET/POST /api/settings and /api/tools,
thin adapters over cam.machine_file and cam.tool_table, tested with the real server in-process; Z Drill Up / Down
and the work offsets kept across a server restart; in Chromium, a setting and a tool edited on the page are
there after a reload and a restart, with screenshots for docs/web.md."""
from __future__ import annotations

import shutil

import pytest

from cam.drive.state import read_state
from cam.machine_file import machine_file_of
from cam.settings import load_settings
from cam.tool_table import read_tool_table

from conftest import ROOT, SAMPLES
from test_web import Server, browser  # noqa: F401 (the browser fixture)
from test_web_track import DESKTOP, PHONE, _shot

SLOW_CASES: set[str] = set()


@pytest.fixture
def machine(tmp_path):
    """A copy of the thesis machine file, made fast (constant ramps, short delays) for the page's jobs."""
    path = tmp_path / "mill.toml"
    shutil.copy(ROOT / "profiles" / "thesis-machine.toml", path)
    text = path.read_text()
    path.write_text(text + "\n")
    return path


def _server(tmp_path, machine, **config):
    return Server(tmp_path, settings=load_settings(machine), machine_file=str(machine), realtime=False,
                  state_file=str(tmp_path / "state.json"), **config)


def test_settings_are_listed_with_unit_range_and_help(tmp_path, machine):
    s = _server(tmp_path, machine)
    try:
        status, r = s.call("GET", "/api/settings")
        assert status == 200, r
        assert r["file"] == str(machine) and r["exists"]
        by_key = {e["key"]: e for e in r["settings"]}
        speed = by_key["max_speed_x_mm_s"]
        assert speed["unit"] == "mm/s" and speed["lo"] == 0.01 and speed["hi"] == 10000 and speed["help"]
        assert speed["value"] == s.session.settings.max_speed_x_mm_s
        assert by_key["maximus.delay_x"]["range"].startswith("1..255")
        assert by_key["ramp"]["choices"] == ["lookahead", "linear40", "constant"]
        assert "travel.x_max_steps" in by_key and "mm_per_step_y" not in by_key
    finally:
        s.close()


def test_a_setting_saved_on_the_page_is_in_the_file_with_a_backup_and_runs_the_next_job(tmp_path, machine):
    old_text = machine.read_text()
    s = _server(tmp_path, machine)
    try:
        status, up = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
        status, before = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, before
        status, r = s.call("POST", "/api/settings", {"values": {"max_speed_x_mm_s": "4.5", "ramp": "constant"}})
        assert status == 200, r
        by_key = {e["key"]: e for e in r["settings"]}
        assert by_key["max_speed_x_mm_s"]["value"] == 4.5 and by_key["ramp"]["value"] == "constant"
        assert load_settings(machine).max_speed_x_mm_s == 4.5
        assert (tmp_path / "mill.toml.bak").read_text() == old_text
        assert s.session.settings.ramp == "constant" and s.app.state.config.settings.ramp == "constant"
        # the next job is planned with it: constant speed, no ramps, takes another time
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        assert planned["estimated_time_s"] != before["estimated_time_s"]
        # out of range: one line naming the key, the unit and the range; nothing written
        text = machine.read_text()
        status, r = s.call("POST", "/api/settings", {"values": {"max_speed_x_mm_s": 20000}})
        assert status == 400 and r["error"] == "'max_speed_x_mm_s' must be 0.01..10000 mm/s, got 20000"
        status, r = s.call("POST", "/api/settings", {"values": {"maximus.delay_x": "300"}})
        assert status == 400 and "maximus.delay_x" in r["error"] and "1..255" in r["error"]
        status, r = s.call("POST", "/api/settings", {"values": {"no_such_key": 1}})
        assert status == 400 and "no_such_key" in r["error"]
        status, r = s.call("POST", "/api/settings", {"values": []})
        assert status == 400
        assert machine.read_text() == text
        # the state file records the file as saved: no "changed since" at the next start
        assert read_state(tmp_path / "state.json", s.session.settings).machine.sha256 is not None
    finally:
        s.close()
    s = _server(tmp_path, machine)
    try:
        assert s.session.settings.max_speed_x_mm_s == 4.5
        assert not any("changed since" in line["text"] for line in s.session.state(0)["log"])
    finally:
        s.close()


def test_the_tool_table_is_edited_through_the_api_and_kept_beside_the_machine_file(tmp_path, machine):
    s = _server(tmp_path, machine)
    try:
        status, r = s.call("GET", "/api/tools")
        assert status == 200 and r["tools"] == [] and r["file"] == str(tmp_path / "mill.tools.toml")
        status, r = s.call("POST", "/api/tools", {"number": 3, "shape": "v", "diameter_mm": "0.2", "angle_deg": "30",
                                                   "length_mm": "12.3"})
        assert status == 200, r
        assert r["tools"] == [{"number": 3, "shape": "v", "diameter_mm": 0.2, "angle_deg": 30.0, "length_mm": 12.3,
                               "text": "T3: V bit 30 degrees, tip 0.2 mm, length 12.3 mm"}]
        assert read_tool_table(tmp_path / "mill.tools.toml").get(3).length_mm == 12.3
        for bad, word in (({"number": 4, "shape": "v", "diameter_mm": 0.2}, "angle"),
                          ({"number": 4, "shape": "drill", "diameter_mm": 1}, "shape"),
                          ({"number": -1, "shape": "flat", "diameter_mm": 1}, "number"),
                          ({"number": 4, "shape": "flat"}, "diameter_mm"),
                          ({"number": 4, "shape": "flat", "diameter_mm": "x"}, "diameter_mm")):
            status, r = s.call("POST", "/api/tools", bad)
            assert status == 400 and word in r["error"] and "\n" not in r["error"], (bad, r)
        status, r = s.call("POST", "/api/tools/remove", {"number": 7})
        assert status == 400 and "T7" in r["error"]
        status, r = s.call("POST", "/api/tools/remove", {"number": 3})
        assert status == 200 and r["tools"] == []
    finally:
        s.close()


def test_a_drill_job_warns_when_the_table_tool_differs_and_the_prompt_names_it(tmp_path, machine):
    s = _server(tmp_path, machine)
    try:
        s.call("POST", "/api/tools", {"number": 1, "shape": "flat", "diameter_mm": 0.8})
        s.call("POST", "/api/tools", {"number": 3, "shape": "flat", "diameter_mm": 1.0})
        status, up = s.upload("board.drl", (SAMPLES / "board.drl").read_bytes())
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        assert any(w.startswith("T3: the drill file's 3.2 mm wins") for w in planned["warnings"]), planned["warnings"]
        note = s.session.tool_change_note(planned["tool_changes"][0])
        assert note.endswith("[tool table T1: flat end mill 0.8 mm]")
    finally:
        s.close()


def test_work_offsets_are_kept_across_a_server_restart(tmp_path, machine):
    s = _server(tmp_path, machine)
    try:
        assert s.call("POST", "/api/goto", {"xyz": [2, 3, 0], "unit": "mm"})[0] == 200
        s.wait_idle()
        status, st = s.call("POST", "/api/offset", {})
        assert status == 200, st
        zero = st["where"]["offsets_mm"]["G54"]
    finally:
        s.close()
    s = _server(tmp_path, machine)
    try:
        st = s.call("GET", "/api/state")[1]
        assert st["where"]["offsets_mm"]["G54"] == zero and st["where"]["work_mm"] == [0, 0, 0]
    finally:
        s.close()


def test_z_drill_up_and_down_set_on_the_page_are_kept_across_a_restart(tmp_path, emu):
    from cam.drive.maximus.board import MAXIMUS_SETTINGS

    machine = tmp_path / "maximus.toml"
    shutil.copy(ROOT / "profiles" / "maximus-machine.toml", machine)

    def server():
        return Server(tmp_path, settings=load_settings(machine, base=MAXIMUS_SETTINGS), machine_file=str(machine),
                      machine_port=f"maximus:{emu.device_path}", realtime=True, state_file=str(tmp_path / "m.json"))

    s = server()
    try:
        assert s.call("POST", "/api/set-position", {"xyz": [0, 0, 0], "unit": "steps"})[0] == 200
        for z, which in ((40, "up"), (60, "down")):
            assert s.call("POST", "/api/jog", {"axis": "z", "steps": z})[0] == 200
            s.wait_idle(20)
            status, r = s.call("POST", "/api/drill-z", {"which": which})
            assert status == 200, r
        assert load_settings(machine).maximus.drill_z_up_steps == 40
        assert load_settings(machine).maximus.drill_z_down_steps == 100
    finally:
        s.close()
    s = server()
    try:
        m = s.session.settings.maximus
        assert (m.drill_z_up_steps, m.drill_z_down_steps) == (40, 100)
        by_key = {e["key"]: e for e in s.call("GET", "/api/settings")[1]["settings"]}
        assert by_key["maximus.drill_z_down_steps"]["value"] == 100
    finally:
        s.close()


@pytest.fixture
def page(browser):
    ctx = browser.new_context(viewport=DESKTOP, bypass_csp=True)  # wait_for_function evals
    p = ctx.new_page()
    p.set_default_timeout(30_000)
    yield p
    ctx.close()


@pytest.mark.browser
def test_a_setting_and_a_tool_edited_on_the_page_are_there_after_a_reload_and_a_restart(tmp_path, machine, page):
    s = _server(tmp_path, machine)
    try:
        page.goto(s.url + "/")
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        field = page.locator("#settings-list [name='max_speed_x_mm_s']")
        field.wait_for(state="attached")
        page.fill("#settings-filter", "max_speed_x")  # the filter opens the group the key is in
        field.fill("4.25")
        page.click("#settings-save")
        page.wait_for_function("document.querySelector(\"#settings-list [name='max_speed_x_mm_s']\").dataset.was"
                               " === '4.25'")
        assert load_settings(machine).max_speed_x_mm_s == 4.25
        # out of range: the server's one line in the page's error banner, nothing saved
        field = page.locator("#settings-list [name='max_speed_x_mm_s']")
        field.fill("20000")
        page.click("#settings-save")
        page.wait_for_function("!document.getElementById('error').hidden")
        assert "'max_speed_x_mm_s' must be 0.01..10000 mm/s, got 20000" in page.inner_text("#error-text")
        assert load_settings(machine).max_speed_x_mm_s == 4.25
        page.click("#error-close")
        # a tool
        page.fill("#tool-number", "3")
        page.select_option("#tool-shape", "v")
        page.fill("#tool-diameter", "0.2")
        page.fill("#tool-angle", "30")
        page.fill("#tool-length", "12.3")
        page.click("#tool-save")
        page.locator("#tools-list li[data-number='3']").wait_for()
        assert read_tool_table(tmp_path / "mill.tools.toml").get(3).length_mm == 12.3
        # after a reload both come back from the server
        page.reload()
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        page.locator("#tools-list li[data-number='3']").wait_for()
        assert page.inner_text("#tools-list li[data-number='3'] span") == \
            "T3: V bit 30 degrees, tip 0.2 mm, length 12.3 mm"
        page.wait_for_function("document.querySelector(\"#settings-list [name='max_speed_x_mm_s']\") !== null")
        assert page.input_value("#settings-list [name='max_speed_x_mm_s']") == "4.25"
        # and after the server restarts
        s.close()
        s = _server(tmp_path, machine)
        page.goto(s.url + "/")
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        page.locator("#tools-list li[data-number='3']").wait_for()
        page.wait_for_function("document.querySelector(\"#settings-list [name='max_speed_x_mm_s']\") !== null")
        assert page.input_value("#settings-list [name='max_speed_x_mm_s']") == "4.25"
        assert s.session.settings.max_speed_x_mm_s == 4.25
        # screenshots for docs/web.md: the saved setting after the restart (desktop), the tool table (phone size)
        page.fill("#settings-filter", "max_speed")
        page.locator("#settings-list [name='max_speed_x_mm_s']").wait_for(state="visible")
        _shot(page, "#settings-card", "web-settings-restart.png")
        page.set_viewport_size(PHONE)
        _shot(page, "#tools-card", "web-tools-phone.png")
        page.set_viewport_size(DESKTOP)
        # edit it from the list, then remove it
        page.click("#tools-list li[data-number='3'] .tool-edit")
        assert page.input_value("#tool-angle") == "30" and page.input_value("#tool-length") == "12.3"
        page.click("#tools-list li[data-number='3'] .tool-remove")
        page.locator("#tools-list li[data-number='3']").wait_for(state="detached")
        assert read_tool_table(tmp_path / "mill.tools.toml").get(3) is None
    finally:
        s.close()


def test_the_settings_and_tools_routes_take_any_json_value_without_a_500(tmp_path, machine):
    from test_api_sweep import WEIRD_JSON, _checked, _post

    s = _server(tmp_path, machine)
    try:
        for text in WEIRD_JSON:
            for path, body in (("/api/settings", f'{{"values": {text}}}'),
                               ("/api/settings", f'{{"values": {{"maximus.delay_x": {text}}}}}'),
                               ("/api/settings", f'{{"values": {{"homing.order": {text}}}}}'),
                               ("/api/settings", f'{{"values": {{"mock.home_x_steps": {text}}}}}'),
                               ("/api/tools/remove", f'{{"number": {text}}}')):
                status, reply = _post(s, path, body)
                _checked(status, reply, (path, body[:60]))
            for field in ("number", "shape", "diameter_mm", "angle_deg", "length_mm"):
                body = {"number": 2, "shape": "v", "diameter_mm": 0.2, "angle_deg": 30}
                raw = ", ".join(f'"{k}": {text if k == field else json_of(v)}' for k, v in {**body, field: 0}.items())
                status, reply = _post(s, "/api/tools", "{" + raw + "}")
                _checked(status, reply, ("/api/tools", field, text[:40]))
        load_settings(machine)  # whatever was taken, the file reads
        read_tool_table(tmp_path / "mill.tools.toml")
    finally:
        s.close()


def json_of(value) -> str:
    import json

    return json.dumps(value)


def test_settings_saved_without_a_machine_file_are_read_by_the_next_serve(tmp_path):
    """The built-in settings (cam serve with no --machine) are saved to default.toml in the state folder, which the
    mock's default state file records: the next cam serve without --machine runs with it, on the same state file."""
    import argparse

    from cam.cli.common import state_path_of, use_recorded_machine
    from cam.drive.state import default_state_path

    state_file = default_state_path(None, "mock")
    s = Server(tmp_path, realtime=False, machine_file="", state_file=str(state_file))
    try:
        status, r = s.call("POST", "/api/settings", {"values": {"max_speed_x_mm_s": 4.0}})
        assert status == 200, r
        assert r["file"] == str(machine_file_of(None))
    finally:
        s.close()
    args = argparse.Namespace(machine=None, machine_changed=False, state=None, port="mock")
    use_recorded_machine(args)
    assert args.machine == str(machine_file_of(None)) and state_path_of(args) == state_file
    assert load_settings(args.machine).max_speed_x_mm_s == 4.0
