"""Every job option has a field on the page, made from the option schema (issue #47 point 6).

``GET /api/options`` gives each option of :data:`cam.options.JOB_OPTIONS` (name, label, group, type, unit, range,
choices, the kinds it applies to, the default on each, help); a job planned through the page's API with each option
set is the library's plan with it; an option added to the schema is served with no other change; and in Chromium
the form is made from it: a drill file's options and a drawing's, a depth that reaches the plan, a value out of
range refused by the server in one line in the error banner, and two depths refused by the page itself (a rule
between options, served with the schema).
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from cam.drive.state import MachineState
from cam.errors import CamError
from cam.kinds import job_options, kind_defaults, schema_json
from cam.kinds.jobs import JobOptions, prepare_job
from cam.options import GROUPS, Option

JOB_OPTIONS = job_options()
"""Every option, its kinds filled in from the file kinds' traits (cam.kinds)."""

from conftest import ROOT, SAMPLES
from test_web import FAST, Server, browser  # noqa: F401 (the browser fixture)

DOME = ROOT / "profiles" / "dome.png"
SHOT = ROOT / "docs" / "web-options.png"

SVG_LAYER = "{layer}"  # the first layer of logo.svg, as the library reads it (filled in by the sweep)
_3D = {"profile_expr": "k", "tool": "ball:1", "stepdown_mm": "0.1"}
_HEIGHTMAP = {"heightmap": True}
CASES: dict[str, tuple[str, object, dict]] = {
    # option: (sample file, its value as the page's field sends it, the other options it goes with)
    "depth": ("ellipse.png", "3", {}),
    "passes": ("ellipse.png", "2", {}),
    "start": ("two_curves.png", "thesis", {}),
    "start_at": ("ellipse.png", "2,3,0", {}),
    "pause_at": ("ellipse.png", "10,10", {}),
    "profile": ("disc.png", DOME, {}),
    "profile_expr": ("disc.png", "k", {}),
    "cut_depth_mm": ("board.drl", "1.5", {}),
    "travel_height_mm": ("board.drl", "2", {}),
    "allow_surface_travel": ("board.drl", True, {"travel_height_mm": "0"}),
    "origin": ("board.drl", "center", {}),
    "offset_mm": ("board.drl", "5,80", {}),
    "mirror_x": ("board.drl", True, {}),
    "drill_order": ("board.drl", "file", {}),
    "excellon_units": ("board.drl", "metric", {}),
    "excellon_digits": ("board.drl", "3:3", {}),
    "excellon_zeros": ("board.drl", "TZ", {}),
    "kind": ("board.drl", "excellon", {}),
    "strict": ("board.drl", True, {}),
    "mill_holes_over_mm": ("board.drl", "0.9", {}),
    "flip_y": ("moves.ngc", True, {}),
    "scale": ("logo.svg", "2", {}),
    "fit_mm": ("logo.svg", "80x40", {}),
    "layers": ("logo.svg", SVG_LAYER, {}),
    "pause_between_layers": ("logo.svg", True, {}),
    "keep_duplicates": ("logo.svg", True, {}),
    "max_lines": ("moves.ngc", "100000", {}),
    "trace": ("ellipse.png", True, {}),
    "trace_min_length_px": ("ellipse.png", "20", {"trace": True}),
    "trace_fill": ("ellipse.png", True, {"trace": True, "depth": "3"}),
    "tool": ("ellipse.png", "flat:1", {}),
    "line_width_mm": ("ellipse.png", "0.3", {"tool": "v:60:0.1"}),
    "stepdown_mm": ("disc.png", "0.1", {"profile_expr": "k", "tool": "ball:1"}),
    "stepover": ("disc.png", "0.4", _3D),
    "rough_tool": ("disc.png", "flat:2", _3D),
    "heightmap": ("ellipse.png", True, {}),
    "invert": ("ellipse.png", True, _HEIGHTMAP),
    "max_depth_mm": ("ellipse.png", "0.5", _HEIGHTMAP),
    "pixel_size_mm": ("ellipse.png", "0.2", _HEIGHTMAP),
    "heightmap_order": ("ellipse.png", "peel", _HEIGHTMAP),
}
"""A value of each option the page may set, on a file of a kind it applies to (a new option needs one here)."""

MOVES_NGC = "G21 G90\nG92 X0 Y0 Z0\nG1 Z0.5 F200\nG1 X5 Y5\nG1 X10 Y2\nG0 Z0\nM2\n"
"""A G-code program that moves either way in Y from where the tool stands (G92 there)."""


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path, settings=FAST, realtime=False)
    yield s
    s.close()


def test_every_option_of_the_schema_is_in_api_options(server):
    status, served = server.call("GET", "/api/options")
    assert status == 200
    assert [o["name"] for o in served] == [o.name for o in JOB_OPTIONS]
    defaults = kind_defaults()
    for o, record in zip(JOB_OPTIONS, served):
        assert record["label"] and record["help"] == o.help and record["unit"] == o.unit, o.name
        assert record["group"] in GROUPS and record["kinds"] == sorted(o.kinds), o.name
        assert (record["min"], record["max"], record["range"], record["choices"]) == (o.lo, o.hi, o.range_text(),
                                                                                       list(o.choices)), o.name
        assert set(record["defaults"]) == o.kinds, o.name
        for kind, value in record["defaults"].items():
            want = defaults.get(kind, {}).get(o.name, o.default)
            assert value == json.loads(json.dumps(want)), (o.name, kind)
    by_name = {o["name"]: o for o in served}
    assert by_name["cut_depth_mm"]["defaults"]["excellon"] == 2.0 and by_name["cut_depth_mm"]["unit"] == "mm"
    assert by_name["cut_depth_mm"]["defaults"]["drawing"] is None  # a drawing's depth is its own (depth, 10 Z px)


def test_a_new_option_of_the_schema_is_served_with_no_other_change(server, monkeypatch):
    import cam.options

    new = Option("coolant_pct", "--coolant", "whole", "%", frozenset({"excellon", "gcode"}), None,
                 "coolant flow in percent", lo=0, hi=100, group="Drill file")
    monkeypatch.setattr(cam.options, "JOB_OPTIONS", cam.options.JOB_OPTIONS + (new,))
    status, served = server.call("GET", "/api/options")
    assert status == 200
    record = served[-1]
    assert record["name"] == "coolant_pct" and record["label"] == "Coolant pct" and record["unit"] == "%"
    assert record["range"] == "0..100" and record["kinds"] == ["excellon", "gcode"] and record["web"] is True
    assert record["defaults"] == {"excellon": None, "gcode": None} and record["help"] == "coolant flow in percent"


def _library_options(name: str, value: object, more: dict) -> JobOptions:
    """The options the page's values stand for, as the library takes them (a profile by its path)."""
    return JobOptions.from_mapping({**more, name: str(value) if isinstance(value, Path) else value})


def test_every_option_set_through_the_page_api_is_planned_with_it(server, tmp_path):
    """The sweep: each option the page may set, sent as the form sends it, plans the job the library plans with
    it (the same step writes, time, depth and summary); an option whose value changes the plan changes it."""
    web = [o.name for o in JOB_OPTIONS if o.web]
    assert sorted(CASES) == sorted(web), "give each option of the page a case here"
    layer = prepare_job(SAMPLES / "logo.svg", JobOptions(), FAST).report["layers"][0]["name"]
    (tmp_path / "moves.ngc").write_text(MOVES_NGC)
    uploads: dict[str, str] = {}
    for name, (sample, value, more) in CASES.items():
        value = layer if value == SVG_LAYER else value
        path = SAMPLES / sample if (SAMPLES / sample).exists() else tmp_path / sample
        if sample not in uploads:
            status, up = server.upload(sample, path.read_bytes())
            assert status == 200, up
            uploads[sample] = up["job"]
        sent = value
        if isinstance(value, Path):  # a file the page uploads: sent by its upload id
            status, up = server.upload(value.name, value.read_bytes(), role="profile")
            assert status == 200, up
            sent = up["job"]
        # a G-code program runs from where the tool stands: from the middle of the travel, either way in Y
        here = (4000, 4000, 0) if sample.endswith(".ngc") else (0, 0, 0)
        server.session.set_position(here)
        status, planned = server.call("POST", "/api/plan", {"job": uploads[sample], "options": {**more, name: sent}})
        assert status == 200, (name, planned)
        state = MachineState(position_steps=here)
        want = prepare_job(path, _library_options(name, value, more), FAST, machine_state=state)
        assert (planned["writes"], planned["depth_mm"]) == (len(want.plan), want.depth_mm), name
        assert planned["estimated_time_s"] == pytest.approx(want.estimated_time_s, abs=1e-3), name
        try:
            without = len(prepare_job(path, JobOptions.from_mapping(more), FAST, machine_state=state).plan)
        except CamError:  # the file needs it (a 3D drawing's profile)
            continue
        if without != len(want.plan):  # the option changes the plan: the page's plan has it
            assert planned["writes"] != without, name


# -- in Chromium --------------------------------------------------------------------------------------------------

@pytest.fixture
def page(browser):  # noqa: F811
    ctx = browser.new_context(viewport={"width": 1280, "height": 900}, bypass_csp=True)  # wait_for_function evals
    p = ctx.new_page()
    p.set_default_timeout(60_000)
    yield p
    ctx.close()


def _shown(page, name: str) -> bool:
    return page.evaluate(f"""(() => {{ const w = document.querySelector('#options-fields [data-option="{name}"]');
        return !!w && w.offsetParent !== null; }})()""")


@pytest.mark.browser
def test_the_form_is_made_from_the_schema_and_its_values_reach_the_plan(page, tmp_path, monkeypatch):
    import cam.options

    new = Option("coolant_pct", "--coolant", "whole", "%", frozenset({"excellon"}), None, "coolant flow in percent",
                 lo=0, hi=100, group="Drill file")
    monkeypatch.setattr(cam.options, "JOB_OPTIONS", cam.options.JOB_OPTIONS + (new,))  # served, not planned
    s = Server(tmp_path, settings=FAST, realtime=False)
    try:
        page.goto(s.url + "/")
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        page.wait_for_selector("#opt-coolant")  # a new option of the schema: a field, no page code
        for o in cam.options.JOB_OPTIONS:  # before a file: every option has its field, under its group
            assert page.locator(f'#options-fields fieldset[data-group="{o.group}"] [data-option="{o.name}"]').count() \
                or o.name == "kind", o.name
        assert "(%, 0..100)" in page.text_content('[data-option="coolant_pct"]')
        # a drill file: the drill file's options, with their defaults; none of a drawing's
        with page.expect_response(lambda r: r.url.endswith("/api/plan")):
            page.set_input_files("#file", str(SAMPLES / "board.drl"))
        page.wait_for_function("!document.getElementById('start').disabled")
        for o in JOB_OPTIONS:
            if o.name != "kind":
                assert _shown(page, o.name) == ("excellon" in o.kinds), o.name
        assert _shown(page, "coolant_pct")
        assert page.get_attribute("#opt-cut-depth", "placeholder") == "2"  # the drill file's default depth
        assert "Cut depth (mm, > 0 and at most 10000)" in page.text_content('[data-option="cut_depth_mm"]')
        page.fill("#opt-cut-depth", "1.25")
        page.check("#opt-strict")
        with page.expect_response(lambda r: r.url.endswith("/api/plan")) as planned:
            page.click("#plan")
        assert planned.value.request.post_data_json["options"] == {"cut_depth_mm": "1.25", "strict": True}
        page.wait_for_function("document.getElementById('job-size').textContent.includes('depth 1.25')")
        want = prepare_job(SAMPLES / "board.drl", JobOptions(cut_depth_mm=1.25, strict=True), FAST)
        assert planned.value.json()["writes"] == len(want.plan)
        page.evaluate("window.scrollTo(0, 0)")
        page.screenshot(path=str(SHOT))  # the docs' picture (docs/web.md): the form at desktop size
        # out of range: the server refuses it in one line, shown in the error banner
        page.fill("#opt-cut-depth", "0")
        with page.expect_response(lambda r: r.url.endswith("/api/plan")) as refused:
            page.click("#plan")
        assert refused.value.status == 400
        page.wait_for_selector("#error:not([hidden])")
        text = page.text_content("#error-text")
        assert "option 'cut_depth_mm' must be > 0 and at most 10000 mm" in text and "\n" not in text
        # a drawing: its options show, the drill file's hide; a depth in Z pixels reaches the plan
        page.fill("#opt-cut-depth", "")
        with page.expect_response(lambda r: r.url.endswith("/api/plan")):
            page.set_input_files("#file", str(SAMPLES / "ellipse.png"))
        page.wait_for_function("!document.getElementById('start').disabled")
        for o in JOB_OPTIONS:
            if o.name != "kind":
                assert _shown(page, o.name) == ("drawing" in o.kinds), o.name
        assert not _shown(page, "coolant_pct")
        page.fill("#opt-depth", "3")
        page.select_option("#opt-heightmap-order", "peel")  # shown, but a height map's only: not sent unless set
        page.select_option("#opt-heightmap-order", "")
        with page.expect_response(lambda r: r.url.endswith("/api/plan")) as planned:
            page.click("#plan")
        assert planned.value.request.post_data_json["options"] == {"depth": "3"}
        want = prepare_job(SAMPLES / "ellipse.png", JobOptions(depth=(3,)), FAST)
        assert planned.value.json()["writes"] == len(want.plan)
        assert planned.value.json()["depth_mm"] == want.depth_mm
        # two depths: a rule between options (cam.options.RULES, served with the schema) refused by the page
        # itself, in the server's words, both fields marked, and nothing sent
        sent: list[str] = []
        page.on("request", lambda r: sent.append(r.url) if r.url.endswith("/api/plan") else None)
        page.fill("#opt-cut-depth", "0.1")
        page.click("#plan")
        page.wait_for_selector("#error:not([hidden])")
        text = page.text_content("#error-text")
        assert text.startswith("option 'cut_depth_mm' cannot be given together with depth: give the depth once"), text
        assert not sent
        marked = page.eval_on_selector_all("#options-fields .broken", "els => els.map(e => e.dataset.option)")
        assert sorted(marked) == ["cut_depth_mm", "depth"]
        page.fill("#opt-cut-depth", "")
        with page.expect_response(lambda r: r.url.endswith("/api/plan")) as planned:
            page.click("#plan")
        assert planned.value.status == 200 and not page.eval_on_selector_all("#options-fields .broken", "els => els.length")
    finally:
        s.close()
