"""G-code in: run RS-274 programs from other CAM programs on the step/dir machine.

Supported (what grbl- and LinuxCNC-oriented CAM programs emit):

* motion: G0, G1, G2/G3 (XY-plane arcs by I/J or by R, full circles by I/J,
  helical Z), G4 (dwell, P seconds); G17 (the only plane: G18/G19 are errors);
* units and modes: G20/G21, G90/G91, G92 (set position), F, S;
* M3/M4/M5 (spindle; the step/dir machine has no spindle output: accepted,
  no motion), M6 with T (tool change: the job pauses), M0/M1 (pause),
  M2/M30 (end; later lines are not run);
* harmless modal words that CAM headers carry: G40, G49, G54, G61, G64, G80, G94;
* comments in ``( )`` and after ``;``, ``N`` line numbers, ``%`` lines, several words per line.

Anything else is a :class:`~cam.errors.ParseError` naming the line and the word.

Frames, as for G-code out (:mod:`cam.formats.gcode_export`): machine X steps = X mm / mm per step;
machine Y steps = -Y mm / mm per step (machine Y grows upward, the drawing
frame's rows downward; ``flip_y`` uses +Y); machine Z steps = -Z mm / mm per
step Z (+Z up in G-code, deeper is + in `cam`).  G-code (0, 0, 0) is the home.

Motion is generated so that every position the motors take is the nearest
step to a point on the programmed path: each period moves every axis by at
most one step, and each position is the rounding of the exact path point, so
the decoded motion stays within half a step (per axis) of the program.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ParseError, TravelError
from ..fileio import read_text
from ..settings import DEFAULT_SETTINGS, MachineSettings

__all__ = ["GcodeMove", "GcodeProgram", "parse_gcode", "load_gcode", "plan_gcode_steps", "GCODE_SUFFIXES"]

GCODE_SUFFIXES = (".ngc", ".nc", ".gcode", ".gc", ".g", ".tap", ".cnc")

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")
_NOOP_G = {40, 49, 54, 61, 64, 80, 94}


@dataclass
class GcodeMove:
    """One programmed move in mm (machine-independent, G-code frame: +Y up, +Z up).

    ``kind``: "rapid", "feed", "arc", "dwell" or "pause".  ``end`` is absolute mm;
    arcs carry ``center`` (mm) and ``clockwise``; dwell carries ``seconds``;
    pause carries ``note``; ``feed_mm_min`` applies to feed and arc moves.
    """

    kind: str
    line: int
    end: tuple[float, float, float]
    feed_mm_min: float = 0.0
    center: tuple[float, float] | None = None
    clockwise: bool = False
    turns: int = 1
    seconds: float = 0.0
    note: str = ""


@dataclass
class GcodeProgram:
    """Parsed program: moves in order, plus warnings; ``source`` names the file."""

    moves: list[GcodeMove]
    source: str = "<gcode>"
    warnings: list[str] = field(default_factory=list)


def _strip_comments(line: str, err) -> str:
    out = []
    depth = 0
    for ch in line:
        if ch == "(":
            if depth:
                raise err("nested comment '('")
            depth = 1
        elif ch == ")":
            if not depth:
                raise err("')' without '('")
            depth = 0
        elif ch == ";" and not depth:
            break
        elif not depth:
            out.append(ch)
    if depth:
        raise err("comment '(' is not closed on its line")
    return "".join(out)


@dataclass
class _Modal:
    """What a G-code program carries from one line to the next (mm, program frame)."""

    pos: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # absolute program position
    offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # G92: machine = program + offset
    scale: float = 1.0  # 25.4 in G20
    absolute: bool = True
    motion: int | None = None  # modal motion: 0, 1, 2, 3
    feed: float = 0.0
    tool: int = 0


def _line_words(body: str, err) -> tuple[list[float], list[float], dict[str, float]]:
    """The G codes, the M codes and the other words (letter -> value) of one line without comments."""
    leftover = _WORD.sub("", body).strip()
    if leftover:
        bad = leftover.split()[0]
        if bad[:1].isalpha():
            raise err(f"word '{bad}' has no number")
        raise err(f"cannot read '{bad}'")
    gs: list[float] = []
    ms: list[float] = []
    vals: dict[str, float] = {}
    for m in _WORD.finditer(body):
        k = m.group(1).upper()
        v = float(m.group(2))
        if k == "G":
            gs.append(v)
        elif k == "M":
            ms.append(v)
        elif k not in "XYZIJRFSTPN":
            raise err(f"unsupported word '{m.group(0).replace(' ', '')}'")
        elif k in vals:
            raise err(f"word '{k}' appears twice")
        else:
            vals[k] = v
    return gs, ms, vals


def _g_codes(gs: list[float], st: _Modal, err) -> tuple[bool, bool]:
    """Apply the modal G codes of one line; returns (dwell on this line, G92 on this line)."""
    dwell = False
    set_pos = False
    for g in gs:
        if g in (0, 1, 2, 3):
            st.motion = int(g)
        elif g == 4:
            dwell = True
        elif g == 17:
            pass
        elif g in (18, 19):
            raise err(f"unsupported plane 'G{g:g}' (only G17, the XY plane)")
        elif g == 20:
            st.scale = 25.4
        elif g == 21:
            st.scale = 1.0
        elif g == 90:
            st.absolute = True
        elif g == 91:
            st.absolute = False
        elif g == 92:
            set_pos = True
        elif g in _NOOP_G:
            pass
        else:
            raise err(f"unsupported word 'G{g:g}'")
    return dwell, set_pos


def _m_codes(ms: list[float], st: _Modal, line_no: int, moves: list[GcodeMove], err) -> bool:
    """Apply the M codes of one line (pauses join ``moves``); True at the end of the program."""
    end_program = False
    for mcode in ms:
        if mcode in (3, 4, 5):
            continue
        if mcode == 6:
            moves.append(GcodeMove("pause", line_no, tuple(st.pos), note=f"tool change: T{st.tool} (line {line_no})"))
        elif mcode in (0, 1):
            moves.append(GcodeMove("pause", line_no, tuple(st.pos),
                                   note=f"program pause M{mcode:g} (line {line_no})"))
        elif mcode in (2, 30):
            end_program = True
        else:
            raise err(f"unsupported word 'M{mcode:g}'")
    return end_program


def _set_position(vals: dict[str, float], st: _Modal, err) -> None:
    """G92: the named axes take the given program coordinates; the machine does not move."""
    if not any(a in vals for a in "XYZ"):
        raise err("G92 needs at least one of X, Y, Z")
    for i, a in enumerate("XYZ"):
        if a in vals:
            machine = st.pos[i] + st.offset[i]
            st.pos[i] = vals[a] * st.scale
            st.offset[i] = machine - st.pos[i]


def _arc_center(vals: dict[str, float], st: _Modal, target: list[float], err) -> tuple[float, float]:
    """Centre (program frame, mm) of the G2/G3 arc from ``st.pos`` to ``target``, by R or by I/J."""
    motion, scale = st.motion, st.scale
    x0, y0 = st.pos[0], st.pos[1]
    x1, y1 = target[0], target[1]
    if "R" in vals:
        if "I" in vals or "J" in vals:
            raise err("give either R or I/J for an arc, not both")
        r = vals["R"] * scale
        chord = math.hypot(x1 - x0, y1 - y0)
        if chord == 0:
            raise err("an R arc needs an end point different from its start")
        if abs(r) < chord / 2 - 1e-6 * max(1.0, chord):
            raise err(f"arc radius {abs(r) / scale:g} is too small to reach the end point")
        h = math.sqrt(max(0.0, r * r - chord * chord / 4))
        mx, my = (x0 + x1) / 2, (y0 + y1) / 2
        ux, uy = (x1 - x0) / chord, (y1 - y0) / chord
        # the centre lies right of the travel direction for G2 with R > 0 (and G3 with R < 0),
        # left of it otherwise; R > 0 picks the short arc, R < 0 the long one
        if (motion == 2) == (r > 0):
            return mx + h * uy, my - h * ux
        return mx - h * uy, my + h * ux
    if "I" not in vals and "J" not in vals:
        raise err(f"G{motion} arc needs I/J or R")
    cx, cy = x0 + vals.get("I", 0.0) * scale, y0 + vals.get("J", 0.0) * scale
    r0, r1 = math.hypot(x0 - cx, y0 - cy), math.hypot(x1 - cx, y1 - cy)
    if r0 == 0 or abs(r0 - r1) > max(0.002 * scale, 1e-3 * r0):
        raise err(f"arc end point is not on the circle (radius {r0 / scale:g} at the start, "
                  f"{r1 / scale:g} at the end)")
    return cx, cy


def _motion(vals: dict[str, float], axes: list[str], st: _Modal, line_no: int, err) -> GcodeMove | None:
    """The move of one line in the modal motion mode (None if the line names no axis or arc word)."""
    has_arc_words = any(k in vals for k in "IJR")
    if not axes and not has_arc_words:
        return None
    if st.motion is None:
        raise err("coordinates without a motion mode (G0, G1, G2 or G3)")
    target = list(st.pos)
    for i, a in enumerate("XYZ"):
        if a in vals:
            target[i] = vals[a] * st.scale if st.absolute else st.pos[i] + vals[a] * st.scale
    machine_end = tuple(t + o for t, o in zip(target, st.offset))
    if st.motion in (0, 1):
        if has_arc_words:
            raise err("I, J or R given without G2/G3")
        if st.motion == 1 and st.feed <= 0:
            raise err("G1 without a feed rate 'F'")
        move = GcodeMove("rapid" if st.motion == 0 else "feed", line_no, machine_end, feed_mm_min=st.feed)
    else:
        if st.feed <= 0:
            raise err(f"G{st.motion} without a feed rate 'F'")
        cx, cy = _arc_center(vals, st, target, err)
        move = GcodeMove("arc", line_no, machine_end, feed_mm_min=st.feed,
                         center=(cx + st.offset[0], cy + st.offset[1]), clockwise=(st.motion == 2))
    st.pos = target
    return move


def parse_gcode(text: str, *, source: str = "<gcode>") -> GcodeProgram:
    """Interpret G-code text into absolute moves in mm.

    Raises:
        ParseError: ``source:line: message "line text"`` for any unsupported or malformed word.
    """
    moves: list[GcodeMove] = []
    st = _Modal()
    warnings: list[str] = []
    for line_no, raw in enumerate(text.splitlines(), start=1):
        def err(msg: str, line_no: int = line_no, raw: str = raw) -> ParseError:
            return ParseError(f'{source}:{line_no}: {msg} "{raw.strip()[:60]}"')

        body = _strip_comments(raw, err).strip()
        if not body or body == "%" or body.startswith("/"):
            continue
        gs, ms, vals = _line_words(body, err)
        dwell, set_pos = _g_codes(gs, st, err)
        if "F" in vals:
            if vals["F"] <= 0:
                raise err("feed 'F' must be > 0")
            st.feed = vals["F"] * st.scale
        if "T" in vals:
            st.tool = int(vals["T"])
        end_program = _m_codes(ms, st, line_no, moves, err)
        if dwell:
            if "P" not in vals or vals["P"] < 0:
                raise err("G4 needs a dwell time 'P' in seconds")
            moves.append(GcodeMove("dwell", line_no, tuple(st.pos), seconds=vals["P"]))
        axes = [a for a in "XYZ" if a in vals]
        if set_pos:
            _set_position(vals, st, err)
            axes = []
        if end_program:
            break
        move = _motion(vals, axes, st, line_no, err)
        if move is not None:
            moves.append(move)
    return GcodeProgram(moves, source, warnings)


def load_gcode(path: str | os.PathLike) -> GcodeProgram:
    """Read and interpret a G-code file (errors name file:line)."""
    p, text = read_text(path, not_text="not a G-code text file")
    return parse_gcode(text, source=str(p))


def _arc_points(p0: np.ndarray, mv: GcodeMove, step_mm: np.ndarray) -> np.ndarray:
    """Points along an arc (mm), close enough that no axis moves more than 0.9 step between them."""
    cx, cy = mv.center
    x1, y1, z1 = mv.end
    a0 = math.atan2(p0[1] - cy, p0[0] - cx)
    a1 = math.atan2(y1 - cy, x1 - cx)
    r = math.hypot(p0[0] - cx, p0[1] - cy)
    if mv.clockwise:
        sweep = -((a0 - a1) % (2 * math.pi))
        if abs(sweep) < 1e-12:
            sweep = -2 * math.pi
    else:
        sweep = (a1 - a0) % (2 * math.pi)
        if abs(sweep) < 1e-12:
            sweep = 2 * math.pi
    arc_len_steps = abs(sweep) * r / min(step_mm[0], step_mm[1])
    dz_steps = abs(z1 - p0[2]) / step_mm[2]
    n = max(1, int(math.ceil(max(arc_len_steps, dz_steps) / 0.9)))
    t = np.arange(1, n + 1) / n
    a = a0 + sweep * t
    pts = np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), p0[2] + (z1 - p0[2]) * t])
    pts[-1] = (x1, y1, z1)
    return pts


def plan_gcode_steps(
    program: GcodeProgram, settings: MachineSettings = DEFAULT_SETTINGS, *, flip_y: bool = False
):
    """Step plan of a G-code program (see the module docstring for frames and accuracy).

    Rapids run at the configured step delays; feed moves at their F, never faster than the delays allow;
    then the speed ramps of ``settings.ramp`` lengthen periods (:mod:`cam.drive.ramps`), stopping at pauses.

    Raises:
        TravelError: a move leaves the machine travel (naming the line).
    """
    from ..drive.steps import StepPlan, port_writes

    s = settings
    # mm -> machine steps: X, -Y (or +Y), -Z
    to_steps = np.array([1 / s.mm_per_step_xy, (1 if flip_y else -1) / s.mm_per_step_xy, -1 / s.mm_per_step_z])
    step_mm = np.array([s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z])
    to_mm_y = s.mm_per_step_xy * (1 if flip_y else -1)
    lo = np.array([b[0] for b in s.travel.bounds_steps()], np.float64)
    hi = np.array([b[1] for b in s.travel.bounds_steps()], np.float64)
    min_period = {True: max(s.delay_xy_ns, s.delay_z_ns), False: s.delay_xy_ns}

    ideal_chunks: list[np.ndarray] = []  # ideal positions (steps, float) at the end of each period
    period_chunks: list[np.ndarray] = []
    pause_at_period: list[int] = []
    pause_notes: list[str] = []
    move_first: list[int] = []  # first period of each move and dwell (the 40-step ramp is per move)
    dwell_rests: list[int] = []  # the machine rests before these periods (both sides of a dwell)
    n_periods = 0
    cur = np.zeros(3)  # mm, G-code frame
    cur_steps_ideal = np.zeros(3)
    for mv in program.moves:
        if mv.kind == "pause":
            pause_at_period.append(n_periods)
            pause_notes.append(mv.note)
            continue
        if mv.kind == "dwell":
            if mv.seconds > 0:
                dwell_rests += [n_periods, n_periods + 1]  # at rest during the dwell
                move_first.append(n_periods)
                ideal_chunks.append(cur_steps_ideal[None, :].copy())
                period_chunks.append(np.array([int(round(mv.seconds * 1e9))], np.int64))
                n_periods += 1
            continue
        end = np.array(mv.end, np.float64)
        if mv.kind == "arc":
            way = _arc_points(cur, mv, step_mm)
        else:
            way = end[None, :]
        way_steps = way * to_steps
        outside = np.any((np.rint(way_steps) < lo) | (np.rint(way_steps) > hi), axis=1)
        if np.any(outside):
            q = way[int(np.flatnonzero(outside)[0])]
            x_mm = sorted(v * step_mm[0] + 0.0 for v in (lo[0], hi[0]))
            y_mm = sorted(to_mm_y * v + 0.0 for v in (lo[1], hi[1]))
            z_mm = sorted(-v * step_mm[2] + 0.0 for v in (lo[2], hi[2]))
            raise TravelError(
                f"{program.source}:{mv.line}: move to X{q[0]:.3f} Y{q[1]:.3f} Z{q[2]:.3f} mm leaves the machine "
                f"travel (X {x_mm[0]:g}..{x_mm[1]:g} mm, Y {y_mm[0]:g}..{y_mm[1]:g} mm, Z {z_mm[0]:g}..{z_mm[1]:g} mm)"
            )
        starts = np.vstack([cur_steps_ideal[None, :], way_steps[:-1]])
        d = way_steps - starts  # (W, 3) per sub-segment
        n_sub = np.maximum(1, np.ceil(np.abs(d).max(axis=1) - 1e-9).astype(np.int64))
        length_mm = float(np.sum(np.linalg.norm((way - np.vstack([cur[None, :], way[:-1]])), axis=1)))
        total_periods = int(n_sub.sum())
        uses_z = bool(np.any(d[:, 2] != 0))
        floor_ns = min_period[uses_z] if bool(np.any(d[:, :2] != 0)) else s.delay_z_ns
        if mv.kind == "rapid" or mv.feed_mm_min <= 0:
            per_ns = floor_ns
        else:
            per_ns = max(floor_ns, int(round(length_mm / (mv.feed_mm_min / 60.0) * 1e9 / total_periods)))
        seg = np.repeat(np.arange(len(d)), n_sub)
        first = np.cumsum(n_sub) - n_sub
        k = np.arange(total_periods) - np.repeat(first, n_sub) + 1
        ideal = starts[seg] + d[seg] * (k / n_sub[seg])[:, None]
        ideal_chunks.append(ideal)
        move_first.append(n_periods)
        period_chunks.append(np.full(total_periods, per_ns, np.int64))
        n_periods += total_periods
        cur = end
        cur_steps_ideal = way_steps[-1]
    if ideal_chunks:
        ideal_all = np.vstack(ideal_chunks)
        periods = np.concatenate(period_chunks)
    else:
        ideal_all = np.zeros((0, 3))
        periods = np.zeros(0, np.int64)
    positions = np.floor(ideal_all + 0.5).astype(np.int64)  # nearest step to the exact path point
    signed = np.diff(np.vstack([np.zeros((1, 3), np.int64), positions]), axis=0)
    assert signed.size == 0 or np.abs(signed).max() <= 1, "a period moved an axis by more than one step"
    t_ns, data, strobe = port_writes(signed, periods, s, move_first=np.array(move_first, np.int64),
                                     stops=np.array(pause_at_period + dwell_rests, np.int64))
    end_steps = tuple(int(v) for v in positions[-1]) if len(positions) else (0, 0, 0)
    return StepPlan(
        t_ns=t_ns,
        data=data,
        strobe=strobe,
        point_write=np.zeros(0, np.int64),
        pause_writes=2 * np.asarray(pause_at_period, np.int64),
        steps_total=np.abs(signed).sum(axis=0),
        settings=s,
        end_steps=end_steps,  # type: ignore[arg-type]
        safe_z_steps=0,
        warnings=list(program.warnings),
        pause_notes=pause_notes,
    )
