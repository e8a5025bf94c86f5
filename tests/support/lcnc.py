"""LinuxCNC as an independent reference: run its ``rs274`` interpreter and read its canonical moves.

Debian's ``linuxcnc-uspace`` package provides ``rs274``; ``rs274 -g FILE``
interprets a G-code program without a machine and prints one canonical
machining call per line (``STRAIGHT_TRAVERSE``, ``STRAIGHT_FEED``,
``ARC_FEED``, ...).  Tests and benchmarks use it to check `cam`'s G-code.
"""
from __future__ import annotations

import math
import re
import shutil
import subprocess
from dataclasses import dataclass

import numpy as np

from cam.errors import CamError

__all__ = ["CanonMove", "run_rs274", "parse_canonical", "canonical_polyline_mm", "carve_canonical", "bezier_mm",
           "mark_spline_ends", "canonical_motion", "canonical_time_s"]

_CALL = re.compile(r"^\s*\d+\s+N[.\d]*\s*(\w+)\((.*)\)\s*$")


@dataclass
class CanonMove:
    """One canonical move: ``kind`` is "traverse", "feed", "arc", "nurbs" or "spline"; positions in mm.

    rs274 prints a G5/G5.1 spline as ``NURBS_FEED(n, ...)``, without its points: a "nurbs" move knows only
    ``order`` (n control points, start and end included) and its end only in a program marked by
    :func:`mark_spline_ends` (else NaN).  A test that knows the inner control points makes it a "spline" move
    (the Bezier curve from the previous end through ``controls`` to ``end``).
    """

    kind: str
    end: tuple[float, float, float]
    center: tuple[float, float] | None = None
    rotation: int = 0  # ARC_FEED: >0 counter-clockwise turns, <0 clockwise
    plane: str = "XY"  # ARC_FEED: the arc's plane; ``center`` is in its (first, second) axes
    order: int = 0  # NURBS_FEED: its number of control points
    controls: tuple[tuple[float, float, float], ...] = ()  # a spline's inner control points, mm


def run_rs274(path: str, *, units_mm: bool = True, tool_table: str | None = None, var_file: str | None = None,
              ini: str | None = None, timeout_s: float = 600) -> str:
    """Canonical output of LinuxCNC's interpreter for a G-code file (raises CamError on an interpreter error).

    ``tool_table``, ``var_file`` (parameters; rs274 writes it back) and ``ini`` (for ``[RS274NGC]
    SUBROUTINE_PATH``) are rs274's ``-t``, ``-v`` and ``-i``.  rs274's machine units are inches: the tool
    table's lengths and the var file's positions are in inches.
    """
    exe = shutil.which("rs274")
    if exe is None:
        raise CamError("rs274 not found: install Debian's linuxcnc-uspace")
    args = [exe]
    for flag, value in (("-t", tool_table), ("-v", var_file), ("-i", ini)):
        if value is not None:
            args += [flag, str(value)]
    proc = subprocess.run([*args, "-g", str(path)], capture_output=True, text=True, timeout=timeout_s,
                          stdin=subprocess.DEVNULL)
    if proc.returncode != 0:
        msg = [ln for ln in proc.stderr.splitlines() if ln.strip() and ln.strip() != "executing"]
        raise CamError(f"{path}: rs274 reports: {' / '.join(msg[:2]) or 'error'}")
    return proc.stdout


def parse_canonical(text: str) -> list[CanonMove]:
    """Moves of rs274's canonical output in machine mm.

    Canonical coordinates are in the program frame; the G5x and G92 offsets
    that rs274 reports are added, and inches are converted to mm.  A "nurbs" move
    (``NURBS_FEED``) ends where a :func:`mark_spline_ends` message says.
    """
    moves: list[CanonMove] = []
    scale = 1.0
    g5x = [0.0, 0.0, 0.0]
    g92 = [0.0, 0.0, 0.0]
    tlo = [0.0, 0.0, 0.0]
    plane = "XY"
    for line in text.splitlines():
        m = _CALL.match(line)
        if not m:
            continue
        name, args = m.group(1), [a.strip() for a in m.group(2).split(",")]
        off = [a + b + c for a, b, c in zip(g5x, g92, tlo)]
        if name == "USE_LENGTH_UNITS":
            scale = 25.4 if "INCH" in args[0] else 1.0
        elif name == "SET_G5X_OFFSET":
            g5x = [float(a) * scale for a in args[1:4]]
        elif name == "USE_TOOL_LENGTH_OFFSET":
            tlo = [float(a) * scale for a in args[0].split()[:3]]
        elif name == "SET_XY_ROTATION" and float(args[0]) != 0:
            raise CamError(f"rs274 rotates the XY plane ({args[0]} degrees): not compared")
        elif name == "SET_G92_OFFSET":
            g92 = [float(a) * scale for a in args[0:3]]
        elif name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "STRAIGHT_PROBE"):
            # a probe (G38.x): rs274 alone has no probe and runs it to its target, as cam does without a machine
            x, y, z = (float(a) * scale + o for a, o in zip(args[:3], off))
            moves.append(CanonMove("traverse" if name == "STRAIGHT_TRAVERSE" else "feed", (x, y, z)))
        elif name == "SELECT_PLANE":
            plane = args[0].replace("CANON_PLANE_", "")
        elif name == "ARC_FEED":
            # ARC_FEED(first_end, second_end, first_axis, second_axis, rotation, axis_end_point, ...);
            # first/second are X/Y in the XY plane, Y/Z in YZ and Z/X in XZ
            e1, e2, c1, c2 = (float(a) * scale for a in args[:4])
            rot = int(args[4])
            e3 = float(args[5]) * scale
            first, second, third = {"XY": (0, 1, 2), "YZ": (1, 2, 0), "XZ": (2, 0, 1)}[plane]
            end = [0.0, 0.0, 0.0]
            end[first], end[second], end[third] = e1, e2, e3
            end = [v + o for v, o in zip(end, off)]
            moves.append(CanonMove("arc", tuple(end), (c1 + off[first], c2 + off[second]), rot, plane))
        elif name == "NURBS_FEED":
            moves.append(CanonMove("nurbs", (math.nan,) * 3, order=int(args[0])))
        elif name == "MESSAGE" and args[0].strip('"').split()[:1] == [SPLINE_END]:
            if not moves or moves[-1].kind != "nurbs":
                raise CamError(f"rs274 printed a spline end after no spline: {line}")
            moves[-1].end = tuple(float(a) * scale + o for a, o in zip(args[0].strip('"').split()[1:4], off))
    return moves


def bezier_mm(points_mm: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(len(t), 3)`` points of the Bezier curve with control points ``points_mm`` (``(k, 3)``, start first,
    end last) at parameters ``t``, by de Casteljau's repeated linear interpolation (not cam's formula)."""
    t = np.asarray(t, np.float64)[:, None, None]
    pts = np.broadcast_to(np.asarray(points_mm, np.float64)[None], (t.shape[0], *np.shape(points_mm)))
    while pts.shape[1] > 1:
        pts = pts[:, :-1] * (1 - t) + pts[:, 1:] * t
    return pts[:, 0]


_SPLINE_WORD = re.compile(r"g\s*0*5\s*(\.\s*1)?(?![\d.])", re.I)
SPLINE_END = "spline_end"


def mark_spline_ends(text: str) -> str:
    """The program with a ``(debug, spline_end #<_x> #<_y> #<_z>)`` line after each G5/G5.1 line, so that rs274
    prints where each spline ends (its ``NURBS_FEED`` has no points): :func:`parse_canonical` gives that
    ``nurbs`` move its end.  The comments change no motion."""
    out = []
    for line in text.splitlines():
        out.append(line)
        code = re.match(r"[^(;]*", line).group(0)
        if _SPLINE_WORD.search(code):
            out.append(f"(debug,{SPLINE_END} #<_x> #<_y> #<_z>)")
    return "\n".join(out) + "\n"


def canonical_polyline_mm(moves: list[CanonMove], *, max_chord_mm: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """The path as a dense polyline: ``(K, 3)`` mm points and ``(K,)`` bool "reached by a feed move".

    Arcs and splines are split into chords no longer than ``max_chord_mm``.  The start is (0, 0, 0).
    """
    pts = [(0.0, 0.0, 0.0)]
    feed = [False]
    for mv in moves:
        x0, y0, z0 = pts[-1]
        if mv.kind == "nurbs":
            raise CamError("rs274 prints NURBS_FEED without its points: make it a 'spline' move first")
        if mv.kind == "spline":
            ctrl = np.array([pts[-1], *mv.controls, mv.end], np.float64)
            n = max(1, int(math.ceil(np.linalg.norm(np.diff(ctrl, axis=0), axis=1).sum() / max_chord_mm)))
            pts.extend(map(tuple, bezier_mm(ctrl, np.arange(1, n + 1) / n)))
            feed.extend([True] * n)
            pts[-1] = mv.end
            continue
        if mv.kind != "arc":
            pts.append(mv.end)
            feed.append(mv.kind == "feed")
            continue
        first, second, third = {"XY": (0, 1, 2), "YZ": (1, 2, 0), "XZ": (2, 0, 1)}[mv.plane]
        p0 = (x0, y0, z0)
        u0, v0, w0 = p0[first], p0[second], p0[third]
        u1, v1, w1 = mv.end[first], mv.end[second], mv.end[third]
        cu, cv = mv.center
        a0 = math.atan2(v0 - cv, u0 - cu)
        a1 = math.atan2(v1 - cv, u1 - cu)
        r = math.hypot(u0 - cu, v0 - cv)
        if mv.rotation > 0:
            sweep = (a1 - a0) % (2 * math.pi) or 2 * math.pi
            sweep += 2 * math.pi * (mv.rotation - 1)
        else:
            sweep = -((a0 - a1) % (2 * math.pi) or 2 * math.pi)
            sweep -= 2 * math.pi * (-mv.rotation - 1)
        n = max(1, int(math.ceil(abs(sweep) * max(r, 1e-9) / max_chord_mm)))
        for k in range(1, n + 1):
            t = k / n
            a = a0 + sweep * t
            q = [0.0, 0.0, 0.0]
            q[first], q[second], q[third] = cu + r * math.cos(a), cv + r * math.sin(a), w0 + (w1 - w0) * t
            pts.append(tuple(q))
            feed.append(True)
        pts[-1] = mv.end
    return np.array(pts, np.float64), np.array(feed, bool)


def carve_canonical(
    moves: list[CanonMove],
    shape_hw: tuple[int, int],
    settings,
    *,
    flip_y: bool = False,
    samples_per_px: int = 4,
) -> np.ndarray:
    """Surface cut by a point tool following rs274's feed moves below Z = 0, on the drawing's pixel grid.

    Frames as in :mod:`cam.kinds.gcode_export`: column = X / (steps/px x mm/step), row = -Y / (...) (or +Y with
    ``flip_y``), depth in Z steps = -Z / mm/step Z.  Each feed segment is sampled at the midpoints of
    an even number (about ``samples_per_px x length_px``) of equal parts plus its end, so a
    move between pixel centres is never sampled exactly on a pixel border.

    Returns:
        ``(H, W)`` int64 deepest cut in Z steps (0 = untouched).
    """
    h, w = shape_hw
    mm_px = settings.steps_per_px_xy * settings.mm_per_step_xy
    y_sign = 1.0 if flip_y else -1.0
    pts, feed = canonical_polyline_mm(moves)
    out = np.zeros((h, w), np.int64)
    for i in np.flatnonzero(feed):
        p0, p1 = pts[i - 1], pts[i]
        if p0[2] >= 0 and p1[2] >= 0:
            continue
        length_px = max(abs(p1[0] - p0[0]), abs(p1[1] - p0[1])) / mm_px
        n = 2 * max(1, int(math.ceil(length_px * samples_per_px / 2)))  # even: no sample at t = 1/2
        t = np.concatenate([(np.arange(n) + 0.5) / n, [1.0]])
        seg = p0[None, :] + (p1 - p0)[None, :] * t[:, None]
        seg = seg[seg[:, 2] < 0]
        col = np.floor(seg[:, 0] / mm_px + 0.5).astype(np.int64)
        row = np.floor(y_sign * seg[:, 1] / mm_px + 0.5).astype(np.int64)
        depth = np.rint(-seg[:, 2] / settings.mm_per_step_z).astype(np.int64)
        inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        if not np.all(inside):
            j = int(np.flatnonzero(~inside)[0])
            raise CamError(f"G-code cuts below the surface outside the drawing at pixel ({col[j]}, {row[j]})")
        np.maximum.at(out, (row, col), depth)
    return out


def canonical_motion(moves: list[CanonMove], settings, *, flip_y: bool = False,
                     offset_steps: tuple[float, float, float] = (0.0, 0.0, 0.0), max_chord_mm: float = 0.005,
                     exact: bool = False):
    """rs274's moves (feeds and traverses: a traverse through the material cuts too) as the step positions a stepper machine passes through: a
    :class:`cam.verify.pinlog.Motion` for :func:`cam.verify.toolcarve.carve_tool` (only ``position_steps`` is
    meaningful; times are 0).

    Frames as in :mod:`cam.kinds.gcode_export`: x steps = X / mm/step, y steps = -Y / mm/step (+Y with
    ``flip_y``), z steps = -Z / mm/step Z, plus ``offset_steps``.  Each feed segment is split into as many
    equal parts as its longest axis has steps, every part's end rounded to the nearest step: for a move along an
    axis or at 45 degrees (the only cutting moves `cam` makes) these are exactly the positions of the DDA that
    `cam`'s step plan uses.

    Args:
        exact: raise CamError if a move's end at or below the surface (Z <= 0) is not on a step (within 1e-6
            step): `cam`'s own programs' are (its safe height need not be).
    """
    from cam.verify.pinlog import Motion

    pts, _ = canonical_polyline_mm(moves, max_chord_mm=max_chord_mm)
    scale = np.array([settings.mm_per_step_xy, (1.0 if flip_y else -1.0) * settings.mm_per_step_xy,
                      -settings.mm_per_step_z])
    f = pts / scale + np.asarray(offset_steps, np.float64)
    if exact:
        off = np.abs(f - np.rint(f)) * (pts[:, 2:3] <= 1e-9)
        if off.size and off.max() > 1e-6:
            k = int(np.argmax(off.max(axis=1)))
            raise CamError(f"canonical point {k} {pts[k].tolist()} mm is not on a step ({f[k].tolist()} steps)")
    out = [np.rint(f[:1]).astype(np.int64)]
    for i in range(1, len(f)):
        a, b = f[i - 1], f[i]
        n = max(1, int(math.ceil(np.abs(b - a).max() - 1e-9)))
        t = np.arange(1, n + 1, dtype=np.float64)[:, None] / n
        out.append(np.rint(a + (b - a) * t).astype(np.int64))
    p = np.vstack(out) if out else np.zeros((0, 3), np.int64)
    counts = np.abs(np.diff(p, axis=0)).sum(axis=0) if len(p) > 1 else np.zeros(3, np.int64)
    return Motion(t_ns=np.zeros(len(p), np.int64), position_steps=p, step_counts=counts.astype(np.int64))


def canonical_time_s(moves: list[CanonMove], settings, *, max_chord_mm: float = 0.05) -> float:
    """Machine time of rs274's path (feeds and traverses alike) on `cam`'s stepper machine at its top speeds: each
    segment takes ``max(|dx| / v_x, |dy| / v_y, |dz| / v_z)`` (the axes step together, as in `cam`'s step plan),
    no acceleration (which only favours the program measured)."""
    pts, _ = canonical_polyline_mm(moves, max_chord_mm=max_chord_mm)
    d = np.abs(np.diff(pts, axis=0))
    v = np.array([settings.max_speed_x_mm_s, settings.max_speed_y_mm_s, settings.max_speed_z_mm_s])
    return float((d / v).max(axis=1).sum()) if len(d) else 0.0
