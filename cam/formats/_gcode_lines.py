"""G-code in, the lines of one file: read on demand, a file a line at a time, and where its O words are.

A program's text is its lines as ``str.splitlines`` of the file read as UTF-8 in universal-newline mode gives
them (:func:`cam.fileio.read_text`).  :class:`_Source` gives line ``i`` (0-based) of a text held in memory or
of a file, which it reads forward a line at a time: a file's lines are never all held.  One pass over the
file first (:meth:`_Source.scan`) counts its lines and finds its O words (a subroutine may be called before
it is defined, a branch jumps forward to its ``endif``) and notes where some lines start (every
:data:`MARK_EVERY` th, each O word's and the line after it, the places a jump lands), so going back to a
loop's head seeks there instead of reading from the start.  Each line read is cached with its parsed form
(:data:`CACHE_LINES` at most, so a loop's lines are read once, and the cache never grows with the file).
"""
from __future__ import annotations

import bisect
import re
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple, Optional, Sequence, Union

from ..errors import ParseError

MARK_EVERY = 4096
"""A file line whose start is noted every this many lines (a seek lands at most this many lines early)."""
CACHE_LINES = 1 << 14
"""Lines kept with their parsed form (the cache is emptied when it is full)."""

_O = re.compile(r"^\s*/?\s*[oO]\s*(<[^>]*>|\d+)\s*([a-zA-Z]+)")


class PlainLine(NamedTuple):
    """A cached line the plain-line path read (:func:`cam.formats._gcode_flow._plain_at`): its text and its
    match of the plain-line pattern."""

    text: str
    match: "re.Match[str]"


class ReadLine(NamedTuple):
    """A cached line the general interpreter read (:meth:`cam.formats._gcode_flow._Flow._read`): its text, its
    body (no comments or spaces, lower case) and what it says (a parsed :class:`cam.formats.ngc.Line`, or None)."""

    raw: str
    body: str
    line: Any


CachedLine = Union[PlainLine, ReadLine]
"""What :attr:`_Source.cache` holds for a line."""


def _decoded(raw: bytes, path: Path) -> list[str]:
    """The lines of one ``\\n``-ended piece of a file, as ``str.splitlines`` of the universal-newline text gives
    them (``\\r\\n`` and ``\\r`` end lines too)."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ParseError(f"{path}:1: not a G-code text file") from None
    return text.splitlines() or [""]


_BLOCK_BYTES = 1 << 16
"""About how much of a file is read at a time."""
_OTHER_ENDS = (b"\r", b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e")
"""The ASCII characters other than ``\\n`` that end a line for ``str.splitlines``."""


def _block_lines(raws: list[bytes], path: Path) -> list[str]:
    """The lines of consecutive ``\\n``-ended pieces of a file, as :func:`_decoded` gives them one by one: a
    piece of ASCII without another line end is one line, its text without the ``\\n``."""
    block = b"".join(raws)
    if not block.isascii() or any(end in block for end in _OTHER_ENDS):
        return [text for raw in raws for text in _decoded(raw, path)]
    lines = block.decode("ascii").split("\n")
    if block.endswith(b"\n"):
        lines.pop()
    return lines


def _no_bom(text: str) -> str:
    """The text without a UTF-8 byte-order mark at its start (Windows editors and some posts write one)."""
    return text[1:] if text.startswith("\ufeff") else text


class _Source:
    """One program file's lines, read on demand (``line(i)``), and where its O words are.

    ``text``: the program in memory; else ``path``: the file, read a line at a time (the source is
    :meth:`close` d when a pass ends).  ``cache``: line index -> what the interpreter made of it (bounded)."""

    def __init__(self, name: str, text: Optional[str] = None, *, path: Optional[Path] = None) -> None:
        self.name = name
        self.path = path
        self._lines: Optional[Sequence[str]] = _no_bom(text).splitlines() if text is not None else None
        self.o_at: dict[str, list[tuple[int, str]]] = {}  # label -> [(index, keyword)] in order
        self.subs: dict[str, int] = {}
        self.cache: dict[int, CachedLine] = {}
        self._marks: list[tuple[int, int]] = []  # (line index, byte offset of the file line it starts)
        self._handle: Optional[BinaryIO] = None
        self._next = 0  # the index of the line the file gives next
        self._pending: list[str] = []  # the lines read from the file and not yet given, the next one last
        self.n_lines = self.scan()

    def _open(self) -> BinaryIO:
        try:
            return open(self.path, "rb")  # type: ignore[arg-type]
        except FileNotFoundError:
            raise ParseError(f"{self.path}: file not found") from None
        except OSError as exc:
            raise ParseError(f"{self.path}: cannot read ({exc.strerror or exc})") from None

    def _note_o(self, i: int, raw: str) -> bool:
        """Note line ``i`` if it is an O word; True if it is."""
        if "o" not in raw and "O" not in raw:
            return False
        m = _O.match(raw.split("(", 1)[0].split(";", 1)[0])
        if not m:
            return False
        label = re.sub(r"\s", "", m.group(1).lower())
        if not label.startswith("<"):
            label = str(int(label))
        kw = m.group(2).lower()
        self.o_at.setdefault(label, []).append((i, kw))
        if kw == "sub" and label not in self.subs:
            self.subs[label] = i
        return True

    def scan(self) -> int:
        """One pass over the lines: their number, the O words, the marks (a file's); nothing per line kept."""
        if self._lines is not None:
            for i, raw in enumerate(self._lines):
                self._note_o(i, raw)
            return len(self._lines)
        n = 0
        last_mark = -MARK_EVERY
        mark_next = False
        with self._open() as f:
            offset = 0
            for raw in f:
                lines = _decoded(raw, self.path)  # type: ignore[arg-type]
                if n == 0:
                    lines[0] = _no_bom(lines[0])
                if mark_next or n - last_mark >= MARK_EVERY:
                    self._marks.append((n, offset))
                    last_mark, mark_next = n, False
                for k, text in enumerate(lines):
                    if self._note_o(n + k, text):
                        if k == 0 and last_mark != n:
                            self._marks.append((n, offset))
                            last_mark = n
                        mark_next = True
                n += len(lines)
                offset += len(raw)
        return n

    def line(self, i: int) -> str:
        """Line ``i`` (0-based) of the program, without its line end."""
        if self._lines is not None:
            return self._lines[i]
        if i != self._next or self._handle is None:
            self._seek(i)
        if not self._pending:  # the next lines, last first
            raws = self._handle.readlines(_BLOCK_BYTES)  # type: ignore[union-attr]
            self._pending = _block_lines(raws, self.path)[::-1] if raws else [""]  # type: ignore[arg-type]
        self._next += 1
        text = self._pending.pop()
        return _no_bom(text) if i == 0 else text

    def _seek(self, i: int) -> None:
        """Go to line ``i`` of the file: seek to the last mark at or before it and read on."""
        if self._handle is None:
            self._handle = self._open()
        k = bisect.bisect_right(self._marks, (i, 1 << 62)) - 1
        line0, offset = self._marks[k] if k >= 0 else (0, 0)
        self._handle.seek(offset)
        self._next, self._pending = line0, []
        while self._next < i:
            self.line(self._next)

    def close(self) -> None:
        """Close the file (a pass has ended); reading again opens it again."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
        self.cache.clear()

    def next_o(self, label: str, after: int, kws: Sequence[str]) -> int | None:
        """The first line after ``after`` with O word ``label`` and a keyword in ``kws``."""
        entries = self.o_at.get(label, [])
        k = bisect.bisect_right(entries, (after, "\uffff"))
        for i, kw in entries[k:]:
            if kw in kws:
                return i
        return None

    def prev_o(self, label: str, before: int) -> tuple[int, str] | None:
        """The last O word ``label`` before line ``before``."""
        entries = self.o_at.get(label, [])
        k = bisect.bisect_left(entries, (before, ""))
        return entries[k - 1] if k else None
