"""The README is a short map and the pages under docs/ stay true to the code.

* README.md has at most 250 lines and starts with its two commands (install and cut; install and test);
* every ``cam.<name>`` and ``cam.<module>.<name>`` in the code blocks and inline code of README.md and
  docs/*.md resolves (an attribute of ``cam``, a submodule, or an attribute of one);
* every relative link and image of those pages points to a file that exists.
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import cam

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = [README] + sorted((ROOT / "docs").glob("*.md"))
MAX_README_LINES = 250

INSTALL_AND_CUT = "pip install -e . && python -m cam drill samples/ellipse.png --depth 5 --pin-log ellipse-pins.csv"
INSTALL_AND_TEST_PREFIX = "pip install -e '.[test"  # the second command's test part may change; the install stays

FENCE = re.compile(r"^(```|~~~)[^\n]*\n(.*?)^\1[ \t]*$", re.M | re.S)
INLINE = re.compile(r"(`+)(.+?)\1", re.S)
# cam.<name>[.<name>...], not part of a longer name or path (mycam.x, x.cam.y, src/cam.x)
DOTTED = re.compile(r"(?<![\w./-])cam(?:\.[A-Za-z_][A-Za-z0-9_]*)+")
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def code_spans(text: str) -> list[str]:
    """The text of every fenced code block and every inline code span."""
    spans = [m.group(2) for m in FENCE.finditer(text)]
    prose = FENCE.sub("", text)
    spans += [m.group(2) for m in INLINE.finditer(prose)]
    return spans


def dotted_names(text: str) -> set[str]:
    return {m.group(0) for span in code_spans(text) for m in DOTTED.finditer(span)}


def resolve(dotted: str) -> object:
    """The object ``dotted`` (``cam.a.b``) names: each part an attribute of the one before (``cam``'s lazy
    names included), else a submodule to import (raises AttributeError or ImportError when neither).

    Attributes come first, so ``cam.digitize`` is the public function, not the package of the same name.
    """
    parts = dotted.split(".")
    assert parts[0] == "cam", dotted
    obj: object = cam
    for i, name in enumerate(parts[1:], start=2):
        try:
            obj = getattr(obj, name)
        except AttributeError:
            obj = importlib.import_module(".".join(parts[:i]))
    return obj


def test_readme_is_short_and_starts_with_its_two_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines (at most {MAX_README_LINES})"
    text = "\n".join(lines)
    first = FENCE.search(text)
    assert first is not None, "README.md has no code block"
    before = text[:first.start()].strip()
    assert before in ("", "# cam"), f"README.md: text before its commands: {before!r}"
    commands = [c for c in first.group(2).splitlines() if c.strip()]
    assert commands[0] == INSTALL_AND_CUT, commands[0]
    assert commands[1].startswith(INSTALL_AND_TEST_PREFIX) and "pytest" in commands[1], commands[1]


def test_the_pages_exist():
    names = {p.name for p in PAGES}
    for page in ("architecture.md", "command-line.md", "file-formats.md", "machine-and-ports.md", "maximus.md",
                 "web.md", "real-cutters.md", "speed.md", "tests.md"):
        assert page in names, page


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_cam_name_in_code_resolves(page):
    missing = []
    for dotted in sorted(dotted_names(page.read_text(encoding="utf-8"))):
        try:
            resolve(dotted)
        except (AttributeError, ImportError) as exc:
            missing.append(f"{dotted} ({type(exc).__name__}: {exc})")
    assert not missing, f"{page.name}: names that do not resolve:\n" + "\n".join(missing)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_points_to_a_file(page):
    text = FENCE.sub("", page.read_text(encoding="utf-8"))
    text = INLINE.sub("", text)
    broken = []
    for m in LINK.finditer(text):
        target = m.group(1)
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue  # a URL (http:, mailto:) or an anchor on the same page
        path = target.split("#", 1)[0].split("?", 1)[0]
        if not (page.parent / path).exists():
            broken.append(target)
    assert not broken, f"{page.name}: links to missing files: {broken}"


def test_the_checks_catch_what_they_should():
    """The name finder and resolver themselves: a wrong name fails, names in prose are not read."""
    text = "Use `cam.plan(x)` and\n```python\ncam.job.gcode.plan_gcode(p)\n```\nnot cam.nothing in prose."
    assert dotted_names(text) == {"cam.plan", "cam.job.gcode.plan_gcode"}
    assert resolve("cam.digitize") is cam.digitize  # the function, not the package
    assert resolve("cam.kinds.jobs.prepare_job") is cam.prepare_job
    for wrong in ("cam.load_gcode", "cam.plan_gcode", "cam.job.no_such_module.x"):
        with pytest.raises((AttributeError, ImportError)):
            resolve(wrong)


STALE = (
    (r"G-code program is still run from where the tool stands", "a G-code program runs in the state's work offsets"),
    (r"G54\.\.G59\.3 inside programs are issue #29", "work offsets inside programs are done (issue #29 point 4)"),
    (r"plan a program from the home with every offset 0, as before", "info and preview read the state file"),
    (r"placed where the tool stands", "drill, HPGL and SVG jobs are placed at the active work zero"),
)
"""Statements the docs once made about where a job runs that the code no longer does (issue #44 point 7), and
what is true instead (cam.drive.placement, cam.kinds.jobs.prepare_job's machine_state)."""


def test_docs_do_not_say_gcode_runs_from_where_the_tool_stands():
    """A G-code program runs as a sender runs it, in the state's work offsets (G54..G59.3, G10, G53), from where
    the tool stands; drill, HPGL and SVG files are placed at the active work zero. No page says otherwise."""
    from cam.drive.placement import placed_kinds

    assert "gcode" not in placed_kinds() and {"excellon", "hpgl", "svg"} <= set(placed_kinds())  # what the docs say
    found = []
    for page in PAGES:
        text = " ".join(page.read_text(encoding="utf-8").split())
        found += [f"{page.name}: '{m.group(0)}' ({why})" for pattern, why in STALE
                  for m in re.finditer(pattern, text)]
    assert not found, "stale statements:\n" + "\n".join(found)
    ports = " ".join((ROOT / "docs" / "machine-and-ports.md").read_text(encoding="utf-8").split())
    assert re.search(r"A G-code program is not moved to the work zero: it runs as a G-code sender runs it, its "
                     r"coordinates in the state's work offsets", ports)


def test_readme_map_names_every_reader_and_planner():
    """The README's data-flow map names a reader and the planner of every file kind (the grey-level relief's
    too), each name resolving into that module, and every kind of port."""
    from cam.drive.machines import REGISTRY, backend_of
    from cam.kinds import kind_names

    backend_of("mock")  # the registry loaded

    text = README.read_text(encoding="utf-8")
    block = FENCE.search(text, text.index("## Data flow"))
    assert block is not None
    modules = set()
    for dotted in {m.group(0) for m in DOTTED.finditer(block.group(2))}:
        obj = resolve(dotted)
        modules.add(obj.__name__ if isinstance(obj, type(cam)) else getattr(obj, "__module__", ""))
    wanted = {  # file kind -> (reader module, planner module)
        "drawing": ("cam.digitize.drawing", "cam.digitize"),
        "digitized": ("cam.digitize.digitized", "cam.job.drawing_stream"),
        "excellon": ("cam.formats.excellon", "cam.job.drill"),
        "hpgl": ("cam.formats.hpgl", "cam.job.hpgl_stream"),
        "svg": ("cam.formats.svg", "cam.job.svg"),
        "dxf": ("cam.formats.dxf", "cam.job.svg"),  # read into an SvgDrawing, planned as SVG
        "gcode": ("cam.formats.gcode", "cam.job.gcode"),
    }
    for name in set(kind_names()) - set(wanted):  # a kind added since: its module, which names its reader and planner
        wanted[name] = (f"cam.kinds.{name}", f"cam.kinds.{name}")
    wanted["heightmap"] = ("cam.job.heightmap", "cam.job.heightmap")  # drawings cut as grey-level reliefs
    wanted["sketch"] = ("cam.digitize.sketch", "cam.digitize.sketch")  # photos traced into drawings
    wanted["profile"] = ("cam.digitize.profile", "cam.digitize.profile")  # 3D depth profiles
    wanted["moves"] = ("cam.job.moves", "cam.job.moves")  # jog, go to
    missing = [f"{kind}: {m}" for kind, pair in wanted.items() for m in pair if m not in modules]
    assert not missing, "the README's map leaves out:\n" + "\n".join(missing)
    spelled = {"mock": '"mock"', "parport": '"/dev/parport', "cmd": '"cmd:', "maximus": '"maximus:', "grbl": '"grbl:'}
    assert set(spelled) == {b.kind for b in REGISTRY}, "a new kind of port: add it to the README's map and here"
    assert all(s in block.group(2) for s in spelled.values()), [k for k, s in spelled.items() if s not in block.group(2)]
