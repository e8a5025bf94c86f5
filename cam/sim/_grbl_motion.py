"""The grbl emulator's planner and motion: blocks, look-ahead, trapezoids, hold, limits, homing.

A part of :class:`cam.sim.grbl.GrblEmulator`.
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

from ._grbl_base import STARVE_WINDOW_S, Block, ExecutedBlock


class _Motion:
    """The grbl emulator's planner and motion: blocks, look-ahead, trapezoids, hold, limits, homing."""

    settings: dict

    def _halt_motion(self) -> None:
        """Stop at once where the carriage is (a reset or a limit): the running block is logged as halted."""
        if self._planner:
            blk = self._planner[0]
            self._log_block(blk, list(self._pos), halted=True)
        self._planner.clear()
        self._v = 0.0
        self._s_mm = 0.0
        self._timed = None

    def _raise_alarm(self, code: int, critical: bool) -> None:
        self._halt_motion()
        self._alarm = True
        self._critical = critical
        self._state = "Alarm"
        self._actions = None
        self._event(f"ALARM:{code}")
        self._send(f"ALARM:{code}")
        if critical:
            self._send("[MSG:Reset to continue]")

    def _nominal_mm_s(self, blk: Block) -> float:
        if blk.jog:
            v = blk.feed_mm_min / 60.0
        elif blk.rapid:
            v = blk.max_mm_s * self._rapid_ov / 100.0
        else:
            v = blk.feed_mm_min / 60.0 * self._feed_ov / 100.0
        return max(1e-6, min(v, blk.max_mm_s))

    def _exit_speed(self) -> float:
        """The most the running block may leave at: a backward pass over the queue, ending stopped."""
        v_next = 0.0
        for k in range(len(self._planner) - 1, 0, -1):
            blk = self._planner[k]
            v_next = min(blk.junction_mm_s, self._nominal_mm_s(blk),
                         math.sqrt(v_next * v_next + 2.0 * blk.accel_mm_s2 * blk.length_mm))
        return v_next

    def _motion(self, dt: float) -> None:
        while dt > 1e-12 and self._planner and not self._critical:
            blk = self._planner[0]
            a = blk.accel_mm_s2
            rem = blk.length_mm - self._s_mm
            if self._hold:
                v1 = max(0.0, self._v - a * dt)
                if self._v <= 1e-9:
                    self._v = 0.0
                    if self._probe_stopped():  # a probe's trigger: the cycle ends where the carriage stopped
                        return
                    if self._state == "Jog":   # a jog cancel: stopped, the other jog blocks flushed
                        self._log_block(blk, list(self._pos), halted=True)
                        self._planner.clear()
                        self._s_mm = 0.0
                        self._hold = False
                        self._state = "Idle"
                        self._parser_pos = list(self._pos)
                    return
            else:
                v_exit = self._exit_speed()
                v_cap = math.sqrt(v_exit * v_exit + 2.0 * a * max(rem, 0.0))
                v_nom = self._nominal_mm_s(blk)
                v1 = min(self._v + a * dt, v_nom, v_cap)
                if v1 < self._v - a * dt and v_cap >= v_nom:   # an override dropped: slow down at a
                    v1 = self._v - a * dt
            ds = 0.5 * (self._v + v1) * dt
            if not self._hold:
                ds = max(ds, 0.5 * a * dt * dt)
            self._check_trip(blk, ds)
            self._check_probe(blk, ds)
            if self._critical:
                return
            if ds >= rem - 1e-12:
                v_avg = max(0.5 * (self._v + v1), 1e-9)
                used = min(dt, rem / v_avg) if rem > 0 else 0.0
                v_end = self._v + (v1 - self._v) * (used / dt)
                self._v = v_end if self._hold else min(v_end, self._exit_speed())
                self._finish_block()
                dt -= max(used, 1e-9)
                continue
            self._s_mm += ds
            self._v = v1
            self._pos = [blk.start[i] + blk.unit[i] * self._s_mm for i in range(3)]
            dt = 0.0

    def _check_trip(self, blk: Block, ds: float) -> None:
        if not self._trips:
            return
        trip = self._trips[0]
        if trip[0] > 0:
            return
        at = blk.length_mm * trip[1]
        if self._s_mm + ds >= at:
            self._trips.pop(0)
            self._s_mm = at
            self._pos = [blk.start[i] + blk.unit[i] * at for i in range(3)]
            self._raise_alarm(1, critical=True)

    def _finish_block(self) -> None:
        blk = self._planner.popleft()
        self._pos = list(blk.end)
        self._s_mm = 0.0
        self._log_block(blk, blk.end, halted=False)
        if self._trips and self._trips[0][0] > 0:
            self._trips[0][0] -= 1
        if self._state == "Run" and len(self._planner) <= 1 and self._dry_at is None:
            self._dry_at = self._t   # nothing queued behind the running block: no look-ahead left
        if not self._planner:
            self._v = 0.0
            if self._state in ("Run", "Jog"):
                self._state = "Idle"
        self._probe_block_done(blk)

    def _log_block(self, blk: Block, end: Sequence[float], halted: bool) -> None:
        row = ExecutedBlock(blk.line, blk.kind, tuple(blk.start), tuple(end), blk.feed_mm_min, self._t, halted)
        self._executed.append(row)  # type: ignore[arg-type]
        if self._log_file is not None:
            self._log_file.write(",".join(str(v) for v in (
                row.line, row.kind, *(f"{c:.4f}" for c in row.start_mm), *(f"{c:.4f}" for c in row.end_mm),
                f"{row.feed_mm_min:.1f}", f"{row.t_end_s:.4f}", int(halted))) + "\n")
            self._log_file.flush()

    def _make_block(self, line: int, kind: str, start: list[float], end: list[float], feed_mm_min: float,
                    rapid: bool, jog: bool = False) -> Optional[Block]:
        delta = [end[i] - start[i] for i in range(3)]
        length = math.sqrt(sum(d * d for d in delta))
        if length < 1e-9:
            return None
        unit = tuple(d / length for d in delta)
        accel = min(self.settings[120 + i] / abs(unit[i]) for i in range(3) if abs(unit[i]) > 1e-12)
        max_mm_s = min(self.settings[110 + i] / 60.0 / abs(unit[i]) for i in range(3) if abs(unit[i]) > 1e-12)
        if rapid:
            feed_mm_min = max_mm_s * 60.0
        return Block(line, kind, list(start), list(end), feed_mm_min, rapid, jog, length, unit,  # type: ignore[arg-type]
                      accel, max_mm_s)

    def _junction(self, prev: Block, blk: Block) -> float:
        """The entry speed a corner allows (``$11`` junction deviation, the centripetal model)."""
        cos_turn = -sum(prev.unit[i] * blk.unit[i] for i in range(3))   # cos of the angle between the paths
        if cos_turn > 0.999999:
            return 0.0          # a reversal
        a = min(prev.accel_mm_s2, blk.accel_mm_s2)
        limit = min(self._nominal_mm_s(prev), self._nominal_mm_s(blk))
        if cos_turn < -0.999999:
            return limit        # straight on
        sin_half = math.sqrt(0.5 * (1.0 - cos_turn))
        return min(limit, math.sqrt(a * self.settings[11] * sin_half / (1.0 - sin_half)))

    def _queue_block(self, blk: Block) -> None:
        if self._planner:
            blk.junction_mm_s = self._junction(self._planner[-1], blk)
        if self._dry_at is not None and not blk.jog and self._t - self._dry_at <= STARVE_WINDOW_S:
            self.starvation_count += 1
            self._event(f"planner starved: nothing queued behind the running block for "
                        f"{self._t - self._dry_at:.4f} s before line {blk.line}")
        self._dry_at = None
        self._planner.append(blk)
        if self._state == "Idle":
            self._state = "Jog" if blk.jog else "Run"

    def _start_homing(self) -> None:
        """``$H``: Z up to its switch, then X and Y together, at the seek rate, then the pull-off."""
        self._state = "Home"
        phys = [self._pos[i] + self._phys_offset[i] for i in range(3)]
        seek_mm_s = self.settings[25] / 60.0
        pull = self.settings[27]
        ends = []
        for i in range(3):
            travel = self.settings[130 + i]
            toward_minus = int(self.settings[23]) >> i & 1
            ends.append(-travel if toward_minus else 0.0)
        if any(abs(phys[i] - ends[i]) > 1.5 * self.settings[130 + i] for i in range(3)):
            self._timed = (self._t, lambda: self._raise_alarm(9, critical=False))
            return
        t_z = abs(ends[2] - phys[2]) / seek_mm_s
        t_xy = max(abs(ends[0] - phys[0]), abs(ends[1] - phys[1])) / seek_mm_s
        t_locate = 3 * 2 * pull / (self.settings[24] / 60.0)
        start = list(self._pos)

        def done() -> None:
            for i in range(3):
                toward_minus = int(self.settings[23]) >> i & 1
                machine = (-self.settings[130 + i] + pull) if toward_minus else -pull
                phys_end = ends[i] + (pull if toward_minus else -pull)
                self._phys_offset[i] = phys_end - machine
                self._pos[i] = machine
            self._parser_pos = list(self._pos)
            self._homed = True
            self._alarm = False
            self._state = "Idle"
            self._executed.append(ExecutedBlock(self._line_no, "home", tuple(start), tuple(self._pos),  # type: ignore[arg-type]
                                                self.settings[25], self._t))
            self._event("homed")
            self._run_startup_lines()

        self._timed = (self._t + t_z + t_xy + t_locate, done)

    def _within_travel(self, target: Sequence[float]) -> bool:
        # either homing direction leaves grbl's machine space at [-travel, 0] (zero at the switch end)
        return all(-self.settings[130 + i] - 1e-6 <= target[i] <= 1e-6 for i in range(3))

    def _start_dwell(self, seconds: float) -> None:
        self._timed = (self._t + seconds, lambda: None)
