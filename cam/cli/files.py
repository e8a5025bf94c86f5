"""Commands that read or write files and move nothing: export, preview, info, digitize, profile."""
from __future__ import annotations

import argparse
import json
import re
import sys
from typing import Optional

from ..choices import is_height_map
from ..digitize import digitize
from ..digitize.digitized import save_digitized
from ..digitize.drawing import load_image
from ..digitize.profile import load_profile
from ..drive.machines import DEFAULT_PORT, can
from ..errors import CamError
from ..kinds import has, kind, kinds
from ..kinds.gcode import probe_lines
from ..kinds.gcode_export import exact_geometry, save_gcode
from ..job.heightmap_level import load_height_map
from ..job.model import pause_points
from .common import machine_settings, port_settings, reading_bar, speeds_line
from .checks import job_kind_of
from .height_map import info_height_map, preview_height_map
from .planning import job_options, prepare, write_job_preview

__all__ = ["cmd_export", "cmd_preview", "cmd_info", "cmd_digitize", "cmd_profile"]


def cmd_export(args: argparse.Namespace) -> int:
    refusal = kind(job_kind_of(args)).export_refusal if args.image else None
    if refusal is not None:
        raise CamError(f"{args.image} {refusal}")
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
    exact_xy, exact_z = exact_geometry(job, kind(job.kind).default("cut_depth_mm") if args.cut_depth is None else
                                       args.cut_depth, job_options(args))
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
    if has(job.kind, "pixels"):
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
        print("\n".join(probe_lines(job.probing.probes)))
    return 0


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


def cmd_info(args: argparse.Namespace) -> int:
    if is_height_map(args.image):  # not a job: what was probed, where
        return info_height_map(args)
    port = getattr(args, "port", None) or DEFAULT_PORT
    # a delay the ramps would not honour: refused before anything is read; a MAXIMUS board: its own settings
    machine = machine_settings(args)
    settings = port_settings(args, port) if can(port, "board_settings") else machine
    the_kind = kind(job_kind_of(args))
    if the_kind.info is None or the_kind.info_lines is None:
        readers = [k.listed_as for k in kinds() if k.info is not None]
        raise CamError(f"{args.image}: info reads {', '.join(readers[:-1])} and {readers[-1]}, not {the_kind.noun}")
    args.no_progress = getattr(args, "no_progress", True)
    with reading_bar(args) as progress:
        rep = the_kind.info(args.image, job_options(args), machine, prepare=lambda: prepare(args, machine),
                            progress=progress)
    print(json.dumps(rep, indent=2) if args.json else "\n".join(the_kind.info_lines(rep, args.image)))
    if not args.json:
        print(speeds_line(settings, port))
    return 0
