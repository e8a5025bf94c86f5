"""The rules between job options are declared once (``cam.options.RULES``, issue #48 point 3) and asked by every
front end alike: the command line refuses a rule broken in one line naming both flags (exit code 2), the API
(``JobOptions``) naming both options, the page's server with the same words (HTTP 400), and the page itself before
it sends the form, from the rules ``GET /api/options`` gives each option.  No front end writes a rule again."""
from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Any

import pytest

from cam.cli.parser import build_parser
from cam.errors import CamError
from cam.kinds.jobs import JobOptions
from cam.kinds import job_options, schema_json
from cam.options import RULE_KINDS, RULES, Rule, broken_rule, given, keyword_error

from conftest import ROOT, SAMPLES
from test_cli_checks import cli, refused
from test_options_schema import KIND_FILES, sample_value

JOB_OPTIONS = job_options()
"""Every option, the kinds it applies to filled in from the file kinds' traits (cam.kinds)."""
OPTIONS = {o.name: o for o in JOB_OPTIONS}

CAM = ROOT / "cam"
DOME = ROOT / "profiles" / "dome.png"
_PYTHON = {"flag": True, "text": "k", "tool": "flat:1", "size": (80.0, 40.0)}
"""A value of each option type as the API takes it, where the command line's text is not it (None: the number)."""


def _kind(rule: Rule) -> str:
    """A file kind every option the rule's case gives applies to (:func:`_case`)."""
    names = _case(rule)
    return next(k for k in KIND_FILES if k != "digitized" and all(k in OPTIONS[n].kinds for n in names))


def _case(rule: Rule) -> list[str]:
    """The options given to break ``rule``: its option with the first of its others it goes against (not_with), or
    alone (needs)."""
    return [rule.option, rule.others[0]] if rule.kind == "not_with" else [rule.option]


def _api_value(name: str) -> Any:
    o = OPTIONS[name]
    if o.type in ("whole", "number"):
        return (int if o.type == "whole" else float)(sample_value(o))  # type: ignore[arg-type]
    if o.type == "wholes":
        return tuple(int(v) for v in sample_value(o).split(","))  # type: ignore[union-attr]
    if o.type == "points":
        return ((1, 1),)
    return _PYTHON.get(o.type) or sample_value(o)


def _argv(name: str) -> str:
    o = OPTIONS[name]
    return o.flag if o.type == "flag" else f"{o.flag}={sample_value(o)}"


def _ids(rule: Rule) -> str:
    return f"{rule.option}-{rule.kind}-{rule.others[0]}"


def test_every_rule_names_options_that_exist_and_could_be_given_together():
    assert RULES and len(set(RULES)) == len(RULES)
    for rule in RULES:
        assert rule.kind in RULE_KINDS, rule
        assert rule.option in OPTIONS and rule.others and all(n in OPTIONS for n in rule.others), rule
        assert rule.option not in rule.others, rule
        # each {name} of its message is an option (or {other}, the partner found); the message names its partners
        words = set(re.findall(r"\{(\w+)\}", rule.why))
        assert words <= set(OPTIONS) | {"other"}, (rule, words - set(OPTIONS))
        assert "{other}" in rule.why or set(rule.others) <= words, rule
        # the rule can be broken on some file kind: its option and a partner apply to one kind together
        assert any(OPTIONS[rule.option].kinds & OPTIONS[n].kinds for n in rule.others), rule


def test_given_is_set_and_not_the_default():
    assert not given("depth", None) and not given("pause_at", ()) and not given("pause_at", [])
    assert not given("heightmap", False) and given("heightmap", True)
    assert not given("stepover", 0.5) and given("stepover", 0.3)  # the default changes nothing
    assert not given("start_at", [0, 0, 0]) and given("start_at", [1, 0, 0])  # a list as the command line has it
    assert given("depth", [3]) and given("profile", "dome.png")


@pytest.mark.parametrize("rule", RULES, ids=_ids)
def test_each_rule_is_refused_alike_by_the_cli_and_the_api(rule, tmp_path):
    names = _case(rule)
    assert broken_rule({n: _api_value(n) for n in names}.get) is not None
    flags = {n: OPTIONS[n].flag for n in (rule.option, *rule.others)}
    # the command line: one line, exit code 2, naming the flags in its words; nothing runs
    path = KIND_FILES[_kind(rule)]
    proc = cli("drill", path, *(_argv(n) for n in names), "--pin-log", tmp_path / "p.csv")
    name, why = broken_rule({k: _api_value(k) for k in names}.get, lambda n: OPTIONS[n].flag)  # type: ignore[misc]
    refused(proc, f"cam: error: {flags[name]} {why}", *(flags[n] for n in names))
    assert not (tmp_path / "p.csv").exists()
    # the API: JobOptions, naming the options in its words
    with pytest.raises(CamError) as info:
        JobOptions(**{n: _api_value(n) for n in names}).checked()
    message = str(info.value)
    assert "\n" not in message and f"option '{rule.option}' " in message
    for n in names:
        assert re.search(rf"(?<![-\w]){n}(?![-\w])", message), (n, message)
    assert "--" not in message, message  # option names, not flags
    # the same rule, its words said by each front end's names
    assert message.startswith(f"options: option '{name}' {broken_rule({k: _api_value(k) for k in names}.get)[1]}")


def test_the_planners_ask_the_same_rules_and_ranges():
    """A planner called by itself refuses what JobOptions refuses, in the same words (its keywords are the
    options' names)."""
    import cam

    assert keyword_error({"scale": 2.0, "fit_mm": (10.0, 10.0)}) == \
        "fit_mm " + broken_rule({"scale": 2.0, "fit_mm": (10.0, 10.0)}.get)[1]  # type: ignore[index]
    assert keyword_error({"stepover": 0.3}) is None  # a rule whose partners are not among the keywords: not asked
    assert keyword_error({"stepover": 0.0}) == "stepover must be > 0 and at most 1, got 0.0"
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    with pytest.raises(CamError, match=r"^cut_depth_mm cannot be given together with depth: give the depth once"):
        cam.plan(d, depth=5, cut_depth_mm=1.0)
    with pytest.raises(CamError, match=r"^rough_tool is for roughing in levels: it needs stepdown_mm"):
        cam.plan(d, rough_tool="flat:1")
    with pytest.raises(CamError, match=r"^passes must be 1\.\.1000, got 0"):
        cam.plan(d, passes=0)
    with pytest.raises(CamError, match=r"^depth each value must be 0\.\.1000000 Z px, got \[3, -1\]"):
        cam.plan(d, depth=[3, -1])


# -- the page and its server ----------------------------------------------------------------------------------

def test_api_options_gives_each_option_its_rules_in_their_order():
    served = {record["name"]: record for record in schema_json()}
    every = sorted((r["index"], name, r["kind"], tuple(r["others"]), r["why"])
                   for name, record in served.items() for r in record["rules"])
    assert every == [(i, r.option, r.kind, r.others, r.why) for i, r in enumerate(RULES)]


def test_the_page_refuses_a_broken_rule_from_the_served_rules():
    """app.js reads each option's rules from GET /api/options and asks them before it sends a form (no rule of
    its own: it names no option, test_options_schema.test_the_page_builds_its_fields_from_the_schema)."""
    js = (CAM / "web" / "static" / "app.js").read_text()
    assert "o.rules" in js and 'r.kind === "not_with"' in js and 'r.kind === "needs"' in js
    plan = js[js.index("async function planJob"):js.index("$(\"file\").addEventListener")]
    assert plan.index("brokenRule(options)") < plan.index('api("/api/plan"')


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    pytest.importorskip("uvicorn")
    from test_web import FAST, Server

    s = Server(tmp_path_factory.mktemp("rules"), settings=FAST, realtime=False)
    yield s
    s.close()


@pytest.mark.parametrize("rule", [r for r in RULES if all(OPTIONS[n].web for n in _case(r))], ids=_ids)
def test_each_rule_is_refused_by_the_page_server(rule, server):
    names = _case(rule)
    kind = _kind(rule)
    status, up = server.upload(KIND_FILES[kind].name, KIND_FILES[kind].read_bytes())
    assert status == 200, up
    options: dict[str, Any] = {}
    for n in names:
        o = OPTIONS[n]
        options[n] = True if o.type == "flag" else sample_value(o)  # as the form sends it
        if n == "profile":  # a file the page uploads, sent by its upload id
            status, profile = server.upload(DOME.name, DOME.read_bytes(), role="profile")
            assert status == 200, profile
            options[n] = profile["job"]
    status, reply = server.call("POST", "/api/plan", {"job": up["job"], "options": options})
    assert status == 400, reply
    name, why = broken_rule({n: _api_value(n) for n in names}.get)  # type: ignore[misc]
    assert f"option '{name}' {why}" in reply["error"] and "\n" not in reply["error"], reply


# -- written once -----------------------------------------------------------------------------------------------

_NOT_RULES = {"kind"}
"""Option names that are also the name of something else where they are compared (the file's kind)."""


def _options_named(node: ast.AST) -> set[str]:
    """The job options an expression names: as an attribute (``options.depth``, ``args.cut_depth``), a variable
    (a planner's keyword) or a string (``getattr(args, "depth")``), by name or argparse dest."""
    of = {**{o.dest: o.name for o in JOB_OPTIONS}, **{o.name: o.name for o in JOB_OPTIONS}}
    found = set()
    for n in ast.walk(node):
        word = (n.attr if isinstance(n, ast.Attribute) else n.id if isinstance(n, ast.Name)
                else n.value if isinstance(n, ast.Constant) and isinstance(n.value, str) else None)
        if word in of and of[word] not in _NOT_RULES:
            found.add(of[word])
    return found


_DECIDED_BY_THE_FILE = {
    ("cam/job/drawing.py", frozenset({"depth", "profile"})): "a 3D drawing needs a depth or a profile: its mode decides",
}
"""Conditions on two options that are no rule between them: something else decides (why)."""


def test_no_rule_between_options_is_written_outside_cam_options():
    """No condition in cam/ (the command line, JobOptions, the planners, the server) joins two job options with
    ``and``: a rule between them is declared in cam.options.RULES (or own_zero), and asked there."""
    found = []
    for path in sorted(CAM.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel == "cam/options.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.BoolOp) and isinstance(node.op, ast.And):
                names = frozenset(_options_named(node))
                if len(names) >= 2 and (rel, names) not in _DECIDED_BY_THE_FILE:
                    found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "a rule between options written again:\n" + "\n".join(found)


def test_no_job_option_is_in_an_argparse_group_of_its_own():
    """argparse's mutually exclusive groups would be a second copy of a rule (and another message)."""
    dests = {o.dest for o in JOB_OPTIONS}
    commands = build_parser()._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    for command, parser in commands.items():
        for group in parser._mutually_exclusive_groups:
            assert not {a.dest for a in group._group_actions} & dests, command


def test_the_scanner_finds_a_rule_written_again():
    """The test above would have found the copies it replaced."""
    copies = ('if self.scale is not None and self.fit_mm is not None: pass',
              'if kind in DRAWINGS and _given(args, "cut_depth") and _given(args, "depth"): pass',
              'if scale is not None and fit_mm is not None: pass')
    for text in copies:
        node = next(n for n in ast.walk(ast.parse(text)) if isinstance(n, ast.BoolOp))
        assert len(_options_named(node)) == 2, text
