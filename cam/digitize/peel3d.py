"""3D digitizing (thesis 4.1.4.3): a black contour around a red interior, peeled inward into layers.

Layers: the black contour is layer 1; layer k+1 is the red pixels that are
4-adjacent to layer k (the thesis's PaintInner paints red next to the
contour blue, and the blue pixels become the next contour).  Peeling repeats
until no red is left.

Each layer is split into rings (its 8-connected pieces: a dumbbell's layers
split in two at the neck).  A ring is traced from its first pixel in scan
order -- or, after the first ring of a layer, from the ring nearest the tool
-- stepping to the first untraced neighbour in the order of Figure 4.15::

    7 1 6        NW N  NE
    4 X 2   =    W  X  E        order: N, E, S, W, SE, NE, NW, SW
    8 3 5        SW S  SE

When the trace stops with pixels of the ring left (a layer can be two pixels
thick where it turns), it goes on from the untraced pixel of the ring nearest
the tool.  Every pixel of every layer is traced exactly once, and each ring
is one object of the digitized matrix, never a scatter of one-pixel objects.
The toolpath planner bridges the small gaps inside a ring through pixels of
the same layer, so they cost no retract.
"""
from __future__ import annotations

import cv2
import numpy as np

from ._kernels import peel_padded_kernel, trace_layers_kernel
from .drawing import BLACK, RED, WHITE
from ..errors import DrawingError

__all__ = ["peel_layers", "peel_layers_padded", "trace_layers", "trace_padded", "NEIGHBOURS_3D"]

NEIGHBOURS_3D = ((-1, 0), (0, 1), (1, 0), (0, -1), (1, 1), (-1, 1), (-1, -1), (1, -1))
"""(drow, dcol) in the scan order of Figure 4.15: N, E, S, W, SE, NE, NW, SW."""


def peel_layers(classes: np.ndarray, *, source: str = "<array>") -> np.ndarray:
    """Layer number of every pixel of a 3D drawing.

    Args:
        classes: ``(H, W)`` uint8 class array (WHITE/BLACK/RED).

    Returns:
        ``(H, W)`` int32: 1 on the black contour, k+1 on red pixels 4-adjacent
        to layer k, 0 on white.

    Raises:
        DrawingError: red 4-adjacent to white or to the image border (an open
            contour), naming a pixel where the red leaks out; red enclosed by no contour.
    """
    red = classes == RED
    black = classes == BLACK
    white = classes == WHITE
    four = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], np.uint8)
    # every red region must touch a contour
    n, labels = cv2.connectedComponents(red.astype(np.uint8), connectivity=4)
    if n > 1:
        near_black = cv2.dilate(black.astype(np.uint8), four).astype(bool)
        touching = set(np.unique(labels[near_black & red]).tolist())
        for lab in range(1, n):
            if lab not in touching:
                r, c = np.argwhere(labels == lab)[0]
                raise DrawingError(f"{source}: red region at (x={c}, y={r}) has no black contour around it")
    # red next to white, or on the border (outside the image is white paper)
    white_pad = cv2.copyMakeBorder(white.astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=1)
    near_white = cv2.dilate(white_pad, four)[1:-1, 1:-1].astype(bool)
    leak = np.argwhere(red & near_white)
    if len(leak):
        r, c = leak[0]
        raise DrawingError(
            f"{source}: the contour is open: red pixel (x={c}, y={r}) touches white "
            f"({len(leak)} such pixel(s)); close the black contour around the red"
        )
    layer = np.zeros(classes.shape, np.int32)
    layer[black] = 1
    # layer k+1 = red at 4-distance k from the contour: one distance transform does all the peeling
    if red.any():
        not_contour = np.where(black, 0, 255).astype(np.uint8)
        dist = cv2.distanceTransform(not_contour, cv2.DIST_L1, 3)
        layer[red] = dist[red].astype(np.int32) + 1
    return layer


def peel_layers_padded(classes: np.ndarray, *, source: str = "<array>") -> np.ndarray:
    """:func:`peel_layers` with a one-pixel border of zeros: ``(H + 2, W + 2)`` int32.

    One compiled pass (two chamfer sweeps) when every red pixel lies inside the image and touches
    only black or red; otherwise the checks of :func:`peel_layers` run and name the bad pixel.
    """
    padded, suspect = peel_padded_kernel(np.ascontiguousarray(classes, np.uint8), BLACK, RED, WHITE)
    if suspect:
        padded = np.zeros((classes.shape[0] + 2, classes.shape[1] + 2), np.int32)
        padded[1:-1, 1:-1] = peel_layers(classes, source=source)
    return padded


def trace_layers(layer: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Trace every layer into rings (compiled; tests compare it with a plain-Python reference)."""
    h, w = layer.shape
    padded = np.zeros((h + 2, w + 2), np.int32)
    padded[1:-1, 1:-1] = layer
    return trace_padded(padded, in_place=True)


def trace_padded(padded: np.ndarray, *, in_place: bool = False) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`trace_layers` of a layer map already padded by one pixel of zeros (``(H + 2, W + 2)``).

    ``in_place=True`` lets the tracer mark traced pixels in ``padded`` itself (it is left with
    negated layer numbers) instead of working on a copy.
    """
    padded = np.ascontiguousarray(padded, np.int32) if in_place else np.array(padded, np.int32, order="C")
    wp = padded.shape[1]
    offsets = np.array([dr * wp + dc for dr, dc in NEIGHBOURS_3D], np.int64)
    drow = np.array([dr for dr, _ in NEIGHBOURS_3D], np.int64)
    dcol = np.array([dc for _, dc in NEIGHBOURS_3D], np.int64)
    xy, starts, levels = trace_layers_kernel(padded.ravel(), wp, offsets, drow, dcol)
    return [xy[a:b] for a, b in zip(starts[:-1], starts[1:])], levels.astype(np.int32)


