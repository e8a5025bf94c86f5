"""What imports what: a cheap ``import cam`` and ``--help``, no import cycle, few function-level imports.

Every module under ``cam/`` is read with :mod:`ast` (nothing here imports
the package to learn its structure), and the start-up checks run in fresh
interpreters, where ``sys.modules`` shows what was really loaded.
"""
from __future__ import annotations

import argparse
import ast
import functools
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Iterator, Optional

from cam import choices
from cam.kinds import KIND_MODULES
from cam.cli import COMMANDS
from cam.cli.parser import build_parser
from cam.kinds import jobs

from conftest import ROOT, parsed_source

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}

HEAVY = ("numba", "cv2", "scipy", "starlette", "uvicorn", "skimage")
"""Packages that make start-up slow (numba alone takes most of a second) or are optional extras."""

KIND_HOOK_MODULES = {f"cam.kinds.{name}" for name in KIND_MODULES}
"""The file kinds' modules (issue #48 point 1) may import inside their hooks: a kind's module is read for its name,
suffixes and sniffer by ``--help``, the sniffer and every flag's check, so it loads its reader and planner only when
a hook plans, reports or exports a file."""

FUNCTION_LEVEL_IMPORTS = {
    ("cam.drive.ports", "cam.motion.kernels"): "numba: loaded only when the mock streams its pin log to a file, so "
                                              "opening a port stays light",
    ("cam.settings", "cam.tool"): "cam.tool needs numpy; the settings module stays light for --help",
    ("cam.cli.parser", "cam.errors"): "--tool is checked by cam.tool (numpy) only when given: --help stays light",
    ("cam.cli.parser", "cam.tool"): "cam.tool needs numpy; the parser stays light for --help",
    ("cam.verify.toolcarve", "cv2"): "only a notebook's picture of a comparison needs OpenCV's PNG encoder",
    ("cam._compiled", "cam._kernel_signatures"): "the kernels' table is read only when compiling or loading them",
    ("cam._compiled", "numba"): "numba's types, only when the kernels' table is read: importing the kernel list "
                                "loads no numba",
    ("cam._kernel_cache", "cam.cli"): "the cache filler: the sample jobs run only when collecting argument types",
    ("cam.worker", "cam._compiled"): "the worker child loads the cached kernels before its memory limit; the "
                                         "parent never needs the table",
    ("cam._kernel_cache", "numba"): "the cache filler: numba's types, only when writing the table",
    # (importing module, imported module): why it may not be imported at the importing module's top
    ("cam.drive.ports", "parallel"):
        "optional dependency: pyparallel (cam[parport]), needed only when a /dev/parport* port is opened",
    ("cam.web.server", "starlette"):
        "optional dependency: the web stack (cam[web]); cam.web.server imports without it, so 'cam serve' "
        "can name the extra in one line",
    ("cam.web.server", "uvicorn"): "optional dependency: the web stack (cam[web]), as starlette",
    ("cam.web.connections", "uvicorn"): "optional dependency: the web stack (cam[web]), as cam.web.server",
    ("cam.drive.machines", "cam.drive.machines"): "the registry's back ends register themselves when a port is "
                                                  "first named: each imports the registry's base, and the grbl "
                                                  "and MAXIMUS hosts load only for a port that needs them",
    ("cam.formats.dxf", "ezdxf"): "heavy (about 0.7 s): loaded only when a DXF file is read, not with every job "
                                  "kind's reader (cam.kinds.jobs imports cam.formats.dxf)",
    ("cam.cli", "cam._compiled"): "the kernels' cache folder is chosen (and made) when a command runs, not for "
                                  "--help or bad options",
    ("cam.cli", "numba"): "heavy (about half a second): the first-compile note is registered only when a "
                          "command runs, so --help and bad options stay quick",
}
"""The only import statements allowed inside functions (the project rule: none, except to keep an optional
dependency optional)."""

MAX_CLI_FUNCTION_LINES = 80


# -- reading the package ---------------------------------------------------------------------------------


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in sorted((ROOT / "cam").rglob("*.py"))}


def is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def import_statements(tree: ast.AST) -> Iterator[tuple[ast.stmt, Optional[str]]]:
    """Every import statement that runs, with the function it is in (None: runs when the module loads).

    Imports under ``if TYPE_CHECKING:`` never run and are left out.
    """
    def walk(node: ast.AST, function: Optional[str]) -> Iterator[tuple[ast.stmt, Optional[str]]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child, function
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                yield from walk(child, getattr(child, "name", "<lambda>") if function is None else function)
            elif isinstance(child, ast.If) and is_type_checking(child.test):
                for stmt in child.orelse:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), function)
            else:
                yield from walk(child, function)

    return walk(tree, None)


def import_targets(importer: str, node: ast.stmt) -> list[str]:
    """The modules an import statement loads, relative imports resolved; ``from p import m`` loads ``p.m``
    too when ``m`` is a module of the package."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    assert isinstance(node, ast.ImportFrom)
    if node.level:
        package = importer.split(".")
        if MODULES[importer].name != "__init__.py":
            package = package[:-1]
        package = package[: len(package) - (node.level - 1)]
        base = ".".join(package + ([node.module] if node.module else []))
    else:
        base = node.module or ""
    return [base] + [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in MODULES]


def ancestors(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


@functools.lru_cache(maxsize=None)
def module_imports(name: str) -> list[tuple[ast.stmt, Optional[str]]]:
    """The import statements of cam module ``name`` (:func:`import_statements`), its source parsed once for all."""
    path = MODULES[name]
    return list(import_statements(parsed_source(path)))


def import_graph() -> dict[str, set[str]]:
    """cam module -> the cam modules its module-level imports load.

    Importing ``cam.a.b`` runs ``cam/a/__init__.py`` first, so that package counts too, unless it is the
    importer's own package (then it is already being imported).
    """
    graph: dict[str, set[str]] = {name: set() for name in MODULES}
    for importer, path in MODULES.items():
        own = set(ancestors(importer)) | {importer}
        for node, function in module_imports(importer):
            if function is not None:
                continue
            for target in import_targets(importer, node):
                if target in MODULES:
                    graph[importer].add(target)
                graph[importer].update(a for a in ancestors(target) if a in MODULES and a not in own)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> Optional[list[str]]:
    """One cycle of ``graph`` as [a, b, ..., a], or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> Optional[list[str]]:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            found = visit(start)
            if found:
                return found
    return None


def function_level_imports() -> dict[tuple[str, str], list[str]]:
    """(importing module, imported module) -> where: every import statement inside a function under cam/.

    The imported module is the resolved cam module, or the top-level package of anything else.
    """
    found: dict[tuple[str, str], list[str]] = {}
    for importer, path in MODULES.items():
        for node, function in module_imports(importer):
            if function is None:
                continue
            target = import_targets(importer, node)[0]
            key = (importer, target if target.startswith("cam.") or target == "cam" else target.split(".")[0])
            found.setdefault(key, []).append(f"{path.relative_to(ROOT)}:{node.lineno} in {function}()")
    return found


def _subcommands() -> list[str]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices)


# -- start-up: what a fresh interpreter loads -------------------------------------------------------------


def _heavy(modules: list[str]) -> list[str]:
    return sorted(m for m in modules if m.split(".")[0] in HEAVY)


def test_import_cam_loads_no_heavy_package():
    proc = subprocess.run([sys.executable, "-c", "import json, sys, cam; print(json.dumps(sorted(sys.modules)))"],
                          capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert _heavy(json.loads(proc.stdout)) == []


SLOW_CASES = {'test_only_the_emulator_command_imports_the_emulator'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

RUNNER = r"""
import contextlib, io, json, runpy, sys

heavy, runs, report = set(sys.argv[1].split(",")), json.loads(sys.argv[2]), {}
for argv in runs:
    sys.argv = ["cam", *argv]
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            runpy.run_module("cam", run_name="__main__", alter_sys=True)  # python -m cam ARGV
        except SystemExit:
            pass
    report[" ".join(argv)] = sorted(m for m in sys.modules if m.split(".")[0] in heavy)
print(json.dumps(report))
"""


def test_help_of_every_command_loads_no_heavy_package():
    """``python -m cam``, ``--help`` and every ``COMMAND --help``, one after the other in one interpreter:
    after each, none of the heavy packages is loaded."""
    runs = [[], ["--help"], ["--version"]] + [[c, "--help"] for c in _subcommands()]
    proc = subprocess.run([sys.executable, "-c", RUNNER, ",".join(HEAVY), json.dumps(runs)],
                          capture_output=True, text=True, env=ENV, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert len(report) == len(runs)
    assert {run: loaded for run, loaded in report.items() if loaded} == {}


def test_every_command_has_a_module_and_function():
    assert sorted(COMMANDS) == sorted(_subcommands())
    for name, (module, function) in COMMANDS.items():
        assert callable(getattr(importlib.import_module(module), function)), name


# -- the import graph -------------------------------------------------------------------------------------------


def test_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_graph_resolves_relative_imports_and_packages():
    graph = import_graph()
    assert "cam.errors" in graph["cam.settings"]  # from .errors import ...
    assert "cam.drive.maximus.protocol" in graph["cam.drive.maximus.board"]  # from .protocol import (...)
    assert "cam.digitize" in graph["cam.job.drawing"]  # cam/digitize/__init__.py runs first
    assert "cam.digitize" not in graph["cam.digitize.peel3d"]  # its own package: already loading


def test_package_has_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_cli_parser_imports_only_light_modules():
    """What ``--help`` may load: the parser's module-level imports, followed through the package."""
    graph, seen, todo = import_graph(), set(), ["cam.cli.parser", "cam.cli"]
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo.extend(graph[name])
    assert seen <= {"cam", "cam.cli", "cam.cli.parser", "cam.cli.checks", "cam.choices", "cam.sniff", "cam.errors",
                    "cam.kinds",  # the file kinds' registry (its kind modules are light: KIND_HOOK_MODULES)
                    "cam.settings", "cam.limits", "cam.options",  # cam.limits, cam.options: standard library
                    "cam.drive", "cam.drive.machines",  # the registry's base: its back ends load when asked
                    "cam.drive.maximus",  # emulate-maximus's switch options (argparse only):
                    "cam.drive.maximus.switch_options"}, seen


def test_only_the_emulator_command_imports_the_emulator():
    """The host never imports the MAXIMUS emulator (a test bench); ``cam emulate-maximus`` alone starts it."""
    graph = import_graph()
    users = {m for m, targets in graph.items() if any(t.startswith("cam.sim") for t in targets)}
    users |= {m for m, target in function_level_imports() if target.startswith("cam.sim")}
    assert {m for m in users if not m.startswith("cam.sim")} == {"cam.cli.emulate"}


# -- function-level imports ------------------------------------------------------------------------------------


def test_function_level_imports_are_only_the_allowed_ones():
    found = function_level_imports()
    unexpected = {f"{m} imports {t} inside a function ({', '.join(where)})" for (m, t), where in found.items()
                  if (m, t) not in FUNCTION_LEVEL_IMPORTS and m not in KIND_HOOK_MODULES}
    assert not unexpected, "move these to the module top, or allow them with a reason:\n" + "\n".join(sorted(unexpected))
    stale = set(FUNCTION_LEVEL_IMPORTS) - set(found)
    assert not stale, f"allowed but no longer there (remove from FUNCTION_LEVEL_IMPORTS): {sorted(stale)}"
    assert all(reason.strip() for reason in FUNCTION_LEVEL_IMPORTS.values())


def test_function_level_import_finder_sees_nested_and_skips_type_checking():
    tree = ast.parse("import os\nif TYPE_CHECKING:\n    import numpy\ndef f():\n    def g():\n        import cv2\n")
    assert [(n.names[0].name, f) for n, f in import_statements(tree)] == [("os", None), ("cv2", "f")]


def test_cli_functions_are_short():
    long = []
    for name, path in MODULES.items():
        if name == "cam.cli" or name.startswith("cam.cli."):
            for node in ast.walk(parsed_source(path)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_CLI_FUNCTION_LINES:
                        long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {n} lines")
    assert not long, long


def test_suffix_lists_agree_with_the_job_model():
    """The kinds' suffixes (cam.kinds, what the --help texts list) are what the job model accepts."""
    from cam import kinds

    assert jobs.accepted_suffixes() == kinds.suffixes()
    assert jobs.PROFILE_SUFFIXES == choices.PROFILE_SUFFIXES
    assert set(kinds.kind_names()) == {"drawing", "digitized", "gcode", "excellon", "hpgl", "svg", "dxf"}


def test_no_steps_per_pixel_trick_in_the_library():
    """Jobs are in machine steps: no planner fakes pixels by setting one step per pixel."""
    for path in (ROOT / "cam").rglob("*.py"):
        text = path.read_text()
        assert "steps_per_px_xy=1" not in text and "steps_per_px_z=1" not in text, path


def test_port_names_are_read_in_one_place():
    """Only cam.drive.ports (and the MAXIMUS board's own URL parser) look at a "maximus:" prefix."""
    readers = {p.relative_to(ROOT).as_posix() for p in (ROOT / "cam").rglob("*.py")
               if 'startswith("maximus:")' in p.read_text() or "startswith('maximus:')" in p.read_text()}
    assert readers == set(), readers
