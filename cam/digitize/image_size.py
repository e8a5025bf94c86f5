"""The size of an image, read from its file header without decoding a pixel.

A compressed image says how large it is in its first bytes; decoding a
279 KB PNG of 16000 x 16000 pixels takes 768 MB before anything can look at
it.  :func:`image_size_px` reads the width and height from the header of a
PNG (``IHDR``), JPEG (the first start-of-frame marker), BMP (the DIB header),
GIF (the logical screen) or TIFF file (the first image's ``ImageWidth`` and ``ImageLength`` tags), so a
drawing too large for the machine is refused before it is decoded
(:func:`cam.digitize.drawing.load_image`, :func:`cam.kinds.jobs.prepare_job`).

Pure computation on bytes, standard library only.

>>> import struct
>>> png = b"\\x89PNG\\r\\n\\x1a\\n" + struct.pack(">I4sII", 13, b"IHDR", 16000, 9000) + bytes(5)
>>> image_size_px(png)
(16000, 9000)
>>> image_size_px(b"GIF89a" + struct.pack("<HH", 640, 480))
(640, 480)
>>> image_size_px(b"GIF89a...") is None
True
"""
from __future__ import annotations

import struct
from typing import Optional

__all__ = ["image_size_px", "HEADER_FORMATS"]

HEADER_FORMATS = ("PNG", "JPEG", "BMP", "TIFF", "GIF")
"""The image formats whose size :func:`image_size_px` reads (the drawing suffixes of :mod:`cam.choices`)."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
"""Start-of-frame markers (baseline, extended, progressive, lossless; Huffman or arithmetic coded)."""
_JPEG_NO_LENGTH = {0x01, *range(0xD0, 0xD9)}
"""Markers without a length field (TEM, RST0..7, SOI)."""


def image_size_px(header: bytes) -> Optional[tuple[int, int]]:
    """``(width, height)`` in pixels from the first bytes of an image file, or None.

    Args:
        header: the file's first bytes (a PNG, BMP or TIFF needs at most a few hundred; a JPEG as far
            as its first start-of-frame marker, after any metadata).

    Returns:
        The size the header states, or None when the bytes are not one of :data:`HEADER_FORMATS` or end
        before the size.
    """
    data = bytes(header)
    for reader in (_png, _jpeg, _bmp, _tiff, _gif):
        size = reader(data)
        if size is not None:
            return size
    return None


def _png(data: bytes) -> Optional[tuple[int, int]]:
    if not data.startswith(_PNG_SIGNATURE) or len(data) < 24 or data[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def _jpeg(data: bytes) -> Optional[tuple[int, int]]:
    if not data.startswith(b"\xff\xd8"):
        return None
    i = 2
    while i + 1 < len(data):
        if data[i] != 0xFF:
            return None  # not at a marker: a damaged file
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in _JPEG_NO_LENGTH:
            i += 2
            continue
        if i + 4 > len(data):
            return None
        (length,) = struct.unpack(">H", data[i + 2:i + 4])
        if marker in _JPEG_SOF:
            if i + 9 > len(data):
                return None
            height, width = struct.unpack(">HH", data[i + 5:i + 9])
            return width, height
        if marker in (0xD9, 0xDA) or length < 2:  # end of image, or the scan before any frame
            return None
        i += 2 + length
    return None


def _bmp(data: bytes) -> Optional[tuple[int, int]]:
    if not data.startswith(b"BM") or len(data) < 26:
        return None
    (dib_size,) = struct.unpack("<I", data[14:18])
    if dib_size == 12:  # BITMAPCOREHEADER: 16-bit sizes
        width, height = struct.unpack("<HH", data[18:22])
        return width, height
    width, height = struct.unpack("<ii", data[18:26])
    return abs(width), abs(height)  # a negative height is a top-down bitmap


def _tiff(data: bytes) -> Optional[tuple[int, int]]:
    if data[:4] == b"II*\x00":
        order = "<"
    elif data[:4] == b"MM\x00*":
        order = ">"
    else:
        return None
    if len(data) < 8:
        return None
    (ifd,) = struct.unpack(order + "I", data[4:8])
    if ifd + 2 > len(data):
        return None
    (n_entries,) = struct.unpack(order + "H", data[ifd:ifd + 2])
    size: dict[int, int] = {}
    for k in range(n_entries):
        at = ifd + 2 + 12 * k
        if at + 12 > len(data):
            return None
        tag, kind, count = struct.unpack(order + "HHI", data[at:at + 8])
        if tag in (256, 257) and count == 1 and kind in (3, 4):  # ImageWidth, ImageLength: SHORT or LONG
            size[tag] = struct.unpack(order + ("H" if kind == 3 else "I"), data[at + 8:at + (10 if kind == 3 else 12)])[0]
    if 256 in size and 257 in size:
        return size[256], size[257]
    return None


def _gif(data: bytes) -> Optional[tuple[int, int]]:
    """The logical screen's size (every frame lies within it); None for an empty screen (no real GIF's)."""
    if data[:6] not in (b"GIF87a", b"GIF89a") or len(data) < 10:
        return None
    width, height = struct.unpack("<HH", data[6:10])
    return (width, height) if width and height else None
