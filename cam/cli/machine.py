"""Commands that move the machine without a job file: goto and jog.

Both start where the machine state file (:mod:`cam.drive.state`) says the tool stands, are checked against
the travel in the machine frame before anything moves, and record where the tool ended.
"""
from __future__ import annotations

import argparse
import sys

from ..drive.machines import backend_of
from ..drive.state import PositionUnknownError, StateHold, check_in_travel, soft_limits_off, steps_to_mm
from ..drive.session import UNKNOWN_JOG_LINE
from ..errors import CamError
from ..job.moves import jog, jog_steps
from ..settings import MachineSettings
from .common import port_settings
from .execute import check_port_options, execute
from .machine_state import hold_machine
from ..drive.placement import goto_path
from .parser import EXIT_INTERRUPTED

__all__ = ["cmd_goto", "cmd_jog", "target_steps"]

Steps3 = tuple[int, int, int]


def target_steps(values: list[float], unit: str, settings: MachineSettings) -> Steps3:
    """X,Y,Z in ``unit`` (``px``: drawing pixels, ``mm``, ``steps``) as steps, in the frame they were given in.

    Raises:
        CamError: a pixel or step count that is not whole.
    """
    if unit in ("px", "steps"):
        if any(float(v) != int(v) for v in values):
            raise CamError(f"X,Y,Z in {unit} must be whole numbers, got {','.join(f'{v:g}' for v in values)}")
        per = (settings.steps_per_px_xy, settings.steps_per_px_xy, settings.steps_per_px_z) if unit == "px" \
            else (1, 1, 1)
        return tuple(int(v) * p for v, p in zip(values, per))  # type: ignore[return-value]
    per_mm = settings.mm_per_step_axes
    return tuple(int(round(float(v) / p)) for v, p in zip(values, per_mm))  # type: ignore[return-value]


def _where_line(machine: Steps3, work: Steps3, offset: str, settings: MachineSettings) -> str:
    mx, my, mz = steps_to_mm(machine, settings)
    return (f"at X={work[0]} Y={work[1]} Z={work[2]} steps in {offset} (machine X={machine[0]} Y={machine[1]} "
            f"Z={machine[2]} steps = {mx:g}, {my:g}, {mz:g} mm)")


def cmd_goto(args: argparse.Namespace) -> int:
    check_port_options(args)
    settings = port_settings(args, args.port)
    rel = target_steps(args.position, args.unit, settings)
    with hold_machine(args, settings, "cam goto") as hold:
        hold.require_known()
        state = hold.state
        zero = (0, 0, 0) if args.machine_coords else state.work_zero_steps()
        frame = "machine" if args.machine_coords else state.active_offset
        target = tuple(int(z) + int(r) for z, r in zip(zero, rel))
        check_in_travel(target, settings, f"X,Y,Z {','.join(f'{v:g}' for v in args.position)} {args.unit} "
                        f"in {frame} (machine {list(target)} steps)")
        job = goto_path(state.position_steps, target, zero[2], settings)  # type: ignore[arg-type]
        if job is None:
            print(_where_line(state.position_steps, state.to_work(state.position_steps), state.active_offset,
                              settings) + ": there already")
            return 0
        outcome = execute(job, args, settings, hold=hold)
        state = hold.state
    if not outcome.finished:
        for m in outcome.messages:
            print(m, file=sys.stderr)
        return EXIT_INTERRUPTED
    print(_where_line(state.position_steps, state.to_work(state.position_steps), state.active_offset, settings))
    return 0


def _jog_steps(args: argparse.Namespace, settings: MachineSettings) -> tuple[str, int]:
    axis = args.axis.upper()
    if len(axis) != 2 or axis[0] not in "XYZ" or axis[1] not in "+-":
        raise CamError(f"axis must be X+, X-, Y+, Y-, Z+ or Z-, got '{args.axis}'")
    if args.steps <= 0:
        raise CamError(f"steps must be > 0, got {args.steps:g}")
    half = backend_of(args.port).half_step(settings, axis[0].lower())
    n = jog_steps(axis[0], args.steps, args.unit, settings=settings, half_step=half)
    if n == 0:
        raise CamError(f"a jog of {args.steps:g} {args.unit} is less than one step")
    return axis[0], n if axis[1] == "+" else -n


def _unknown(hold: StateHold, args: argparse.Namespace) -> bool:
    """Whether the position is unknown (a jog is allowed then, issue #45 point 3): keeps why in
    ``args.position_unknown`` for the run (:func:`cam.cli.execute.execute`).  A missing device is refused."""
    if hold.state.position_known:
        return False
    try:
        hold.require_known()  # a typo in --port (no such device) is what the user fixes first
    except PositionUnknownError:
        pass
    args.position_unknown = hold.state.unknown_reason or "not recorded"
    return True


def cmd_jog(args: argparse.Namespace) -> int:
    check_port_options(args)
    settings = port_settings(args, args.port)
    axis, n = _jog_steps(args, settings)
    with hold_machine(args, settings, "cam jog") as hold:
        start = hold.state.position_steps
        if _unknown(hold, args):  # as LinuxCNC jogs an unhomed machine: soft limits off, still unknown after
            free = soft_limits_off(settings)
            outcome = execute(jog(axis, n, settings=free), args, free, hold=hold)
        else:
            outcome = execute(jog(axis, n, settings=settings, position_steps=start), args, settings, hold=hold)
        state = hold.state
    if getattr(args, "position_unknown", None):  # once the jog ran (a port that did not open: its one line only)
        print(UNKNOWN_JOG_LINE, file=sys.stderr, flush=True)
    if not outcome.finished:
        for m in outcome.messages:
            print(m, file=sys.stderr)
        moved = [int(p) - int(s) for p, s in zip(state.position_steps, start)]
        print(f"jog stopped: moved X={moved[0]} Y={moved[1]} Z={moved[2]} steps", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"jogged {axis} by {n} steps; "
          + _where_line(state.position_steps, state.to_work(state.position_steps), state.active_offset, settings)
          + ("" if state.position_known else "; the position is still unknown (cam home, or cam where --set X,Y,Z)"))
    return 0
