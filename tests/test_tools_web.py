"""The page's tool select (issue #19): the options reach JobOptions.from_mapping, the plan is the library's, and
the page names the cutter.  Browser tests drive Debian's Chromium through Playwright, as tests/test_web.py does."""
from __future__ import annotations

import pytest

import cam
from cam.errors import CamError
from cam.kinds.jobs import JobOptions, prepare_job

from conftest import ROOT, SAMPLES

from test_web import FAST, Server, browser  # noqa: E402,F401  (the real server on a free port, in a thread;
# the browser fixture: Debian chromium through Playwright)

SLOW_CASES = {'test_api_plan_names_the_tool'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

DOME = ROOT / "profiles" / "dome.png"


def test_from_mapping_takes_tool_and_line_width():
    o = JobOptions.from_mapping({"tool": "ball:1", "profile": str(DOME)})
    assert o.tool == "ball:1"
    o = JobOptions.from_mapping({"tool": "v:60:0.1", "line_width_mm": "0.3"})
    assert o.tool == "v:60:0.1" and o.line_width_mm == pytest.approx(0.3)
    with pytest.raises(CamError, match="tool"):
        JobOptions.from_mapping({"tool": "drill:3"})
    with pytest.raises(CamError, match="line_width_mm"):
        JobOptions.from_mapping({"tool": "v:60:0.1", "line_width_mm": "0.3", "depth": "4"})


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = Server(tmp_path_factory.mktemp("web-tools"), settings=FAST, realtime=True)
    yield s
    s.close()


def test_api_plan_names_the_tool(server):
    status, up = server.upload("disc.png", (SAMPLES / "disc.png").read_bytes())
    assert status == 200
    status, prof = server.upload("dome.png", DOME.read_bytes(), role="profile")
    assert status == 200
    status, r = server.call("POST", "/api/plan", {"job": up["job"], "options": {"profile": prof["job"],
                                                                                "tool": "ball:1"}})
    assert status == 200, r
    assert r["tool"] == "ball 1 mm"
    status, r = server.call("POST", "/api/plan", {"job": up["job"], "options": {"profile": prof["job"],
                                                                                "tool": "ball:-1"}})
    assert status == 400 and "tool" in r["error"]


@pytest.fixture
def page(browser):
    ctx = browser.new_context(viewport={"width": 390, "height": 844}, bypass_csp=True)  # wait_for_function evals
    p = ctx.new_page()
    p.set_default_timeout(60_000)
    yield p
    ctx.close()


def _open(page, server) -> None:
    page.goto(server.url + "/")
    page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")


@pytest.mark.browser
def test_page_ball_tool_plans_a_3d_job_that_names_it(page, server):
    _open(page, server)
    # only the inputs of the chosen shape show
    assert page.is_hidden("#opt-tool-diameter") and page.is_hidden("#opt-tool-angle")
    page.select_option("#opt-tool-shape", "ball")
    assert page.is_visible("#opt-tool-diameter") and page.is_hidden("#opt-tool-angle")
    page.fill("#opt-tool-diameter", "1")
    page.set_input_files("#profile-file", str(DOME))
    page.wait_for_function("document.getElementById('profile-name').textContent.includes('dome.png')")
    with page.expect_response(lambda r: r.url.endswith("/api/plan")) as planned:
        page.set_input_files("#file", str(SAMPLES / "disc.png"))
    r = planned.value.json()
    page.wait_for_function("!document.getElementById('start').disabled")
    page.wait_for_function("document.getElementById('job-cutter').textContent === 'ball 1 mm'")
    # the server's plan is the library's plan of the same file with the same tool, whose report names the tool
    want = prepare_job(SAMPLES / "disc.png", JobOptions(profile=str(DOME), tool="ball:1"), FAST)
    assert r["tool"] == want.report["tool"] == "ball 1 mm"
    assert r["writes"] == len(want.plan) and r["estimated_time_s"] == pytest.approx(want.estimated_time_s, abs=1e-3)
    assert want.toolpath.tool == cam.tool.parse_tool("ball:1")
    # not the point tool's plan: the ball cannot follow the dome everywhere (drop-cutter rule)
    point = prepare_job(SAMPLES / "disc.png", JobOptions(profile=str(DOME)), FAST)
    assert r["writes"] != len(point.plan) and "tool" not in point.report
    assert want.toolpath.points_steps[:, 2].max() <= point.toolpath.points_steps[:, 2].max()


@pytest.mark.browser
def test_page_v_bit_line_width_sets_a_2d_depth(page, server):
    _open(page, server)
    page.select_option("#opt-tool-shape", "v")
    assert page.is_visible("#opt-tool-angle") and page.is_visible("#opt-line-width")
    page.fill("#opt-tool-angle", "60")
    page.fill("#opt-tool-tip", "0.1")
    page.fill("#opt-tool-diameter", "")
    page.fill("#opt-line-width", "0.3")
    page.set_input_files("#file", str(SAMPLES / "ellipse.png"))
    page.wait_for_function("document.getElementById('job-cutter').textContent.includes('lines')")
    text = page.text_content("#job-cutter")
    want = prepare_job(SAMPLES / "ellipse.png", JobOptions(tool="v:60:0.1", line_width_mm=0.3), FAST)
    assert text == f"{want.report['tool']}, lines {want.report['line_width_mm']:.3f} mm wide"


@pytest.mark.browser
def test_page_tool_spec_field_wins_and_bad_spec_is_an_error(page, server):
    _open(page, server)
    page.select_option("#opt-tool-shape", "ball")
    page.fill("#opt-tool-spec", "flat:0.5")
    page.set_input_files("#profile-file", str(DOME))
    page.wait_for_function("document.getElementById('profile-name').textContent.includes('dome.png')")
    page.set_input_files("#file", str(SAMPLES / "disc.png"))
    page.wait_for_function("document.getElementById('job-cutter').textContent === 'flat 0.5 mm'")
    page.fill("#opt-tool-spec", "cone:3")
    page.click("#plan")
    page.wait_for_selector("#error:not([hidden])")
    assert "tool" in page.text_content("#error-text")

