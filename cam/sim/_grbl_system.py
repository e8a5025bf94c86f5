"""The grbl emulator's line handling: the receive buffer's lines, ``ok``/``error``, waits, ``$`` commands.

A part of :class:`cam.sim.grbl.GrblEmulator`.
"""
from __future__ import annotations

from collections import deque
from typing import Optional

from ._grbl_base import (BOOL_SETTINGS, DEFAULT_SETTINGS, HELP, INT_SETTINGS, LINE_MAX_CHARS, MM_PER_INCH,
                         NUM_RE, SETTING_RE, GrblCodeError, fmt, preparse)


class _System:
    """The grbl emulator's line handling: the receive buffer's lines, ``ok``/``error``, waits, ``$`` commands."""

    settings: dict
    build_info: str

    def _take_line(self) -> Optional[str]:
        for i, b in enumerate(self._rx):
            if b in (10, 13):
                data = bytes(self._rx.popleft() for _ in range(i))
                self._rx.popleft()
                return data.decode("latin-1")
        return None

    def _service(self) -> None:
        while not self._critical:
            if self._actions is not None:
                if not self._run_actions():
                    return
                self._actions = None
                self._answer("ok")
                continue
            if self._timed is not None:
                return
            raw = self._take_line()
            if raw is None:
                return
            self._line_no += 1
            with_lock_row = (self._line_no, raw, "pending")
            self._lines.append(with_lock_row)
            self._answered = False
            try:
                self._handle_line(raw)
            except GrblCodeError as exc:
                self._actions = None
                self._answer(f"error:{exc.code}")
                continue
            if self._actions is None and not self._answered:
                self._answer("ok")

    def _answer(self, text: str) -> None:
        for k in range(len(self._lines) - 1, -1, -1):
            if self._lines[k][2] == "pending":
                self._lines[k] = (self._lines[k][0], self._lines[k][1], text)
                if text != "ok":
                    self._event(f"{text} for line {self._lines[k][0]}")
                break
        self._send(text)

    def _run_actions(self) -> bool:
        """Run the current line's actions in order; False while one has to wait (planner full, sync, pause)."""
        while self._actions:
            if self._timed is not None:
                return False
            kind, arg = self._actions[0]
            if kind == "block":
                if len(self._planner) >= self.planner_size:
                    return False
                self._queue_block(arg)
            elif kind == "sync":
                if self._planner or self._state == "Hold" or self._timed is not None:
                    return False
                self._dry_at = None
            elif kind == "call":
                arg()
                if self._actions is None:   # it raised an alarm: the line is not answered
                    return False
            elif kind == "probe":  # the probing cycle (cam.sim._grbl_probe): answered when it has ended
                if not self._probe_step(arg):
                    return False
            elif kind == "wait":   # a dwell or the homing cycle: the callable starts it and sets _timed
                arg()
                self._actions.popleft()
                return False
            elif kind == "pause":
                self._state = "Hold"
                self._hold = True
                self._pause = True
                self._actions[0] = ("paused", None)
                return False
            elif kind == "paused":
                if self._pause:
                    return False
            self._actions.popleft()
        return self._timed is None

    def _handle_line(self, raw: str) -> None:
        line = preparse(raw)
        if len(line) > LINE_MAX_CHARS:
            raise GrblCodeError(11)
        if not line:
            return
        if line.startswith("$"):
            self._system_command(line)
            return
        if self._state == "Alarm":
            raise GrblCodeError(9)
        if self._state == "Jog":
            raise GrblCodeError(9)
        self._parse_gcode(line, self._line_no, queue=True)

    def _require_idle(self) -> None:
        if self._state not in ("Idle", "Alarm", "Check"):
            raise GrblCodeError(8)

    def _system_command(self, line: str) -> None:
        """A ``$`` line: a report (``$`` ``$$`` ``$#`` ``$G`` ``$I`` ``$N``), the build info (``$I=``) or a control
        command."""
        self._dry_at = None
        if line == "$":
            self._send(HELP)
        elif line == "$$":
            self._require_idle()
            for key in sorted(self.settings):
                value = self.settings[key]
                self._send(f"${key}={int(value)}" if key in INT_SETTINGS else f"${key}={value:.3f}")
        elif line == "$#":
            self._require_idle()
            for k in range(6):
                self._send(f"[G{54 + k}:{fmt(self._wcs_mm[k])}]")
            self._send(f"[G28:{fmt(self._g28_mm)}]")
            self._send(f"[G30:{fmt(self._g30_mm)}]")
            self._send(f"[G92:{fmt(self._parser.g92_mm)}]")
            self._send(f"[TLO:{self._parser.tlo_mm:.3f}]")
            self._send(f"[PRB:{fmt(self._prb[0])}:{int(self._prb[1])}]")
        elif line == "$G":
            p = self._parser
            motion = {0: "G0", 1: "G1", 2: "G2", 3: "G3", 80: "G80"}.get(p.motion, f"G{p.motion:g}")
            coolant = " ".join(f"M{c}" for c in sorted(p.coolant)) or "M9"
            self._send(f"[GC:{motion} G{54 + p.wcs} G{p.plane} {'G20' if p.inches else 'G21'} "
                       f"{'G91' if p.incremental else 'G90'} {'G93' if p.inverse_time else 'G94'} M{p.spindle} "
                       f"{coolant} T{p.tool} F{p.feed / (MM_PER_INCH if p.inches else 1):.0f} S{p.rpm:.0f}]")
        elif line == "$I":  # grbl 1.1h: [VER:version.build:build info] then [OPT:...], in Idle or Alarm
            self._require_idle()
            self._send(f"[VER:1.1h.20190830:{self.build_info}]")
            self._send(f"[OPT:V,{self.planner_size},{self.rx_buffer_bytes}]")
        elif line.startswith("$I="):  # the build info kept in the EEPROM (upper case, no spaces: the pre-parser's)
            self._require_idle()
            self.build_info = line[3:]
        elif line == "$N":
            for k, text in enumerate(self._startup):
                self._send(f"$N{k}={text}")
        else:
            self._system_control(line)

    def _system_control(self, line: str) -> None:
        """``$Nx=``, ``$C``, ``$X``, ``$H``, ``$J=``, ``$RST=`` and ``$x=val``."""
        if line.startswith("$N") and "=" in line:
            self._require_idle()
            idx = line[2:line.index("=")]
            if idx not in ("0", "1"):
                raise GrblCodeError(3)
            self._startup[int(idx)] = line[line.index("=") + 1:]
        elif line == "$C":
            self._require_idle()
            if self._state == "Alarm":
                raise GrblCodeError(9)
            if self._check:
                self._send("[MSG:Disabled]")
                self._answer("ok")
                self._reset_state(alarm_code=None)
                self._answered = True  # after the reset, which clears it: grbl answers $C once, before its restart
                return
            self._check = True
            self._state = "Check"
            self._send("[MSG:Enabled]")
        elif line == "$X":
            self._dry_at = None
            if self._state == "Alarm":
                self._alarm = False
                self._state = "Idle"
                self._parser_pos = list(self._pos)
                self._send("[MSG:Caution: Unlocked]")
                self._event("alarm unlocked ($X)")
        elif line == "$H":
            self._require_idle()
            if not self.settings[22]:
                raise GrblCodeError(5)
            self._actions = deque([("wait", self._start_homing)])
        elif line.startswith("$J="):
            self._jog(line[3:])
        elif line.startswith("$RST="):
            self._require_idle()
            what = line[5:]
            if what not in ("$", "#", "*"):
                raise GrblCodeError(3)
            if what in ("$", "*"):
                self.settings = dict(DEFAULT_SETTINGS)
            if what in ("#", "*"):
                self._wcs_mm = [[0.0, 0.0, 0.0] for _ in range(6)]
                self._g28_mm = [0.0, 0.0, 0.0]
                self._g30_mm = [0.0, 0.0, 0.0]
            self._send("[MSG:Restoring defaults]")
        elif line == "$SLP":
            raise GrblCodeError(3)
        else:
            self._write_setting(line)

    def _write_setting(self, line: str) -> None:
        m = SETTING_RE.match(line)
        if not m:
            raise GrblCodeError(3)
        self._require_idle()
        key = int(m.group(1))
        if key not in self.settings:
            raise GrblCodeError(3)
        if not NUM_RE.match(m.group(2)):
            raise GrblCodeError(2)
        value = float(m.group(2))
        if value < 0:
            raise GrblCodeError(4)
        if key == 0 and value < 3:
            raise GrblCodeError(6)
        if key == 20 and value and not self.settings[22]:
            raise GrblCodeError(10)
        if key in BOOL_SETTINGS:
            value = 1.0 if value else 0.0
        self.settings[key] = float(int(value)) if key in INT_SETTINGS else value

    def _jog(self, text: str) -> None:
        if self._state not in ("Idle", "Jog"):
            raise GrblCodeError(8 if self._state != "Alarm" else 9)
        words = self._words(text)
        inches, incremental, machine = self._parser.inches, self._parser.incremental, False
        axes: dict[int, float] = {}
        feed: Optional[float] = None
        for letter, value in words:
            if letter == "G" and value in (20, 21, 90, 91, 53):
                if value in (20, 21):
                    inches = value == 20
                elif value in (90, 91):
                    incremental = value == 91
                else:
                    machine = True
            elif letter in "XYZ":
                axes["XYZ".index(letter)] = value
            elif letter == "F":
                feed = value
            else:
                raise GrblCodeError(16)
        if not axes:
            raise GrblCodeError(26)
        if feed is None or feed <= 0:
            raise GrblCodeError(22)
        scale = MM_PER_INCH if inches else 1.0
        base = list(self._parser_pos)
        target = list(base)
        wco = self._wco()
        for i, v in axes.items():
            v *= scale
            target[i] = base[i] + v if incremental else (v if machine else v + wco[i])
        if self.settings[20] and not self._within_travel(target):
            raise GrblCodeError(15)
        blk = self._make_block(self._line_no, "jog", base, target, feed * scale, rapid=False, jog=True)
        if blk is not None:
            self._parser_pos = list(target)
            self._actions = deque([("block", blk)])
