"""G-code in, the program's flow: lines one after the other, O words (subroutines, branches, loops).

LinuxCNC's rules, as its ``rs274`` runs them: a subroutine call saves and clears the numbered parameters
#1..#30 and gives the subroutine its own named local parameters; ``o<name> call`` finds ``name.ngc`` in the
subroutine path; a loop's end goes back to its head, ``break`` and ``continue`` find the loop of their label
around them.
"""
from __future__ import annotations

import bisect
import re
from typing import Iterator

from ..fileio import read_text
from ..limits import MAX_COORD_MM, MAX_FEED_MM_MIN, MAX_GCODE_CALL_DEPTH, MAX_LINE_NUMBER, MAX_REPEAT, MIN_FEED_MM_MIN
from ._gcode_data import GcodeMove, _End, _Frame, _Source, _shown, _strip_comments
from ._gcode_lines import CACHE_LINES, PlainLine, ReadLine
from ._gcode_state import _State
from .ngc import NUMBER, Line, NgcSyntaxError, read_line

FAST_LINES = True
"""Run plain lines (:data:`_PLAIN`) by :meth:`_PlainLines.plain_lines`; False: every line by the general
interpreter (the tests compare the two)."""

_NUM = rf"([-+]?(?:{NUMBER}))"
_PLAIN = re.compile(r"[ \t]*(?:[nN](\d+)[ \t]*)?(?:[gG]0*([01])(?![\d.])[ \t]*)?"
                    + "".join(rf"(?:[{a}{a.upper()}]{_NUM}[ \t]*)?" for a in "xyzf"))
"""A plain line, as most of a CAM post's lines are: an optional N, G0 or G1, then X Y Z F in that order, each a
plain decimal number at most once, spaces or tabs between words; nothing else (no comment, parameter,
expression or other word)."""


class _PlainLines(_State):
    """Plain lines (:data:`_PLAIN`) run without the general interpreter: the same moves, and a line that the
    general interpreter would refuse (a feed move without F, a word or move out of range), or that the modal
    state makes anything but a straight move, is left to it."""

    def plain_lines(self, src: _Source, idx: int, limit: int) -> tuple[int, str | None]:
        """Run the plain lines from line ``idx`` of ``src`` on, at most ``limit``, and stop once :attr:`moves`
        holds :attr:`batch_moves` (as :func:`cam.formats.gcode._interpret` takes them after each line): how many
        lines ran, and the text of the line they stopped at when it was read (None: not read)."""
        if self.inverse_time or self.resync is not None or (self.spindle and not self.spindle_noted) or self.comp_side \
                or self.comp_exit is not None \
                or len(self.moves) >= self.batch_moves:
            return 0, None
        keep = bool(src.o_at)  # cache the lines: O words may run them again
        text, m = _plain_at(src, idx, keep)
        if m is None:  # most lines of a program that is not plain: no set-up for them
            return 0, text
        scale, absolute, lim = self.scale, self.absolute, MAX_COORD_MM
        o0, o1, o2 = self.offsets()  # nothing a plain line does changes them
        s0, s1, s2 = self.start
        m0, m1, m2 = self.mach
        motion, feed, spindle = self.motion, self.feed, self.spindle
        rpm = self.spindle_rpm if spindle else 0.0
        file = "" if src is self.main else src.name
        moves, n, stop = self.moves, 0, self.batch_moves
        end_idx = min(src.n_lines, idx + limit)
        raw, moved = "", False
        while True:
            ns, gs, xs, ys, zs, fs = m.groups()
            if ns is not None and not float(ns) <= MAX_LINE_NUMBER:
                break
            new_motion = motion if gs is None else int(gs)
            new_feed = feed
            if fs is not None:
                new_feed = float(fs) * scale
                if not MIN_FEED_MM_MIN <= new_feed <= MAX_FEED_MM_MIN:
                    break
            if xs is not None or ys is not None or zs is not None:
                if new_motion not in (0, 1) or (new_motion == 1 and new_feed <= 0):
                    break
                # as the general interpreter: the program position, the axis words, the machine position
                p0, p1, p2 = m0 - o0, m1 - o1, m2 - o2
                v0 = v1 = v2 = 0.0
                if xs is not None:
                    v0 = float(xs) * scale
                    p0 = v0 if absolute else p0 + v0
                if ys is not None:
                    v1 = float(ys) * scale
                    p1 = v1 if absolute else p1 + v1
                if zs is not None:
                    v2 = float(zs) * scale
                    p2 = v2 if absolute else p2 + v2
                q0, q1, q2 = p0 + o0, p1 + o1, p2 + o2
                if not (abs(v0) <= lim and abs(v1) <= lim and abs(v2) <= lim and abs(p0) <= lim and abs(p1) <= lim
                        and abs(p2) <= lim and abs(q0) <= lim and abs(q1) <= lim and abs(q2) <= lim):
                    break
                end = (q0 - s0, q1 - s1, q2 - s2)
                if new_motion:
                    moves.append(GcodeMove("feed", idx + n + 1, end, new_feed, file=file, spindle=spindle,
                                           spindle_rpm=rpm))
                else:
                    moves.append(GcodeMove("rapid", idx + n + 1, end, file=file, spindle=spindle, spindle_rpm=rpm))
                m0, m1, m2, moved = q0, q1, q2, True
            if gs is not None:
                self.cycle_il = None  # G0, G1: a new series of canned cycles starts where the tool stands
            raw, n, motion, feed, text = text, n + 1, new_motion, new_feed, None
            if idx + n >= end_idx or len(moves) >= stop:  # a batch ends where it would line by line
                break
            text, m = _plain_at(src, idx + n, keep)
            if m is None:
                break
        if moved:
            self.mach, self.g5_reflect = [m0, m1, m2], None
        if n:
            self.motion, self.feed = motion, feed
            self.source, self.line_no, self.raw = src, idx + n, raw
        return n, text


def _plain_at(src: _Source, i: int, keep: bool) -> tuple[str | None, re.Match | None]:
    """Line ``i`` of ``src`` and its match of :data:`_PLAIN` (None: not a plain line); ``(None, None)``: the line
    is cached as the general interpreter read it.  ``keep``: cache a plain line."""
    cached = src.cache.get(i)
    if cached is None:
        text = src.line(i)
        m = _PLAIN.fullmatch(text)
        if m is None or m.lastindex is None:
            return text, None
        if keep:
            if len(src.cache) >= CACHE_LINES:
                src.cache.clear()
            src.cache[i] = PlainLine(text, m)
        return text, m
    if isinstance(cached, PlainLine):
        return cached
    return None, None


class _Flow(_PlainLines):
    """Runs the lines: each block (:meth:`block`, from :class:`~._gcode_block._Block`) or O word in turn."""

    def run(self) -> Iterator[None]:
        """Run the program a line at a time: a generator that yields after each line that made moves (the caller
        takes :attr:`moves` then; :func:`cam.formats.gcode.interpret`), and ends with the program.  After a probe
        (G38.2, G38.3) nothing more is read until the caller asks again: then where the probe tripped is asked
        (:meth:`~._gcode_probe._Probe.after_probe`)."""
        src, idx = self.main, 0
        executed = 0
        budget = self.max_lines + src.n_lines  # one pass of the file's own lines, then max_lines more
        percent = False
        ran = False
        pending = None  # the text of line idx when the plain lines before it read it
        while True:
            if idx >= src.n_lines:
                if len(self.frames) > 1:
                    self.source, self.raw = src, ""
                    self.line_no = src.n_lines
                    raise self.err(f"the file ends inside subroutine 'o{self.frames[-1].label}'")
                return
            executed += 1
            if executed > budget:
                self.source, self.line_no, self.raw = src, idx + 1, src.line(idx)
                raise self.err(f"the program has run {self.max_lines:,} lines more than its own {self.main.n_lines:,} "
                               "and does not end (a loop without an exit?); raise the limit with --max-lines")
            if FAST_LINES and pending is None:
                done, pending = self.plain_lines(src, idx, budget - executed + 1)
                if done:
                    ran = True
                    executed += done - 1
                    idx += done
                    if self.moves:
                        yield
                    continue
            body, line = self._read(src, idx, pending)
            pending = None
            if line is None:
                if body.startswith("$"):
                    self.note_once("$", f"grbl system command '{_shown(self.raw.strip())}' skipped (and any later "
                                        "'$' lines): it is a command to grbl itself, not G-code")
                elif body == "?":
                    self.note_once("?", "grbl real-time status query '?' skipped (and any later '?' lines): it "
                                        "asks grbl where it is, it is not G-code")
                if body == "%":
                    if percent or ran:
                        self._after_percent(src, idx)
                        return  # the closing '%' ends the program
                    percent = True
                idx += 1
                continue
            ran = True
            if line.o is not None:
                src, idx = self.o_word(src, idx, line.o)
                continue
            try:
                self.block(line)
            except _End:
                return
            if self.moves:
                yield
            if self.probe_pending is not None:  # the caller ran the probe before it asked for more: where it tripped
                self.after_probe()
            idx += 1

    def _after_percent(self, src: _Source, idx: int) -> None:
        """The closing ``%`` at line ``idx`` ends the program, as in LinuxCNC; one warning when lines that would
        run follow it (a grbl sender skips ``%`` lines and would run them)."""
        for j in range(idx + 1, src.n_lines):
            text = src.line(j)
            if text.strip() and re.sub(r"\s+", "", text.split("(", 1)[0].split(";", 1)[0]) not in ("", "%"):
                self.warnings.append(f"{src.name}:{idx + 1}: the program ends at this '%', as in LinuxCNC: line "
                                     f"{j + 1} and those after it are not run (a grbl sender would skip the '%' "
                                     "and run them)")
                return

    def _read(self, src: _Source, idx: int, text: str | None = None) -> tuple[str, Line | None]:
        """Line ``idx`` of ``src`` made current (:attr:`source`, :attr:`line_no`, :attr:`raw`): its body (no
        comments, no spaces, lower case) and what it says (None: nothing to run, or ``%``); cached.  ``text``:
        the line's text when it was read already."""
        cached = src.cache.get(idx)
        if isinstance(cached, ReadLine):
            self.source, self.line_no, self.raw = src, idx + 1, cached.raw
            return cached.body, cached.line
        if cached is not None:
            text = cached.text  # a plain line (:meth:`plain_lines`) not run as one
        self.source, self.line_no, self.raw = src, idx + 1, src.line(idx) if text is None else text
        body = "".join(_strip_comments(self.raw, self.err).split()).lower()  # the spaces str.split takes are re's \s
        if body.startswith("/"):
            body = body[1:]  # block delete is off, as in rs274: the line runs
        line = None
        if body and body not in ("%", "?") and not body.startswith("$"):
            try:
                line = read_line(body)
            except NgcSyntaxError as exc:
                raise self.err(str(exc)) from None
        if len(src.cache) >= CACHE_LINES:
            src.cache.clear()
        src.cache[idx] = ReadLine(self.raw, body, line)
        return body, line

    # -- O words ----------------------------------------------------------------------------------------------

    def _o_args(self, src: _Source, i: int) -> list:
        """The arguments of the O word of line ``i`` (made the current line)."""
        return self._read(src, i)[1].o[2]  # type: ignore[union-attr]

    def _need(self, found: int | None, what: str) -> int:
        if found is None:
            raise self.err(f"no matching {what}")
        return found

    def _do_of(self, src: _Source, label: str, idx: int) -> int | None:
        """The ``do`` line whose loop the ``while`` at ``idx`` ends (its own break/continue skipped), or None."""
        prev = src.prev_o(label, idx)
        while prev is not None and prev[1] in ("break", "continue"):
            prev = src.prev_o(label, prev[0])
        return prev[0] if prev is not None and prev[1] == "do" else None

    def _loop_head(self, src: _Source, label: str, idx: int, opener: str) -> int:
        """The line of the ``o<label> opener`` (``while``/``repeat``) that the loop end at ``idx`` closes."""
        head = src.prev_o(label, idx)
        while head is not None and head[1] != opener:
            head = src.prev_o(label, head[0])
        return self._need(head and head[0], f"'o{label} {opener}'")

    def _is_do_tail(self, src: _Source, label: str, idx: int) -> bool:
        return self._do_of(src, label, idx) is not None

    def o_word(self, src: _Source, idx: int, o: tuple) -> tuple[_Source, int]:
        """Run the O word ``o`` (label, keyword, arguments) of line ``idx``: the source and line to go on at."""
        label, kw, args = o
        if kw == "sub":
            return src, self._need(src.next_o(label, idx, ("endsub",)), f"'o{label} endsub'") + 1
        if kw in ("endsub", "return"):
            return self._o_return(label, kw, args)
        if kw == "call":
            return self._o_call(src, idx, label, args)
        if kw == "if":
            return src, self._o_if(src, idx, label, args)
        if kw in ("elseif", "else"):
            return src, self._need(src.next_o(label, idx, ("endif",)), f"'o{label} endif'") + 1
        if kw in ("endif", "do"):
            return src, idx + 1
        if kw == "while":
            return src, self._o_while(src, idx, label, args)
        if kw == "endwhile":
            return src, self._loop_head(src, label, idx, "while")
        if kw == "repeat":
            return src, self._o_repeat(src, idx, label, args)
        if kw == "endrepeat":
            return src, self._loop_head(src, label, idx, "repeat")
        return src, self._o_break(src, idx, label, kw)

    def _o_true(self, args: list) -> bool:
        """The condition of an ``if``, ``elseif`` or ``while``: its first argument not 0 (none: false)."""
        return self.value_of(args[0]) != 0 if args else False

    def _o_return(self, label: str, kw: str, args: list) -> tuple[_Source, int]:
        """``endsub`` or ``return``: the caller's numbered parameters and M73 state back, on after its call."""
        frame = self.frames[-1]
        if len(self.frames) == 1:
            raise self.err(f"'o{label} {kw}' outside a subroutine")
        if args:
            self.value, self.value_returned = self.value_of(args[0]), 1.0
        else:
            self.value_returned = 0.0
        self.frames.pop()
        for n in range(1, 31):
            self.params.pop(n, None)
        self.params.update(frame.saved_numbered)
        if frame.modal is not None:
            self.restore_modal(frame.modal)
        return frame.source, frame.back

    def _o_call(self, src: _Source, idx: int, label: str, args: list) -> tuple[_Source, int]:
        """``call``: the arguments become #1..#30 (the caller's are saved), on at the subroutine's first line."""
        values = [self.value_of(a) for a in args]
        target, start = self.find_sub(src, label)
        if len(self.frames) > MAX_GCODE_CALL_DEPTH:
            raise self.err(f"subroutines call each other more than {MAX_GCODE_CALL_DEPTH} deep")
        saved = {n: self.params[n] for n in range(1, 31) if n in self.params}
        for n in range(1, 31):
            self.params.pop(n, None)
        for n, v in enumerate(values[:30], start=1):
            self.params[n] = v
        self.frames.append(_Frame(src, idx + 1, label, saved))
        self.value_returned = 0.0
        return target, start + 1

    def _o_kind(self, src: _Source, label: str, j: int) -> str:
        """The keyword of the O word ``label`` at line ``j``."""
        return src.o_at[label][bisect.bisect_left(src.o_at[label], (j, ""))][1]

    def _o_if(self, src: _Source, idx: int, label: str, args: list) -> int:
        """``if``: the line after the first branch whose condition holds (``elseif``) or after ``else``/``endif``."""
        if self._o_true(args):
            return idx + 1
        j = idx
        while True:
            j = self._need(src.next_o(label, j, ("elseif", "else", "endif")), f"'o{label} endif'")
            if self._o_kind(src, label, j) == "elseif":
                if self._o_true(self._o_args(src, j)):
                    return j + 1
                continue
            return j + 1

    def _o_while(self, src: _Source, idx: int, label: str, args: list) -> int:
        """``while``: a loop's head, or the tail of a ``do`` loop (back to the ``do`` while its condition holds)."""
        if self._is_do_tail(src, label, idx):
            return self._do_of(src, label, idx) + 1 if self._o_true(args) else idx + 1
        if self._o_true(args):
            return idx + 1
        return self._need(src.next_o(label, idx, ("endwhile",)), f"'o{label} endwhile'") + 1

    def _o_repeat(self, src: _Source, idx: int, label: str, args: list) -> int:
        """``repeat``: the count is taken when the loop starts; past the ``endrepeat`` when it runs out."""
        repeats = self.frames[-1].repeats
        key = (id(src), idx)
        if key not in repeats:
            n = self.value_of(args[0]) if args else 0.0
            if not 0 <= n <= MAX_REPEAT * 100:
                raise self.err(f"repeat count {n:g} is out of range 0..{MAX_REPEAT * 100}")
            repeats[key] = int(n)
        if repeats[key] > 0:
            repeats[key] -= 1
            return idx + 1
        del repeats[key]
        return self._need(src.next_o(label, idx, ("endrepeat",)), f"'o{label} endrepeat'") + 1

    def _o_break(self, src: _Source, idx: int, label: str, kw: str) -> int:
        """``break`` or ``continue``: past the end of the loop with this label that encloses the line, or to that
        end (``endwhile`` and ``endrepeat`` jump back, a ``do``'s ``while`` tests its condition)."""
        j = idx
        while True:
            j = self._need(src.next_o(label, j, ("endwhile", "endrepeat", "while")), f"end of loop 'o{label}'")
            kind = self._o_kind(src, label, j)
            if kind != "while" or self._is_do_tail(src, label, j):
                break
        if kw == "break":
            if kind == "endrepeat":
                head = src.prev_o(label, j)
                while head is not None and head[1] != "repeat":
                    head = src.prev_o(label, head[0])
                if head is not None:
                    self.frames[-1].repeats.pop((id(src), head[0]), None)
            return j + 1
        return j

    def find_sub(self, src: _Source, label: str) -> tuple[_Source, int]:
        for s in (src, self.main, *self.files.values()):
            if label in s.subs:
                return s, s.subs[label]
        if label.startswith("<"):
            name = label[1:-1]
            for d in self.path:
                f = d / f"{name}.ngc"
                if f.is_file():
                    _, text = read_text(f, not_text="not a G-code text file")
                    s = _Source(str(f), text)
                    self.files[str(f)] = s
                    if label in s.subs:
                        return s, s.subs[label]
                    raise self.err(f"{f} does not define 'o{label} sub'")
        where = f" (searched {', '.join(str(d) for d in self.path)})" if self.path else " (no --subroutine-path)"
        raise self.err(f"subroutine 'o{label}' is not defined{where}")

