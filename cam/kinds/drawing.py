"""Drawings: black 1-pixel curves on white (2D), a black contour around red (3D), a scanned sketch or photo
(``--trace``), or a grey-level height map (``--heightmap``), digitized and cut by the thesis's rules
(:mod:`cam.digitize`, :mod:`cam.job.drawing_stream`, :mod:`cam.job.heightmap`).  Saved digitized matrices
(:mod:`cam.kinds.digitized`) are cut by :func:`prepare_pixels` too."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from ..choices import IMAGE_SUFFIXES
from ..errors import CamError
from ..options import MAX_DEPTH_PX
from . import Head, Kind

__all__ = ["KIND", "prepare_pixels", "pixels_picture"]

_IMAGE_MAGIC = (b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff", b"II*\x00", b"MM\x00*", b"GIF87a", b"GIF89a")
"""PNG, JPEG, TIFF (both byte orders) and GIF signatures."""


def _sniff(head: Head) -> bool:
    raw = head.raw
    return raw.startswith(_IMAGE_MAGIC) or (raw[:2] == b"BM" and len(raw) >= 26 and raw[6:10] == b"\0\0\0\0")


def _drawing_depth(options: Any) -> Any:
    """The drawing planner's ``depth`` in Z pixels (one for all or one per object), or None (``cut_depth_mm``,
    which the planner takes as it is and converts, or the default)."""
    if options.depth is None:
        return None
    return options.depth[0] if len(options.depth) == 1 else list(options.depth)


def _profile(options: Any, digitized: Any) -> Any:
    """The depth profile the options name (a file or an expression in k and n), or None."""
    from ..digitize.profile import load_profile, profile_from_expr

    if options.profile:
        return load_profile(options.profile)
    if options.profile_expr:
        return profile_from_expr(options.profile_expr, max(1, digitized.n_layers))
    return None


def prepare_pixels(path: Path, kind: str, options: Any, settings: Any) -> Any:
    """The job of a drawing (``kind`` "drawing": traced first with ``options.trace``) or a saved digitized matrix
    ("digitized"), planned by the thesis's rules at every size (a large one kept in pieces)."""
    from ..digitize import digitize
    from ..digitize.digitized import load_digitized
    from ..digitize.drawing import drawing_size_px, load_image
    from ..job.drawing import check_drawing_size
    from ..job.drawing_stream import STREAM_TARGETS, plan, stream_drawing
    from ..render.report import job_report
    from ..tool import parse_tool, tool_of_settings
    from .jobs import PreparedJob, line_depth_mm, plan_chunks

    drawing = None
    traced: list[str] = []
    if kind == "drawing" and options.trace:  # a sketch or a photo: its size is checked once traced (shrunk)
        from ..digitize.sketch import load_sketch, trace  # scipy and scikit-image: 0.6 s, for a traced sketch only

        drawing = trace(load_sketch(path), trace_min_length_px=options.trace_min_length_px,
                        trace_fill=options.trace_fill, source=str(path))
        check_drawing_size(drawing.width_px, drawing.height_px, settings, str(path))
        traced.append(f"{path.name}: traced: {drawing.summary()}")
        digitized = digitize(drawing, start=options.start)
    elif kind == "drawing":
        check_drawing_size(*drawing_size_px(path), settings, str(path))  # from the header: before decoding
        drawing = load_image(path)
        digitized = digitize(drawing, start=options.start)
    else:
        digitized = load_digitized(path)
        check_drawing_size(digitized.width_px, digitized.height_px, settings, str(path))
    profile = _profile(options, digitized)
    cutter = parse_tool(options.tool, "--tool") if options.tool else tool_of_settings(settings.tool)
    depth, cut_depth_mm = _drawing_depth(options), options.cut_depth_mm
    if options.line_width_mm is not None:
        if digitized.mode == "3d":
            raise CamError("--line-width sets the depth of a 2D drawing's engraved lines; this drawing is 3D")
        depth_px = line_depth_mm(cutter, options.line_width_mm) / settings.px_to_mm_z(1)
        if not depth_px <= MAX_DEPTH_PX:
            raise CamError(f"--line-width: a {options.line_width_mm:g} mm line of a {cutter.describe()} is "
                           f"{depth_px:.3g} Z pixels deep, more than {MAX_DEPTH_PX}")
        depth, cut_depth_mm = max(1, int(round(depth_px))), None
    kw: dict[str, Any] = dict(depth=depth, settings=settings, passes=options.passes, start_at=options.start_at,
                              pause_at=list(options.pause_at), profile=profile, tool=cutter,
                              stepdown_mm=options.stepdown_mm, stepover=options.stepover, rough_tool=options.rough_tool,
                              cut_depth_mm=cut_depth_mm)
    # one planner at every size: a large job is kept in pieces (bounded memory), a smaller one joined (the
    # same moves, held in memory)
    big = digitized.n_points * options.passes > STREAM_TARGETS
    toolpath = stream_drawing(digitized, **kw) if big else plan(digitized, **kw)
    steps = plan_chunks(toolpath, start_steps=None, fingerprint=True)  # its own frame: placed when it runs
    report = job_report(digitized, toolpath, steps)
    rgb = drawing.to_rgb() if drawing is not None else None  # made after the report: not held while it counts
    summary = (f"{path.name}: {report['objects']} object(s), {report['points']} points, "
               f"{report['retracts']} retracts")
    return PreparedJob(
        source=str(path), kind=kind, plan=steps, settings=settings, toolpath=toolpath,
        size_mm=(report["width_mm"], report["height_mm"]), depth_mm=report["depth_mm"],
        warnings=traced + list(report["warnings"]), summary=summary, report=report, drawing_rgb=rgb,
        digitized=digitized,
    )


def _prepare_heightmap(path: Path, options: Any, settings: Any) -> Any:
    """The job of an image cut as a height map (``options.heightmap``): each pixel's grey its depth
    (:mod:`cam.job.heightmap`)."""
    import numpy as np

    from ..job.heightmap import DEFAULT_MAX_DEPTH_MM, depth_steps_of, load_heightmap, plan_heightmap
    from ..tool import parse_tool, tool_of_settings
    from .jobs import PreparedJob, plan_chunks

    grey = load_heightmap(path)
    cutter = parse_tool(options.tool, "--tool") if options.tool else tool_of_settings(settings.tool)
    max_depth_mm = options.max_depth_mm if options.max_depth_mm is not None else DEFAULT_MAX_DEPTH_MM
    depth = depth_steps_of(grey, max_depth_mm, settings, invert=bool(options.invert))
    # the path at every X step (X and Z together) is faster on smooth slopes, the staircase at pixel centres on
    # jagged ones (a flat end mill's drop-cutter depth between centres): both are planned, the faster kept
    best = None
    for slopes in ((True, False) if not cutter.is_point else (False,)):
        candidate = plan_heightmap(depth, tool=cutter, settings=settings, pixel_size_mm=options.pixel_size_mm,
                                   stepover=options.stepover, heightmap_order=options.heightmap_order,
                                   stepdown_mm=options.stepdown_mm, slopes=slopes, source=path.name)
        steps = plan_chunks(candidate, start_steps=None, fingerprint=True)  # its own frame: placed when it runs
        if best is None or steps.estimated_time_s < best[1].estimated_time_s:
            best = (candidate, steps, slopes)
    job, steps, slopes = best  # type: ignore[misc]
    spp = job.pixels.steps_per_px_xy
    h, w = depth.shape
    levels = len(np.unique(np.rint(grey * 255)))
    summary = (f"{path.name}: height map {w}x{h} px of {spp * settings.mm_per_step_xy:.4g} mm, {levels} grey levels, "
               f"{max_depth_mm:g} mm deep, {cutter.describe()}, {len(job)} points")
    rgb = np.repeat(np.rint(grey * 255).astype(np.uint8)[:, :, None], 3, axis=2)
    report = {"heightmap": {"width_px": w, "height_px": h, "pixel_size_mm": spp * settings.mm_per_step_xy,
                            "max_depth_mm": max_depth_mm, "invert": bool(options.invert),
                            "order": options.heightmap_order, "grey_levels": levels,
                            "path": "every X step" if slopes else "pixel centres"},
              "points": len(job), "tool": cutter.describe()}
    return PreparedJob(source=str(path), kind="drawing", plan=steps, settings=settings, toolpath=job,
                       warnings=list(job.warnings), summary=summary, report=report, drawing_rgb=rgb)


def pixels_picture(job: Any) -> Any:
    """A drawing's (or digitized matrix's) preview: its toolpath over the drawing, in drawing pixels
    (:func:`cam.render.picture.toolpath_picture`); None for a job kept in pieces (the moves seen from above)."""
    from ..job.model import Job
    from ..render.picture import toolpath_picture

    if not isinstance(job.toolpath, Job):
        return None
    return toolpath_picture(job.toolpath, drawing_rgb=job.drawing_rgb, estimated_time_s=job.estimated_time_s)


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    if options.heightmap:  # a grey-level relief (issue #31 point 7; its options' rules: JobOptions.checked)
        return _prepare_heightmap(path, options, settings)
    return prepare_pixels(path, "drawing", options, settings)


def _info(path: Any, options: Any, settings: Any, *, prepare: Any = None, progress: Any = None) -> dict:
    """The drawing digitized (:func:`cam.render.report.image_report`: its objects, layers, size), and with a
    profile or a uniform depth of a 3D drawing, its depth."""
    from ..digitize import digitize
    from ..digitize.drawing import load_image
    from ..render.report import image_report

    d = digitize(load_image(path), start=options.start)
    rep = image_report(d, settings)
    prof = _profile(options, d)
    if d.mode == "3d" and (prof is not None or options.depth):
        depth_px = int(prof.depth_of(d.levels).max()) if prof is not None else int(max(options.depth))
        rep["depth_px"] = depth_px
        rep["depth_mm"] = round(settings.px_to_mm_z(depth_px), 4)
    return rep


def _info_lines(rep: dict, name: str) -> list[str]:
    from ..render.report import format_report

    return [format_report(rep)]


KIND = Kind(
    name="drawing", noun="an image", title="drawing", suffixes=IMAGE_SUFFIXES,
    traits=frozenset({"pixels"}), prepare=_prepare, sniff=_sniff, sniff_rank=10, info=_info, info_lines=_info_lines,
    picture=pixels_picture,
    job_noun="drawing job", default_origin="file", listed_as="a drawing",
    help="is digitized and cut by the thesis's rules (black curves: 2D; a black contour around red: 3D)",
)
