"""Commands that read or write files and move nothing: export, preview, info, digitize, profile."""
from __future__ import annotations

import argparse
import json
import re
import sys
from typing import Optional

import numpy as np

from ..choices import is_height_map
from ..sniff import KIND_NAMES
from ..digitize import digitize
from ..digitize.digitized import save_digitized
from ..digitize.drawing import load_image
from ..digitize.profile import load_profile
from ..drive.machines import DEFAULT_PORT, can
from ..errors import CamError, TravelError
from ..formats.excellon import HoleList, load_excellon
from ..formats.gcode import load_tool_table, open_gcode
from ..kinds.gcode_export import exact_geometry, save_gcode
from ..job.gcode import program_extent_mm, work_zero_range_mm
from ..job.drill import DEFAULT_CUT_DEPTH_MM
from ..job.heightmap_level import load_height_map
from ..formats.hpgl import PLOTTER_UNIT_MM, scan_hpgl
from ..job.model import pause_points
from ..render.report import format_report, image_report
from .common import format_duration, machine_settings, port_settings, reading_bar, speeds_line
from .checks import job_kind_of
from .height_map import info_height_map, preview_height_map
from .planning import excellon_digits, job_options, prepare, profile_of, write_job_preview

__all__ = ["cmd_export", "cmd_preview", "cmd_info", "cmd_digitize", "cmd_profile"]


def cmd_export(args: argparse.Namespace) -> int:
    if args.image and job_kind_of(args) == "gcode":
        raise CamError(f"{args.image} is G-code already; run it with 'cam drill', or preview it")
    travel_height_mm = 1.0 if args.travel_height is None else args.travel_height
    if not travel_height_mm > 0:
        raise CamError(f"--travel-height must be > 0 mm for G-code out, got {args.travel_height}")
    job = prepare(args)
    at = pause_points(job.toolpath) + 1  # a tool change comes before the point after its pause
    if job.drill_plan is not None:
        changes = {int(i): (tool, f"T{tool} {dia:.3f} mm, {n} holes")
                   for i, (tool, dia, n) in zip(at, job.drill_plan.tool_sequence)}
    else:  # HPGL: "tool change: pen N"; other pauses (Pause At, between SVG layers) are M0 with their note
        notes = job.toolpath.pause_notes or ["Pause At"] * len(at)
        changes = {int(i): (_tool_number(note), note) for i, note in zip(at, notes)}
    exact_xy, exact_z = exact_geometry(job, DEFAULT_CUT_DEPTH_MM if args.cut_depth is None else args.cut_depth,
                                       job_options(args))
    level = None
    if job.levelled_home_steps is not None:  # levelled (--level): its depths are the surface's, not one asked
        exact_z = {}  # and its travels are written levelled too (the map read again when the job is held whole)
        level = (getattr(job.toolpath, "height_map", None) or load_height_map(args.level), job.levelled_home_steps)
    save_gcode(job.toolpath, args.output, flip_y=args.flip_y, travel_height_mm=travel_height_mm,
               title=f"cam: {args.image or args.load_digitized}", tool_changes=changes,
               post=getattr(args, "post", "generic"), feed_mm_min=getattr(args, "feed", None),
               plunge_feed_mm_min=getattr(args, "plunge_feed", None), spindle_rpm=getattr(args, "spindle_rpm", None),
               exact_xy_mm=exact_xy, exact_z_mm=exact_z, snap=getattr(args, "snap", False),
               arc_tolerance_mm=getattr(args, "arc_tolerance", None) or None, level=level)  # issue #30 point 4
    if job.kind in ("drawing", "digitized"):
        print(f"{args.output}: {job.toolpath.n_targets} points, {job.toolpath.n_retracts} retracts"
              + (f", {len(changes)} pause(s)" if changes else ""))
    else:
        tools = sum(n is not None for n, _ in changes.values())
        pauses = len(changes) - tools
        print(f"{args.output}: {job.summary}, {tools} tool change(s)" + (f", {pauses} pause(s)" if pauses else ""))
    return 0


def _tool_number(note: str) -> Optional[int]:
    """The tool a pause's note changes to (``tool change: pen 2``, ``tool change: T3 ...``), or None: a pause.

    >>> _tool_number("tool change: pen 2"), _tool_number("tool change: T3 = T4 1.000 mm"), _tool_number("Pause At")
    (2, 3, None)
    """
    found = re.match(r"tool change: (?:pen (\d+)$|T(\d+)\b)", note)
    return None if found is None else int(found.group(1) or found.group(2))


def cmd_preview(args: argparse.Namespace) -> int:
    if args.image and is_height_map(args.image):  # a height map: its picture, a job over it (--over)
        return preview_height_map(args)
    if getattr(args, "over", None) is not None:
        raise CamError(f"--over draws a job over a height map (cam preview MAP.json --over FILE); {args.image} is "
                       "not one")
    job = prepare(args)
    write_job_preview(args, job, args.output, surface=args.surface)
    print(f"{args.output}: {'cut surface' if args.surface else 'toolpath'} picture")
    if job.probing is not None:
        print("\n".join(_probe_lines(job)))
    return 0


def _probe_lines(job) -> list[str]:
    """What ``cam info`` and ``cam preview`` say of a program that probes (G38.2/G38.3): each probe, and that the
    moves after it depend on the contact."""
    return [f"  probe {p}" for p in job.probing.probes] + [
        "  the moves after a probe depend on where it touches: shown and planned here as if each touched at its "
        "target (its deepest); a machine that probes plans them from the contact as it runs (the MAXIMUS board and "
        "cmd: have no probe)"]


def cmd_profile(args: argparse.Namespace) -> int:
    settings = machine_settings(args)
    prof = load_profile(args.profile)
    for w in prof.warnings:
        print(f"warning: {w}", file=sys.stderr)
    lo, hi = int(prof.depth_px.min()), int(prof.depth_px.max())
    print(f"{args.profile}: {prof.n_layers} layers, depth {lo}..{hi} Z px = "
          f"{settings.px_to_mm_z(lo):.3f}..{settings.px_to_mm_z(hi):.3f} mm")
    return 0


def cmd_digitize(args: argparse.Namespace) -> int:
    d = digitize(load_image(args.image), start=args.start)
    for w in d.warnings:
        print(f"warning: {w}", file=sys.stderr)
    save_digitized(d, args.output)
    print(f"{args.output}: {len(d.objects)} object(s), {d.n_points} points")
    return 0


def _load_drill_file(args: argparse.Namespace) -> HoleList:
    return load_excellon(args.image, excellon_units=args.excellon_units, excellon_digits=excellon_digits(args),
                         excellon_zeros=args.excellon_zeros, strict=bool(getattr(args, "strict", False)))


def _info_excellon(args: argparse.Namespace) -> int:
    holes = _load_drill_file(args)
    x0, y0, x1, y1 = holes.extent_mm()
    if args.json:
        print(json.dumps({
            "source": args.image, "kind": "excellon", "holes": len(holes.holes_mm),
            "extent_mm": [x0, y0, x1, y1], "size_mm": [round(x1 - x0, 4), round(y1 - y0, 4)],
            "tools": [{"tool": int(tool), "diameter_mm": float(dia), "holes": int(count)}
                      for tool, dia, count in holes.tool_table()],
            "warnings": list(holes.warnings),
        }, indent=2))
        return 0
    lines = [f"{args.image}: {len(holes.holes_mm)} holes, board extent X {x0:.3f}..{x1:.3f} mm, "
             f"Y {y0:.3f}..{y1:.3f} mm ({x1 - x0:.2f} x {y1 - y0:.2f} mm)"]
    for tool, dia, count in holes.tool_table():
        slots = holes.slot_count(tool)
        lines.append(f"  T{tool}: {dia:.3f} mm, {count} holes" + (f", {slots} slots" if slots else ""))
    lines += [f"warning: {w}" for w in holes.warnings]
    print("\n".join(lines))
    return 0


def _info_hpgl(args: argparse.Namespace) -> int:
    args.no_progress = getattr(args, "no_progress", True)
    with reading_bar(args) as progress:
        scan = scan_hpgl(args.image, progress=progress)
    if args.json:
        print(json.dumps({"source": args.image, "kind": "hpgl", **scan.__dict__, "size_mm": scan.size_mm()}, indent=2))
        return 0
    lines = [f"{args.image}: {scan.n_strokes} pen-down strokes, {scan.n_points} points, pens "
             f"{', '.join(map(str, scan.pens)) or 'none selected'}"]
    if scan.extent_pu is not None:
        x0, y0, x1, y1 = scan.extent_pu
        w, h = scan.size_mm()
        lines.append(f"  extent X {x0:g}..{x1:g}, Y {y0:g}..{y1:g} plotter units ({w:.2f} x {h:.2f} mm at "
                     f"{PLOTTER_UNIT_MM} mm per unit)")
    lines.append("  commands: " + ", ".join(f"{k} {n}" for k, n in scan.command_counts.items()))
    lines += [f"warning: {w}" for w in scan.warnings]
    print("\n".join(lines))
    return 0


def _gcode_extent(args: argparse.Namespace) -> Optional[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """The program's extent in its own frame (run from its work zero, offsets 0: G-code mm, +Y up, +Z up) and the
    work zeros that keep it in the travel (machine frame: +Y toward the operator, +Z deeper), each ``(lo, hi)``;
    None when it makes no moves.  Nothing is planned: a program that does not fit where it would run now still
    has them."""
    settings, options = machine_settings(args), job_options(args)
    s = settings
    program = open_gcode(
        args.image, home_g28_mm=(s.g28_x_mm, s.g28_y_mm, s.g28_z_mm), home_g30_mm=(s.g30_x_mm, s.g30_y_mm, s.g30_z_mm),
        tool_lengths_mm=load_tool_table(options.tool_table) if options.tool_table else None,
        subroutine_path=options.subroutine_path, max_lines=options.max_lines)
    extent = program_extent_mm(program)
    if extent is None:
        return None
    return (*extent, *work_zero_range_mm(extent, settings, flip_y=options.flip_y))


def _info_gcode(args: argparse.Namespace) -> int:
    """``cam info`` of a G-code program: its report as planned where it would run now (the machine state), its
    extent in its own frame and where its work zero may stand; a program that leaves the travel from the work
    zero it would run from now is not refused (its size is what a user needs to choose a zero)."""
    travel_error: Optional[str] = None
    job = None
    try:
        job = prepare(args)
    except TravelError as exc:
        travel_error = str(exc)
    extent = _gcode_extent(args)
    if args.json:
        rep = job.full_report() if job is not None else {"source": args.image, "kind": "gcode"}
        if extent is not None:
            rep["extent_program_mm"] = [[round(float(v), 4) for v in extent[0]], [round(float(v), 4) for v in extent[1]]]
            rep["work_zero_fits_machine_mm"] = [[round(float(v), 4) for v in extent[2]],
                                                [round(float(v), 4) for v in extent[3]]]
        if travel_error is not None:
            rep["travel_error"] = travel_error
        print(json.dumps(rep, indent=2))
        return 0
    if job is not None:
        w, h = job.size_mm
        lines = [f"{args.image}: {job.report.get('moves', 0)} moves, cut area {w:.2f} x {h:.2f} mm, depth "
                 f"{job.depth_mm:.3f} mm, machine time {format_duration(job.estimated_time_s)}"]
    else:
        lines = [f"{args.image}: G-code program, not planned where it would run now: {travel_error}"]
    if extent is not None:
        lo, hi, zero_lo, zero_hi = extent
        size = hi - lo
        lines.append(f"  extent in the program's own frame (G-code mm from its zero, +Y up, +Z up): "
                     f"X {lo[0]:.3f}..{hi[0]:.3f}, Y {lo[1]:.3f}..{hi[1]:.3f}, Z {lo[2]:.3f}..{hi[2]:.3f} mm "
                     f"({size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} mm)")
        too_large = [f"{'XYZ'[a]}" for a in range(3) if zero_lo[a] > zero_hi[a]]
        if too_large:
            lines.append(f"  it does not fit the machine travel on {', '.join(too_large)} wherever its zero is")
        else:
            lines.append(f"  fits the machine travel with its work zero at machine X {zero_lo[0]:.3f}..{zero_hi[0]:.3f}, "
                         f"Y {zero_lo[1]:.3f}..{zero_hi[1]:.3f}, Z {zero_lo[2]:.3f}..{zero_hi[2]:.3f} mm (the machine "
                         "frame of cam where, cam zero --at and cam goto: from the home, +Y toward the operator, "
                         "+Z deeper)")
    if job is not None:
        lines += _probe_lines(job) if job.probing is not None else []
        lines += [f"  {note}" for note in job.tool_changes]
        lines += [f"warning: {w}" for w in job.warnings]
    print("\n".join(lines))
    return 0


def _info_svg(args: argparse.Namespace) -> int:
    job = prepare(args)  # at the defaults: its own size, 0.5 mm deep
    rep = job.full_report()
    w, h = job.size_mm
    if args.json:
        print(json.dumps(rep, indent=2))
        return 0
    elements = ", ".join(f"{n} {name}" for name, n in sorted(rep["elements"].items())) or "none"
    segments = ", ".join(f"{n} {name}" for name, n in rep["segments"].items())
    dw, dh = rep["document_mm"]
    dxf = rep.get("dxf")  # a DXF file: read into the same drawing (cam.formats.dxf)
    lines = [f"{args.image}: {rep['strokes']} strokes from {elements}",
             f"  segments: {segments} (arcs as cubic Béziers)",
             (f"  DXF {dxf['version']}, units {dxf['units']} (from {dxf['units_from']}); drawing {dw:.2f} x {dh:.2f} mm"
              if dxf else f"  page {dw:.2f} x {dh:.2f} mm") + f"; cut area {w:.2f} x {h:.2f} mm at scale 1, machine time "
             f"{format_duration(job.estimated_time_s)} at 0.5 mm deep"]
    layers = rep.get("layers", [])  # issue #31 point 6: what --layers can name
    named = {"inkscape": "Inkscape layers", "dxf": "DXF layers"}.get(rep.get("layers_from"), "by stroke colour")
    lines.append(f"  {len(layers)} layer(s), {named}, in file order:")
    lines += [f"    '{layer['name']}': {layer['strokes']} strokes, {layer['length_mm']:.1f} mm" for layer in layers]
    lines += [f"warning: {w}" for w in job.warnings]
    print("\n".join(lines))
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    if is_height_map(args.image):  # not a job: what was probed, where
        return info_height_map(args)
    port = getattr(args, "port", None) or DEFAULT_PORT
    # a delay the ramps would not honour: refused before anything is read; a MAXIMUS board: its own settings
    settings = port_settings(args, port) if can(port, "board_settings") else machine_settings(args)
    code = _info_of_kind(args, job_kind_of(args))
    if not args.json:
        print(speeds_line(settings, port))
    return code


def _info_of_kind(args: argparse.Namespace, kind: str) -> int:
    if kind in ("svg", "dxf"):
        return _info_svg(args)
    if kind == "hpgl":
        return _info_hpgl(args)
    if kind == "excellon":
        return _info_excellon(args)
    if kind == "gcode":
        return _info_gcode(args)
    if kind != "drawing":
        raise CamError(f"{args.image}: info reads drawings, drill, HPGL, SVG, DXF and G-code files, not {KIND_NAMES[kind]}")
    settings = machine_settings(args)
    d = digitize(load_image(args.image), start=args.start)
    rep = image_report(d, settings)
    prof = profile_of(args, d)
    uniform_px = getattr(args, "depth", None)
    if d.mode == "3d" and (prof is not None or uniform_px):
        depth_px = int(prof.depth_of(d.levels).max()) if prof is not None else int(max(uniform_px))
        rep["depth_px"] = depth_px
        rep["depth_mm"] = round(settings.px_to_mm_z(depth_px), 4)
    print(json.dumps(rep, indent=2) if args.json else format_report(rep))
    return 0
