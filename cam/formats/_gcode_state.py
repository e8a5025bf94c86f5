"""G-code in, the interpreter's state: where the tool is, the frames and offsets, parameters, modal state.

The base of the interpreter's parts (:mod:`._gcode_flow`, :mod:`._gcode_block`, :mod:`._gcode_motion`,
:mod:`._gcode_cycles`); :class:`cam.formats.gcode._Interp` puts them together.
"""
from __future__ import annotations

from operator import sub
from pathlib import Path

from ..errors import ParseError
from ..limits import MAX_TOOL_NUMBER
from ._gcode_data import CS_NAMES, GcodeMove, _Frame, _Source
from .ngc import NgcSyntaxError, evaluate


def _cs_param(cs: int) -> int:
    """The parameter holding the X offset of coordinate system ``cs`` (1 = G54 .. 9 = G59.3); Y and Z follow it.
    LinuxCNC's numbering: #5221 for G54, each system 20 further."""
    return 5221 + 20 * (cs - 1)


class _State:
    """Everything one run of a program keeps between its lines, and the words that read or set it."""

    comp_side = 0  # cutter radius compensation (:class:`~._gcode_comp._Comp`): +1 left, -1 right, 0 off
    comp_emitting = False  # its held moves are being recorded
    comp_exit = None  # after G40: the programmed position the exit move starts from (machine mm)
    probe_code = 382  # motion mode 38's probe (:mod:`._gcode_probe`): 382 (G38.2) or 383 (G38.3)
    probe_pending = None  # the probe given last: where it tripped is asked before the next line runs

    def __init__(self, source: _Source, *, home_g28_mm, home_g30_mm, tool_lengths_mm, subroutine_path,
                 max_lines, start_mm=(0.0, 0.0, 0.0), work_offsets_mm=None, active_offset="G54", probed=None) -> None:
        self.main = source
        self.probed = probed  # where a probe tripped, asked after it (:mod:`._gcode_probe`); None: at its target
        self.tool_lengths_mm = None if tool_lengths_mm is None else dict(tool_lengths_mm)
        # tool number -> diameter mm, for G41/G42 (a tool table's, see cam.formats.gcode.ToolTable; G10 L1 R)
        self.tool_diameters_mm = None if tool_lengths_mm is None else dict(getattr(tool_lengths_mm, "diameters_mm",
                                                                                   {}))
        self.path = [Path(p) for p in subroutine_path]
        self.max_lines = int(max_lines)
        self.files: dict[str, _Source] = {}
        self.moves: list[GcodeMove] = []
        self.batch_moves = 1 << 62  # the caller takes the moves once they are this many (after a line)
        self.warnings: list[str] = []
        self.coolant_warned = False
        self.sync_warned = False
        self.spindle_rpm = 0.0  # S: the machine has no spindle output; G33's feed is K x S
        self.spindle_on = False  # M3/M4 (on) or M5 (off): rs274 refuses G33 with the spindle stopped
        self.spindle = 0  # 3 (M3), 4 (M4) or 0 (M5): recorded with each move
        self.spindle_noted = False
        self.dialect_noted: set[str] = set()  # the grbl habits already warned about (one warning each)
        self.params: dict[int, float] = {}
        for i, a in enumerate(home_g28_mm):
            self.params[5161 + i] = float(a)
        for i, a in enumerate(home_g30_mm):
            self.params[5181 + i] = float(a)
        for name, zero in (work_offsets_mm or {}).items():
            if name not in CS_NAMES:
                raise ParseError(f"{source.name}: unknown work offset {str(name)[:20]!r} (known: "
                                 f"{', '.join(CS_NAMES)})")
            for i, v in enumerate(zero):
                self.params[_cs_param(CS_NAMES.index(name) + 1) + i] = float(v)
        if active_offset not in CS_NAMES:
            raise ParseError(f"{source.name}: unknown work offset {str(active_offset)[:20]!r} (known: "
                             f"{', '.join(CS_NAMES)})")
        self.globals: dict[str, float] = {}
        self.frames: list[_Frame] = [_Frame(source, -1, "", {})]
        self.start = tuple(float(v) for v in start_mm)  # where the tool stands at the start, machine mm
        self.mach = list(self.start)  # machine position, mm
        self.g92 = [0.0, 0.0, 0.0]
        self.tlo = 0.0
        self.cs = 1
        self.select_cs(CS_NAMES.index(active_offset) + 1)
        self.scale = 1.0
        self.absolute = True
        self.arc_absolute = False
        self.plane = "XY"
        self.motion: int | None = None
        self.g5_reflect: tuple[float, float] | None = None  # mm: the I J a G5 without them takes after a G5
        self.feed = 0.0  # mm/min (G94) or 1/min (G93)
        self.inverse_time = False
        self.retract_r = False  # G99
        self.cycle_il: float | None = None
        self.cycle: dict[str, float] = {}
        self.selected_tool = 0
        self.tool = 0
        self.saved_modal: dict | None = None
        self.resync: list[float] | None = None  # after M6: the program position the next block starts from
        self.line_no = 0
        self.source = source
        self.raw = ""
        self.value = 0.0
        self.value_returned = 0.0

    # -- errors and parameters --------------------------------------------------------------------------------

    def err(self, msg: str) -> ParseError:
        return ParseError(f'{self.source.name}:{self.line_no}: {msg} "{self.raw.strip()[:60]}"')

    def note_once(self, key: str, message: str) -> None:
        """Warn ``message`` (with ``file:line``) the first time the habit ``key`` is met in the run."""
        if key not in self.dialect_noted:
            self.dialect_noted.add(key)
            self.warnings.append(f"{self.source.name}:{self.line_no}: {message}")

    def emit(self, kind: str, mach=None, **kw) -> GcodeMove:
        """Record a move of ``kind`` ending at machine mm ``mach`` (default: where the tool is), given from
        where the tool stood at the start (:attr:`start`), with the spindle's state."""
        if self.comp_side and not self.comp_emitting:
            what = {"dwell": "a dwell (G4)", "pause": "a pause or a tool change", "spline": "a spline (G5/G5.1)"}.get(
                kind, "a move other than G0..G3 (a canned cycle, G28/G30, G53)")
            raise self.err(f"{what} while cutter compensation is on is not supported: turn it off (G40) first")
        end = tuple(map(sub, self.mach if mach is None else mach, self.start))
        move = GcodeMove(kind, self.line_no, end, spindle=self.spindle,  # type: ignore[arg-type]
                         spindle_rpm=self.spindle_rpm if self.spindle else 0.0, **kw)
        self.moves.append(move)
        return move

    def work_offsets_mm(self) -> dict[str, tuple[float, float, float]]:
        """Every work offset's zero as it stands now (machine mm, G-code axes), by name (G54..G59.3)."""
        return {name: tuple(self.g5x(k + 1)) for k, name in enumerate(CS_NAMES)}  # type: ignore[misc]

    def g5x(self, cs: int | None = None) -> list[float]:
        base = _cs_param(cs or self.cs)
        return [self.params.get(base + i, 0.0) for i in range(3)]

    def offsets(self) -> list[float]:
        """The active work offset plus G92 (and the tool length offset in Z), mm: as ``g5x()`` + ``g92``."""
        base = _cs_param(self.cs)
        get, g92 = self.params.get, self.g92
        return [get(base, 0.0) + g92[0], get(base + 1, 0.0) + g92[1], get(base + 2, 0.0) + g92[2] + self.tlo]

    def pos(self) -> list[float]:
        """The program position (mm, in the active coordinate system)."""
        return [m - o for m, o in zip(self.mach, self.offsets())]

    def read_param(self, ref: tuple) -> float:
        if ref[0] == "num":
            n = ref[1]
            if n != int(n) or not 1 <= n <= 5602:
                raise self.err(f"parameter number #{n:g} is out of range 1..5602")
            n = int(n)
            if n in (5420, 5421, 5422):
                return self.pos()[n - 5420] / self.scale
            if n == 5400:
                return float(self.tool)
            if n == 5403:
                return self.tlo
            if n in (5211, 5212, 5213):
                return self.g92[n - 5211] if self.params.get(5210, 0.0) else self.params.get(n, 0.0)
            return self.params.get(n, 0.0)
        name = ref[1]
        if name.startswith("_"):
            special = self._special(name)
            if special is not None:
                return special
            if name in self.globals:
                return self.globals[name]
        elif name in self.frames[-1].named:
            return self.frames[-1].named[name]
        raise self.err(f"named parameter '#<{name}>' is not defined")

    def _special(self, name: str) -> float | None:
        p = self.pos()
        table = {
            "_x": p[0] / self.scale, "_y": p[1] / self.scale, "_z": p[2] / self.scale,
            "_metric": float(self.scale == 1.0), "_imperial": float(self.scale != 1.0),
            "_absolute": float(self.absolute), "_incremental": float(not self.absolute),
            "_value": self.value, "_value_returned": self.value_returned, "_call_level": float(len(self.frames) - 1),
            "_feed": self.feed / (1.0 if self.inverse_time else self.scale), "_current_tool": float(self.tool),
            "_selected_tool": float(self.selected_tool), "_line": float(self.line_no),
            "_coord_system": float({1: 540, 2: 550, 3: 560, 4: 570, 5: 580, 6: 590, 7: 591, 8: 592, 9: 593}[self.cs]),
            "_plane": float({"XY": 170, "XZ": 180, "YZ": 190}[self.plane]),
            "_motion_mode": float(self.probe_code if self.motion == 38 else
                                  self.motion * 10 if self.motion is not None else 800),
            "_retract_r_plane": float(self.retract_r), "_retract_old_z": float(not self.retract_r),
            "_task": 0.0, "_rpm": self.spindle_rpm,
        }
        return table.get(name)

    def exists(self, ref: tuple) -> bool:
        if ref[0] == "num":
            return True
        name = ref[1]
        if name.startswith("_"):
            return self._special(name) is not None or name in self.globals
        return name in self.frames[-1].named

    def write_param(self, ref: tuple, value: float) -> None:
        if ref[0] == "num":
            n = ref[1]
            if n != int(n) or not 1 <= n <= 5602:
                raise self.err(f"parameter number #{n:g} is out of range 1..5602")
            if int(n) in (5400, 5403, 5420, 5421, 5422):
                raise self.err(f"parameter #{int(n)} is read-only")
            self.params[int(n)] = value
            return
        name = ref[1]
        if name.startswith("_"):
            if self._special(name) is not None:
                raise self.err(f"parameter '#<{name}>' is read-only")
            self.globals[name] = value
        else:
            self.frames[-1].named[name] = value

    def value_of(self, tree) -> float:
        try:
            return evaluate(tree, self.read_param, self.exists)
        except NgcSyntaxError as exc:
            raise self.err(str(exc)) from None


    # -- modal state, offsets ---------------------------------------------------------------------------------

    def modal_state(self) -> dict:
        return {"scale": self.scale, "absolute": self.absolute, "arc_absolute": self.arc_absolute,
                "plane": self.plane, "feed": self.feed, "inverse_time": self.inverse_time, "cs": self.cs,
                "retract_r": self.retract_r, "spindle_rpm": self.spindle_rpm, "spindle_on": self.spindle_on}

    def restore_modal(self, state: dict) -> None:
        for k, v in state.items():
            if k != "cs":
                setattr(self, k, v)
        self.select_cs(state["cs"])

    def select_cs(self, cs: int) -> None:
        self.cs = cs
        self.params[5220] = float(cs)

    def tool_length(self, codes: set[int], vals: dict[str, float]) -> None:
        if 431 in codes:
            if "z" not in vals:
                raise self.err("G43.1 needs a tool length 'Z'")
            self.tlo = vals.pop("z") * self.scale
            return
        tool = int(vals["h"]) if "h" in vals else self.tool
        if tool == 0:
            self.tlo = 0.0
            return
        if self.tool_lengths_mm is None:
            raise self.err(f"G43 needs the length of tool {tool}: give a tool table (--tool-table FILE)")
        if tool not in self.tool_lengths_mm:
            raise self.err(f"tool {tool} is not in the tool table")
        self.tlo = self.tool_lengths_mm[tool]

    def g10(self, vals: dict[str, float]) -> None:
        lv = vals.get("l")
        if lv not in (1, 2, 20):
            raise self.err("unsupported G10: only G10 L1 (tool length), L2 and L20 (work offsets)")
        if "p" not in vals or vals["p"] != int(vals["p"]):
            raise self.err(f"G10 L{lv:g} needs a whole number 'P'")
        p = int(vals["p"])
        if lv == 1:
            if not 1 <= p <= MAX_TOOL_NUMBER:
                raise self.err("G10 L1 needs a tool number 'P'")
            if self.tool_lengths_mm is None:
                self.tool_lengths_mm, self.tool_diameters_mm = {}, {}
            if "z" in vals:
                self.tool_lengths_mm[p] = vals["z"] * self.scale
            if "r" in vals:  # the tool's radius, as in rs274
                if vals["r"] < 0:
                    raise self.err("G10 L1 'R' (the tool's radius) must be 0 or more")
                self.tool_lengths_mm.setdefault(p, 0.0)
                self.tool_diameters_mm[p] = 2 * vals["r"] * self.scale
            for a in "xyz":
                vals.pop(a, None)
            return
        if not 0 <= p <= 9:
            raise self.err(f"G10 L{lv:g} P{p} names no coordinate system (P0..P9)")
        if vals.get("r", 0.0):
            raise self.err("coordinate system rotation (G10 L2 R) is not supported")
        cs = p or self.cs
        base = _cs_param(cs)
        for i, a in enumerate("xyz"):
            if a in vals:
                v = vals[a] * self.scale
                if lv == 2:
                    self.params[base + i] = v
                else:
                    self.params[base + i] = self.mach[i] - self.g92[i] - (self.tlo if i == 2 else 0.0) - v

    def set_g92(self, codes: set[int], vals: dict[str, float]) -> None:
        if 920 in codes:
            if not any(a in vals for a in "xyz"):
                raise self.err("G92 needs at least one of X, Y, Z")
            g = self.g5x()
            for i, a in enumerate("xyz"):
                if a in vals:
                    self.g92[i] = self.mach[i] - g[i] - (self.tlo if i == 2 else 0.0) - vals[a] * self.scale
            for i in range(3):
                self.params[5211 + i] = self.g92[i]
            self.params[5210] = 1.0
        elif 921 in codes:
            self.g92 = [0.0, 0.0, 0.0]
            for i in range(3):
                self.params[5211 + i] = 0.0
            self.params[5210] = 0.0
        elif 922 in codes:
            self.g92 = [0.0, 0.0, 0.0]
            self.params[5210] = 0.0
        else:
            self.g92 = [self.params.get(5211 + i, 0.0) for i in range(3)]
            self.params[5210] = 1.0

