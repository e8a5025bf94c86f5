"""The runner: sends a step plan to a port, on time, and obeys pause / resume / stop / emergency stop.

Two clocks:

* **simulated** (the default for the mock): writes go out in batches at
  once, stamped with their scheduled times -- a job "finishes" instantly;
* **real time** (``realtime=True``, always for a real port): each write waits
  for its scheduled time; the mock then logs the measured time of each write.

Control (:class:`Controller`, thread-safe, usable from another thread or a
signal handler) is checked before every write, and every wait wakes on a
control request, so a stop or an emergency stop takes effect well within
one step period.  A stop lifts the tool straight up to the safe plane (Z = 0)
at the Z step rate; an emergency stop sends nothing more at all.
"""
from __future__ import annotations

import queue
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Optional

import numpy as np

from ..errors import CamError
from ..job.model import Job
from ..verify.pinlog import PinLog, _decode, carve, decode_pin_log
from .ports import MockPort, Port, open_port
from .pins import axis_bits
from .chunks import ChunkedPlan, StepChunk
from .steps import StepPlan, plan_steps

__all__ = ["Controller", "RunResult", "Lateness", "STALL_NS", "run", "simulate_surface", "FINISHED", "STOPPED", "EMERGENCY_STOPPED"]

FINISHED = "finished"
STOPPED = "stopped"
EMERGENCY_STOPPED = "emergency-stopped"

_BATCH = 16384
_SPIN_NS = 2_000_000  # busy-wait the last 2 ms before a write: sleeps here overshoot by up to ~1.5 ms (p99)
_PROGRESS_EVERY_NS = 50_000_000
_SWITCH_S = 0.0002
"""The interpreter's switch interval during a chunked real-time run (Python's default is 5 ms): how long the
thread making the next chunk may hold the interpreter while a write is due."""


class Controller:
    """Pause, resume, stop and emergency-stop a running job (thread-safe)."""

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


@dataclass
class Lateness:
    """How late the real-time writes went out, each against its time on the shifted schedule.

    Attributes:
        max_ns: the largest delay of one write.
        total_ns: the sum of the delays: how much later than planned the run ended (pauses not counted).
        late_writes: writes sent after their time at all.
        stalls: writes late by more than :data:`STALL_NS`.
    """

    max_ns: int = 0
    total_ns: int = 0
    late_writes: int = 0
    stalls: int = 0

    def add(self, late_ns: int) -> None:
        """Book one write sent ``late_ns`` (> 0) after its time."""
        self.late_writes += 1
        self.total_ns += late_ns
        if late_ns > self.max_ns:
            self.max_ns = late_ns
        if late_ns > STALL_NS:
            self.stalls += 1


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

    def pin_log(self) -> PinLog:
        """The mock port's pin log (only for the mock)."""
        if not isinstance(self.port, MockPort):
            raise CamError(f"port {self.port.name} keeps no pin log; run on 'mock'")
        return self.port.pin_log()


ProgressFn = Callable[[int, int, int], None]
"""progress(writes_done, writes_total, machine_time_ns_done)."""
PauseFn = Callable[[tuple[int, int, int], str], None]
"""on_pause(position_steps, note): called at a pause (Pause At, tool change); the job continues when it returns."""


def _lift_writes(plan: StepPlan, data_now: int, z_now: int) -> tuple[np.ndarray, np.ndarray]:
    """Writes (relative times, data) that lift Z from ``z_now`` to the safe plane, clocks low first."""
    s = plan.settings
    clock, dirbit = axis_bits(s)
    base = int(data_now) & ~int(clock.sum()) & ~int(dirbit[2]) & 0xFF  # clocks low, Z direction up (-)
    n = max(0, z_now - plan.safe_z_steps)
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
    """The Pause At points of a plan, and what happens at one (shared by both clocks)."""

    def __init__(self, plan: "StepPlan | ChunkedPlan", ctl: Controller, on_pause: Optional[PauseFn], external: bool,
                 position_of: Optional[Callable[[int], tuple[int, int, int]]] = None) -> None:
        self.position_of = position_of or (lambda sent: _position_after(plan, sent))  # type: ignore[arg-type]
        self.ctl = ctl
        self.on_pause = on_pause
        self.external = external  # the caller gave the controller: pause it and wait for its resume
        self.at = set(int(i) for i in plan.pause_writes)
        self.notes = dict(zip((int(i) for i in plan.pause_writes), plan.pause_notes or []))
        self.count = 0

    def honour(self, sent: int) -> bool:
        """Pause after write ``sent - 1``; False if the job was stopped meanwhile."""
        self.count += 1
        pos = self.position_of(sent)
        if self.on_pause is not None:
            self.on_pause(pos, self.notes.get(sent - 1, "pause"))
        elif self.external:
            self.ctl.pause()
        return _wait_while_paused(self.ctl)


def run(
    job: Job | StepPlan,
    port: str | Port = "mock",
    *,
    realtime: bool = False,
    controller: Optional[Controller] = None,
    progress: Optional[ProgressFn] = None,
    on_pause: Optional[PauseFn] = None,
) -> RunResult:
    """Run a job on a port.

    Args:
        job: a :class:`~cam.job.model.Job` (planned into steps here) or a :class:`StepPlan`.
        port: a port name (``"mock"``, ``"/dev/parport0"``) or an open :class:`Port`.
        realtime: wait for each write's time.  Forced on for real ports.
        controller: pause / resume / stop / emergency stop from elsewhere.
        progress: called now and then with (writes done, writes total, machine ns done).
        on_pause: called at each Pause At point; if None, the runner pauses its
            controller and waits for :meth:`Controller.resume` (or continues
            at once when no controller was given).

    Returns:
        A :class:`RunResult`; the mock's pin log is ``result.pin_log()``.
    """
    p = open_port(port)
    if not isinstance(p, MockPort):
        realtime = True
    if isinstance(job, ChunkedPlan):
        if realtime:
            return _run_chunks_realtime(job, p, controller, progress, on_pause)
        return _run_chunks(job, p, controller, progress, on_pause)
    plan = job if isinstance(job, StepPlan) else plan_steps(job)
    ctl = controller or Controller()
    pauses = _Pauses(plan, ctl, on_pause, controller is not None)
    wall0 = time.monotonic_ns()
    lateness = Lateness()
    if realtime:
        sent = _send_realtime([(plan.t_ns, plan.data, plan.strobe)], len(plan), p, ctl, pauses, progress, wall0,
                              lateness)
    else:
        sent = _send_simulated(plan, p, ctl, pauses, progress)
    status, position, messages = _ending(plan, p, ctl, sent, len(plan), _position_after(plan, sent),
                                         wall0 if realtime else None, lateness)
    wall = (time.monotonic_ns() - wall0) / 1e9
    machine = float(plan.t_ns[sent - 1]) / 1e9 if sent else 0.0
    return RunResult(status, position, sent, machine, wall, pauses.count, p, messages, wall0, lateness)


def _send_simulated(plan: StepPlan, p: Port, ctl: Controller, pauses: _Pauses,
                    progress: Optional[ProgressFn]) -> int:
    """Send the plan in batches at once, stamped with their scheduled times; returns the writes sent."""
    t_ns, data, strobe = plan.t_ns, plan.data, plan.strobe
    total = len(plan)
    pause_set = pauses.at
    pause_points = sorted(pause_set)
    sent = 0
    while sent < total:
        if ctl.halted or (ctl.paused and not _wait_while_paused(ctl)):
            break
        end = min(total, sent + _BATCH)
        for pp in pause_points:
            if sent <= pp < end:
                end = pp + 1
                break
        p.write_many(t_ns[sent:end], data[sent:end], strobe[sent:end])
        sent = end
        if progress:
            progress(sent, total, int(t_ns[sent - 1]))
        if (sent - 1) in pause_set and sent < total and not pauses.honour(sent):
            break
    return sent


def _send_realtime(chunks: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]], total: int, p: Port,
                   ctl: Controller, pauses: _Pauses, progress: Optional[ProgressFn], t0: int, lateness: "Lateness",
                   on_progress: Optional[Callable[[int], None]] = None) -> int:
    """Send each write at its time after ``t0`` (monotonic ns), pauses added; returns the writes sent.

    ``chunks``: consecutive ``(t_ns, data, strobe)`` arrays of the plan's ``total`` writes (a whole plan is one).
    ``on_progress(sent)`` runs with each progress report (before ``progress``).

    Sleeps on the controller's wake event until :data:`_SPIN_NS` before a write, then spins.  A write
    sent late (a stall, a busy machine, a stopped process) shifts every later write by its lateness:
    the runner never catches up, so each interval between writes is at least the planned one (ramps
    included) and a stepper never gets steps faster than its plan.  ``lateness`` books each delay.
    """
    pause_set = pauses.at
    sent = 0
    offset = 0
    last_progress = 0
    wake = ctl._wake
    for t_ns, data, strobe in chunks:
        n = len(t_ns)
        j = 0
        halted = False
        while j < n:
            target = t0 + offset + int(t_ns[j])
            while True:
                if ctl.halted:
                    halted = True
                    break
                if ctl.paused:
                    began = time.monotonic_ns()
                    if not _wait_while_paused(ctl):
                        halted = True
                        break
                    paused_ns = time.monotonic_ns() - began
                    offset += paused_ns
                    target += paused_ns
                    continue
                remaining = target - time.monotonic_ns()
                if remaining <= 0:
                    break
                if remaining > _SPIN_NS:
                    wake.wait((remaining - _SPIN_NS) / 1e9)
                    wake.clear()
            if halted:
                break
            now = time.monotonic_ns()
            late_ns = now - target
            if late_ns > 0:  # behind: the rest of the schedule moves later, so no interval is shorter than planned
                offset += late_ns
                lateness.add(late_ns)
            p.write(int(data[j]), int(strobe[j]), now - t0)
            j += 1
            sent += 1
            if (progress or on_progress) and (target - last_progress > _PROGRESS_EVERY_NS or sent == total):
                last_progress = target
                if on_progress is not None:
                    on_progress(sent)
                if progress:
                    progress(sent, total, int(t_ns[j - 1]))
            if (sent - 1) in pause_set and sent < total:
                began = time.monotonic_ns()
                if not pauses.honour(sent):
                    halted = True
                    break
                offset += time.monotonic_ns() - began
        if halted:
            break
    return sent


def _ending(plan: "StepPlan | _Tail", p: Port, ctl: Controller, sent: int, total: int,
            position: tuple[int, int, int], t0: Optional[int], lateness: Optional["Lateness"]
            ) -> tuple[str, tuple[int, int, int], list[str]]:
    """How a run that sent ``sent`` of its ``total`` writes ends: ``(status, position_steps, messages)``.  A stop
    lifts the tool (:func:`_stop`); an emergency stop sends nothing more.  The mock's log is flushed."""
    status = FINISHED
    messages: list[str] = []
    if sent < total:
        if ctl.estop_requested:
            status = EMERGENCY_STOPPED
            messages.append(f"emergency stop at {position} steps; nothing more was sent")
        else:
            status, position = _stop(plan, p, ctl, sent, position, t0, lateness)  # type: ignore[arg-type]
            messages.append(f"stopped at X={position[0]} Y={position[1]} steps; tool lifted to Z={position[2]}")
    if isinstance(p, MockPort):
        p._flush()
    return status, position, messages


def _stop(plan: StepPlan, p: Port, ctl: Controller, sent: int, position: tuple[int, int, int],
          t0: Optional[int], lateness: Optional[Lateness] = None) -> tuple[str, tuple[int, int, int]]:
    """Lift the tool straight up to the safe plane after ``sent`` writes; returns (status, position_steps).

    ``t0``: the real-time job start (monotonic ns), None on the simulated clock.  An emergency stop
    during a real-time lift ends it (status :data:`EMERGENCY_STOPPED`).  A late lift write moves the
    rest of the lift later, as in a job.
    """
    lift_t, lift_d = _lift_writes(plan, int(plan.data[sent - 1]) if sent else 0, position[2])
    strobe = plan.strobe[0]
    if t0 is None:
        start = int(plan.t_ns[sent - 1]) if sent else 0
        p.write_many(start + lift_t, lift_d, np.full(len(lift_t), strobe, np.uint8))
        return STOPPED, (position[0], position[1], min(position[2], plan.safe_z_steps))
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
        now = time.monotonic_ns()
        late_ns = now - t_lift0 - t_rel
        if late_ns > 0:
            t_lift0 += late_ns
            if lateness is not None:
                lateness.add(late_ns)
        p.write(d, int(strobe), start + (now - lift_began))
        if d & z_clock:
            position = (position[0], position[1], position[2] - 1)
    return STOPPED, position


class _LastWrite:
    """Stands for a plan's arrays where only the last write sent is read (a stop after a chunked run)."""

    def __init__(self, value: int) -> None:
        self.value = value

    def __getitem__(self, index: int) -> int:
        return self.value


class _Tail:
    """What :func:`_stop` reads of a plan, for a :class:`ChunkedPlan` whose writes are no longer held."""

    def __init__(self, plan: ChunkedPlan, last_t_ns: int, last_data: int) -> None:
        self.settings = plan.settings
        self.safe_z_steps = plan.safe_z_steps
        self.t_ns = _LastWrite(last_t_ns)
        self.data = _LastWrite(last_data)
        self.strobe = np.full(1, 1 if plan.settings.half_step else 0, np.uint8)


def _run_chunks(plan: ChunkedPlan, p: Port, controller: Optional[Controller], progress: Optional[ProgressFn],
                on_pause: Optional[PauseFn]) -> RunResult:
    """:func:`run` of a :class:`ChunkedPlan` on the simulated clock: a chunk at a time, in bounded memory.

    The writes and pauses are those of the whole plan; the position is decoded as the writes go out
    (and published as ``plan.live``: ``(writes sent, position_steps)``, for the session's live position).
    """
    ctl = controller or Controller()
    clock, dirbit = axis_bits(plan.settings)
    pause_at = set(int(i) for i in plan.pause_writes)
    notes = dict(zip((int(i) for i in plan.pause_writes), plan.pause_notes or []))
    total = len(plan)
    wall0 = time.monotonic_ns()
    sent, pauses, last_t, last_d = 0, 0, 0, 0
    pos = np.zeros(3, np.int64)
    halted = False
    for chunk in plan.chunks():
        i = 0
        while i < len(chunk):
            if ctl.halted or (ctl.paused and not _wait_while_paused(ctl)):
                halted = True
                break
            g = chunk.first_write + i
            end = min(len(chunk), i + _BATCH)
            nxt = [w for w in pause_at if g <= w < chunk.first_write + end]
            if nxt:
                end = min(nxt) - chunk.first_write + 1
            data = chunk.data[i:end]
            p.write_many(chunk.t_ns[i:end], data, chunk.strobe[i:end])
            decoded, _ = _decode(data, last_d, pos, clock, dirbit)
            pos = decoded[-1].copy()
            last_t, last_d = int(chunk.t_ns[end - 1]), int(data[-1])
            sent += end - i
            i = end
            plan.live = (sent, tuple(int(v) for v in pos))
            if progress:
                progress(sent, total, last_t)
            if (sent - 1) in pause_at and sent < total:
                pauses += 1
                here = tuple(int(v) for v in pos)
                if on_pause is not None:
                    on_pause(here, notes.get(sent - 1, "pause"))  # type: ignore[arg-type]
                elif controller is not None:
                    ctl.pause()
                if not _wait_while_paused(ctl):
                    halted = True
                    break
        if halted:
            break
    status, position, messages = _ending(_Tail(plan, last_t, last_d), p, ctl, sent, total,
                                         tuple(int(v) for v in pos), None, None)
    wall = (time.monotonic_ns() - wall0) / 1e9
    return RunResult(status, position, sent, last_t / 1e9, wall, pauses, p, messages, wall0)  # type: ignore[arg-type]


class _Cursor:
    """The position of a real-time run of a :class:`ChunkedPlan` as its writes go out, decoded a few at a time
    (at each progress report, pause and stop: never a whole chunk between two writes)."""

    def __init__(self, plan: ChunkedPlan) -> None:
        self.plan = plan
        self.clock, self.dirbit = axis_bits(plan.settings)
        self.pos = np.zeros(3, np.int64)
        self.last_data = 0
        self.last_t_ns = 0
        self.done = 0  # writes decoded into pos
        self.chunk: Optional[StepChunk] = None

    def chunks(self) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The plan's chunks, made ahead in a thread (:func:`_made_ahead`), noted as they start."""
        for chunk in _made_ahead(self.plan.chunks()):
            if self.chunk is not None:
                self.advance(self.chunk.first_write + len(self.chunk))
            self.chunk = chunk
            yield chunk.t_ns, chunk.data, chunk.strobe

    def advance(self, sent: int) -> tuple[int, int, int]:
        """Position (x, y, z) in steps after ``sent`` writes (of the current chunk; never behind ``done``)."""
        c = self.chunk
        if c is not None and sent > self.done:
            data = c.data[self.done - c.first_write: sent - c.first_write]
            decoded, _ = _decode(data, self.last_data, self.pos, self.clock, self.dirbit)
            self.pos = decoded[-1].copy()
            self.last_data = int(data[-1])
            self.last_t_ns = int(c.t_ns[sent - 1 - c.first_write])
            self.done = sent
            self.plan.live = (sent, tuple(int(v) for v in self.pos))
        return tuple(int(v) for v in self.pos)  # type: ignore[return-value]


def _made_ahead(chunks: Iterator[StepChunk], ahead: int = 2) -> Iterator[StepChunk]:
    """``chunks``, made by a thread up to ``ahead`` chunks before they are taken (the real-time runner sends
    one while the next is planned).  An error making them is raised where the chunk would have come."""
    q: "queue.Queue[Any]" = queue.Queue(maxsize=ahead)
    done = threading.Event()
    end = object()

    def make() -> None:
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


def _run_chunks_realtime(plan: ChunkedPlan, p: Port, controller: Optional[Controller],
                         progress: Optional[ProgressFn], on_pause: Optional[PauseFn]) -> RunResult:
    """:func:`run` of a :class:`ChunkedPlan` in real time: each write at its time, a chunk at a time (the next
    made by a thread meanwhile), in bounded memory; the same writes, pauses, lateness rule and stops as a
    whole plan's."""
    ctl = controller or Controller()
    switch_s = sys.getswitchinterval()
    sys.setswitchinterval(min(switch_s, _SWITCH_S))  # the thread making chunks yields the interpreter soon
    try:
        return _send_chunks_realtime(plan, p, ctl, controller is not None, progress, on_pause)
    finally:
        sys.setswitchinterval(switch_s)


def _send_chunks_realtime(plan: ChunkedPlan, p: Port, ctl: Controller, external: bool,
                          progress: Optional[ProgressFn], on_pause: Optional[PauseFn]) -> RunResult:
    cursor = _Cursor(plan)
    pauses = _Pauses(plan, ctl, on_pause, external, position_of=cursor.advance)
    wall0 = time.monotonic_ns()
    lateness = Lateness()
    total = len(plan)
    sent = _send_realtime(cursor.chunks(), total, p, ctl, pauses, progress, wall0, lateness,
                          on_progress=cursor.advance)
    position = cursor.advance(sent)
    status, position, messages = _ending(_Tail(plan, cursor.last_t_ns, cursor.last_data), p, ctl, sent, total,
                                         position, wall0, lateness)
    wall = (time.monotonic_ns() - wall0) / 1e9
    return RunResult(status, position, sent, cursor.last_t_ns / 1e9, wall, pauses.count, p, messages, wall0,
                     lateness)


def _wait_while_paused(ctl: Controller) -> bool:
    """Block while paused; False if a stop came meanwhile."""
    while ctl.paused and not ctl.halted:
        ctl._wake.wait(0.05)
        ctl._wake.clear()
    return not ctl.halted


def _position_after(plan: StepPlan, n_writes: int) -> tuple[int, int, int]:
    """Machine position in steps after the first ``n_writes`` writes of ``plan``."""
    if n_writes == 0:
        return (0, 0, 0)
    log = PinLog(plan.t_ns[:n_writes], plan.data[:n_writes], plan.strobe[:n_writes])
    return decode_pin_log(log, plan.settings).final_steps


def simulate_surface(job: Job) -> "np.ndarray":
    """The surface ``job`` would cut: run it on the mock, decode the pin log, carve with a point tool.

    Returns:
        ``(height_px, width_px)`` :class:`~cam.verify.pinlog.Surface`, depth in Z steps, drawing frame.
    """
    result = run(job, MockPort())
    motion = decode_pin_log(result.pin_log(), job.settings)
    return carve(motion, (job.height_px, job.width_px), job.settings, origin_px=job.origin_px)
