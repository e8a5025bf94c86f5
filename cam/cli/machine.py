"""Commands that move the machine without a job file: goto and jog."""
from __future__ import annotations

import argparse
import sys

from ..errors import CamError
from ..job.moves import goto, jog
from .common import machine_settings, port_settings
from .execute import check_port_options, execute
from .parser import EXIT_INTERRUPTED

__all__ = ["cmd_goto", "cmd_jog"]


def cmd_goto(args: argparse.Namespace) -> int:
    settings = machine_settings(args)
    check_port_options(args)
    outcome = execute(goto(tuple(args.position), settings=settings), args, settings)
    if not outcome.finished:
        for m in outcome.messages:
            print(m, file=sys.stderr)
        return EXIT_INTERRUPTED
    x, y, z = outcome.position_steps
    print(f"at X={x} Y={y} Z={z} steps")
    return 0


def cmd_jog(args: argparse.Namespace) -> int:
    axis = args.axis.upper()
    if len(axis) != 2 or axis[0] not in "XYZ" or axis[1] not in "+-":
        raise CamError(f"axis must be X+, X-, Y+, Y-, Z+ or Z-, got '{args.axis}'")
    if args.steps <= 0:
        raise CamError(f"steps must be > 0, got {args.steps}")
    check_port_options(args)
    n = args.steps if axis[1] == "+" else -args.steps
    settings = port_settings(args, args.port)
    bounds = settings.travel.bounds_steps()
    lo, hi = bounds["XYZ".index(axis[0])]
    if abs(n) > hi - lo:
        raise CamError(f"a jog of {n} steps is longer than the {axis[0]} travel ({hi - lo} steps)")
    # the command line does not know where the tool stands: a jog fits when it fits from one end of the travel
    start = [b_lo for b_lo, _ in bounds]
    if n < 0:
        start["XYZ".index(axis[0])] = hi
    outcome = execute(jog(axis[0], n, settings=settings), args, settings, start_steps=tuple(start))
    if not outcome.finished:
        for m in outcome.messages:
            print(m, file=sys.stderr)
        moved = [int(p) - int(s) for p, s in zip(outcome.position_steps, start)]
        print(f"jog stopped: moved X={moved[0]} Y={moved[1]} Z={moved[2]} steps", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"jogged {axis[0]} by {n} steps")
    return 0
