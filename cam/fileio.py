"""File helpers: atomic writes (a failed run never leaves a half-written output behind), bounded reads
whose failures are one-line parse errors naming the file, and the user's state folder (:func:`state_dir`)."""
from __future__ import annotations

import glob
import os
import secrets
import time
from pathlib import Path
from typing import Iterable, Mapping, Optional

from .errors import CamError, ParseError

__all__ = ["atomic_write_bytes", "atomic_write_text", "read_bytes", "read_text", "state_dir"]

_NEW_FILE_MODE = 0o666
"""Mode asked for a new output; the process umask takes its bits away (0o644 under umask 022), as for open()."""


def _create_temporary(folder: Path, name: str) -> tuple[int, str]:
    """A new, empty file next to the target: (descriptor, path).

    Made like :func:`tempfile.mkstemp` (exclusive create, random name), but with the normal mode of a new
    file instead of mkstemp's owner-only 0o600, so the renamed output is readable as any other file.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    for _ in range(100):
        tmp_name = str(folder / f".{name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(tmp_name, flags, _NEW_FILE_MODE), tmp_name
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name for {name} in {folder}")


def _remove_stale_temporaries(folder: Path, name: str, max_age_s: float = 60.0) -> None:
    """Temporary files a killed run left for ``name`` (older than ``max_age_s``: not another run's, writing now)."""
    now = time.time()
    for leftover in folder.glob(f".{glob.escape(name)}.*.tmp"):
        try:
            if now - leftover.stat().st_mtime > max_age_s:
                leftover.unlink()
        except OSError:
            pass


def atomic_write_bytes(path: str | os.PathLike, data: bytes | Iterable[bytes]) -> Path:
    """Write ``data`` (bytes, or consecutive pieces of them: a file too large to hold) to ``path`` through a
    temporary file in the same folder and a rename.

    Either the old file stays as it was or the new one is complete.  The file gets the mode
    ``0o666 & ~umask``, as a file made by :func:`open` would.  A path that is a symbolic link writes the
    file it points to (the link stays a link).  Temporary files a killed earlier run left for the same
    output are removed.
    """
    given = Path(path)
    target = Path(os.path.realpath(given)) if given.is_symlink() else given
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise CamError(f"{given}: folder {folder} does not exist")
    _remove_stale_temporaries(folder, target.name)
    try:
        fd, tmp_name = _create_temporary(folder, target.name)
    except OSError as exc:
        raise CamError(f"{given}: cannot write ({exc.strerror or exc})") from exc
    try:
        with os.fdopen(fd, "wb") as handle:
            for piece in ([data] if isinstance(data, (bytes, bytearray, memoryview)) else data):
                handle.write(piece)
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
    return given


def atomic_write_text(path: str | os.PathLike, text: str | Iterable[str]) -> Path:
    """Write ``text`` (UTF-8; or consecutive pieces of it) to ``path`` atomically; see :func:`atomic_write_bytes`."""
    if isinstance(text, str):
        return atomic_write_bytes(path, text.encode("utf-8"))
    return atomic_write_bytes(path, (piece.encode("utf-8") for piece in text))


def read_bytes(path: str | os.PathLike, *, max_bytes: Optional[int] = None, what: str = "a file"
               ) -> tuple[Path, bytes]:
    """``(path, bytes)`` of a file, read whole, at most ``max_bytes`` long (None: any length).

    The size is taken from the open file and the read stops one byte past ``max_bytes``, so a file that grows
    while it is read is refused too, and never read past that bound.

    Raises:
        ParseError: one line naming the file: ``"{path}: file not found"``, ``"{path}: is a folder, not {what}"``,
            ``"{path}: {size} bytes, more than {what} may be ({max_bytes})"`` and ``"{path}: cannot read (...)"``.

    >>> read_bytes("/nonexistent/map.json")
    Traceback (most recent call last):
    ...
    cam.errors.ParseError: /nonexistent/map.json: file not found
    """
    p = Path(path)
    if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 0):
        raise ValueError(f"max_bytes must be a whole number >= 0 or None, got {max_bytes!r}")

    def too_big(size: int) -> ParseError:
        return ParseError(f"{p}: {size:,} bytes, more than {what} may be ({max_bytes:,})")

    try:
        with open(p, "rb") as handle:
            if max_bytes is None:
                return p, handle.read()
            size = os.fstat(handle.fileno()).st_size
            if size > max_bytes:
                raise too_big(size)
            data = handle.read(max_bytes + 1)
    except FileNotFoundError:
        raise ParseError(f"{p}: file not found") from None
    except IsADirectoryError:
        raise ParseError(f"{p}: is a folder, not {what}") from None
    except OSError as exc:
        if p.is_dir():  # Windows says "permission denied" of a folder
            raise ParseError(f"{p}: is a folder, not {what}") from None
        raise ParseError(f"{p}: cannot read ({exc.strerror or exc})") from None
    if len(data) > max_bytes:  # it grew while it was read
        raise too_big(len(data))
    return p, data


def read_text(path: str | os.PathLike, *, not_text: str, max_bytes: Optional[int] = None,
              what: str = "a file") -> tuple[Path, str]:
    """``(path, text)`` of a UTF-8 text file (read by :func:`read_bytes`, at most ``max_bytes`` long), its line
    ends made ``\\n`` (``\\r\\n`` and ``\\r`` too, as Python's text files read them).

    Raises:
        ParseError: the one-line messages of :func:`read_bytes`, or ``"{path}:1: {not_text}"`` when the bytes are
            not UTF-8.
    """
    p, raw = read_bytes(path, max_bytes=max_bytes, what=what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ParseError(f"{p}:1: {not_text}") from None
    return p, text.replace("\r\n", "\n").replace("\r", "\n")


def state_dir(environ: Optional[Mapping[str, str]] = None) -> Path:
    """The user's state folder for `cam`: ``$XDG_STATE_HOME/cam``, else ``~/.local/state/cam``.

    The machine state files (:mod:`cam.drive.state`), the default machine file (:mod:`cam.machine_file`) and the
    default tool table (:mod:`cam.tool_table`) live there; ``environ`` stands for :data:`os.environ` (tests)."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_STATE_HOME") or ""
    if not os.path.isabs(base):  # the XDG rule: a relative path is ignored
        base = os.path.join(os.path.expanduser("~"), ".local", "state")
    return Path(base) / "cam"
