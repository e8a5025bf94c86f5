"""Numbers are numbers (issue #43 point 8): every coordinate, step count and percent the web API takes is a finite
number of its documented type, checked after its unit's conversion, by the machine session itself (one validator,
:mod:`cam.values`, for the API, the CLI and the Python API).  Text, booleans, infinity and counts that overflow
once converted to steps get a one-line 400 naming the field, and nothing moves."""
from __future__ import annotations

import json

import pytest

from cam.drive.session import MachineSession
from cam.errors import PlanError
from conftest import run_cli
from test_web import FAST, Server, servers, fast  # noqa: F401 (fixtures)


def _post_text(server, path: str, text: str):
    """POST a JSON text as it is (Infinity and NaN as JavaScript's JSON.stringify never sends them)."""
    return server.call("POST", path, raw=text.encode(), headers={"Content-Type": "application/json"})


def _refused(server, status, reply, *words: str) -> None:
    """A one-line 400 naming ``words``; nothing moved, nothing runs."""
    assert status == 400, (status, reply)
    error = reply["error"]
    assert "\n" not in error and "Traceback" not in error and len(error) < 300, error
    for w in words:
        assert w in error, (w, error)
    assert not server.session.busy and server.session.position_steps() == (0, 0, 0)


def test_api_jog_1e308_mm_is_refused(fast):
    for unit in ("mm", "0.1mm", "0.1in"):
        status, reply = fast.call("POST", "/api/jog", {"axis": "x", "steps": 1e308, "unit": unit})
        _refused(fast, status, reply, "steps", "at most 100000 steps", f"1e+308 {unit}")
    # in steps, and as an integer too large for a float (the JSON text itself)
    status, reply = fast.call("POST", "/api/jog", {"axis": "y", "steps": 1e308, "unit": "steps"})
    _refused(fast, status, reply, "steps", "at most 100000 steps")
    status, reply = _post_text(fast, "/api/jog", '{"axis": "z", "steps": 1' + "0" * 400 + ', "unit": "mm"}')
    _refused(fast, status, reply, "steps must be a finite number")
    # just over the longest jog after the conversion: refused; a jog within it still runs
    over_mm = (100_000 + 1) * FAST.mm_per_step_xy
    status, reply = fast.call("POST", "/api/jog", {"axis": "x", "steps": over_mm, "unit": "mm"})
    _refused(fast, status, reply, "at most 100000 steps")
    status, reply = fast.call("POST", "/api/jog", {"axis": "x", "steps": 1, "unit": "mm"})
    assert status == 200, reply
    fast.wait_idle()
    assert fast.session.position_steps() == (round(1 / FAST.mm_per_step_xy), 0, 0)
    fast.session.set_position((0, 0, 0))


@pytest.mark.parametrize("steps", ["5", True, None, [5], {"n": 5}, "NaN", "-Infinity"])
def test_api_jog_steps_must_be_a_number(fast, steps):
    text = json.dumps({"axis": "x", "unit": "steps"})[:-1] + ', "steps": ' + (
        steps if steps in ("NaN", "-Infinity") else json.dumps(steps)) + "}"
    status, reply = _post_text(fast, "/api/jog", text)
    _refused(fast, status, reply, "steps must be a")


def test_api_feed_override_infinity_is_refused(fast):
    for value in ("Infinity", "-Infinity", "NaN", "1e308", "1" + "0" * 400, "true", '"150"', "[150]", "null"):
        status, reply = _post_text(fast, "/api/feed-override", '{"percent": ' + value + "}")
        _refused(fast, status, reply, "percent must be")
    status, reply = fast.call("POST", "/api/feed-override", {"percent": 250})
    _refused(fast, status, reply, "percent must be 10..200 %")
    # a good number on a port with no feed override: the port's refusal (409), not the number's
    status, reply = fast.call("POST", "/api/feed-override", {"percent": 150})
    assert status == 409 and "grbl" in reply["error"], reply


def test_api_goto_string_xyz_is_refused(fast):
    for xyz in ("123", "1,2,3", {"x": 1, "y": 2, "z": 3}, [1, 2], [1, 2, 3, 4], ["1", "2", "3"], None):
        status, reply = fast.call("POST", "/api/goto", {"xyz": xyz, "unit": "mm"})
        _refused(fast, status, reply, "xyz")


def test_api_goto_booleans_refused(fast):
    for xyz in ([True, False, True], [1, 0, True]):
        status, reply = fast.call("POST", "/api/goto", {"xyz": xyz, "unit": "mm"})
        _refused(fast, status, reply, "must be a number, got True")
    status, reply = fast.call("POST", "/api/goto", {"xyz": [1, 0, 0], "unit": "mm", "machine": "yes"})
    _refused(fast, status, reply, "machine must be true or false")


def test_api_goto_is_checked_after_the_unit_conversion(fast):
    for xyz, unit, words in (([1e308, 0, 0], "mm", "xyz X must be at most"), ([0, 1e300, 0], "mm", "xyz Y"),
                             ([0, 0, 2e9], "steps", "xyz Z must be at most 1000000000 steps")):
        status, reply = fast.call("POST", "/api/goto", {"xyz": xyz, "unit": unit})
        _refused(fast, status, reply, words)
    status, reply = _post_text(fast, "/api/goto", '{"xyz": [0, Infinity, 0]}')
    _refused(fast, status, reply, "xyz Y must be a finite number")
    status, reply = fast.call("POST", "/api/goto", {"xyz": [1, 0, 0], "unit": 5})
    _refused(fast, status, reply, "unit must be")
    # numbers of the right type still go
    status, reply = fast.call("POST", "/api/goto", {"xyz": [1, 0.5, 0], "unit": "mm"})
    assert status == 200, reply
    fast.wait_idle()
    mm = FAST.mm_per_step_xy
    assert fast.session.position_steps() == (round(1 / mm), round(0.5 / mm), 0)
    fast.session.set_position((0, 0, 0))


def test_api_zero_answer_and_drill_z_take_their_types_only(fast):
    for path, body, words in (("/api/zero", {"axes": ["X"]}, "axes must be"), ("/api/zero", {"axes": True}, "axes"),
                              ("/api/answer", {"prompt": True}, "prompt must be a number"),
                              ("/api/answer", {"prompt": "1"}, "prompt must be a number"),
                              ("/api/answer", {"prompt": 1.5}, "prompt must be a whole number"),
                              ("/api/answer", {"prompt": 1, "action": ["stop"]}, "action must be")):
        status, reply = fast.call("POST", path, body)
        _refused(fast, status, reply, words)


def test_api_work_offsets_take_names_and_numbers_of_their_type(tmp_path):
    s = Server(tmp_path, settings=FAST, state_file=str(tmp_path / "m.json"))
    try:
        start = s.session.position_steps()
        for path, body, words in (("/api/use-offset", {"offset": ["G55"]}, "offset must be one of"),
                                  ("/api/use-offset", {"offset": 55}, "offset must be one of"),
                                  ("/api/zero", {"axes": "XY", "offset": ["G55"]}, "offset must be one of"),
                                  ("/api/goto", {"xyz": "000"}, "xyz must be a list of 3 numbers")):
            status, reply = s.call("POST", path, body)
            assert status == 400 and words in reply["error"] and "\n" not in reply["error"], (path, reply)
        assert s.session.where()["active_offset"] == "G54" and s.session.position_steps() == start
        status, reply = s.call("POST", "/api/use-offset", {"offset": "G55"})
        assert status == 200 and reply["where"]["active_offset"] == "G55", reply
    finally:
        s.close()


def test_the_session_checks_the_numbers_for_every_front_end():
    """The library does the checking (the API's handlers and the CLI pass the values on as given)."""
    session = MachineSession("mock", FAST)
    cases = [(session.jog, ("x", 1e308, "mm"), "steps must be at most 100000 steps"),
             (session.jog, ("x", "5", "mm"), "steps must be a number"),
             (session.go_to, ("123",), "xyz must be a list of 3 numbers"),
             (session.go_to, ([True, False, True],), "xyz X must be a number, got True"),
             (session.feed_override, (float("inf"),), "percent must be a finite number"),
             (session.set_position, ((1.5, 0, 0),), "position X must be a whole number"),
             (session.set_position, ((True, 0, 0),), "position X must be a number"),
             (session.set_position, ((0, 0, 10 ** 12),), "position Z must be")]
    for method, args, words in cases:
        with pytest.raises(PlanError, match="^" + words.replace("(", r"\(")):
            method(*args)
    assert session.position_steps() == (0, 0, 0) and not session.busy


@pytest.mark.parametrize("amount, words", [("1e308", "STEPS must be a number"),
                                           ("1e9", "at most 1000000000 steps either way")])
def test_cli_jog_of_too_many_steps_is_one_line_error(tmp_path, amount, words):
    """The flag's own range, then the library's after the conversion (1e9 mm is 3.5e10 steps)."""
    r = run_cli("jog", "X+", amount, "--unit", "mm", "--state", tmp_path / "m.json", cwd=tmp_path)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert words in r.stderr, r.stderr


def test_api_job_options_refuse_booleans_infinity_and_absurd_tools(fast):
    """Job options keep their documented forms (numbers, or numbers as the form's text); a boolean for a number,
    NaN or infinity, and the V bit of 1e-308 degrees (issue #43 point 8) get a one-line 400 naming the option."""
    from conftest import SAMPLES

    status, up = fast.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
    assert status == 200, up
    for options, words in (('{"depth": true}', "option 'depth' must be a whole number"),
                           ('{"passes": 1.5}', "option 'passes' must be a whole number"),
                           ('{"stepover": Infinity}', "option 'stepover' must be a finite number"),
                           ('{"cut_depth_mm": NaN}', "option 'cut_depth_mm' must be a finite number"),
                           ('{"tool": "v:1e-308:0", "line_width_mm": 0.3}', "angle must be 1..179 degrees")):
        status, reply = _post_text(fast, "/api/plan", f'{{"job": "{up["job"]}", "options": {options}}}')
        _refused(fast, status, reply, words)
    status, reply = fast.call("POST", "/api/plan", {"job": up["job"], "options": {"depth": "2"}})  # the form's text
    assert status == 200, reply
