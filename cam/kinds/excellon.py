"""Excellon drill files: the holes of a PCB, drilled tool by tool (:mod:`cam.formats.excellon`, :mod:`cam.job.drill`).

PCB programs name their drill files by habit, not by the Excellon suffixes (Altium ``NC Drill/*-RoundHoles.TXT``,
Fritzing ``*_drill.txt``, CNC programs ``.nc``), so a file whose suffix says nothing certain is recognised by its
content: :func:`excellon_or_gcode` weighs the evidence for a drill file against that for G-code (issue #31
point 1), and the G-code kind (:mod:`cam.kinds.gcode`) asks it too.
"""
from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path
from typing import Any, Optional

from . import Head, Kind

__all__ = ["KIND", "excellon_or_gcode"]

_EXC_HEADER = re.compile(
    r"M48|M7[12]|(?:INCH|METRIC)(?:,.*)?|FMAT,\d|ICI,.*|VER,\d|DETECT,.*|ATC,.*|OSTOP,.*|"
    r"T\d+(?:[FSBHZ][-+\d.]*)*C[\d.]+.*"  # a tool definition: T1C0.8, T01F00S00C0.0280
)
_EXC_COORD = re.compile(r"(?:T\d+)?(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?")
_EXC_TOOL = re.compile(r"T\d+")
_EXC_COMMENT = re.compile(r";\s*(?:FILE_FORMAT|TYPE=|LAYER_COLOR|HEADER:|DRILL FILE|HOLESIZE|#@!)", re.I)
_EXC_REPEAT = re.compile(r"R\d+(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?")  # Allegro's R02X001000: a repeated hole
_EXC_ROUTE_M = re.compile(r"M1[567]")  # Excellon routing: plunge, retract
_EXC_ROUTE = re.compile(r"G0[0-3](?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?(?:[AIJ][-+]?[\d.]+)*")  # G00X..Y.., no spaces
_EXC_DRILL_G = re.compile(r"G(?:05|85|90|93)(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?|(?:X[-+]?[\d.]+)?(?:Y[-+]?[\d.]+)?G85.*")
_EXC_HOLESIZE = re.compile(r";\s*(?:T\d+\s+)?HOLESIZE\s+\d+", re.I)

_GC_WORD = re.compile(r"([A-Z])\s*([-+]?(?:\d+(?:\.\d*)?|\.\d+))")
# each number reads one way only (digits, then an optional fraction): a long line that fails to match
# cannot start a backtracking storm (a 7 kB drill file hung the sniffer for minutes)
_GC_LINE = re.compile(r"(?:[A-Z]\s*[-+]?(?:\d+(?:\.\d*)?|\.\d+)\s*)+")
_GC_COMMENT = re.compile(r"\([^)]*\)|;.*")


@lru_cache(maxsize=16)
def excellon_or_gcode(lines: tuple[str, ...]) -> Optional[str]:
    """"excellon", "gcode" or None for a text file's lines (:attr:`cam.kinds.Head.lines`), by weighed evidence.

    For Excellon: a header (``M48``, ``M71`` / ``M72``, ``INCH`` / ``METRIC``, ``FMAT``, tool definitions
    ``T1C0.8``), its comments (Allegro's ``;T01 Holesize 1. = ...``, ``;FILE_FORMAT``, ...), ``R`` repeat codes,
    routing (``M15`` / ``M16`` with the ``G00`` / ``G01`` moves between them, written without spaces), tool
    selections and bare ``X..Y..`` holes.  For G-code: words with spaces, ``Z``, ``F``, ``S``, spindle and tool
    change ``M`` codes, plane and unit ``G`` codes, ``I`` / ``J`` arcs outside Excellon routing.
    """
    routes = any(_EXC_ROUTE_M.fullmatch(_GC_COMMENT.sub("", raw).strip()) for raw in lines)
    exc_strong = 0.0
    exc_weak = 0.0
    exc_tool = exc_coord = 0
    gcode_strong = gcode_like = 0
    for raw in lines:
        if raw.startswith(";"):
            if _EXC_HOLESIZE.match(raw):
                exc_strong += 3
            elif _EXC_COMMENT.match(raw):
                exc_strong += 2
            continue
        line = _GC_COMMENT.sub("", raw).strip()
        if not line or line == "%":
            continue
        if _EXC_HEADER.fullmatch(line):
            exc_strong += 3
            continue
        if _EXC_TOOL.fullmatch(line):
            exc_tool += 1
            continue
        if " " not in line and ("X" in line or "Y" in line) and _EXC_COORD.fullmatch(line):
            exc_coord += 1
            continue
        if " " not in line and _EXC_REPEAT.fullmatch(line):
            exc_strong += 2
            continue
        if routes and " " not in line and (_EXC_ROUTE_M.fullmatch(line) or _EXC_ROUTE.fullmatch(line)):
            exc_strong += 1
            continue
        if " " not in line and _EXC_DRILL_G.fullmatch(line):
            exc_weak += 1
            continue
        if not _GC_LINE.fullmatch(line):
            continue
        gcode_like += 1
        words = {(letter, float(value)) for letter, value in _GC_WORD.findall(line)}
        letters = {letter for letter, _ in words}
        if (letters & {"Z", "F", "I", "J", "R", "S"}
                or any(letter == "G" and value in (0, 1, 2, 3, 17, 20, 21, 28, 54, 91) for letter, value in words)
                or any(letter == "M" and value in (3, 4, 5, 6) for letter, value in words)):
            gcode_strong += 1
    exc_score = exc_strong + exc_weak + exc_tool + 0.25 * exc_coord
    gcode_score = 2.0 * gcode_strong + 0.5 * (gcode_like - gcode_strong)
    if exc_strong and exc_score >= gcode_score:
        return "excellon"
    if exc_tool and exc_coord and exc_score >= gcode_score:
        return "excellon"  # a headless drill file (old Eagle, P-CAD): tool selects and X..Y.. holes
    if gcode_like:
        return "gcode"
    if exc_tool and exc_coord:
        return "excellon"
    return None


def _sniff(head: Head) -> bool:
    return head.plain_text and excellon_or_gcode(head.lines) == "excellon"


def _options_of(options: Any) -> dict[str, Any]:
    return dict(excellon_units=options.excellon_units, excellon_digits=options.excellon_digits,
                excellon_zeros=options.excellon_zeros, strict=bool(options.strict))


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    import numpy as np

    from ..formats.excellon import load_excellon
    from ..job.drill import plan_drill
    from .jobs import PreparedJob, plan_chunks

    holes = load_excellon(path, **_options_of(options))
    depth_mm = KIND.default("cut_depth_mm") if options.cut_depth_mm is None else options.cut_depth_mm
    travel_mm = KIND.default("travel_height_mm") if options.travel_height_mm is None else options.travel_height_mm
    dp = plan_drill(holes, settings=settings, cut_depth_mm=depth_mm, travel_height_mm=travel_mm,
                    offset_mm=options.offset_mm, mirror_x=options.mirror_x, drill_order=options.drill_order,
                    mill_holes_over_mm=options.mill_holes_over_mm, home_steps=home)
    steps = plan_chunks(dp.toolpath, start_steps=home, fingerprint=True)
    tools = ", ".join(f"T{t} {dia:.3f} mm x{n}" for t, dia, n in dp.tool_sequence)
    hole_xy = np.asarray(dp.holes_steps, np.int64).reshape(-1, 2)
    span = dp.extent_steps[1] - dp.extent_steps[0]  # holes and milled slots (issue #31 point 4)
    milled = (f", {dp.n_slots} slots" if dp.n_slots else "") + (f", {dp.n_milled} holes milled" if dp.n_milled else "")
    return PreparedJob(
        source=str(path), kind="excellon", plan=steps, settings=settings, toolpath=dp.toolpath,
        size_mm=(round(float(span[0]) * settings.mm_per_step_axes[0], 3),
                 round(float(span[1]) * settings.mm_per_step_axes[1], 3)),
        depth_mm=round(depth_mm, 4),
        warnings=list(holes.warnings), summary=f"{path.name}: {len(hole_xy)} holes{milled} ({tools})",
        report={"holes": len(hole_xy), "tools": [list(t) for t in dp.tool_sequence],
                **({"slots": dp.n_slots} if dp.n_slots else {}), **({"milled_holes": dp.n_milled} if dp.n_milled else {})},
        drill_plan=dp if not (dp.n_slots or dp.n_milled) else None,  # the MAXIMUS board's drill mode only drills
    )


def _info(path: Path, options: Any, settings: Any, *, prepare: Any = None, progress: Any = None) -> dict:
    """The holes, tools, extent and warnings of a drill file as read (nothing planned)."""
    from ..formats.excellon import load_excellon

    holes = load_excellon(path, **_options_of(options))
    x0, y0, x1, y1 = holes.extent_mm()
    tools = []
    for tool, dia, count in holes.tool_table():
        slots = holes.slot_count(tool)
        tools.append({"tool": int(tool), "diameter_mm": float(dia), "holes": int(count), **({"slots": slots} if slots else {})})
    return {"source": str(path), "kind": "excellon", "holes": len(holes.holes_mm), "extent_mm": [x0, y0, x1, y1],
            "size_mm": [round(x1 - x0, 4), round(y1 - y0, 4)], "tools": tools, "warnings": list(holes.warnings)}


def _info_lines(rep: dict, name: str) -> list[str]:
    x0, y0, x1, y1 = rep["extent_mm"]
    lines = [f"{name}: {rep['holes']} holes, board extent X {x0:.3f}..{x1:.3f} mm, "
             f"Y {y0:.3f}..{y1:.3f} mm ({x1 - x0:.2f} x {y1 - y0:.2f} mm)"]
    for t in rep["tools"]:
        slots = t.get("slots", 0)
        lines.append(f"  T{t['tool']}: {t['diameter_mm']:.3f} mm, {t['holes']} holes" + (f", {slots} slots" if slots else ""))
    return lines + [f"warning: {w}" for w in rep["warnings"]]


def _exact_geometry(prepared: Any, cut_depth_mm: Optional[float], options: Any) -> tuple[dict, dict]:
    """A drill file's holes at their mm before rounding to steps (the first hole of a step wins), and
    ``cut_depth_mm`` for its drill depth."""
    import numpy as np

    xy: dict[tuple[int, int], tuple[float, float]] = {}
    z: dict[int, float] = {}
    plan = getattr(prepared, "drill_plan", None)
    if plan is not None and getattr(plan, "holes_mm", None) is not None:
        for (xs, ys), (xm, ym) in zip(np.asarray(plan.holes_steps).tolist(), np.asarray(plan.holes_mm).tolist()):
            xy.setdefault((int(xs), int(ys)), (float(xm), float(ym)))
        mm_z = prepared.settings.mm_per_step_z
        if cut_depth_mm is not None and plan.depth_steps > 0 and round(cut_depth_mm / mm_z) == plan.depth_steps:
            z[int(plan.depth_steps)] = float(cut_depth_mm)
    return xy, z


KIND = Kind(
    name="excellon", noun="an Excellon drill file", title="Excellon drill file",
    suffixes=(".drl", ".xln", ".exc", ".drd"), traits=frozenset({"placed", "holes"}),
    prepare=_prepare, sniff=_sniff, sniff_rank=60, info=_info, info_lines=_info_lines,
    exact_geometry=_exact_geometry, job_noun="drill job",
    help="is drilled tool by tool in a short order, also on the MAXIMUS board (--port maximus:/dev/ttyUSB0)",
)
