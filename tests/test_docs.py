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
    assert resolve("cam.job.jobs.prepare_job") is cam.prepare_job
    for wrong in ("cam.load_gcode", "cam.plan_gcode", "cam.job.no_such_module.x"):
        with pytest.raises((AttributeError, ImportError)):
            resolve(wrong)
