"""Commands that move the machine without a job file: goto and jog."""
from __future__ import annotations

import argparse
import sys

import numpy as np

from ..drive.maximus.board import MaximusBoard
from ..drive.runner import FINISHED
from ..errors import CamError
from ..job.toolpath import TRAVEL, Toolpath, goto
from ..settings import Travel
from .common import machine_settings, port_settings
from .execute import execute
from .parser import EXIT_INTERRUPTED

__all__ = ["cmd_goto", "cmd_jog"]


def cmd_goto(args: argparse.Namespace) -> int:
    settings = machine_settings(args)
    job = goto(tuple(args.position), settings=settings)
    result = execute(job, args)
    if result.status != FINISHED:
        for m in result.messages:
            print(m, file=sys.stderr)
        return EXIT_INTERRUPTED
    x, y, z = result.position_steps
    print(f"at X={x} Y={y} Z={z} steps")
    return 0


def cmd_jog(args: argparse.Namespace) -> int:
    axis = args.axis.upper()
    if len(axis) != 2 or axis[0] not in "XYZ" or axis[1] not in "+-":
        raise CamError(f"axis must be X+, X-, Y+, Y-, Z+ or Z-, got '{args.axis}'")
    if args.steps <= 0:
        raise CamError(f"steps must be > 0, got {args.steps}")
    n = args.steps if axis[1] == "+" else -args.steps
    if args.port.startswith("maximus:"):
        with MaximusBoard(args.port) as board:
            board.jog(axis[0].lower(), n, half_step=port_settings(args, args.port).half_step)
        print(f"jogged {axis[0]} by {n} steps")
        return 0
    settings = machine_settings(args)
    lo, hi = settings.travel.bounds_steps()["XYZ".index(axis[0])]
    if abs(n) > hi - lo:
        raise CamError(f"a jog of {n} steps is longer than the {axis[0]} travel ({hi - lo} steps)")
    span = hi - lo
    unit = settings.replace(steps_per_px_xy=1, steps_per_px_z=1,
                            travel=Travel(-span, span, -span, span, -span, span))  # from wherever it stands
    point = [0, 0, 0]
    point["XYZ".index(axis[0])] = n
    job = Toolpath(points_px=np.array([point]), kind=np.array([TRAVEL], np.uint8), target=np.zeros(1, bool),
                   pause=np.zeros(1, bool), settings=unit)
    result = execute(job, args)
    if result.status != FINISHED:
        return EXIT_INTERRUPTED
    print(f"jogged {axis[0]} by {n} steps")
    return 0
