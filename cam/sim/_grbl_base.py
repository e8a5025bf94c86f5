"""Constants, data types and small helpers of the grbl 1.1 emulator (:mod:`cam.sim.grbl`)."""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Sequence

WELCOME = "Grbl 1.1h ['$' for help]"
RX_BUFFER_BYTES = 128
PLANNER_BLOCKS = 15
LINE_MAX_CHARS = 80
TICK_S = 0.001
BOOT_WALL_S = 0.02     # a host opened the port: the board restarts this long after (the host's open has flushed)
STARVE_WINDOW_S = 1.0   # a planner dry for longer than this before the next motion: the host paused, not starved
MM_PER_INCH = 25.4

# grbl's $$ as listed in interface.md (defaults.h values), with $10=1 (MPos reports, grbl 1.1's default).
DEFAULT_SETTINGS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 0, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0, 30: 1000, 31: 0, 32: 0,
    100: 250.0, 101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0,
    120: 10.0, 121: 10.0, 122: 10.0, 130: 200.0, 131: 200.0, 132: 200.0,
}
INT_SETTINGS = {0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 30, 31, 32}
BOOL_SETTINGS = {4, 5, 6, 13, 20, 21, 22, 32}
HELP = "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"
UNLOCK_MSG = "[MSG:'$H'|'$X' to unlock]"

# real-time bytes (commands.md, "Realtime commands")
RT_RESET, RT_STATUS, RT_HOLD, RT_START = 0x18, ord("?"), ord("!"), ord("~")
RT_DOOR, RT_JOG_CANCEL = 0x84, 0x85
RT_SPINDLE_STOP, RT_FLOOD, RT_MIST = 0x9E, 0xA0, 0xA1


class GrblCodeError(Exception):
    """A line refused with ``error:code``."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


@dataclass(frozen=True)
class ExecutedBlock:
    """One planner block the emulated machine ran to its end (or was halted in: ``halted``).

    ``line`` counts the lines the emulator took since power-up, from 1 (every line, ``$`` commands and empty
    lines too); ``kind`` is ``G0``, ``G1``, ``G2``, ``G3`` (one chord of an arc), ``G28``, ``G30``, ``jog``
    or ``home``; positions are machine coordinates in mm; ``feed_mm_min`` the programmed rate (rapids: the
    axes' maximum); ``t_end_s`` the simulated time the block ended."""

    line: int
    kind: str
    start_mm: tuple[float, float, float]
    end_mm: tuple[float, float, float]
    feed_mm_min: float
    t_end_s: float
    halted: bool = False


@dataclass
class Block:
    line: int
    kind: str
    start: list[float]
    end: list[float]
    feed_mm_min: float          # programmed (G93: from the block's duration); rapids: max rate
    rapid: bool
    jog: bool = False
    length_mm: float = 0.0
    unit: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_mm_s2: float = 0.0
    max_mm_s: float = 0.0
    junction_mm_s: float = 0.0  # the most this block may be entered at (0 when it starts from a stop)


@dataclass
class ParserState:
    """grbl's g-code parser state (the modal groups, offsets and the planned position)."""

    motion: int = 0
    plane: int = 17
    inches: bool = False
    incremental: bool = False
    inverse_time: bool = False
    wcs: int = 0               # 0..5 = G54..G59
    spindle: int = 5
    coolant: set = field(default_factory=set)
    feed: float = 0.0          # mm/min (or 1/min with G93)
    rpm: float = 0.0
    tool: int = 0
    tlo_mm: float = 0.0
    g92_mm: list = field(default_factory=lambda: [0.0, 0.0, 0.0])


WORD_RE = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")
SETTING_RE = re.compile(r"^\$(\d+)=(.*)$")
NUM_RE = re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)$")


def preparse(raw: str) -> str:
    """grbl's pre-parser: drop spaces and control characters, ``( )`` comments and ``;`` to the end, upper case."""
    out = []
    depth = 0
    for ch in raw:
        if depth:
            if ch == ")":
                depth = 0
            continue
        if ch == "(":
            depth = 1
        elif ch == ";":
            break
        elif ch > " " and ord(ch) < 0x7F:
            out.append(ch.upper())
    return "".join(out)


def fmt(values: Sequence[float], inches: bool = False) -> str:
    if inches:
        return ",".join(f"{v / MM_PER_INCH:.4f}" for v in values)
    return ",".join(f"{v:.3f}" for v in values)


LOG_HEADER = "line,kind,x0_mm,y0_mm,z0_mm,x1_mm,y1_mm,z1_mm,feed_mm_min,t_end_s,halted"
"""The columns of the ``log_path`` CSV: machine coordinates of each executed block's start and end."""
