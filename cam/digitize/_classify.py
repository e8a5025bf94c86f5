"""Compiled colour classification (numba): one pass over the image, no full-size temporaries.

:func:`classify_kernel` gives exactly the classes that the plain numpy
reference in ``tests/support/references.py`` gives (the rules are in the
docstring of :mod:`cam.digitize.drawing`): per pixel the neutral test and,
for coloured pixels, OpenCV's 8-bit ``COLOR_RGB2HSV_FULL`` hue in its own
integer arithmetic (12-bit fixed point with a rounded division table), then
the hue classes from a 256-entry table; then, only when there is red, the
JPEG contour rule on the red pixels.  :func:`black_rules_kernel` finds the
thesis rule violations of the black pixels in one more pass over the classes.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .._compiled import entry

WHITE, BLACK, RED, BLUE = 0, 1, 2, 3
UNKNOWN = 255
_RED_TO_BLACK = 4  # a red pixel that the contour rule makes black (still red for its neighbours' rule)
_VALLEY_TO_BLACK = 5  # the same, by the thin-dark-line rule (its second pass)
_DIM_RED = 6  # a neutral-looking dark pixel that is the interior's red dimmed by JPEG (red after the hue loop)
_PALE_TO_WHITE = 7  # a pale red or unnamed colour beside white that the pale rule makes white
_DIM_TO_BLACK = 8  # a dim red pixel beside white: an anti-aliased contour pixel, black
_HSV_SHIFT = 12

DIM_CHROMA_MIN = 40
"""A pixel below :data:`~cam.digitize.drawing.CHROMA_MIN` but with at least this chroma, a red hue (red the
largest channel, ``2 |G - B| <= chroma``) and the luminance of red (:data:`DIM_RED_Y_MIN`) is red, not black: JPEG
at quality 60 dims the interior's red beside the contour to (129, 50, 53), chroma 79, as bright as pure red."""
DIM_RED_Y_MIN = 64
"""The least luminance of such a dim red pixel (the contour's black, however red JPEG makes it, stays below); one
4-adjacent to white is the contour, blurred with the red and the white beside it (anti-aliasing), so black."""
PALE_MIN = 128
"""A red or unnamed-colour pixel whose every channel is at least this (paler than halfway to white) and that is
4-adjacent to white is white: JPEG's ringing beside a black line on white (pale cyan (166, 255, 240), pink
(238, 160, 156)); a 3D drawing's red never touches white, and a patch of a wrong colour keeps its inner pixels."""


def hue_division_table() -> np.ndarray:
    """OpenCV's ``hdiv_table256``: ``round((256 << 12) / (6 i))`` for chroma ``i`` (0 for 0)."""
    i = np.arange(256, dtype=np.float64)
    with np.errstate(divide="ignore"):
        t = np.rint((256 << _HSV_SHIFT) / (6.0 * i))
    t[0] = 0
    return t.astype(np.int64)


@entry
@njit(cache=True, nogil=True)
def classify_kernel(img, ch_r, ch_b, chroma_min, dark_sum_max, hue_class, hdiv, contour_y_max, core_y_max,
                    valley_min, out, w):
    """Classify ``img`` (a flattened ``(H, W, 3)`` uint8 image, red in channel ``ch_r``, green in 1, blue in
    ``ch_b``) into ``out`` (the flattened ``(H, W)`` classes).  Flat indices: the loops run about three times
    faster than over 3-D indices.

    Returns ``(n_unknown, first_unknown_flat, n_black)``; ``hue_class[h]`` is the class of OpenCV hue ``h``.
    """
    n = out.shape[0]
    if ch_r == 0:  # constant channels: the loop is vectorised
        n_coloured = _neutral(img, out, n, 0, 2, chroma_min, dark_sum_max)
    else:
        n_coloured = _neutral(img, out, n, 2, 0, chroma_min, dark_sum_max)
    n_unknown = 0
    first_unknown = -1
    n_red = 0
    last_packed = -1
    last_class = np.uint8(UNKNOWN)
    for k in range(n if n_coloured else 0):
        if out[k] == _DIM_RED:  # red or black by its neighbours (_pale_to_white)
            n_red += 1
            continue
        if out[k] != UNKNOWN:
            continue
        r = np.int64(img[3 * k + ch_r])
        g = np.int64(img[3 * k + 1])
        b = np.int64(img[3 * k + ch_b])
        packed = (r << 16) | (g << 8) | b
        if packed == last_packed:  # drawings have few colours: the hue of the last one is reused
            c = last_class
        else:
            c = _hue_class(r, g, b, hue_class, hdiv)
            last_packed = packed
            last_class = c
        out[k] = c
        if c == RED:
            n_red += 1
        elif c == UNKNOWN:
            if n_unknown == 0:
                first_unknown = k
            n_unknown += 1
    if n_red or n_unknown:
        n_red, n_unknown, first_unknown = _pale_to_white(img, out, w)
    if n_red:
        _contour_in_red(img, ch_r, ch_b, contour_y_max, core_y_max, valley_min, out, w)
    n_black = 0
    for k in range(n):
        n_black += out[k] == BLACK
    return n_unknown, first_unknown, n_black


@njit(cache=True, inline="always")
def _hue_class(r, g, b, hue_class, hdiv):
    """The class of a coloured pixel from OpenCV's 8-bit full-range hue, in OpenCV's integer arithmetic."""
    v = max(r, max(g, b))
    diff = v - min(r, min(g, b))
    if v == r:
        hh = g - b
    elif v == g:
        hh = b - r + 2 * diff
    else:
        hh = r - g + 4 * diff
    hh = (hh * hdiv[diff] + (1 << (_HSV_SHIFT - 1))) >> _HSV_SHIFT
    if hh < 0:
        hh += 256
    if hh > 255:
        hh = 255
    return hue_class[hh]


@njit(cache=True, inline="always")
def _neutral(img, out, n, ch_r, ch_b, chroma_min, dark_sum_max):
    """Neutral pixels, branch-free; coloured ones marked UNKNOWN (for the hue loop), dim red ones
    :data:`_DIM_RED` (see :data:`DIM_CHROMA_MIN`); returns how many of both."""
    n_coloured = 0
    for k in range(n):
        r = np.int32(img[3 * k + ch_r])
        g = np.int32(img[3 * k + 1])
        b = np.int32(img[3 * k + ch_b])
        diff = max(r, max(g, b)) - min(r, min(g, b))
        dark = r + g + b < dark_sum_max
        dim_red = (dark and diff >= DIM_CHROMA_MIN and r >= g and r >= b and 2 * abs(g - b) <= diff
                   and 299 * r + 587 * g + 114 * b >= 1000 * DIM_RED_Y_MIN)
        c = np.uint8(_DIM_RED) if dim_red else (np.uint8(BLACK) if dark else np.uint8(WHITE))
        out[k] = c if diff < chroma_min else np.uint8(UNKNOWN)
        n_coloured += (diff >= chroma_min) or dim_red
    return n_coloured


@njit(cache=True, nogil=True)
def _pale_to_white(img, out, w):
    """The pale rule (:data:`PALE_MIN`) and the dim red rule (:data:`DIM_RED_Y_MIN`: red, black beside white), in
    place, order-free (decided on the classes before it); returns the red and unknown pixels left, and the flat
    index of the first unknown one (-1 if none)."""
    n = out.shape[0]
    h = n // w
    flipped = False
    for k in range(n):
        c = out[k]
        if c != RED and c != UNKNOWN and c != _DIM_RED:
            continue
        if c != _DIM_RED and min(img[3 * k], min(img[3 * k + 1], img[3 * k + 2])) < PALE_MIN:
            continue
        i = k // w
        j = k - i * w
        if ((i > 0 and out[k - w] == WHITE) or (i < h - 1 and out[k + w] == WHITE)
                or (j > 0 and out[k - 1] == WHITE) or (j < w - 1 and out[k + 1] == WHITE)):
            out[k] = _DIM_TO_BLACK if c == _DIM_RED else _PALE_TO_WHITE
            flipped = True
    n_red = 0
    n_unknown = 0
    first_unknown = -1
    for k in range(n):
        if out[k] == _DIM_RED:
            out[k] = RED
        elif flipped and out[k] == _PALE_TO_WHITE:
            out[k] = WHITE
        elif flipped and out[k] == _DIM_TO_BLACK:
            out[k] = BLACK
        n_red += out[k] == RED
        if out[k] == UNKNOWN:
            if n_unknown == 0:
                first_unknown = k
            n_unknown += 1
    return n_red, n_unknown, first_unknown


@njit(cache=True, inline="always")
def _luma(img, k, ch_r, ch_b):
    return (np.float32(0.299) * np.float32(img[3 * k + ch_r]) + np.float32(0.587) * np.float32(img[3 * k + 1])
            + np.float32(0.114) * np.float32(img[3 * k + ch_b]))


@njit(cache=True, nogil=True)
def _contour_in_red(img, ch_r, ch_b, contour_y_max, core_y_max, valley_min, out, w):
    """The JPEG contour rule (module docstring of :mod:`cam.digitize.drawing`), on red pixels only, in place.

    Two passes, so that no pixel's fate depends on the scan order: first the dark red pixels that touch white
    (the contour's outer side), then the thin dark lines among the rest; a thin-line candidate with three or
    more black 8-neighbours after the first pass lies beside the contour, not on it (JPEG's dark ringing on the
    inner side of a staircase contour, darker than the white and the red across the line's corner): the
    1-pixel contour has at most two (thesis 4.1.1), so it stays red; so does one beside a black pixel that already
    has two black neighbours (black, it would thicken the contour into a corner, as on the inner side of a
    diagonal contour).
    """
    n = out.shape[0]
    h = n // w
    y_contour = np.float32(contour_y_max)
    y_core = np.float32(core_y_max)
    v_min = np.float32(valley_min)
    flipped = False
    for second in (False, True):
        for k in range(n):
            if out[k] != RED:
                continue
            y = _luma(img, k, ch_r, ch_b)
            if not y < (y_core if second else y_contour):
                continue
            i = k // w
            j = k - i * w
            if not second:
                if not (i == 0 or out[k - w] == WHITE or i == h - 1 or out[k + w] == WHITE
                        or j == 0 or out[k - 1] == WHITE or j == w - 1 or out[k + 1] == WHITE):
                    continue
            else:
                valley = -np.inf
                for d in range(4):  # along a row, a column and both diagonals; the image edge repeats
                    di = 0 if d == 0 else 1
                    dj = 1 if d == 0 else (0 if d == 1 else (1 if d == 2 else -1))
                    k0 = min(max(i - di, 0), h - 1) * w + min(max(j - dj, 0), w - 1)
                    k1 = min(max(i + di, 0), h - 1) * w + min(max(j + dj, 0), w - 1)
                    valley = max(valley, min(_luma(img, k0, ch_r, ch_b), _luma(img, k1, ch_r, ch_b)) - y)
                if not valley >= v_min:
                    continue
            lone = True  # a red pixel with no red 8-neighbour (a profile's origin) stays red
            n_black = 0
            a0 = b0 = a1 = b1 = -9
            for a in range(max(i - 1, 0), min(i + 2, h)):
                for b in range(max(j - 1, 0), min(j + 2, w)):
                    q = out[a * w + b]
                    if (a != i or b != j) and (q == RED or q == _RED_TO_BLACK or q == _VALLEY_TO_BLACK):
                        lone = False
                    if q == BLACK or q == _RED_TO_BLACK:
                        n_black += 1
                        if n_black == 1:
                            a0, b0 = a, b
                        else:
                            a1, b1 = a, b
            if lone or (second and n_black > 2):
                continue
            if second and n_black > 0 and (_thickened(out, a0, b0, h, w) or (n_black == 2
                                                                            and _thickened(out, a1, b1, h, w))):
                continue  # black, it would give a contour pixel a third black neighbour: beside the contour
            out[k] = _VALLEY_TO_BLACK if second else _RED_TO_BLACK
            flipped = True
    if flipped:
        for k in range(n):
            if out[k] == _RED_TO_BLACK or out[k] == _VALLEY_TO_BLACK:
                out[k] = BLACK


@njit(cache=True, inline="always")
def _thickened(out, a, b, h, w):
    """Whether the black pixel ``(a, b)`` already has two black 8-neighbours (one more breaks thesis 4.1.1)."""
    n_black = 0
    for c in range(max(a - 1, 0), min(a + 2, h)):
        for d in range(max(b - 1, 0), min(b + 2, w)):
            q = out[c * w + d]
            n_black += (c != a or d != b) and (q == BLACK or q == _RED_TO_BLACK)
    return n_black >= 2


@entry
@njit(cache=True, nogil=True)
def black_rules_kernel(classes, w, n_listed):
    """Thesis 4.1.1 checks of the black pixels of the flattened ``(H, W)`` ``classes`` in one pass.

    Returns ``(counts, first_rc)``: ``counts[k]`` pixels of kind k (0: more than two black 8-neighbours,
    1: on the border, 2: no black neighbour), ``first_rc[k, :min(count, n_listed)]`` the first (row, col)
    of each kind in row-major order.
    """
    n = classes.shape[0]
    h = n // w
    counts = np.zeros(3, np.int64)
    first = np.zeros((3, n_listed, 2), np.int64)
    for k in range(n):
        if classes[k] != BLACK:
            continue
        i = k // w
        j = k - i * w
        nb = 0
        for a in range(max(i - 1, 0), min(i + 2, h)):
            for b in range(max(j - 1, 0), min(j + 2, w)):
                nb += classes[a * w + b] == BLACK
        nb -= 1
        border = i == 0 or j == 0 or i == h - 1 or j == w - 1
        for kind in range(3):
            hit = nb > 2 if kind == 0 else (border if kind == 1 else nb == 0)
            if hit:
                if counts[kind] < n_listed:
                    first[kind, counts[kind], 0] = i
                    first[kind, counts[kind], 1] = j
                counts[kind] += 1
    return counts, first
