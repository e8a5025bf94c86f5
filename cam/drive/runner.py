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

import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..errors import CamError
from ..job.model import Job
from ..verify.pinlog import PinLog, carve, decode_pin_log
from .ports import MockPort, Port, open_port
from .pins import axis_bits
from .steps import StepPlan, plan_steps

__all__ = ["Controller", "RunResult", "run", "simulate_surface", "FINISHED", "STOPPED", "EMERGENCY_STOPPED"]

FINISHED = "finished"
STOPPED = "stopped"
EMERGENCY_STOPPED = "emergency-stopped"

_BATCH = 16384
_SPIN_NS = 2_000_000  # busy-wait the last 2 ms before a write: sleeps here overshoot by up to ~1.5 ms (p99)
_PROGRESS_EVERY_NS = 50_000_000


class Controller:
    """Pause, resume, stop and emergency-stop a running job (thread-safe)."""

    def __init__(self) -> None:
        self._wake = threading.Event()
        self.paused = False
        self.stop_requested = False
        self.estop_requested = False

    def pause(self) -> None:
        """Hold before the next write; the tool stays where it is."""
        self.paused = True
        self._wake.set()

    def resume(self) -> None:
        """Continue a paused job."""
        self.paused = False
        self._wake.set()

    def stop(self) -> None:
        """Stop before the next step and lift the tool to the safe plane."""
        self.stop_requested = True
        self._wake.set()

    def emergency_stop(self) -> None:
        """Stop before the next step and send nothing more."""
        self.estop_requested = True
        self._wake.set()

    @property
    def halted(self) -> bool:
        return self.stop_requested or self.estop_requested


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
    plan = job if isinstance(job, StepPlan) else plan_steps(job)
    p = open_port(port)
    if not isinstance(p, MockPort):
        realtime = True
    external_controller = controller is not None
    ctl = controller or Controller()
    total = len(plan)
    pause_set = set(int(i) for i in plan.pause_writes)
    notes = dict(zip((int(i) for i in plan.pause_writes), plan.pause_notes or []))
    wall0 = time.monotonic_ns()
    sent = 0
    pauses = 0
    status = FINISHED
    messages: list[str] = []
    t_ns, data, strobe = plan.t_ns, plan.data, plan.strobe

    def do_pause() -> bool:
        """Honour a Pause At point; False if the job was stopped meanwhile."""
        nonlocal pauses
        pauses += 1
        pos = _position_after(plan, sent)
        if on_pause is not None:
            on_pause(pos, notes.get(sent - 1, "pause"))
        elif external_controller:
            ctl.pause()
        return _wait_while_paused(ctl)

    if not realtime:
        pause_points = sorted(pause_set)
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
            if (sent - 1) in pause_set and sent < total and not do_pause():
                break
        clock_now = lambda: int(t_ns[sent - 1]) if sent else 0  # noqa: E731
    else:
        t0 = wall0
        offset = 0
        last_progress = 0
        wake = ctl._wake
        while sent < total:
            target = t0 + offset + int(t_ns[sent])
            halted = False
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
            p.write(int(data[sent]), int(strobe[sent]), time.monotonic_ns() - t0)
            sent += 1
            if progress and (target - last_progress > _PROGRESS_EVERY_NS or sent == total):
                last_progress = target
                progress(sent, total, int(t_ns[sent - 1]))
            if (sent - 1) in pause_set and sent < total:
                began = time.monotonic_ns()
                if not do_pause():
                    break
                offset += time.monotonic_ns() - began
        clock_now = lambda: time.monotonic_ns() - t0  # noqa: E731

    position = _position_after(plan, sent)
    if sent < total:
        if ctl.estop_requested:
            status = EMERGENCY_STOPPED
            messages.append(f"emergency stop at {position} steps; nothing more was sent")
        else:
            status = STOPPED
            lift_t, lift_d = _lift_writes(plan, int(data[sent - 1]) if sent else 0, position[2])
            start = clock_now()
            if realtime:
                t_lift0 = time.monotonic_ns()
                for t_rel, d in zip(lift_t.tolist(), lift_d.tolist()):
                    while time.monotonic_ns() - t_lift0 < t_rel:
                        if ctl.estop_requested:
                            break
                        time.sleep(min(0.001, max(0.0, (t_rel - (time.monotonic_ns() - t_lift0)) / 1e9)))
                    if ctl.estop_requested:
                        status = EMERGENCY_STOPPED
                        break
                    p.write(d, int(strobe[0]), start + (time.monotonic_ns() - t_lift0))
                    if d & int(axis_bits(plan.settings)[0][2]):
                        position = (position[0], position[1], position[2] - 1)
            else:
                p.write_many(start + lift_t, lift_d, np.full(len(lift_t), strobe[0], np.uint8))
                position = (position[0], position[1], min(position[2], plan.safe_z_steps))
            messages.append(f"stopped at X={position[0]} Y={position[1]} steps; tool lifted to Z={position[2]}")
    if isinstance(p, MockPort):
        p._flush()
    wall = (time.monotonic_ns() - wall0) / 1e9
    machine = float(t_ns[sent - 1]) / 1e9 if sent else 0.0
    return RunResult(status, position, sent, machine, wall, pauses, p, messages, wall0)


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
