"""The picture of a height map (``cam preview MAP.json``): the probed surface as a colour scale, with a job over it.

Frame: the picture shows the map's area in the **machine frame**, seen from above: machine X to the right, machine
+Y (toward the operator) down, ``px_per_mm`` picture pixels a mm.  Machine ``(x_mm, y_mm)`` is at picture column
``MARGIN_PX + (x_mm - x0) * px_per_mm``, row ``MARGIN_PX + (y_mm - y0) * px_per_mm`` (``x0, y0``: the map's first
column and row).  Heights between the probed points are the map's bilinear ones
(:func:`cam.job.heightmap_level.height_at`), coloured low (dark blue) to high (yellow); each probed point is a small
black ring; a job's cuts (machine mm polylines, :func:`cam.drive.probing.job_cuts_mm`) are drawn in magenta.  A legend
under the map gives the colour scale in mm with its lowest and highest heights.
"""
from __future__ import annotations

from typing import Optional, Sequence

import cv2
import numpy as np

from .heightmap_level import HeightMap, height_at

__all__ = ["height_map_picture", "map_pixel", "height_colours", "MARGIN_PX", "CUT_RGB", "POINT_RGB"]

MARGIN_PX = 24
"""White border round the map, picture pixels (the job's cuts may reach into it)."""
LEGEND_PX = 56
CUT_RGB = (230, 0, 200)
"""The colour of a job's cuts over the map (magenta: in no part of the height scale)."""
POINT_RGB = (0, 0, 0)
"""The colour of the probed points' rings."""


def height_colours(t: np.ndarray) -> np.ndarray:
    """``(..., 3)`` uint8 RGB of ``t`` in 0..1 (0 lowest: dark blue, 1 highest: yellow; viridis)."""
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(-1, 1), cv2.COLORMAP_VIRIDIS)[:, 0, ::-1]
    return lut[np.clip(np.rint(np.asarray(t, np.float64) * 255), 0, 255).astype(np.int64)]


def _auto_px_per_mm(height_map: HeightMap, target_px: int = 800) -> float:
    w = float(height_map.x_mm[-1] - height_map.x_mm[0])
    h = float(height_map.y_mm[-1] - height_map.y_mm[0])
    return max(0.05, min(40.0, target_px / max(w, h)))


def map_pixel(height_map: HeightMap, x_mm: np.ndarray, y_mm: np.ndarray, px_per_mm: float) -> np.ndarray:
    """``(N, 2)`` float64 picture ``(column, row)`` of machine ``(x_mm, y_mm)`` (see the module docstring).

    >>> m = HeightMap([10, 20], [5, 15], np.zeros((2, 2)), spacing_mm=10)
    >>> map_pixel(m, np.array([10.0, 20.0]), np.array([5.0, 15.0]), 2.0).tolist()
    [[24.0, 24.0], [44.0, 44.0]]
    """
    x = np.asarray(x_mm, np.float64).reshape(-1)
    y = np.asarray(y_mm, np.float64).reshape(-1)
    return np.column_stack([MARGIN_PX + (x - height_map.x_mm[0]) * px_per_mm,
                            MARGIN_PX + (y - height_map.y_mm[0]) * px_per_mm])


def height_map_picture(height_map: HeightMap, *, cuts_mm: Optional[Sequence[np.ndarray]] = None,
                       px_per_mm: Optional[float] = None, title: str = "") -> np.ndarray:
    """The map as an ``(H, W, 3)`` uint8 RGB picture (see the module docstring for its frame).

    Args:
        height_map: the map.
        cuts_mm: a job's cuts, each an ``(N, 2)`` array of machine X, Y in mm (N >= 1; one point: a hole), drawn over
            the map (clipped to the picture).
        px_per_mm: picture pixels a mm (default: the map's longer side about 800 pixels).
        title: the legend's first line (default: the map's size and spacing).
    """
    k = float(px_per_mm) if px_per_mm else _auto_px_per_mm(height_map)
    gx, gy = height_map.x_mm, height_map.y_mm
    w_px = int(round((gx[-1] - gx[0]) * k)) + 1
    h_px = int(round((gy[-1] - gy[0]) * k)) + 1
    width = max(w_px + 2 * MARGIN_PX, 560)
    img = np.full((h_px + 2 * MARGIN_PX + LEGEND_PX, width, 3), 255, np.uint8)
    xs = gx[0] + np.arange(w_px) / k
    ys = gy[0] + np.arange(h_px) / k
    heights = height_at(height_map, xs[None, :], ys[:, None])
    lo, hi = float(height_map.height_mm.min()), float(height_map.height_mm.max())
    span = hi - lo
    t = (heights - lo) / span if span > 0 else np.full(heights.shape, 0.5)
    img[MARGIN_PX:MARGIN_PX + h_px, MARGIN_PX:MARGIN_PX + w_px] = height_colours(t)
    ring = max(2, int(round(min(np.diff(gx).min(), np.diff(gy).min()) * k / 8)))
    px, py = np.meshgrid(gx, gy)
    for c, r in np.rint(map_pixel(height_map, px, py, k)).astype(int):
        cv2.circle(img, (int(c), int(r)), ring, POINT_RGB, 1, cv2.LINE_8)
    thick = max(1, int(round(k / 4)))
    for cut in cuts_mm or ():
        cut = np.asarray(cut, np.float64).reshape(-1, 2)
        if not len(cut):
            continue
        p = np.rint(map_pixel(height_map, cut[:, 0], cut[:, 1], k)).astype(np.int32)
        if len(p) == 1 or not np.any(p != p[0]):
            cv2.circle(img, (int(p[0, 0]), int(p[0, 1])), max(2, thick), CUT_RGB, -1, cv2.LINE_8)
        else:
            cv2.polylines(img, [p.reshape(-1, 1, 2)], False, CUT_RGB, thick, cv2.LINE_8)
    _legend(img, h_px + 2 * MARGIN_PX, lo, hi, title or (
        f"height map {len(gx)} x {len(gy)} points, {gx[-1] - gx[0]:.4g} x {gy[-1] - gy[0]:.4g} mm (machine X "
        f"{gx[0]:.4g}..{gx[-1]:.4g}, Y {gy[0]:.4g}..{gy[-1]:.4g}), probed every {height_map.spacing_mm:g} mm"),
            bool(cuts_mm))
    return img


def _legend(img: np.ndarray, y0: int, lo: float, hi: float, title: str, with_job: bool) -> None:
    img[y0:] = 245
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(img, title, (6, y0 + 16), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    bar_x, bar_w = 70, 200
    bar = height_colours(np.linspace(0.0, 1.0, bar_w))
    img[y0 + 28:y0 + 40, bar_x:bar_x + bar_w] = bar[None, :, :]
    cv2.putText(img, "height", (6, y0 + 38), font, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{lo:.3f} mm", (bar_x, y0 + 52), font, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{hi:.3f} mm", (bar_x + bar_w - 60, y0 + 52), font, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "o probed point", (bar_x + bar_w + 16, y0 + 38), font, 0.4, POINT_RGB, 1, cv2.LINE_AA)
    if with_job:
        cv2.putText(img, "- the job's cuts", (bar_x + bar_w + 130, y0 + 38), font, 0.4, CUT_RGB, 1, cv2.LINE_AA)
