"""Stage 1: a drawing, its pixels classified as white, black, red or blue.

Frames: a drawing is an image array indexed ``[row, col]``; points are given
as ``(x, y)`` = ``(col, row)`` pixels, the origin at the top-left pixel, x to
the right and y downward (thesis 4.1.4.2 scans rows top to bottom, columns
left to right).

Colour classes and thresholds
-----------------------------
Drawings come from paint programs, scanners and JPEG files, so colours are
classified with tolerance.  For each pixel, with ``chroma = max(R,G,B) -
min(R,G,B)``:

* ``chroma < 80`` (a neutral grey): **black** when ``(R+G+B)/3 < 128``,
  otherwise **white**.  Anti-aliased edges therefore snap to the nearer of
  black and white.
* ``chroma >= 80`` (a real colour): the hue decides.  **Red** when the hue is
  within 30 degrees of 0, **blue** within 30 degrees of 240.  Any other hue
  (green, yellow, cyan, magenta, ...) fits no class: that is an error naming
  how many such pixels there are and where one is.

Then the neighbourhood (JPEG and anti-aliasing): a red pixel whose luminance
``Y = 0.299 R + 0.587 G + 0.114 B`` is below :data:`CONTOUR_Y_MAX` and that is
4-adjacent to a white pixel, or below :data:`CORE_Y_MAX` and darker by at least
:data:`VALLEY_MIN` than both its neighbours along some direction (a thin dark
line), is **black**: the 1-pixel contour of a 3D drawing (a red pixel with no red
neighbour, a profile's origin, stays red).  JPEG's 4:2:0 chroma
subsampling gives the contour the red of the interior around it (dark red,
which pixel by pixel reads as red), but keeps its luminance; and no red pixel
of a closed contour's interior touches white.  A thin-line pixel beside a black
pixel that already has two black neighbours stays red (it would thicken the
contour on the inner side of a diagonal).

Low JPEG qualities (60-65, issue #44 point 2), before the rules above: a near-grey
pixel with a red hue and the luminance of red (``chroma >= 40``, luminance at least
:data:`~cam.digitize._classify.DIM_RED_Y_MIN`: the interior's red dimmed by JPEG) is
red, unless it is 4-adjacent to white (then it is an anti-aliased contour pixel:
black); a red or unnamed-colour pixel paler than halfway to white (every channel at
least :data:`~cam.digitize._classify.PALE_MIN`) that is 4-adjacent to white is white
(JPEG's pale cyan or pink ringing beside a black line on white).

Rule checks (thesis 4.1.1) give warnings with coordinates, never errors: a
black pixel with more than two black 8-neighbours, a black pixel on the
image border, an isolated black pixel.
"""
from __future__ import annotations

import io
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import PIL.Image  # GIF drawings (see _decode_gif)

from ..errors import DrawingError
from ..limits import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE_PX
from ..render.picture import auto_scale, encode_png
from ._classify import black_rules_kernel, classify_kernel, hue_division_table
from .image_size import HEADER_FORMATS, image_size_px

__all__ = [
    "WHITE",
    "BLACK",
    "RED",
    "BLUE",
    "Drawing",
    "load_image",
    "drawing_size_px",
    "check_image_size",
    "classify",
    "neighbour_count",
    "CHROMA_MIN",
    "DARK_MAX",
    "HUE_TOLERANCE_DEG",
    "CONTOUR_Y_MAX",
    "CORE_Y_MAX",
    "VALLEY_MIN",
]

WHITE, BLACK, RED, BLUE = 0, 1, 2, 3
CLASS_NAMES = {WHITE: "white", BLACK: "black", RED: "red", BLUE: "blue"}
_UNKNOWN = 255

CHROMA_MIN = 80
"""Pixels with max(R,G,B) - min(R,G,B) below this are neutral (black or white)."""
DARK_MAX = 128
"""Neutral pixels with mean(R,G,B) below this are black."""
HUE_TOLERANCE_DEG = 30
"""Coloured pixels within this many degrees of red (0) or blue (240) count as red or blue."""

CONTOUR_Y_MAX = 64
"""A red-looking pixel 4-adjacent to white and darker than this (luminance) is the contour: pure red (76) is
not, so a contour left open in pure red is still an error, never healed (JPEG at quality 60 leaves a contour pixel
at (115, 39, 15), luminance 59)."""
CORE_Y_MAX = 40
"""A red-looking pixel darker than this that is a thin dark line (see :data:`VALLEY_MIN`) is black."""
VALLEY_MIN = 12
"""How much darker than both its neighbours along a direction a thin dark line's pixel is (luminance)."""

_MAX_LISTED = 5


@dataclass
class Drawing:
    """A classified drawing.

    Attributes:
        classes: ``(H, W)`` uint8, one of :data:`WHITE`, :data:`BLACK`,
            :data:`RED`, :data:`BLUE` per pixel, indexed ``[row, col]``.
        warnings: rule violations (thesis 4.1.1), one string each, with (x, y) coordinates.
        source: where the drawing came from (a path, or ``"<array>"``).
    """

    classes: np.ndarray
    warnings: list[str] = field(default_factory=list)
    source: str = "<array>"

    @property
    def height_px(self) -> int:
        return int(self.classes.shape[0])

    @property
    def width_px(self) -> int:
        return int(self.classes.shape[1])

    @property
    def black(self) -> np.ndarray:
        """``(H, W)`` bool mask of black pixels."""
        return self.classes == BLACK

    @property
    def kind(self) -> str:
        """``"2d"`` (black only), ``"3d"`` (black contour, red interior) or ``"profile"`` (blue curve)."""
        top = int(self.classes.max()) if self.classes.size else WHITE
        if top <= BLACK:
            return "2d"
        if top == BLUE:
            return "profile"
        return "3d"

    def to_rgb(self) -> np.ndarray:
        """``(H, W, 3)`` uint8 RGB picture of the classes (pure white, black, red, blue)."""
        palette = np.array([[255, 255, 255], [0, 0, 0], [255, 0, 0], [0, 0, 255]], np.uint8)
        return palette[self.classes]

    def _repr_png_(self) -> bytes:
        """Notebook picture: the classified drawing, scaled up so single pixels show."""
        k = auto_scale(self.width_px, self.height_px, 600)
        return encode_png(np.repeat(np.repeat(self.to_rgb(), k, axis=0), k, axis=1))


def _hue_classes() -> np.ndarray:
    """Class of each 8-bit OpenCV hue (``COLOR_RGB2HSV_FULL``: 256 steps to the circle) of a coloured pixel."""
    hue_deg = np.arange(256, dtype=np.float32) * np.float32(360.0 / 256.0)
    dist_red = np.minimum(hue_deg, np.float32(360.0) - hue_deg)
    dist_blue = np.abs(hue_deg - np.float32(240.0))
    table = np.full(256, _UNKNOWN, np.uint8)
    table[dist_red <= HUE_TOLERANCE_DEG] = RED
    table[dist_blue <= HUE_TOLERANCE_DEG] = BLUE
    return table


_HUE_CLASSES = _hue_classes()
_HUE_DIVISION = hue_division_table()


def _classify_pixels(img: np.ndarray, *, bgr: bool = False) -> tuple[np.ndarray, int, int, int]:
    """``(classes, n_unknown, first_unknown_flat, n_black)`` of an ``(H, W, 3)`` uint8 image; unknown
    pixels are 255.  One compiled pass (:mod:`._classify`); ``bgr``: the channels are OpenCV's order."""
    img = np.asarray(img)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise DrawingError(f"colour classification needs an (H, W, 3) uint8 image, got {img.dtype} {img.shape}")
    img = np.ascontiguousarray(img)  # one compiled layout
    out = np.empty(img.shape[:2], np.uint8)
    n_unknown, first, n_black = classify_kernel(img.reshape(-1), 2 if bgr else 0, 0 if bgr else 2,
                                                CHROMA_MIN, 3 * DARK_MAX, _HUE_CLASSES, _HUE_DIVISION,
                                                CONTOUR_Y_MAX, CORE_Y_MAX, VALLEY_MIN, out.reshape(-1),
                                                max(img.shape[1], 1))
    return out, int(n_unknown), int(first), int(n_black)


def _unknown_error(img: np.ndarray, n_bad: int, first: int, source: str, bgr: bool) -> DrawingError:
    row, col = divmod(first, img.shape[1])
    r, g, b = (int(v) for v in img[row, col, :3])
    if bgr:
        r, b = b, r
    return DrawingError(
        f"{source}: {n_bad} pixel(s) are not white, black, red or blue, "
        f"e.g. pixel (x={col}, y={row}) has RGB ({r}, {g}, {b})"
    )


def classify(rgb: np.ndarray, *, source: str = "<array>") -> np.ndarray:
    """Classify each pixel of an RGB image as WHITE, BLACK, RED or BLUE (the rules of the module docstring).

    One compiled pass over the image (and one more over the red pixels when there are any), at about the
    speed of reading it.

    Args:
        rgb: ``(H, W, 3)`` uint8 RGB image.
        source: name used in error messages.

    Returns:
        ``(H, W)`` uint8 class array.

    Raises:
        DrawingError: if a pixel fits no class; gives the count and one (x, y).
    """
    rgb = np.asarray(rgb)
    out, n_bad, first, _ = _classify_pixels(rgb)
    if n_bad:
        raise _unknown_error(rgb, n_bad, first, source, bgr=False)
    return out


def neighbour_count(mask: np.ndarray) -> np.ndarray:
    """Number of set 8-neighbours of every pixel of a ``(H, W)`` bool mask (outside counts as unset)."""
    m = mask.astype(np.uint8)
    kernel = np.ones((3, 3), np.float32)
    kernel[1, 1] = 0
    return cv2.filter2D(m, cv2.CV_16S, kernel, borderType=cv2.BORDER_CONSTANT).astype(np.int16)


def check_rules(classes: np.ndarray) -> list[str]:
    """Thesis 4.1.1 rule violations of black pixels as warning strings with (x, y) coordinates (one pass)."""
    classes = np.ascontiguousarray(classes, dtype=np.uint8)
    counts, first_rc = black_rules_kernel(classes.reshape(-1), max(classes.shape[-1], 1), _MAX_LISTED)
    warnings: list[str] = []
    texts = ("black pixel(s) have more than two black neighbours (lines must be 1 pixel wide): ",
             "black pixel(s) lie on the image border: ", "stray isolated black pixel(s): ")
    for k, text in enumerate(texts):
        n = int(counts[k])
        if n:
            listed = first_rc[k, :min(n, _MAX_LISTED)]
            more = n - _MAX_LISTED
            pts = ", ".join(f"({int(c)}, {int(r)})" for r, c in listed)
            warnings.append(f"{n} {text}" + pts + (f" and {more} more" if more > 0 else ""))
    return warnings


_HEADER_BYTES = 1 << 20
"""Bytes read for an image's size; a JPEG whose metadata runs longer is read whole."""


def _check_file(path: Path) -> None:
    if not path.exists():
        raise DrawingError(f"{path}: file not found")
    if path.is_dir():
        raise DrawingError(f"{path}: is a folder, not an image")


def _size_of(header: bytes, source: str) -> tuple[int, int]:
    size = image_size_px(header)
    if size is None:
        raise DrawingError(f"{source}: not a readable image (its size cannot be read from its header: "
                           f"{', '.join(HEADER_FORMATS)} images only)")
    return size


def check_image_size(width_px: int, height_px: int, source: str) -> None:
    """Refuse an image larger than :data:`~cam.limits.MAX_IMAGE_SIDE_PX` on a side or
    :data:`~cam.limits.MAX_IMAGE_PIXELS` in all (the memory of digitizing it), or empty.

    Raises:
        DrawingError: naming the image, its size and the limit.
    """
    if width_px < 1 or height_px < 1:
        raise DrawingError(f"{source}: image is empty ({width_px}x{height_px} px)")
    if max(width_px, height_px) > MAX_IMAGE_SIDE_PX or width_px * height_px > MAX_IMAGE_PIXELS:
        raise DrawingError(f"{source}: the image is {width_px}x{height_px} px; a drawing may have at most "
                           f"{MAX_IMAGE_SIDE_PX} px on a side and {MAX_IMAGE_PIXELS} px in all")


def drawing_size_px(path: str | os.PathLike) -> tuple[int, int]:
    """``(width, height)`` of an image file from its header, without decoding it (see :mod:`.image_size`).

    Raises:
        DrawingError: a missing file, or one whose header is not a PNG, JPEG, BMP, TIFF or GIF image's.
    """
    p = Path(path)
    _check_file(p)
    with open(p, "rb") as f:
        header = f.read(_HEADER_BYTES)
        if image_size_px(header) is None and len(header) == _HEADER_BYTES:
            header += f.read()
    return _size_of(header, str(p))


def _read_rgb(path: Path) -> np.ndarray:
    img, bgr = read_image(path)
    return _to_rgb(img, bgr=bgr, source=str(path))


def read_image(path: Path) -> tuple[np.ndarray, bool]:
    """The image file at ``path`` decoded as OpenCV gives it (``(H, W)`` or ``(H, W, C)``, its size checked
    before decoding), and whether its channels are BGR (a GIF's are RGB).  The drawings' reader and the height
    map's (:mod:`cam.job.heightmap`) both read images with it: the same formats and the same size checks."""
    _check_file(path)
    data = np.fromfile(str(path), dtype=np.uint8)
    header = data[:_HEADER_BYTES].tobytes()
    if image_size_px(header) is None and data.size > _HEADER_BYTES:
        header = data.tobytes()
    check_image_size(*_size_of(header, str(path)), str(path))  # before decoding: a small file may hold a huge image
    bgr = header[:6] not in _GIF_SIGNATURES
    if not bgr:
        img = _decode_gif(data)
    else:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise DrawingError(f"{path}: not a readable image (PNG, BMP, JPEG, TIFF or GIF)")
    check_image_size(img.shape[1], img.shape[0], str(path))
    return img, bgr


_GIF_SIGNATURES = (b"GIF87a", b"GIF89a")


def _decode_gif(data: np.ndarray) -> "np.ndarray | None":
    """The first frame of a GIF file's bytes, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA when it has a transparent
    colour (composited over white paper as a PNG's alpha is); None when it cannot be decoded.

    Pillow decodes it: OpenCV reads GIF only from 4.11 on, and only when it was built with its GIF codec.
    The palette is exact, so a GIF gives the very pixels of the PNG it was saved from.
    """
    try:
        with PIL.Image.open(io.BytesIO(data.tobytes())) as im:
            im.seek(0)
            transparent = "transparency" in im.info or im.mode in ("RGBA", "LA", "PA")
            return np.asarray(im.convert("RGBA" if transparent else "RGB"))
    except (OSError, ValueError, EOFError, PIL.UnidentifiedImageError, PIL.Image.DecompressionBombError):
        return None


def _to_rgb(img: np.ndarray, *, bgr: bool, source: str) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    elif img.dtype == bool:
        img = np.where(img, 0, 255).astype(np.uint8)  # True = ink
    elif img.dtype != np.uint8:
        raise DrawingError(f"{source}: image must be uint8, got dtype {img.dtype}")
    if img.ndim == 2:
        return np.repeat(img[:, :, None], 3, axis=2)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        rgb = img[:, :, :3]
        if bgr:
            rgb = rgb[:, :, ::-1]
        if img.shape[2] == 4:  # composite over white paper
            alpha = img[:, :, 3:4].astype(np.float32) / 255.0
            rgb = np.round(rgb.astype(np.float32) * alpha + 255.0 * (1.0 - alpha)).astype(np.uint8)
        return np.ascontiguousarray(rgb)
    raise DrawingError(f"{source}: image must be (H, W), (H, W, 3) or (H, W, 4), got shape {img.shape}")


def load_image(path_or_array: str | os.PathLike | np.ndarray) -> Drawing:
    """Load and classify a drawing.

    Args:
        path_or_array: an image file (PNG, BMP, JPEG, TIFF or GIF; its size is read
            from its header before it is decoded and may be at most
            :data:`~cam.limits.MAX_IMAGE_SIDE_PX` on a side and
            :data:`~cam.limits.MAX_IMAGE_PIXELS` in all) or an array: ``(H, W)`` grey,
            ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA uint8; a bool array means True = black ink.

    Returns:
        A :class:`Drawing` with rule warnings.

    Raises:
        DrawingError: unreadable file, an image too large (naming its size and the limit, before it is
            decoded), out-of-palette pixels, or a drawing with nothing drawn.

    >>> import numpy as np
    >>> img = np.full((5, 6), 255, np.uint8); img[2, 1:5] = 0
    >>> d = load_image(img)
    >>> d.width_px, d.height_px, int(d.black.sum()), d.warnings
    (6, 5, 4, [])
    """
    if isinstance(path_or_array, np.ndarray):
        source, img, bgr = "<array>", path_or_array, False
    else:
        source = str(path_or_array)
        img, bgr = read_image(Path(path_or_array))
    if not (img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3):  # grey, alpha, 16-bit: to RGB first
        img, bgr = _to_rgb(img, bgr=bgr, source=source), False
    if img.shape[0] < 1 or img.shape[1] < 1:
        raise DrawingError(f"{source}: image is empty (shape {img.shape})")
    classes, n_bad, first, n_black = _classify_pixels(img, bgr=bgr)
    if n_bad:
        error = _unknown_error(img, n_bad, first, source, bgr)
        if n_bad >= PHOTO_PIXELS * classes.size and _grey_levels(img) >= PHOTO_GREY_LEVELS:
            raise DrawingError(f"{error}; {PHOTO_HINT}")
        raise error
    if n_black == 0:
        if not np.any(classes != WHITE):
            raise DrawingError(f"{source}: the drawing is empty (no black pixels)")
        raise DrawingError(f"{source}: the drawing has no black pixels (curves and contours must be black)")
    warnings = check_rules(classes)
    if _looks_like_photo(img, classes, n_black):
        warnings.append(f"{source}: {PHOTO_HINT}")
    return Drawing(classes=classes, warnings=warnings, source=source)


PHOTO_HINT = ("this looks like a photograph or a height map, not a line drawing: --trace traces a sketch or photo "
              "into lines first, --heightmap cuts its grey levels as depths (black deepest)")
"""The hint of a drawing that is plainly a photograph or a height map (issue #31 point 7)."""
PHOTO_GREY_LEVELS = 32
"""Grey levels (each on at least 0.05 % of the pixels) from which an image may be a photograph or a height map."""
PHOTO_PIXELS = 0.01
"""The share of pixels that fit no class, or of black pixels in thick areas, that with many grey levels makes one."""


def _grey_levels(img: np.ndarray) -> int:
    """How many 8-bit grey levels (the channels' mean) each cover at least 0.05 % of the image's pixels."""
    grey = np.asarray(img[:, :, :3], np.uint16).sum(axis=2) // 3
    counts = np.bincount(grey.ravel(), minlength=256)
    return int(np.count_nonzero(counts >= max(1, 0.0005 * grey.size)))


def _looks_like_photo(img: np.ndarray, classes: np.ndarray, n_black: int) -> bool:
    """Many grey levels and black mostly in thick areas (not 1-pixel lines): a photograph or a height map."""
    if n_black < PHOTO_PIXELS * classes.size:
        return False
    black = classes == BLACK
    thick = int(np.count_nonzero(black & (neighbour_count(black) > 2)))
    return thick >= 0.5 * n_black and _grey_levels(img) >= PHOTO_GREY_LEVELS
