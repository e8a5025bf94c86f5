"""``cam home``: find the home switches and set the machine's zero (issue #29 point 5; :mod:`cam.drive.homing`).

Homing needs home switches wired in the machine file's ``[inputs]`` and runs on a step/dir port: a parallel
port, or the mock with simulated switches (the machine file's ``[mock]`` places).  It may start while the
position is unknown (that is what it is for); the state file then says where the tool stands (the homed axes
at their ``[homing] offset_A_mm``, machine frame), known and homed.  A homing that could not finish leaves the
position unknown.
"""
from __future__ import annotations

import argparse
import signal
import sys
from dataclasses import replace
from typing import Any

from ..drive.homing import HomingError, HomingPhase, check_homing, home
from ..drive.ports import MockPort, SwitchSchedule, open_port, port_kind, require
from ..drive.runner import Controller
from ..drive.state import steps_to_mm
from ..drive.session import MachineSession
from ..errors import CamError, CapabilityError
from ..settings import MachineSettings
from ..verify.pinlog import write_pin_log
from .common import port_settings
from .machine_state import hold_machine
from .parser import EXIT_INTERRUPTED

__all__ = ["cmd_home"]

_STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


def _port_of(args: argparse.Namespace, settings: MachineSettings, start: tuple[int, int, int]) -> Any:
    """The open port homing runs on: the mock with its simulated switches (refused without), or a real one."""
    kind = port_kind(args.port)
    if kind == "maximus":
        raise CapabilityError(f"{args.port} (the MAXIMUS board) has no home switches cam reads: cam home needs a "
                              f"step/dir port (/dev/parportN, or the mock with [mock] switch places)")
    if kind == "mock":
        if not settings.mock.places():
            raise CapabilityError("the mock port has no switches to find: give their places in the machine file's "
                                  "[mock] table (home_x_steps = 0, ...; see docs/machine-and-ports.md)")
        return MockPort(switches=SwitchSchedule(settings, start))
    require(args.port, "step_dir", what="homing")
    return open_port(args.port)


def _say(phase: HomingPhase) -> None:
    print(f"homing {phase.axis.upper()}: {phase.phase} {phase.moved_steps:+d} steps at {phase.speed_mm_s:g} mm/s",
          file=sys.stderr, flush=True)


def cmd_home(args: argparse.Namespace) -> int:
    settings = port_settings(args, args.port)
    if port_kind(args.port) == "grbl":
        return _home_grbl(args, settings)
    order = check_homing(settings, args.axes)
    with hold_machine(args, settings, "cam home") as hold:
        start = hold.state.position_steps
        was_known = hold.state.position_known
        port = _port_of(args, settings, start)
        ctl = Controller()
        previous = {s: signal.signal(s, lambda signum, frame: ctl.stop()) for s in _STOP_SIGNALS}
        hold.mark_running(f"cam home {order}")
        try:
            result = home(port, settings, start, axes=order, realtime=args.realtime, controller=ctl,
                          on_phase=_say)
        except HomingError as exc:
            hold.record(hold.state.lost(f"homing did not finish ({exc})"))
            print(f"homing did not finish: {exc}; the machine is not homed, its position unknown", file=sys.stderr)
            return EXIT_INTERRUPTED
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
            if hold.state.running is not None:  # an error that is not homing's own: nothing is known
                hold.record(hold.state.lost("homing did not finish"))
            if isinstance(port, MockPort) and args.pin_log:
                write_pin_log(port.pin_log(), args.pin_log)
            elif not isinstance(port, MockPort):
                port.close()
        left = "".join(a for a in "XYZ" if a.lower() not in order)
        if left and not was_known and not hold.existed:
            # a new machine (no state file): the axes not homed have no coordinate at all, not even a guess to keep
            # (issue #43 point 5); after a stop the file's guess is kept, as before
            hold.record(replace(hold.state, position_steps=tuple(result.position_steps)).lost(
                f"homed {order.upper()} only, {left} unknown: home every axis (cam home) or say where the tool is "
                f"(cam where --set X,Y,Z)"))
            print(f"homed {order.upper()}; {left} not homed on a new machine: the position stays unknown "
                  f"(home every axis with cam home, or cam where --set X,Y,Z)", file=sys.stderr)
            return 0
        hold.record(replace(hold.state.moved_to(result.position_steps), homed=True))
    x, y, z = steps_to_mm(result.position_steps, settings)
    print(f"homed {order.upper()}: the machine stands at X={x:g} Y={y:g} Z={z:g} mm "
          f"({' '.join(f'{a}={v}' for a, v in zip('XYZ', result.position_steps))} steps), position known")
    return 0


def _home_grbl(args: argparse.Namespace, settings: MachineSettings) -> int:
    """``cam home`` on a grbl port: grbl's own homing cycle ``$H`` (its ``$2x`` settings); the machine frame is
    then grbl's machine coordinates."""
    if args.axes:
        raise CamError(f"grbl homes all its axes with $H (its own [homing] order, $23-$27); drop --axes {args.axes}")
    with hold_machine(args, settings, "cam home") as hold:
        session = MachineSession(args.port, settings, state=hold)
        print("homing with grbl's $H ...", file=sys.stderr, flush=True)
        previous = {s: signal.signal(s, lambda signum, frame: session.stop()) for s in _STOP_SIGNALS}
        try:
            session.home()
            while not session.wait_idle(0.2):  # wakes for Ctrl-C
                pass
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
        if session.last_run.get("status") != "finished":
            print(f"homing did not finish: {'; '.join(session.last_run.get('messages') or ['stopped'])}; the "
                  f"machine is not homed, its position unknown", file=sys.stderr)
            return EXIT_INTERRUPTED if session.last_run.get("status") == "emergency-stopped" else 2
        pos = hold.state.position_steps
    x, y, z = steps_to_mm(pos, settings)
    print(f"homed: the machine stands at X={x:g} Y={y:g} Z={z:g} mm "
          f"({' '.join(f'{a}={v}' for a, v in zip('XYZ', pos))} steps), position known")
    return 0
