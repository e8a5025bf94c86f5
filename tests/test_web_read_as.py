"""The page's "Read as" list (issue #31 point 1, ``--kind`` on the page): the plan route and the page read a file
as the kind asked, whatever its name and content say (here an Excellon file read as G-code gets the G-code
reader's own one-line error, and read as Excellon again plans its holes)."""
from __future__ import annotations

import pytest

from test_web import FAST, Server, _open, browser, page  # noqa: F401 (fixtures)

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_plan_route_reads_a_file_as_the_kind_asked'}

HOLES = "M48\nMETRIC\nT1C0.8\n%\nT1\nX10.0Y10.0\nX20.0Y10.0\nX20.0Y20.0\nM30\n"


def test_plan_route_reads_a_file_as_the_kind_asked(tmp_path):
    s = Server(tmp_path, settings=FAST, realtime=False)
    try:
        status, up = s.upload("holes.txt", HOLES.encode())
        assert status == 200 and up["kind"] == "excellon", up
        status, err = s.call("POST", "/api/plan", {"job": up["job"], "options": {"kind": "gcode"}})
        assert status == 400 and "has no number" in err["error"] and "holes.txt:2" in err["error"], err
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {"kind": "excellon"}})
        assert status == 200 and planned["kind"] == "excellon" and "3 holes" in planned["summary"], planned
        status, err = s.call("POST", "/api/plan", {"job": up["job"], "options": {"kind": "pdf"}})
        assert 400 <= status < 500 and "kind" in err["error"], err
    finally:
        s.close()


@pytest.mark.browser
def test_page_read_as(page, tmp_path):  # noqa: F811
    s = Server(tmp_path, settings=FAST, realtime=False)
    try:
        _open(page, s)
        f = tmp_path / "holes.txt"
        f.write_text(HOLES)
        page.set_input_files("#file", str(f))
        page.wait_for_function("document.getElementById('job-summary').textContent.includes('3 holes')")
        page.select_option("#read-as", "gcode")
        page.wait_for_function("document.getElementById('error-text').textContent.includes('has no number')")
        page.select_option("#read-as", "excellon")
        page.wait_for_function("document.getElementById('job-summary').textContent.includes('3 holes')")
        assert page.is_visible("#opt-drill-order")  # the drill file's options show
    finally:
        s.close()
