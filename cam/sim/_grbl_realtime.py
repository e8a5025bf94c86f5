"""The grbl emulator's real-time bytes (``?`` ``!`` ``~`` 0x18, overrides) and status reports.

A part of :class:`cam.sim.grbl.GrblEmulator`.
"""
from __future__ import annotations

from ._grbl_base import (MM_PER_INCH, RT_FLOOD, RT_HOLD, RT_JOG_CANCEL, RT_MIST, RT_RESET,
                         RT_SPINDLE_STOP, RT_START, RT_STATUS, fmt)


class _Realtime:
    """The grbl emulator's real-time bytes (``?`` ``!`` ``~`` 0x18, overrides) and status reports."""

    settings: dict

    def _rx_byte(self, b: int) -> None:
        if b == RT_RESET:
            self._soft_reset()
        elif b == RT_STATUS:
            if not self._critical and self._state != "Home":
                self._send(self._status_report())
        elif b == RT_HOLD:
            self._feed_hold()
        elif b == RT_START:
            self._cycle_start()
        elif b >= 0x80:
            self._realtime_ext(b)
        else:
            if len(self._rx) >= self.rx_buffer_bytes:
                self._service()  # the parser may free room first, as grbl's would between two bytes
            if len(self._rx) >= self.rx_buffer_bytes:
                self.overflow_bytes += 1
                self._event(f"serial receive buffer overflow: byte {b:#04x} lost")
                return
            self._rx.append(b)
            self.max_rx_bytes = max(self.max_rx_bytes, len(self._rx))

    def _realtime_ext(self, b: int) -> None:
        before = (self._feed_ov, self._rapid_ov, self._spindle_ov)
        if b == RT_JOG_CANCEL:
            if self._state == "Jog":
                self._hold = True
        elif 0x90 <= b <= 0x94:
            self._feed_ov = 100 if b == 0x90 else self._feed_ov + {0x91: 10, 0x92: -10, 0x93: 1, 0x94: -1}[b]
            self._feed_ov = min(200, max(10, self._feed_ov))
        elif 0x95 <= b <= 0x97:
            self._rapid_ov = {0x95: 100, 0x96: 50, 0x97: 25}[b]
        elif 0x99 <= b <= 0x9D:
            self._spindle_ov = 100 if b == 0x99 else self._spindle_ov + {0x9A: 10, 0x9B: -10, 0x9C: 1, 0x9D: -1}[b]
            self._spindle_ov = min(200, max(10, self._spindle_ov))
        elif b == RT_SPINDLE_STOP:
            if self._state == "Hold":
                self._spindle_stopped = not self._spindle_stopped
        elif b in (RT_FLOOD, RT_MIST):
            if self._state in ("Idle", "Run", "Hold"):
                self._parser.coolant ^= {8 if b == RT_FLOOD else 7}
        if (self._feed_ov, self._rapid_ov, self._spindle_ov) != before:
            self._ov_count = 0

    def _feed_hold(self) -> None:
        if self._state in ("Idle", "Run", "Jog"):
            if self._state != "Idle":
                self._event("feed hold")
            self._hold = True
            if self._state != "Jog":
                self._state = "Hold"
            self._dry_at = None

    def _cycle_start(self) -> None:
        if self._state == "Hold" and self._v <= 1e-9:
            self._hold = False
            self._pause = False
            self._spindle_stopped = False
            self._state = "Run" if self._planner else "Idle"

    def _state_text(self) -> str:
        if self._state == "Hold":
            return "Hold:1" if self._v > 1e-9 else "Hold:0"
        return self._state

    def _wco(self) -> list[float]:
        p = self._parser
        off = [self._wcs_mm[p.wcs][i] + p.g92_mm[i] for i in range(3)]
        off[2] += p.tlo_mm
        return off

    def _status_report(self) -> str:
        inches = bool(self.settings[13])
        mask = int(self.settings[10])
        wco = self._wco()
        if mask & 1:
            fields = [self._state_text(), "MPos:" + fmt(self._pos, inches)]
        else:
            fields = [self._state_text(), "WPos:" + fmt([self._pos[i] - wco[i] for i in range(3)], inches)]
        if mask & 2:
            fields.append(f"Bf:{self.planner_size - len(self._planner)},{self.rx_buffer_bytes - len(self._rx)}")
        feed = self._v * 60.0 / (MM_PER_INCH if inches else 1.0)
        fields.append(f"FS:{feed:.1f},{self._rpm_now():.0f}" if inches else f"FS:{feed:.0f},{self._rpm_now():.0f}")
        moving = self._state in ("Run", "Jog", "Hold", "Home")
        wco_now = self._wco_count <= 0
        if wco_now:
            fields.append("WCO:" + fmt(wco, inches))
            self._wco_count = 10 if moving else 30
        self._wco_count -= 1
        ov = (self._feed_ov, self._rapid_ov, self._spindle_ov)
        if self._ov_count <= 0 and not wco_now:
            fields.append("Ov:%d,%d,%d" % ov)
            acc = ("S" if self._parser.spindle == 3 else "C" if self._parser.spindle == 4 else "")
            acc += "".join(sorted(("F" if c == 8 else "M") for c in self._parser.coolant))
            if acc:
                fields.append("A:" + acc)
            self._ov_count = 10 if moving else 20
        elif not wco_now:
            self._ov_count -= 1
        return "<" + "|".join(fields) + ">"

    def _rpm_now(self) -> float:
        if self._parser.spindle == 5 or self._spindle_stopped:
            return 0.0
        return min(self.settings[30], self._parser.rpm * self._spindle_ov / 100.0)
