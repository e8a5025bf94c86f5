"""``cam info MAP.json`` and ``cam preview MAP.json [--over FILE] -o PIC.png``: a height map shown (issue #46 point 1).

Thin adapters: :func:`cam.job.heightmap_level.map_summary` says what the map holds,
:func:`cam.job.map_picture.height_map_picture` draws it, and :func:`cam.drive.probing.job_cuts_mm` places a job
over it where ``cam drill`` would run it (the state file's active work zero, ``--origin`` as drill's), as ``cam probe
grid --over`` finds the job's area.  A map is recognised by its content (:func:`cam.choices.is_height_map`).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..drive.probing import job_cuts_mm, job_area_mm
from ..drive.state import new_machine_state
from ..errors import CamError
from ..job.heightmap_level import load_height_map, map_summary, outside_text
from ..job.map_picture import height_map_picture
from ..render.picture import save_picture
from .checks import check_output_path
from .common import machine_settings
from .planning import _state_to_view, prepare

__all__ = ["info_height_map", "preview_height_map"]


def info_height_map(args: argparse.Namespace) -> int:
    """``cam info MAP.json [--json]``."""
    summary = {"source": args.image, **map_summary(load_height_map(args.image))}
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    s = summary
    (x0, y0, x1, y1), (w, h), hm = s["area_mm"], s["size_mm"], s["height_mm"]
    (ax, ay), (bx, by) = s["between_mm"]
    cell = s["cell_mm"]
    finest = "" if min(cell) >= s["spacing_mm"] - 1e-9 else f" (cells from {min(cell):g} mm)"
    print("\n".join([
        f"{args.image}: height map, {s['grid'][0]} x {s['grid'][1]} points ({s['points']}) probed every "
        f"{s['spacing_mm']:g} mm{finest}",
        f"  area: machine X {x0:.3f}..{x1:.3f}, Y {y0:.3f}..{y1:.3f} mm ({w:.2f} x {h:.2f} mm; the machine frame: "
        "from the home, +Y toward the operator)",
        f"  heights (up positive): min {hm['min']:.4f}, max {hm['max']:.4f}, mean {hm['mean']:.4f} mm (range "
        f"{s['range_mm']:.4f} mm)",
        f"  largest neighbour difference: {s['max_neighbour_diff_mm']:.4f} mm, between X {ax:g}, Y {ay:g} and X {bx:g}, "
        f"Y {by:g} mm",
        f"  reference (the work Z zero's surface): {s['reference_mm']:.4f} mm",
        f"  machine file: {s['machine'] or '(the built-in settings)'}",
        f"  probed: {s['time'] or '(not recorded)'}",
    ]))
    return 0


def preview_height_map(args: argparse.Namespace) -> int:
    """``cam preview MAP.json [--over FILE] -o PIC.png``."""
    if Path(args.output).suffix.lower() != ".png":
        raise CamError(f"{args.output}: a height map's picture is written as .png")
    check_output_path(args.output, "-o")
    height_map = load_height_map(args.image)
    cuts = None
    note = ""
    if args.over is not None:
        if not Path(args.over).is_file():
            raise CamError(f"--over {args.over}: no such file")
        settings = machine_settings(args)
        over = argparse.Namespace(**{**vars(args), "image": args.over, "level": None})
        job = prepare(over, settings)
        state = _state_to_view(args, settings) or new_machine_state()
        cuts = job_cuts_mm(job, state, settings, getattr(args, "origin", None))
        x0, y0, x1, y1 = job_area_mm(job, state, settings, getattr(args, "origin", None))
        outside = outside_text(height_map, [x0, x1], [y0, y1], name_point=False)
        note = f"; {args.over} over it" + (f" ({outside.replace('the job reaches', 'it reaches')})" if outside else "")
    save_picture(height_map_picture(height_map, cuts_mm=cuts), args.output)
    print(f"{args.output}: height map picture{note}")
    return 0
