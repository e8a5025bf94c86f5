"""One module per file kind (issue #48 point 1): the table, the rules every kind module keeps, and a new kind added
as its module and one registry line, then cut, shown, exported and offered by every front end.

The new kind is an "XY hole list": a CSV of ``x_mm,y_mm,d_mm`` rows under that header, as a spreadsheet or a
pick-and-place export writes it.  Its module is written here into a temporary folder, loaded, and registered with
:func:`cam.kinds.register` (the run-time form of its line in :data:`cam.kinds.KIND_MODULES`); nothing else of
`cam` is told about it.
"""
from __future__ import annotations

import ast
import contextlib
import importlib.util
import io
import json
import sys

import numpy as np
import pytest

from cam import kinds
from cam.cli import main
from cam.kinds.jobs import JobOptions, prepare_job
from cam.settings import MachineSettings
from cam.verify.pinlog import decode_pin_log, read_pin_log

from conftest import ROOT

XYD_MODULE = '''
"""XY hole lists: x_mm,y_mm,d_mm rows under that header (a spreadsheet's export), drilled hole by hole."""
from pathlib import Path

from cam.kinds import Head, Kind


def _sniff(head: Head) -> bool:
    return head.text is not None and bool(head.lines) and head.lines[0].replace(" ", "") == "X_MM,Y_MM,D_MM"


def _holes(path):
    import numpy as np

    from cam.formats.excellon import HoleList

    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    sizes = sorted(set(rows[:, 2].tolist()))
    tools = {i + 1: d for i, d in enumerate(sizes)}
    tool_of = np.array([sizes.index(d) + 1 for d in rows[:, 2]], np.int64)
    return HoleList(holes_mm=rows[:, :2].copy(), tool_of_hole=tool_of, tools=tools,
                    line_of_hole=np.arange(2, len(rows) + 2), source=str(path))


def _prepare(path, options, settings, *, home=None, progress=None, machine_state=None):
    from cam.job.drill import plan_drill
    from cam.kinds.jobs import PreparedJob, plan_chunks

    depth = KIND.default("cut_depth_mm") if options.cut_depth_mm is None else options.cut_depth_mm
    travel = KIND.default("travel_height_mm") if options.travel_height_mm is None else options.travel_height_mm
    dp = plan_drill(_holes(path), settings=settings, cut_depth_mm=depth, travel_height_mm=travel,
                    offset_mm=options.offset_mm, mirror_x=options.mirror_x, drill_order=options.drill_order,
                    home_steps=home)
    n = len(dp.holes_steps)
    return PreparedJob(source=str(path), kind="xyd", plan=plan_chunks(dp.toolpath, start_steps=home, fingerprint=True),
                       settings=settings, toolpath=dp.toolpath, summary=f"{Path(path).name}: {n} listed holes",
                       report={"holes": n}, drill_plan=dp, depth_mm=depth)


def _info(path, options, settings, *, prepare, progress=None):
    return {"source": str(path), "kind": "xyd", "holes": len(_holes(path).holes_mm)}


def _info_lines(rep, name):
    return [f"{name}: {rep['holes']} listed holes"]


KIND = Kind(name="xyd", noun="an XY hole list", title="XY hole list", suffixes=(".xyd",),
            traits=frozenset({"placed", "holes"}), prepare=_prepare, sniff=_sniff, sniff_rank=45, info=_info,
            info_lines=_info_lines, job_noun="hole list job", help="is drilled hole by hole")
'''

HOLES_MM = np.array([[5.0, 5.0], [25.0, 5.0], [25.0, 15.0], [10.0, 20.0]])


@pytest.fixture
def xyd(tmp_path):
    """The new kind, registered for one test, and a file of it with a name its suffix does not say (``.txt``)."""
    module_path = tmp_path / "xyd_kind.py"
    module_path.write_text(XYD_MODULE)
    spec = importlib.util.spec_from_file_location("xyd_kind", module_path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    kinds.register(module.KIND)  # the one line a new kind adds to the table
    try:
        path = tmp_path / "plate holes.txt"
        path.write_text("x_mm, y_mm, d_mm\r\n" + "".join(f"{x},{y},0.8\r\n" for x, y in HOLES_MM))
        yield path
    finally:
        kinds.unregister("xyd")


def _cam(*argv: str, stdin: str = "") -> tuple[int, str, str]:
    """``cam ARGV`` in this process (the kind registered here), with ``stdin`` answering its prompts."""
    out, err = io.StringIO(), io.StringIO()
    real_stdin = sys.stdin
    sys.stdin = io.StringIO(stdin)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in argv])
            except SystemExit as exc:  # --help, and argparse's own errors
                code = int(exc.code or 0)
    finally:
        sys.stdin = real_stdin
    return code, out.getvalue(), err.getvalue()


def _plunges_xy(position_steps: np.ndarray) -> np.ndarray:
    """(x, y) steps of each descent below the surface."""
    below = position_steps[:, 2] > 0
    starts = np.flatnonzero(below & ~np.concatenate([[False], below[:-1]]))
    return position_steps[starts, :2]


def test_every_kind_is_one_module_of_the_table():
    table = kinds.kinds()
    assert [k.name for k in table] == list(kinds.KIND_MODULES)
    for name in kinds.KIND_MODULES:
        module = importlib.import_module(f"cam.kinds.{name}")
        assert module.KIND.name == name and module.KIND.prepare.__module__ == module.__name__, name
    every = [s for k in table for s in k.suffixes]
    assert len(every) == len(set(every)), "a suffix names one kind"
    assert len(set(kinds.forced_names())) == len(table)
    assert {k.name for k in table} == {"drawing", "digitized", "gcode", "excellon", "hpgl", "svg", "dxf"}


def test_kind_names_are_compared_only_in_their_own_modules():
    """No if/elif on kind names outside the kind modules: a comparison with a kind's name (``kind == "excellon"``,
    ``kind in ("svg", "dxf")``) is dispatch the table does.  The digitized matrix's and the drawing's own commands
    (cam digitize, --load-digitized, --save-digitized) and the Excellon-only flags name their kind by its module."""
    names = set(kinds.KIND_MODULES) | {"matrix"}
    found = []
    for path in sorted((ROOT / "cam").rglob("*.py")):
        if path.parent.name == "kinds" and path.stem in kinds.KIND_MODULES:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                constants = [c.value for s in sides for c in ast.walk(s) if isinstance(c, ast.Constant)]
                if any(c in names for c in constants) and not any(
                        isinstance(s, ast.Attribute) and s.attr == "name" for s in sides) \
                        and "tag" not in ast.unparse(node):  # an SVG element's tag is no kind
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "dispatch on a kind's name outside its module:\n" + "\n".join(found)


def test_options_apply_by_traits_and_defaults_are_declared_once():
    assert kinds.option_kinds()["mirror_x"] == frozenset({"excellon"})
    assert kinds.option_kinds()["layers"] == frozenset({"svg", "dxf"})
    assert kinds.option_kinds()["level"] == frozenset(kinds.KIND_MODULES)
    from cam.job import drill, hpgl_stream, svg
    from cam.options import OPTIONS

    assert drill.DEFAULT_CUT_DEPTH_MM == kinds.kind("excellon").default("cut_depth_mm") == 2.0
    assert svg.DEFAULT_CUT_DEPTH_MM == hpgl_stream.DEFAULT_CUT_DEPTH_MM == kinds.kind("dxf").default("cut_depth_mm")
    assert kinds.kind("drawing").default("cut_depth_mm") is None  # a drawing's depth is its own (10 Z px)
    assert OPTIONS["cut_depth_mm"].trait_defaults == (("holes", 2.0), ("strokes", 0.5))
    assert kinds.kind_defaults()["hpgl"] == {"cut_depth_mm": 0.5, "travel_height_mm": 1.0}


def test_a_new_kind_is_its_module_and_one_registry_line(xyd, tmp_path):
    settings = MachineSettings()
    # recognised by its content (.txt says nothing certain), named by its suffix, forced by --kind
    assert kinds.job_kind(xyd) == "xyd" and kinds.job_kind("a.XYD") == "xyd"
    assert kinds.forced_kind("xyd") == "xyd" and "xyd" in kinds.suffixes()
    # its traits bring the options of drill files and their defaults: 2 mm deep, travel 1 mm
    assert kinds.option_kinds()["mirror_x"] == frozenset({"excellon", "xyd"})
    assert kinds.kind_defaults()["xyd"] == {"cut_depth_mm": 2.0, "travel_height_mm": 1.0}
    job = prepare_job(xyd, JobOptions())
    assert job.kind == "xyd" and abs(job.depth_mm - 2.0) <= settings.mm_per_step_z and job.report["holes"] == 4
    with pytest.raises(Exception, match="layers"):
        prepare_job(xyd, JobOptions(layers="top"))  # an SVG/DXF option: refused, naming it

    # cam drill on the mock: the pin log decoded back into motion drills every hole where the list says
    log = tmp_path / "pins.csv"
    code, out, err = _cam("drill", xyd, "--pin-log", log, stdin="\n")  # Enter at the tool change to T1
    assert code == 0, err
    assert "4 listed holes" in out
    motion = decode_pin_log(read_pin_log(log), settings)
    got = _plunges_xy(motion.position_steps)
    assert len(got) == 4 and motion.position_steps[:, 2].max() == round(2.0 / settings.mm_per_step_z)
    want = np.column_stack([HOLES_MM[:, 0] - HOLES_MM[:, 0].min(), HOLES_MM[:, 1].max() - HOLES_MM[:, 1]])
    want = np.rint(want / settings.mm_per_step_xy)
    rel = got - got.min(axis=0)
    assert sorted(map(tuple, rel.tolist())) == sorted(map(tuple, want.tolist()))

    # cam info (text and JSON), cam preview, cam export, --help: all from the table
    code, out, err = _cam("info", xyd)
    assert code == 0 and "plate holes.txt: 4 listed holes" in out, err
    code, out, _ = _cam("info", xyd, "--json")
    assert json.loads(out[:out.rindex("}") + 1])["holes"] == 4
    picture = tmp_path / "holes.png"
    code, out, err = _cam("preview", xyd, "-o", picture)
    assert code == 0 and picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", err
    ngc = tmp_path / "holes.ngc"
    code, out, err = _cam("export", xyd, "-o", ngc)
    assert code == 0, err
    plunges = [ln for ln in ngc.read_text().splitlines() if ln.startswith("G1 Z-")]  # at its steps: Z-1.9939
    assert len(plunges) == 4
    code, out, _ = _cam("drill", "--help")
    assert ".xyd" in " ".join(out.split()) and "drilled hole by hole" in " ".join(out.split())
    # a flag of another kind: one line naming it
    code, out, err = _cam("drill", xyd, "--layers", "top")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--layers" in err and "xyd" in err


def test_the_page_lists_the_kinds_from_the_table(xyd):
    from cam.kinds import kinds_json

    listed = {k["name"]: k for k in kinds_json()}
    assert listed["xyd"]["title"] == "XY hole list" and listed["xyd"]["suffixes"] == [".xyd"]
    assert listed["digitized"]["forced_as"] == "matrix"
    app = (ROOT / "cam" / "web" / "static" / "app.js").read_text()
    html = (ROOT / "cam" / "web" / "static" / "index.html").read_text()
    assert "/api/kinds" in app and "forcedKind" in app
    for name in kinds.KIND_MODULES:  # the page's HTML names no kind itself: the list is served
        assert f'value="{name}"' not in html


def test_registering_a_kind_twice_is_refused(xyd):
    with pytest.raises(Exception, match="exists already"):
        kinds.register(kinds.kind("xyd"))
