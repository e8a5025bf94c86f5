"""SVG drawings (Inkscape, Illustrator, logo tools): every visible stroke and outline cut at the cut depth
(:mod:`cam.formats.svg`, :mod:`cam.job.svg`).  DXF files are read into the same drawing
(:mod:`cam.kinds.dxf`), so their planning, report and ``cam info`` are this module's."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable, Optional

from . import Head, Kind

__all__ = ["KIND", "prepare_drawing", "drawing_info", "drawing_info_lines", "drawing_exact_geometry"]


def _sniff(head: Head) -> bool:
    return head.text is not None and head.text.lstrip().startswith("<") and bool(
        re.search(r"<svg[\s>/]", head.text, re.I))


def _load(path: Any) -> Any:
    from ..formats.svg import load_svg

    return load_svg(path)


def prepare_drawing(load: Callable[[Any], Any], kind: Kind, path: Path, options: Any, settings: Any,
                    home: Any = None) -> Any:
    """The job of a vector drawing ``load(path)`` reads (an :class:`~cam.formats.svg.SvgDrawing`), cut by the SVG
    planner with ``kind``'s defaults."""
    from ..job.svg import plan_svg
    from .jobs import PreparedJob, engraving, plan_chunks

    drawing = load(path)
    depth_mm, engraved = engraving(options, settings, kind.default("cut_depth_mm"))
    travel_mm = kind.default("travel_height_mm") if options.travel_height_mm is None else options.travel_height_mm
    toolpath = plan_svg(drawing, settings=settings, cut_depth_mm=depth_mm, travel_height_mm=travel_mm,
                        scale=options.scale, fit_mm=options.fit_mm, offset_mm=options.offset_mm,
                        layers=options.layers, pause_between_layers=bool(options.pause_between_layers),
                        keep_duplicates=bool(options.keep_duplicates), home_steps=home)
    steps = plan_chunks(toolpath, start_steps=home, fingerprint=True)
    counts = ", ".join(f"{n} {name}" for name, n in sorted(drawing.element_counts.items()))
    layer_list = [{"name": name, "strokes": int((drawing.layer_of_stroke == i).sum()), "length_mm": round(length, 3)}
                  for i, (name, length) in enumerate(zip(drawing.layers(), drawing.layer_lengths_mm()))]
    return PreparedJob(
        source=str(path), kind=kind.name, plan=steps, settings=settings, toolpath=toolpath,
        warnings=list(drawing.warnings), summary=f"{path.name}: {drawing.n_strokes} strokes ({counts})",
        report={"strokes": drawing.n_strokes, "elements": dict(drawing.element_counts),
                "segments": drawing.segment_counts, "document_mm": [round(v, 3) for v in drawing.size_mm],
                "layers": layer_list, "layers_from": drawing.layers_from,
                **({"dxf": {"version": drawing.dxf_version, "units": drawing.units, "units_from": drawing.units_from,
                            "skipped": dict(drawing.skipped)}} if getattr(drawing, "dxf_version", None) else {}),
                **engraved},
    )


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    return prepare_drawing(_load, KIND, path, options, settings, home)


def drawing_info(path: Any, options: Any, settings: Any, *, prepare: Any, progress: Any = None) -> dict:
    """The report of a vector drawing planned at its defaults (its own size, 0.5 mm deep): strokes, elements,
    segments, page or drawing size, layers."""
    return prepare().full_report()


def drawing_info_lines(rep: dict, name: str) -> list[str]:
    """What ``cam info`` says of a vector drawing's report."""
    from ..values import format_duration

    w, h = rep["size_mm"]
    elements = ", ".join(f"{n} {e}" for e, n in sorted(rep["elements"].items())) or "none"
    segments = ", ".join(f"{n} {s}" for s, n in rep["segments"].items())
    dw, dh = rep["document_mm"]
    dxf = rep.get("dxf")  # a DXF file: read into the same drawing (cam.formats.dxf)
    lines = [f"{name}: {rep['strokes']} strokes from {elements}",
             f"  segments: {segments} (arcs as cubic Béziers)",
             (f"  DXF {dxf['version']}, units {dxf['units']} (from {dxf['units_from']}); drawing {dw:.2f} x {dh:.2f} mm"
              if dxf else f"  page {dw:.2f} x {dh:.2f} mm") + f"; cut area {w:.2f} x {h:.2f} mm at scale 1, machine time "
             f"{format_duration(rep['estimated_time_s'])} at 0.5 mm deep"]
    layers = rep.get("layers", [])  # issue #31 point 6: what --layers can name
    named = {"inkscape": "Inkscape layers", "dxf": "DXF layers"}.get(rep.get("layers_from"), "by stroke colour")
    lines.append(f"  {len(layers)} layer(s), {named}, in file order:")
    lines += [f"    '{layer['name']}': {layer['strokes']} strokes, {layer['length_mm']:.1f} mm" for layer in layers]
    return lines + [f"warning: {w}" for w in rep.get("warnings", [])]


def drawing_exact_geometry(load: Callable[[Any], Any], prepared: Any, options: Any) -> tuple[dict, dict]:
    """A vector drawing's strokes at their mm (:func:`cam.kinds.gcode_export.svg_exact_xy_mm`, with the job's
    options: scale, fit, offset, layers)."""
    from .gcode_export import own_offset, svg_exact_xy_mm

    if options is None:
        return {}, {}
    return svg_exact_xy_mm(load(prepared.source), prepared.settings, scale=options.scale, fit_mm=options.fit_mm,
                           offset_mm=own_offset(options), layers=options.layers), {}


def _exact_geometry(prepared: Any, cut_depth_mm: Optional[float], options: Any) -> tuple[dict, dict]:
    return drawing_exact_geometry(_load, prepared, options)


KIND = Kind(
    name="svg", noun="an SVG drawing", title="SVG", suffixes=(".svg",),
    traits=frozenset({"placed", "strokes", "layers"}), prepare=_prepare, sniff=_sniff, sniff_rank=30,
    info=drawing_info, info_lines=drawing_info_lines, exact_geometry=_exact_geometry, job_noun="SVG job",
    help="every visible stroke and outline is cut at --cut-depth",
)
