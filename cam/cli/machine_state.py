"""``cam where`` and ``cam zero``: the machine state file from the command line (issue #29 point 3).

The state file (:mod:`cam.drive.state`) is ``--state FILE``, else the machine's default one in the user's
state folder, named after the machine file and the port.  Positions given on the command line are in mm:
``where --set`` and ``zero --at`` in the machine frame (from the machine's home, +Z deeper).
"""
from __future__ import annotations

import argparse
import signal
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

from ..drive.state import (
    MachineLock, MachineState, StateBusyError, StateHold, check_in_travel, dump_json, machine_record, mm_to_steps, read_state,
    steps_to_mm,
)
from ..drive.grbl_machine import GRBL_OFFSETS, adopt_position, grbl_machine
from ..drive.machines import DEFAULT_PORT, backend_of, can
from ..drive.ports import MockPort
from ..drive.session import MachineSession
from ..errors import CamError
from ..settings import MachineSettings
from ..verify.pinlog import write_pin_log
from .common import port_settings, state_path_of

__all__ = ["cmd_where", "cmd_zero", "hold_machine", "state_path_of"]

Steps3 = tuple[int, int, int]


def hold_machine(args: argparse.Namespace, settings: MachineSettings, what: str) -> StateHold:
    """The command's hold on its machine's state file (the lock taken; see :class:`StateHold`).  On a grbl
    port the board is asked where it stands first (:func:`cam.drive.grbl_machine.adopt_position`): the state
    file then says what grbl says.

    The hold is the port's (:class:`StateHold` with ``port``): on a real port the device's own lock is taken
    first (a second command on the device is refused, naming the first), a missing state file is a position
    unknown, and another machine file than the recorded one is refused unless ``--machine-changed``."""
    hold = StateHold(state_path_of(args), settings, what, port=getattr(args, "port", None) or DEFAULT_PORT,
                     machine=machine_record(getattr(args, "machine", None)),
                     machine_changed=bool(getattr(args, "machine_changed", False)))
    for warning in hold.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    if can(getattr(args, "port", None) or DEFAULT_PORT, "reports_position"):
        try:
            machine = grbl_machine(args.port, settings)
            if machine.warning and not machine.warned:
                machine.warned = True  # once a process
                print(f"warning: {machine.warning}", file=sys.stderr)
            adopt_position(machine, hold, lambda text, level: None)  # why it is unknown: in the state file
        except BaseException:
            hold.close()
            raise
    return hold


def _triple(text: str) -> str:
    return " ".join(f"{a}={v}" for a, v in zip("XYZ", text))


def where_report(state: MachineState, settings: MachineSettings, path: Path, driving: Any = None) -> dict:
    """What ``cam where --json`` prints: machine and work position (steps and mm), offsets, flags."""
    work = state.to_work(state.position_steps)
    return {
        "state_file": str(path),
        "machine_steps": list(state.position_steps), "machine_mm": list(steps_to_mm(state.position_steps, settings)),
        "work_steps": list(work), "work_mm": list(steps_to_mm(work, settings)),
        "active_offset": state.active_offset,
        "offsets_steps": {k: list(v) for k, v in state.offsets_steps.items()},
        "position_known": state.position_known, "unknown_reason": state.unknown_reason, "homed": state.homed,
        "tool": state.tool,
        "running": None if driving is None else vars(driving),
        "machine_file": None if state.machine is None else state.machine.named(),
        "board": state.board,
    }


def _print_where(rep: dict) -> None:
    print(f"machine: {_triple(rep['machine_mm'])} mm ({_triple(rep['machine_steps'])} steps)")
    print(f"work {rep['active_offset']}: {_triple(rep['work_mm'])} mm ({_triple(rep['work_steps'])} steps)")
    known = "position known" if rep["position_known"] else f"position UNKNOWN ({rep['unknown_reason']})"
    print(f"{known}; {'homed' if rep['homed'] else 'not homed'}; tool: {rep['tool'] or 'not said'}")
    set_offsets = [f"{k} {_triple(v)}" for k, v in rep["offsets_steps"].items() if any(v)]
    print(f"work zeros (machine steps): {'; '.join(set_offsets) if set_offsets else 'all at the home'}")
    if rep["running"]:
        r = rep["running"]
        print(f"driven now by pid {r['pid']} ({r['command']}, since {r['since']}): this is where it started")
    print(f"state file: {rep['state_file']}" + (f" (machine file: {rep['machine_file']})" if rep["machine_file"]
                                               else ""))
    if rep["board"]:
        print(f"board: {rep['board']}")


def _read_now(path: Path, settings: MachineSettings, port: str) -> tuple[MachineState, Any]:
    """The state as it stands, without the lock: a running marker whose process holds no lock any more is
    shown as what it is (the position unknown); one that does names the command driving the machine.  A
    missing file on a real port: the position unknown."""
    state = read_state(path, settings, port)
    r = state.running
    if r is None:
        return state, None
    if MachineLock(path).holder() is None:
        return replace(state.lost(f"cam (pid {r.pid}: {r.command}) ended without recording where the tool stopped"),
                       running=None), None
    return state, r


def _hold_unless_served(args: argparse.Namespace, settings: MachineSettings) -> StateHold:
    """``cam where``'s hold on the machine.  While ``cam serve`` drives it (the server holds the lock, issue #45
    point 3) the state is the server's to change: one line naming its pid and the page's Set position (nothing is
    routed to the server: the page is where its operator sees what the machine does)."""
    what = "cam where --set/--use" if args.set is not None or args.use else "cam where"
    try:
        return hold_machine(args, settings, what)
    except StateBusyError as exc:
        if not (exc.holder_command or "").startswith("cam serve"):
            raise
        pid = f"pid {exc.holder_pid}" if exc.holder_pid is not None else "another process"
        raise StateBusyError(f"{what} refused: cam serve ({pid}) drives this machine; use Set position (or Home) on "
                             f"its page, or stop the server first") from None


def cmd_where(args: argparse.Namespace) -> int:
    settings = port_settings(args, args.port)
    path = state_path_of(args)
    driving = None
    grbl = can(args.port or DEFAULT_PORT, "reports_position")
    if args.set is not None or args.use or grbl:  # grbl: what the board says, read now
        with _hold_unless_served(args, settings) as hold:
            state = hold.state
            if args.set is not None:
                steps = mm_to_steps(args.set, settings)
                check_in_travel(steps, settings, f"--set {','.join(f'{v:g}' for v in args.set)} mm")
                state = replace(state.moved_to(steps), homed=False)
                if grbl:  # the user's word: grbl unlocked where the tool stands, its MPos read from here
                    machine = grbl_machine(args.port, settings)
                    if machine.in_alarm():
                        machine.unlock()
                    machine.rebase(steps)
            if args.use:
                state = replace(state, active_offset=args.use)
                if grbl and args.use in GRBL_OFFSETS:  # grbl's own active offset too
                    grbl_machine(args.port, settings).use_offset(args.use)
            hold.record(state)
    else:
        state, driving = _read_now(path, settings, args.port or DEFAULT_PORT)
    rep = where_report(state, settings, path, driving)
    if args.json:
        print(dump_json(rep), end="")
    else:
        _print_where(rep)
    return 0


def _axes(text: str) -> str:
    axes = text.upper()
    if not axes or any(a not in "XYZ" for a in axes) or len(set(axes)) != len(axes):
        raise CamError(f"axes must be X, Y, Z or several of them (XY, XYZ), got '{text}'")
    return axes


def cmd_zero(args: argparse.Namespace) -> int:
    axes = _axes(args.axes)
    settings = port_settings(args, args.port)
    if can(args.port or DEFAULT_PORT, "reports_position") and args.at is None:
        return _zero_on_grbl(args, axes, settings)
    with hold_machine(args, settings, "cam zero") as hold:
        state = hold.state
        name = args.offset or state.active_offset
        if args.at is not None:
            point = mm_to_steps(args.at, settings)
            check_in_travel(point, settings, f"--at {','.join(f'{v:g}' for v in args.at)} mm")
        else:
            hold.require_known()
            point = state.position_steps
        zero = list(state.work_zero_steps(name))
        for a in axes:
            zero["XYZ".index(a)] = point["XYZ".index(a)]
        state = state.with_offset(name, tuple(zero))  # type: ignore[arg-type]
        hold.record(state)
    zmm = steps_to_mm(zero, settings)
    print(f"{name} zero of {axes} set: its zero is at machine {_triple(zmm)} mm ({_triple(zero)} steps)"
          + ("" if name == state.active_offset else f"; the active offset is still {state.active_offset} "
             f"(cam where --use {name})"))
    return 0


def _zero_on_grbl(args: argparse.Namespace, axes: str, settings: MachineSettings) -> int:
    """``cam zero`` on a grbl port: the state file's offset and grbl's own (``G10 L20``), where grbl says the
    tool stands."""
    with hold_machine(args, settings, "cam zero") as hold:
        session = MachineSession(args.port, settings, state=hold)
        session.zero(axes, args.offset)
        state = hold.state
    name = args.offset or state.active_offset
    zero = state.work_zero_steps(name)
    print(f"{name} zero of {axes} set here (grbl's too): its zero is at machine {_triple(steps_to_mm(zero, settings))} "
          f"mm ({_triple(zero)} steps)")
    return 0


_STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


def run_activity(args: argparse.Namespace, settings: MachineSettings, hold: Any,
                 start: Callable[[MachineSession], Any]) -> tuple[MachineSession, dict[str, Any]]:
    """A session on ``--port`` (a mock of this command's, whose pin log ``--pin-log`` is written here) holding the
    machine by ``hold``; ``start(session)`` run with Ctrl-C (and SIGTERM, SIGHUP) as a stop, each phase it says
    printed on stderr, waited for.  Returns the session and its last run (``cam home``, ``cam probe``)."""
    port = backend_of(args.port).logging_port(args.port, settings)
    session = MachineSession(port, settings, realtime=bool(getattr(args, "realtime", False)), state=hold)
    session.on_detail = lambda text: print(text, file=sys.stderr, flush=True)
    previous = {s: signal.signal(s, lambda signum, frame: session.stop()) for s in _STOP_SIGNALS}
    try:
        start(session)
        while not session.wait_idle(0.2):  # wakes for Ctrl-C
            pass
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if isinstance(port, MockPort) and getattr(args, "pin_log", None):
            write_pin_log(port.pin_log(), args.pin_log)
    return session, session.last_run
