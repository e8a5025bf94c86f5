"""Digitizing: a classified :class:`~cam.digitize.drawing.Drawing` to a :class:`~cam.digitize.digitized.Digitized` matrix.

Pure computation on arrays: nothing here reads files or touches ports.
"""
from __future__ import annotations

import numpy as np

from .digitized import Digitized
from .drawing import BLACK, Drawing, load_image
from ..errors import DrawingError
from .peel3d import peel_layers_padded, trace_padded
from .trace2d import START_RULES, trace_curves

__all__ = ["digitize", "START_RULES"]


def _stray_warning(objects: list[np.ndarray]) -> list[str]:
    singles = [o for o in objects if len(o) == 1]
    if not singles:
        return []
    where = ", ".join(f"({int(o[0, 0])}, {int(o[0, 1])})" for o in singles[:5])
    return [
        f"the object count ({len(objects)}) includes {len(singles)} single-pixel object(s), "
        f"probably stray points: {where}"
    ]


def digitize(drawing: Drawing | np.ndarray | str, *, start: str = "top") -> Digitized:
    """Trace a drawing into a digitized matrix.

    Args:
        drawing: a :class:`Drawing` (or anything :func:`cam.load_image` accepts).
        start: ``"top"``, ``"min-distance"`` or ``"thesis"`` (thesis 4.1.4.2; see
            :func:`cam.digitize.trace2d.trace_curves`).

    Returns:
        A :class:`Digitized`.  For a 2D drawing (black curves): one object per
        traced curve, its ``level`` the object number.  For a 3D drawing
        (black contour, red interior): one object per traced ring, its
        ``level`` the layer (see :mod:`cam.digitize.peel3d`; ``start`` is not
        used).  Warnings of the drawing are carried over.

    >>> import numpy as np
    >>> img = np.full((6, 7), 255, np.uint8); img[2, 1:4] = 0; img[4, 3:6] = 0
    >>> d = digitize(img)
    >>> len(d.objects), d.to_array()[:, :3].tolist()
    (2, [[1, 1, 2], [1, 2, 2], [1, 3, 2], [2, 3, 4], [2, 4, 4], [2, 5, 4]])
    """
    if not isinstance(drawing, Drawing):
        drawing = load_image(drawing)
    if start not in START_RULES:
        raise DrawingError(f"unknown start rule '{start}' (choose {' or '.join(START_RULES)})")
    kind = drawing.kind
    if kind == "profile":
        raise DrawingError(f"{drawing.source}: this is a profile drawing (blue curve); use it with --profile")
    if kind == "3d":
        objects, levels = trace_padded(peel_layers_padded(drawing.classes, source=drawing.source), in_place=True)
        warnings = list(drawing.warnings)
        return Digitized("3d", drawing.width_px, drawing.height_px, objects, levels, warnings)
    objects = trace_curves(drawing.classes, start=start, value=BLACK)
    levels = np.arange(1, len(objects) + 1, dtype=np.int32)
    warnings = list(drawing.warnings) + _stray_warning(objects)
    return Digitized("2d", drawing.width_px, drawing.height_px, objects, levels, warnings)
