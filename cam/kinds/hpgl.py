"""HPGL pen-plotter files: every pen-down stroke cut at the cut depth (:mod:`cam.formats.hpgl`,
:mod:`cam.job.hpgl_stream`)."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Optional

from . import Head, Kind

__all__ = ["KIND"]

_HPGL_TOKEN = re.compile(r"(?:[A-Z]{2}[-+\d.,\s]*)+")
_HPGL_MOTION = re.compile(r"IN|PU|PD|PA|PR|SP")
_ESCAPE = re.compile(r"\x1b\.[^A-Za-z:]*[A-Za-z:]?")  # an HP-GL/2 device escape (ESC . ...)


def _sniff(head: Head) -> bool:
    """Mostly two-letter mnemonics with numbers, split by ``;``, some of them pen moves."""
    if not head.plain_text:
        return False
    text = _ESCAPE.sub("", " ".join(head.lines))
    tokens = [t.strip() for t in re.split(r";", text) if t.strip()]
    if not tokens or not _HPGL_MOTION.search(text):
        return False
    good = sum(1 for t in tokens if _HPGL_TOKEN.fullmatch(t))
    return good >= 0.8 * len(tokens) and any(t[:2] in ("PU", "PD", "PA", "PR") for t in tokens)


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    from ..formats.hpgl import scan_hpgl
    from ..job.hpgl_stream import STREAM_POINTS, stream_hpgl
    from .jobs import PreparedJob, engraving, plan_chunks

    depth_mm, engraved = engraving(options, settings, KIND.default("cut_depth_mm"))
    scan = scan_hpgl(path, progress=progress)
    travel_mm = KIND.default("travel_height_mm") if options.travel_height_mm is None else options.travel_height_mm
    stream = stream_hpgl(path, settings=settings, cut_depth_mm=depth_mm, travel_height_mm=travel_mm,
                         offset_mm=options.offset_mm, scan=scan, scale=options.scale, fit_mm=options.fit_mm,
                         home_steps=home)
    # one planner whatever the size: above STREAM_POINTS its pieces are read from the file on every pass (bounded
    # memory), below they are joined and held (the step planner then sees every move: linear40 ramps)
    toolpath = stream if scan.n_points > STREAM_POINTS else stream.joined()
    return PreparedJob(
        source=str(path), kind="hpgl", plan=plan_chunks(toolpath, start_steps=home, fingerprint=True),
        settings=settings, toolpath=toolpath,
        warnings=list(scan.warnings), summary=f"{path.name}: {scan.n_strokes} pen-down strokes",
        report={"strokes": scan.n_strokes, "points": scan.n_points, "pens": sorted(set(scan.pens)), **engraved},
    )


def _info(path: Any, options: Any, settings: Any, *, prepare: Any = None, progress: Any = None) -> dict:
    """The strokes, pens, extent and commands of a plotter file, read once (nothing planned)."""
    from ..formats.hpgl import scan_hpgl

    scan = scan_hpgl(path, progress=progress)
    return {"source": str(path), "kind": "hpgl", **scan.__dict__, "size_mm": scan.size_mm()}


def _info_lines(rep: dict, name: str) -> list[str]:
    from ..formats.hpgl import PLOTTER_UNIT_MM

    lines = [f"{name}: {rep['n_strokes']} pen-down strokes, {rep['n_points']} points, pens "
             f"{', '.join(map(str, rep['pens'])) or 'none selected'}"]
    if rep["extent_pu"] is not None:
        x0, y0, x1, y1 = rep["extent_pu"]
        w, h = rep["size_mm"]
        lines.append(f"  extent X {x0:g}..{x1:g}, Y {y0:g}..{y1:g} plotter units ({w:.2f} x {h:.2f} mm at "
                     f"{PLOTTER_UNIT_MM} mm per unit)")
    lines.append("  commands: " + ", ".join(f"{k} {n}" for k, n in rep["command_counts"].items()))
    return lines + [f"warning: {w}" for w in rep["warnings"]]


def _exact_geometry(prepared: Any, cut_depth_mm: Optional[float], options: Any) -> tuple[dict, dict]:
    """An HPGL file's pen-down points and which of its chords are arcs (not a file of more than
    :data:`cam.kinds.gcode_export.MAX_SAMPLES` points: written at its steps)."""
    from ..formats.hpgl import load_hpgl
    from .gcode_export import MAX_SAMPLES, arc_positions, hpgl_exact_xy_mm, own_offset

    if options is None or int((getattr(prepared, "report", None) or {}).get("points", 0)) > MAX_SAMPLES:
        return {}, {}
    return hpgl_exact_xy_mm(load_hpgl(prepared.source), prepared.settings, scale=options.scale,
                            fit_mm=options.fit_mm, offset_mm=own_offset(options),
                            arc_positions=arc_positions(prepared.source)), {}


KIND = Kind(
    name="hpgl", noun="an HPGL file", title="HPGL", suffixes=(".plt", ".hpgl", ".hpg"),
    traits=frozenset({"placed", "strokes"}), prepare=_prepare, sniff=_sniff, sniff_rank=50, info=_info,
    info_lines=_info_lines, exact_geometry=_exact_geometry, job_noun="HPGL job",
    help="is cut pen-down at --cut-depth",
)
