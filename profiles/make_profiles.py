"""Generate the sample Z-profile drawings (thesis 4.1.1, Figure 4.5).

Run ``python profiles/make_profiles.py [--out DIR]`` (default: this folder).
The output is deterministic: the same bytes on every run.

Layout convention (8-bit RGB PNG, indexed ``[row, col]``):

* white (255, 255, 255) background;
* the ORIGIN is the top-left corner of the axes, at ``(ORIGIN_ROW, ORIGIN_COL)``
  (2, 2), and is the only RED (255, 0, 0) pixel;
* the horizontal (layer) axis is BLACK, along the origin's row, from the column
  right of the origin to ``ORIGIN_COL + N_LAYERS``;
* the vertical (depth) axis is BLACK, along the origin's column, running DOWN
  from the row below the origin (depth grows downward, into the material) to
  2 px below the deepest layer;
* column ``ORIGIN_COL + k`` is layer k (k = 1 .. N_LAYERS; layer 1 is the
  object's outer contour) and holds exactly one BLUE (0, 0, 255) pixel, at row
  ``ORIGIN_ROW + depth_k``, depth in Z pixels.  Every depth is >= 1, so blue
  never overlaps the black axis; no other column holds blue;
* at least a 2 px white margin keeps axes and curve off the image border.

Profiles, each with N_LAYERS = 120 layers (enough for drawings of up to 120
layers):

* ``dome.png``    a circular-arc (hemispherical bowl) depth: 1 at layer 1,
  rising steeply, then levelling off at 40 at layer 120;
* ``cone.png``    linear depth from 1 at layer 1 to 40 at layer 120;
* ``pyramid.png`` steps: depth 5 for layers 1-15, 10 for 16-30, ... 40 for 106-120;
* ``flat.png``    constant depth 10.
"""
from __future__ import annotations

import argparse
import math
import pathlib
from typing import Callable, Sequence

import cv2
import numpy as np

WHITE_RGB = (255, 255, 255)
BLACK_RGB = (0, 0, 0)
RED_RGB = (255, 0, 0)
BLUE_RGB = (0, 0, 255)

N_LAYERS = 120
ORIGIN_ROW, ORIGIN_COL = 2, 2
MARGIN_PX = 2
AXIS_PAST_DEEPEST_PX = 2
MAX_DEPTH_PX = 40


def round_half_up(value: float) -> int:
    """Round to the nearest integer, halves upwards."""
    return int(math.floor(value + 0.5))


def layer_fraction(layer: int) -> float:
    """0.0 at layer 1, 1.0 at the last layer."""
    return (layer - 1) / (N_LAYERS - 1)


def dome_depth_px(layer: int) -> int:
    """Quarter circle: 1 + 39 * sqrt(1 - (1 - t)^2), t from 0 to 1."""
    t = layer_fraction(layer)
    return round_half_up(1 + (MAX_DEPTH_PX - 1) * math.sqrt(1 - (1 - t) ** 2))


def cone_depth_px(layer: int) -> int:
    """Straight line from depth 1 to depth 40."""
    return round_half_up(1 + (MAX_DEPTH_PX - 1) * layer_fraction(layer))


def pyramid_depth_px(layer: int) -> int:
    """Stepped: 5 px deeper every 15 layers, starting at 5."""
    return 5 * (1 + (layer - 1) // 15)


def flat_depth_px(layer: int) -> int:
    """Constant depth 10."""
    return 10


PROFILES: dict[str, Callable[[int], int]] = {
    "dome.png": dome_depth_px,
    "cone.png": cone_depth_px,
    "pyramid.png": pyramid_depth_px,
    "flat.png": flat_depth_px,
}


def depths_px(depth_of_layer: Callable[[int], int]) -> list[int]:
    """Depth of layers 1 .. N_LAYERS; each must be >= 1."""
    depths = [int(depth_of_layer(k)) for k in range(1, N_LAYERS + 1)]
    if min(depths) < 1:
        raise ValueError("every layer needs a depth of at least 1 px")
    return depths


def axis_depth_px(depths: Sequence[int]) -> int:
    """Length of the vertical axis below the origin."""
    return max(depths) + AXIS_PAST_DEEPEST_PX


def draw_profile(depths: Sequence[int]) -> np.ndarray:
    """RGB image of a profile drawing with the module's layout convention."""
    axis_len_px = axis_depth_px(depths)
    height_px = ORIGIN_ROW + axis_len_px + 1 + MARGIN_PX
    width_px = ORIGIN_COL + len(depths) + 1 + MARGIN_PX
    rgb = np.full((height_px, width_px, 3), 255, np.uint8)
    rgb[ORIGIN_ROW, ORIGIN_COL + 1:ORIGIN_COL + len(depths) + 1] = BLACK_RGB
    rgb[ORIGIN_ROW + 1:ORIGIN_ROW + axis_len_px + 1, ORIGIN_COL] = BLACK_RGB
    rgb[ORIGIN_ROW, ORIGIN_COL] = RED_RGB
    for layer, depth in enumerate(depths, start=1):
        rgb[ORIGIN_ROW + depth, ORIGIN_COL + layer] = BLUE_RGB
    return rgb


def write_png(path: pathlib.Path, rgb: np.ndarray) -> pathlib.Path:
    """Write an RGB array as a PNG with cv2 (which wants BGR)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"could not write {path}")
    return path


def read_rgb(path: pathlib.Path) -> np.ndarray:
    """Read a PNG back as an RGB array."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise AssertionError(f"{path.name}: cannot be read back")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def colour_mask(rgb: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    return np.all(rgb == np.array(colour, np.uint8), axis=2)


def check_profile(name: str, path: pathlib.Path, depths: Sequence[int]) -> None:
    """Check a written profile file against the layout convention."""
    rgb = read_rgb(path)
    white, black, red, blue = (colour_mask(rgb, c) for c in (WHITE_RGB, BLACK_RGB, RED_RGB, BLUE_RGB))
    if not (white | black | red | blue).all():
        r, c = np.argwhere(~(white | black | red | blue))[0]
        raise AssertionError(f"{name}: pixel of an unexpected colour at (x={c}, y={r})")
    if [tuple(p) for p in np.argwhere(red)] != [(ORIGIN_ROW, ORIGIN_COL)]:
        raise AssertionError(f"{name}: the only red pixel must be the origin (x={ORIGIN_COL}, y={ORIGIN_ROW})")
    n = len(depths)
    if not black[ORIGIN_ROW, ORIGIN_COL + 1:ORIGIN_COL + n + 1].all():
        raise AssertionError(f"{name}: horizontal axis incomplete on row {ORIGIN_ROW}")
    if not black[ORIGIN_ROW + 1:ORIGIN_ROW + axis_depth_px(depths) + 1, ORIGIN_COL].all():
        raise AssertionError(f"{name}: vertical axis incomplete on column {ORIGIN_COL}")
    if black.sum() != n + axis_depth_px(depths):
        raise AssertionError(f"{name}: black pixels off the axes")
    per_col = blue.sum(axis=0)
    layer_cols = slice(ORIGIN_COL + 1, ORIGIN_COL + n + 1)
    if not (per_col[layer_cols] == 1).all() or per_col.sum() != n:
        raise AssertionError(f"{name}: need exactly one blue pixel in each of the {n} layer columns and none elsewhere")
    found = (np.argmax(blue[:, layer_cols], axis=0) - ORIGIN_ROW).tolist()
    if found != list(depths):
        raise AssertionError(f"{name}: blue depths differ from the intended profile")
    for mask in (black, red, blue):
        if mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
            raise AssertionError(f"{name}: drawing touches the image border")


def make_all(out_dir: pathlib.Path) -> dict[str, pathlib.Path]:
    """Write every profile PNG into ``out_dir``, check them, return name -> path."""
    out_dir = pathlib.Path(out_dir)
    paths = {}
    for name, depth_of_layer in PROFILES.items():
        depths = depths_px(depth_of_layer)
        paths[name] = write_png(out_dir / name, draw_profile(depths))
        check_profile(name, paths[name], depths)
    return paths


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path(__file__).resolve().parent,
                        help="output folder (default: this script's folder)")
    args = parser.parse_args(argv)
    for path in make_all(args.out).values():
        print(path)


if __name__ == "__main__":
    main()
