"""Pictures of every stage: drawings, digitized matrices, toolpaths and cut surfaces.

All functions return pictures as data (``(H, W, 3)`` uint8 RGB arrays or SVG
text); writing files is left to :func:`save_picture`.  The toolpath picture
draws the job over its drawing, scaled up so that one drawing pixel is
``scale`` picture pixels: cutting moves coloured by depth (shallow yellow to
deep purple), moves at or above the surface dashed grey, the start marked
with a green circle, the end with a red square, and a legend with the size
in mm, the depth range and the estimated time.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional
from xml.sax.saxutils import escape

import cv2
import numpy as np

from ..errors import CamError
from ..fileio import atomic_write_bytes, atomic_write_text

__all__ = ["depth_colours", "toolpath_picture", "toolpath_svg", "surface_picture", "save_picture", "auto_scale",
           "encode_png", "canvas_size_px"]

LEGEND_PX = 44
_START = (0, 170, 0)
_END = (220, 0, 0)
_TRAVEL = (150, 150, 150)


def auto_scale(width_px: int, height_px: int, target_px: int = 900) -> int:
    """Picture pixels per drawing pixel: large enough to see single pixels, at most 8."""
    return int(max(1, min(8, target_px // max(1, width_px, height_px))))


def depth_colours(depth: np.ndarray, max_depth: float) -> np.ndarray:
    """``(N, 3)`` uint8 RGB for depths: shallow = yellow, deep = purple (viridis, reversed)."""
    t = np.clip(np.asarray(depth, np.float64) / max(1e-9, float(max_depth)), 0, 1)
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8).reshape(-1, 1), cv2.COLORMAP_VIRIDIS)[:, 0, ::-1]
    return lut[np.round((1.0 - t) * 255).astype(int)]


def encode_png(rgb: np.ndarray) -> bytes:
    """PNG bytes of an ``(H, W, 3)`` RGB array."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover
        raise CamError("cannot encode PNG")
    return buf.tobytes()


def _grid(job) -> tuple[np.ndarray, tuple[int, int, int], tuple[int, int], tuple[float, float]]:
    """A job's points on the picture grid: drawing pixels for a drawing job, machine steps otherwise.

    Returns ``(points (N, 3), origin (x, y, z), drawing size (w, h), mm per grid unit (xy, z))``.
    """
    s = job.settings
    if job.pixels is not None:
        return (job.points_px(), job.origin_px, (job.width_px, job.height_px),
                (s.px_to_mm_xy(1), s.px_to_mm_z(1)))
    return np.asarray(job.points_steps, np.int64), (0, 0, 0), (0, 0), (s.mm_per_step_xy, s.mm_per_step_z)


def _legend_text(job, estimated_time_s: Optional[float]) -> str:
    pts, origin, _, (mm_xy, mm_z) = _grid(job)
    cut = pts[job.target] if job.n_targets else np.zeros((1, 3), np.int64)
    w_units = int(cut[:, 0].max() - cut[:, 0].min() + 1)
    h_units = int(cut[:, 1].max() - cut[:, 1].min() + 1)
    oz = origin[2]
    d_lo, d_hi = int(cut[:, 2].min() - oz), int(cut[:, 2].max() - oz)
    text = (f"{w_units * mm_xy:.1f} x {h_units * mm_xy:.1f} mm   depth {d_lo * mm_z:.2f}"
            f"..{d_hi * mm_z:.2f} mm")
    if estimated_time_s is not None:
        m, sec = divmod(int(round(estimated_time_s)), 60)
        text += f"   time {m // 60}:{m % 60:02d}:{sec:02d}"
    return text


def canvas_size_px(job) -> tuple[int, int]:
    """``(width, height)`` in pixels of the picture that holds ``job`` whole: its drawing from the picture's
    origin and every point it moves to (:func:`toolpath_picture`'s canvas; the tracker draws on the same)."""
    pts, origin, (w_draw, h_draw), _ = _grid(job)
    w = max(w_draw + origin[0], int(pts[:, 0].max()) + 1)
    h = max(h_draw + origin[1], int(pts[:, 1].max()) + 1)
    return w, h


def _dashed(img: np.ndarray, p0: tuple[int, int], p1: tuple[int, int], colour, dash_px: int = 6) -> None:
    length = float(np.hypot(p1[0] - p0[0], p1[1] - p0[1]))
    n = max(1, int(length // dash_px))
    for k in range(0, n, 2):
        a = (p0[0] + (p1[0] - p0[0]) * k / n, p0[1] + (p1[1] - p0[1]) * k / n)
        b = (p0[0] + (p1[0] - p0[0]) * min(n, k + 1) / n, p0[1] + (p1[1] - p0[1]) * min(n, k + 1) / n)
        cv2.line(img, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), colour, 1, cv2.LINE_AA)


def toolpath_picture(
    toolpath,
    *,
    drawing_rgb: Optional[np.ndarray] = None,
    scale: Optional[int] = None,
    estimated_time_s: Optional[float] = None,
) -> np.ndarray:
    """The job over its drawing as an ``(H x scale + legend, W x scale, 3)`` RGB array.

    Drawing pixel (x, y) maps to the picture square whose centre is
    ``((x + 0.5) x scale, (y + 0.5) x scale)``; a job without a drawing is drawn on its machine-step grid.
    """
    grid_pts, origin, _, _ = _grid(toolpath)
    w, h = canvas_size_px(toolpath)
    k = scale or auto_scale(w, h)
    img = np.full((h * k + LEGEND_PX, max(w * k, 420), 3), 255, np.uint8)
    if drawing_rgb is not None:
        faded = (255 - (255 - drawing_rgb.astype(np.int32)) * 0.25).astype(np.uint8)
        big = np.repeat(np.repeat(faded, k, axis=0), k, axis=1)
        ox, oy = origin[0] * k, origin[1] * k
        hh, ww = min(big.shape[0], h * k - oy), min(big.shape[1], img.shape[1] - ox)
        img[oy:oy + hh, ox:ox + ww] = big[:hh, :ww]
    pts = np.vstack([[0, 0, 0], grid_pts])
    centre = pts[:, :2] * k + k // 2
    surface = origin[2]
    d_max = max(1, int(pts[:, 2].max()) - surface)
    cols = depth_colours(pts[:, 2] - surface, d_max)
    cutting = (pts[:-1, 2] > surface) & (pts[1:, 2] > surface)
    for i in np.flatnonzero(~cutting) + 1:  # moves above the surface first, cuts drawn over them
        a, b = tuple(int(v) for v in centre[i - 1]), tuple(int(v) for v in centre[i])
        if a != b:
            _dashed(img, a, b, _TRAVEL)
    for i in np.flatnonzero(cutting) + 1:
        a, b = tuple(int(v) for v in centre[i - 1]), tuple(int(v) for v in centre[i])
        if a != b:
            cv2.line(img, a, b, tuple(int(v) for v in cols[i]), max(1, k // 2), cv2.LINE_8)
    if toolpath.n_targets:
        first = grid_pts[np.flatnonzero(toolpath.target)[0]]
        cv2.circle(img, (int(first[0] * k + k // 2), int(first[1] * k + k // 2)), max(4, k), _START, 2)
    end = centre[-1]
    r = max(4, k)
    cv2.rectangle(img, (int(end[0]) - r, int(end[1]) - r), (int(end[0]) + r, int(end[1]) + r), _END, 2)
    y0 = h * k
    img[y0:] = 245
    cv2.putText(img, _legend_text(toolpath, estimated_time_s), (6, y0 + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "start", (6, y0 + 36), cv2.FONT_HERSHEY_SIMPLEX, 0.4, _START, 1, cv2.LINE_AA)
    cv2.putText(img, "end", (50, y0 + 36), cv2.FONT_HERSHEY_SIMPLEX, 0.4, _END, 1, cv2.LINE_AA)
    cv2.putText(img, "- - above surface", (85, y0 + 36), cv2.FONT_HERSHEY_SIMPLEX, 0.4, _TRAVEL, 1, cv2.LINE_AA)
    bar_x = 230
    for j in range(120):
        c = tuple(int(v) for v in depth_colours([j], 119)[0])
        cv2.line(img, (bar_x + j, y0 + 28), (bar_x + j, y0 + 38), c, 1)
    cv2.putText(img, "shallow", (bar_x - 2, y0 + 26), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "deep", (bar_x + 100, y0 + 26), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def toolpath_svg(toolpath, *, scale: Optional[int] = None, estimated_time_s: Optional[float] = None) -> str:
    """The same picture as :func:`toolpath_picture`, as SVG text (vector; no drawing underneath)."""
    grid_pts, origin, _, _ = _grid(toolpath)
    w, h = canvas_size_px(toolpath)
    k = scale or auto_scale(w, h)
    pts = np.vstack([[0, 0, 0], grid_pts])
    surface = origin[2]
    cols = depth_colours(pts[:, 2] - surface, max(1, int(pts[:, 2].max()) - surface))
    W, H = max(w * k, 420), h * k + LEGEND_PX
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}">',
           f'<rect width="{W}" height="{H}" fill="white"/>']
    c = pts[:, :2] * k + k / 2
    for i in range(1, len(pts)):
        if (c[i - 1] == c[i]).all():
            continue
        cut = pts[i - 1, 2] > surface and pts[i, 2] > surface
        style = (f'stroke="rgb{tuple(int(v) for v in cols[i])}" stroke-width="{max(1, k // 2)}"' if cut
                 else 'stroke="rgb(150,150,150)" stroke-width="1" stroke-dasharray="4 4"')
        out.append(f'<line x1="{c[i-1][0]:g}" y1="{c[i-1][1]:g}" x2="{c[i][0]:g}" y2="{c[i][1]:g}" {style}/>')
    if toolpath.n_targets:
        f = grid_pts[np.flatnonzero(toolpath.target)[0]] * k + k / 2
        out.append(f'<circle cx="{f[0]:g}" cy="{f[1]:g}" r="{max(4, k)}" fill="none" stroke="rgb{_START}" stroke-width="2"/>')
    r = max(4, k)
    out.append(f'<rect x="{c[-1][0] - r:g}" y="{c[-1][1] - r:g}" width="{2 * r}" height="{2 * r}" fill="none" '
               f'stroke="rgb{_END}" stroke-width="2"/>')
    out.append(f'<text x="6" y="{h * k + 18}" font-family="sans-serif" font-size="12">'
               f'{escape(_legend_text(toolpath, estimated_time_s))}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def surface_picture(depth_steps: np.ndarray, *, scale: Optional[int] = None, legend: str = "") -> np.ndarray:
    """A shaded depth map of a cut surface: ``(H, W)`` depth in Z steps to an RGB picture.

    Untouched pixels are white; cut pixels are coloured by depth and lit from the top-left
    so slopes and steps show.
    """
    d = np.asarray(depth_steps, np.float64)
    h, w = d.shape
    k = scale or auto_scale(w, h)
    cols = depth_colours(d.ravel(), max(1.0, d.max())).reshape(h, w, 3).astype(np.float64)
    gy, gx = np.gradient(-d)
    shade = np.clip(1.0 + 0.15 * (gx + gy), 0.55, 1.25)[..., None]
    rgb = np.clip(cols * shade, 0, 255)
    rgb[d <= 0] = 255
    img = np.repeat(np.repeat(rgb.astype(np.uint8), k, axis=0), k, axis=1)
    band = np.full((LEGEND_PX // 2, max(img.shape[1], 300), 3), 245, np.uint8)
    if img.shape[1] < band.shape[1]:
        img = np.hstack([img, np.full((img.shape[0], band.shape[1] - img.shape[1], 3), 255, np.uint8)])
    text = legend or f"cut surface: max depth {int(d.max())} Z steps"
    cv2.putText(band, text, (6, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([img, band])


def save_picture(picture: np.ndarray | str, path: str | os.PathLike) -> Path:
    """Write an RGB array as PNG, or SVG text as .svg, atomically (the suffix must match)."""
    p = Path(path)
    if isinstance(picture, str):
        if p.suffix.lower() != ".svg":
            raise CamError(f"{p}: SVG pictures need a .svg name")
        return atomic_write_text(p, picture)
    if p.suffix.lower() != ".png":
        raise CamError(f"{p}: pictures are written as .png or .svg")
    return atomic_write_bytes(p, encode_png(picture))
