"""What the parts of the MAXIMUS firmware emulator share: the labels where the firmware waits, and the
exceptions that carry control between them (see :mod:`cam.sim.maximus`)."""
from __future__ import annotations

from dataclasses import dataclass

# Where the firmware waits for a byte (its labels; the 9-byte Init read has no label of its own).
POWER_UP = "POWER_UP"
MODE_SELECTION = "MODE_SELECTION"
JOG_DATA_INPUT = "JOG_DATA_INPUT"
DRILL_MODE1_INITIALIZE = "DRILL_MODE1_INITIALIZE"
INITIALIZE_DRILL_MODE = "INITIALIZE_DRILL_MODE"
DRILL_MODE1_INPUT = "DRILL_MODE1_INPUT"
BUSY = "BUSY"


class _Goto(Exception):
    """``goto_address(...)`` out of an interrupt service routine."""

    def __init__(self, label: str) -> None:
        super().__init__(label)
        self.label = label


class _PowerOn(Exception):
    """The board is reset: start again at ``main()``."""


class _Halt(Exception):
    """The emulator is stopped."""


@dataclass
class _ReplyFault:
    kind: str  # "drop", "corrupt" or "late"
    match: int | None
    skip: int
    value: float
