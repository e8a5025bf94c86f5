"""The host side of a grbl 1.1 serial link: ``grbl:/dev/ttyUSB0?baud=115200``.

:class:`GrblLink` opens the device with pyserial (8N1), waits for grbl's welcome line (``Grbl 1.1h ['$' for
help]``; when none comes, as when the board did not reset on open, it sends a soft reset 0x18 to get one), reads
``$$`` into :attr:`GrblLink.settings`, and streams G-code with *character counting*: it keeps a count of the
bytes sent whose ``ok``/``error`` has not come back yet and sends the next line as soon as it fits in grbl's
128-byte serial receive buffer, never waiting for each ``ok`` first (grbl's interface.md, "Streaming
Protocol: Character-Counting"), so grbl's planner keeps blocks to plan on short segments.

grbl's answers become one line each: ``error:n`` a :class:`GrblError` naming the line and grbl's meaning of
``n``, ``ALARM:n`` a :class:`GrblAlarm` with the alarm's meaning, a closed or silent port a
:class:`~cam.errors.PortError`.  The meanings paraphrase grbl's tables (gnea/grbl ``doc/markdown/interface.md``,
"Grbl Response Messages" and "Alarm Message"; ``doc/csv/error_codes_en_US.csv``,
``doc/csv/alarm_codes_en_US.csv``).

Real-time commands go out at once, outside the count: :meth:`GrblLink.hold` (``!``), :meth:`GrblLink.resume`
(``~``), :meth:`GrblLink.soft_reset` (0x18), :meth:`GrblLink.override` (0x90-0x9D) and :meth:`GrblLink.status`
(``?``, parsed into a :class:`GrblStatus` with machine and work positions from ``MPos``/``WPos`` and the last
``WCO``).  :meth:`GrblLink.cancel` shuts the gate on lines: a stream waiting for room ends with a
:class:`~cam.errors.PortError` and nothing more is sent until :meth:`GrblLink.allow` (a stop must never let a
queued line through after the reset that ends it).  The machine session drives a board through
:mod:`cam.drive.grbl_machine`.
"""
from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable, Iterable, Optional
from urllib.parse import parse_qs

import serial

from ..errors import PortError
from ..settings import MachineSettings

__all__ = [
    "GRBL_PREFIX", "RX_BUFFER_BYTES", "ERROR_MEANINGS", "ALARM_MEANINGS", "GrblError", "GrblAlarm", "GrblStatus",
    "StreamReport", "GrblLink", "parse_grbl_url", "parse_identity", "parse_buffer_sizes", "parse_settings", "parse_status",
    "settings_mismatches",
    "strip_comments", "open_grbl",
]

GRBL_PREFIX = "grbl:"
RX_BUFFER_BYTES = 128
PLANNER_BLOCKS = 15
"""grbl 1.1's planner blocks on an ATmega328P (config.h ``BLOCK_BUFFER_SIZE`` 16, one kept free): the most
motion that can be queued behind a line grbl has not answered yet."""
RING_POLL_S = 0.01
"""How often a line waiting for room in grbl's receive buffer asks for a status report: the room the buffer
report shows is what lets it go."""
ASK_AGAIN_S = 0.5
"""How long a ``?`` may stay unanswered before the next poll asks again (a report lost on the line)."""
CUT_SHORT_S = 0.5
"""How long a status report cut short (no ``>``) waits for the line after it: grbl's welcome says a reset cut
it, anything else (or nothing) makes it a link fault."""
HOMING_S = 600.0
"""The longest a ``$H`` may take before its answer is overdue (a homing cycle's search distance at its slowest)."""
DEFAULT_BAUD = 115200

# grbl 1.1 error codes (interface.md "Grbl Response Messages"; doc/csv/error_codes_en_US.csv), paraphrased.
ERROR_MEANINGS: dict[int, str] = {
    1: "a G-code word has no letter",
    2: "a number is missing or badly formed",
    3: "unknown or unsupported '$' command",
    4: "negative value where a positive one is expected",
    5: "homing is not enabled ($22)",
    6: "step pulse time must be at least 3 microseconds",
    7: "EEPROM read failed; settings restored to defaults",
    8: "'$' command refused unless grbl is idle",
    9: "G-code is locked out in the alarm or jog state",
    10: "soft limits need homing enabled",
    11: "line too long (over grbl's 80 characters); not executed",
    12: "setting would exceed the maximum step rate",
    13: "safety door open",
    14: "build info or startup line too long for EEPROM",
    15: "jog target outside the machine travel; jog ignored",
    16: "bad jog command (no '=' or a forbidden G-code)",
    17: "laser mode needs PWM output",
    20: "unsupported or invalid G-code command",
    21: "two G-code commands of the same modal group in one block",
    22: "feed rate not set",
    23: "this G-code command needs an integer value",
    24: "two G-code commands in the block both need the axis words",
    25: "a G-code word is repeated in the block",
    26: "the command needs axis words and the block has none",
    27: "line number out of range (1-9,999,999)",
    28: "a required P or L value word is missing",
    29: "only G54-G59 work coordinate systems exist (no G59.x)",
    30: "G53 needs G0 or G1 motion mode",
    31: "axis words in the block with no motion using them (G80)",
    32: "G2/G3 arc without an axis word in the selected plane",
    33: "invalid motion target (impossible arc or probe target)",
    34: "arc radius definition cannot be computed",
    35: "G2/G3 arc without an I/J/K offset word in the selected plane",
    36: "unused value words left in the block",
    37: "G43.1 tool length offset on an axis other than the configured one",
    38: "tool number above the supported maximum",
}

# grbl 1.1 alarm codes (interface.md "Alarm Message"; doc/csv/alarm_codes_en_US.csv), paraphrased.
ALARM_MEANINGS: dict[int, str] = {
    1: "hard limit triggered; the machine position is probably lost, re-home",
    2: "motion target beyond the machine travel (soft limit); position kept, unlock with $X",
    3: "reset while moving; the position may be lost, re-home",
    4: "probe fail: the probe was not in its expected state before the cycle",
    5: "probe fail: no contact within the programmed travel",
    6: "homing fail: the homing cycle was reset",
    7: "homing fail: the safety door opened during homing",
    8: "homing fail: pull-off did not clear the limit switch",
    9: "homing fail: limit switch not found within the search distance",
}


class GrblError(PortError):
    """grbl refused a line (``error:n``) or the link broke its protocol; one line, grbl's meaning in it."""

    def __init__(self, message: str, code: Optional[int] = None) -> None:
        super().__init__(message)
        self.code = code


class GrblAlarm(GrblError):
    """grbl raised ``ALARM:n``: it halted and locks out G-code until a reset, ``$X`` or ``$H``."""


def error_text(code: int) -> str:
    return f"error:{code} ({ERROR_MEANINGS.get(code, 'unknown grbl error code')})"


def alarm_text(code: int) -> str:
    return f"ALARM:{code} ({ALARM_MEANINGS.get(code, 'unknown grbl alarm code')})"


def strip_comments(line: str) -> str:
    """A G-code line without its ``( )`` and ``;`` comments and outer spaces.

    >>> strip_comments("G1 X1 (ok?) Y2 ; done!")
    'G1 X1  Y2'
    """
    out = []
    depth = 0
    for ch in line:
        if depth:
            depth = 0 if ch == ")" else 1
            continue
        if ch == "(":
            depth = 1
        elif ch == ";":
            break
        else:
            out.append(ch)
    return "".join(out).strip()


def parse_grbl_url(url: str) -> tuple[str, int]:
    """``grbl:/dev/ttyUSB0?baud=115200`` -> ``("/dev/ttyUSB0", 115200)`` (baud 115200 when not given).

    >>> parse_grbl_url("grbl:/dev/ttyACM0?baud=250000")
    ('/dev/ttyACM0', 250000)
    >>> parse_grbl_url("grbl:COM3")
    ('COM3', 115200)
    """
    rest = url[len(GRBL_PREFIX):] if url.startswith(GRBL_PREFIX) else url
    device, _, query = rest.partition("?")
    if not device:
        raise PortError(f"{url!r}: no device after 'grbl:' (e.g. grbl:/dev/ttyUSB0?baud=115200)")
    baud = DEFAULT_BAUD
    params = parse_qs(query, keep_blank_values=True)
    for key in params:
        if key != "baud":
            raise PortError(f"{url!r}: unknown option {key!r} (only baud=)")
    if "baud" in params:
        try:
            baud = int(params["baud"][-1])
        except ValueError:
            raise PortError(f"{url!r}: baud must be a whole number, got {params['baud'][-1]!r}") from None
        if baud <= 0:
            raise PortError(f"{url!r}: baud must be > 0")
    return device, baud


def parse_identity(lines: Iterable[str]) -> Optional[str]:
    """The board's identity in grbl's ``$I`` answer: its ``[VER:...]`` and ``[OPT:...]`` lines, one space
    between, or None without a ``[VER:`` line.  ``VER`` holds grbl's version and build date and, after the last
    ``:``, the build info the user sets with ``$I=NAME`` (grbl's interface.md, "Feedback Messages").

    >>> parse_identity(["[VER:1.1h.20190830:MILL-A]", "[OPT:V,15,128]"])
    '[VER:1.1h.20190830:MILL-A] [OPT:V,15,128]'
    >>> parse_identity(["[MSG:x]"]) is None
    True
    """
    found = [text.strip() for text in lines if text.strip().startswith(("[VER:", "[OPT:"))]
    if not any(text.startswith("[VER:") for text in found):
        return None
    return " ".join(found)[:200]


def parse_buffer_sizes(identity: Optional[str]) -> Optional[tuple[int, int]]:
    """``(planner blocks, receive buffer bytes)`` from the ``[OPT:codes,blocks,bytes...]`` of a ``$I`` answer
    (grbl 1.1: ``[OPT:V,15,128]``; grblHAL: ``[OPT:VNMSL,35,1024,3,0]``), or None when it says no sizes, or
    sizes no board has.

    >>> parse_buffer_sizes("[VER:1.1h.20190830:] [OPT:V,15,128]")
    (15, 128)
    >>> parse_buffer_sizes("[VER:1.1f.20220325:] [OPT:VNMSL,35,1024,3,0]")
    (35, 1024)
    >>> parse_buffer_sizes("[VER:1.1h.20190830:]") is None
    True
    """
    if not identity or "[OPT:" not in identity:
        return None
    fields = identity.split("[OPT:", 1)[1].split("]", 1)[0].split(",")
    try:
        blocks, rx_bytes = int(fields[1]), int(fields[2])
    except (IndexError, ValueError):
        return None
    if not (1 <= blocks <= 1000 and 64 <= rx_bytes <= 65536):
        return None
    return blocks, rx_bytes


def parse_settings(lines: Iterable[str], device: str = "grbl") -> dict[int, float]:
    """grbl's ``$$`` answer (``$100=250.000`` lines) as ``{100: 250.0}``.

    >>> parse_settings(["$0=10", "$100=250.000", "[MSG:x]"])
    {0: 10.0, 100: 250.0}
    """
    settings: dict[int, float] = {}
    for text in lines:
        key, eq, value = text.partition("=")
        if eq and key.startswith("$") and key[1:].isdigit():
            try:
                settings[int(key[1:])] = float(value)
            except ValueError:
                raise GrblError(f"{device} sent a bad setting line {text!r}") from None
    return settings


def settings_mismatches(grbl: dict[int, float], machine: MachineSettings, *,
                        rel_tolerance: float = 0.01) -> list[str]:
    """Where grbl's ``$$`` disagrees with the machine file by more than ``rel_tolerance``: steps/mm ($100-$102
    against 1 / ``mm_per_step``), max rates ($110-$112, mm/min, against ``max_speed_*_mm_s``), accelerations
    ($120-$122) and travel ($130-$132 against the travel limits' span).  One short item each; a setting grbl
    did not send is skipped.

    >>> settings_mismatches({100: 250.0, 120: 50.0}, MachineSettings())
    ['X steps/mm $100=250 vs 34.6']
    """
    per_step = (machine.mm_per_step_xy, machine.mm_per_step_xy, machine.mm_per_step_z)
    rate = (machine.max_speed_x_mm_s, machine.max_speed_y_mm_s, machine.max_speed_z_mm_s)
    accel = (machine.accel_x_mm_s2, machine.accel_y_mm_s2, machine.accel_z_mm_s2)
    span = [(hi - lo) * per_step[i] for i, (lo, hi) in enumerate(machine.travel.bounds_steps())]
    out = []
    for i, axis in enumerate("XYZ"):
        for base, what, want in ((100, "steps/mm", 1.0 / per_step[i]), (110, "max rate mm/min", rate[i] * 60.0),
                                 (120, "accel mm/s^2", accel[i]), (130, "travel mm", span[i])):
            have = grbl.get(base + i)
            if have is not None and abs(have - want) > rel_tolerance * max(abs(want), 1e-9):
                out.append(f"{axis} {what} ${base + i}={have:g} vs {want:.3g}")
    return out


@dataclass(frozen=True)
class GrblStatus:
    """One ``?`` status report.  Positions in mm (or inches with ``$13=1``), X, Y, Z; a position grbl did not
    send is worked out from the other and the last ``WCO`` (``WPos = MPos - WCO``)."""

    state: str                                  # Idle, Run, Hold:0, Hold:1, Jog, Alarm, Door:n, Check, Home, Sleep
    mpos_mm: tuple[float, ...]
    wpos_mm: tuple[float, ...]
    wco_mm: tuple[float, ...]
    feed_mm_min: float
    spindle_rpm: float
    planner_free: Optional[int] = None          # Bf: blocks free
    rx_free: Optional[int] = None               # Bf: bytes free
    overrides: Optional[tuple[int, int, int]] = None
    raw: str = ""


MAX_POSITION_MM = 1.0e5
"""The largest machine or work coordinate a status report may hold, mm (100 m: no desktop machine comes near;
a value past it is a corrupted report, not a place)."""


def _numbers(text: str) -> Optional[tuple[float, ...]]:
    """``"1.0,2,3"`` as floats, or None when a value is not a plain finite number."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        return None
    return values if all(math.isfinite(v) for v in values) else None


def parse_status(line: str, last_wco_mm: Optional[tuple[float, ...]] = None) -> GrblStatus:
    """Parse ``<Idle|MPos:1.000,2.000,0.000|FS:0,0|WCO:0.000,1.000,0.000>`` (interface.md, "Real-time Status
    reports"), as grbl 1.1, grblHAL and FluidNC send it.

    A report is data: the positions (``MPos``, ``WPos``, ``WCO``) must hold at least X, Y and Z as finite
    numbers within :data:`MAX_POSITION_MM` (more axes, as grblHAL and FluidNC send for A/B/C, are dropped), or
    the report is refused with a :class:`GrblError`, a link fault; the optional fields (``Bf``, ``FS``, ``F``,
    ``Ov``) are taken when well formed and ignored otherwise, and fields ``cam`` does not use (``Pn``, ``Ln``,
    ``A``, ``T``, ``H``, ``SD`` ...) are ignored.

    >>> s = parse_status("<Run|MPos:1.000,2.000,3.000|Bf:14,100|FS:500,0|WCO:1.000,0.000,0.000>")
    >>> s.state, s.wpos_mm, s.planner_free, s.feed_mm_min
    ('Run', (0.0, 2.0, 3.0), 14, 500.0)
    >>> parse_status("<Idle|MPos:1,2,3|Bf:15|Ov:100,100>").overrides is None
    True
    """
    text = line.strip()
    if not (text.startswith("<") and text.endswith(">")) or len(text) > 400:
        raise GrblError(f"not a grbl status report: {line[:80]!r}")
    fields = text[1:-1].split("|")
    state = fields[0]
    if not state or not state.replace(":", "").isalnum():
        raise GrblError(f"grbl status report with no state: {line[:80]!r}")
    values: dict[str, str] = {}
    for item in fields[1:]:
        key, _, val = item.partition(":")
        values[key] = val

    def position(key: str) -> tuple[float, ...]:
        nums = _numbers(values[key])
        if nums is None or len(nums) < 3 or any(abs(v) > MAX_POSITION_MM for v in nums[:3]):
            raise GrblError(f"impossible {key} in grbl status report {line[:80]!r} (X, Y, Z must be finite "
                            f"numbers within {MAX_POSITION_MM:g} mm)")
        return nums[:3]

    def optional(key: str, count: int) -> Optional[tuple[float, ...]]:
        nums = _numbers(values[key]) if key in values else None
        return nums if nums is not None and len(nums) >= count and all(abs(v) < 1e9 for v in nums) else None

    wco = position("WCO") if "WCO" in values else (last_wco_mm or (0.0, 0.0, 0.0))
    if "MPos" in values:
        mpos = position("MPos")
        wpos = tuple(m - w for m, w in zip(mpos, wco))
    elif "WPos" in values:
        wpos = position("WPos")
        mpos = tuple(p + w for p, w in zip(wpos, wco))
    else:
        raise GrblError(f"grbl status report without a position: {line[:80]!r}")
    feed = rpm = 0.0
    fs = optional("FS", 1) or optional("F", 1)
    if fs is not None:
        feed, rpm = fs[0], (fs[1] if len(fs) > 1 else 0.0)
    bf = optional("Bf", 2)
    planner_free, rx_free = (int(bf[0]), int(bf[1])) if bf is not None else (None, None)
    ov = optional("Ov", 3)
    overrides = (int(ov[0]), int(ov[1]), int(ov[2])) if ov is not None else None
    return GrblStatus(state, mpos, wpos, wco, feed, rpm, planner_free, rx_free, overrides, text)


@dataclass(frozen=True)
class StreamReport:
    """What a :meth:`GrblLink.stream` sent: lines, bytes, and the most bytes it had outstanding at once."""

    lines: int
    bytes_sent: int
    max_outstanding_bytes: int


_WORD = re.compile(r"([A-Z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


class LineTimer:
    """How long grbl may take to run a G-code line, in seconds at 100 % override, from grbl's own ``$$``: the
    path at the line's feed (rapids at the slowest moving axis' ``$11x``) plus one full acceleration and
    deceleration at the lowest ``$12x``; dwells their ``P``; ``$H`` :data:`HOMING_S`.  It follows the modal
    state the lines set (position, feed, G0/G1, G90/G91, G20/G21).  An axis whose position is not known yet
    counts its whole travel (``$13x``, else 1 m).  An upper bound for the answer deadline, not a planner.

    >>> t = LineTimer({110: 600.0, 111: 600.0, 112: 600.0, 120: 10.0, 121: 10.0, 122: 10.0})
    >>> t.time_s("G53G0X0Y0Z0") > 0, round(t.time_s("G53G1X10F600"), 3)
    (True, 2.0)
    """

    def __init__(self, settings: dict[int, float]) -> None:
        self.rate_mm_s = [max(1e-3, settings.get(110 + i, 500.0) / 60.0) for i in range(3)]
        self.accel_mm_s2 = [max(1e-3, settings.get(120 + i, 10.0)) for i in range(3)]
        self.travel_mm = [settings.get(130 + i, 0.0) or 1000.0 for i in range(3)]
        self.pos_mm: list[Optional[float]] = [None, None, None]
        self.feed_mm_min = 0.0
        self.motion = 0.0
        self.absolute = True
        self.inch = False

    def time_s(self, text: str) -> float:
        upper = text.upper()
        if upper.startswith("$H"):
            return HOMING_S
        if upper.startswith("$J="):
            upper = "G1" + upper[3:]
        elif upper.startswith("$"):
            return 0.0
        words = _WORD.findall(upper)
        gs = [float(v) for k, v in words if k == "G"]
        axes = {"XYZ".index(k): float(v) for k, v in words if k in "XYZ"}
        for g in gs:
            if g in (20.0, 21.0):
                self.inch = g == 20.0
            elif g in (90.0, 91.0):
                self.absolute = g == 90.0
            elif g in (0.0, 1.0, 2.0, 3.0) or 38.0 <= g < 39.0:
                self.motion = g
        scale = 25.4 if self.inch else 1.0
        for k, v in words:
            if k == "F":
                self.feed_mm_min = float(v) * scale
        if 4.0 in gs:
            return max(0.0, next((float(v) for k, v in words if k == "P"), 0.0))
        if not axes:
            return 0.0
        absolute = self.absolute or 53.0 in gs
        delta = [0.0, 0.0, 0.0]
        for i, v in axes.items():
            here = self.pos_mm[i]
            target = v * scale if absolute else (here or 0.0) + v * scale
            delta[i] = self.travel_mm[i] if here is None else abs(target - here)
            self.pos_mm[i] = target if absolute or here is not None else None
        length_mm = math.sqrt(sum(d * d for d in delta))
        moving = [i for i in range(3) if delta[i] > 0] or [0]
        if self.motion == 0.0:
            speed = min(self.rate_mm_s[i] for i in moving)
        else:
            speed = max(1e-3, min(self.feed_mm_min / 60.0, *(self.rate_mm_s[i] for i in moving)))
        if self.motion in (2.0, 3.0):
            length_mm = length_mm * math.pi + 2.0 * max(self.travel_mm)  # an arc's path is unknown here: bound it
        return length_mm / speed + speed / min(self.accel_mm_s2[i] for i in moving)


class _RealtimeBytes:
    """grbl's real-time commands that answer nothing, and the halt after a fault (a part of :class:`GrblLink`)."""

    _cond: threading.Condition
    _cancelled: Optional[str]
    _status_seq: int
    _lost: Optional[BaseException]
    _welcomes: int
    _fault: Optional[str]
    _done_errors: list
    status_report: Optional["GrblStatus"]
    settings: dict[int, float]
    timeout_s: float

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _wait(self, predicate: Callable[[], bool], timeout_s: Optional[float], *, check: bool = True,
              where: str = "", quiet_ok: bool = False, poll_s: Optional[float] = None) -> bool:
        raise NotImplementedError

    def _ask_status(self, *, again: bool = False) -> None:
        raise NotImplementedError

    def cancel(self, reason: str) -> None:
        """Shut the gate on lines: a stream or command waiting ends with ``PortError(reason)``, and no line goes
        out until :meth:`allow` (real-time bytes still do)."""
        with self._cond:
            self._cancelled = reason
            self._cond.notify_all()

    def allow(self) -> None:
        """Open the gate :meth:`cancel` shut (the next activity sends again)."""
        with self._cond:
            self._cancelled = None


    def hold(self) -> None:
        """Feed hold ``!``: decelerate to a stop, keep the rest queued."""
        self._write(b"!")

    def resume(self) -> None:
        """Cycle start ``~``: resume after a feed hold or an M0 pause."""
        self._write(b"~")

    def jog_cancel(self) -> None:
        """0x85: stop a ``$J=`` jog and drop the jogs queued behind it."""
        self._write(b"\x85")

    def override(self, byte: int) -> None:
        """One of grbl's override bytes (0x90-0x9D feed, rapid and spindle; 0x9E-0xA1 toggles)."""
        if not 0x90 <= byte <= 0xA1:
            raise PortError(f"not a grbl override byte: {byte:#04x}")
        self._write(bytes([byte]))

    def halt(self, reason: str, *, hold_wait_s: Optional[float] = None) -> bool:
        """Stop grbl after a fault so that nothing queued before it runs: shut the gate on lines
        (:meth:`cancel`), feed hold ``!`` at once, wait until grbl reports it stands still (at most
        ``hold_wait_s``; by default three times the longest stop its ``$$`` allows, plus a second), then soft
        reset (0x18), which drops every block still queued, and wait for the restart.  Never raises: returns
        True when grbl restarted, False when the link is gone.  The link's fault is cleared (its counts start
        again from the reset); the gate stays shut until :meth:`allow`."""
        self.cancel(reason)
        try:
            self._write(b"!")
        except PortError:
            return False
        if hold_wait_s is None:
            rate = max(self.settings.get(110 + i, 500.0) for i in range(3)) / 60.0
            accel = min(max(1e-3, self.settings.get(120 + i, 10.0)) for i in range(3))
            hold_wait_s = 3.0 * rate / accel + 1.0
        deadline = time.monotonic() + hold_wait_s
        with self._cond:
            seq = self._status_seq
        try:
            while time.monotonic() < deadline:
                self._ask_status()
                with self._cond:
                    self._cond.wait_for(lambda: self._status_seq > seq or self._lost is not None, 0.05)
                    report, fresh = self.status_report, self._status_seq > seq
                    seq = self._status_seq
                if fresh and report is not None and report.state.startswith(("Hold:0", "Idle", "Alarm", "Door:0")):
                    break
            with self._cond:
                self._welcomes = 0
            self._write(b"\x18")
            restarted = self._wait(lambda: self._welcomes > 0, self.timeout_s, check=False)
        except PortError:
            return False
        with self._cond:
            self._welcomes = 0
            self._fault = None
            self._done_errors.clear()
        return restarted


def _is_welcome(line: str) -> bool:
    """The welcome line a board of the grbl family prints at every start and reset: grbl's ``Grbl 1.1h ['$' for
    help]``, grblHAL's ``GrblHAL 1.1f ['$' or '$HELP' for help]``, FluidNC's ``Grbl 3.7 [FluidNC v3.7.8 (wifi)
    '$' for help]``.

    >>> [_is_welcome(t) for t in ("Grbl 1.1h ['$' for help]", "GrblHAL 1.1f ['$' or '$HELP' for help]", "ok")]
    [True, True, False]
    """
    return line.startswith(("Grbl ", "GrblHAL ")) and "for help" in line


class _Replies:
    """The reader side of :class:`GrblLink`: its thread reads grbl's lines and books each one under the link's
    lock (answers against the unanswered lines, status reports, push messages); a reply it cannot make sense of
    is a link fault, never a dead thread."""

    _cond: threading.Condition
    _ser: serial.Serial
    _closing: bool
    _lost: Optional[BaseException]
    _fault: Optional[str]
    _cut_short: Optional[tuple[str, float]]
    _line_bytes_written: int
    _asks: deque
    _ring_bound: Optional[int]
    _ring_base: int
    _connected: bool
    _outstanding: deque
    _outstanding_bytes: int
    _info: list
    _done_errors: list
    _answered_s: deque
    _answer_clock: float
    _expected_resets: int
    _welcomes: int
    _alarm: Optional[int]
    _status_seq: int
    _last_rx: float
    _wco: Optional[tuple[float, ...]]
    _serial_errors: tuple
    device: str
    welcome: str
    messages: list[str]
    status_report: Optional[GrblStatus]
    slowest_override_pct: int
    rx_buffer_bytes: int
    reply_margin_s: float

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _read_loop(self) -> None:
        buf = bytearray()
        while not self._closing:
            try:
                chunk = self._ser.read(max(1, self._ser.in_waiting))
            except self._serial_errors as exc:
                if not self._closing:
                    with self._cond:
                        self._lost = exc
                        self._cond.notify_all()
                return
            except TypeError:   # pyserial after close() from another thread
                return
            if not chunk:
                continue
            buf += chunk
            while True:
                cut = buf.find(b"\n")
                if cut < 0:
                    break
                line = buf[:cut].decode("ascii", "replace").strip()
                del buf[:cut + 1]
                if line:
                    self._on_line(line)

    def _on_line(self, line: str) -> None:
        with self._cond:
            try:
                self._take_line(line)
            except Exception as exc:  # noqa: BLE001 - a reply cam cannot read is a link fault, never a dead reader
                self._set_fault(f"grbl on {self.device} sent {line[:60]!r}, which cam cannot read "
                                f"({type(exc).__name__}: {exc})")
            self._cond.notify_all()

    def _set_fault(self, reason: str) -> None:
        """Book a link fault (under the lock): the first one is kept and raised by every check until a reset."""
        if self._fault is None:
            self._fault = reason
        self._cond.notify_all()

    def _take_line(self, line: str) -> None:
        now = time.monotonic()
        self._last_rx = now
        if self._cut_short is not None:
            cut, self._cut_short = self._cut_short[0], None
            if not _is_welcome(line):  # a welcome next: grbl was reset mid-report, which the welcome tells
                self._set_fault(f"grbl on {self.device} sent a status report cut short ({cut[:60]!r})")
        if line.startswith("<") and not line.endswith(">"):
            self._cut_short = (line, now)  # a reset cuts grbl's output short: wait for the next line
            return
        if line == "ok" or line.startswith("error:"):
            if not self._outstanding:
                if self._connected:
                    self._set_fault(f"grbl on {self.device} answered {line!r} with no line waiting for an answer "
                                    f"(a duplicated or stray reply): its receive buffer can no longer be counted")
                return
            self._answer(line, now)
        elif line.startswith("<"):
            try:
                status = parse_status(line, self._wco)
            except GrblError as exc:
                self._set_fault(f"grbl on {self.device} sent {exc}")
                return
            self._take_status(status, now)
        else:
            self._take_push(line)

    def _answer(self, line: str, now: float) -> None:
        entry = self._outstanding.popleft()
        self._outstanding_bytes -= entry[0]
        entry[3] = line
        entry[4] = self._info
        self._info = []
        self._answered_s.append(entry[6])
        self._answer_clock = now
        if "[MSG:Disabled]" in entry[4]:   # check mode left: grbl resets itself, as documented
            self._expected_resets += 1
        if line != "ok":
            self._done_errors.append(entry)

    def _take_status(self, status: GrblStatus, now: float) -> None:
        self._wco = status.wco_mm
        self.status_report = status
        self._status_seq += 1
        if status.state.startswith(("Hold", "Door", "Tool")):
            self._answer_clock = now  # held by the operator: the queued moves' time stands still
        if status.overrides is not None:
            self.slowest_override_pct = max(1, min(status.overrides[0], status.overrides[1]))
        base = self._asks.popleft()[0] if self._asks else None  # a report answers the oldest ? (or a later one)
        if status.rx_free is None:
            self._ring_bound = None  # no buffer report ($10 without bit 1): the count of answers alone decides
        elif base is not None:
            self._ring_bound, self._ring_base = self.rx_buffer_bytes - status.rx_free, base
        if status.rx_free is not None and self._connected:
            held_bytes = self.rx_buffer_bytes - 1 - status.rx_free  # at least what grbl's receive buffer holds
            if held_bytes > self._outstanding_bytes:
                self._set_fault(f"grbl on {self.device} holds at least {held_bytes} bytes in its receive buffer "
                                f"but cam counted {self._outstanding_bytes} unanswered (a duplicated reply was "
                                f"counted): its receive buffer can no longer be counted")

    def _take_push(self, line: str) -> None:
        if line.startswith("ALARM:"):
            try:
                self._alarm = int(line[6:])
            except ValueError:
                self._alarm = -1
            self.messages.append(line)
        elif _is_welcome(line):
            self.welcome = line
            if self._expected_resets:
                self._expected_resets -= 1
            else:
                self._welcomes += 1
            self._outstanding.clear()   # a reset empties grbl's buffers: nothing sent is pending any more
            self._outstanding_bytes = 0
            self._answered_s.clear()
            self._asks.clear()
            self._ring_bound = None  # until the next buffer report: the reset emptied it
            self._info = []
        else:
            if line.startswith("[MSG:") or line.startswith(">"):
                self.messages.append(line)
            self._info.append(line)

    def _ask_status(self, *, again: bool = False) -> None:
        """Send ``?``, booking how many line bytes went before it: the report that answers it bounds grbl's
        receive buffer (:meth:`_ring_fits`).  One ``?`` at a time (so that grbl never answers two with one
        report), unless ``again`` or the last one went unanswered for :data:`ASK_AGAIN_S`; a report answering
        a later ``?`` than the one it is booked against only makes the bound larger (safe)."""
        with self._cond:
            now = time.monotonic()
            if self._asks and not again and now - self._asks[-1][1] < ASK_AGAIN_S:
                return
            self._asks.append((self._line_bytes_written, now))
            self._write(b"?")

    def _ring_fits(self, n_bytes: int) -> bool:
        """Whether ``n_bytes`` more fit into grbl's receive buffer whatever its answers said (under the lock): the
        last buffer report's bytes plus every line byte written after the ``?`` it answers, plus these, within
        the buffer.  Without a buffer report (``Bf`` off) the count of answers alone decides."""
        if self._ring_bound is None:
            return True
        return self._ring_bound + (self._line_bytes_written - self._ring_base) + n_bytes <= self.rx_buffer_bytes - 1

    def _overdue(self, now: float) -> str:
        """Why the oldest unanswered line's answer is overdue, or "" (under the lock).  grbl answers a line once
        it is planned, so at the latest when the moves queued before it (the last answered lines, no more than
        its planner holds) are done: their time at the slowest override, three times over (a simulated board
        runs slower than a real one), plus :attr:`reply_margin_s`; a hold stops the clock."""
        head = self._outstanding[0]
        since = max(self._answer_clock, head[5])
        queued_s = (sum(self._answered_s) + head[6]) * 100.0 / max(1, self.slowest_override_pct)
        allowed_s = self.reply_margin_s + 3.0 * queued_s
        if now - since <= allowed_s:
            return ""
        what = f"line {head[1]} {head[2]!r}" if head[1] else repr(head[2])
        return (f"grbl on {self.device} has not answered {what} for {now - since:.1f} s, longer than the moves "
                f"queued before it could take ({allowed_s:.1f} s with margin): a reply was lost")


class GrblLink(_Replies, _RealtimeBytes):
    """A grbl 1.1 board on a serial port (see the module docstring).

    Args:
        url: ``grbl:DEVICE?baud=N`` or a bare device path.
        welcome_timeout_s: how long to wait for the welcome line the board prints when the port opens (an
            Arduino resets then) before sending a soft reset to get one.
        timeout_s: how long grbl may stay silent (status polls unanswered) before the link counts as lost.
        poll_s: the status poll period while waiting for grbl.
        read_settings: read ``$$`` once connected.
    """

    def __init__(self, url: str, *, welcome_timeout_s: float = 2.5, timeout_s: float = 5.0, poll_s: float = 0.2,
                 read_settings: bool = True) -> None:
        self.url = url
        self.device, self.baud = parse_grbl_url(url)
        self.timeout_s = float(timeout_s)
        self.poll_s = float(poll_s)
        self.settings: dict[int, float] = {}
        self.identity: Optional[str] = None   # $I: what the board says it is (:meth:`read_identity`)
        self.welcome = ""
        self.messages: list[str] = []          # [MSG:...] and other push messages, in order
        self.status_report: Optional[GrblStatus] = None
        self._cond = threading.Condition()
        self._outstanding: deque[list] = deque()   # [bytes, line number, text, answer or None, info lines]
        self._outstanding_bytes = 0
        self._info: list[str] = []
        self._done_errors: list[list] = []
        self._alarm: Optional[int] = None
        self._welcomes = 0
        self._expected_resets = 0
        self._status_seq = 0
        self._lost: Optional[BaseException] = None
        self._last_rx = time.monotonic()
        self._closing = False
        self._wco: Optional[tuple[float, ...]] = None
        self._cancelled: Optional[str] = None
        self._fault: Optional[str] = None      # a link fault: replies that cannot be right; sticky until a reset
        self._cut_short: Optional[tuple[str, float]] = None  # a status report with no end, and when it came
        self._line_bytes_written = 0            # every line byte written since the link opened
        self._asks: deque[tuple[int, float]] = deque()  # each unanswered ?: line bytes written before it, when
        self._ring_bound: Optional[int] = None  # grbl's receive buffer at the last report (Bf) can hold no more
        self._ring_base = 0                     # ... than this, and every line byte written after its ?
        self._connected = False                 # the welcome came: from here on every reply is counted
        self.rx_buffer_bytes = RX_BUFFER_BYTES  # the board's receive buffer and planner (its $I [OPT:] when it says)
        self.planner_blocks = PLANNER_BLOCKS
        self._answered_s: deque[float] = deque(maxlen=PLANNER_BLOCKS + 2)  # machine time of the last answers
        self._answer_clock = time.monotonic()   # the last answer (or a hold, which stops the clock)
        self.reply_margin_s = max(10.0, 2.0 * self.timeout_s)
        self.slowest_override_pct = 100         # the lowest of grbl's feed and rapid overrides, percent
        self._timer: Optional[LineTimer] = None
        self.reset_on_open = False   # the welcome came by itself when the port opened: grbl restarted (power-up)
        self._serial_errors = (serial.SerialException, OSError)
        try:
            self._ser = serial.Serial(self.device, baudrate=self.baud, bytesize=8, parity="N", stopbits=1,
                                      timeout=0.05, write_timeout=self.timeout_s)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortError(f"cannot open grbl port {self.device}: {exc}") from None
        self._reader = threading.Thread(target=self._read_loop, name="grbl-link-reader", daemon=True)
        self._reader.start()
        try:
            self._connect(welcome_timeout_s)
            if read_settings:
                self.read_settings()
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ connection
    def _connect(self, welcome_timeout_s: float) -> None:
        self.reset_on_open = self._wait(lambda: self._welcomes > 0, welcome_timeout_s, check=False)
        if not self.reset_on_open:
            self._write(b"\x18")
            if not self._wait(lambda: self._welcomes > 0, self.timeout_s, check=False):
                self._raise_if_lost()
                raise PortError(f"no grbl on {self.device}: no welcome line within "
                                f"{welcome_timeout_s + self.timeout_s:g} s, even after a soft reset "
                                f"(is it grbl 1.1 at {self.baud} baud?)")
        with self._cond:
            self._welcomes = 0
            self._connected = True

    def close(self) -> None:
        """Close the port (grbl keeps running whatever it has queued)."""
        self._closing = True
        try:
            self._ser.close()
        except self._serial_errors:
            pass
        if self._reader.is_alive() and self._reader is not threading.current_thread():
            self._reader.join(timeout=1.0)

    def __enter__(self) -> "GrblLink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ helpers
    def _write(self, data: bytes) -> None:
        self._raise_if_lost()
        try:
            self._ser.write(data)
        except self._serial_errors as exc:
            raise PortError(f"grbl link on {self.device} lost: {exc}") from None

    def _raise_if_lost(self) -> None:
        if self._lost is not None:
            raise PortError(f"grbl link on {self.device} lost: {self._lost}") from None

    def _check(self, where: str = "") -> None:
        """Raise the first fault seen: a lost link, a cancelled stream, an alarm, a reset grbl did on its own, a
        refused line."""
        self._raise_if_lost()
        if self._cut_short is not None and time.monotonic() - self._cut_short[1] > CUT_SHORT_S:
            self._set_fault(f"grbl on {self.device} sent a status report cut short ({self._cut_short[0][:60]!r})")
            self._cut_short = None
        if self._fault is not None:
            raise GrblError(self._fault)
        if self._cancelled is not None:
            raise PortError(self._cancelled)
        if self._alarm is not None:
            code, self._alarm = self._alarm, None
            raise GrblAlarm(f"grbl on {self.device} raised {alarm_text(code)}{where}", code)
        if self._welcomes:
            self._welcomes = 0
            raise GrblError(f"grbl on {self.device} reset itself{where} (its buffers and the job are lost)")
        if self._done_errors:
            entry = self._done_errors.pop(0)
            self._done_errors.clear()
            code = int(entry[3][6:]) if entry[3][6:].isdigit() else -1
            what = f"line {entry[1]} {entry[2]!r}" if entry[1] else repr(entry[2])
            raise GrblError(f"grbl refused {what}: {error_text(code)}", code)

    def _wait(self, predicate: Callable[[], bool], timeout_s: Optional[float], *, check: bool = True,
              where: str = "", quiet_ok: bool = False, poll_s: Optional[float] = None) -> bool:
        """Wait for ``predicate`` (under the lock), polling ``?`` (every ``poll_s``, default :attr:`poll_s`) so that
        a silent grbl is found out (unless ``quiet_ok``: grbl answers no status report while homing)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        next_poll = time.monotonic() + (poll_s or self.poll_s)
        with self._cond:
            while True:
                if check:
                    self._check(where)
                else:
                    self._raise_if_lost()
                if predicate():
                    return True
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    return False
                if check and not quiet_ok and now - self._last_rx > self.timeout_s:
                    raise PortError(f"grbl on {self.device} stopped answering (nothing for {self.timeout_s:g} s, "
                                    f"status polls included){where}")
                if check and self._outstanding:
                    overdue = self._overdue(now)
                    if overdue:
                        self._set_fault(overdue)
                        continue
                if check and now >= next_poll:
                    self._ask_status()
                    next_poll = now + (poll_s or self.poll_s)
                wake = next_poll if deadline is None else min(next_poll, deadline)
                self._cond.wait(max(0.001, wake - now))

    # ------------------------------------------------------------------ lines
    def _send_line(self, text: str, number: int) -> list:
        label = f"line {number}" if number else "command"
        bad = next((ch for ch in text if ch in "?!~" or not " " <= ch < "\x7f"), None)
        if bad is not None:
            raise GrblError(f"{label} {text[:40]!r} holds {bad!r}, which grbl would take as a real-time command "
                            f"or cannot read (ASCII only)")
        data = (text + "\n").encode("ascii")
        if len(data) > self.rx_buffer_bytes:
            raise GrblError(f"{label} is {len(data)} bytes, more than grbl's {self.rx_buffer_bytes}-byte "
                            f"receive buffer: {text[:40]!r}")
        where = f" at {label} {text!r}"
        self._wait(lambda: self._outstanding_bytes + len(data) <= self.rx_buffer_bytes and self._ring_fits(len(data)),
                   None, where=where, poll_s=RING_POLL_S)
        if self._timer is None:
            self._timer = LineTimer(self.settings)
        entry = [len(data), number, text, None, [], time.monotonic(), self._timer.time_s(text)]
        with self._cond:
            if self._cancelled is not None:  # cancelled while it waited: the gate is shut
                raise PortError(self._cancelled)
            if not self._outstanding:
                self._answer_clock = entry[5]
            self._outstanding.append(entry)
            self._outstanding_bytes += len(data)
            self._line_bytes_written += len(data)
            self._write(data)  # under the lock: a cancel cannot slip between the check and the write
        return entry

    def command(self, line: str, timeout_s: Optional[float] = None) -> list[str]:
        """Send one line, wait for its ``ok`` and return the lines grbl pushed before it (``$#``, ``$G``...)."""
        text = line.strip()
        entry = self._send_line(text, 0)
        self._wait(lambda: entry[3] is not None, timeout_s, where=f" answering {text!r}", quiet_ok=text == "$H")
        if entry[3] is None:
            raise PortError(f"grbl on {self.device} did not answer {line.strip()!r} within {timeout_s:g} s")
        return list(entry[4])

    def read_identity(self) -> Optional[str]:
        """``$I`` into :attr:`identity`: the board's own word of what it is, ``"[VER:1.1h.20190830:NAME]
        [OPT:V,15,128]"`` (grbl's version and build date, the build info ``NAME`` that ``$I=NAME`` sets, and its
        compile options), or None when it answers no ``[VER:`` line or refuses ``$I`` (then nothing tells this
        board from another)."""
        try:
            lines = self.command("$I", timeout_s=self.timeout_s)
        except GrblError as exc:
            if isinstance(exc, GrblAlarm) or exc.code is None:
                raise
            lines = []  # refused (error:n): a board with no $I
        self.identity = parse_identity(lines)
        sizes = parse_buffer_sizes(self.identity)
        if sizes is not None:  # stream to the board's own sizes (grblHAL's 1024 bytes, not grbl's 128)
            with self._cond:
                self.planner_blocks, self.rx_buffer_bytes = sizes
                self._answered_s = deque(self._answered_s, maxlen=self.planner_blocks + 2)
        return self.identity

    def read_settings(self) -> dict[int, float]:
        """``$$`` into :attr:`settings` (``{100: 250.0, ...}``)."""
        self.settings = parse_settings(self.command("$$", timeout_s=self.timeout_s), self.device)
        self._timer = LineTimer(self.settings)
        return self.settings

    def stream(self, lines: Iterable[str], *, progress: Optional[Callable[[int], None]] = None,
               wait_idle: bool = True) -> StreamReport:
        """Stream G-code lines with character counting; return when grbl has answered every one (and, with
        ``wait_idle``, the machine has stopped).  Comments are dropped (grbl would drop them, and a ``?``, ``!``
        or ``~`` in one would act as a real-time command), blank lines skipped; line numbers in errors count
        every line given, from 1."""
        sent = total = peak = 0
        for number, raw in enumerate(lines, 1):
            text = strip_comments(raw)
            if not text:
                continue
            self._send_line(text, number)
            sent += 1
            total += len(text) + 1
            with self._cond:
                peak = max(peak, self._outstanding_bytes)
                self._check(f" at line {number} {text!r}")
            if progress is not None:
                progress(number)
        self._wait(lambda: not self._outstanding, None, where=" at the end of the stream")
        if wait_idle:
            self.wait_idle()
        return StreamReport(sent, total, peak)

    def wait_idle(self, timeout_s: Optional[float] = None) -> GrblStatus:
        """Poll ``?`` until grbl reports Idle (every queued motion done; ``Check`` in check mode)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            status = self.status()
            if status.state in ("Idle", "Check"):
                return status
            if status.state in ("Alarm", "Sleep"):
                raise GrblAlarm(f"grbl on {self.device} is in the {status.state} state, not running the job "
                                f"(unlock with $X or home with $H)")
            if deadline is not None and time.monotonic() > deadline:
                raise PortError(f"grbl on {self.device} still {status.state} after {timeout_s:g} s")
            time.sleep(self.poll_s / 2)

    # ------------------------------------------------------------------ real-time
    def status(self, timeout_s: Optional[float] = None) -> GrblStatus:
        """Send ``?`` and return the report that answers it."""
        with self._cond:
            self._check()
            if self._asks:  # a ? already on its way: its report may be older than this call; ask anew after it
                seq = self._status_seq
                self._wait(lambda: self._status_seq > seq, min(self.timeout_s, ASK_AGAIN_S))
            seq = self._status_seq
            self._ask_status(again=True)
        ok = self._wait(lambda: self._status_seq > seq, timeout_s if timeout_s is not None else self.timeout_s)
        if not ok or self.status_report is None:
            raise PortError(f"grbl on {self.device} sent no status report")
        return self.status_report

    def soft_reset(self, timeout_s: Optional[float] = None) -> str:
        """Ctrl-X: grbl stops at once (``ALARM:3`` if it was moving) and restarts; returns the welcome line.
        An alarm the reset raises is kept in :attr:`messages`, not raised."""
        with self._cond:
            self._welcomes = 0
            self._done_errors.clear()
        self._write(b"\x18")
        if not self._wait(lambda: self._welcomes > 0, timeout_s or self.timeout_s, check=False):
            raise PortError(f"grbl on {self.device} did not restart after a soft reset")
        with self._cond:
            self._welcomes = 0
            self._alarm = None
            self._fault = None  # the reset emptied grbl's buffers: the counts start again
        return self.welcome

    @property
    def alarm_pending(self) -> Optional[int]:
        """The code of an ``ALARM:n`` seen and not raised yet, or None."""
        return self._alarm

    def unlock(self) -> None:
        """``$X``: leave the alarm state."""
        self.command("$X", timeout_s=self.timeout_s)


def open_grbl(url: str, **options: object) -> GrblLink:
    """Open ``grbl:DEVICE?baud=N`` (keyword arguments: :class:`GrblLink`'s)."""
    return GrblLink(url, **options)  # type: ignore[arg-type]
