"""``cam home``: find the home switches and set the machine's zero (issue #29 point 5; :mod:`cam.drive.homing`).

Homing needs home switches wired in the machine file's ``[inputs]`` and runs on a step/dir port: a parallel
port, or the mock with simulated switches (the machine file's ``[mock]`` places).  It may start while the
position is unknown (that is what it is for); the state file then says where the tool stands (the homed axes
at their ``[homing] offset_A_mm``, machine frame), known and homed.  A homing that could not finish leaves the
position unknown.  It runs through the machine session (:meth:`cam.drive.session.MachineSession.home`), as the
page's Home does (issue #45 point 3); on grbl that is grbl's own ``$H``.
"""
from __future__ import annotations

import argparse
import sys

from ..drive.homing import check_homing
from ..drive.machines import backend_of
from ..drive.state import steps_to_mm
from ..errors import CamError
from .common import port_settings
from .machine_state import hold_machine, run_activity
from .parser import EXIT_INTERRUPTED

__all__ = ["cmd_home"]


def cmd_home(args: argparse.Namespace) -> int:
    """``cam home``: the session's :meth:`~cam.drive.session.MachineSession.home` (the page's Home runs the same),
    each phase said on stderr, the end in one line."""
    settings = port_settings(args, args.port)
    backend = backend_of(args.port)
    own_cycle = backend.can("homes_itself", args.port)
    if own_cycle and args.axes:
        raise CamError(f"{args.port} homes all its axes with its own cycle ($H, its own [homing] order, $23-$27); "
                       f"drop --axes {args.axes}")
    if not own_cycle:
        backend.home_refusal(args.port)  # a machine that cannot home: what it can do instead, in one line
    order = "" if own_cycle else check_homing(settings, args.axes)  # before anything opens: one line
    with hold_machine(args, settings, "cam home") as hold:
        if own_cycle:
            print("homing with the board's own cycle ($H) ...", file=sys.stderr, flush=True)
        session, _ = run_activity(args, settings, hold, lambda s: s.home(order or None))
        status = session.last_run.get("status")
        if status != "finished":
            print(f"homing did not finish: {'; '.join(session.last_run.get('messages') or ['stopped'])}; the "
                  f"machine is not homed, its position unknown", file=sys.stderr)
            return 2 if own_cycle and status != "emergency-stopped" else EXIT_INTERRUPTED
        state = hold.state
    if not state.position_known:  # a new machine homed on some axes only: the others have no coordinate at all
        left = "".join(a for a in "XYZ" if a.lower() not in order)
        print(f"homed {order.upper()}; {left} not homed on a new machine: the position stays unknown "
              f"(home every axis with cam home, or cam where --set X,Y,Z)", file=sys.stderr)
        return 0
    pos = state.position_steps
    x, y, z = steps_to_mm(pos, settings)
    print(f"homed{' ' + order.upper() if order else ''}: the machine stands at X={x:g} Y={y:g} Z={z:g} mm "
          f"({' '.join(f'{a}={v}' for a, v in zip('XYZ', pos))} steps), position known")
    return 0
