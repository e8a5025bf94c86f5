"""Cutter shapes and the drop-cutter rule (issue #19).

A :class:`Tool` is the shape of the cutter's end: a point (the thesis's model
and the default), a flat end mill, a ball end mill or a V bit.  Its *profile*
``h(r)`` is how far above the tool's tip its cutting surface lies at a
distance ``r`` from its axis (mm); beyond its radius it cuts nothing.

The target is a height field sampled at pixel centres (as LinuxCNC's
``image-to-gcode`` and height-field simulations take an image).  The
drop-cutter rule (:func:`drop_depth_px`): with the axis over pixel ``p``, the
tip may go down to ``min over pixels q under the tool of depth(q) + h(r)``,
where ``r`` is the least distance between where the axis can be and ``q``'s
centre.  The planner moves the axis between the centres of adjacent pixels
only, at a depth no deeper than both ends allow, so "where the axis can be" is
the *star* of ``p``: the eight half-moves from its centre to its edges'
midpoints and corners.  Taking the least distance from the star (not from the
centre) keeps every position along every move free of gouges, not only the
pixel centres.

Frames: pixels ``(row, col)`` as in the digitized matrix, depths in Z pixels
below the surface (+ deeper), distances in mm or pixels as named.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from .errors import CamError
MAX_MM = 100.0
"""The largest tool dimension accepted (mm)."""
MIN_MM = 0.001
"""The smallest tool dimension accepted other than 0 (mm, one micrometre): a smaller one is a slip, and the
divisions by it (a V bit's depth for a width, the footprint in pixels) would overflow."""
MIN_V_ANGLE_DEG = 1.0
MAX_V_ANGLE_DEG = 179.0
"""A V bit's included angle is 1..179 degrees: a sharper one would cut a line 0.3 mm wide deeper than any
machine's travel (the depth grows as 1 / tan(angle / 2), infinite at 0), a flatter one would be no V bit."""

__all__ = ["Tool", "POINT", "parse_tool", "drop_depth_px", "reach_depth_px", "tool_of_settings", "corner_depth_px",
           "footprint_px", "TOOL_SHAPES", "lowest_under_footprint"]

TOOL_SHAPES = ("point", "flat", "ball", "v")
V_SHANK_MM = 3.175
"""Diameter a V bit's cone reaches when none is given: the common 1/8 inch shank."""


@dataclass(frozen=True)
class Tool:
    """A cutter's end shape.

    Attributes:
        shape: ``"point"``, ``"flat"``, ``"ball"`` or ``"v"``.
        diameter_mm: the cutting diameter (flat, ball), or where a V bit's cone ends (its shank); 0 for a point.
        angle_deg: a V bit's included angle (between its two cutting edges), 0 < angle < 180.
        tip_mm: a V bit's flat tip diameter (0: sharp).
    """

    shape: str = "point"
    diameter_mm: float = 0.0
    angle_deg: float = 0.0
    tip_mm: float = 0.0

    def __post_init__(self) -> None:
        if self.shape not in TOOL_SHAPES:
            raise CamError(f"tool: unknown shape {self.shape!r} (one of {', '.join(TOOL_SHAPES)})")
        for key, hi in (("diameter_mm", MAX_MM), ("angle_deg", MAX_V_ANGLE_DEG), ("tip_mm", MAX_MM)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite(value) \
                    or not 0 <= value <= hi:
                raise CamError(f"tool: {key} must be a number 0..{hi:g}, got {str(value)[:40]}")
            if key != "angle_deg" and 0 < value < MIN_MM:
                raise CamError(f"tool: {key} must be 0 or {MIN_MM:g}..{MAX_MM:g} mm, got {value:g}")
        if self.shape in ("flat", "ball") and not self.diameter_mm > 0:
            raise CamError(f"tool: a {self.shape} cutter needs a diameter > 0 mm (e.g. {self.shape}:1)")
        if self.shape == "v":
            if not MIN_V_ANGLE_DEG <= self.angle_deg <= MAX_V_ANGLE_DEG:
                raise CamError(f"tool: a V bit's angle must be {MIN_V_ANGLE_DEG:g}..{MAX_V_ANGLE_DEG:g} degrees, "
                               f"got {self.angle_deg:g}")
            if not self.tip_mm < self.diameter_mm:
                raise CamError(f"tool: a V bit's tip ({self.tip_mm:g} mm) must be narrower than its diameter "
                               f"({self.diameter_mm:g} mm)")

    @property
    def radius_mm(self) -> float:
        return self.diameter_mm / 2

    @property
    def is_point(self) -> bool:
        return self.shape == "point"

    def profile_mm(self, r_mm: np.ndarray) -> np.ndarray:
        """Height of the cutting surface above the tip at distance ``r_mm`` from the axis (same shape as
        ``r_mm``); ``inf`` where the tool does not reach (beyond its radius; anywhere but 0 for a point)."""
        r = np.asarray(r_mm, np.float64)
        if self.shape == "point":
            return np.where(r <= 0, 0.0, np.inf)
        R = self.radius_mm
        inside = r <= R
        if self.shape == "flat":
            h = np.zeros_like(r)
        elif self.shape == "ball":
            h = R - np.sqrt(np.maximum(R * R - np.minimum(r, R) ** 2, 0.0))
        else:  # v
            h = np.maximum(r - self.tip_mm / 2, 0.0) / math.tan(math.radians(self.angle_deg) / 2)
        return np.where(inside, h, np.inf)

    def width_at_depth_mm(self, depth_mm: float) -> float:
        """Width of the groove the tool cuts at ``depth_mm`` (an engraved line's width)."""
        d = max(float(depth_mm), 0.0)
        if self.shape == "point" or d == 0:
            return 0.0
        if self.shape == "flat":
            return self.diameter_mm
        if self.shape == "ball":
            R = self.radius_mm
            return self.diameter_mm if d >= R else 2 * math.sqrt(R * R - (R - d) ** 2)
        return min(self.tip_mm + 2 * d * math.tan(math.radians(self.angle_deg) / 2), self.diameter_mm)

    def depth_for_width_mm(self, width_mm: float) -> float:
        """The depth at which a V bit cuts a groove ``width_mm`` wide.

        Raises:
            CamError: not a V bit, or a width it cannot cut (under its tip or over its diameter).
        """
        if self.shape != "v":
            raise CamError(f"a line width sets the depth of a V bit only (the tool is {self.describe()})")
        if not (self.tip_mm <= width_mm <= self.diameter_mm):
            raise CamError(f"a {self.describe()} cuts lines {self.tip_mm:g} to {self.diameter_mm:g} mm wide, "
                           f"not {width_mm:g} mm")
        return (width_mm - self.tip_mm) / (2 * math.tan(math.radians(self.angle_deg) / 2))

    def describe(self) -> str:
        """``"ball 1 mm"``, ``"V 60 deg, tip 0.1 mm"``, ``"point"``: for reports, comments and messages."""
        if self.shape == "point":
            return "point"
        if self.shape == "v":
            return f"V {self.angle_deg:g} deg, tip {self.tip_mm:g} mm, {self.diameter_mm:g} mm shank"
        return f"{self.shape} {self.diameter_mm:g} mm"

    def spec(self) -> str:
        """The text :func:`parse_tool` reads back (``"v:60:0.1:3.175"``)."""
        if self.shape == "point":
            return "point"
        if self.shape == "v":
            return f"v:{self.angle_deg:g}:{self.tip_mm:g}:{self.diameter_mm:g}"
        return f"{self.shape}:{self.diameter_mm:g}"


def _finite(value: float) -> bool:
    """A finite number as a float (an integer of 400 digits is not: it overflows one)."""
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


POINT = Tool()


def parse_tool(text: Union[str, Tool, None], source: str = "--tool") -> Tool:
    """A tool from ``point``, ``flat:D``, ``ball:D`` or ``v:ANGLE:TIP[:D]`` (mm, degrees; D of a V bit: where
    its cone ends, default 1/8 inch).  None gives the point tool.

    >>> parse_tool("ball:1").describe()
    'ball 1 mm'
    >>> parse_tool("v:60:0.1").width_at_depth_mm(0.5) > 0.6
    True

    Raises:
        CamError: naming ``source`` and the text.
    """
    if text is None:
        return POINT
    if isinstance(text, Tool):
        return text
    parts = [p.strip() for p in str(text).strip().lower().split(":")]
    shape = parts[0]
    try:
        numbers = [float(p) for p in parts[1:]]
    except ValueError:
        raise CamError(f"{source}: {text!r} is not a tool (point, flat:D, ball:D or v:ANGLE:TIP, in mm and "
                       f"degrees)") from None
    counts = {"point": (0, 0), "flat": (1, 1), "ball": (1, 1), "v": (2, 3)}
    if shape not in counts or not counts[shape][0] <= len(numbers) <= counts[shape][1]:
        raise CamError(f"{source}: {text!r} is not a tool (point, flat:D, ball:D or v:ANGLE:TIP, in mm and "
                       f"degrees)")
    try:
        if shape == "point":
            return POINT
        if shape in ("flat", "ball"):
            return Tool(shape, diameter_mm=numbers[0])
        diameter = numbers[2] if len(numbers) == 3 else max(V_SHANK_MM, numbers[1] * 2)
        return Tool("v", diameter_mm=diameter, angle_deg=numbers[0], tip_mm=numbers[1])
    except CamError as exc:
        raise CamError(f"{source}: {exc}") from None


def tool_of_settings(t: "object") -> Tool:
    """The :class:`Tool` of a ``[tool]`` settings table (:class:`cam.settings.ToolShape`)."""
    shape = getattr(t, "shape", "point")
    diameter = float(getattr(t, "diameter_mm", 0.0))
    if shape == "v" and diameter == 0:
        diameter = max(V_SHANK_MM, 2 * float(getattr(t, "tip_mm", 0.0)))
    if shape == "point":
        return POINT
    return Tool(shape, diameter_mm=diameter, angle_deg=float(getattr(t, "angle_deg", 0.0)),
                tip_mm=float(getattr(t, "tip_mm", 0.0)))


def footprint_px(tool: Tool, px_mm: float, zpx_mm: float, centre: tuple[float, float] = (0.0, 0.0)
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixel centres a tool touches with its axis at ``centre`` (pixels, relative to pixel (0, 0)):
    ``(dy (K,), dx (K,), rise_zpx (K,))``.

    ``rise_zpx`` (float) is how far, in Z pixels, the tool's surface stays above its tip over that pixel
    centre.  The point tool touches its own pixel only.
    """
    if tool.is_point:
        z = np.zeros(1, np.int64)
        return z, z.copy(), z.copy()
    reach = int(math.ceil(tool.radius_mm / px_mm)) + 1
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    dy, dx = dy.ravel(), dx.ravel()
    h_mm = tool.profile_mm(np.hypot(dx - centre[0], dy - centre[1]) * px_mm)
    keep = np.isfinite(h_mm)
    return dy[keep].astype(np.int64), dx[keep].astype(np.int64), h_mm[keep] / zpx_mm


def _over_footprint(a: np.ndarray, dy: np.ndarray, dx: np.ndarray, add: np.ndarray, out: np.ndarray,
                    reduce: np.ufunc, fill: float, shift: int = 0) -> np.ndarray:
    """Fold ``a[i + dy_k - shift, j + dx_k - shift] + add_k`` over every offset ``k`` into ``out`` (shape
    ``(h, w)``, updated in place with ``reduce``, ``np.minimum`` or ``np.maximum``); outside ``a`` is ``fill``."""
    h, w = out.shape
    reach = int(max(np.abs(dy).max(initial=0), np.abs(dx).max(initial=0))) + shift + 1
    padded = np.full((a.shape[0] + 2 * reach, a.shape[1] + 2 * reach), fill, np.float64)
    padded[reach:reach + a.shape[0], reach:reach + a.shape[1]] = a
    for oy, ox, r in zip(dy.tolist(), dx.tolist(), add.tolist()):
        y0, x0 = reach + oy - shift, reach + ox - shift
        reduce(out, padded[y0:y0 + h, x0:x0 + w] + r, out=out)
    return out


def lowest_under_footprint(d: np.ndarray, dy: np.ndarray, dx: np.ndarray, rise: np.ndarray, out_hw: tuple[int, int],
                           shift: int) -> np.ndarray:
    """``floor(min over k of d[i + dy_k - shift, j + dx_k - shift] + rise_k)`` for each ``(i, j)`` of
    ``out_hw`` (whole Z pixels, rounded down once, after the least is taken: never below any target); outside
    ``d`` is the surface (0)."""
    cap = int(d.max(initial=0))
    # where the tool's surface is above every target it cannot limit anything
    keep = rise < cap
    out = _over_footprint(d, dy[keep], dx[keep], rise[keep], np.full(out_hw, float(cap), np.float64),
                          np.minimum, 0.0, shift)
    # a least that is a whole number in exact arithmetic may come out a hair under it in floats: such a hair
    # (under 1e-7 Z pixel, far below any machine's resolution) is not taken as a whole pixel less
    return np.floor(out + 1e-7).astype(np.int64)


def drop_depth_px(depth_px: np.ndarray, tool: Tool, px_mm: float, zpx_mm: float) -> np.ndarray:
    """The deepest the tool's tip may go with its axis over each pixel centre without cutting below
    ``depth_px`` at any pixel centre.

    Args:
        depth_px: ``(H, W)`` int target depth of each pixel in Z pixels (0 = the surface, untouched); the
            material outside the array counts as surface.
        tool: the cutter.
        px_mm: a pixel's size in X and Y (mm); zpx_mm: a Z pixel's (mm).

    Returns:
        ``(H, W)`` int64 allowed tip depth in Z pixels, ``<= depth_px`` everywhere (equal for the point tool).
    """
    d = np.asarray(depth_px, np.int64)
    if tool.is_point:
        return d.copy()
    dy, dx, rise = footprint_px(tool, px_mm, zpx_mm)
    return np.maximum(np.minimum(lowest_under_footprint(d, dy, dx, rise, d.shape, 0), d), 0)


def corner_depth_px(depth_px: np.ndarray, tool: Tool, px_mm: float, zpx_mm: float) -> np.ndarray:
    """As :func:`drop_depth_px`, with the axis at each pixel corner: ``(H + 1, W + 1)`` int64, entry ``(i, j)``
    for the corner shared by pixels ``(i - 1, j - 1)`` and ``(i, j)`` (the midpoint of a diagonal move).

    A move between two pixels side by side is nearest every pixel centre at one of its ends, so the ends'
    depths keep it safe; a diagonal move passes closer to the two pixels beside it than either end does, at
    its midpoint, so the planner keeps diagonal moves no deeper than this.
    """
    d = np.asarray(depth_px, np.int64)
    dy, dx, rise = footprint_px(tool, px_mm, zpx_mm, centre=(-0.5, -0.5))
    return np.maximum(lowest_under_footprint(d, dy, dx, rise, (d.shape[0] + 1, d.shape[1] + 1), 0), 0)


def reach_depth_px(allowed_px: np.ndarray, tool: Tool, px_mm: float, zpx_mm: float) -> np.ndarray:
    """How deep the tool cuts each pixel centre when its tip goes to ``allowed_px`` over every pixel: the
    deepest, over the pixels ``p`` within its radius, of ``allowed(p) - profile(distance)`` (Z pixels,
    float ``(H, W)``).  ``depth - reach`` is the material the tool leaves (its rest)."""
    a = np.asarray(allowed_px, np.float64)
    if tool.is_point:
        return a.copy()
    reach = int(math.ceil(tool.radius_mm / px_mm))
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    rise = tool.profile_mm(np.hypot(dy, dx) * px_mm).ravel() / zpx_mm
    keep = np.isfinite(rise)
    out = _over_footprint(a, dy.ravel()[keep], dx.ravel()[keep], -rise[keep], a.copy(), np.maximum, -np.inf)
    return np.maximum(out, 0.0)
