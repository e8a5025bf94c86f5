"""Carve with a real tool shape and compare with the target (issue #19 point 5).

An independent check of a job cut with a flat, ball or V cutter: the decoded
pin log's every step position lowers the tool's shape into a height field
sampled at pixel centres (the frame of :func:`cam.verify.pinlog.carve`: pixel
``(row, col)`` of the drawing, depths in Z steps below the surface), and the
result is compared with the depth asked at each pixel: *gouge* where the tool
cut below it, *rest material* where it left material above it.

It shares nothing with the planner's drop-cutter code but the tool's profile.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..tool import Tool
from .pinlog import Motion

__all__ = ["carve_tool", "ToolCarve", "Comparison", "compare_surface", "gouge_rest_picture", "least_rest_steps"]

_CHUNK = 1 << 20  # tool-sample pairs per chunk: memory stays bounded whatever the job's length


@dataclass
class ToolCarve:
    """What a tool cut.

    Attributes:
        depth_steps: ``(H, W)`` float64 deepest cut at each pixel centre, Z steps below the surface (0 = untouched).
        outside_steps: the deepest cut at any pixel centre outside the drawing (0 = none).
    """

    depth_steps: np.ndarray
    outside_steps: float


def carve_tool(motion: Motion, shape_hw: tuple[int, int], tool: Tool,
               settings: MachineSettings = DEFAULT_SETTINGS, *, origin_px: tuple[int, int, int] = (0, 0, 0)
               ) -> ToolCarve:
    """The height field left by ``tool`` following ``motion`` (every step position, in machine steps).

    A tool position ``(x, y, z)`` steps has its axis at pixel coordinates ``(x / spp_xy - ox, y / spp_xy -
    oy)`` (pixel centres at whole numbers) with its tip ``z - oz x spp_z`` steps below the surface; at a pixel
    centre a distance ``r`` from the axis it cuts to ``tip - profile(r)``.
    """
    h, w = shape_hw
    s = settings
    ox, oy, oz = origin_px
    spp = s.steps_per_px_xy
    p = np.asarray(motion.position_steps, np.int64)
    depth = p[:, 2] - oz * s.steps_per_px_z
    below = depth > 0
    p, depth = p[below], depth[below]
    # one tool position per (x, y) step: its deepest tip
    xy = p[:, :2]
    if len(xy):
        order = np.lexsort((-depth, xy[:, 1], xy[:, 0]))
        xy, depth = xy[order], depth[order]
        first = np.ones(len(xy), bool)
        first[1:] = np.any(xy[1:] != xy[:-1], axis=1)
        xy, depth = xy[first], depth[first]
    px_mm = s.px_to_mm_xy(1)
    reach = int(np.ceil(max(tool.radius_mm, 0.0) / px_mm)) + 1
    pad = reach + 1
    out = np.zeros((h + 2 * pad, w + 2 * pad), np.float64)
    ax = xy[:, 0] / spp - ox
    ay = xy[:, 1] / spp - oy
    cx, cy = np.rint(ax).astype(np.int64), np.rint(ay).astype(np.int64)
    oy_, ox_ = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    oy_, ox_ = oy_.ravel(), ox_.ravel()
    per = max(1, _CHUNK // len(oy_))
    for a in range(0, len(xy), per):
        b = min(a + per, len(xy))
        qx = cx[a:b, None] + ox_[None, :]
        qy = cy[a:b, None] + oy_[None, :]
        r_mm = np.hypot(qx - ax[a:b, None], qy - ay[a:b, None]) * px_mm
        rise_steps = tool.profile_mm(r_mm) / s.mm_per_step_z
        cut = depth[a:b, None] - rise_steps
        ok = np.isfinite(cut) & (cut > 0)
        qx, qy, cut = qx[ok] + pad, qy[ok] + pad, cut[ok]
        inside = (qx >= 0) & (qx < out.shape[1]) & (qy >= 0) & (qy < out.shape[0])
        np.maximum.at(out, (qy[inside], qx[inside]), cut[inside])
    inner = out[pad:pad + h, pad:pad + w].copy()
    out[pad:pad + h, pad:pad + w] = 0
    return ToolCarve(depth_steps=inner, outside_steps=float(out.max(initial=0.0)))


@dataclass
class Comparison:
    """A cut surface against its target, per pixel and in mm.

    Attributes:
        gouge_mm: ``(H, W)`` how far below the target the tool cut (0 where it did not).
        rest_mm: ``(H, W)`` material left above the target (0 where none).
        max_gouge_mm, rest_mean_mm, rest_p95_mm: summaries (rest over the pixels with a target below the
            surface).
    """

    gouge_mm: np.ndarray
    rest_mm: np.ndarray
    max_gouge_mm: float
    rest_mean_mm: float
    rest_p95_mm: float

    def _repr_png_(self) -> bytes:
        import cv2

        return cv2.imencode(".png", gouge_rest_picture(self)[:, :, ::-1])[1].tobytes()


def least_rest_steps(target_steps: np.ndarray, tool: Tool, settings: MachineSettings = DEFAULT_SETTINGS,
                     k: int | None = None) -> np.ndarray:
    """The least material any cut without a gouge can leave, with the tool's axis on a grid ``k`` times finer
    than the pixels (None: every step position, ``k = steps_per_px_xy``) and its tip on whole Z steps.

    By brute force: at every position of the grid the deepest tip that cuts no pixel centre below the target
    (rounded up to a whole Z step), then the deepest any of them reaches at each pixel centre.  No program
    can cut a pixel deeper without cutting some pixel centre below its target.

    Args:
        target_steps: ``(H, W)`` target depth at each pixel centre, Z steps below the surface.

    Returns:
        ``(H, W)`` float64 Z steps of material left, at least.
    """
    s = settings
    k = int(s.steps_per_px_xy if k is None else k)
    want = np.asarray(target_steps, np.float64)
    h, w = want.shape
    px_mm = s.px_to_mm_xy(1)
    reach = int(np.ceil(max(tool.radius_mm, 0.0) / px_mm)) + 1
    pad = np.zeros((h + 2 * reach, w + 2 * reach))
    pad[reach:reach + h, reach:reach + w] = want
    best = np.zeros((h, w))
    oy_, ox_ = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    for sy in range(k):
        for sx in range(k):  # the positions (i + sy / k, j + sx / k)
            rise = tool.profile_mm(np.hypot(oy_ - sy / k, ox_ - sx / k) * px_mm) / s.mm_per_step_z
            offsets = [(int(a), int(b), float(r)) for a, b, r in zip(oy_.ravel(), ox_.ravel(), rise.ravel())
                       if np.isfinite(r)]
            tip = np.full((h, w), np.inf)
            for oy, ox, r in offsets:
                np.minimum(tip, pad[reach + oy:reach + oy + h, reach + ox:reach + ox + w] + r, out=tip)
            tip = np.maximum(np.floor(tip + 1e-7), 0.0)
            for oy, ox, r in offsets:
                y0, y1, x0, x1 = max(0, -oy), min(h, h - oy), max(0, -ox), min(w, w - ox)
                if y0 < y1 and x0 < x1:
                    np.maximum(best[y0 + oy:y1 + oy, x0 + ox:x1 + ox], tip[y0:y1, x0:x1] - r,
                               out=best[y0 + oy:y1 + oy, x0 + ox:x1 + ox])
    return np.maximum(want - best, 0.0)


def compare_surface(cut_steps: np.ndarray, target_steps: np.ndarray,
                    settings: MachineSettings = DEFAULT_SETTINGS, tolerance_steps: float = 1e-6) -> Comparison:
    """Gouge and rest material of a cut ``(H, W)`` (Z steps below the surface) against the target ``(H, W)``."""
    cut = np.asarray(cut_steps, np.float64)
    target = np.asarray(target_steps, np.float64)
    over = cut - target
    gouge = np.where(over > tolerance_steps, over, 0.0) * settings.mm_per_step_z
    rest = np.where(-over > tolerance_steps, -over, 0.0) * settings.mm_per_step_z
    asked = target > 0
    rest_asked = rest[asked] if np.any(asked) else np.zeros(1)
    return Comparison(gouge_mm=gouge, rest_mm=rest, max_gouge_mm=float(gouge.max(initial=0.0)),
                      rest_mean_mm=float(rest_asked.mean()), rest_p95_mm=float(np.percentile(rest_asked, 95)))


def gouge_rest_picture(c: Comparison, scale_mm: float | None = None) -> np.ndarray:
    """``(H, W, 3)`` uint8 RGB: white where the cut equals the target, blue deepening with rest material, red
    with gouge (full colour at ``scale_mm``, default the largest of either)."""
    top = scale_mm or max(float(c.rest_mm.max(initial=0.0)), float(c.gouge_mm.max(initial=0.0)), 1e-9)
    rest = np.clip(c.rest_mm / top, 0, 1)
    gouge = np.clip(c.gouge_mm / top, 0, 1)
    rgb = np.full(c.rest_mm.shape + (3,), 255.0)
    rgb[..., 0] -= 255 * rest
    rgb[..., 1] -= 255 * np.maximum(rest, gouge)
    rgb[..., 2] -= 255 * gouge
    return np.clip(rgb, 0, 255).astype(np.uint8)
