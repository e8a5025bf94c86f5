"""Small things a user meets (issue #44 point 7).

* a value that starts with a negative number (``cam where --set -200,20,0``, ``cam goto -10,0,0``) is a value,
  not an unknown option, after every option and as a positional;
* ``--start thesis``: the thesis's own Min Distance rule (section 4.1.4.2), every object at its point nearest the
  origin, beside cam's ``min-distance`` (nearest the tool); the order changes, the cut surface does not;
* the mock's unknown-position error says how to start the simulated machine again (``cam where --set=0,0,0``).

(The docs' half of the point is in tests/test_docs.py.)
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

import cam
from cam.cli.parser import build_parser
from cam.digitize.trace2d import START_RULES
from cam.drive.state import MachineState, StateHold, read_state, unknown_message, write_state
from cam.kinds import job_options, schema_json
from cam.settings import load_settings
from conftest import (assert_surface_equal, carve_job, drawing_from_rows, expected_surface_2d, ok, one_line_error,
                      run_cli)

JOB_OPTIONS = job_options()
"""Every option, its kinds filled in from the file kinds' traits (cam.kinds)."""

S = cam.MachineSettings()


# -- negative numbers after an option -------------------------------------------------------------------------

def test_where_set_takes_negative_numbers(tmp_path):
    """``--set -200,20,0`` (a space, not ``=``) is the position, as ``--set=-200,20,0`` is: on a machine whose
    travel reaches X -200 mm it is recorded; then goto's positional and zero's --at take negatives too."""
    machine = tmp_path / "mill.toml"
    machine.write_text("[travel]\nx_min_steps = -10000\n")
    st, m = tmp_path / "m.json", load_settings(machine)
    ok(run_cli("where", "--set", "-200,20,-1", "--machine", machine, "--state", st))
    assert read_state(st, m).position_steps == (-6920, 692, -64)  # 200 / 0.0289 mm, -1 / 0.0157 mm (up)
    ok(run_cli("where", "--set=-100,0,0", "--machine", machine, "--state", st))
    assert read_state(st, m).position_steps == (-3460, 0, 0)
    ok(run_cli("zero", "--at", "-50,0,0", "--machine", machine, "--state", st))
    assert read_state(st, m).offsets_steps["G54"] == (-1730, 0, 0)
    out = ok(run_cli("goto", "-10,0,-1", "--unit", "mm", "--machine", machine, "--state", st)).stdout
    assert read_state(st, m).position_steps == (-1730 - 346, 0, -64), out
    rep = json.loads(ok(run_cli("where", "--json", "--machine", machine, "--state", st)).stdout)
    assert rep["work_steps"] == [-346, 0, -64]
    # outside the default machine's travel: the travel says so, not argparse
    one_line_error(run_cli("where", "--set", "-200,20,0", "--state", tmp_path / "d.json"), "--set -200,20,0 mm",
                   "X travel")
    # a word that is no number is still no value, and a mistyped option is still refused
    one_line_error(run_cli("where", "--set", "-x", "--state", st), "--set", "expected one argument")
    one_line_error(run_cli("where", "-200x", "--state", st), "unrecognized arguments: -200x")


def _value_options() -> list[tuple[list[str], list[str], str, object]]:
    """(argv with a space, the same with ``=`` (or as it is: a positional), dest, parsed value or None: any
    negatives) of every job option whose value may start with a negative number, and of the machine commands'
    coordinates."""
    cases: list[tuple[list[str], list[str], str, object]] = []
    for o in JOB_OPTIONS:
        if o.type in ("wholes", "numbers", "points", "whole", "number") and o.lo is not None and o.lo < 0:
            text = "-1,-2" if o.type == "points" else ",".join(["-1"] * (o.count or 1))
            cases.append((["drill", "x.png", o.flag, text], ["drill", "x.png", f"{o.flag}={text}"], o.dest, None))
    cases += [(["where", "--set", "-200,20,-1.5"], ["where", "--set=-200,20,-1.5"], "set", [-200.0, 20.0, -1.5]),
              (["zero", "--at", "-1,-2,-3"], ["zero", "--at=-1,-2,-3"], "at", [-1.0, -2.0, -3.0]),
              (["goto", "-1e1,-.5,0"], ["goto", "--", "-1e1,-.5,0"], "position", [-10.0, -0.5, 0.0]),
              (["goto", "--machine-coords", "-3,-2,-1"], ["goto", "--machine-coords", "--", "-3,-2,-1"], "position",
               [-3.0, -2.0, -1.0])]
    return cases


def test_every_option_taking_coordinates_takes_a_negative_first_number():
    """Each job option that allows negatives (--start-at, --pause-at, --offset, ...) and the machine commands'
    X,Y,Z take a value starting with ``-`` after a space, as with ``=`` (or after ``--``)."""
    cases = _value_options()
    assert {argv[2] for argv, _, _, _ in cases if argv[0] == "drill"} >= {"--start-at", "--pause-at", "--offset"}
    for argv, same, dest, want in cases:
        got = getattr(build_parser().parse_args(argv), dest)
        assert got == getattr(build_parser().parse_args(same), dest), argv
        if want is not None:
            assert got == want, argv
        else:
            assert float(np.ravel(got)[0]) < 0, (argv, got)


# -- --start thesis: the thesis's own Min Distance rule -------------------------------------------------------

ROWS = [
    "....................",
    "............##......",
    "...........#..#.....",
    "............##......",
    "....................",
    "...##...............",
    "..#..#......######..",
    "...##...............",
    "....................",
    "......#.............",
    "......#.............",
    ".......#####........",
    "....................",
]
"""Two closed rings, a bar and an open hook, placed so that the three start rules give three orders."""


def _d2(p) -> int:
    return int(p[0]) ** 2 + int(p[1]) ** 2


def test_start_thesis_rule_starts_each_object_nearest_the_origin():
    img = drawing_from_rows(ROWS)
    objects = cam.digitize(img, start="thesis").objects
    assert len(objects) == 4
    left = {tuple(p) for o in objects for p in o.tolist()}
    for obj in objects:
        pts = [tuple(p) for p in obj.tolist()]
        nearest = min(_d2(p) for p in left)
        # the object is the one holding the untraced black pixel nearest the origin ...
        assert min(_d2(p) for p in pts) == nearest
        closed = max(abs(pts[0][0] - pts[-1][0]), abs(pts[0][1] - pts[-1][1])) <= 1 and len(pts) > 2
        if closed:  # ... and a ring starts at that pixel
            assert _d2(pts[0]) == nearest, pts
        else:  # ... an open curve at its end nearer the origin (cam traces it end to end)
            assert _d2(pts[0]) <= _d2(pts[-1]), pts
        left -= set(pts)
    assert not left
    starts = [tuple(o[0].tolist()) for o in objects]
    assert [_d2(p) for p in starts] == sorted(_d2(p) for p in starts)  # in order of their distance
    # not cam's min-distance (from where the tool stands), nor top (scan order)
    orders = {s: [tuple(o[0].tolist()) for o in cam.digitize(img, start=s).objects] for s in START_RULES}
    assert len({tuple(v) for v in orders.values()}) == 3, orders
    assert orders["min-distance"][0] == orders["thesis"][0]  # the first object: the tool starts at the origin


def test_start_thesis_cuts_the_same_surface_and_reaches_every_command(tmp_path):
    """Every start rule cuts exactly what the drawing asks (carved from the mock's pin log); --start thesis goes
    through cam digitize and cam drill (the streaming planner's objects are the traced ones, in that order)."""
    img = drawing_from_rows(ROWS)
    want = None
    for start in START_RULES:
        d = cam.digitize(img, start=start)
        surface, _, _ = carve_job(cam.plan(d, depth=3))
        expected = expected_surface_2d(d, [3] * len(d.objects), S)
        assert_surface_equal(surface, expected)
        want = expected if want is None else want
        assert_surface_equal(surface, want)
    png = tmp_path / "rows.png"
    import cv2

    cv2.imwrite(str(png), img)
    ok(run_cli("digitize", png, "-o", tmp_path / "m.txt", "--start", "thesis"))
    loaded = cam.load_digitized(tmp_path / "m.txt")
    assert [o.tolist() for o in loaded.objects] == [o.tolist() for o in cam.digitize(img, start="thesis").objects]
    report = tmp_path / "r.json"
    ok(run_cli("drill", png, "--start", "thesis", "--depth", "3", "--report", report, "--yes"))
    assert json.loads(report.read_text())["objects"] == 4
    job = cam.prepare_job(png, cam.JobOptions(start="thesis", depth=(3,)))
    assert [o.tolist() for o in job.digitized.objects] == [o.tolist() for o in loaded.objects]
    one_line_error(run_cli("drill", png, "--start", "origin"), "--start", "thesis")


def test_the_page_offers_every_choice_of_the_schema():
    """The page builds its selects of job options from the schema it is served (GET /api/options; issue #47 point
    6): every choice option reaches it with exactly the schema's choices (--start thesis on the page too), and the
    page's HTML holds no select of its own for a job option."""
    served = {record["name"]: record for record in schema_json()}
    choice_options = [o for o in JOB_OPTIONS if o.type == "choice"]
    for o in choice_options:
        assert served[o.name]["type"] == "choice" and served[o.name]["choices"] == list(o.choices), o.name
    assert "thesis" in served["start"]["choices"] and len(choice_options) >= 1
    html = (Path(cam.__file__).parent / "web" / "static" / "index.html").read_text()
    names = set(re.findall(r'<select[^>]* name="(\w+)"', html))
    assert not names & {o.name for o in JOB_OPTIONS if o.web}, names


# -- the mock's unknown position -------------------------------------------------------------------------------

def test_mock_unknown_position_says_how_to_recover(tmp_path):
    """A command killed on the mock (its running marker left behind, as a timeout's SIGKILL leaves it) makes the
    position unknown; the error says, on the mock, the command that starts the simulated machine at its home
    again, and that command works as written."""
    st = tmp_path / "m.json"
    write_state(st, MachineState(position_steps=(50, 0, 0)))
    with StateHold(st, S) as hold:  # a command that starts driving, then vanishes without recording
        hold.mark_running("cam drill part.png")
    line = one_line_error(run_cli("goto", "1,1,0", "--state", st), "position is unknown", "on the mock",
                          "cam where --set=0,0,0", "cam home")
    advice = re.search(r"cam (where --set=\S+?)(?:,? or|$)", line)
    assert advice, line
    ok(run_cli(*advice.group(1).split(), "--state", st))
    assert read_state(st, S).position_known and read_state(st, S).position_steps == (0, 0, 0)
    ok(run_cli("goto", "1,1,0", "--state", st))
    assert read_state(st, S).position_steps == (8, 8, 0)
    # a real machine's error does not send the user to the mock's home
    lost = MachineState().lost("a killed command")
    for port in ("/dev/parport0", "grbl:/dev/ttyUSB0", "maximus:/dev/ttyUSB0"):
        assert "mock" not in unknown_message(lost, port) and "cam where --set X,Y,Z" in unknown_message(lost, port)
    assert "cam where --set=0,0,0" in unknown_message(lost, "mock") == unknown_message(lost)
    # every port: what works, for the page and the command line alike, in one line (issue #45 point 3)
    for port in ("mock", "/dev/parport0", "grbl:/dev/ttyUSB0", "maximus:/dev/ttyUSB0"):
        line = unknown_message(lost, port)
        assert "\n" not in line and "Set position on the page" in line and "cam where --set X,Y,Z" in line, line
        assert "a jog is allowed meanwhile to find the work (soft limits off)" in line, line
        can_home = not port.startswith("maximus:")  # the MAXIMUS board has no switches cam reads
        assert ("Home on the page" in line and "(cam home)" in line) == can_home, line
        assert ("cannot home" in line) != can_home, line
