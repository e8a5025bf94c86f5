"""Generate the sample drawings used by ``cam``'s docs, tests and benchmarks.

Run ``python samples/make_samples.py [--out DIR]`` (default: this folder).
The output is deterministic: the same bytes on every run.

Colours (8-bit RGB): white (255, 255, 255) background, black (0, 0, 0)
1-pixel curves, red (255, 0, 0) interiors of 3D objects.

2D drawings (black curves on white):

* ``ellipse.png``    one closed ellipse, black extent exactly 286 x 144 px,
  7 px white margin on every side (thesis Figure 5.1), image 300 x 158.
* ``two_curves.png`` two open curves (thesis Figure 4.14): a left arch (an
  upside-down U) and a right vertical S.  On the LEFT ARCH the topmost pixels
  are at the apex (mid-curve) and the black pixel nearest the origin (0, 0)
  lies on its left flank, also mid-curve, not at an end.
* ``gear.png``       a 20-tooth gear outline plus a circular hub hole (2 closed
  curves, thesis Figure 5.3).
* ``word.png``       the word "CNC" (thesis Figure 5.8) in single-stroke
  letters drawn here (C = elliptic arc, N = 3-segment polyline): 3 open curves.
* ``stamp.png``      an outer circle, an inner circle and a five-pointed star
  (3 nested closed curves).

3D drawings (one closed black contour, solid red strictly inside it):

* ``disc.png`` (r = 40 px), ``pyramid.png`` (80 x 80 px square),
  ``heart.png`` (101 x 92 px), ``dumbbell.png`` (two r = 30 px discs
  joined by a neck 7 px wide outside-to-outside), ``ring.png`` (an annulus
  between circles of r = 45 px and r = 18 px; the hole stays white, so it has
  2 closed contours).

Every curve obeys the thesis drawing rules, checked at the end of
:func:`make_all` on the files as written: each black pixel has 1 or 2 black
8-neighbours, nothing black on the image border, every 8-connected black
component is a simple path (2 endpoints) or a simple cycle (no endpoints),
and no red pixel is 4-adjacent to a white one.
"""
from __future__ import annotations

import argparse
import math
import pathlib
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import cv2
import numpy as np

WHITE_RGB = (255, 255, 255)
BLACK_RGB = (0, 0, 0)
RED_RGB = (255, 0, 0)

# The 8 neighbours of a pixel as (d_row, d_col), walking round the ring.
RING_OFFSETS = ((-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1))
# Largest distance in px between two consecutive samples when rasterising.
SAMPLE_STEP_PX = 0.25

PointsXY = Sequence[tuple[float, float]]


# --------------------------------------------------------------------------
# Rasterising curves
# --------------------------------------------------------------------------

def round_half_up(values: np.ndarray) -> np.ndarray:
    """Round to the nearest integer, halves upwards (platform independent)."""
    return np.floor(np.asarray(values, np.float64) + 0.5).astype(np.int64)


def draw_polyline(mask: np.ndarray, points_xy: PointsXY, *, closed: bool) -> None:
    """Set the pixels of a polyline in ``mask`` (indexed ``[row, col]``).

    Every segment is sampled at most :data:`SAMPLE_STEP_PX` apart and each
    sample is rounded to its nearest pixel, so consecutive pixels are always
    8-adjacent.  The result may have staircase corners; see :func:`prune`.
    """
    pts = np.asarray(points_xy, np.float64)
    if closed:
        pts = np.vstack([pts, pts[:1]])
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        length_px = math.hypot(x1 - x0, y1 - y0)
        n_samples = max(2, int(math.ceil(length_px / SAMPLE_STEP_PX)) + 1)
        t = np.linspace(0.0, 1.0, n_samples)
        cols = round_half_up(x0 + (x1 - x0) * t)
        rows = round_half_up(y0 + (y1 - y0) * t)
        mask[rows, cols] = True


def arc_points(centre_xy: tuple[float, float], radius_px: float, start_rad: float,
               end_rad: float, n_points: int = 0) -> list[tuple[float, float]]:
    """Points on a circular arc from ``start_rad`` to ``end_rad`` (image axes, y down)."""
    if n_points <= 0:
        n_points = max(2, int(math.ceil(abs(end_rad - start_rad) * radius_px / 0.5)) + 1)
    cx, cy = centre_xy
    return [(cx + radius_px * math.cos(a), cy + radius_px * math.sin(a))
            for a in np.linspace(start_rad, end_rad, n_points)]


def circle_points(centre_xy: tuple[float, float], radius_px: float) -> list[tuple[float, float]]:
    """Points round a full circle (without repeating the first one)."""
    return arc_points(centre_xy, radius_px, 0.0, 2 * math.pi)[:-1]


def ellipse_points(centre_xy: tuple[float, float], semi_x_px: float,
                   semi_y_px: float, n_points: int = 2000) -> list[tuple[float, float]]:
    """Points round an axis-aligned ellipse (without repeating the first one)."""
    cx, cy = centre_xy
    angles = np.linspace(0.0, 2 * math.pi, n_points, endpoint=False)
    return [(cx + semi_x_px * math.cos(a), cy + semi_y_px * math.sin(a)) for a in angles]


# --------------------------------------------------------------------------
# Making curves rule-conforming
# --------------------------------------------------------------------------

def black_degree(mask: np.ndarray, row: int, col: int) -> int:
    """Number of black 8-neighbours of an interior pixel."""
    return sum(bool(mask[row + dr, col + dc]) for dr, dc in RING_OFFSETS)


def _count_components(cells: list[tuple[int, int]], adjacent: Callable[[tuple[int, int], tuple[int, int]], bool]) -> list[set]:
    """Connected components of a few cells under the ``adjacent`` relation."""
    components: list[set] = []
    unseen = list(cells)
    while unseen:
        stack = [unseen.pop(0)]
        comp = set(stack)
        while stack:
            cell = stack.pop()
            for other in list(unseen):
                if adjacent(cell, other):
                    unseen.remove(other)
                    comp.add(other)
                    stack.append(other)
        components.append(comp)
    return components


def is_simple_point(mask: np.ndarray, row: int, col: int) -> bool:
    """True when removing the black pixel keeps the topology unchanged.

    Its black 8-neighbours must form one 8-connected group (the curve stays
    connected) and its white 4-neighbours one 4-connected group within the
    3x3 neighbourhood (no new hole is opened and no two white regions merge).
    """
    black = [(dr, dc) for dr, dc in RING_OFFSETS if mask[row + dr, col + dc]]
    white = [(dr, dc) for dr, dc in RING_OFFSETS if not mask[row + dr, col + dc]]
    eight = lambda a, b: max(abs(a[0] - b[0]), abs(a[1] - b[1])) == 1
    four = lambda a, b: abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1
    if len(_count_components(black, eight)) != 1:
        return False
    white_touching = [comp for comp in _count_components(white, four)
                      if any(abs(dr) + abs(dc) == 1 for dr, dc in comp)]
    return len(white_touching) == 1


def is_prunable(mask: np.ndarray, row: int, col: int) -> bool:
    """A redundant black pixel: a simple point at a crowded spot, not an endpoint.

    Crowded means it has more than 2 black neighbours itself, or it is the
    outer corner of a staircase (2 neighbours, one of them with more than 2).
    """
    degree = black_degree(mask, row, col)
    if degree < 2:
        return False  # never remove endpoints (or isolated pixels)
    if degree == 2:
        crowded_neighbour = any(
            mask[row + dr, col + dc] and black_degree(mask, row + dr, col + dc) > 2
            for dr, dc in RING_OFFSETS)
        if not crowded_neighbour:
            return False
    return is_simple_point(mask, row, col)


def prune(mask: np.ndarray) -> np.ndarray:
    """Thin a rasterised curve mask to 1-pixel curves (returns a new mask).

    Pixels are visited in raster order and removed one at a time while they
    are prunable (see :func:`is_prunable`); pixels with more than 2 neighbours
    go first, then staircase corners; repeated until nothing changes.
    Deterministic for a given input.
    """
    work = np.pad(mask.astype(bool), 1)
    for _ in range(10_000):
        changed = False
        for want_crowded in (True, False):
            for row, col in np.argwhere(work):
                if not work[row, col]:
                    continue
                crowded = black_degree(work, row, col) > 2
                if crowded == want_crowded and is_prunable(work, row, col):
                    work[row, col] = False
                    changed = True
            if changed:
                break
        if not changed:
            return work[1:-1, 1:-1].copy()
    raise RuntimeError("prune did not converge")


MAX_SPUR_PX = 3


def trace_spur(mask: np.ndarray, row: int, col: int, max_len_px: int) -> list[tuple[int, int]] | None:
    """Pixels of the branch from endpoint ``(row, col)`` up to a junction.

    Returns them (junction excluded) when a pixel with more than 2 black
    neighbours is reached within ``max_len_px`` pixels, else ``None``.
    """
    branch = [(row, col)]
    prev, cur = None, (row, col)
    while len(branch) <= max_len_px:
        nexts = [(cur[0] + dr, cur[1] + dc) for dr, dc in RING_OFFSETS
                 if mask[cur[0] + dr, cur[1] + dc] and (cur[0] + dr, cur[1] + dc) != prev]
        if len(nexts) != 1:
            return None  # another endpoint, or already at a junction-like spot
        nxt = nexts[0]
        if black_degree(mask, *nxt) > 2:
            return branch
        prev, cur = cur, nxt
        branch.append(cur)
    return None


def remove_spurs(mask: np.ndarray, max_len_px: int = MAX_SPUR_PX) -> tuple[np.ndarray, bool]:
    """Delete short branches (<= ``max_len_px``) that end at a junction.

    They appear where two strokes meet at an acute angle and merge for a few
    pixels (the corners of an "N").  Returns the new mask and whether it changed.
    """
    work = np.pad(mask.astype(bool), 1)
    changed = False
    for row, col in np.argwhere(work):
        if work[row, col] and black_degree(work, row, col) == 1:
            spur = trace_spur(work, row, col, max_len_px)
            if spur:
                for r, c in spur:
                    work[r, c] = False
                changed = True
    return work[1:-1, 1:-1].copy(), changed


def thin_curves(mask: np.ndarray) -> np.ndarray:
    """Make rasterised curves rule-conforming: prune, trim spurs, repeat."""
    mask = prune(mask)
    while True:
        mask, changed = remove_spurs(mask)
        if not changed:
            return mask
        mask = prune(mask)


def fill_interior(black: np.ndarray, hole_seeds_rc: Iterable[tuple[int, int]] = ()) -> np.ndarray:
    """Red mask: every non-black pixel strictly inside the closed contours.

    The non-black pixels are split into 4-connected regions (an 8-connected
    black curve separates them); regions that touch the image border or hold a
    hole seed ``(row, col)`` stay white, all other regions become red.
    """
    n_labels, labels = cv2.connectedComponents((~black).astype(np.uint8), connectivity=4)
    border = np.concatenate([labels[0, :], labels[-1, :], labels[:, 0], labels[:, -1]])
    white_labels = set(int(v) for v in border) | {int(labels[r, c]) for r, c in hole_seeds_rc}
    white_labels.discard(0)  # label 0 is the black curve itself
    red = ~black & ~np.isin(labels, sorted(white_labels))
    return red


def to_rgb(black: np.ndarray, red: np.ndarray | None = None) -> np.ndarray:
    """Compose an (H, W, 3) uint8 RGB image from black (and red) masks."""
    rgb = np.full(black.shape + (3,), 255, np.uint8)
    if red is not None:
        rgb[red] = RED_RGB
    rgb[black] = BLACK_RGB
    return rgb


def write_png(path: pathlib.Path, rgb: np.ndarray) -> pathlib.Path:
    """Write an RGB array as a PNG with cv2 (which wants BGR)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"could not write {path}")
    return path


def curves_mask(shape_hw: tuple[int, int], polylines: Iterable[tuple[PointsXY, bool]]) -> np.ndarray:
    """Rasterise ``(points_xy, closed)`` polylines into one mask, then thin it."""
    mask = np.zeros(shape_hw, bool)
    for points_xy, closed in polylines:
        draw_polyline(mask, points_xy, closed=closed)
    return thin_curves(mask)


# --------------------------------------------------------------------------
# 2D drawings
# --------------------------------------------------------------------------

ELLIPSE_WIDTH_PX, ELLIPSE_HEIGHT_PX, ELLIPSE_MARGIN_PX = 286, 144, 7


def draw_ellipse() -> np.ndarray:
    """Thesis Figure 5.1: a 286 x 144 px ellipse with a 7 px margin."""
    width_px = ELLIPSE_WIDTH_PX + 2 * ELLIPSE_MARGIN_PX
    height_px = ELLIPSE_HEIGHT_PX + 2 * ELLIPSE_MARGIN_PX
    # Extreme samples land exactly on pixel centres 7 and 7 + 286 - 1.
    semi_x_px = (ELLIPSE_WIDTH_PX - 1) / 2
    semi_y_px = (ELLIPSE_HEIGHT_PX - 1) / 2
    centre = (ELLIPSE_MARGIN_PX + semi_x_px, ELLIPSE_MARGIN_PX + semi_y_px)
    return to_rgb(curves_mask((height_px, width_px), [(ellipse_points(centre, semi_x_px, semi_y_px), True)]))


def draw_two_curves() -> np.ndarray:
    """Thesis Figure 4.14: two open curves side by side (200 x 120 image).

    Left: an arch (upside-down U) from (20, 100) over its apex (60, 20) down to
    (100, 100).  Its topmost pixels are the apex, mid-curve, and the black
    pixel nearest the origin (0, 0) is on its left flank (about (33, 40)),
    also mid-curve: an end is NOT the nearest pixel.
    Right: a vertical S from (150, 15) to (150, 105).
    """
    arch = [(60 - 40 * math.cos(t), 100 - 80 * math.sin(t)) for t in np.linspace(0, math.pi, 400)]
    s_curve = [(150 + 30 * math.sin(2 * math.pi * s), 15 + 90 * s) for s in np.linspace(0, 1, 400)]
    return to_rgb(curves_mask((120, 200), [(arch, False), (s_curve, False)]))


def gear_points(centre_xy: tuple[float, float], n_teeth: int, root_radius_px: float,
                tip_radius_px: float) -> list[tuple[float, float]]:
    """Outline of a gear with trapezoidal teeth, as a closed polyline."""
    pitch_rad = 2 * math.pi / n_teeth
    # Fractions of one tooth pitch: root land, rising flank, tip land, falling flank.
    rise_start, tip_start, tip_end, fall_end = 0.22, 0.39, 0.61, 0.78
    points: list[tuple[float, float]] = []
    for tooth in range(n_teeth):
        a0 = tooth * pitch_rad
        points += arc_points(centre_xy, root_radius_px, a0, a0 + rise_start * pitch_rad)[:-1]
        points += arc_points(centre_xy, tip_radius_px, a0 + tip_start * pitch_rad, a0 + tip_end * pitch_rad)
        points += arc_points(centre_xy, root_radius_px, a0 + fall_end * pitch_rad, a0 + pitch_rad)[:-1]
    return points


def draw_gear() -> np.ndarray:
    """Thesis Figure 5.3: a 20-tooth gear (tip r 86 px) with a hub hole (r 16 px)."""
    centre = (100.0, 100.0)
    outline = gear_points(centre, n_teeth=20, root_radius_px=70, tip_radius_px=86)
    hub = circle_points(centre, 16)
    return to_rgb(curves_mask((201, 201), [(outline, True), (hub, True)]))


def letter_c_points(left_x: float, top_y: float, width_px: float, height_px: float) -> list[tuple[float, float]]:
    """A single-stroke "C": an elliptic arc open on the right (about 80 degrees)."""
    semi_x, semi_y = width_px / 2, height_px / 2
    cx, cy = left_x + semi_x, top_y + semi_y
    angles = np.linspace(math.radians(40), math.radians(320), 600)
    return [(cx + semi_x * math.cos(a), cy + semi_y * math.sin(a)) for a in angles]


def letter_n_points(left_x: float, top_y: float, width_px: float, height_px: float) -> list[tuple[float, float]]:
    """A single-stroke "N": up the left side, diagonally down, up the right side."""
    right_x, bottom_y = left_x + width_px, top_y + height_px
    return [(left_x, bottom_y), (left_x, top_y), (right_x, bottom_y), (right_x, top_y)]


def draw_word() -> np.ndarray:
    """Thesis Figure 5.8: "CNC" as single-stroke letters (3 open curves), 80 px high.

    The letters are drawn here rather than with ``cv2.putText``: OpenCV 5
    renders filled outline fonts, not the Hershey single strokes of OpenCV 4.
    """
    height_px, c_width_px, n_width_px, gap_px, margin_px = 80, 56, 50, 16, 10
    top_y = margin_px
    c1_x = margin_px
    n_x = c1_x + c_width_px + gap_px
    c2_x = n_x + n_width_px + gap_px
    image_w_px = c2_x + c_width_px + margin_px + 1
    return to_rgb(curves_mask((height_px + 2 * margin_px + 1, image_w_px), [
        (letter_c_points(c1_x, top_y, c_width_px, height_px), False),
        (letter_n_points(n_x, top_y, n_width_px, height_px), False),
        (letter_c_points(c2_x, top_y, c_width_px, height_px), False),
    ]))


def star_points(centre_xy: tuple[float, float], n_points: int, outer_radius_px: float,
                inner_radius_px: float) -> list[tuple[float, float]]:
    """Vertices of a star, first point straight up."""
    cx, cy = centre_xy
    vertices = []
    for i in range(2 * n_points):
        angle = -math.pi / 2 + i * math.pi / n_points
        radius = outer_radius_px if i % 2 == 0 else inner_radius_px
        vertices.append((cx + radius * math.cos(angle), cy + radius * math.sin(angle)))
    return vertices


def draw_stamp() -> np.ndarray:
    """A stamp: outer circle (r 100), inner circle (r 86), a 5-point star (r 62/30)."""
    centre = (110.0, 110.0)
    return to_rgb(curves_mask((221, 221), [
        (circle_points(centre, 100), True),
        (circle_points(centre, 86), True),
        (star_points(centre, 5, 62, 30), True),
    ]))


# --------------------------------------------------------------------------
# 3D drawings
# --------------------------------------------------------------------------

def solid(shape_hw: tuple[int, int], contours: Iterable[PointsXY],
          hole_seeds_rc: Iterable[tuple[int, int]] = ()) -> np.ndarray:
    """RGB image of closed black contours with the inside filled red."""
    black = curves_mask(shape_hw, [(pts, True) for pts in contours])
    return to_rgb(black, fill_interior(black, hole_seeds_rc))


def draw_disc() -> np.ndarray:
    """A disc of radius 40 px."""
    return solid((101, 101), [circle_points((50.0, 50.0), 40)])


def draw_square_pyramid() -> np.ndarray:
    """An axis-aligned 80 x 80 px square (carved as a pyramid by a profile)."""
    first_px, last_px = 10, 89
    corners = [(first_px, first_px), (last_px, first_px), (last_px, last_px), (first_px, last_px)]
    return solid((100, 100), [corners])


def tangent_point(from_xy: tuple[float, float], centre_xy: tuple[float, float],
                  radius_px: float, side: int) -> tuple[float, float]:
    """Point where a line from ``from_xy`` touches a circle; ``side`` is +1 or -1."""
    dx, dy = centre_xy[0] - from_xy[0], centre_xy[1] - from_xy[1]
    dist = math.hypot(dx, dy)
    turn = side * math.asin(radius_px / dist)
    ux, uy = dx / dist, dy / dist
    vx = ux * math.cos(turn) - uy * math.sin(turn)
    vy = ux * math.sin(turn) + uy * math.cos(turn)
    reach = math.sqrt(dist * dist - radius_px * radius_px)
    return from_xy[0] + vx * reach, from_xy[1] + vy * reach


def heart_points(centre_x: float, top_y: float) -> list[tuple[float, float]]:
    """A heart: two lobes (r 26 px, centres 48 px apart) and a V to the tip.

    The outline goes from the bottom tip up the right tangent line, over the
    right lobe to the top notch, over the left lobe and back down.
    """
    radius_px, half_gap_px = 26.0, 24.0
    lobe_y = top_y + radius_px
    right_centre = (centre_x + half_gap_px, lobe_y)
    tip = (centre_x, lobe_y + 65.0)
    notch_y = lobe_y - math.sqrt(radius_px ** 2 - half_gap_px ** 2)
    touch = tangent_point(tip, right_centre, radius_px, side=+1)
    start_rad = math.atan2(touch[1] - lobe_y, touch[0] - right_centre[0])
    notch_rad = math.atan2(notch_y - lobe_y, centre_x - right_centre[0])
    right_arc = arc_points(right_centre, radius_px, start_rad, notch_rad)
    left_arc = [(2 * centre_x - x, y) for x, y in reversed(right_arc)]
    return [tip] + right_arc + left_arc[1:]


def draw_heart() -> np.ndarray:
    """A heart 101 px wide and 92 px high (black extent)."""
    return solid((111, 120), [heart_points(centre_x=60.0, top_y=10.0)])


def dumbbell_points(left_centre_xy: tuple[float, float], centres_apart_px: float,
                    radius_px: float, half_neck_px: float) -> list[tuple[float, float]]:
    """Two equal circles joined by a straight neck, as one closed outline."""
    lx, cy = left_centre_xy
    rx = lx + centres_apart_px
    attach_rad = math.asin(half_neck_px / radius_px)
    # Left lobe: from its upper neck corner round the far side to the lower one.
    left = arc_points((lx, cy), radius_px, -attach_rad, -2 * math.pi + attach_rad)
    # Right lobe: from its lower neck corner round the far side to the upper one.
    right = arc_points((rx, cy), radius_px, math.pi - attach_rad, -math.pi + attach_rad)
    return left + right


def draw_dumbbell() -> np.ndarray:
    """Two r 30 px discs, centres 90 px apart, joined by a neck 7 px wide."""
    return solid((81, 171), [dumbbell_points((40.0, 40.0), 90.0, 30.0, 3.0)])


def draw_ring() -> np.ndarray:
    """An annulus between r 45 px and r 18 px; the hole stays white."""
    centre = (55.0, 55.0)
    return solid((111, 111), [circle_points(centre, 45), circle_points(centre, 18)],
                 hole_seeds_rc=[(55, 55)])


# --------------------------------------------------------------------------
# Checking
# --------------------------------------------------------------------------

@dataclass(frozen=True)
class Spec:
    """What a sample must contain: its closed and open curve counts, 2D or 3D."""

    closed_curves: int
    open_curves: int
    solid: bool


SAMPLES: dict[str, tuple[Callable[[], np.ndarray], Spec]] = {
    "ellipse.png": (draw_ellipse, Spec(1, 0, False)),
    "two_curves.png": (draw_two_curves, Spec(0, 2, False)),
    "gear.png": (draw_gear, Spec(2, 0, False)),
    "word.png": (draw_word, Spec(0, 3, False)),
    "stamp.png": (draw_stamp, Spec(3, 0, False)),
    "disc.png": (draw_disc, Spec(1, 0, True)),
    "pyramid.png": (draw_square_pyramid, Spec(1, 0, True)),
    "heart.png": (draw_heart, Spec(1, 0, True)),
    "dumbbell.png": (draw_dumbbell, Spec(1, 0, True)),
    "ring.png": (draw_ring, Spec(2, 0, True)),
}


def _fail(name: str, message: str, row: int | None = None, col: int | None = None) -> None:
    where = "" if row is None else f" at (x={col}, y={row})"
    raise AssertionError(f"{name}: {message}{where}")


def neighbour_counts(mask: np.ndarray) -> np.ndarray:
    """Black 8-neighbour count of every pixel (the border counts as white)."""
    padded = np.pad(mask.astype(np.int32), 1)
    h, w = mask.shape
    return sum(padded[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] for dr, dc in RING_OFFSETS)


def read_rgb(path: pathlib.Path) -> np.ndarray:
    """Read a PNG back as an RGB array."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise AssertionError(f"{path.name}: cannot be read back")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def colour_mask(rgb: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    return np.all(rgb == np.array(colour, np.uint8), axis=2)


def check_curves(name: str, black: np.ndarray, closed_curves: int, open_curves: int) -> None:
    """Check the black curve rules and the closed/open curve counts."""
    rows, cols = np.nonzero(black)
    on_border = (rows == 0) | (cols == 0) | (rows == black.shape[0] - 1) | (cols == black.shape[1] - 1)
    if on_border.any():
        i = int(np.flatnonzero(on_border)[0])
        _fail(name, "black pixel on the image border", rows[i], cols[i])
    counts = neighbour_counts(black)
    for bad, what in (((counts == 0), "isolated black pixel"),
                      ((counts > 2), "black pixel with more than 2 black neighbours")):
        hits = np.argwhere(black & bad)
        if len(hits):
            _fail(name, what, *hits[0])
    n_labels, labels = cv2.connectedComponents(black.astype(np.uint8), connectivity=8)
    n_closed = n_open = 0
    for label in range(1, n_labels):
        n_ends = int(np.count_nonzero((labels == label) & (counts == 1)))
        if n_ends == 0:
            n_closed += 1  # connected, every pixel has 2 neighbours: a simple cycle
        elif n_ends == 2:
            n_open += 1    # connected, 2 ends, the rest 2 neighbours: a simple path
        else:
            r, c = np.argwhere(labels == label)[0]
            _fail(name, f"curve with {n_ends} endpoints", r, c)
    if (n_closed, n_open) != (closed_curves, open_curves):
        _fail(name, f"expected {closed_curves} closed + {open_curves} open curves, "
                    f"found {n_closed} closed + {n_open} open")


def check_red(name: str, rgb: np.ndarray) -> None:
    """Red fills exactly the inside: never 4-adjacent to white, never empty."""
    white, red = colour_mask(rgb, WHITE_RGB), colour_mask(rgb, RED_RGB)
    if not red.any():
        _fail(name, "no red interior")
    padded_white = np.pad(white, 1)
    h, w = white.shape
    touches_white = np.zeros_like(white)
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        touches_white |= padded_white[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
    hits = np.argwhere(red & touches_white)
    if len(hits):
        _fail(name, "red pixel 4-adjacent to white", *hits[0])


def check_sample(name: str, path: pathlib.Path, spec: Spec) -> None:
    """Check one written sample file against the drawing rules and its spec."""
    rgb = read_rgb(path)
    black, white, red = (colour_mask(rgb, c) for c in (BLACK_RGB, WHITE_RGB, RED_RGB))
    allowed = black | white | (red if spec.solid else np.zeros_like(red))
    if not allowed.all():
        _fail(name, "pixel of a colour not allowed here", *np.argwhere(~allowed)[0])
    check_curves(name, black, spec.closed_curves, spec.open_curves)
    if spec.solid:
        check_red(name, rgb)


def check_extras(paths: dict[str, pathlib.Path]) -> None:
    """File-specific promises made in the module docstring."""
    black = colour_mask(read_rgb(paths["ellipse.png"]), BLACK_RGB)
    rows, cols = np.nonzero(black)
    extent = (cols.max() - cols.min() + 1, rows.max() - rows.min() + 1)
    if extent != (ELLIPSE_WIDTH_PX, ELLIPSE_HEIGHT_PX) or (cols.min(), rows.min()) != (ELLIPSE_MARGIN_PX,) * 2:
        _fail("ellipse.png", f"extent {extent} at (x={cols.min()}, y={rows.min()}), want 286 x 144 at (7, 7)")

    black = colour_mask(read_rgb(paths["two_curves.png"]), BLACK_RGB)
    counts = neighbour_counts(black)
    rows, cols = np.nonzero(black)
    nearest = int(np.argmin(rows.astype(np.int64) ** 2 + cols.astype(np.int64) ** 2))
    if counts[rows[nearest], cols[nearest]] != 2:
        _fail("two_curves.png", "pixel nearest the origin should be mid-curve", rows[nearest], cols[nearest])
    left = cols < 110
    top_row = rows[left].min()
    for r, c in zip(rows[left & (rows == top_row)], cols[left & (rows == top_row)]):
        if counts[r, c] != 2:
            _fail("two_curves.png", "arch top should be mid-curve", r, c)

    rgb = read_rgb(paths["ring.png"])
    if not colour_mask(rgb, WHITE_RGB)[55, 55]:
        _fail("ring.png", "the hole should be white", 55, 55)


def make_all(out_dir: pathlib.Path) -> dict[str, pathlib.Path]:
    """Write every sample PNG into ``out_dir``, check them, return name -> path."""
    out_dir = pathlib.Path(out_dir)
    paths = {name: write_png(out_dir / name, draw()) for name, (draw, _) in SAMPLES.items()}
    for name, (_, spec) in SAMPLES.items():
        check_sample(name, paths[name], spec)
    check_extras(paths)
    return paths


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path(__file__).resolve().parent,
                        help="output folder (default: this script's folder)")
    args = parser.parse_args(argv)
    for name, path in make_all(args.out).items():
        print(path)


if __name__ == "__main__":
    main()
