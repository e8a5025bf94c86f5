"""The runner: sends a step plan to a port, on time, and obeys pause / resume / stop / emergency stop.

Two clocks:

* **simulated** (the default for the mock): writes go out in batches at
  once, stamped with their scheduled times -- a job "finishes" instantly;
* **real time** (``realtime=True``, always for a real port): each write waits
  for its scheduled time; the mock then logs the measured time of each write.

Switches (``[inputs]`` of the machine file, :class:`SwitchWatch`) are sampled before every write on a port
that reads inputs (a parallel port; the mock with a :class:`~cam.drive.ports.SwitchSchedule`, looked at a
batch ahead on the simulated clock): a closed limit switch or e-stop ends the run before the next write, and
nothing more is sent.  Without switches the send loop is as it was.

Control (:class:`Controller`, thread-safe, usable from another thread or a
signal handler) is checked before every write, and every wait wakes on a
control request, so a stop or an emergency stop takes effect well within
one step period.  A stop lifts the tool straight up to the safe plane (Z = 0)
at the Z step rate; an emergency stop sends nothing more at all.
"""
from __future__ import annotations

import math
import queue
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Optional, Union

import numpy as np

from ..errors import CamError
from ..job.model import Job, JobLike
from ..settings import INPUT_BITS, MachineSettings
from ..verify.pinlog import PinLog, carve, decode_pin_log
from .._compiled import resolved
from ..motion.kernels import net_steps_kernel
from .priority import as_background, real_time_class
from .machines import open_port
from .ports import MockPort, Port
from ..pins import axis_bits
from ..motion.chunks import ChunkedPlan, StepChunk, plan_chunks
from ..motion.steps import StepPlan

__all__ = ["Controller", "Cursor", "RunResult", "Lateness", "STALL_NS", "JITTER_NS", "run", "simulate_surface", "FINISHED",
           "STOPPED", "EMERGENCY_STOPPED", "LIMIT_STOPPED", "SWITCHED", "SwitchWatch"]

Plan = Union[StepPlan, ChunkedPlan]
"""What the runner sends: a step plan, made a chunk at a time or held whole (both have ``chunks()``)."""

FINISHED = "finished"
STOPPED = "stopped"
EMERGENCY_STOPPED = "emergency-stopped"
LIMIT_STOPPED = "limit-stopped"
"""A limit switch closed: the run ended before the next write, nothing more was sent."""
SWITCHED = "switched"
"""The switch the run waited for (:attr:`SwitchWatch.until`, homing) changed: the run ended there."""

_BATCH = 16384
_SPIN_NS = 2_000_000  # busy-wait the last 2 ms before a write: sleeps here overshoot by up to ~1.5 ms (p99)
_SPIN_REAL_TIME_NS = 200_000
"""The busy-wait of a writer in a real-time scheduling class, whose sleeps end on time: short, because the kernel
stops a real-time task that runs all the time for 50 ms each second (``sched_rt_runtime_us``, 950 ms of 1 s by
default): with the 2 ms spin a 0.5 ms job spun without a break and stalled 50 ms every second."""
_PROGRESS_EVERY_NS = 50_000_000
_SWITCH_S = 0.0002
"""The interpreter's switch interval during a chunked real-time run (Python's default is 5 ms): how long the
thread making the next chunk may hold the interpreter while a write is due."""


class Controller:
    """Pause, resume, stop and emergency-stop a running job (thread-safe)."""

    z_top_steps: Optional[int] = None
    """The highest Z a stop's lift may reach, in the run's own frame (steps from where it started, +Z deeper): the top
    of the Z travel, set by what moved the tool at a pause where the plan does not know it (a tool probed at a tool
    change, :func:`cam.drive.pause_probe.probe_at_pause`).  None: the plan's safe plane, checked with the job."""

    def __init__(self) -> None:
        self._wake = threading.Event()
        self.paused = False
        self.stop_requested = False
        self.estop_requested = False
        self.listeners: list[Callable[[], None]] = []
        """Called (from the requesting thread) after every request: e.g. to pass it to a runner process."""

    def _changed(self) -> None:
        self._wake.set()
        for listener in list(self.listeners):
            listener()

    def pause(self) -> None:
        """Hold before the next write; the tool stays where it is."""
        self.paused = True
        self._changed()

    def resume(self) -> None:
        """Continue a paused job."""
        self.paused = False
        self._changed()

    def stop(self) -> None:
        """Stop before the next step and lift the tool to the safe plane.

        The lift goes straight up at the Z step delay; with speed ramps on, no faster than Z's start
        speed, since it starts from rest.
        """
        self.stop_requested = True
        self._changed()

    def emergency_stop(self) -> None:
        """Stop before the next step and send nothing more (during a stop's lift too)."""
        self.estop_requested = True
        self._changed()

    @property
    def halted(self) -> bool:
        return self.stop_requested or self.estop_requested


STALL_NS = 1_000_000
"""A real-time write later than its (shifted) time by more than this counts as a stall in the report."""
JITTER_NS = 10_000
"""A real-time write later than this is booked by index (``Lateness.slow_writes``): the slowdown it made is the
host's, not the plan's, and the ramp checker judges the re-ramp after it.  The look-ahead planner leaves 10 % of
the acceleration spare, which on the default machine's steepest ramps (5 ms periods) covers a write about 20 us
late; a write 22 us late while decelerating broke R2 by 0.0009 mm/s in a loaded CI run when this was 100 us."""


@dataclass
class Lateness:
    """How late the real-time writes went out, each against its time on the shifted schedule.

    Attributes:
        max_ns: the largest delay of one write.
        total_ns: the sum of the delays: how much later than planned the run ended (pauses not counted).
        late_writes: writes sent after their time at all.
        stalls: writes late by more than :data:`STALL_NS`.
        reramps: re-ramps after late writes (the steps held back to the machine's acceleration).
    """

    max_ns: int = 0
    total_ns: int = 0
    late_writes: int = 0
    stalls: int = 0
    reramps: int = 0
    """Times the run came back to its plan through a re-ramp (:class:`_ReRamp`) after writes went out late."""
    stall_writes: list[int] = field(default_factory=list)
    """The plan's writes sent over :data:`STALL_NS` late (:func:`cam.verify.ramps.check_ramps` takes them)."""
    slow_writes: list[int] = field(default_factory=list)
    """The plan's writes sent over :data:`JITTER_NS` late (the stalls among them)."""

    def add(self, late_ns: int, write: Optional[int] = None) -> None:
        """Book write number ``write`` (of the plan; None: not one) sent ``late_ns`` (> 0) after its time."""
        self.late_writes += 1
        self.total_ns += late_ns
        if late_ns > self.max_ns:
            self.max_ns = late_ns
        if late_ns > JITTER_NS and write is not None:
            self.slow_writes.append(write)
        if late_ns > STALL_NS:
            self.stalls += 1
            if write is not None:
                self.stall_writes.append(write)


@dataclass
class RunResult:
    """What a run did.

    Attributes:
        status: :data:`FINISHED`, :data:`STOPPED` or :data:`EMERGENCY_STOPPED`.
        position_steps: machine position (x, y, z) in steps at the end.
        writes: number of plan writes sent (lift writes of a stop not counted).
        machine_time_s: scheduled job time of the last plan write sent.
        wall_time_s: how long the run took.
        pauses: number of pauses honoured.
        port: the port written to (a :class:`MockPort` holds the pin log).
        started_ns: ``time.monotonic_ns()`` at the job start; the real-time
            mock logs write times relative to it.
        lateness: how late real-time writes went out (each delay moved the rest of the run later).
        switch: the switch that ended the run (``limit_x_max``, ``estop``, a homing's ``home_z``), or "".
    """

    status: str
    position_steps: tuple[int, int, int]
    writes: int
    machine_time_s: float
    wall_time_s: float
    pauses: int
    port: Port
    messages: list[str] = field(default_factory=list)
    started_ns: int = 0
    lateness: Lateness = field(default_factory=Lateness)
    switch: str = ""

    def pin_log(self) -> PinLog:
        """The mock port's pin log (only for the mock)."""
        if not isinstance(self.port, MockPort):
            raise CamError(f"port {self.port.name} keeps no pin log; run on 'mock'")
        return self.port.pin_log()


ProgressFn = Callable[[int, int, int], None]
"""progress(writes_done, writes_total, machine_time_ns_done)."""
PauseFn = Callable[[tuple[int, int, int], str], None]
"""on_pause(position_steps, note): called at a pause (Pause At, tool change); the job continues when it returns."""


class Cursor:
    """Where a run is: the writes sent and the position after them, decoded from the writes as they go out.

    The runner owns it and moves it on after each batch of writes; any thread may read it (the session's
    live position, the journal): :attr:`live` is one tuple, replaced whole.  Frame: steps from where the tool
    stood when the run started (+Z deeper).

    Args:
        settings: the pin map the writes use.
    """

    def __init__(self, settings: MachineSettings) -> None:
        clock, dirbit = axis_bits(settings)
        self.clock, self.dirbit = np.asarray(clock, np.int64), np.asarray(dirbit, np.int64)
        self.live: tuple[int, tuple[int, int, int]] = (0, (0, 0, 0))
        """``(writes sent, position_steps after them)``."""
        self.last_data = 0
        self.last_t_ns = 0
        self._count: dict[tuple, Callable] = {}  # the step counting kernel, resolved once per kind of writes array

    @property
    def sent(self) -> int:
        """Writes sent so far."""
        return self.live[0]

    @property
    def position_steps(self) -> tuple[int, int, int]:
        """Position (x, y, z) in steps after the writes sent so far."""
        return self.live[1]

    def counts(self, data: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """``(K, 3)`` int64 steps (x, y, z) the writes ``data[:ends[k]]`` would make after those noted so far
        (``data``: ``(M,)`` uint8; ``ends``: ``(K,)`` int64 ascending, at most M), counted in one pass."""
        args = (data, np.int64(self.last_data), self.clock, self.dirbit, ends)
        flags = data.flags
        kind = (data.dtype, flags.c_contiguous, flags.writeable)
        count = self._count.get(kind)
        if count is None:
            count = self._count[kind] = resolved(net_steps_kernel, *args)
        return count(*args)

    def note(self, t_ns: np.ndarray, data: np.ndarray, steps: Optional[tuple[int, int, int]] = None) -> None:
        """The writes ``(K,)`` times and data just went out, in order; ``steps``: the steps (x, y, z) they make,
        when the caller has counted them already (:meth:`counts`), else they are counted here."""
        n = len(data)
        if not n:
            return
        dx, dy, dz = steps if steps is not None else self.counts(data, np.array([n], np.int64))[0].tolist()
        sent, (x, y, z) = self.live
        self.last_data, self.last_t_ns = int(data[-1]), int(t_ns[-1])
        self.live = (sent + n, (x + dx, y + dy, z + dz))

    def set(self, sent: int, position_steps: tuple[int, int, int]) -> None:
        """Mirror another process's run (the real-time runner's): ``sent`` writes, then ``position_steps``."""
        self.live = (int(sent), tuple(int(v) for v in position_steps))  # type: ignore[assignment]


def _lift_writes(settings: MachineSettings, safe_z_steps: int, data_now: int, z_now: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Writes (relative times, data) that lift Z from ``z_now`` to ``safe_z_steps``, clocks low first."""
    s = settings
    clock, dirbit = axis_bits(s)
    base = int(data_now) & ~int(clock.sum()) & ~int(dirbit[2]) & 0xFF  # clocks low, Z direction up (-)
    n = max(0, z_now - safe_z_steps)
    per = s.delay_z_ns
    if s.ramp != "constant":
        # Z starts from rest: lift at its start speed, which it can start and stop at without a ramp
        step_mm, v_start, _, _ = s.axis_limits()
        per = max(per, int(round(step_mm[2] / v_start[2] * 1e9)))
    t = np.empty(1 + 2 * n, np.int64)
    d = np.empty(1 + 2 * n, np.uint8)
    t[0] = 0
    d[0] = base
    k = np.arange(n, dtype=np.int64)
    t[1::2] = k * per + per // 2
    d[1::2] = base | int(clock[2])
    t[2::2] = (k + 1) * per
    d[2::2] = base
    return t, d


class _Pauses:
    """The pauses of a plan (Pause At points, tool changes), and what happens at one."""

    def __init__(self, plan: Plan, ctl: Controller, on_pause: Optional[PauseFn], external: bool) -> None:
        self.ctl = ctl
        self.on_pause = on_pause
        self.external = external  # the caller gave the controller: pause it and wait for its resume
        self.writes = np.unique(np.asarray(plan.pause_writes, np.int64))
        self.notes = dict(zip((int(i) for i in plan.pause_writes), plan.pause_notes or []))
        self._writes: list[int] = self.writes.tolist()
        self._next = 0
        self.count = 0

    def marks(self, chunk: StepChunk, cursor: Cursor) -> dict[int, tuple[int, int, int]]:
        """The steps (x, y, z) ``chunk``'s writes make up to its end and up to each pause in it (by write count in
        the chunk, from the cursor's position before it), counted in one pass: the send loop's batches end there
        (a job of tens of thousands of tool changes counted batch by batch paid a compiled call at each)."""
        n = len(chunk)
        lo, hi = np.searchsorted(self.writes, (chunk.first_write, chunk.first_write + n))
        ends = np.append(self.writes[lo:hi] - (chunk.first_write - 1), n)
        return dict(zip(ends.tolist(), map(tuple, cursor.counts(chunk.data, ends).tolist()))) | {0: (0, 0, 0)}

    def next_after(self, write: int) -> int:
        """The first pause write at or after ``write`` (a huge number: none); ``write`` never goes back."""
        while self._next < len(self._writes) and self._writes[self._next] < write:
            self._next += 1
        return self._writes[self._next] if self._next < len(self._writes) else 1 << 62

    def honour(self, sent: int, position_steps: tuple[int, int, int]) -> bool:
        """Pause after write ``sent - 1``; False if the job was stopped meanwhile."""
        self.count += 1
        if self.on_pause is not None:
            self.on_pause(position_steps, self.notes.get(sent - 1, "pause"))
        elif self.external:
            self.ctl.pause()
        return _wait_while_paused(self.ctl)


class SwitchWatch:
    """What the runner does with the input pins (``[inputs]``): a closed limit switch or e-stop ends the run.

    A limit switch that closes during the run ends it before the next write.  One closed already when the run
    starts (the tool stopped on it) stops only a step of its axis toward its side (``limit_x_max``: an X+ step),
    so the axis may move off it, until it has opened; a pin shared by both ends of an axis then stops that axis
    both ways.  The e-stop ends the run whenever it is closed.

    Args:
        settings: the machine settings (``settings.inputs`` wires the switches; the pin map).
        until: ``(switch name, closed)``: end the run when that switch is closed (True) or open (False), status
            :data:`SWITCHED` (homing); None: run to the end.
        ignore: limit switches that stop nothing in this run (homing: those sharing the home switch's pin).
    """

    def __init__(self, settings: MachineSettings, until: Optional[tuple[str, bool]] = None,
                 ignore: "tuple[str, ...] | frozenset[str]" = ()) -> None:
        wired = settings.inputs.wired()
        bits = {name: (1 << INPUT_BITS[pin], high) for name, (pin, high) in wired.items()}
        clock, dirbit = axis_bits(settings)
        self.stops = []  # (name, mask, high, clock bit, dir bit, side: +1 max / -1 min / 0 e-stop)
        for name, (mask, high) in bits.items():
            if name == "estop" or (name.startswith("limit") and name not in ignore):
                a = "xyz".index(name[6]) if name != "estop" else 0
                self.stops.append((name, mask, high, int(clock[a]), int(dirbit[a]),
                                   0 if name == "estop" else (1 if name.endswith("max") else -1)))
        self.until = None if until is None else (until[0], *bits[until[0]], bool(until[1]))
        self.pins = {name: pin for name, (pin, _) in wired.items()}
        self.seen_open = {name: False for name, *_ in self.stops}
        self.last_data = 0
        self.tripped = ""
        """The switch that ended the run ("" while none has)."""

    @property
    def active(self) -> bool:
        """Whether anything is watched at all."""
        return bool(self.stops) or self.until is not None

    def check(self, levels: int, data: int) -> bool:
        """Sampled ``levels`` (:meth:`~cam.drive.ports.Port.read_inputs`) before write ``data``: True to send it
        and no more.  The rule of :meth:`first` for one write, in plain integers (the real-time runner calls it
        before every write: a few microseconds)."""
        prev, hit = self.last_data, ""
        for n, mask, high, clock, dirbit, side in self.stops:
            on = bool(levels & mask) == high
            if side == 0 or self.seen_open[n]:
                if on and (not hit or n == "estop"):
                    hit = n
            elif not on:
                self.seen_open[n] = True
            elif data & clock and not prev & clock and bool(data & dirbit) == (side > 0) and not hit:
                hit = n
        if not hit and self.until is not None:
            n, mask, high, closed = self.until
            if (bool(levels & mask) == high) == closed:
                hit = n
        if hit:
            self.tripped = hit
            return True
        self.last_data = int(data)
        return False

    def _stop_at(self, on: np.ndarray, d: np.ndarray, prev: np.ndarray, name: str, clock: int, dirbit: int,
                 side: int) -> int:
        """The first write a closed limit or e-stop forbids (K: none); notes whether it has been seen open."""
        k = len(on)
        if side == 0 or self.seen_open[name]:
            return int(np.argmax(on)) if on.any() else k
        opened = int(np.argmax(~on)) if (~on).any() else k
        toward = ((d & clock) != 0) & ((prev & clock) == 0) & (((d & dirbit) != 0) == (side > 0))
        first_toward = int(np.argmax(toward[:opened])) if toward[:opened].any() else k
        if opened < k:
            self.seen_open[name] = True
            closes = on[opened:]
            first_toward = min(first_toward, opened + int(np.argmax(closes)) if closes.any() else k)
        return first_toward

    def first(self, levels: np.ndarray, data: np.ndarray) -> int:
        """The first of ``(K,)`` writes ``data`` that must not go out, ``levels`` sampled before each (K: none);
        books the switch that forbids it."""
        d = np.asarray(data, np.int64)
        prev = np.concatenate([[self.last_data], d[:-1]])
        hit, name = len(levels), ""
        for n, mask, high, clock, dirbit, side in self.stops:
            k = self._stop_at(((levels & mask) != 0) == high, d, prev, n, clock, dirbit, side)
            if k < hit or (k == hit and n == "estop" and k < len(levels)):
                hit, name = k, n
        if self.until is not None:
            n, mask, high, closed = self.until
            on = ((levels & mask) != 0) == high
            k = int(np.argmax(on == closed)) if np.any(on == closed) else len(levels)
            if k < hit:
                hit, name = k, n
        if hit < len(levels):
            self.tripped = name
        if hit > 0:
            self.last_data = int(d[hit - 1])
        return hit

    def message(self, position_steps: tuple[int, int, int]) -> str:
        """The one line that says which switch ended the run (``position_steps``: the run's own frame)."""
        name = self.tripped
        pin = self.pins.get(name, 0)
        if name.startswith("limit"):  # a pin shared by several limits: which one closed, the pin cannot tell
            name = "/".join(n for n, *_ in self.stops if n != "estop" and self.pins[n] == pin)
        moved = " ".join(f"{a}={v:+d}" for a, v in zip("XYZ", position_steps))
        if name == "estop":
            return f"emergency stop: the e-stop input (pin {pin}) is closed; nothing more was sent (the run " \
                   f"moved {moved} steps)"
        if name.startswith("limit") and not any(position_steps):
            return f"limit switch {name} (pin {pin}) is closed: no step toward it was sent, the tool did not move"
        if name.startswith("limit"):
            return f"limit switch {name} (pin {pin}) closed; the motion stopped, nothing more was sent (the run " \
                   f"moved {moved} steps); the position is unknown until cam home or cam where --set"
        return f"{name} (pin {pin}) {'closed' if self.until and self.until[3] else 'opened'} (the run moved {moved} " \
               f"steps)"


def switch_watch(settings: MachineSettings, port: Port, given: Optional[SwitchWatch]) -> Optional[SwitchWatch]:
    """The watch of a run: ``given``, else the machine file's limit and e-stop switches; None when the port reads
    no inputs or nothing is wired (the send loop then samples nothing)."""
    if not port.reads_inputs:
        return None
    watch = given if given is not None else SwitchWatch(settings)
    return watch if watch.active else None


class _SimulatedClock:
    """Writes go out in batches at once, stamped with their scheduled times (the mock's default).  With
    ``switches`` (a mock with a switch schedule), each batch is sent up to the first write a switch forbids."""

    batch = _BATCH
    counts_chunks = True  # a chunk's steps counted once up to each pause in it (_Pauses.marks)

    def __init__(self, switches: Optional[SwitchWatch] = None) -> None:
        self.lateness = Lateness()  # nothing is late on the simulated clock
        self.switches = switches

    def chunks(self, plan: Plan) -> Iterator[StepChunk]:
        return _made_ahead(plan.chunks())  # the next chunks are planned (compiled, without the GIL) meanwhile

    def may_go(self, ctl: Controller) -> bool:
        """Before a batch: False if the run is halted or a switch ended it (a pause waits here for its end)."""
        if self.switches is not None and self.switches.tripped:
            return False
        return not (ctl.halted or (ctl.paused and not _wait_while_paused(ctl)))

    def send(self, p: Port, chunk: StepChunk, i: int, end: int, ctl: Controller) -> int:
        if self.switches is not None:  # the mock's levels before each write of the batch: up to the first stop
            end = i + self.switches.first(p.inputs_along(chunk.t_ns[i:end], chunk.data[i:end]),  # type: ignore
                                          chunk.data[i:end])
        p.write_many(chunk.t_ns[i:end], chunk.data[i:end], chunk.strobe[i:end])
        return end

    def paused_for(self, ns: int) -> None:
        pass


class _ReRamp:
    """After a late write the motors ran slower than planned, or stopped: the steps that follow are held back so
    that the step rate grows again within the machine's limits instead of jumping back to the plan.

    After a stall (a write over :data:`STALL_NS` late) the motors have stopped: the interval after the first step
    that follows is one step at ``u_start``, the slowest axis's start speed in steps per second (an axis stepping
    in every period starts at no more than its start speed).  After that, or after a smaller delay, a step may
    come no sooner than the rate ``max(u_start, sqrt(u_last^2 + 2 alpha))`` allows, ``u_last`` the rate of the
    interval before it and ``alpha`` the smallest axis acceleration in steps/s^2 (with the look-ahead planner's
    margin).  This holds until the plan's own time for a step is no sooner than the limit (the run is back on its
    plan); a run on time is never touched.  Times are wall ns.
    """

    def __init__(self, settings: MachineSettings, lateness: Lateness) -> None:
        s_mm, v_start, _, acc = settings.axis_limits()
        self.u_start = min(v / s for v, s in zip(v_start, s_mm))
        self.alpha = _RERAMP_MARGIN * min(a / s for a, s in zip(acc, s_mm))
        clock, _ = axis_bits(settings)
        self.clocks = int(np.bitwise_or.reduce(clock))
        self.lateness = lateness
        self.ramped = settings.ramp != "constant"
        self.active = False
        self.held = False  # this re-ramp has held a step back (counted once)
        self.restart = 0  # 1: stalled, the first step after it is due; 2: that step went out, the next starts
        self.last_ns: Optional[int] = None  # wall time of the last step write
        self.last_interval_ns = 0

    def late(self, stalled: bool) -> None:
        """A write went out late (``stalled``: by over :data:`STALL_NS`): the next steps re-ramp (with speed ramps
        only: the ``constant`` mode, the thesis's, plans no acceleration to come back within)."""
        if not self.ramped:
            return
        if not self.active:
            self.active, self.held = True, False
        if stalled:
            self.restart = 1

    def earliest(self, data: int, target_ns: int) -> int:
        """The wall time write ``data`` due at ``target_ns`` may go out (later while re-ramping a step)."""
        if not self.active or not data & self.clocks or self.last_ns is None or self.restart == 1:
            return target_ns
        if self.restart == 2:
            u = self.u_start
        else:
            u_last = 1e9 / max(1, self.last_interval_ns)
            u = max(self.u_start, math.sqrt(u_last * u_last + 2.0 * self.alpha))
        limit = self.last_ns + int(math.ceil(1e9 / u))
        if limit <= target_ns:
            if self.restart == 0:
                self.active = False  # back on the plan
            return target_ns
        if not self.held:
            self.held = True
            self.lateness.reramps += 1
        return limit

    def sent(self, data: int, now_ns: int) -> None:
        if data & self.clocks:
            if self.last_ns is not None:
                self.last_interval_ns = now_ns - self.last_ns
            self.last_ns = now_ns
            self.restart = 2 if self.restart == 1 else 0


_RERAMP_MARGIN = 0.8
"""Fraction of the machine's acceleration a re-ramp uses: below the look-ahead planner's 0.9, because a re-ramp's
steps go out at wall times that jitter too (a run in the whole suite once broke R2 by 8 % of its limit after a
small late write with 0.9)."""


class _RealClock:
    """Each write at its time after ``t0`` (monotonic ns), pauses added.

    Sleeps on the controller's wake event until :data:`_SPIN_NS` before a write, then spins.  A write sent
    late (a stall, a busy machine, a stopped process) shifts every later write by its lateness: the runner
    never catches up, so each interval between writes is at least the planned one (ramps included) and a
    stepper never gets steps faster than its plan.  ``lateness`` books each delay.  The plan's chunks are made
    ahead by a thread (:func:`_made_ahead`) while the writes go out.
    """

    batch = 1 << 62  # a batch ends at a progress report, a pause, or the chunk's end
    counts_chunks = False  # each batch's steps are counted after it went out, before the next write is due: a
    # chunk counted at its start would hold its first write back (about a millisecond for 2^18 periods)

    def __init__(self, t0: int, settings: MachineSettings, switches: Optional[SwitchWatch] = None) -> None:
        self.t0 = t0
        self.switches = switches
        self.offset = 0
        self.lateness = Lateness()
        self.reramp = _ReRamp(settings, self.lateness)
        self.last_progress = -_PROGRESS_EVERY_NS
        self.spin_ns = _SPIN_REAL_TIME_NS if real_time_class() else _SPIN_NS

    def chunks(self, plan: Plan) -> Iterator[StepChunk]:
        return _made_ahead(plan.chunks())

    def may_go(self, ctl: Controller) -> bool:
        return not ctl.halted and not (self.switches is not None and self.switches.tripped)

    def paused_for(self, ns: int) -> None:
        self.offset += ns

    def send(self, p: Port, chunk: StepChunk, i: int, end: int, ctl: Controller) -> int:
        """Send writes ``i..end`` of ``chunk`` each at its time; returns where it stopped (a halt, or a progress
        report is due)."""
        wake = ctl._wake
        t_ns, data, strobe = chunk.t_ns, chunk.data, chunk.strobe
        j = i
        while j < end:
            target = self.t0 + self.offset + int(t_ns[j])
            held = self.reramp.earliest(int(data[j]), target)
            if held > target:  # re-ramping: this and every later write move later (as for a late write)
                self.offset += held - target
                target = held
            while True:
                if ctl.halted:
                    return j
                if ctl.paused:
                    began = time.monotonic_ns()
                    if not _wait_while_paused(ctl):
                        return j
                    paused_ns = time.monotonic_ns() - began
                    self.offset += paused_ns
                    target += paused_ns
                    continue
                remaining = target - time.monotonic_ns()
                if remaining <= 0:
                    break
                if remaining > self.spin_ns:
                    wake.wait((remaining - self.spin_ns) / 1e9)
                    wake.clear()
            if self.switches is not None and self.switches.check(p.read_inputs(), int(data[j])):
                return j  # a switch closed (or the one waited for changed): nothing more is sent
            now = time.monotonic_ns()
            late_ns = now - target
            if late_ns > 0:  # behind: the rest of the schedule moves later, so no interval is shorter than planned
                self.offset += late_ns
                self.lateness.add(late_ns, chunk.first_write + j)
                self.reramp.late(late_ns > STALL_NS)  # ... and the motors, slowed or stopped, re-ramp to the plan
            p.write(int(data[j]), int(strobe[j]), now - self.t0)
            self.reramp.sent(int(data[j]), now)
            j += 1
            if int(t_ns[j - 1]) - self.last_progress > _PROGRESS_EVERY_NS:
                self.last_progress = int(t_ns[j - 1])
                return j
        return j


def run(
    job: "JobLike | Plan",
    port: str | Port = "mock",
    *,
    realtime: bool = False,
    controller: Optional[Controller] = None,
    progress: Optional[ProgressFn] = None,
    on_pause: Optional[PauseFn] = None,
    cursor: Optional[Cursor] = None,
    switches: Optional[SwitchWatch] = None,
) -> RunResult:
    """Run a job on a port: its step plan a chunk at a time, through one send loop.

    Args:
        job: a job (any :class:`~cam.job.model.JobLike`: planned here with :func:`cam.motion.chunks.plan_chunks`)
            or a step plan (:class:`~cam.motion.chunks.ChunkedPlan`, or a :class:`StepPlan` held whole).
        port: a port name (``"mock"``, ``"/dev/parport0"``) or an open :class:`Port`.
        realtime: wait for each write's time.  Forced on for real ports.
        controller: pause / resume / stop / emergency stop from elsewhere.
        progress: called now and then with (writes done, writes total, machine ns done).
        on_pause: called at each Pause At point; if None, the runner pauses its
            controller and waits for :meth:`Controller.resume` (or continues
            at once when no controller was given).
        cursor: where the run is, moved on as the writes go out (a new one if None): the live position.
        switches: what the input pins do (:class:`SwitchWatch`); None: the limit and e-stop switches of
            ``plan.settings.inputs``.  Sampled only on a port that reads inputs (:attr:`Port.reads_inputs`).

    Returns:
        A :class:`RunResult`; the mock's pin log is ``result.pin_log()``.
    """
    plan: Plan = job if isinstance(job, (StepPlan, ChunkedPlan)) else plan_chunks(job)  # type: ignore[assignment]
    p = open_port(port, plan.settings)
    if not isinstance(p, MockPort):
        realtime = True
    ctl = controller or Controller()
    cursor = cursor or Cursor(plan.settings)
    pauses = _Pauses(plan, ctl, on_pause, controller is not None)
    watch = switch_watch(plan.settings, p, switches)
    wall0 = time.monotonic_ns()
    clock: "_SimulatedClock | _RealClock" = _RealClock(wall0, plan.settings, watch) if realtime \
        else _SimulatedClock(watch)
    if realtime:
        switch_s = sys.getswitchinterval()
        sys.setswitchinterval(min(switch_s, _SWITCH_S))  # the thread making chunks yields the interpreter soon
    try:
        _send(plan, p, ctl, clock, cursor, pauses, progress)
    finally:
        if realtime:
            sys.setswitchinterval(switch_s)
    status, position, messages = _ending(plan, p, ctl, cursor, wall0 if realtime else None, clock.lateness, watch)
    wall = (time.monotonic_ns() - wall0) / 1e9
    return RunResult(status, position, cursor.sent, cursor.last_t_ns / 1e9, wall, pauses.count, p, messages, wall0,
                     clock.lateness, watch.tripped if watch is not None else "")


def _send(plan: Plan, p: Port, ctl: Controller, clock: "_SimulatedClock | _RealClock", cursor: Cursor,
          pauses: _Pauses, progress: Optional[ProgressFn]) -> None:
    """The send loop: the plan's chunks in batches (up to a pause, a progress report or :data:`_BATCH`), the
    cursor moved on after each, each pause honoured; returns when the writes end or the run is halted."""
    total = len(plan)
    for chunk in clock.chunks(plan):
        i, n = 0, len(chunk)
        marks = pauses.marks(chunk, cursor) if clock.counts_chunks else {}
        while i < n:
            if not clock.may_go(ctl):
                return
            pause = pauses.next_after(chunk.first_write + i)
            end = min(n, i + clock.batch, pause - chunk.first_write + 1)
            j = clock.send(p, chunk, i, end, ctl)
            a, b = marks.get(i), marks.get(j)
            cursor.note(chunk.t_ns[i:j], chunk.data[i:j],
                        None if a is None or b is None else (b[0] - a[0], b[1] - a[1], b[2] - a[2]))
            i = j
            sent = cursor.sent
            if progress and j > 0:
                progress(sent, total, int(chunk.t_ns[j - 1]))
            if sent - 1 == pause and sent < total:
                began = time.monotonic_ns()
                if not pauses.honour(sent, cursor.position_steps):
                    return
                clock.paused_for(time.monotonic_ns() - began)
            elif j < end and ctl.halted:
                return


def _ending(plan: Plan, p: Port, ctl: Controller, cursor: Cursor, t0: Optional[int], lateness: Lateness,
            watch: Optional[SwitchWatch] = None) -> tuple[str, tuple[int, int, int], list[str]]:
    """How a run ends: ``(status, position_steps, messages)``.  A run halted before its last write lifts the tool
    (:func:`_stop`); an emergency stop, or a switch, sends nothing more.  The mock's log is flushed."""
    status = FINISHED
    messages: list[str] = []
    position = cursor.position_steps
    if cursor.sent < len(plan):
        if watch is not None and watch.tripped:
            status = _switch_status(watch)
            messages.append(watch.message(position))
        elif ctl.estop_requested:
            status = EMERGENCY_STOPPED
            messages.append(f"emergency stop at {position} steps; nothing more was sent")
        else:
            status, position = _stop(plan, p, ctl, cursor, t0, lateness, watch)
            messages.append(watch.message(position) if watch is not None and watch.tripped else
                            f"stopped at X={position[0]} Y={position[1]} steps; tool lifted to Z={position[2]}")
            top = _lift_target(plan, ctl)
            if top > plan.safe_z_steps and cursor.position_steps[2] > top:  # the safe plane above the travel's top
                messages.append(f"the stop lifted the tool to the top of the Z travel only, {top - plan.safe_z_steps} "
                                f"steps below the job's safe plane (the tool was moved at a pause: a tool probed at a "
                                f"tool change)")
    if isinstance(p, MockPort):
        p._flush()
    return status, position, messages


def _switch_status(watch: SwitchWatch) -> str:
    """The status of a run a switch ended."""
    return {"estop": EMERGENCY_STOPPED}.get(watch.tripped, LIMIT_STOPPED if watch.tripped.startswith("limit")
                                            else SWITCHED)


def _lift_target(plan: Plan, ctl: Controller) -> int:
    """The Z a stop lifts the tool to (the run's frame): the plan's safe plane, or the top of the Z travel when the
    controller knows that to be lower (:attr:`Controller.z_top_steps`: the lift never leaves the travel)."""
    top = getattr(ctl, "z_top_steps", None)
    return int(plan.safe_z_steps) if top is None else max(int(plan.safe_z_steps), int(top))


def _stop(plan: Plan, p: Port, ctl: Controller, cursor: Cursor, t0: Optional[int], lateness: Lateness,
          watch: Optional[SwitchWatch] = None) -> tuple[str, tuple[int, int, int]]:
    """Lift the tool straight up to the safe plane where the cursor is (no higher than the top of the Z travel,
    :func:`_lift_target`); returns (status, position_steps).

    ``t0``: the real-time job start (monotonic ns), None on the simulated clock.  An emergency stop
    during a real-time lift ends it (status :data:`EMERGENCY_STOPPED`).  A late lift write moves the
    rest of the lift later, as in a job.  ``watch``: the switches are sampled before every lift write too (a
    limit switch or the e-stop ends the lift, :func:`_switch_status`).
    """
    position = cursor.position_steps
    safe_z = _lift_target(plan, ctl)
    lift_t, lift_d = _lift_writes(plan.settings, safe_z, cursor.last_data, position[2])
    strobe = 1 if plan.settings.half_step else 0
    if t0 is None:
        n = len(lift_t)
        if watch is not None:  # the mock's simulated switches before each lift write
            n = watch.first(p.inputs_along(cursor.last_t_ns + lift_t, lift_d), lift_d)  # type: ignore[attr-defined]
        p.write_many(cursor.last_t_ns + lift_t[:n], lift_d[:n], np.full(n, strobe, np.uint8))
        if n < len(lift_t):  # a switch ended the lift: each Z clock write before it lifted one step
            z_clock = int(axis_bits(plan.settings)[0][2])
            return _switch_status(watch), (position[0], position[1],  # type: ignore[arg-type]
                                           position[2] - int(np.count_nonzero(lift_d[:n] & z_clock)))
        return STOPPED, (position[0], position[1], min(position[2], safe_z))
    start = time.monotonic_ns() - t0
    z_clock = int(axis_bits(plan.settings)[0][2])
    lift_began = t_lift0 = time.monotonic_ns()  # t_lift0 moves later with each late write
    for t_rel, d in zip(lift_t.tolist(), lift_d.tolist()):
        while time.monotonic_ns() - t_lift0 < t_rel:
            if ctl.estop_requested:
                break
            time.sleep(min(0.001, max(0.0, (t_rel - (time.monotonic_ns() - t_lift0)) / 1e9)))
        if ctl.estop_requested:
            return EMERGENCY_STOPPED, position
        if watch is not None and watch.check(p.read_inputs(), d):
            return _switch_status(watch), position
        now = time.monotonic_ns()
        late_ns = now - t_lift0 - t_rel
        if late_ns > 0:
            t_lift0 += late_ns
            lateness.add(late_ns)
        p.write(d, strobe, start + (now - lift_began))
        if d & z_clock:
            position = (position[0], position[1], position[2] - 1)
    return STOPPED, position


def _made_ahead(chunks: Iterator[StepChunk], ahead: int = 2) -> Iterator[StepChunk]:
    """``chunks``, made by a thread up to ``ahead`` chunks before they are taken (the real-time runner sends
    one while the next is planned).  An error making them is raised where the chunk would have come."""
    q: "queue.Queue[Any]" = queue.Queue(maxsize=ahead)
    done = threading.Event()
    end = object()

    def make() -> None:
        as_background()  # in the real-time runner process: not the writer's class and core
        try:
            for chunk in chunks:
                while not done.is_set():
                    try:
                        q.put(chunk, timeout=0.05)
                        break
                    except queue.Full:
                        continue
                if done.is_set():
                    return
            q.put(end)
        except BaseException as exc:  # noqa: BLE001 - raised in the runner's thread
            q.put(exc)

    maker = threading.Thread(target=make, name="cam-chunk-maker", daemon=True)
    maker.start()
    try:
        while True:
            item = q.get()
            if item is end:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        done.set()


def _wait_while_paused(ctl: Controller) -> bool:
    """Block while paused; False if a stop came meanwhile."""
    while ctl.paused and not ctl.halted:
        ctl._wake.wait(0.05)
        ctl._wake.clear()
    return not ctl.halted


def simulate_surface(job: Job) -> "np.ndarray":
    """The surface ``job`` would cut: run it on the mock, decode the pin log, carve with a point tool.

    Returns:
        ``(height_px, width_px)`` :class:`~cam.verify.pinlog.Surface`, depth in Z steps, drawing frame.
    """
    result = run(job, MockPort())
    motion = decode_pin_log(result.pin_log(), job.settings)
    return carve(motion, (job.height_px, job.width_px), job.settings, origin_px=job.origin_px)
