"""File helpers: atomic writes (a failed run never leaves a half-written output behind) and text reads
whose failures are one-line parse errors."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .errors import CamError, ParseError

__all__ = ["atomic_write_bytes", "atomic_write_text", "read_text"]


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename.

    Either the old file stays as it was or the new one is complete.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise CamError(f"{target}: folder {folder} does not exist")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, target)
    except OSError as exc:
        try:
            os.unlink(tmp_name)
        except OSError:
            pass
        raise CamError(f"{target}: cannot write ({exc.strerror or exc})") from exc
    except BaseException:
        try:
            os.unlink(tmp_name)
        except OSError:
            pass
        raise
    return target


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; see :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def read_text(path: str | os.PathLike, *, not_text: str) -> tuple[Path, str]:
    """``(path, text)`` of a UTF-8 text file.

    Raises:
        ParseError: ``"{path}: file not found"``, ``"{path}: cannot read (...)"``, or
            ``"{path}:1: {not_text}"`` when the bytes are not UTF-8.
    """
    p = Path(path)
    try:
        return p, p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ParseError(f"{p}: file not found") from None
    except UnicodeDecodeError:
        raise ParseError(f"{p}:1: {not_text}") from None
    except OSError as exc:
        raise ParseError(f"{p}: cannot read ({exc.strerror or exc})") from None
