"""No 500 and no traceback for any value (issue #33 point 6): every JSON route of `cam serve` and every flag of
`cam drill` is swept with NaN, +-inf, 1e308, 10^30, 10^4000, lists, objects and empty strings; each answer is a
2xx or a 4xx with a JSON error (a one-line error and exit code 2 from the CLI), and nothing moves on a refusal."""
import json

import pytest

from cam.kinds import job_options

from conftest import SAMPLES, run_cli
from test_web import servers, fast, FAST  # noqa: F401 (fixtures)

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_every_job_option_takes_any_json_value_without_a_500'}

WEIRD_JSON = ["NaN", "Infinity", "-Infinity", "1e308", "-1e308", "1" + "0" * 30, "1" + "0" * 4000, "[]", "{}", '""',
              "[1, [2, [3, []]]]", '{"a": {"b": {"c": {}}}}', "null", "true", '"x"', "-1", "0"]
"""JSON texts of the values swept (NaN and Infinity as Python's json writes them; 10^4000 as a bare integer)."""
ROUTES = {"/api/plan": ("job", "options"), "/api/start": ("job",), "/api/jog": ("axis", "steps", "unit"),
          "/api/resume-job": ("job", "journal"), "/api/drill-z": ("which",), "/api/answer": ("prompt", "action"),
          "/api/pause": (), "/api/resume": (), "/api/stop": (), "/api/estop": ()}
"""The JSON routes and the fields they read (go to the origin and offset are left out: they move or zero the
machine when asked in any way at all)."""


def _post(server, path: str, text: str):
    return server.call("POST", path, raw=text.encode(), headers={"Content-Type": "application/json"})


def _checked(status, reply, what) -> None:
    assert status < 500, (what, status, reply)
    if status >= 400:
        assert isinstance(reply, dict) and isinstance(reply.get("error"), str) and reply["error"], (what, reply)
        assert "\n" not in reply["error"] and "Traceback" not in reply["error"], (what, reply)


def test_every_route_and_field_takes_any_json_value_without_a_500(fast):
    status, up = fast.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
    assert status == 200, up
    job = up["job"]
    for path, names in ROUTES.items():
        for value in WEIRD_JSON:
            _checked(*_post(fast, path, value), (path, "body", value[:20]))  # the body itself
            for name in names:
                body = {"job": job, "axis": "x", "steps": 0} if path in ("/api/plan", "/api/jog") else {}
                text = json.dumps(body)[:-1] + (", " if body else "") + f'"{name}": {value}}}'
                status, reply = _post(fast, path, text)
                _checked(status, reply, (path, name, value[:20]))
                if status != 200:
                    assert not fast.session.busy and fast.session.position_steps() == (0, 0, 0), (path, name)
                fast.session.wait_idle()
                if fast.session.position_steps() != (0, 0, 0):  # an accepted move: back home for the next one
                    fast.session.set_position((0, 0, 0))


def test_every_job_option_takes_any_json_value_without_a_500(fast):
    status, up = fast.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
    job = up["job"]
    for option in job_options():
        for value in WEIRD_JSON:
            text = f'{{"job": "{job}", "options": {{"{option.name}": {value}}}}}'
            _checked(*_post(fast, "/api/plan", text), (option.name, value[:20]))
    assert not fast.session.busy and fast.session.position_steps() == (0, 0, 0)


WEIRD_ARGS = ["nan", "inf", "-inf", "1e308", "1" + "0" * 30, "1" + "0" * 4000, "[]", "{}", "", "-1", "0,0,0,0"]
SAMPLE_OF_KIND = {"drawing": "two_curves.png", "digitized": "two_curves.png", "excellon": "board.drl",
                  "hpgl": "inkscape_star.plt", "svg": "logo.svg", "gcode": "bolt_plate.ngc", "dxf": "bracket.dxf"}


@pytest.mark.slow
def test_every_drill_flag_takes_any_value_without_a_traceback(tmp_path):
    for option in job_options():  # with the kinds their traits give (cam.kinds)
        if option.type == "flag":
            continue
        sample = SAMPLES / SAMPLE_OF_KIND[sorted(option.kinds)[0]]
        for value in WEIRD_ARGS:
            r = run_cli("drill", sample, f"{option.flag}={value}", "--yes", cwd=tmp_path)
            assert r.returncode in (0, 2), (option.flag, value[:20], r.returncode, r.stderr[-500:])
            assert "Traceback" not in r.stderr and "internal error" not in r.stderr, (option.flag, r.stderr[-500:])
            if r.returncode == 2:
                errors = [line for line in r.stderr.splitlines() if "error" in line]
                assert len(errors) == 1, (option.flag, value[:20], r.stderr[-500:])
