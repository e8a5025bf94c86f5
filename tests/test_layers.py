"""No import knot (issue #48 point 4): cam's packages form layers, and no import climbs one.

Bottom to top: the core (the top-level modules: errors, settings, the tool, the pin map, ...), pictures, the file
readers and digitizers, the planners, the checks, the step plans, the file-kind registry, the machines, the
emulators, the public names, the page, the command line.  A module may import the modules of its own unit (its
package; for a top-level module of the core, the whole core) and of units in LOWER layers, never one of its own
layer or above: two units of one layer (digitize and formats) do not import each other.  Imports at a module's top
and inside functions count alike; imports under ``if TYPE_CHECKING:`` never run and do not.

No private name crosses packages either: a name or a module starting with ``_`` (not a dunder) is imported only
inside its own package (a top-level module is a package of its own here).  cam's top-level private modules
(``cam._compiled``, ``cam._kernel_signatures``, ``cam._kernel_cache``) are cam-wide infrastructure: importing one is
no private crossing (their private names still are), though the layers still hold (``cam._kernel_cache`` runs the
command line, so only the application imports it).

The source is read with :mod:`ast` (the helpers of tests/test_imports.py): nothing is imported to learn what
imports what.
"""
from __future__ import annotations

import ast
from typing import NamedTuple, Optional

from conftest import ROOT, parsed_source
from test_imports import MODULES, import_statements, import_targets

CORE = "core"
APPLICATION = "application"

LAYERS: dict[str, tuple[int, str]] = {
    CORE: (0, "facts and small tools every layer uses: errors, settings, ranges, the tool, the pin map, file I/O"),
    "render": (1, "pictures of jobs and surfaces, PNG and SVG encoding"),
    "digitize": (2, "image files to digitized pixel paths"),
    "formats": (2, "file readers (Excellon, G-code, HPGL, SVG, DXF) and G-code export"),
    "job": (3, "planners: each file's reader output to moves in steps"),
    "verify": (4, "decoding pin logs, checking ramps"),
    "motion": (5, "step plans: a job's moves to the machine's writes, with their speed ramps"),
    "kinds": (6, "the file-kind registry: prepare_job, JobOptions, PreparedJob, G-code export (issue #48 point 1)"),
    "drive": (7, "ports, machines, the runner, the machine session, the grbl and MAXIMUS hosts"),
    "sim": (8, "the grbl and MAXIMUS emulators"),
    "api": (9, "the public names of cam/__init__.py (loaded lazily, from the layers below)"),
    "web": (10, "the page (cam serve)"),
    "cli": (11, "the command line; 'cam serve' starts the page"),
    APPLICATION: (12, "programs over all of cam: python -m cam, the kernel cache filler"),
}
"""Unit -> (layer, what it holds).  A unit is a package of cam (cam/NAME/), or a group of top-level modules
(:data:`TOP_LEVEL`).  ``kinds`` does not exist yet: the lead's package of issue #48 point 1 takes its place here."""

TOP_LEVEL: dict[str, tuple[str, str]] = {
    "cam": ("api", "the public names: imports nothing at its top, each name loads on first use"),
    "cam.__main__": (APPLICATION, "python -m cam: runs the command line"),
    "cam._kernel_cache": (APPLICATION, "fills numba's cache: runs the command line's sample jobs"),
    "cam._compiled": (CORE, "numba's cache folder, the kernel marker and the kernel list (cam-wide infrastructure)"),
    "cam._kernel_signatures": (CORE, "generated table of kernel argument types (data)"),
    "cam.arrays": (CORE, "array helpers"),
    "cam.choices": (CORE, "file kinds and the choices --help names (standard library only)"),
    "cam.errors": (CORE, "the error classes, rooted in CamError"),
    "cam.fileio": (CORE, "atomic writes, bounded reads, the user's state folder"),
    "cam.limits": (CORE, "number ranges"),
    "cam.machine_file": (CORE, "the machine file (settings and tools as TOML): reads settings and tools only"),
    "cam.options": (CORE, "the job options declared once"),
    "cam.pins": (CORE, "the step/dir pin map as register bits (thesis Tables 3.2/3.3)"),
    "cam.settings": (CORE, "machine settings"),
    "cam.sniff": (CORE, "a file's kind from its first bytes"),
    "cam.tool": (CORE, "cutter shapes and the drop-cutter rule"),
    "cam.tool_table": (CORE, "the tool table file: reads tools and the state folder only"),
    "cam.values": (CORE, "values shown to the user (numbers, units)"),
    "cam.worker": (CORE, "a child process that runs named calls under a memory limit; it knows no job"),
}
"""Top-level module -> (unit, why it is there).  Every top-level module of cam is listed."""

PENDING: set[tuple[str, str]] = set()
"""(importing module, imported module or name) allowed for now though it climbs a layer or takes a private name;
each entry must still be found (a stale entry fails the tests)."""


class Finding(NamedTuple):
    """One import that breaks a rule: where, who imports what, and why it is refused."""

    where: str  # path:line
    importer: str
    imported: str  # a module, or module.name for a private name
    why: str

    def __str__(self) -> str:
        return f"{self.where}: {self.importer} imports {self.imported}: {self.why}"


def unit_of(module: str) -> str:
    """The unit of cam module ``module``: its package (``cam.job.svg`` -> ``job``), or for a top-level module the
    unit :data:`TOP_LEVEL` gives it (KeyError: an unlisted top-level module)."""
    parts = module.split(".")
    if module in TOP_LEVEL:
        return TOP_LEVEL[module][0]
    if len(parts) > 2 or MODULES.get(module, ROOT).name == "__init__.py":
        return parts[1]
    raise KeyError(f"{module}: a top-level module not in TOP_LEVEL (give it a unit and a reason)")


def layer_of(module: str) -> int:
    """The layer number of cam module ``module`` (:data:`LAYERS`)."""
    return LAYERS[unit_of(module)][0]


def package_of(module: str) -> str:
    """The package a private name belongs to: ``cam.X`` for any module under cam/X/, or the top-level module
    ``cam.X`` itself."""
    return ".".join(module.split(".")[:2])


def _imported_modules(importer: str, node: ast.stmt) -> list[str]:
    """The cam modules an import statement of ``importer`` names: ``from p import m`` names ``p.m`` when ``m`` is a
    module (``p`` too only when some name is not a module: a package's own ``__init__``)."""
    targets = import_targets(importer, node)
    if isinstance(node, ast.ImportFrom) and len(targets) == len(node.names) + 1:
        targets = targets[1:]  # every name is a module: the package itself only holds them
    return [t for t in targets if t == "cam" or t.startswith("cam.")]


def _private_names(importer: str, node: ast.stmt) -> list[str]:
    """The private names (``_x``, not ``__x__``) an import statement takes from another package: whole dotted
    names, a private module of a package (``cam.drive._kernels``) or a private name of any module
    (``cam.tool._lowest``).  cam's top-level private modules themselves are allowed."""
    def private(part: str) -> bool:
        return part.startswith("_") and not (part.startswith("__") and part.endswith("__"))

    found = []
    modules = import_targets(importer, node)
    names = [f"{modules[0]}.{a.name}" for a in node.names] if isinstance(node, ast.ImportFrom) else modules
    for full in names:
        if not (full.startswith("cam.") and package_of(full) != package_of(importer)):
            continue
        if any(private(part) for part in full.split(".")[2:]):
            found.append(full)
    return found


def check_imports(importer: str, tree: ast.AST, path: str) -> list[Finding]:
    """Every import in ``tree`` (the source of cam module ``importer``, file ``path``) that climbs a layer or takes
    a private name from another package, at the module's top or in a function; ``TYPE_CHECKING`` imports skipped."""
    findings = []
    here = layer_of(importer)
    for node, _function in import_statements(tree):
        where = f"{path}:{node.lineno}"
        for target in _imported_modules(importer, node):
            if target not in MODULES:
                continue  # a name of a package's __init__ that is no module: the package counts (targets has it)
            if unit_of(target) == unit_of(importer):
                continue
            there = layer_of(target)
            if there >= here:
                findings.append(Finding(where, importer, target,
                                        f"layer {there} ({unit_of(target)}) from layer {here} ({unit_of(importer)}): "
                                        "an import may only go down a layer"))
        for name in _private_names(importer, node):
            findings.append(Finding(where, importer, name, "a private name of another package"))
    return findings


def findings_of_the_package() -> list[Finding]:
    """:func:`check_imports` over every module under cam/."""
    found = []
    for name, path in MODULES.items():
        found += check_imports(name, parsed_source(path), str(path.relative_to(ROOT)))
    return found


def _not_pending(findings: list[Finding], why: str) -> list[str]:
    return [str(f) for f in findings if why in f.why and (f.importer, f.imported) not in PENDING]


# -- the package ------------------------------------------------------------------------------------------------


def test_every_unit_has_a_layer():
    packages = {unit_of(m) for m in MODULES if m.count(".") >= 1 and MODULES[m].parent != ROOT / "cam"}
    assert packages <= set(LAYERS), f"packages with no layer in LAYERS: {sorted(packages - set(LAYERS))}"
    top = {m for m, p in MODULES.items() if p.parent == ROOT / "cam"}
    assert top == set(TOP_LEVEL), (f"top-level modules with no unit: {sorted(top - set(TOP_LEVEL))}; "
                                   f"listed but gone: {sorted(set(TOP_LEVEL) - top)}")
    assert all(reason.strip() for _unit, reason in TOP_LEVEL.values())
    assert all(unit in LAYERS for unit, _reason in TOP_LEVEL.values())


def test_no_import_climbs_a_layer():
    climbs = _not_pending(findings_of_the_package(), "an import may only go down")
    assert not climbs, "imports that climb a layer (tests/test_layers.py LAYERS):\n" + "\n".join(climbs)


def test_no_private_name_crosses_packages():
    crossings = _not_pending(findings_of_the_package(), "private name")
    assert not crossings, "private names imported from another package:\n" + "\n".join(crossings)


def test_pending_imports_are_still_there():
    found = {(f.importer, f.imported) for f in findings_of_the_package()}
    stale = PENDING - found
    assert not stale, f"no longer found (remove from PENDING): {sorted(stale)}"


# -- the checker itself -----------------------------------------------------------------------------------------


def _check(importer: str, source: str) -> list[Finding]:
    return check_imports(importer, ast.parse(source), "x.py")


def test_the_checker_catches_a_climbing_import():
    """render (layer 1) importing the session (drive, layer 7): at the top, in a function, relative or absolute."""
    for source in ("from ..drive.session import MachineSession\n",
                   "def f():\n    import cam.drive.session\n",
                   "from ..drive import session\n"):
        (finding,) = _check("cam.render.picture", source)
        assert finding.importer == "cam.render.picture" and finding.imported == "cam.drive.session", source
        assert finding.where.startswith("x.py:") and "layer 7 (drive) from layer 1 (render)" in str(finding)


def test_the_checker_refuses_a_unit_of_the_same_layer_and_allows_going_down():
    (finding,) = _check("cam.digitize.drawing", "from ..formats.svg import SvgDrawing\n")
    assert "layer 2 (formats) from layer 2 (digitize)" in finding.why
    assert _check("cam.drive.session", "from ..job.model import Job\nfrom ..errors import CamError\n") == []
    assert _check("cam.settings", "from .tool import Tool\nfrom . import errors\n") == []  # core to core


def test_the_checker_skips_type_checking_imports():
    source = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..job.model import Job\n"
    assert _check("cam.render.report", source) == []


def test_the_checker_catches_a_private_name():
    (name,) = _check("cam.job.subpixel", "from ..tool import Tool, _lowest\n")
    assert (name.imported, name.why) == ("cam.tool._lowest", "a private name of another package")
    (module,) = _check("cam.sim.maximus", "from ..drive.maximus._trust import clear_fault_marker\n")
    assert module.imported == "cam.drive.maximus._trust.clear_fault_marker"
    assert _check("cam.job.svg", "from ._svg_kernels import cells_kernel\n") == []  # its own package
    assert _check("cam.job._route", "from .._compiled import entry\n") == []  # cam-wide infrastructure
    assert _check("cam.drive.ports", "from ..errors import __name__\n") == []  # a dunder is no private name


def test_the_finding_names_file_line_importer_imported_and_layers():
    (finding,) = _check("cam.job.gcode", "import os\n\nfrom ..drive.runner import Cursor\n")
    assert str(finding) == ("x.py:3: cam.job.gcode imports cam.drive.runner: layer 7 (drive) from layer 3 (job): "
                            "an import may only go down a layer")


def test_layer_of_top_level_modules_and_packages():
    assert layer_of("cam.errors") == 0 and layer_of("cam.pins") == 0
    assert layer_of("cam.motion.chunks") == 5 and layer_of("cam.drive.maximus.board") == 7
    assert layer_of("cam") == 9 and layer_of("cam.__main__") == 12
    assert unit_of("cam.drive") == "drive"
