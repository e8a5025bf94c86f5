"""Plain-Python references of compiled or vectorised library code: the tests check the fast versions equal them."""
from __future__ import annotations

import cv2

import numpy as np

from cam.settings import MachineSettings
from cam.digitize.trace2d import NEIGHBOURS_2D, START_RULES
from cam.digitize.peel3d import NEIGHBOURS_3D
from cam.job.drawing import _gap_block
from cam.job.model import CUT, RETRACT, TRAVEL

__all__ = ["classify_reference", "check_rules_reference", "trace_curves_reference", "trace_layers_reference", "assemble_reference", "route_reference"]


def _walk(flat: bytearray, start: int, offsets: tuple[int, ...]) -> list[int]:
    """Greedy trace from ``start`` (already marked traced); marks and returns the pixels it visits."""
    path: list[int] = []
    cur = start
    while True:
        for off in offsets:
            q = cur + off
            if flat[q]:
                flat[q] = 0
                path.append(q)
                cur = q
                break
        else:
            return path


def _trace_ring(
    flat: bytearray, ring_idx: np.ndarray, start: int, offsets: tuple[int, ...], wp: int
) -> tuple[list[int], int]:
    """Trace all pixels of one ring; returns (path, number of greedy segments)."""
    path: list[int] = []
    segments = 0
    cur = start
    remaining = ring_idx
    while True:
        flat[cur] = 0
        path.append(cur)
        segments += 1
        walked = _walk(flat, cur, offsets)
        path.extend(walked)
        cur = walked[-1] if walked else cur
        view = np.frombuffer(flat, np.uint8)
        remaining = remaining[view[remaining] != 0]
        if len(remaining) == 0:
            return path, segments
        rr, cc = remaining // wp, remaining % wp
        d2 = (rr - cur // wp) ** 2 + (cc - cur % wp) ** 2
        cur = int(remaining[int(np.argmin(d2))])

def trace_curves_reference(
    black: np.ndarray,
    *,
    start: str = "top",
    tool_xy_px: tuple[int, int] = (0, 0),
) -> list[np.ndarray]:
    """:func:`cam.digitize.trace2d.trace_curves` as a plain loop (its docstring states the rules).

    ``black`` is an ``(H, W)`` bool mask, indexed ``[row, col]``.
    """
    if start not in START_RULES:
        raise ValueError(f"start must be one of {START_RULES}, got {start!r}")
    black = np.asarray(black, bool)
    h, w = black.shape
    wp = w + 2
    padded = np.zeros((h + 2, wp), np.uint8)
    padded[1:-1, 1:-1] = black
    flat = bytearray(padded.tobytes())
    offsets = tuple(dr * wp + dc for dr, dc in NEIGHBOURS_2D)

    scan = np.flatnonzero(padded)  # scan order: row-major
    scan_rows = scan // wp - 1
    scan_cols = scan % wp - 1
    flat_view = np.frombuffer(flat, np.uint8)  # live view: 0 once traced
    objects: list[np.ndarray] = []
    tool_x, tool_y = tool_xy_px
    cursor = 0  # next candidate in scan order (top mode)
    alive_idx = np.arange(len(scan))  # candidates not yet known traced (min-distance mode)

    while True:
        if start == "top":
            while cursor < len(scan) and not flat[scan[cursor]]:
                cursor += 1
            if cursor == len(scan):
                break
            s = int(scan[cursor])
        else:
            alive_idx = alive_idx[flat_view[scan[alive_idx]] != 0]
            if len(alive_idx) == 0:
                break
            d2 = (scan_cols[alive_idx] - tool_x) ** 2 + (scan_rows[alive_idx] - tool_y) ** 2
            s = int(scan[alive_idx[int(np.argmin(d2))]])
        flat[s] = 0
        arm1 = _walk(flat, s, offsets)
        arm2 = _walk(flat, s, offsets)  # non-empty only when s was mid-curve
        path = arm2[::-1] + [s] + arm1
        if arm2:
            first, last = path[0], path[-1]
            if start == "top":
                flip = last < first  # begin at the end first in scan order
            else:
                def d2_of(p: int) -> int:
                    return (p % wp - 1 - tool_x) ** 2 + (p // wp - 1 - tool_y) ** 2

                flip = d2_of(last) < d2_of(first)
            if flip:
                path.reverse()
        idx = np.asarray(path, np.int64)
        obj = np.empty((len(idx), 2), np.int32)
        obj[:, 0] = idx % wp - 1
        obj[:, 1] = idx // wp - 1
        objects.append(obj)
        if start != "thesis":  # the thesis's Min Distance rule: every object from the origin, tool_xy_px
            tool_x, tool_y = int(obj[-1, 0]), int(obj[-1, 1])
    return objects


def trace_layers_reference(layer: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Trace every layer into rings.

    Args:
        layer: ``(H, W)`` int32 layer numbers from :func:`peel_layers` (0 = not drawn).

    Returns:
        ``(objects, levels)``: one ``(n, 2)`` int32 ``(x, y)`` array per ring in
        cutting order (layer by layer), and ``(n_rings,)`` int32 layer of each ring.
    """
    h, w = layer.shape
    wp = w + 2
    padded = np.zeros((h + 2, wp), np.int32)
    padded[1:-1, 1:-1] = layer
    offsets = tuple(dr * wp + dc for dr, dc in NEIGHBOURS_3D)
    n_layers = int(layer.max())
    objects: list[np.ndarray] = []
    levels: list[int] = []
    if n_layers == 0:
        return objects, np.zeros(0, np.int32)
    flat_all = padded.ravel()
    order = np.argsort(flat_all, kind="stable")  # pixels grouped by layer, scan order within
    counts = np.bincount(flat_all, minlength=n_layers + 1)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    tool = None  # (row, col) in padded coordinates
    for k in range(1, n_layers + 1):
        idx = order[bounds[k] : bounds[k + 1]]  # scan order
        if len(idx) == 0:
            continue
        mask = np.zeros((h + 2) * wp, np.uint8)
        mask[idx] = 1
        n_rings, labels = cv2.connectedComponents(mask.reshape(h + 2, wp), connectivity=8)
        lab = labels.ravel()[idx]
        flat = bytearray(mask.tobytes())
        rings = {r: idx[lab == r] for r in range(1, n_rings)}
        first = True
        while rings:
            if first:
                r_id = int(lab[0])  # the ring of the layer's first pixel in scan order
                start = int(rings[r_id][0])
                first = False
            else:
                # the ring of the untraced pixel nearest the tool (ties: first in scan order)
                left = np.concatenate(list(rings.values()))
                left.sort()
                d2 = (left // wp - tool[0]) ** 2 + (left % wp - tool[1]) ** 2
                start = int(left[int(np.argmin(d2))])
                r_id = int(labels.ravel()[start])
            path, _ = _trace_ring(flat, rings.pop(r_id), start, offsets, wp)
            p = np.asarray(path, np.int64)
            obj = np.empty((len(p), 2), np.int32)
            obj[:, 0] = p % wp - 1
            obj[:, 1] = p // wp - 1
            objects.append(obj)
            levels.append(k)
            tool = (int(p[-1] // wp), int(p[-1] % wp))
    return objects, np.array(levels, np.int32)


def assemble_reference(
    targets: np.ndarray, pause_px: np.ndarray, asked: np.ndarray, settings: MachineSettings,
    surface: int, safe: int, oz: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The planner's rules as a plain loop over the targets; :func:`_assemble` does the same faster."""
    pts: list[tuple[int, int, int]] = []
    kinds: list[int] = []
    tgt: list[bool] = []
    pause: list[bool] = []

    def emit(x: int, y: int, z: int, kind: int, is_target: bool = False) -> None:
        if pts and pts[-1] == (x, y, z):
            if is_target:
                tgt[-1] = True
                kinds[-1] = CUT
                pause[-1] = pause[-1] or bool(pause_px[y, x])
            return
        pts.append((x, y, z))
        kinds.append(kind)
        tgt.append(is_target)
        pause.append(is_target and bool(pause_px[y, x]))

    cx, cy, cz = 0, 0, 0
    on_drawing = False  # is the tool at a drawing pixel at or above its asked depth
    for x, y, d in targets.tolist():
        if on_drawing and max(abs(x - cx), abs(y - cy)) <= 1:
            if d < cz:  # shallower: lift first, then move
                emit(cx, cy, d, CUT)
                cz = d
            emit(x, y, cz, CUT)  # move at the current depth ...
        else:
            for p in _gap_block((cx, cy, cz), (x, y, d), on_drawing, asked, settings, surface, safe, oz):
                emit(*p)
        emit(x, y, d, CUT, is_target=True)  # ... then plunge
        cx, cy, cz = x, y, d
        on_drawing = True
    # end of job: lift, travel home, back to Z = 0
    emit(cx, cy, safe, RETRACT)
    emit(0, 0, safe, TRAVEL)
    emit(0, 0, 0, TRAVEL)
    return (np.array(pts, np.int64).reshape(-1, 3), np.array(kinds, np.uint8), np.array(tgt, bool),
            np.array(pause, bool))


def route_reference(
    asked: np.ndarray, start: tuple[int, int], goal: tuple[int, int], z: int, max_len: int
) -> list[tuple[int, int]] | None:
    """The drawing planner's bridge search in plain Python (see :func:`cam.job.drawing._route`): breadth-first,
    level by level, each pixel's neighbours from the row above to the row below, left to right."""
    from cam.job.drawing import route_window  # the same window; the search here is the plain one

    if max_len < 2:
        return None
    sx, sy = start
    gx, gy = goal
    x0, y0, ok = route_window(asked, start, goal, z, max_len)
    hh, ww = ok.shape
    parent = {(sy - y0) * ww + (sx - x0): -1}
    frontier = [(sy - y0) * ww + (sx - x0)]
    goal_i = (gy - y0) * ww + (gx - x0)
    for _ in range(max_len):
        nxt = []
        for i in frontier:
            r, c = divmod(i, ww)
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    rr, cc = r + dr, c + dc
                    if (dr or dc) and 0 <= rr < hh and 0 <= cc < ww and ok[rr, cc] and rr * ww + cc not in parent:
                        j = rr * ww + cc
                        parent[j] = i
                        if j == goal_i:
                            path = []
                            while parent[j] != -1:
                                path.append(j)
                                j = parent[j]
                            return [(x0 + k % ww, y0 + k // ww) for k in reversed(path)]
                        nxt.append(j)
        if not nxt:
            return None
        frontier = nxt
    return None


def classify_reference(rgb: np.ndarray) -> np.ndarray:
    """The colour classes of ``cam.digitize.drawing`` in plain numpy (the code before the compiled pass):
    ``(H, W)`` uint8 classes, 255 where a pixel fits no class (the library raises there)."""
    from cam.digitize.drawing import (BLACK, BLUE, CHROMA_MIN, CONTOUR_Y_MAX, CORE_Y_MAX, DARK_MAX,
                                      HUE_TOLERANCE_DEG, RED, VALLEY_MIN, WHITE)

    from cam.digitize._classify import DIM_CHROMA_MIN, DIM_RED_Y_MIN, PALE_MIN

    rgb = np.asarray(rgb)
    c = rgb.astype(np.int32)
    chroma = c.max(axis=2) - c.min(axis=2)
    neutral = chroma < CHROMA_MIN
    out = np.full(rgb.shape[:2], 255, np.uint8)
    dark = c.sum(axis=2) < 3 * DARK_MAX
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    dim_red = (neutral & dark & (chroma >= DIM_CHROMA_MIN) & (r >= g) & (r >= b) & (2 * np.abs(g - b) <= chroma)
               & (299 * r + 587 * g + 114 * b >= 1000 * DIM_RED_Y_MIN))  # the interior's red, dimmed by JPEG
    out[neutral & dark] = BLACK
    out[neutral & ~dark] = WHITE
    coloured = ~neutral
    if np.any(coloured):
        hsv = cv2.cvtColor(np.ascontiguousarray(rgb.astype(np.uint8)), cv2.COLOR_RGB2HSV_FULL)
        hue_deg = hsv[..., 0].astype(np.float32) * (360.0 / 256.0)
        dist_red = np.minimum(hue_deg, 360.0 - hue_deg)
        dist_blue = np.abs(hue_deg - 240.0)
        out[coloured & (dist_red <= HUE_TOLERANCE_DEG)] = RED
        out[coloured & (dist_blue <= HUE_TOLERANCE_DEG)] = BLUE
    # pale red or unnamed colours beside white (JPEG's ringing by a black line) are white
    inside = np.pad(out == WHITE, 1, constant_values=False)
    beside_white = inside[:-2, 1:-1] | inside[2:, 1:-1] | inside[1:-1, :-2] | inside[1:-1, 2:]
    pale = ((out == RED) | (out == 255)) & (c.min(axis=2) >= PALE_MIN) & beside_white
    out[pale] = WHITE
    out[dim_red & ~beside_white] = RED  # beside white: the anti-aliased contour, black
    red = out == RED
    if not red.any():
        return out
    f = rgb.astype(np.float32)
    luma = 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]
    white = np.pad(out == WHITE, 1, constant_values=True)
    white4 = white[:-2, 1:-1] | white[2:, 1:-1] | white[1:-1, :-2] | white[1:-1, 2:]
    padded = np.pad(luma, 1, mode="edge")
    h, w = luma.shape
    valley = np.full(luma.shape, -np.inf, np.float32)
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        before = padded[1 - dr:1 - dr + h, 1 - dc:1 - dc + w]
        after = padded[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
        valley = np.maximum(valley, np.minimum(before, after) - luma)
    kernel = np.ones((3, 3), np.float32)
    kernel[1, 1] = 0
    red_neighbours = cv2.filter2D(red.astype(np.uint8), cv2.CV_16S, kernel, borderType=cv2.BORDER_CONSTANT)
    contour = red & (luma < CONTOUR_Y_MAX) & white4 & (red_neighbours > 0)  # first: dark red touching white
    black = (out == BLACK) | contour
    black_neighbours = cv2.filter2D(black.astype(np.uint8), cv2.CV_16S, np.ones((3, 3), np.float32),
                                    borderType=cv2.BORDER_CONSTANT)  # itself is red, not black: 8-neighbours
    crowded = black & (black_neighbours - black >= 2)  # black pixels with two black neighbours already
    next_to_crowded = cv2.filter2D(crowded.astype(np.uint8), cv2.CV_16S, kernel, borderType=cv2.BORDER_CONSTANT)
    line = (red & ~contour & (luma < CORE_Y_MAX) & (valley >= VALLEY_MIN) & (red_neighbours > 0)
            & (black_neighbours <= 2) & (next_to_crowded == 0))  # then thin dark lines, not beside the contour
    out[contour | line] = BLACK
    return out


def check_rules_reference(classes: np.ndarray) -> list[str]:
    """The thesis rule warnings of ``cam.digitize.drawing.check_rules`` in plain numpy (before the compiled pass)."""
    from cam.digitize.drawing import BLACK, neighbour_count

    def listing(points_rc):
        pts = ", ".join(f"({c}, {r})" for r, c in points_rc[:5])
        more = len(points_rc) - 5
        return pts + (f" and {more} more" if more > 0 else "")

    black = classes == BLACK
    warnings: list[str] = []
    n = neighbour_count(black)
    crowded = np.argwhere(black & (n > 2))
    if len(crowded):
        warnings.append(f"{len(crowded)} black pixel(s) have more than two black neighbours (lines must be 1 pixel "
                        "wide): " + listing(crowded))
    border = np.zeros_like(black)
    border[0, :] = border[-1, :] = True
    border[:, 0] = border[:, -1] = True
    on_border = np.argwhere(black & border)
    if len(on_border):
        warnings.append(f"{len(on_border)} black pixel(s) lie on the image border: " + listing(on_border))
    isolated = np.argwhere(black & (n == 0))
    if len(isolated):
        warnings.append(f"{len(isolated)} stray isolated black pixel(s): " + listing(isolated))
    return warnings


def port_writes(step_signed, period_ns, settings):
    """The port writes of step periods (plain numpy): the step plan's writes made without its kernels.

    ``step_signed``: ``(P, 3)`` the step each axis makes in each period (-1, 0, +1); ``period_ns``: ``(P,)``
    nominal lengths, lengthened by ``settings.ramp`` as :func:`cam.motion.ramps.ramp_periods` does.
    Returns ``(t_ns, data, strobe)``, each ``(1 + 2P,)``: a first write at t = 0 with the first directions,
    then per period the rising edges at mid-period and the next directions at its end.
    """
    import numpy as np

    from cam.pins import axis_bits
    from cam.motion.ramps import ramp_periods

    step_signed = np.asarray(step_signed)
    per = np.asarray(period_ns, np.int64)
    n = len(per)
    clock, dirbit = axis_bits(settings)
    dir_data = np.zeros(n, np.int64)
    clock_data = np.zeros(n, np.int64)
    rows = np.arange(n)
    for a in range(3):
        moving = step_signed[:, a] != 0
        last = np.maximum.accumulate(np.where(moving, rows, -1))
        positive = np.where(last >= 0, step_signed[np.maximum(last, 0), a] > 0, False)
        dir_data |= positive.astype(np.int64) * int(dirbit[a])
        clock_data |= moving.astype(np.int64) * int(clock[a])
    high, dirs = (dir_data | clock_data).astype(np.uint8), dir_data.astype(np.uint8)
    per = ramp_periods(high, per, settings)
    ends = np.cumsum(per)
    t_ns = np.zeros(1 + 2 * n, np.int64)
    data = np.zeros(1 + 2 * n, np.uint8)
    data[0] = dirs[0] if n else 0
    t_ns[1::2] = ends - per + per // 2
    data[1::2] = high
    t_ns[2::2] = ends
    data[2::2] = np.append(dirs[1:], dirs[-1:]) if n else dirs
    strobe = np.full(1 + 2 * n, 1 if settings.half_step else 0, np.uint8)
    return t_ns, data, strobe
