"""A scanned sketch or a photo of a drawing, to a drawing that follows the thesis rules (4.1.1).

Frames: images are arrays indexed ``[row, col]``; sizes are in pixels of the
input (after the optional shrink to ``max_side_px``).

The steps of :func:`trace`:

1. **Background flattening.**  The paper's brightness (uneven light, a
   shadow, a phone's vignette) is estimated by a grey closing (a maximum then
   a minimum filter) wider than any stroke, smoothed, and divided out: paper
   becomes 1.0 everywhere, ink a fraction of it.
2. **Adaptive threshold.**  A pixel is ink when it is darker than its
   neighbourhood's mean by :data:`LOCAL_CONTRAST` and darker than
   :data:`INK_MAX` of the paper, so noise on blank paper stays paper.  Holes
   inside a stroke smaller than a stroke's area are filled.  (The flattened
   image is smoothed a little first, against paper grain and sensor noise.)
3. **Thinning** with scikit-image's ``skeletonize`` to 1-pixel centre lines,
   then every pixel that the 8-connected line does not need (the corner of a
   staircase) is removed.
4. **Specks and spurs.**  A piece with fewer than ``trace_min_length_px`` pixels is
   removed (a speck); so is a branch shorter than that from a free end to a
   junction (a spur), repeatedly.
5. **Junctions.**  Where three or more branches meet, the two that continue
   each other best (the straightest pair, when they turn by less than 60°)
   stay joined through the junction; the others are cut back until no pixel
   has more than two black neighbours.  What is left of them is kept if it is
   still ``trace_min_length_px`` long.
6. **Corners.**  Thinning rounds the corner of a stroke 10 px wide or more by 2-3 px; a turn between two
   straight runs is redrawn through the runs' lines' intersection (:mod:`cam.digitize._corners`).
7. **Border.**  Nothing is left on the image border.
8. ``trace_fill=True``: every white region enclosed by a curve (4-connected, not
   reaching the border) becomes red: a 3D drawing.

>>> import numpy as np
>>> img = np.full((40, 60), 230, np.uint8); img[18:22, 5:55] = 40   # a thick dark bar on grey paper
>>> d = trace(img, trace_min_length_px=5)
>>> d.curves, d.warnings, int(d.black.sum()) >= 40
(1, [], True)
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import cv2
import numpy as np
from scipy import ndimage
from skimage.morphology import skeletonize

from ..errors import DrawingError
from ..options import OPTIONS
from ._corners import sharpen_corners
from .drawing import BLACK, RED, WHITE, Drawing, _read_rgb, check_rules

__all__ = ["trace", "load_sketch", "TracedDrawing", "DEFAULT_MIN_LENGTH_PX", "DEFAULT_MAX_SIDE_PX", "INK_MAX", "LOCAL_CONTRAST"]

DEFAULT_MIN_LENGTH_PX: int = OPTIONS["trace_min_length_px"].default
"""Specks and spurs shorter than this many pixels are removed (the job option ``trace_min_length_px``'s default:
:mod:`cam.options` declares it, with its range, once)."""
DEFAULT_MAX_SIDE_PX = 1000
"""A larger photo is shrunk to this many pixels on its longer side before tracing (the thesis machine's
travel holds 1251 pixels a side)."""
INK_MAX = 0.8
"""Ink is darker than this fraction of the paper's brightness (after flattening)."""
LOCAL_CONTRAST = 0.06
"""... and darker than the mean of its neighbourhood by this fraction of the paper's brightness."""
STRAIGHT_DEG = 60.0
"""Two branches through a junction stay joined when they turn by less than this."""

_OFFSETS = ((-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1))
"""The 8 neighbours clockwise from NW, (row, col): bit i of a neighbourhood code is neighbour i."""


@dataclass
class TracedDrawing(Drawing):
    """A :class:`~cam.digitize.drawing.Drawing` traced from a sketch, with what the tracing did.

    Attributes:
        curves: black curves (8-connected pieces) in the result.
        specks_removed: pieces shorter than ``min_length_px`` removed (ink dots, dirt, noise).
        spurs_removed: short branches from a free end to a junction removed.
        junctions_split: places where three or more branches met, resolved.
        regions_filled: white regions made red (``trace_fill=True``).
        shrink: the input was shrunk by this factor first (1.0: not shrunk).
    """

    curves: int = 0
    specks_removed: int = 0
    spurs_removed: int = 0
    junctions_split: int = 0
    regions_filled: int = 0
    shrink: float = 1.0

    def summary(self) -> str:
        """One line saying what the tracing did."""
        text = (f"{self.curves} curve(s), {self.specks_removed} speck(s) and {self.spurs_removed} spur(s) removed, "
                f"{self.junctions_split} junction(s) split")
        if self.regions_filled:
            text += f", {self.regions_filled} region(s) filled red"
        if self.shrink != 1.0:
            text += f", shrunk by {self.shrink:.3g} first"
        return text


def _grey(image: np.ndarray) -> np.ndarray:
    """``(H, W)`` float32 brightness 0..1 of a grey or RGB(A) uint8 image."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = a[..., :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    elif a.ndim != 2:
        raise DrawingError(f"a sketch must be an (H, W) or (H, W, 3) image array, got shape {a.shape}")
    a = a.astype(np.float32)
    if a.size and a.max() > 1.0:
        a = a / 255.0
    return a


def _flatten(grey: np.ndarray, window_px: int) -> np.ndarray:
    """Brightness divided by the paper's (step 1): paper 1.0, ink less."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (window_px, window_px))
    paper = cv2.morphologyEx(grey, cv2.MORPH_CLOSE, kernel, borderType=cv2.BORDER_REFLECT)
    paper = cv2.GaussianBlur(paper, (0, 0), window_px / 4, borderType=cv2.BORDER_REFLECT)
    return np.clip(grey / np.maximum(paper, 1e-3), 0.0, 1.0)


def _ink(flat: np.ndarray, window_px: int) -> np.ndarray:
    """Ink mask (step 2)."""
    local = cv2.blur(flat, (window_px, window_px), borderType=cv2.BORDER_REFLECT)
    ink = (flat < INK_MAX) & (flat < local - LOCAL_CONTRAST)
    ink = cv2.medianBlur(ink.astype(np.uint8) * 255, 3) > 0  # ragged edges make spurs
    dist = ndimage.distance_transform_edt(ink)
    width_px = 2.0 * float(np.median(dist[dist >= 1])) if np.any(dist >= 1) else 1.0
    holes, n = ndimage.label(~ink)  # fill holes inside strokes smaller than a stroke's width squared
    if n:
        area = np.bincount(holes.ravel())
        edge = np.unique(np.concatenate([holes[0], holes[-1], holes[:, 0], holes[:, -1]]))
        small = area < max(4, int(round(width_px * width_px)))
        small[0] = False
        small[edge] = False
        ink |= small[holes]
    return ink


def _codes(mask: np.ndarray) -> np.ndarray:
    """``(H, W)`` int: the 8-bit neighbourhood code of each pixel (bit i: neighbour ``_OFFSETS[i]`` set)."""
    m = np.pad(mask.astype(np.int32), 1)
    h, w = mask.shape
    out = np.zeros((h, w), np.int32)
    for i, (dr, dc) in enumerate(_OFFSETS):
        out |= m[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] << i
    return out


def _removable_table() -> np.ndarray:
    """For each of the 256 neighbourhood codes: may the centre go without changing the line (step 3)?

    Yes when it has at least two neighbours, they form one 8-connected group (without the centre), and the
    background around it is one 4-connected group: a simple point that is not an end.
    """
    table = np.zeros(256, bool)
    for code in range(256):
        on = [(code >> i) & 1 for i in range(8)]
        if sum(on) < 2:
            continue
        # foreground groups of the ring: ring neighbours i, i+1 are adjacent; corners also i, i+2 via an edge
        groups = _ring_groups(on)
        # background: 4-neighbours (edges at 1, 3, 5, 7) off, joined through off corners between them
        edges_off = [i for i in (1, 3, 5, 7) if not on[i]]
        if not edges_off:
            continue
        bg = 0
        seen = set()
        for e in edges_off:
            if e in seen:
                continue
            bg += 1
            stack = [e]
            while stack:
                j = stack.pop()
                if j in seen:
                    continue
                seen.add(j)
                for k in ((j + 2) % 8, (j - 2) % 8):
                    corner = (j + 1) % 8 if k == (j + 2) % 8 else (j - 1) % 8
                    if not on[k] and not on[corner]:
                        stack.append(k)
        table[code] = groups == 1 and bg == 1
    return table


def _ring_groups(on: list[int]) -> int:
    """8-connected groups among the set neighbours of a ring (adjacent along the ring; an edge neighbour also
    touches the edge neighbours two away, e.g. N and E)."""
    seen: set[int] = set()
    groups = 0
    for i in range(8):
        if not on[i] or i in seen:
            continue
        groups += 1
        stack = [i]
        while stack:
            j = stack.pop()
            if j in seen:
                continue
            seen.add(j)
            near = [(j + 1) % 8, (j - 1) % 8]
            if j % 2 == 1:  # an edge neighbour: the next edge neighbours are its 8-neighbours too
                near += [(j + 2) % 8, (j - 2) % 8]
            stack += [k for k in near if on[k] and k not in seen]
    return groups


_REMOVABLE = _removable_table()


def _minimal(skel: np.ndarray) -> np.ndarray:
    """Remove the pixels an 8-connected line does not need, one at a time in scan order, until none is left."""
    skel = skel.copy()
    h, w = skel.shape
    while True:
        codes = _codes(skel)
        cand = np.argwhere(skel & _REMOVABLE[codes])
        if not len(cand):
            return skel
        removed = 0
        for r, c in cand:
            code = 0
            for i, (dr, dc) in enumerate(_OFFSETS):
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and skel[rr, cc]:
                    code |= 1 << i
            if _REMOVABLE[code]:
                skel[r, c] = False
                removed += 1
        if not removed:
            return skel


def _neighbours(mask: np.ndarray) -> np.ndarray:
    """``(H, W)`` int: black 8-neighbours of each pixel."""
    k = np.ones((3, 3), np.float32)
    k[1, 1] = 0
    return np.rint(cv2.filter2D(mask.astype(np.float32), -1, k, borderType=cv2.BORDER_CONSTANT)).astype(np.int64)


_EIGHT = np.ones((3, 3), bool)


def _remove_specks(skel: np.ndarray, min_length_px: int) -> tuple[np.ndarray, int]:
    labels, n = ndimage.label(skel, structure=_EIGHT)
    if n == 0:
        return skel, 0
    sizes = np.bincount(labels.ravel())
    small = sizes < min_length_px
    small[0] = False
    return skel & ~small[labels], int(small[1:].sum())


def _branches(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(junction pixels, junction cluster labels, branch labels, branch count)."""
    junction = skel & (_neighbours(skel) >= 3)
    jl, _ = ndimage.label(junction, structure=_EIGHT)
    bl, nb = ndimage.label(skel & ~junction, structure=_EIGHT)
    return junction, jl, bl, nb


def _remove_spurs(skel: np.ndarray, min_length_px: int) -> tuple[np.ndarray, int]:
    """Remove branches shorter than ``min_length_px`` from a free end to a junction, until none is left."""
    removed = 0
    for _ in range(50):
        junction, jl, bl, nb = _branches(skel)
        if not junction.any():
            break
        count = _neighbours(skel)
        near_junction = cv2.dilate(junction.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        sizes = np.bincount(bl.ravel(), minlength=nb + 1)
        touches = np.zeros(nb + 1, bool)
        touches[np.unique(bl[near_junction & (bl > 0)])] = True
        free_end = np.zeros(nb + 1, bool)
        free_end[np.unique(bl[(count == 1) & (bl > 0)])] = True
        spur = touches & free_end & (sizes < min_length_px)
        spur[0] = False
        if not spur.any():
            break
        skel = skel & ~spur[bl]
        removed += int(spur.sum())
        skel = _minimal(skel)
    return skel, removed


def _direction(branch: np.ndarray, centre: np.ndarray, reach_px: float = 6.0) -> np.ndarray:
    """Unit vector from a junction's centre out along a branch: to the branch's pixels within ``reach_px``."""
    d = branch - centre
    dist = np.hypot(d[:, 0], d[:, 1])
    near = d[dist <= max(reach_px, float(dist.min()) + 1)]
    v = near.mean(axis=0)
    n = float(np.hypot(*v))
    return v / n if n > 0 else v


def _split_junctions(skel: np.ndarray) -> tuple[np.ndarray, int]:
    """Step 5 of the module docstring; returns the new skeleton and the junctions resolved."""
    junction, jl, bl, nb = _branches(skel)
    n_junctions = int(jl.max())
    if n_junctions == 0:
        return skel, 0
    protected = np.zeros_like(skel)
    cut = np.zeros_like(skel)
    h, w = skel.shape
    jpix = ndimage.find_objects(jl)
    for j in range(1, n_junctions + 1):
        sl = jpix[j - 1]
        r0, r1 = max(0, sl[0].start - 1), min(h, sl[0].stop + 1)
        c0, c1 = max(0, sl[1].start - 1), min(w, sl[1].stop + 1)
        here = jl[r0:r1, c0:c1] == j
        centre = np.argwhere(here).mean(axis=0) + (r0, c0)
        touching = np.unique(bl[r0:r1, c0:c1][(bl[r0:r1, c0:c1] > 0)
                                              & (cv2.dilate(here.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)])
        dirs = {}
        for b in touching:
            rr0, rr1 = int(max(0, centre[0] - 8)), int(min(h, centre[0] + 9))
            cc0, cc1 = int(max(0, centre[1] - 8)), int(min(w, centre[1] + 9))
            pts = np.argwhere(bl[rr0:rr1, cc0:cc1] == b) + (rr0, cc0)
            if len(pts):
                dirs[int(b)] = _direction(pts.astype(float), centre)
        best, pair = np.cos(np.radians(180.0 - STRAIGHT_DEG)), None
        keys = sorted(dirs)
        for a in range(len(keys)):
            for b in range(a + 1, len(keys)):
                dot = float(dirs[keys[a]] @ dirs[keys[b]])
                if dot < best:
                    best, pair = dot, (keys[a], keys[b])
        if pair is not None:
            for b in pair:
                protected |= bl == b
            protected[r0:r1, c0:c1] |= here  # the junction joins the pair
        else:
            cut[r0:r1, c0:c1] |= here
    skel = skel & ~cut
    # cut the others back until no pixel has more than two black neighbours
    for _ in range(10_000):
        count = _neighbours(skel)
        bad = skel & (count > 2)
        if not bad.any():
            break
        near_bad = cv2.dilate(bad.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        drop = near_bad & skel & ~protected
        if not drop.any():
            drop = bad  # two protected lines touch: break one
        skel = skel & ~drop
    return skel, n_junctions


def _fill(classes: np.ndarray) -> int:
    """Make every white region (4-connected) that does not reach the border red; returns how many."""
    white = classes == WHITE
    labels, n = ndimage.label(white)
    if n == 0:
        return 0
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    inside = np.ones(n + 1, bool)
    inside[0] = False
    inside[edge] = False
    classes[inside[labels]] = RED
    return int(inside.sum())


def load_sketch(path: str | os.PathLike) -> np.ndarray:
    """``(H, W, 3)`` uint8 RGB of a sketch's image file (PNG, JPEG, BMP, TIFF), its size checked from the
    header before it is decoded (as :func:`cam.load_image`).

    Raises:
        DrawingError: a missing or unreadable file, an image too large.
    """
    return _read_rgb(Path(path))


def trace(
    image: np.ndarray,
    *,
    trace_min_length_px: int = DEFAULT_MIN_LENGTH_PX,
    trace_fill: bool = False,
    max_side_px: Optional[int] = DEFAULT_MAX_SIDE_PX,
    window_px: Optional[int] = None,
    source: str = "<array>",
) -> TracedDrawing:
    """Trace a sketch (a scan or a photo) into a drawing that follows the thesis rules.

    Args:
        image: ``(H, W)`` grey or ``(H, W, 3)`` RGB uint8 array (dark lines on light paper).
        trace_min_length_px: specks and spurs shorter than this are removed (the range of the job option of
            the same name, :data:`cam.options.OPTIONS`: 2..10000).
        trace_fill: mark the regions enclosed by curves red (a 3D drawing); the job option of the same name.
        max_side_px: shrink a larger image to this many pixels on its longer side first (None: never).
        window_px: the background and threshold window (odd; default: about 1/8 of the shorter side, 15..101),
            wider than the thickest stroke.
        source: the name warnings and errors give.

    Returns:
        A :class:`TracedDrawing` (white, black and, with ``trace_fill``, red pixels), ready for
        :func:`cam.digitize` or to save as PNG; its ``warnings`` are the thesis rule checks (empty when every
        rule holds) and :meth:`TracedDrawing.summary` says what was done.

    Raises:
        DrawingError: not an image array, smaller than 8 px a side, or ``trace_min_length_px`` out of its range.
    """
    length = OPTIONS["trace_min_length_px"]
    if not length.in_range(trace_min_length_px) or trace_min_length_px != int(trace_min_length_px):
        raise DrawingError(f"{source}: trace_min_length_px must be {length.range_text()} pixels, "
                           f"got {trace_min_length_px}")
    min_length_px = int(trace_min_length_px)
    grey = _grey(image)
    h, w = grey.shape
    if min(h, w) < 8:
        raise DrawingError(f"{source}: a {w}x{h} image is too small to trace (at least 8 px a side)")
    shrink = 1.0
    if max_side_px is not None and max(h, w) > max_side_px:
        shrink = max_side_px / max(h, w)
        grey = cv2.resize(grey, (max(8, round(w * shrink)), max(8, round(h * shrink))), interpolation=cv2.INTER_AREA)
        h, w = grey.shape
    if window_px is None:
        window_px = int(np.clip(min(h, w) // 8, 15, 101))
    window_px = window_px | 1
    flat = cv2.GaussianBlur(_flatten(grey, window_px), (0, 0), 1.0)  # paper grain and sensor noise
    ink = _ink(flat, window_px)
    ink[[0, -1], :] = False
    ink[:, [0, -1]] = False
    skel = _minimal(skeletonize(ink))
    skel[[0, -1], :] = False  # nothing on the border
    skel[:, [0, -1]] = False
    skel, specks = _remove_specks(skel, min_length_px)
    skel, spurs = _remove_spurs(skel, min_length_px)
    skel, junctions = _split_junctions(skel)
    skel = _minimal(skel)
    skel, _ = sharpen_corners(skel, ink)  # thinning rounds a thick stroke's corner: meet where its lines meet
    skel = _minimal(skel)
    skel, stubs = _remove_specks(skel, min_length_px)
    classes = np.where(skel, BLACK, WHITE).astype(np.uint8)
    filled = _fill(classes) if trace_fill else 0
    _, curves = ndimage.label(skel, structure=_EIGHT)
    return TracedDrawing(classes=classes, warnings=check_rules(classes), source=source, curves=int(curves),
                         specks_removed=specks, spurs_removed=spurs + stubs, junctions_split=junctions,
                         regions_filled=filled, shrink=shrink)
