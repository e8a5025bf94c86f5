"""A grbl board as the machine session drives it: ``--port grbl:/dev/ttyUSB0`` (issue #30 point 2).

One :class:`GrblMachine` a device per process (:func:`grbl_machine`), shared by every session that opens the
port: opening the port again would reset an Arduino (it resets when the host raises DTR), and grbl would lose
its position.  The machine keeps the link (:class:`~cam.drive.grbl_link.GrblLink`) open, polls ``?`` about
7 times a second (:data:`POLL_S`), and gives the session:

* **where the tool is**, read back from grbl's ``MPos``, never counted: ``cam``'s machine steps are
  ``(X / mm_per_step_xy, -Y / mm_per_step_xy, -Z / mm_per_step_z) + base_steps`` (grbl's Y and Z grow away from
  the operator and upward; ``cam``'s toward the operator and deeper, :mod:`cam.job.model`).  After ``$H`` in
  this process, or when a homed machine's state file meets a grbl that did not restart when the port opened,
  ``base_steps`` is 0: ``cam``'s machine frame is grbl's, whose zero is the homing corner (the machine file's
  travel then lies at negative X, e.g. ``x_min_steps = -10380``, ``x_max_steps = 0``).  Otherwise grbl's
  zero is its power-up point, and the base makes ``MPos`` agree with the state file's record of where the tool
  stands (the session's ``set_position``).
* **jobs and moves as G-code** (:func:`job_lines`): each point of any job (drawing, matrix, drill file,
  HPGL, SVG, G-code program, jog, go-to) becomes an absolute machine-frame line ``G53 G1 X.. Y.. Z.. F..``
  (``G53 G0`` for lifts and travels), runs of moves in one direction at one feed joined into one line; the
  feed is the one the job asks (its step periods, as the step/dir runner would take it).  ``G53`` makes the
  lines independent of whatever work offset or ``G92`` grbl holds.  Streamed with character counting; a
  pause of the job (a tool change, a Pause At) waits for grbl to stand still, then prompts.
* **controls** (:class:`GrblControl`): pause = feed hold ``!``, resume = cycle start ``~``, stop = feed hold,
  then a soft reset (0x18) once grbl stands still (position kept), then ``$X`` when grbl asks for it;
  emergency stop = soft reset at once (grbl then raises ``ALARM:3`` if it was moving: the position is lost);
  feed override through grbl's real-time bytes (:meth:`GrblMachine.feed_override`).
* **work offsets** mirrored to grbl (``G10 L20 P<n>``, ``G54``-``G59``) so its own display agrees.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterator, Optional

import numpy as np

from ..errors import CamError, PlanError, PortError
from ..kinds.gcode_export import format_mm
from ..job.model import CUT
from ..settings import MachineSettings, Travel
from ..values import FEED_OVERRIDE_RANGE
from .runner import EMERGENCY_STOPPED, FINISHED, STOPPED
from .grbl_journal import GrblJournal, GrblLines, Seen, on_path_tolerance_steps
from .grbl_link import GrblLink, GrblStatus, alarm_text, open_grbl, parse_grbl_url, settings_mismatches
from .journal import JournalSpec, journal_state_of

__all__ = ["GrblMachine", "GrblControl", "GrblPause", "GrblPosition", "adopt_position", "fault_stop", "run_on_grbl", "grbl_machine", "close_grbl_machines", "job_lines",
           "mpos_to_steps", "steps_to_mpos", "grbl_travel", "travel_advice", "override_bytes", "POLL_S", "GRBL_OFFSETS"]

ERROR = "error"
POLL_S = 0.15
"""Seconds between ``?`` status polls (about 7 a second: issue #30 asks for 5-10 Hz)."""
GRBL_OFFSETS = ("G54", "G55", "G56", "G57", "G58", "G59")
"""The work offsets grbl has (no G59.1-G59.3: grbl's error 29)."""

Steps3 = tuple[int, int, int]


def mpos_to_steps(mpos_mm: Any, settings: MachineSettings) -> Steps3:
    """grbl's machine position (mm; X, Y, Z) as ``cam``'s machine steps before the base (+Y toward the operator,
    +Z deeper: grbl's Y and Z change sign)."""
    x, y, z = (float(v) for v in mpos_mm[:3])
    return (int(round(x / settings.mm_per_step_xy)), int(round(-y / settings.mm_per_step_xy)),
            int(round(-z / settings.mm_per_step_z)))


def steps_to_mpos(steps: Any, settings: MachineSettings) -> tuple[float, float, float]:
    """``cam``'s machine steps (before the base) as grbl's machine position in mm."""
    return (int(steps[0]) * settings.mm_per_step_xy, -int(steps[1]) * settings.mm_per_step_xy,
            -int(steps[2]) * settings.mm_per_step_z)


def grbl_travel(grbl: dict[int, float], settings: MachineSettings) -> Travel:
    """The machine file's travel that matches grbl's machine space ``[-$13x, 0]`` mm on each axis (grbl's
    machine zero is the homing corner, the space lies on the negative side whatever ``$23`` says): in
    ``cam``'s frame X from ``-$130`` to 0, Y from 0 to ``$131`` (toward the operator), Z from 0 to ``$132``
    (deeper), in steps.

    >>> t = grbl_travel({130: 300.0, 131: 200.0, 132: 50.0}, MachineSettings())
    >>> t.x_min_steps, t.y_max_steps, t.z_max_steps
    (-10380, 6920, 3184)
    """
    x, y, z = (float(grbl.get(130 + i, 0.0)) for i in range(3))
    return Travel(x_min_steps=-int(x / settings.mm_per_step_xy), x_max_steps=0, y_min_steps=0,
                  y_max_steps=int(y / settings.mm_per_step_xy), z_min_steps=0,
                  z_max_steps=int(z / settings.mm_per_step_z))


def travel_advice(grbl: dict[int, float], settings: MachineSettings) -> str:
    """The ``[travel]`` lines of the machine file for grbl's machine space (see :func:`grbl_travel`)."""
    t = grbl_travel(grbl, settings)
    return (f"[travel] x_min_steps = {t.x_min_steps}, x_max_steps = 0, y_min_steps = 0, y_max_steps = "
            f"{t.y_max_steps}, z_min_steps = 0, z_max_steps = {t.z_max_steps}")


@dataclass(frozen=True)
class GrblPause:
    """Where a job waits for the operator: after point ``index`` (0-based), ``position_steps`` from the job's
    start, for ``note`` (a tool change, a Pause At)."""

    index: int
    position_steps: Steps3
    note: str


def _default_period_ns(d: np.ndarray, settings: MachineSettings) -> int:
    xy, z = bool(d[0] or d[1]), bool(d[2])
    if xy and z:
        return int(max(settings.delay_xy_ns, settings.delay_z_ns))
    return int(settings.delay_z_ns if z else settings.delay_xy_ns)


PATH_TOLERANCE_STEPS = 1.0
"""How far (steps) a point of the job may lie from the straight line grbl is sent for it: the job's points are
the nearest steps to its path (a line at a slope is a staircase of them, each within half a step of the path on each
axis), so grbl gets the path, not the steps."""
RUN_POINTS = 1024
"""The most job points one line stands for (a bound on the work of checking a run)."""


class _Runs:
    """Joins consecutive points of a job into straight lines: one run is points of one kind (cut or not) and one
    nominal step period (a G-code move's feed, a drawing's step delay), every point within
    :data:`PATH_TOLERANCE_STEPS` of the line from the run's start to its end."""

    def __init__(self, settings: MachineSettings) -> None:
        self.scale_mm = np.array([settings.mm_per_step_xy, settings.mm_per_step_xy, settings.mm_per_step_z])
        self.start = np.zeros(3, np.int64)
        self.points = np.zeros((RUN_POINTS, 3), np.int64)
        self.count = 0
        self.rapid = False
        self.period_ns = 0
        self.time_ns = 0
        self.last_index = -1

    def fits(self, p: np.ndarray, rapid: bool, period_ns: int) -> bool:
        if self.count == 0:
            return True
        if rapid != self.rapid or period_ns != self.period_ns or self.count >= RUN_POINTS:
            return False
        chord = (p - self.start).astype(np.float64)
        inner = self.points[:self.count].astype(np.float64) - self.start
        length2 = float(chord @ chord)
        t = np.clip(inner @ chord / length2, 0.0, 1.0) if length2 else np.zeros(self.count)
        off = inner - t[:, None] * chord
        return float(np.max(np.einsum("ij,ij->i", off, off))) <= PATH_TOLERANCE_STEPS ** 2

    def add(self, p: np.ndarray, rapid: bool, period_ns: int, time_ns: int, index: int) -> None:
        if self.count == 0:
            self.rapid, self.period_ns, self.time_ns = rapid, period_ns, 0
        self.points[self.count] = p
        self.count += 1
        self.time_ns += time_ns
        self.last_index = index

    def take(self) -> tuple[np.ndarray, bool, float, int, int]:
        """The run as (end point, rapid, length mm, time ns, index of its last point); a new run starts at its
        end."""
        end = self.points[self.count - 1].copy()
        length_mm = float(np.linalg.norm((end - self.start) * self.scale_mm))
        self.start, self.count = end, 0
        return end, self.rapid, length_mm, self.time_ns, self.last_index


def job_lines(job: Any, start_steps: Steps3, base_steps: Steps3, settings: MachineSettings,
              on_point: Optional[Callable[[int], None]] = None,
              on_line: Optional[Callable[[np.ndarray, int], None]] = None,
              shift_steps: Optional[np.ndarray] = None) -> Iterator["str | GrblPause"]:
    """The G-code lines that move grbl through ``job`` (any :class:`~cam.job.model.JobLike`), a piece at a time.

    Args:
        job: points in steps relative to where the tool stands at the start (``start_steps``, ``cam``'s
            machine frame); each point's time from its ``period_ns``/``periods`` (else the step delays).
        base_steps: ``cam``'s machine steps of grbl's machine zero (see the module docstring).
        on_point: told the index of the last point a yielded line reaches (progress).
        on_line: told each line's end (``(3,)`` steps from ``start_steps``) and the index of the last point it
            reaches, before the line is yielded (the journal, :class:`~cam.drive.grbl_journal.GrblLines`).
        shift_steps: a ``(3,)`` int64 array the caller may change while the job waits at a pause (a tool probed
            at a tool change: the work Z shifted): every line drawn after that lands shifted by it, as if the job
            had started ``shift_steps`` from ``start_steps`` (None: no shift).

    Yields:
        ``"G53G1X..Y..Z..F.."`` lines (no spaces: fewer bytes on the link) and a :class:`GrblPause` after each
        point the job pauses at.  Moves are joined into the straight lines of the job's path (:class:`_Runs`):
        a G-code program's line goes out as one line at its own feed, not as the staircase of steps it is
        planned into for a step/dir drive.  The first feed move after a pause says its feed again: whatever ran
        at the pause (a probe's ``G38.2 F..``, grbl's soft reset after a probe fail) may have changed grbl's.
    """
    origin = np.asarray(start_steps, np.int64) - np.asarray(base_steps, np.int64)  # grbl frame, in steps
    prev = np.zeros(3, np.int64)
    written = [None, None, None]  # the axis values written last (mm text)
    runs = _Runs(settings)
    move: list[tuple[np.ndarray, bool, float, int, int]] = []  # the lines of the job's move being joined
    feed_now: Optional[float] = None
    index = -1

    def text(end: np.ndarray, rapid: bool, feed: float) -> str:
        nonlocal feed_now
        mm = steps_to_mpos(origin + end if shift_steps is None else origin + end + shift_steps, settings)
        words = "".join(f"{a}{t}" for a, t, w in zip("XYZ", (format_mm(v) for v in mm), written) if t != w)
        for i, t in enumerate(format_mm(v) for v in mm):
            written[i] = t
        if rapid:
            return f"G53G0{words}"
        out = f"G53G1{words}"
        if feed != feed_now:
            feed_now = feed
            out += f"F{format_mm(feed)}"
        return out

    def close_run() -> None:
        if runs.count:
            move.append(runs.take())

    def lines_of_move() -> Iterator[str]:
        """The move's lines at one feed: its length over its time (a move of the source, e.g. one G-code line
        or arc, keeps its own feed whatever staircase of steps it was planned into; in a job that marks no
        moves, each line is one: its length over its points' time, as a step/dir drive runs it)."""
        close_run()
        length_mm = sum(m[2] for m in move)
        time_ns = sum(m[3] for m in move)
        feed = round(length_mm / max(1e-9, time_ns * 1e-9) * 60.0, 1)
        for end, rapid, _, _, last in move:
            if on_line is not None:
                on_line(end, last)
            yield text(end, rapid, 0.0 if rapid else feed)
            if on_point is not None:
                on_point(last)
        move.clear()

    for piece in job.pieces():
        pts = np.asarray(piece.points_steps, np.int64).reshape(-1, 3)
        kinds = np.asarray(piece.kind).tolist()
        pauses = np.asarray(piece.pause, bool).tolist()
        notes = list(piece.pause_notes) if piece.pause_notes is not None else []
        period_ns = None if piece.period_ns is None else np.asarray(piece.period_ns).tolist()
        periods = None if piece.periods is None else np.asarray(piece.periods).tolist()
        starts = None if piece.move_start is None else np.asarray(piece.move_start, bool).tolist()
        for k in range(len(pts)):
            index += 1
            p = pts[k]
            d = p - prev
            prev = p
            if d.any():
                rapid = kinds[k] != CUT
                n = periods[k] if periods is not None else int(np.abs(d).max())
                per = int(period_ns[k]) if period_ns is not None else _default_period_ns(d, settings)
                if (starts is not None and starts[k]) or (move and (rapid != move[0][1] or len(move) >= RUN_POINTS)):
                    yield from lines_of_move()
                elif not runs.fits(p, rapid, per):
                    close_run()
                    if starts is None:  # a job that marks no moves: each line its own feed
                        yield from lines_of_move()
                runs.add(p, rapid, per, max(1, int(n)) * per, index)
            if pauses[k]:
                yield from lines_of_move()
                if on_point is not None:
                    on_point(index)
                note = notes.pop(0) if notes else "Pause At"
                yield GrblPause(index, (int(p[0]), int(p[1]), int(p[2])), note)
                feed_now = None  # grbl's modal feed may have changed at the pause: the next feed move says it
    yield from lines_of_move()
    if on_point is not None:
        on_point(index)


def override_bytes(want_pct: int) -> bytes:
    """grbl's feed override bytes that set the override to ``want_pct``: 0x90 (100 %), then
    +/-10 % (0x91/0x92) and +/-1 % (0x93/0x94) steps (grbl's interface.md, "Real-time commands").

    >>> override_bytes(125).hex()
    '9091919393939393'
    >>> override_bytes(80).hex()
    '909292'
    """
    lo, hi = FEED_OVERRIDE_RANGE
    if not lo <= want_pct <= hi:
        raise PlanError(f"feed override must be {lo}..{hi} %, got {want_pct}")
    out = bytearray([0x90])  # from 100 %: grbl's own value is never guessed from the bytes sent before
    diff = want_pct - 100
    out += bytes([0x91 if diff > 0 else 0x92]) * (abs(diff) // 10)
    out += bytes([0x93 if diff > 0 else 0x94]) * (abs(diff) % 10)
    return bytes(out)


class GrblMachine:
    """One grbl board, its link kept open and polled (see the module docstring; use :func:`grbl_machine`).

    Args:
        url: ``grbl:DEVICE?baud=N``.
        settings: the machine file's settings (grbl's ``$$`` is compared with them once).
        link: an open :class:`GrblLink` (tests); None: opened from ``url``.
    """

    def __init__(self, url: str, settings: MachineSettings, link: Optional[GrblLink] = None) -> None:
        self.url = url
        self.settings = settings
        self.link = link if link is not None else open_grbl(url)
        self.identity: Optional[str] = self.link.read_identity()
        """What the board says it is (``$I``; None: it cannot say): the state file records it, and another board
        on the port makes the position unknown (:func:`adopt_position`)."""
        self.base_steps: Steps3 = (0, 0, 0)
        self.homed_here = False  # $H finished on this link: grbl's frame is the machine frame (base 0)
        self.feed_override_pct = 100
        self._closing = threading.Event()
        mismatch = settings_mismatches(self.link.settings, settings)
        self.warned = False
        self.warning = (f"grbl's settings differ from the machine file: {'; '.join(mismatch)}"
                        if mismatch else "")
        self.notice = self._buffer_report_on()
        self.status()
        self._poller = threading.Thread(target=self._poll, name="grbl-poll", daemon=True)
        self._poller.start()

    def _buffer_report_on(self) -> str:
        """Turn on grbl's buffer report (``$10`` bit 1: ``Bf:planner blocks,rx bytes`` in every status report)
        when it is off, keeping the position bit: each report then checks cam's count of grbl's receive buffer
        (a duplicated ``ok`` counted as credit is found at the next report, :class:`GrblLink`).  Returns what was
        changed, for the log ("" when it was on already or grbl has no ``$10``)."""
        mask = self.link.settings.get(10)
        if mask is None or int(mask) & 2:
            return ""
        new_mask = int(mask) | 2
        self.link.command(f"$10={new_mask}", timeout_s=self.link.timeout_s)
        self.link.settings[10] = float(new_mask)
        return (f"cam turned on grbl's buffer report ($10={int(mask)} -> {new_mask}, kept in its EEPROM): each "
                f"status report checks cam's count of grbl's receive buffer")

    def _poll(self) -> None:
        while not self._closing.wait(POLL_S):
            try:
                self.link._ask_status()
            except PortError:
                return

    def close(self) -> None:
        """Stop polling and close the link (the poller first: a ``?`` it was writing as the link closed failed
        in pyserial with a TypeError on the closed file)."""
        self._closing.set()
        if self._poller is not threading.current_thread():
            self._poller.join(POLL_S + 1.0)
        self.link.close()

    @property
    def lost(self) -> bool:
        """The link broke (unplugged, closed): a new :class:`GrblMachine` is needed."""
        return self.link._lost is not None or self._closing.is_set()

    def status(self) -> GrblStatus:
        """A fresh ``?`` report."""
        return self.link.status()

    def last_status(self) -> Optional[GrblStatus]:
        """The latest report the poller got (no waiting)."""
        return self.link.status_report

    def position_steps(self, status: Optional[GrblStatus] = None) -> Steps3:
        """Where the tool is in ``cam``'s machine steps, from grbl's latest ``MPos``."""
        st = status or self.last_status() or self.status()
        raw = mpos_to_steps(st.mpos_mm, self.settings)
        return tuple(int(r) + int(b) for r, b in zip(raw, self.base_steps))  # type: ignore[return-value]

    def rebase(self, position_steps: Any) -> None:
        """Say where the tool stands now in ``cam``'s machine frame (grbl's zero is not the machine's)."""
        raw = mpos_to_steps(self.status().mpos_mm, self.settings)
        self.base_steps = tuple(int(p) - int(r) for p, r in zip(position_steps, raw))  # type: ignore[assignment]
        self.homed_here = False

    def in_alarm(self) -> Optional[str]:
        """Why grbl refuses motion now (its Alarm state), or None."""
        st = self.status()
        return f"grbl on {self.link.device} is in the Alarm state" if st.state.startswith("Alarm") else None

    def home(self) -> Steps3:
        """``$H``: grbl's homing cycle; its machine frame is then the machine's (base 0).  Returns the position."""
        self.link.allow()
        self.link.command("$H", timeout_s=None)
        self.base_steps, self.homed_here = (0, 0, 0), True
        return self.position_steps(self.link.wait_idle())

    def unlock(self) -> None:
        """``$X``: leave grbl's alarm state (the user says where the tool is)."""
        self.link.allow()
        self.link.unlock()

    def set_work_zero(self, offset: str, axes: str) -> None:
        """``G10 L20 P<n>``: grbl's own work offset ``offset`` (G54-G59) zero of ``axes`` where the tool stands."""
        if offset not in GRBL_OFFSETS:
            raise CamError(f"grbl has work offsets {', '.join(GRBL_OFFSETS)} only, not {offset}")
        words = "".join(f"{a}0" for a in axes.upper())
        self.link.allow()
        self.link.command(f"G10 L20 P{GRBL_OFFSETS.index(offset) + 1} {words}")

    def use_offset(self, offset: str) -> None:
        """Make ``offset`` grbl's active work offset."""
        if offset not in GRBL_OFFSETS:
            raise CamError(f"grbl has work offsets {', '.join(GRBL_OFFSETS)} only, not {offset}")
        self.link.allow()
        self.link.command(offset)

    def feed_override(self, percent: int) -> None:
        """Set grbl's feed override to ``percent`` (10..200) with its real-time override bytes."""
        data = override_bytes(int(percent))
        for b in data:
            self.link.override(b)
        self.feed_override_pct = int(percent)
        self.link.slowest_override_pct = min(self.link.slowest_override_pct, int(percent))


class GrblControl:
    """Pause / stop controls of an activity on a grbl board (the :class:`~cam.drive.runner.Controller` of
    step/dir ports): see the module docstring for what each sends."""

    def __init__(self, machine: GrblMachine, *, stop_resets: bool = False) -> None:
        self.machine = machine
        self.stop_resets = stop_resets  # homing: grbl holds no homing cycle, a stop is a reset
        self.paused = False
        self.halted = False
        self.estopped = False

    def pause(self) -> None:
        self.machine.link.hold()
        self.paused = True

    def resume(self) -> None:
        self.machine.link.resume()
        self.paused = False

    def stop(self) -> None:
        """Feed hold now; the worker resets grbl once it stands still (:func:`finish_stop`)."""
        if self.halted:
            return
        if self.stop_resets:
            self.emergency_stop()
            return
        self.halted = True
        self.machine.link.hold()
        self.machine.link.cancel("stopped")

    def emergency_stop(self) -> None:
        """Soft reset at once: grbl drops everything queued and stops its steps."""
        self.halted = self.estopped = True
        self.machine.link.cancel("emergency stop")
        try:
            self.machine.link._write(b"\x18")
        except PortError:
            pass


def finish_stop(machine: GrblMachine, ctl: GrblControl, timeout_s: float = 30.0) -> str:
    """After a stop or an emergency stop: wait for grbl to stand still, reset it (a stop: only once still, so
    it keeps its position), unlock it where it asks; returns what happened to the position ("" = kept)."""
    link = machine.link
    link.allow()  # the stream has ended (this is its worker): status polls and the reset may go out
    if not ctl.estopped:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:  # fresh reports only: one from before the hold may say Idle
            try:
                if link.status().state in ("Hold:0", "Idle", "Alarm", "Check"):
                    break
            except CamError:  # an alarm or a refused line of the cancelled stream: still wait for the stop
                pass
            time.sleep(POLL_S / 3)
        link.soft_reset()
    else:
        link.soft_reset()  # the 0x18 already went; this one finds grbl restarted (or restarts it)
    lost = ""
    alarm = link.alarm_pending
    st = link.status()
    if alarm is not None or st.state.startswith("Alarm"):
        lost = alarm_text(alarm) if alarm is not None else "grbl is in alarm"
        if alarm == 3 or ctl.estopped:
            return f"{lost}: grbl was reset while moving, its position may be lost"
        link.allow()
        link.unlock()
    return ""


def fault_stop(machine: GrblMachine, error: str) -> str:
    """After any fault of an activity on grbl (a refused line, an alarm, a lost or unexpected reply, a reply
    overdue, a report cam cannot read, a reset, a cable pulled): stop the machine before anything else, feed
    hold and then a soft reset (:meth:`~cam.drive.grbl_link.GrblLink.halt`), so that no block queued before the
    fault runs.  Returns the one line that says what happened; the position is then unknown."""
    restarted = machine.link.halt(error)
    if restarted:
        machine.link.allow()  # the stream has ended: status reports may be read again for the booking
    done = ("cam sent a feed hold and a soft reset, so nothing queued after it ran" if restarted else
            "cam could not reach grbl to stop it: check the machine")
    return f"{error}; {done}; the position is unknown until Home or Set position"


def adopt_position(machine: GrblMachine, hold: Any, log: Callable[[str, str], None]) -> Steps3:
    """Where the tool stands when a session opens on grbl, in ``cam``'s machine steps, and the state file
    (``hold``, a :class:`~cam.drive.state.StateHold`, or None) told so.

    * grbl homed by ``$H`` on this link, or a homed state file and a grbl that did not restart when the port
      opened (so it still holds its homed frame): grbl's machine position, as it reports it.
    * grbl in the Alarm state (homing enabled and not homed since it started, or after a limit): the position
      is unknown until ``cam home`` (or ``cam where --set``, which unlocks grbl where the tool stands).
    * otherwise grbl's zero is where it started: the state file's position (else the session's home, here)
      is where the tool stands, and grbl's ``MPos`` is read from there on.

    First of all the board's ``$I`` (:attr:`GrblMachine.identity`) is held against the one the state file
    records (:meth:`~cam.drive.state.StateHold.bind_board`): another board on the port (one that says another
    ``$I``) makes the position unknown, logged in one line naming both (issue #44 point 5).
    """
    if hold is not None:
        changed = hold.bind_board(machine.identity, machine.link.device)
        if changed:
            log(changed, "warning")
    st = hold.state if hold is not None else None
    status = machine.status()
    if machine.homed_here or (st is not None and st.homed and st.position_known
                              and not machine.link.reset_on_open and not status.state.startswith("Alarm")):
        machine.base_steps, machine.homed_here = (0, 0, 0), True
        pos = machine.position_steps(status)
        if hold is not None:
            hold.record(replace(st.moved_to(pos), homed=True))
        return pos
    if status.state.startswith("Alarm"):
        reason = (f"grbl on {machine.link.device} is in the Alarm state (homing enabled and not homed since it "
                  f"started, or a limit): home it (cam home), or say where the tool is (cam where --set X,Y,Z)")
        log(reason, "warning")
        if hold is not None and st.position_known:
            hold.record(st.lost(reason))
        return tuple(st.position_steps) if st is not None else (0, 0, 0)  # type: ignore[return-value]
    pos = tuple(st.position_steps) if st is not None and st.position_known else (0, 0, 0)
    machine.rebase(pos)
    if machine.link.reset_on_open:
        log(f"grbl on {machine.link.device} restarted when the port opened (an Arduino does): its machine zero is "
            f"where it started; cam keeps the machine frame of its state file", "info")
    return pos  # type: ignore[return-value]


class GrblPosition:
    """The live position of an activity on grbl, as a runner's cursor gives it: ``sent`` lines, and
    ``position_steps`` from where the activity started (read from grbl's latest status report)."""

    def __init__(self, machine: GrblMachine, start_steps: Steps3) -> None:
        self.machine = machine
        self.start = start_steps
        self.sent = 0

    @property
    def position_steps(self) -> Steps3:
        now = self.machine.position_steps()
        return tuple(int(n) - int(s) for n, s in zip(now, self.start))  # type: ignore[return-value]

    def seen(self, status: Optional[GrblStatus] = None) -> Optional[Seen]:
        """Where ``status`` (None: the latest report, if any) has the tool, steps from where the activity started:
        exact (``MPos`` over the resolution, not rounded) and as :attr:`position_steps` books it."""
        st = status or self.machine.last_status()
        if st is None:
            return None
        s = self.machine.settings
        x, y, z = (float(v) for v in st.mpos_mm[:3])
        exact = np.array([x / s.mm_per_step_xy, -y / s.mm_per_step_xy, -z / s.mm_per_step_z]) \
            + np.asarray(self.machine.base_steps, np.float64) - np.asarray(self.start, np.float64)
        booked = tuple(int(n) - int(b) for n, b in zip(self.machine.position_steps(st), self.start))
        return exact, booked  # type: ignore[return-value]


def _stream_until_pause(link: GrblLink, items: Iterator[Any], position: GrblPosition) -> Optional[GrblPause]:
    """Stream lines until the next pause (returned) or the end (None), then wait for grbl to stand still."""
    found: list[GrblPause] = []

    def lines() -> Iterator[str]:
        for item in items:
            if isinstance(item, GrblPause):
                found.append(item)
                return
            position.sent += 1
            yield item

    link.stream(lines(), wait_idle=True)
    return found[0] if found else None


def run_on_grbl(session: Any, name: str, job: Any, ctl: GrblControl, label: str, start_steps: Steps3,
                position: GrblPosition, total: int, estimated_s: float, journal: Optional[JournalSpec] = None,
                pause_probe: Optional[Callable[..., dict]] = None) -> None:
    """The worker thread of an activity on grbl: stream ``job`` (points relative to ``start_steps``), prompt at
    its pauses, end a stop as :func:`finish_stop` does, and book where grbl says the tool stands.  ``journal``:
    keep the job's journal (:class:`~cam.drive.grbl_journal.GrblJournal`: never ahead of where grbl reports the
    tool, closed with where it reports it after the stop).

    ``pause_probe(session, ctl, request, frame_moved)`` (:func:`cam.drive.grbl_pause_probe.probe_at_grbl_pause`;
    None: not offered) probes the new tool while the job waits at a tool change (the session's ``_pause_work``):
    the lines are in machine coordinates (``G53``), so a work Z shifted there shifts the job's frame (``shift``):
    the lines after it, the live position, the journal's home and the end booked all go on from ``start_steps``
    shifted by as much."""
    machine: GrblMachine = session.grbl
    link = machine.link
    error = lost = ""
    keeper: Optional[GrblJournal] = None
    lines: Optional[GrblLines] = None
    sending = False
    shift = np.zeros(3, np.int64)  # the job's frame moved at its pauses (a tool probed at a tool change)

    def frame_moved(by_steps: Any) -> None:
        shift[:] += np.asarray(by_steps, np.int64)
        position.start = tuple(int(s) + int(d) for s, d in zip(start_steps, shift))  # type: ignore[assignment]
        if keeper is not None:
            keeper.home_moved(by_steps)

    def on_point(index: int) -> None:
        done = min(total, index + 1)
        session.progress(done, total, int(estimated_s * 1e9 * done / max(1, total)))

    try:
        if ctl.halted:
            raise PortError("stopped before it started")
        if journal is not None:  # written once before anything is sent: no journal, no job
            lines = GrblLines(on_path_tolerance_steps(link.settings, session.settings))
            keeper = GrblJournal(journal, total, lines, position.seen, on_error=ctl.stop)
        sending = True
        link.allow()
        items = job_lines(job, start_steps, machine.base_steps, session.settings, on_point,
                          None if lines is None else lines.add, shift)
        if pause_probe is not None:
            session._pause_work = lambda request: pause_probe(session, ctl, request, frame_moved)
        link.stream(["G21G90G94"], wait_idle=False)
        while True:
            pause = _stream_until_pause(link, items, position)
            if pause is not None and keeper is not None:  # grbl stands still there: every line sent is done
                keeper.paused_at(pause.index)
            if pause is None or ctl.halted:
                if pause is None and lines is not None:  # the end: grbl idle after every line
                    lines.all_done(-1)
                break
            session.prompt(pause.position_steps, pause.note)
            if ctl.halted:
                break
            if keeper is not None:
                keeper.answered()
    except CamError as exc:
        error = str(exc)
    except Exception as exc:  # noqa: BLE001 - reported in the log; nothing more is sent
        error = f"internal error: {type(exc).__name__}: {exc}"
    finally:
        if pause_probe is not None:
            session._pause_work = None
    if ctl.halted:
        try:
            lost = finish_stop(machine, ctl)
        except CamError as exc:
            lost = str(exc)
    elif error and sending:  # (a journal that could not be written: nothing was sent, nothing to stop)
        lost = fault_stop(machine, error)
    # the end from the shifted start: the session adds what the tool moved at the pauses (its _pause_moved)
    _book_end(session, name, label, ctl, tuple(int(s) + int(d) for s, d in zip(start_steps, shift)),  # type: ignore
              error, lost, estimated_s, keeper, position)


def _book_end(session: Any, name: str, label: str, ctl: GrblControl, start_steps: Steps3, error: str,
              lost: str, estimated_s: float = 0.0, keeper: Optional[GrblJournal] = None,
              position: Optional[GrblPosition] = None) -> None:
    machine: GrblMachine = session.grbl
    seen = None
    try:
        st = machine.status()
        end = machine.position_steps(st)
        moved = np.asarray(end, np.int64) - np.asarray(start_steps, np.int64)
        seen = position.seen(st) if position is not None else None
    except CamError as exc:
        moved, error = None, error or str(exc)
    if ctl.estopped or lost:
        status, messages = EMERGENCY_STOPPED if ctl.estopped else ERROR, [lost or "emergency stop"]
    elif ctl.halted:
        status, messages = STOPPED, []
    elif error:
        status, messages = ERROR, [error]
    else:
        status, messages = FINISHED, []
    info = {"activity": name, "label": label, "status": status, "messages": messages,
            "machine_time_s": round(float(estimated_s), 3)}
    if keeper is not None:  # where grbl reports the tool after the stop: the journal's last word
        journal_error = keeper.close(journal_state_of(status), seen)
        if journal_error:
            messages.append(journal_error)
        info["journal"] = keeper.spec.path
    session.finish(info, moved)
    text = f"{label}: {status}" + (f" ({'; '.join(messages)})" if messages else "")
    session.log(text, "info" if status == FINISHED else ("warning" if status == STOPPED else "error"))


_MACHINES: dict[str, GrblMachine] = {}
_MACHINES_LOCK = threading.Lock()


def grbl_machine(url: str, settings: MachineSettings) -> GrblMachine:
    """The process's :class:`GrblMachine` for the device ``url`` names (opened at the first call; opened again
    when its link was lost).  Two names of one device (``/dev/serial/by-id/...`` and the ``/dev/ttyUSBn`` it
    points at) are one machine: opening the device twice would split grbl's answers between the two links."""
    device = os.path.realpath(parse_grbl_url(url)[0])
    with _MACHINES_LOCK:
        m = _MACHINES.get(device)
        if m is None or m.lost:
            m = GrblMachine(url, settings)
            _MACHINES[device] = m
        m.settings = settings
        return m


def close_grbl_machines() -> None:
    """Close every grbl link this process opened (tests, the end of ``cam serve``)."""
    with _MACHINES_LOCK:
        for m in _MACHINES.values():
            m.close()
        _MACHINES.clear()
