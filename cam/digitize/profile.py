"""Z profiles: the depth of each layer of a 3D object (thesis 4.1.1, 4.1.3, Figure 4.5).

A profile drawing has a white background, black axes and a red origin pixel
where they meet.  The horizontal axis counts layers, the vertical one gives
depth: the blue curve's vertical distance in pixels from the horizontal axis
(above or below it) is the depth of the layer of that column, and the first
column after the origin is layer 1.  There must be only one blue pixel per
column ("only one z depth value for a given layer").

The same curve can come from code: a sequence of depths, a function of the
layer number, a CSV file of depths, or a small arithmetic expression in ``k``
(the layer, from 1) and ``n`` (the layer count), e.g. ``"40*sqrt(1-((n-k)/n)**2)"``.
"""
from __future__ import annotations

import ast
import math
import operator
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence, Union

import numpy as np

from ..options import MAX_DEPTH_PX  # the deepest depth any option or profile may ask for
from .drawing import BLACK, BLUE, RED, Drawing, load_image
from .drawing import _read_rgb as read_rgb
from .drawing import _to_rgb
from ..errors import DrawingError, ParseError, PlanError

def to_rgb(array: np.ndarray) -> np.ndarray:
    """An image array as ``(H, W, 3)`` RGB (see :func:`cam.digitize.drawing.load_image`)."""
    return _to_rgb(array, bgr=False, source="<array>")


__all__ = ["Profile", "load_profile", "profile_from_expr", "profile_from_csv", "profile_from_rgb", "as_profile"]


@dataclass(frozen=True)
class Profile:
    """Depth per layer.

    Attributes:
        depth_px: ``(n_layers,)`` int64, the depth of layer k at index k-1, in Z pixels (>= 0).
        source: where it came from.
    """

    depth_px: np.ndarray
    source: str = "<profile>"
    warnings: tuple[str, ...] = ()
    """Thesis rules the drawing breaks (several blue pixels in a column, ...), read anyway."""

    @property
    def n_layers(self) -> int:
        return int(len(self.depth_px))

    def depth_of(self, levels: np.ndarray) -> np.ndarray:
        """Depth in Z pixels of each layer number in ``levels`` (from 1)."""
        levels = np.asarray(levels)
        if len(levels) and int(levels.max()) > self.n_layers:
            raise PlanError(f"profile has {self.n_layers} layers, the object has {int(levels.max())}")
        return self.depth_px[levels - 1]


def _from_values(values: Sequence[float], source: str) -> Profile:
    arr = np.asarray(values, np.float64)
    if arr.ndim != 1 or len(arr) == 0:
        raise PlanError(f"{source}: a profile needs at least one depth")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > MAX_DEPTH_PX):
        bad = int(np.flatnonzero(~np.isfinite(arr) | (arr < 0) | (arr > MAX_DEPTH_PX))[0])
        raise PlanError(f"{source}: depth of layer {bad + 1} must be a number 0..{MAX_DEPTH_PX} Z pixels, "
                        f"got {arr[bad]}")
    return Profile(np.rint(arr).astype(np.int64), source)


def profile_from_drawing(drawing: Drawing, rgb: np.ndarray | None = None) -> Profile:
    """Read a profile drawing (see the module docstring), as people draw and save them.

    The blue curve may touch or run along either axis (a blue pixel on the layer axis is depth 0), and a
    column may hold several blue pixels (a thick, anti-aliased or JPEG-saved curve): each layer's depth is
    the blue pixel farthest from the layer axis in its column.  Breaking the thesis rules (one blue pixel per
    column) is a warning of the profile.  ``rgb``: the drawing's ``(H, W, 3)`` pixels when at hand (a file):
    a dark bluish pixel is then blue too.
    """
    c = drawing.classes
    src = drawing.source
    black = c == BLACK
    blue = c == BLUE
    if rgb is not None:
        px = np.asarray(rgb).astype(np.int32)
        luma = (299 * px[..., 0] + 587 * px[..., 1] + 114 * px[..., 2]) // 1000
        blue |= (luma < 128) & (px[..., 2] - np.maximum(px[..., 0], px[..., 1]) > _BLUISH_MIN)
        black &= ~blue
    reds = np.argwhere(c == RED)
    if len(reds) > 1:
        r, col = reds[1]
        raise DrawingError(f"{src}: profile must have one red origin pixel, found {len(reds)} (another at x={col}, y={r})")
    if len(reds) == 1:
        r0, c0 = (int(v) for v in reds[0])
    else:
        raise DrawingError(f"{src}: profile has no red origin pixel")
    axis = black | blue  # a blue curve on an axis covers it
    if not (c0 + 1 < c.shape[1] and axis[r0, c0 + 1]):
        raise DrawingError(f"{src}: no black horizontal (layer) axis to the right of the origin (x={c0}, y={r0})")
    if not ((r0 > 0 and axis[r0 - 1, c0]) or (r0 + 1 < c.shape[0] and axis[r0 + 1, c0])):
        raise DrawingError(f"{src}: no black vertical (depth) axis at the origin (x={c0}, y={r0})")
    blue[:, : c0 + 1] = False  # the depth axis's column and what lies left of it are no layers
    if not blue.any():
        raise DrawingError(f"{src}: profile has no blue curve right of the origin (x={c0}, y={r0})")
    per_col = blue.sum(axis=0)
    cols = np.flatnonzero(per_col)
    last = int(cols.max())
    missing = [k for k in range(c0 + 1, last + 1) if per_col[k] == 0]
    if missing:
        raise DrawingError(
            f"{src}: layer {missing[0] - c0} (column {missing[0]}) has no blue depth pixel; the curve must be continuous"
        )
    rows = np.arange(c.shape[0])[:, None]
    distance = np.where(blue[:, c0 + 1 : last + 1], np.abs(rows - r0), -1)
    warnings = []
    crowded = np.flatnonzero((c == BLUE).sum(axis=0)[c0 + 1 : last + 1] > 1)
    if len(crowded):
        listed = ", ".join(str(int(k) + 1) for k in crowded[:8]) + (" ..." if len(crowded) > 8 else "")
        warnings.append(f"{src}: layers {listed} have more than one blue pixel (thesis: one depth per layer); "
                        f"each takes the one farthest from the layer axis")
    prof = _from_values(distance.max(axis=0), src)
    return Profile(prof.depth_px, src, tuple(warnings))


_BLUISH_MIN = 40
"""A dark pixel whose blue exceeds its red and green by more than this is the blue curve (JPEG, anti-aliasing)."""
_BLUE_MIN = 30
"""A pixel of the layer axis whose blue exceeds its red and green by this much is the curve running along it."""
_INK_MIN = 60
"""Darkness (255 - luma) from which a pixel off the axes may be the curve (pure blue has 226)."""
_INK_CORE = 0.85
"""A column's curve pixels are those at least this share as dark as its darkest (a soft line's fringe is not)."""
_AXIS_DARK = 110
"""Luma below which a pixel that is not bluish may be an axis."""
_PURE = 24
"""A channel within this of 0 or 255 is clean; a drawing with other pixels is read as photo-like."""


def is_clean_rgb(rgb: np.ndarray) -> bool:
    """Whether ``(H, W, 3)`` RGB pixels are all clean palette colours (each channel near 0 or 255)."""
    px = np.asarray(rgb)
    return bool(np.all((px <= _PURE) | (px >= 255 - _PURE)))


def profile_from_rgb(rgb: np.ndarray, source: str = "<profile>") -> Profile:
    """Read a photo-like profile drawing (JPEG-saved, anti-aliased): ``(H, W, 3)`` RGB, image frame.

    Colours do not survive JPEG at one pixel's width (4:2:0 subsampling shares colour between 2 x 2 pixels:
    a blue pixel next to the black axis comes out dark grey, the red origin disappears), darkness does.  So:
    the axes are the darkest long row and column and the origin is where they cross; the curve is the ink
    off the layer axis right of the depth axis; each layer's depth is the farthest from the layer axis of the
    pixels in its column at least :data:`_INK_CORE` as dark as its darkest (so a soft line's fringe does not
    count), and a column with no ink off the axis is a curve running along the axis (depth 0), as long as
    the curve goes on further right.  The blue of the curve decides where it ends on the axis row.
    """
    px = np.asarray(rgb).astype(np.int32)
    if px.ndim != 3 or px.shape[2] != 3 or min(px.shape[:2]) < 3:
        raise DrawingError(f"{source}: a profile drawing must be an RGB image of at least 3x3 pixels")
    ink = 255 - (299 * px[..., 0] + 587 * px[..., 1] + 114 * px[..., 2]) // 1000
    blueness = px[..., 2] - np.maximum(px[..., 0], px[..., 1])
    dark = ink > 255 - _AXIS_DARK
    r0 = int(np.argmax(dark.sum(axis=1)))
    c0 = int(np.argmax(dark.sum(axis=0)))
    if dark[r0].sum() < 3 or dark[:, c0].sum() < 3:
        raise DrawingError(f"{source}: no black axes (a horizontal layer axis and a vertical depth axis)")
    # darkness above what each row has anyway (the rows beside a soft axis are all a little dark)
    ink = ink - np.median(ink[:, c0 + 1 :], axis=1).astype(np.int32)[:, None] if c0 + 1 < ink.shape[1] else ink
    curve = ink >= _INK_MIN
    curve[r0] = False  # the layer axis itself
    curve[:, : c0 + 1] = False
    on_axis = blueness[r0] >= _BLUE_MIN
    on_axis[: c0 + 1] = False
    cols = np.flatnonzero(curve.any(axis=0) | on_axis)
    if not len(cols):
        raise DrawingError(f"{source}: profile has no blue curve right of the origin (x={c0}, y={r0})")
    last = int(cols.max())
    span = slice(c0 + 1, last + 1)
    peak = np.where(curve, ink, 0).max(axis=0)
    core = curve & (ink >= _INK_CORE * peak[None, :])
    rows = np.arange(px.shape[0])[:, None]
    distance = np.where(core[:, span], np.abs(rows - r0), 0).max(axis=0)  # no ink off the axis: depth 0
    prof = _from_values(distance, source)
    note = (f"{source}: read as a photo-like drawing (JPEG or anti-aliased): the origin is where the axes "
            f"cross (x={c0}, y={r0})")
    return Profile(prof.depth_px, source, (note,))


def _quoted(text: str) -> str:
    """A number as a message quotes it: at most 24 characters."""
    return f"'{text}'" if len(text) <= 24 else f"'{text[:21]}...'"


def profile_from_csv(path: str | os.PathLike) -> Profile:
    """Depths from a CSV/text file: one depth per line, or ``layer,depth`` lines (a header line is allowed).

    Raises:
        ParseError: naming ``file:line`` for a line that is not a depth, a layer out of order, a depth that is
            not a number 0..1e6 Z pixels (inf, nan and hundreds of digits included), more than 1e6 layers.
    """
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ParseError(f"{p}: cannot read profile ({exc})") from None
    depths: list[float] = []
    for i, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = [s.strip() for s in line.split(",")]
        try:
            values = [float(s) for s in parts]
        except ValueError:
            if i == 1 and not depths:
                continue  # header
            raise ParseError(f'{p}:{i}: expected a depth or layer,depth, got "{raw[:40]}"') from None
        if len(values) not in (1, 2):
            raise ParseError(f'{p}:{i}: expected a depth or layer,depth, got "{raw[:40]}"')
        if len(values) == 2 and values[0] != len(depths) + 1:
            raise ParseError(f"{p}:{i}: expected layer {len(depths) + 1}, got {_quoted(parts[0])}")
        if not 0 <= values[-1] <= MAX_DEPTH_PX:  # NaN too
            raise ParseError(f"{p}:{i}: depth {_quoted(parts[-1])} is out of range: 0..{MAX_DEPTH_PX} Z pixels")
        if len(depths) == MAX_LAYERS:
            raise ParseError(f"{p}:{i}: more than {MAX_LAYERS} layers")
        depths.append(values[-1])
    if not depths:
        raise ParseError(f"{p}: no depths in the profile file")
    return _from_values(depths, str(p))


_FUNCS = {name: getattr(math, name) for name in ("sqrt", "sin", "cos", "tan", "exp", "log", "floor", "ceil", "fabs")}
_FUNCS.update({"abs": abs, "min": min, "max": max, "round": round})
_CONSTS = {"pi": math.pi, "e": math.e}
_BINARY = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
    ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: operator.pow,
}
_MAX_EXPR_CHARS = 500
_MAX_NODES = 200
_MAX_MAGNITUDE = 1e12
"""No number in a profile expression, given or computed, may be larger: depths are pixels, not astronomy."""
_MAX_EXPONENT = 64.0
MAX_LAYERS = 1_000_000


class _Evaluator:
    """Evaluates a parsed profile expression in floats, node by node: no ``eval``, every value bounded."""

    def __init__(self, expr: str, names: dict[str, float]) -> None:
        self.expr = expr
        self.names = names

    def _bounded(self, value: float) -> float:
        if not isinstance(value, (int, float)) or abs(value) > _MAX_MAGNITUDE or not math.isfinite(value):
            raise PlanError(f"profile expression '{self.expr}': a value is out of range ({value!r}; at most "
                            f"{_MAX_MAGNITUDE:g} either way)")
        return float(value)

    def value(self, node: ast.AST) -> float:
        if isinstance(node, ast.Expression):
            return self.value(node.body)
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            return self._bounded(node.value)
        if isinstance(node, ast.Name) and node.id in self.names:
            return self.names[node.id]
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            v = self.value(node.operand)
            return -v if isinstance(node.op, ast.USub) else v
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            a, b = self.value(node.left), self.value(node.right)
            if isinstance(node.op, ast.Pow) and (abs(b) > _MAX_EXPONENT or (a == 0 and b < 0)):
                raise PlanError(f"profile expression '{self.expr}': the power {a:g} ** {b:g} is out of range "
                                f"(exponents at most {_MAX_EXPONENT:g} either way)")
            try:
                return self._bounded(_BINARY[type(node.op)](a, b))
            except (ArithmeticError, ValueError, TypeError) as exc:
                raise PlanError(f"profile expression '{self.expr}': {exc}") from None
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS \
                and not node.keywords and 1 <= len(node.args) <= 8:
            args = [self.value(a) for a in node.args]
            try:
                return self._bounded(_FUNCS[node.func.id](*args))
            except (ArithmeticError, ValueError, TypeError) as exc:
                raise PlanError(f"profile expression '{self.expr}': {node.func.id}: {exc}") from None
        if isinstance(node, ast.Name):
            raise PlanError(f"profile expression '{self.expr}': unknown name '{node.id}' (use k, n, pi, e, sqrt, ...)")
        raise PlanError(f"profile expression '{self.expr}': '{type(node).__name__}' is not allowed "
                        f"(numbers, k, n, pi, e, + - * / // % **, sqrt, sin, ...)")


def profile_from_expr(expr: str, n_layers: int) -> Profile:
    """Depths ``f(k)`` for k = 1..n_layers from an arithmetic expression in ``k`` and ``n``.

    Only numbers, + - * / // % **, ``k``, ``n``, ``pi``, ``e`` and the functions
    sqrt sin cos tan exp log floor ceil fabs abs min max round are allowed.  The expression is
    evaluated by a small evaluator (never ``eval``) in floats: every number, given or computed, is at
    most 1e12 either way, exponents at most 64, and the expression at most 500 characters.

    >>> profile_from_expr("2*k", 3).depth_px.tolist()
    [2, 4, 6]
    """
    if len(expr) > _MAX_EXPR_CHARS:
        raise PlanError(f"profile expression is {len(expr)} characters long; at most {_MAX_EXPR_CHARS}")
    if not (1 <= n_layers <= MAX_LAYERS):
        raise PlanError(f"a profile has 1..{MAX_LAYERS} layers, got {n_layers}")
    try:
        tree = ast.parse(expr, mode="eval")
    except (SyntaxError, ValueError):
        raise PlanError(f"profile expression '{expr}' is not valid arithmetic") from None
    if sum(1 for _ in ast.walk(tree)) > _MAX_NODES:
        raise PlanError(f"profile expression '{expr}' is too long (at most {_MAX_NODES} parts)")
    values = []
    for k in range(1, n_layers + 1):
        names = {**_CONSTS, "k": float(k), "n": float(n_layers)}
        try:
            values.append(_Evaluator(expr, names).value(tree))
        except PlanError as exc:
            raise PlanError(f"{exc} (at layer k={k})") from None
    return _from_values(values, f"expr:{expr}")


ProfileLike = Union[Profile, str, os.PathLike, np.ndarray, Sequence[float], Callable[[int], float], Drawing]


def load_profile(source: str | os.PathLike | np.ndarray | Drawing) -> Profile:
    """Load a profile drawing (image file or array) or a CSV of depths (``.csv``/``.txt``)."""
    if isinstance(source, Drawing):
        return profile_from_drawing(source)
    if isinstance(source, (str, os.PathLike)) and Path(source).suffix.lower() in (".csv", ".txt"):
        return profile_from_csv(source)
    rgb = to_rgb(source) if isinstance(source, np.ndarray) else read_rgb(Path(source))
    name = "<array>" if isinstance(source, np.ndarray) else str(source)
    if not is_clean_rgb(rgb):  # JPEG-saved or anti-aliased: read from the colours themselves
        return profile_from_rgb(rgb, name)
    return profile_from_drawing(load_image(source), rgb=rgb)


def as_profile(profile: ProfileLike, n_layers: int) -> Profile:
    """Anything that describes a profile, as a :class:`Profile` (a function is sampled at k = 1..n_layers)."""
    if isinstance(profile, Profile):
        return profile
    if isinstance(profile, (str, os.PathLike, Drawing)):
        return load_profile(profile)
    if callable(profile):
        return _from_values([profile(k) for k in range(1, n_layers + 1)], "<function>")
    arr = np.asarray(profile)
    if arr.ndim >= 2:
        return load_profile(arr)
    return _from_values(arr, "<sequence>")
