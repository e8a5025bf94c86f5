"""Make the README's sketch -> trace -> drill pictures again: ``python docs/make_sketch_pictures.py``.

* samples/sketch.jpg: a synthetic phone photo of a pen sketch (a house, a sun, a path), drawn here with
  wobbly thick strokes on off-white paper, a shadow across it and sensor noise, saved as JPEG (seeded: the
  same file every time)
* docs/sketch-drawing.png: ``cam trace samples/sketch.jpg -o docs/sketch-drawing.png``
* docs/sketch-preview.png: ``cam preview docs/sketch-drawing.png --depth 3 -o docs/sketch-preview.png``
* docs/logo-preview.png: ``cam preview samples/logo.svg --fit 60x40 -o docs/logo-preview.png``

The cam used is this checkout's, not an installed one.
"""
from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cam.cli import main as cam_main  # noqa: E402  (this checkout's cam, after the path is set)

W_PX, H_PX = 480, 360
SUB = 16


def _wobbly(rng: np.random.Generator, pts: np.ndarray, amp_px: float) -> np.ndarray:
    """A hand's line: the points resampled every 2 px and bent by a smooth random offset."""
    seg = np.diff(pts, axis=0)
    n = np.maximum(2, (np.hypot(seg[:, 0], seg[:, 1]) / 2).astype(int))
    dense = np.vstack([a + (b - a) * np.linspace(0, 1, k, endpoint=False)[:, None]
                       for a, b, k in zip(pts[:-1], pts[1:], n)] + [pts[-1:]])
    noise = np.cumsum(rng.normal(0, amp_px, dense.shape), axis=0)
    noise = cv2.GaussianBlur(noise.astype(np.float32).reshape(-1, 1, 2), (1, 31), 8).reshape(-1, 2)
    return dense + noise - np.linspace(noise[0], noise[-1], len(noise))


def sketch_photo() -> np.ndarray:
    rng = np.random.default_rng(2024)
    big = np.full((H_PX * 4, W_PX * 4), 255, np.uint8)

    def stroke(pts, closed=False, width_px=4):
        pts = np.asarray(pts, float)
        if closed:
            pts = np.vstack([pts, pts[:1]])
        p = np.rint(_wobbly(rng, pts, 0.25) * 4 * SUB).astype(np.int32)
        cv2.polylines(big, [p.reshape(-1, 1, 2)], False, 0, width_px * 4, cv2.LINE_AA, shift=4)

    stroke([(80, 300), (80, 170), (200, 80), (320, 170), (320, 300)], closed=True)   # the house
    stroke([(170, 300), (170, 220), (230, 220), (230, 300)])                        # the door
    stroke([(105, 190), (145, 190), (145, 225), (105, 225)], closed=True)            # a window
    t = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    stroke(np.c_[400 + 35 * np.cos(t), 80 + 35 * np.sin(t)], closed=True)          # the sun
    stroke([(240, 335), (330, 320), (450, 338)], width_px=3)                         # a path
    for _ in range(9):                                                               # crumbs on the paper
        x, y = rng.uniform(20, W_PX - 20), rng.uniform(20, H_PX - 20)
        cv2.circle(big, (int(x * 4 * SUB), int(y * 4 * SUB)), int(5 * SUB), 0, -1, cv2.LINE_AA, 4)
    ink = cv2.resize(big, (W_PX, H_PX), interpolation=cv2.INTER_AREA).astype(float) / 255
    light = np.linspace(1.0, 0.55, W_PX)[None, :] * np.linspace(0.9, 1.0, H_PX)[:, None]
    grey = 240 * light * (0.15 + 0.85 * ink)
    rgb = np.dstack([grey * 1.0, grey * 0.97, grey * 0.9]) + rng.normal(0, 4, (H_PX, W_PX, 3))
    return np.clip(rgb, 0, 255).astype(np.uint8)


LOGO = """<svg xmlns="http://www.w3.org/2000/svg" width="60mm" height="40mm" viewBox="0 0 120 80">
  <!-- a logo as logo tools write it: shapes, a path with curves and arcs, a group transform -->
  <circle cx="30" cy="40" r="24" fill="none" stroke="#000" stroke-width="2"/>
  <path d="M18,46 C22,30 38,30 42,46 A12,6 0 0 1 18,46 Z" fill="#c00"/>
  <g transform="translate(62,16) rotate(8)">
    <rect x="0" y="0" width="50" height="44" rx="6" fill="none" stroke="#000"/>
    <polyline points="8,34 18,12 28,28 36,16 44,34" fill="none" stroke="#000"/>
  </g>
</svg>
"""


def main() -> int:
    photo = ROOT / "samples" / "sketch.jpg"
    rgb = sketch_photo()
    cv2.imwrite(str(photo), rgb[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 85])
    (ROOT / "samples" / "logo.svg").write_text(LOGO)
    docs = ROOT / "docs"
    commands = [
        ["trace", str(photo), "-o", str(docs / "sketch-drawing.png")],
        ["preview", str(docs / "sketch-drawing.png"), "--depth", "3", "-o", str(docs / "sketch-preview.png")],
        ["preview", str(ROOT / "samples" / "logo.svg"), "--fit", "60x40", "-o", str(docs / "logo-preview.png")],
    ]
    for args in commands:
        print("cam " + " ".join(a.replace(str(ROOT) + "/", "") for a in args))
        if cam_main(args) != 0:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
