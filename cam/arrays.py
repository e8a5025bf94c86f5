"""Small numpy helpers the stages share."""
from __future__ import annotations

import numpy as np

__all__ = ["column_range", "max_at_pixels"]


def column_range(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest value of each column of ``(N, K)`` ``points`` (N > 0): two ``(K,)`` arrays of its dtype.

    A column at a time: numpy's ``min(axis=0)`` over a narrow C-order array such as a job's ``(N, 3)`` points
    runs about 5x slower than K strided reductions.
    """
    cols = range(points.shape[1])
    return (np.array([points[:, k].min() for k in cols], points.dtype),
            np.array([points[:, k].max() for k in cols], points.dtype))


def max_at_pixels(out_hw: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``out_hw[y, x] = max(out_hw[y, x], value)`` for every ``(x_px[i], y_px[i], values[i])``, repeats included;
    ``out_hw`` is a C-contiguous ``(H, W)`` map, updated in place and returned.

    On flat indices: ``ufunc.at``'s fast path takes one index array (a tuple of two runs about 5x slower).
    """
    np.maximum.at(out_hw.reshape(-1), np.asarray(y_px, np.int64) * out_hw.shape[1] + x_px, values)
    return out_hw
