"""The MAXIMUS emulator's limit-switch options, declared once for ``cam emulate-maximus`` and
``python -m cam.sim.maximus`` (argparse only: ``cam --help`` loads this module and must stay light).

The switches are the firmware's (seed 000, Appendix 1: HOME_SWITCH_X, LIMIT_SWITCH_X, ... of
:mod:`cam.drive.maximus.protocol`); here they get the names ``--trip`` takes.  The module sits in
:mod:`cam.drive` because both the command line and the emulator (:mod:`cam.sim`) read it, and neither may
import the other (tests/test_layers.py).
"""
from __future__ import annotations

import argparse
from typing import Callable

__all__ = ["MAXIMUS_SWITCHES", "add_maximus_switch_options", "trip_switch"]

MAXIMUS_SWITCHES = ("home-x", "limit-x", "home-y", "limit-y", "home-z", "limit-z")
"""The MAXIMUS board's switches as ``--trip`` names them (HOME_SWITCH_X, LIMIT_SWITCH_X, ... of the firmware)."""

MAX_TRIP_MOVES = 1_000_000
"""The most moves ``--trip SWITCH@MOVES`` lets go by before the switch closes."""


def trip_switch(text: str) -> tuple[str, int]:
    """``--trip SWITCH[@MOVES]``: a switch of :data:`MAXIMUS_SWITCHES` and the moves that go by before it closes.

    >>> trip_switch("Limit-X@3")
    ('limit-x', 3)
    """
    name, _, moves = str(text).strip().lower().partition("@")
    if name not in MAXIMUS_SWITCHES:
        raise argparse.ArgumentTypeError(f"--trip names one of {', '.join(MAXIMUS_SWITCHES)}, got '{text}'")
    skip = int(moves) if moves.isdigit() else 0 if not moves else -1
    if not 0 <= skip <= MAX_TRIP_MOVES:
        raise argparse.ArgumentTypeError(
            f"--trip {name}@MOVES takes a whole number of moves 0..{MAX_TRIP_MOVES}, got '{text}'")
    return name, skip


def _byte_option(name: str) -> Callable[[str], int]:
    """An argparse type: a whole number 0..255 (a Delay byte), refused in one line naming option ``name``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = -1
        if not 0 <= value <= 255:
            raise argparse.ArgumentTypeError(f"{name} takes a whole number 0..255, got '{text}'")
        return value

    return parse


def add_maximus_switch_options(parser: argparse.ArgumentParser) -> None:
    """The limit-switch options of the MAXIMUS emulator (``cam emulate-maximus``, ``python -m cam.sim.maximus``):
    where the switches close, the back-off delay, switches pressed on purpose."""
    for axis in "xy":
        parser.add_argument(f"--travel-{axis}", type=int, nargs=2, metavar=("LOW", "HIGH"),
                            help=f"{axis.upper()} travel ends in pulses from the power-up position: HOME_SWITCH_"
                            f"{axis.upper()} closes below LOW, LIMIT_SWITCH_{axis.upper()} above HIGH "
                            "(default: no switches on this axis)")
    parser.add_argument("--travel-z", type=int, nargs=2, metavar=("LOW", "HIGH"),
                        help="Z travel ends in pulses from the power-up position, height (+ up): HOME_SWITCH_Z "
                        "closes above HIGH, LIMIT_SWITCH_Z below LOW (default: no switches on Z)")
    parser.add_argument("--axis-delay", type=_byte_option("--axis-delay"), default=0, metavar="DELAY",
                        help="the Delay byte (0..255) of the firmware's back-off off a limit switch until a Jog "
                        "packet sets it (the listing's axisDelay, 0 at power-up)")
    parser.add_argument("--trip", type=trip_switch, action="append", default=[], metavar="SWITCH[@MOVES]",
                        help=f"press SWITCH ({', '.join(MAXIMUS_SWITCHES)}) at the first step pulse of a move, "
                        "after MOVES moves (Jog, Offset or Drill Data packets; default 0: the next one); it is let "
                        "go once the firmware has read it; repeatable")
