"""The job options' one declaration (``cam/options.py``, issue #28 point 6) is what the CLI, ``JobOptions`` and the
page use: the same names, flags, kinds and ranges everywhere."""
from __future__ import annotations

import argparse
import asyncio
import contextlib
import io
import json
import re
from dataclasses import fields
from pathlib import Path
from typing import Any, Optional

import pytest

from cam.cli.checks import check_args
from cam.cli.parser import build_parser
from cam.errors import CamError
from cam.kinds.jobs import JobOptions
from cam.kinds import job_options, schema_json
from cam.options import Option, degenerate

from conftest import SAMPLES, run_cli

JOB_OPTIONS = job_options()
"""Every option, the kinds it applies to filled in from the kinds' traits (cam.kinds)."""

KIND_FILES = {
    "drawing": SAMPLES / "gear.png", "excellon": SAMPLES / "board.drl", "hpgl": SAMPLES / "extended.plt",
    "gcode": SAMPLES / "bolt_plate.ngc", "svg": SAMPLES / "logo.svg", "dxf": SAMPLES / "bracket.dxf",
    "digitized": Path("no-such-matrix.txt"),  # kind by suffix; refused before it would be read
}
"""A file of each job kind."""


def sample_value(o: Option) -> Optional[str]:
    """A value in range for the option's flag (None: a flag without a value)."""
    one = {"whole": str(int(o.lo)) if o.lo is not None else "1", "number": "1", "wholes": ",".join(["1"] * (o.count or 1)),
           "numbers": ",".join(["1"] * (o.count or 1)), "points": "1,1", "digits": "2:4", "size": "80x40",
           "text": "k", "tool": "flat:1", "paths": ".", "flag": None}
    return o.choices[-1] if o.type == "choice" else one[o.type]


def _flag_argv(o: Option, value: Optional[str] = None) -> str:
    """``FLAG=VALUE`` (with ``=``: a value such as -1,-1,-1 is no flag to argparse), or the flag of an on/off one."""
    value = sample_value(o) if value is None else value
    return o.flag if o.type == "flag" else f"{o.flag}={value}"


def needed(o: Option, kind: str) -> list[Option]:
    """The options ``o`` needs given with it by :data:`cam.options.RULES` (the first of each "needs" rule's others
    that applies to ``kind``)."""
    from cam.options import RULES

    by_name = {option.name: option for option in JOB_OPTIONS}  # with their kinds (cam.kinds)
    return [next(by_name[n] for n in r.others if kind in by_name[n].kinds)
            for r in RULES if r.option == o.name and r.kind == "needs"]


def argv_of(o: Option, path: Path, value: Optional[str] = None, kind: Optional[str] = None) -> list[str]:
    """``cam drill PATH FLAG=VALUE``, with the flags the option needs (:func:`needed`) on a file of ``kind``."""
    return ["drill", str(path), _flag_argv(o, value), *(_flag_argv(n) for n in needed(o, kind or ""))] if kind \
        else ["drill", str(path), _flag_argv(o, value)]


def test_every_joboptions_field_has_exactly_one_schema_entry():
    names = [o.name for o in JOB_OPTIONS]
    assert len(names) == len(set(names))
    assert names == [f.name for f in fields(JobOptions)]
    assert {f.name: f.default for f in fields(JobOptions)} == {o.name: o.default for o in JOB_OPTIONS}
    assert len({o.flag for o in JOB_OPTIONS}) == len(JOB_OPTIONS)


def test_the_defaults_are_the_libraries():
    from cam.digitize.sketch import DEFAULT_MIN_LENGTH_PX
    from cam.limits import DEFAULT_GCODE_LINES

    assert JobOptions().trace_min_length_px == DEFAULT_MIN_LENGTH_PX
    assert JobOptions().max_lines == DEFAULT_GCODE_LINES


def test_every_schema_flag_is_in_drill_help():
    out = run_cli("drill", "--help")
    assert out.returncode == 0
    for o in JOB_OPTIONS:
        assert re.search(rf"(?<![\w-]){re.escape(o.flag)}(?![\w-])", out.stdout), o.flag


@pytest.mark.parametrize("o", JOB_OPTIONS, ids=lambda o: o.name)
def test_drill_refuses_a_flag_for_the_kinds_the_schema_leaves_out(o):
    for kind, path in KIND_FILES.items():
        if kind in o.kinds:
            args = build_parser().parse_args(argv_of(o, path, kind=kind))
            check_args(args)  # no error: the flag applies, with what it needs (nothing is planned here)
        else:
            out = run_cli(*argv_of(o, path))
            assert out.returncode == 2, (kind, out.stderr)
            lines = out.stderr.strip().splitlines()
            assert len(lines) == 1 and o.flag in lines[0] and "does not apply" in lines[0], (kind, out.stderr)


def _asgi_get(app: Any, path: str) -> tuple[int, bytes]:
    """One GET answered by the ASGI app in this process (no socket)."""
    sent: list[dict] = []

    async def receive() -> dict:
        return {"type": "http.request", "body": b"", "more_body": False}

    async def send(message: dict) -> None:
        sent.append(message)

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "GET", "scheme": "http",
             "path": path, "raw_path": path.encode(), "query_string": b"", "root_path": "",
             "headers": [(b"host", b"127.0.0.1:8000")], "client": ("127.0.0.1", 1), "server": ("127.0.0.1", 8000)}
    asyncio.run(app(scope, receive, send))
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    return status, b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")


def test_the_page_is_served_the_schema(tmp_path):
    pytest.importorskip("starlette")
    from cam.web.server import ServerConfig, create_app

    app = create_app(ServerConfig(jobs_dir=str(tmp_path / "jobs"), port=0))
    try:
        status, body = _asgi_get(app, "/api/options")
    finally:
        app.state.session.shutdown()
    assert status == 200

    assert json.loads(body) == json.loads(json.dumps(schema_json()))
    assert [o["name"] for o in json.loads(body)] == [o.name for o in JOB_OPTIONS]


def test_the_page_builds_its_fields_from_the_schema():
    """The page holds no option field of its own (issue #47 point 6): index.html's options form is empty, app.js
    makes a field of each option from /api/options and names no option but those whose field is special (the
    profile file it uploads, the Read as select of kind)."""
    static = Path(__file__).parent.parent / "cam" / "web" / "static"
    html = (static / "index.html").read_text()
    form = html[html.index('<form id="options-form"'):html.index("</form>", html.index('<form id="options-form"'))]
    assert "data-kinds" not in html and not re.findall(r"<(?:input|select)", form)
    js = (static / "app.js").read_text()
    assert "/api/options" in js
    assert set(re.findall(r'name === "(\w+)"', js)) == {"profile"}
    assert not {o.name for o in JOB_OPTIONS} & set(re.findall(r'name="(\w+)"', js) + re.findall(r'\bo\.(\w+)\b', js))


def _boundary_values(o: Option) -> list[float]:
    lo, hi = float(o.lo), float(o.hi)  # type: ignore[arg-type]
    if o.type in ("whole", "wholes", "points", "digits"):
        return [lo - 1, lo, lo + 1, hi - 1, hi, hi + 1]
    return [lo - 1e-3, lo, lo + 1e-3, hi - 1e-3, hi, hi + 1e-3, hi * 1.5 + 1]


def _cli_accepts(argv: list[str]) -> bool:
    """Whether the command line takes ``argv``: its parser, then its checks before anything runs (a value in
    range that cannot be meant, such as a travel height at the surface, is refused there)."""
    with contextlib.redirect_stderr(io.StringIO()):
        try:
            check_args(build_parser().parse_args(argv))
        except SystemExit as exc:
            assert exc.code == 2
            return False
        except CamError:
            return False
    return True


def _options_accept(o: Option, value: Any, kind: str = "") -> bool:
    partners = {n.name: {"flag": True, "number": 1.0, "text": "k"}[n.type] for n in needed(o, kind)}
    try:
        JobOptions(**{o.name: value}, **partners).checked()
    except CamError:
        return False
    return True


@pytest.mark.parametrize("o", [o for o in JOB_OPTIONS if o.lo is not None], ids=lambda o: o.name)
def test_ranges_are_enforced_alike_by_the_cli_and_joboptions(o):
    kind = next(k for k in KIND_FILES if k in o.kinds)
    path = KIND_FILES[kind]
    for v in _boundary_values(o):
        whole = o.type in ("whole", "wholes", "points", "digits")
        text = str(int(v)) if whole else repr(v)
        value: Any = int(v) if whole else v
        n = o.count or 1
        if o.type in ("wholes", "numbers"):
            text, value = ",".join([text] * n), tuple([value] * n)
        elif o.type == "points":
            text, value = f"{text},{text}", ((value, value),)
        elif o.type == "digits":
            text, value = f"{text}:{text}", (value, value)
        elif o.type == "size":
            text, value = f"{text}x{text}", (value, value)
        accepted = _options_accept(o, value, kind)
        assert _cli_accepts(argv_of(o, path, text, kind)) == accepted, (o.name, v)
        # with what the option needs: only its range refuses it (or a zero that cannot be meant as given)
        assert accepted == (o.in_range(v) and degenerate({o.name: value}.get) is None), (o.name, v)


def test_trace_min_length_is_one_range_in_trace_and_drill():
    o = next(o for o in JOB_OPTIONS if o.name == "trace_min_length_px")
    for v in (o.lo - 1, o.lo, o.hi, o.hi + 1):
        accepted = o.lo <= v <= o.hi
        assert _cli_accepts(["trace", "photo.jpg", "-o", "d.png", "--trace-min-length", str(int(v))]) == accepted
        assert _cli_accepts(["trace", "photo.jpg", "-o", "d.png", "--min-length", str(int(v))]) == accepted
        assert _cli_accepts(["drill", "photo.jpg", "--trace", "--trace-min-length", str(int(v))]) == accepted


def test_one_name_for_the_depth_and_height_in_the_planners():
    """The planners take JobOptions' names as keywords."""
    import inspect

    from cam.job.drill import plan_drill
    from cam.job.hpgl import plan_hpgl
    from cam.job.hpgl_stream import stream_hpgl
    from cam.job.svg import plan_svg

    for planner in (plan_drill, plan_hpgl, stream_hpgl, plan_svg):
        params = inspect.signature(planner).parameters
        assert {"cut_depth_mm", "travel_height_mm", "offset_mm"} <= set(params), planner.__name__
        assert not {"depth_mm", "safe_height_mm"} & set(params), planner.__name__
    from cam.job.gcode import plan_gcode

    wanted = {plan_drill: {"mirror_x", "drill_order"}, plan_svg: {"scale", "fit_mm"}, plan_gcode: {"flip_y"}}
    for planner, names in wanted.items():
        assert names <= set(inspect.signature(planner).parameters), planner.__name__


def _stem(name: str) -> str:
    """A setting's name without its unit and kind: ``stepdown_px`` and ``stepdown_mm`` -> ``stepdown``,
    ``excellon_digits`` and ``digits`` -> ``digits``, ``trace_min_length_px`` -> ``min_length``."""
    name = re.sub(r"_(mm|px|z_px|deg|steps|in|inch)$", "", name)
    return re.sub(r"^(excellon|trace|drill|svg|hpgl|gcode)_", "", name)


def _planners() -> list:
    """Every function that takes job options as keywords: the planners, the readers with options, the tracer."""
    from cam.digitize.sketch import trace
    from cam.formats.excellon import load_excellon, parse_excellon
    from cam.job.drawing_stream import plan, stream_drawing
    from cam.job.drill import plan_drill
    from cam.job.gcode import plan_gcode
    from cam.job.hpgl import plan_hpgl
    from cam.job.hpgl_stream import stream_hpgl
    from cam.job.svg import plan_svg

    return [plan, stream_drawing, plan_drill, plan_hpgl, stream_hpgl, plan_svg, plan_gcode, parse_excellon,
            load_excellon, trace]


def test_no_planner_keyword_is_a_second_name_of_an_option():
    """A planner's keyword that is an option's setting (the same name up to its unit or kind prefix) is the
    option's name: no ``stepdown_px`` beside ``stepdown_mm``, no ``digits`` beside ``excellon_digits``, no
    ``min_length_px`` beside ``trace_min_length_px``."""
    import inspect

    by_stem = {_stem(o.name): o.name for o in JOB_OPTIONS}
    assert len(by_stem) == len(JOB_OPTIONS)
    for planner in _planners():
        for param in inspect.signature(planner).parameters:
            option = by_stem.get(_stem(param))
            assert option is None or param == option, f"{planner.__name__}({param}=): the option is {option}"
    wanted = {"stepdown_mm", "stepover", "rough_tool", "tool", "depth", "cut_depth_mm", "passes", "start_at",
              "pause_at", "profile"}
    for planner in _planners()[:2]:
        assert wanted <= set(inspect.signature(planner).parameters), planner.__name__
    for planner in _planners()[-3:-1]:
        assert {"excellon_units", "excellon_digits", "excellon_zeros"} <= set(inspect.signature(planner).parameters)
    assert {"trace_min_length_px", "trace_fill"} <= set(inspect.signature(_planners()[-1]).parameters)


def _commands() -> dict[str, argparse.ArgumentParser]:
    return dict(build_parser()._subparsers._group_actions[0].choices)  # type: ignore[union-attr]


def test_no_command_shows_a_second_flag_of_an_option():
    """On every command, a shown flag that is an option's setting (same name up to its unit or kind prefix) is
    the option's flag, with the option's dest; an older spelling is accepted only hidden (not in --help)."""
    by_stem = {_stem(o.dest): o for o in JOB_OPTIONS}
    for command, parser in _commands().items():
        for action in parser._actions:
            if not action.option_strings:
                continue
            o = by_stem.get(_stem(action.dest))
            if o is None:
                continue
            shown = action.help != argparse.SUPPRESS
            assert action.dest == o.dest, (command, action.option_strings, o.name)
            if shown:
                assert action.option_strings == [o.flag], (command, action.option_strings, o.flag)
            else:
                assert o.flag not in action.option_strings, (command, action.option_strings)


def test_trace_takes_drill_traces_flags():
    """``cam trace`` and ``cam drill --trace`` set the tracer's two settings by the same flags."""
    trace = build_parser().parse_args(["trace", "p.jpg", "-o", "d.png", "--trace-min-length", "12", "--trace-fill"])
    drill = build_parser().parse_args(["drill", "p.jpg", "--trace", "--trace-min-length", "12", "--trace-fill"])
    assert (trace.trace_min_length, trace.trace_fill) == (drill.trace_min_length, drill.trace_fill) == (12, True)


def test_the_drawing_planner_takes_the_cut_depth_in_mm(monkeypatch):
    """cam.plan(cut_depth_mm=) is --cut-depth: prepare_job gives the option unchanged, the planner makes it whole
    Z pixels (depth_px_of), the same job as the depth in Z pixels."""
    import cam
    from cam.job import drawing_stream
    from cam.kinds import jobs
    from cam.job.drawing_stream import depth_px_of

    s = cam.MachineSettings()
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    one = s.px_to_mm_z(1)
    assert [depth_px_of(k * one, s) for k in (0.5001, 1, 4.4, 4.6)] == [1, 1, 4, 5]
    a, b = cam.plan(d, cut_depth_mm=5 * one), cam.plan(d, depth=5)
    assert (a.points_steps == b.points_steps).all()
    with pytest.raises(CamError, match="less than one Z pixel"):
        cam.plan(d, cut_depth_mm=one / 3)
    with pytest.raises(CamError, match="give the depth once"):
        cam.plan(d, depth=5, cut_depth_mm=1.0)
    seen: dict = {}
    real = drawing_stream.plan

    def spy(digitized, **kw):
        seen.update(kw)
        return real(digitized, **kw)

    monkeypatch.setattr(drawing_stream, "plan", spy)  # the drawing kind's planner (cam.kinds.drawing)
    jobs.prepare_job(SAMPLES / "ellipse.png", JobOptions(cut_depth_mm=0.2), s)
    assert seen["cut_depth_mm"] == 0.2 and seen["depth"] is None


def test_the_stepdown_is_converted_in_one_place(monkeypatch):
    """The planner takes stepdown_mm, as JobOptions and --stepdown do: prepare_job gives it the option's value
    unchanged, and the planner's levels are stepdown_px_of(stepdown_mm) Z pixels apart."""
    import cam
    from cam.job import drawing_stream
    from cam.kinds import jobs
    from cam.job.drawing_stream import stepdown_px_of

    s = cam.MachineSettings()
    one = s.px_to_mm_z(1)
    assert [stepdown_px_of(k * one, s) for k in (0.01, 1, 2, 30, 30.5)] == [1, 1, 2, 30, 30]
    seen: dict = {}
    real = drawing_stream.plan

    def spy(digitized, **kw):
        seen.update(kw)
        return real(digitized, **kw)

    monkeypatch.setattr(drawing_stream, "plan", spy)  # the drawing kind's planner (cam.kinds.drawing)
    jobs.prepare_job(SAMPLES / "disc.png", JobOptions(profile_expr="k", tool="ball:1", stepdown_mm=0.1), s)
    assert seen["stepdown_mm"] == 0.1 and "stepdown_px" not in seen
    with pytest.raises(CamError, match="stepdown_mm must be > 0"):
        cam.plan(cam.digitize(cam.load_image(SAMPLES / "disc.png")), profile=lambda k: k, stepdown_mm=0.0)


def test_the_help_of_each_flag_is_the_schemas():
    parser = build_parser()
    drill = next(a for a in parser._subparsers._group_actions[0].choices.items() if a[0] == "drill")[1]  # type: ignore[union-attr]
    helps = {a.option_strings[0]: a.help for a in drill._actions if a.option_strings}
    for o in JOB_OPTIONS:
        assert helps[o.flag] == o.help, o.flag
    assert isinstance(drill, argparse.ArgumentParser)


def test_a_renamed_flag_keeps_its_old_spelling():
    """--excellon-digits is excellon_digits' flag; --excellon-format, its old name, still sets it, hidden."""
    for flag in ("--excellon-digits", "--excellon-format"):
        args = build_parser().parse_args(["drill", str(KIND_FILES["excellon"]), flag, "3:3"])
        assert args.excellon_digits == [3, 3]
    assert run_cli("drill", KIND_FILES["excellon"], "--excellon-format", "9:1").returncode == 2
    for command in ("drill", "info"):
        assert "--excellon-format" not in run_cli(command, "--help").stdout
