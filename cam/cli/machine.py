"""Commands that move the machine without a job file: goto and jog."""
from __future__ import annotations

import argparse
import sys

from ..errors import CamError
from ..job.moves import goto, jog, jog_steps
from .common import port_settings
from .execute import check_port_options, execute
from .parser import EXIT_INTERRUPTED
from ..drive.ports import port_kind

__all__ = ["cmd_goto", "cmd_jog"]


def cmd_goto(args: argparse.Namespace) -> int:
    check_port_options(args)
    settings = port_settings(args, args.port)
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
        raise CamError(f"steps must be > 0, got {args.steps:g}")
    check_port_options(args)
    settings = port_settings(args, args.port)
    half = getattr(settings.maximus, f"half_step_{axis[0].lower()}") if port_kind(args.port) == "maximus" \
        else settings.half_step
    n = jog_steps(axis[0], args.steps, args.unit, settings=settings, half_step=half)
    if n == 0:
        raise CamError(f"a jog of {args.steps:g} {args.unit} is less than one step")
    n = n if axis[1] == "+" else -n
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
