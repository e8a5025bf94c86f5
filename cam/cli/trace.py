"""``cam trace``: a scanned sketch or a photo of a drawing, to a drawing (a thin adapter over :func:`cam.trace`)."""
from __future__ import annotations

import argparse
import sys

from ..digitize.sketch import load_sketch, trace
from ..render.picture import save_picture

__all__ = ["cmd_trace"]


def cmd_trace(args: argparse.Namespace) -> int:
    drawing = trace(load_sketch(args.image), trace_min_length_px=args.trace_min_length, trace_fill=args.trace_fill,
                    max_side_px=args.max_side, source=args.image)
    for w in drawing.warnings:
        print(f"warning: {w}", file=sys.stderr)
    save_picture(drawing.to_rgb(), args.output)
    kind = "3D" if drawing.regions_filled else "2D"
    print(f"{args.output}: {drawing.width_px}x{drawing.height_px} px {kind} drawing: {drawing.summary()}")
    return 0
