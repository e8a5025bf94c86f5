"""HPGL in: pen-plotter files (``.plt``, ``.hpgl``, ``.hpg``) cut on the step/dir machine.

The seed's subset (``shared/seeds/004``, section 3.6.2): ``SPn`` selects
pen/tool n, ``PU`` lifts the tool, ``PD`` lowers it, ``PAx,y`` moves in
absolute plotter units; one plotter unit is 0.025 mm (40 units per mm).
Beyond the seed, so that files from Inkscape, vpype and CAD programs work:

* ``IN`` (initialise: pen up, absolute moves, default P1 and P2, no
  scaling, chord angles), ``DF`` (defaults: absolute moves, no scaling,
  chord angles), ``PR`` (relative moves);
* ``PU``/``PD``/``PA``/``PR`` with any number of coordinate pairs
  (``PD10,10,20,10,20,20;``), signed and decimal numbers;
* commands separated by ``;``, by a newline, or by nothing (the next
  two-letter mnemonic starts a command); whitespace anywhere; numbers
  separated by ``,`` or whitespace;
* ``SC``, ``IP`` and ``IR`` scale the plot as an HP-GL/2 plotter does, ``RO``
  turns its coordinate system (below);
* ``CI`` circles, ``AA``/``AR`` arcs, ``AT``/``RT`` three-point arcs, ``CT``
  chord tolerance mode (below);
* ``IW`` input window: pen-down strokes clipped to it (below);
* anything else is an unknown command: skipped with a warning naming its
  byte offset and line (``LT``, ``VS``, ``CO "comment"``; ``LB`` label text
  runs to the label terminator, ETX ``\\x03`` or the character set by ``DT``;
  ``PE`` runs to ``;``).  Drawing commands outside the subset (encoded
  polylines ``PE``, Beziers, rectangles and wedges, labels, ...) are therefore
  not cut.

Scaling (HP-GL/2): ``IP x1,y1,x2,y2`` sets the scaling points P1 and P2 in
plotter units (``IP x1,y1`` moves P1 and keeps P2 where it was relative to
it; ``IP;`` and ``IN`` restore the defaults, :data:`DEFAULT_P1_PU` and
:data:`DEFAULT_P2_PU`: an HP 7475A's on A4 paper, 250 x 180 mm apart; a P2
equal to P1 on an axis is moved one unit on).  ``SC xmin,xmax,ymin,ymax``
(type 0, anisotropic) maps user (xmin, ymin) to P1 and (xmax, ymax) to P2;
``SC xmin,xmax,ymin,ymax,1[,left,bottom]`` (isotropic) gives both axes the
smaller unit and leaves ``left`` % of the unused width to the left and
``bottom`` % of the unused height below (50, 50: centred);
``SC xmin,xfactor,ymin,yfactor,2`` (point factor) puts user (xmin, ymin) at
P1 with ``factor`` plotter units per user unit.  ``SC;``, ``DF`` and ``IN``
turn scaling off.  While scaling is on, ``PA``/``PU``/``PD`` coordinates,
``PR`` increments, arc centres and radii are user units; a new ``IP`` rescales
the user units that follow; the pen stays where it is (points are kept in
plotter units).  ``IR x1,y1[,x2,y2]`` is ``IP`` in percent (0..100) of the
rectangle from the default P1 to the default P2 (the page this reader
assumes); ``IR;`` restores the defaults.  ``RO angle`` (0, 90, 180 or 270;
``RO;`` and ``IN``: 0) turns the coordinate system that many degrees from +X
toward +Y about plotter (0, 0): a point (x, y) that follows is plotted at
(x, y) turned by the angle, P1 and P2 keep their values in the turned system,
and the pen stays where it is on the paper (its coordinates change).  The
shift a plotter adds to keep a turned plot on its page is not made: the
drawing is placed by its extent (or ``--offset``) when it is cut.

Input window (HP-GL/2): ``IW xll,yll,xur,yur`` sets the soft-clip window, its
corners either way round, in the current units (plotter units; user units
while scaling is on); a plotter draws only inside it, so every pen-down
segment (lines, and the chords of circles and arcs) is clipped to it, edges
included: the part inside is drawn, a segment coming in starts a stroke where
it crosses the edge, one going out ends there, and the pen moves up outside (a
dot outside is not made).  A window given in user units keeps its user
coordinates when ``IP``/``IR`` move P1 and P2, until an ``SC`` binds it to the
plotter units where it stands; a window in plotter units stays put.  It is
fixed on the paper as plotted: a later ``RO`` does not turn it.  ``IW;``, ``DF``
and ``IN`` take it away (the hard-clip limits: none, the page is not known).

Circles and arcs (HP-GL/2): ``CI r[,chord]`` draws a circle about the pen,
whether the pen is up or down: it starts at 0 degrees (180 for a negative
radius), counter-clockwise, a stroke of its own; the pen then stands at the
centre again, up or down as before (down: the next move draws from the centre;
no plunge there unless it moves).  ``AA x,y,sweep[,chord]`` (centre absolute)
and ``AR dx,dy,sweep[,chord]`` (centre relative to the pen) draw from the pen
through ``sweep`` degrees (positive counter-clockwise) when the pen is down,
and only move the pen when it is up.  Arcs are drawn in user units, so
anisotropic scaling makes ellipses.  ``AT xi,yi,xe,ye[,chord]`` (absolute)
and ``RT`` (both points relative to the pen) draw from the pen through the
intermediate point to the end point, the way round that passes the
intermediate point first, and leave the pen at the end point (up: it only
moves there).  The intermediate point at the pen or at the end point, or on
the line between them, draws a line; the end point at the pen draws a whole
circle whose diameter runs from the pen to the intermediate point; three points
on one line with the intermediate point outside the other two (a plotter
draws two lines out to the page's edges) is a :class:`~cam.errors.ParseError`.
The chord parameter is a chord angle in
degrees (default 5), or with ``CT1`` the most a chord may stray from the arc
(in the radius's units; ``CT0``/``CT;`` back to angles); the angle is clamped
to 0.5..180 degrees and the arc drawn with the fewest equal chords within it.
A circle's or an arc's chords are counted before one is made: more than
:data:`MAX_ARC_CHORDS` is a :class:`~cam.errors.ParseError` naming the
command and the count.

Malformed input is a :class:`~cam.errors.ParseError` ``file:line:column:``:
a malformed number (``1.2.3``, ``12x``, ``--4``), an empty parameter
(``PA,5``), an odd number of coordinates, an unterminated command at the end
of the file (``PA100,`` or a dangling mnemonic), a coordinate or a pen position beyond
:data:`MAX_COORD_PU` either way (a number of hundreds of digits included; after scaling), a pen beyond
:data:`cam.limits.MAX_TOOL_NUMBER`, a scaling, circle or arc command with the wrong number of
parameters, a degenerate ``SC`` (xmin = xmax, a factor 0, left/bottom outside 0..100), a circle or
arc that reaches beyond :data:`MAX_COORD_PU` or would take more than :data:`MAX_ARC_CHORDS` chords, an
``RO`` angle other than 0, 90, 180, 270, an ``IR`` percentage outside 0..100, the ``AT``/``RT`` above, an
``IW`` with other than 0 or 4 parameters.

Streaming: the file is read in chunks (:data:`CHUNK_BYTES`) by a compiled
tokenizer and a compiled interpreter, so :func:`scan_hpgl` keeps memory flat
however large the file is; :func:`load_hpgl` keeps only the pen-down points.

Interpretation: the pen starts up at plotter (0, 0) in absolute mode.  A pen
change (``SP``) lifts the pen; ``SP0``/``SP`` (no pen) keeps the tool that is
in the machine.  Each pen-down stroke starts where the pen goes down (a
``PD`` with no coordinates and then ``PU`` is a dot: plunge and lift).  Pen-up
moves only say where the next stroke starts: the machine goes there directly
at the safe height.

Planning the cut (frames, depths, tool changes) is :mod:`cam.job.hpgl`.

>>> d = parse_hpgl(b"IN;SP1;PU0,0;PD400,0,400,-400;PU;", source="sq.plt")
>>> d.points_pu.tolist(), d.stroke_pen.tolist()
([[0.0, 0.0], [400.0, 0.0], [400.0, -400.0]], [1])
"""
from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Callable, Iterator, Optional, TextIO, Union

import numpy as np
from numba import njit

from .._compiled import entry
from ..arrays import column_range
from ..errors import ParseError
from ..limits import MAX_COORD_MM, MAX_TOOL_NUMBER

__all__ = [
    "PLOTTER_UNIT_MM", "CHUNK_BYTES", "MAX_COORD_PU", "MAX_ARC_CHORDS", "ARC_MNEMONICS",
    "DEFAULT_P1_PU", "DEFAULT_P2_PU", "KNOWN",
    "HpglCommand", "HpglScan", "HpglDrawing", "PointBatch",
    "iter_hpgl", "scan_hpgl", "load_hpgl", "parse_hpgl", "point_batches",
]

PLOTTER_UNIT_MM = 0.025
"""One plotter unit: 0.025 mm, 40 units per mm (004 section 3.6.2)."""
CHUNK_BYTES = 1 << 19
"""Bytes read per chunk while streaming a file."""
MAX_COORD_PU = MAX_COORD_MM / PLOTTER_UNIT_MM
"""Every coordinate, and every pen position relative moves lead to, at most 4e7 plotter units (1e6 mm,
:data:`cam.limits.MAX_COORD_MM`) either way; pens ``SP`` 0..:data:`cam.limits.MAX_TOOL_NUMBER`."""

Progress = Callable[[int, Optional[int]], None]
Source = Union[str, os.PathLike, BinaryIO, TextIO]


def _code(mnemonic: str) -> int:
    return (ord(mnemonic[0]) << 8) | ord(mnemonic[1])


def _name(code: int) -> str:
    return chr((code >> 8) & 0xFF) + chr(code & 0xFF)


C_IN, C_DF, C_SP, C_PU, C_PD, C_PA, C_PR = (_code(m) for m in ("IN", "DF", "SP", "PU", "PD", "PA", "PR"))
C_LB, C_DT, C_PE = _code("LB"), _code("DT"), _code("PE")
C_SC, C_IP, C_CI, C_AA, C_AR, C_CT = (_code(m) for m in ("SC", "IP", "CI", "AA", "AR", "CT"))
C_AT, C_RT, C_RO, C_IR, C_IW = (_code(m) for m in ("AT", "RT", "RO", "IR", "IW"))
KNOWN = ("IN", "DF", "SP", "PU", "PD", "PA", "PR", "SC", "IP", "CI", "AA", "AR", "CT", "AT", "RT", "RO", "IR", "IW")
ARC_MNEMONICS = ("CI", "AA", "AR", "AT", "RT")
"""The commands that draw circles and arcs (each of their points carries the command's line and column)."""
ARC_CODES = np.array([_code(m) for m in ARC_MNEMONICS], np.int64)
"""The commands that draw chords (their points are counted before they are made)."""

# tokenizer modes
M_IDLE, M_MN1, M_PARAMS, M_SKIP, M_QUOTE, M_LABEL, M_DT, M_PE = range(8)
# error codes
(E_NONE, E_CHAR, E_MNEMONIC, E_NUMBER, E_EMPTY, E_TRAIL, E_EOF_COMMA, E_EOF_MNEMONIC, E_EOF_LABEL,
 E_EOF_STRING, E_ODD, E_SP, E_RANGE, E_ARGS, E_SCALE, E_CHORDS, E_ARC_RANGE, E_VALUE, E_ARC_LINE) = range(19)
# interpreter state slots (float64, kept from one chunk to the next): pen down, relative moves, the pen's
# position (plotter units), the pen, where the last coordinate stood, a pen down to restore after a circle
# (the stroke starts at the next move), P1 and P2, scaling on, its type and six parameters, the user-to-plotter
# transform (plotter = a * user + b per axis), the chord tolerance mode, the coordinate system's rotation
# (``RO``, in quarter turns: the pen's position and P1, P2 are in the rotated system, points as plotted), the
# input window (``IW``: on, its corners as plotted, whether it is bound to user units and its corners in them),
# and the clip's state: the last point of the stroke as plotted (before clipping) and whether the clipped stroke
# is open there (the pen is down inside the window)
(I_DOWN, I_REL, I_X, I_Y, I_PEN, I_LINE, I_COL, I_PENDING, I_P1X, I_P1Y, I_P2X, I_P2Y, I_SC, I_SCTYPE,
 I_SC0, I_SC1, I_SC2, I_SC3, I_SC4, I_SC5, I_AX, I_BX, I_AY, I_BY, I_CT, I_RO,
 I_IW, I_IWX0, I_IWY0, I_IWX1, I_IWY1, I_IWU, I_IWU0, I_IWU1, I_IWU2, I_IWU3, I_LX, I_LY, I_LIN) = range(39)
N_IST = 39
DEFAULT_P1_PU = (603.0, 521.0)
DEFAULT_P2_PU = (10603.0, 7721.0)
"""P1 and P2 after ``IN`` or ``IP;``: an HP 7475A's on A4 paper (10000 x 7200 plotter units, 250 x 180 mm apart)."""
DEFAULT_CHORD_DEG = 5.0
MIN_CHORD_DEG, MAX_CHORD_DEG = 0.5, 180.0
"""A chord angle (given, or made from a chord tolerance) is clamped to 0.5..180 degrees (HP-GL/2)."""
MAX_ARC_CHORDS = 100_000
"""One circle or arc (``CI``, ``AA``, ``AR``) is drawn with at most this many chords (139 turns at the finest
chord angle); its count is known before a chord is made, and a file that asks for more is refused naming it."""
BATCH_POINTS = 1 << 20
"""The most pen-down points made at once from a chunk with circles and arcs (memory stays flat)."""
# tokenizer state slots (int64): kept from one chunk to the next ...
(S_LINE, S_LSTART, S_BASE, S_TERM, S_RESUME, S_COFF, S_CLINE, S_CCOL, S_CONSUMED, S_NCMD, S_NPAR,
 S_ERR, S_ERRPOS, S_ERRLINE, S_ERRCOL, S_ERRAUX) = range(16)
# ... and the current command's, used within one chunk (indices into the chunk)
(S_CODE, S_CSTART, S_P0, S_EXPECT, S_SAFE, S_SAFE_LINE, S_SAFE_LSTART, S_PAIR_POS, S_PAIR_NP, S_PAIR_LINE,
 S_PAIR_LSTART, S_NUM_START, S_NUM_END) = range(16, 29)
N_SLOTS = 29
# what _number found
NUM_OK, NUM_MORE, NUM_BAD = range(3)

_COMMAND_DTYPES = (np.int64, np.int64, np.int32, np.int32, np.int32, np.int32)
"""Per command: mnemonic code, byte offset, line, column, first parameter, parameter count."""
_PARAM_DTYPES = (np.float64, np.int32, np.int32)
"""Per numeric parameter: value, line, column."""
_POINT_DTYPES = (np.float64, np.float64, np.int32, np.int32, np.bool_, np.int32)
"""Per pen-down point: x, y, line, column, stroke start, pen."""


def _arrays(n: int, dtypes) -> tuple[np.ndarray, ...]:
    return tuple(np.empty(n, t) for t in dtypes)


@njit(cache=True, nogil=True)
def _letter(c):
    return (65 <= c <= 90) or (97 <= c <= 122)


@njit(cache=True, nogil=True)
def _space(c):
    # space, tab, LF, VT, FF, CR; NUL, ETX and SUB (^Z) padding outside labels
    return c == 32 or (9 <= c <= 13) or c == 0 or c == 3 or c == 26


@njit(cache=True, nogil=True)
def _upper(c):
    return c - 32 if 97 <= c <= 122 else c


@njit(cache=True, nogil=True)
def _coord_cmd(code):
    return code == 0x5055 or code == 0x5044 or code == 0x5041 or code == 0x5052  # PU PD PA PR


@njit(cache=True, nogil=True)
def _known(code):
    return (_coord_cmd(code) or code == 0x494E or code == 0x4446 or code == 0x5350  # IN DF SP
            or code == 0x5343 or code == 0x4950 or code == 0x4349 or code == 0x4141  # SC IP CI AA
            or code == 0x4152 or code == 0x4354 or code == 0x4154 or code == 0x5254  # AR CT AT RT
            or code == 0x524F or code == 0x4952 or code == 0x4957)  # RO IR IW


@njit(cache=True, nogil=True)
def _mode_of(code):
    """The tokenizer mode after the mnemonic ``code``."""
    if code == C_LB:
        return M_LABEL
    if code == C_DT:
        return M_DT
    if code == C_PE:
        return M_PE
    if _known(code):
        return M_PARAMS
    return M_SKIP


@njit(cache=True, nogil=True)
def _emit(c_code, c_off, c_line, c_col, c_p0, c_np, nc, st, npar):
    """Record the current command (mnemonic code, byte offset, line, column in ``st``) with its parameters
    ``st[S_P0]`` to ``npar`` as command ``nc``; return nc + 1."""
    c_code[nc] = st[S_CODE]
    c_off[nc] = st[S_COFF]
    c_line[nc] = st[S_CLINE]
    c_col[nc] = st[S_CCOL]
    c_p0[nc] = st[S_P0]
    c_np[nc] = npar - st[S_P0]
    return nc + 1


# The helpers that take arrays and run per command or per number are written so that numba can drop
# the reference counting of those arrays (otherwise two atomic operations per array and call, which
# more than doubled the tokenizer's time): their loops end by their condition (no return or break
# inside), each array is last used in one place, and nothing on the way can raise -- hence _pow10 and
# np.true_divide in _number, where ``10.0 ** n`` and ``/`` would each bring an error exit.  _number and
# _params are inlined into the kernel (numba IR), so their calls cost nothing either.


@njit(cache=True, nogil=True)
def _pow10(exp):
    """``10.0 ** exp`` for ``exp >= 0``, computed exactly as numba computes a float to an integer power."""
    if exp > 0x10000:
        return math.pow(10.0, float(exp))
    r = 1.0
    a = 10.0
    while exp != 0:
        if exp & 1:
            r *= a
        exp >>= 1
        a *= a
    return r


@njit(cache=True, inline="always")
def _number(buf, i, final):
    """Read the number at ``buf[i]``: a sign, digits, a point, digits.

    Returns ``(status, value, j)``: NUM_OK with ``j`` just after the number; NUM_MORE when the chunk
    ends where the number might go on; NUM_BAD when there are no digits or the number is followed
    by something that cannot follow a number.
    """
    n = buf.shape[0]
    c = buf[i]
    j = i
    sign = 1.0
    if c == 43 or c == 45:
        if c == 45:
            sign = -1.0
        j += 1
    ival = 0.0
    nd = 0
    while j < n and 48 <= buf[j] <= 57:
        ival = ival * 10.0 + (buf[j] - 48)
        nd += 1
        j += 1
    point = j < n and buf[j] == 46
    if point:
        j += 1
    frac = 0.0
    nf = 0
    while point and j < n and 48 <= buf[j] <= 57:
        frac = frac * 10.0 + (buf[j] - 48)
        nf += 1
        j += 1
    after = buf[min(j, n - 1)]  # the two bytes after the number (where there are such bytes)
    after2 = buf[min(j + 1, n - 1)]
    status = NUM_OK
    if j >= n and not final:
        status = NUM_MORE
    elif nd + nf == 0:
        status = NUM_BAD
    elif j < n:
        if _letter(after):
            if j + 1 < n:
                if not _letter(after2):
                    status = NUM_BAD
            elif not final:
                status = NUM_MORE
        elif not (after == 44 or after == 59 or _space(after)):
            status = NUM_BAD
    value = ival
    if nf:
        value += np.true_divide(frac, _pow10(nf))
    return status, sign * value, j


@njit(cache=True, nogil=True)
def _begin_chunk(st):
    """Set the current command's slots for a new chunk; returns the mode to start in."""
    line = st[S_LINE]
    lstart = st[S_LSTART]
    st[S_CSTART] = 0
    st[S_P0] = 0
    st[S_SAFE] = 0  # where the command being read began: a chunk that ends inside it hands over from here
    st[S_SAFE_LINE] = line
    st[S_SAFE_LSTART] = lstart
    st[S_PAIR_POS] = -1  # just after the last complete coordinate pair of the command being read
    st[S_PAIR_NP] = 0
    st[S_PAIR_LINE] = line
    st[S_PAIR_LSTART] = lstart
    st[S_NUM_START] = -1
    st[S_NUM_END] = -1  # index just after the last number
    if st[S_RESUME] != 0:  # a coordinate command goes on from the last chunk (its position is in st)
        st[S_CODE] = st[S_RESUME]
        st[S_EXPECT] = 1
        return M_PARAMS
    st[S_CODE] = st[S_COFF] = st[S_CLINE] = st[S_CCOL] = 0
    st[S_EXPECT] = 0
    return M_IDLE


@njit(cache=True, nogil=True)
def _between(buf, i, st, base, line, lstart):
    """M_IDLE: blanks and ';' up to the next mnemonic.  Returns ``(i, mode, line, lstart, err)``."""
    n = buf.shape[0]
    mode = M_IDLE
    err = E_NONE
    while i < n and mode == M_IDLE and err == E_NONE:
        c = buf[i]
        if _letter(c):
            st[S_CSTART] = i
            st[S_SAFE] = i
            st[S_SAFE_LINE] = line
            st[S_SAFE_LSTART] = lstart
            mode = M_MN1
        elif not (c == 59 or _space(c)):
            st[S_ERRPOS] = base + i
            err = E_CHAR
        elif c == 10:
            line += 1
            lstart = base + i + 1
        i += 1
    return i, mode, line, lstart, err


@njit(cache=True, nogil=True)
def _mnemonic(buf, i, st, base, line, lstart, npar):
    """M_MN1: ``buf[i]`` ends the mnemonic begun at ``st[S_CSTART]``; records the command.

    Returns ``(mode, err)``.
    """
    c = buf[i]
    cstart = st[S_CSTART]
    if not _letter(c):
        if st[S_NUM_END] == cstart and st[S_NUM_START] >= 0:  # it began right after a number: a bad number
            st[S_ERRPOS] = base + st[S_NUM_START]
            return M_MN1, E_NUMBER
        st[S_ERRPOS] = base + cstart
        return M_MN1, E_MNEMONIC
    code = (_upper(buf[cstart]) << 8) | _upper(c)
    st[S_CODE] = code
    st[S_COFF] = base + cstart
    st[S_CLINE] = line
    st[S_CCOL] = base + cstart - lstart + 1
    st[S_P0] = npar
    st[S_PAIR_POS] = -1
    st[S_EXPECT] = 0  # in M_PARAMS: 0 after the mnemonic, 1 after a number, 2 after ','
    return _mode_of(code), E_NONE


@njit(cache=True, inline="always")
def _params(buf, i, final, st, base, line, lstart, npar, p_val, p_line, p_col):
    """M_PARAMS: the numbers of a known command, up to ';' or the next mnemonic.

    Returns ``(i, ended, npar, line, lstart, err, incomplete)``: ``ended`` when the command ended,
    ``incomplete`` when the chunk ends inside a number.
    """
    n = buf.shape[0]
    coord = _coord_cmd(st[S_CODE])
    p0 = st[S_P0]
    expect = st[S_EXPECT]
    err = E_NONE
    ended = False
    incomplete = False
    while i < n and not ended and not incomplete and err == E_NONE:
        c = buf[i]
        step = 1
        if c == 44:  # ','
            if expect != 1:
                err = E_EMPTY
            expect = 2
        elif c == 59 or _letter(c):  # ';' or the next mnemonic
            if expect == 2:
                err = E_TRAIL
            else:
                ended = True
                step = 1 if c == 59 else 0
        elif c == 43 or c == 45 or c == 46 or (48 <= c <= 57):
            status, value, j = _number(buf, i, final)
            incomplete = status == NUM_MORE
            if status == NUM_BAD:
                err = E_NUMBER
            elif status == NUM_OK:
                p_val[npar] = value
                p_line[npar] = line
                p_col[npar] = base + i - lstart + 1
                npar += 1
                expect = 1
                st[S_NUM_START] = i
                st[S_NUM_END] = j
                if coord and (npar - p0) % 2 == 0:
                    st[S_PAIR_POS] = j
                    st[S_PAIR_NP] = npar
                    st[S_PAIR_LINE] = line
                    st[S_PAIR_LSTART] = lstart
                step = j - i
        elif c == 10:
            line += 1
            lstart = base + i + 1
        elif not _space(c):
            err = E_CHAR
        if err == E_NONE and not incomplete:
            i += step
    st[S_ERRPOS] = base + i  # read only after an error
    st[S_EXPECT] = expect
    return i, ended, npar, line, lstart, err, incomplete


@njit(cache=True, nogil=True)
def _skip(buf, i, mode, st, base, line, lstart):
    """An unknown command (M_SKIP, with its quoted strings M_QUOTE), PE, DT or a label (M_LABEL), up to its end.

    Returns ``(i, mode, line, lstart, ended)``; ``ended`` when the command ended (not at the chunk's end).
    """
    n = buf.shape[0]
    ended = False
    while i < n and not ended:
        c = buf[i]
        step = 1
        if mode == M_DT and c != 59:  # the byte after DT is the label terminator
            st[S_TERM] = c
            mode = M_SKIP
        elif mode == M_QUOTE:
            if c == 34:
                mode = M_SKIP
        elif mode == M_LABEL:
            ended = c == st[S_TERM]
        else:  # M_SKIP, M_PE, or DT followed by ';' (the default terminator, ETX)
            if mode == M_DT:
                st[S_TERM] = 3
                mode = M_SKIP
            if c == 59 or (mode == M_SKIP and _letter(c)):
                ended = True
                step = 1 if c == 59 else 0
            elif c == 34 and mode == M_SKIP:  # '"' opens a quoted string
                mode = M_QUOTE
        if c == 10 and step:
            line += 1
            lstart = base + i + 1
        i += step
    return i, mode, line, lstart, ended


@njit(cache=True, nogil=True)
def _hand_over(st, mode, n, npar, line, lstart):
    """The chunk ends (not the file): what is consumed, and where the next chunk starts.

    Returns ``(npar, consumed, line, lstart, resume, emit)``; ``emit``: record the current command.
    """
    if mode == M_IDLE:
        return npar, n, line, lstart, 0, False
    code = st[S_CODE]
    safe = st[S_SAFE]
    if mode == M_PARAMS and _coord_cmd(code) and st[S_PAIR_POS] >= 0 and safe == 0:
        # a coordinate command that fills the buffer: hand over its complete pairs, resume after them
        return st[S_PAIR_NP], st[S_PAIR_POS], st[S_PAIR_LINE], st[S_PAIR_LSTART], code, True
    resume = 0
    if st[S_RESUME] != 0 and safe == 0 and mode == M_PARAMS:
        resume = st[S_RESUME]  # the resumed command is still without a complete pair: read more
    return (st[S_P0] if mode != M_MN1 else npar), safe, st[S_SAFE_LINE], st[S_SAFE_LSTART], resume, False


@njit(cache=True, nogil=True)
def _end_of_file(st, mode, n, base):
    """The file ends in ``mode``.  Returns ``(err, emit)``; ``emit``: record the current command."""
    if mode == M_MN1:
        st[S_ERRPOS] = base + st[S_CSTART]
        return E_EOF_MNEMONIC, False
    if mode == M_PARAMS and st[S_EXPECT] == 2:
        st[S_ERRPOS] = base + n
        return E_EOF_COMMA, False
    if mode == M_LABEL or mode == M_QUOTE:
        st[S_ERRPOS] = base + n
        return (E_EOF_LABEL if mode == M_LABEL else E_EOF_STRING), False
    return E_NONE, mode != M_IDLE


@njit(cache=True, nogil=True)
def _error_at(st, err, line, lstart):
    """Line and column of the error at file offset ``st[S_ERRPOS]`` (from the last known line start)."""
    at = st[S_ERRPOS]
    el = line
    els = lstart
    if at < lstart:  # the error lies before the current line (at a command start)
        el = st[S_SAFE_LINE]
        els = st[S_SAFE_LSTART]
    st[S_ERRLINE] = el
    st[S_ERRCOL] = at - els + 1
    st[S_ERRAUX] = st[S_CODE]
    if err == E_EOF_COMMA or err == E_EOF_LABEL or err == E_EOF_STRING or err == E_TRAIL:
        st[S_ERRLINE] = st[S_CLINE]
        st[S_ERRCOL] = st[S_CCOL]


@entry
@njit(cache=True, nogil=True)
def _tokenize(buf, final, st, c_code, c_off, c_line, c_col, c_p0, c_np, p_val, p_line, p_col):
    """Commands and numeric parameters of one chunk (see :func:`_chunks` for the contract).

    Returns the number of commands.  Each mode's helper reads bytes as long as the tokenizer stays in
    its mode; ``st`` carries the state from one chunk to the next and the current command's.
    """
    n = buf.shape[0]
    base = st[S_BASE]
    line = st[S_LINE]
    lstart = st[S_LSTART]
    mode = _begin_chunk(st)
    nc = 0
    npar = 0
    err = E_NONE
    incomplete = False
    i = 0
    while i < n and err == E_NONE and not incomplete:
        ended = False
        if mode == M_IDLE:
            i, mode, line, lstart, err = _between(buf, i, st, base, line, lstart)
        elif mode == M_MN1:
            mode, err = _mnemonic(buf, i, st, base, line, lstart, npar)
            i += 1
        elif mode == M_PARAMS:
            i, ended, npar, line, lstart, err, incomplete = _params(buf, i, final, st, base, line, lstart, npar,
                                                                    p_val, p_line, p_col)
        else:
            i, mode, line, lstart, ended = _skip(buf, i, mode, st, base, line, lstart)
        if ended:
            nc = _emit(c_code, c_off, c_line, c_col, c_p0, c_np, nc, st, npar)
            mode = M_IDLE
    consumed = n
    resume = 0
    emit = False
    if err == E_NONE and (incomplete or not final):
        npar, consumed, line, lstart, resume, emit = _hand_over(st, mode, n, npar, line, lstart)
    elif err == E_NONE:  # the end of the file
        err, emit = _end_of_file(st, mode, n, base)
    if emit:
        nc = _emit(c_code, c_off, c_line, c_col, c_p0, c_np, nc, st, npar)
    if err != E_NONE:
        _error_at(st, err, line, lstart)
    st[S_ERR] = err
    st[S_CONSUMED] = consumed
    st[S_NCMD] = nc
    st[S_NPAR] = npar
    st[S_LINE] = line
    st[S_LSTART] = lstart
    st[S_BASE] = base + consumed
    st[S_RESUME] = resume
    return nc


@njit(cache=True, nogil=True)
def _point(o_x, o_y, o_line, o_col, o_start, o_pen, k, x, y, line, col, start, pen, write, ro=0.0):
    """Record pen-down point ``k`` (:data:`_POINT_DTYPES`) when ``write`` (else only count it); return k + 1.
    ``(x, y)`` is in the coordinate system turned ``ro`` quarter turns (``RO``): recorded as plotted."""
    if write:
        o_x[k], o_y[k] = _turn(x, y, ro)
        o_line[k], o_col[k] = line, col
        o_start[k], o_pen[k] = start, pen
    return k + 1


@njit(cache=True, nogil=True)
def _clip(ax, ay, bx, by, x0, y0, x1, y1):
    """The part of the segment from ``(ax, ay)`` to ``(bx, by)`` inside the box ``x0..x1`` by ``y0..y1`` (edges
    included): its parameters ``(t0, t1)`` along the segment, ``t0 > t1`` when it misses the box (Liang and
    Barsky's clip)."""
    t0, t1 = 0.0, 1.0
    dx, dy = bx - ax, by - ay
    for side in range(4):
        if side == 0:
            p, q = -dx, ax - x0
        elif side == 1:
            p, q = dx, x1 - ax
        elif side == 2:
            p, q = -dy, ay - y0
        else:
            p, q = dy, y1 - ay
        if p == 0.0:
            if q < 0.0:
                return 1.0, 0.0
        else:
            r = q / p
            if p < 0.0:
                if r > t1:
                    return 1.0, 0.0
                t0 = max(t0, r)
            else:
                if r < t0:
                    return 1.0, 0.0
                t1 = min(t1, r)
    return t0, t1


@njit(cache=True, nogil=True)
def _along(ax, ay, bx, by, t, ist):
    """The point at ``t`` along the segment from ``(ax, ay)`` to ``(bx, by)``, kept inside the window (a point
    computed on its edge may not stray off it by rounding); its ends exactly."""
    if t <= 0.0:
        return ax, ay
    if t >= 1.0:
        return bx, by
    x = min(max(ax + (bx - ax) * t, ist[I_IWX0]), ist[I_IWX1])
    y = min(max(ay + (by - ay) * t, ist[I_IWY0]), ist[I_IWY1])
    return x, y


@njit(cache=True, nogil=True)
def _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, x, y, line, col, start, pen, write):
    """The pen down at ``(x, y)`` (the coordinate system turned ``ist[I_RO]``, a stroke's first point when
    ``start``): the points it plots, recorded from ``k`` (:func:`_point`) as plotted, or only counted; returns the
    next ``k``.  With an input window (``IW``) the stroke is clipped to it as a plotter clips it: the part of each
    segment inside the window is drawn, a segment coming in starts a stroke where it crosses the edge, one
    going out ends there, and the pen moves up outside; the same points are counted as recorded."""
    px, py = _turn(x, y, ist[I_RO])
    ax, ay = ist[I_LX], ist[I_LY]
    ist[I_LX], ist[I_LY] = px, py
    if ist[I_IW] == 0:
        if not start and ist[I_LIN] == 0:  # the window was taken away with the pen down outside it
            k = _point(o_x, o_y, o_line, o_col, o_start, o_pen, k, ax, ay, line, col, True, pen, write)
        ist[I_LIN] = 1.0
        return _point(o_x, o_y, o_line, o_col, o_start, o_pen, k, px, py, line, col, start, pen, write)
    x0, y0, x1, y1 = ist[I_IWX0], ist[I_IWY0], ist[I_IWX1], ist[I_IWY1]
    if start:
        inside = x0 <= px <= x1 and y0 <= py <= y1
        ist[I_LIN] = 1.0 if inside else 0.0
        if inside:
            k = _point(o_x, o_y, o_line, o_col, o_start, o_pen, k, px, py, line, col, True, pen, write)
        return k
    t0, t1 = _clip(ax, ay, px, py, x0, y0, x1, y1)
    if t0 >= t1 and not (ax == px and ay == py and t0 <= t1):  # misses the window, or only touches it
        ist[I_LIN] = 0.0
        return k
    if t0 > 0.0 or ist[I_LIN] == 0:
        sx, sy = _along(ax, ay, px, py, t0, ist)
        k = _point(o_x, o_y, o_line, o_col, o_start, o_pen, k, sx, sy, line, col, True, pen, write)
    ex, ey = _along(ax, ay, px, py, t1, ist)
    k = _point(o_x, o_y, o_line, o_col, o_start, o_pen, k, ex, ey, line, col, False, pen, write)
    ist[I_LIN] = 1.0 if t1 >= 1.0 else 0.0
    return k


@njit(cache=True, nogil=True)
def _window(ist):
    """The input window's corners as plotted (``ist[I_IWX0..I_IWY1]``, lower left and upper right) from its
    corners as ``IW`` gave them (``ist[I_IWU0..I_IWU3]``, in the units in force then: user units, through the
    scaling, while it is on), and whether the stroke is open at the pen (the pen down inside the window)."""
    ax, bx, ay, by = ist[I_AX], ist[I_BX], ist[I_AY], ist[I_BY]
    xa, ya = _turn(ax * ist[I_IWU0] + bx, ay * ist[I_IWU1] + by, ist[I_RO])
    xb, yb = _turn(ax * ist[I_IWU2] + bx, ay * ist[I_IWU3] + by, ist[I_RO])
    ist[I_IWX0], ist[I_IWX1] = min(xa, xb), max(xa, xb)
    ist[I_IWY0], ist[I_IWY1] = min(ya, yb), max(ya, yb)
    ist[I_IW] = 1.0
    lx, ly = ist[I_LX], ist[I_LY]
    inside = ist[I_IWX0] <= lx <= ist[I_IWX1] and ist[I_IWY0] <= ly <= ist[I_IWY1]
    ist[I_LIN] = 1.0 if ist[I_LIN] != 0 and inside else 0.0


@njit(cache=True, nogil=True)
def _iw(m, p0, p_val, p_line, p_col, line, col, ist, err):
    """``IW xll,yll,xur,yur``: the input window, in the current units (user units while scaling is on; the window
    then keeps its user coordinates when P1 and P2 move, until an ``SC`` binds it to plotter units); ``IW;``: no
    window (the hard-clip limits: none here).  Returns False after recording an error in ``err``."""
    if not (m == 0 or m == 4):
        _fail(err, E_ARGS, line, col, m, C_IW)
        return False
    if m == 0:
        ist[I_IW] = 0.0
        ist[I_IWU] = 0.0
        return True
    for q in range(p0, p0 + 4):
        if not abs(p_val[q]) <= MAX_COORD_PU:
            _fail(err, E_RANGE, p_line[q], p_col[q], q, 0)
            return False
    ist[I_IWU0], ist[I_IWU1], ist[I_IWU2], ist[I_IWU3] = p_val[p0], p_val[p0 + 1], p_val[p0 + 2], p_val[p0 + 3]
    ist[I_IWU] = ist[I_SC]
    _window(ist)
    return True


@njit(cache=True, nogil=True)
def _turn(x, y, quarters):
    """``(x, y)`` turned ``quarters`` quarter turns counter-clockwise (+X toward +Y) about (0, 0); exact."""
    q = int(quarters) % 4
    if q == 1:
        return -y, x
    if q == 2:
        return -x, -y
    if q == 3:
        return y, -x
    return x, y


@njit(cache=True, nogil=True)
def _rescale(ist):
    """The user-to-plotter transform (``ist[I_AX..I_BY]``) from P1, P2 and the ``SC`` parameters (HP-GL/2):
    type 0 maps (xmin, ymin) to P1 and (xmax, ymax) to P2; type 1 does so with one unit size for both axes
    (the smaller), the unused space split by the left and bottom percentages; type 2 puts (xmin, ymin) at P1
    with the given plotter units per user unit.  Scaling off: user units are plotter units."""
    if ist[I_SC] == 0:
        ist[I_AX], ist[I_BX], ist[I_AY], ist[I_BY] = 1.0, 0.0, 1.0, 0.0
        return
    p1x, p1y, p2x, p2y = ist[I_P1X], ist[I_P1Y], ist[I_P2X], ist[I_P2Y]
    kind = ist[I_SCTYPE]
    xmin, ymin = ist[I_SC0], ist[I_SC2]
    if kind == 2:
        ax, ay = ist[I_SC1], ist[I_SC3]
        bx, by = p1x - xmin * ax, p1y - ymin * ay
    else:
        ax = (p2x - p1x) / (ist[I_SC1] - xmin)
        ay = (p2y - p1y) / (ist[I_SC3] - ymin)
        bx, by = p1x - xmin * ax, p1y - ymin * ay
        if kind == 1:
            unit = min(abs(ax), abs(ay))
            ax = unit if ax > 0 else -unit
            ay = unit if ay > 0 else -unit
            spare_x = (p2x - p1x) - ax * (ist[I_SC1] - xmin)
            spare_y = (p2y - p1y) - ay * (ist[I_SC3] - ymin)
            bx = p1x + ist[I_SC4] / 100.0 * spare_x - xmin * ax
            by = p1y + ist[I_SC5] / 100.0 * spare_y - ymin * ay
    ist[I_AX], ist[I_BX], ist[I_AY], ist[I_BY] = ax, bx, ay, by


@njit(cache=True, nogil=True)
def _reset(ist, initialise):
    """``DF`` (scaling off, chord angles) and, with ``initialise``, ``IN`` (also P1 and P2 to their defaults)."""
    ist[I_SC] = 0.0
    ist[I_CT] = 0.0
    ist[I_IW] = ist[I_IWU] = 0.0  # no input window
    if initialise:
        ist[I_P1X], ist[I_P1Y] = DEFAULT_P1_PU[0], DEFAULT_P1_PU[1]
        ist[I_P2X], ist[I_P2Y] = DEFAULT_P2_PU[0], DEFAULT_P2_PU[1]
    _rescale(ist)


@njit(cache=True, nogil=True)
def _chords(ist, sweep_deg, radius_user, has_chord, chord):
    """The number of equal chords of an arc of ``sweep_deg`` (float: it may be huge): the chord angle (or, in
    ``CT1`` mode, the angle whose chord strays ``chord`` from the arc, in the radius's units) clamped to
    0.5..180 degrees, as few chords as keep each within it."""
    angle = DEFAULT_CHORD_DEG
    if has_chord:
        angle = abs(chord)
        if ist[I_CT] != 0:
            tolerance = abs(chord)
            r = abs(radius_user)
            angle = MAX_CHORD_DEG
            if r > 0 and tolerance < r:
                angle = math.degrees(2.0 * math.acos(1.0 - tolerance / r))
    angle = min(max(angle, MIN_CHORD_DEG), MAX_CHORD_DEG)
    n = np.ceil(abs(sweep_deg) / angle - 1e-9)  # a float: a huge sweep must not overflow an integer
    return max(n, 1.0) if sweep_deg != 0 else 0.0


@njit(cache=True, nogil=True)
def _fail(err, code, line, col, aux, aux2):
    err[0], err[1], err[2], err[3], err[4] = code, line, col, aux, aux2


@njit(cache=True, nogil=True)
def _ip(m, p0, p_val, p_line, p_col, line, col, ist, err):
    """``IP``: the scaling points P1 and P2 (plotter units).  Returns False after recording an error in ``err``."""
    if not (m == 0 or m == 2 or m == 4):
        _fail(err, E_ARGS, line, col, m, C_IP)
        return False
    for q in range(p0, p0 + m):
        if not abs(p_val[q]) <= MAX_COORD_PU:
            _fail(err, E_RANGE, p_line[q], p_col[q], q, 0)
            return False
    _p1p2(m, p_val[p0:p0 + m], ist)
    return True


@njit(cache=True, nogil=True)
def _ir(m, p0, p_val, p_line, p_col, line, col, ist, err):
    """``IR``: P1 and P2 at percentages (0..100) of the rectangle between the default P1 and P2 (the page this
    reader assumes, :data:`DEFAULT_P1_PU`, :data:`DEFAULT_P2_PU`).  Returns False after recording an error."""
    if not (m == 0 or m == 2 or m == 4):
        _fail(err, E_ARGS, line, col, m, C_IR)
        return False
    at = np.empty(m)
    for q in range(p0, p0 + m):
        if not 0.0 <= p_val[q] <= 100.0:
            _fail(err, E_VALUE, p_line[q], p_col[q], q, C_IR)
            return False
        axis = (q - p0) % 2
        at[q - p0] = DEFAULT_P1_PU[axis] + p_val[q] / 100.0 * (DEFAULT_P2_PU[axis] - DEFAULT_P1_PU[axis])
    _p1p2(m, at, ist)
    return True


@njit(cache=True, nogil=True)
def _p1p2(m, at, ist):
    """P1 (and P2) at ``at`` (plotter units; ``m`` 0: the defaults; 2: P2 keeps its place relative to P1)."""
    if m == 0:
        ist[I_P1X], ist[I_P1Y] = DEFAULT_P1_PU[0], DEFAULT_P1_PU[1]
        ist[I_P2X], ist[I_P2Y] = DEFAULT_P2_PU[0], DEFAULT_P2_PU[1]
    else:
        dx, dy = ist[I_P2X] - ist[I_P1X], ist[I_P2Y] - ist[I_P1Y]
        ist[I_P1X], ist[I_P1Y] = at[0], at[1]
        if m == 4:
            ist[I_P2X], ist[I_P2Y] = at[2], at[3]
        else:  # P2 keeps its place relative to P1
            ist[I_P2X], ist[I_P2Y] = ist[I_P1X] + dx, ist[I_P1Y] + dy
        if ist[I_P2X] == ist[I_P1X]:  # HP-GL/2: P2 one unit further
            ist[I_P2X] += 1.0
        if ist[I_P2Y] == ist[I_P1Y]:
            ist[I_P2Y] += 1.0
    _rescale(ist)
    if ist[I_IW] != 0 and ist[I_IWU] != 0:  # a window in user units keeps them: it moves with P1 and P2
        _window(ist)


@njit(cache=True, nogil=True)
def _turn_to(quarters, ist, cx, cy):
    """``RO`` (``IN``: back to none): the coordinate system turned ``quarters`` quarter turns from the plotter's.
    The pen stays where it is on the paper, so its coordinates in the new system change; returns them."""
    x, y = _turn(cx, cy, ist[I_RO] - quarters)
    ist[I_RO] = quarters
    return x, y


@njit(cache=True, nogil=True)
def _setting(code, m, p0, p_val, p_line, p_col, line, col, ist, cx, cy, err):
    """``CT``, ``RO`` or ``IR``.  Returns ``(cx, cy, ok)``, the pen in the (new) coordinate system; not ``ok``: an
    error is recorded in ``err``."""
    v = p_val[p0] if m else 0.0
    if code == C_IR:
        return cx, cy, _ir(m, p0, p_val, p_line, p_col, line, col, ist, err)
    if m > 1 or (code == C_CT and not (v == 0 or v == 1)):
        _fail(err, E_ARGS, line, col, m, code)
        return cx, cy, False
    if code == C_CT:
        ist[I_CT] = v
        return cx, cy, True
    if not (v == 0 or v == 90 or v == 180 or v == 270):
        _fail(err, E_VALUE, p_line[p0], p_col[p0], p0, C_RO)
        return cx, cy, False
    cx, cy = _turn_to(v / 90.0, ist, cx, cy)
    return cx, cy, True


@njit(cache=True, nogil=True)
def _three_points(ui, vi, ue, ve):
    """The arc from (0, 0) through ``(ui, vi)`` to ``(ue, ve)`` (``AT``/``RT`` in user units from the pen), as
    HP-GL/2 draws it: ``(kind, centre x, centre y, radius, start angle (radians), sweep (degrees))``, kind 1 an
    arc (a whole circle, the first two points its diameter, when the end is the pen), 0 a line to the end (the
    intermediate point at an end, or between them on one line), 2 three points on a line with the intermediate
    point outside (a plotter draws two lines to the page's edges)."""
    if (ui == 0 and vi == 0) or (ui == ue and vi == ve):
        return 0, 0.0, 0.0, 0.0, 0.0, 0.0
    if ue == 0 and ve == 0:
        ux, uy = ui / 2.0, vi / 2.0
        return 1, ux, uy, math.hypot(ux, uy), math.atan2(-uy, -ux), 360.0
    cross = ui * ve - vi * ue
    if abs(cross) <= 1e-12 * math.hypot(ui, vi) * math.hypot(ue, ve):
        between = ui * ue + vi * ve > 0 and (ue - ui) * ue + (ve - vi) * ve > 0
        return (0 if between else 2), 0.0, 0.0, 0.0, 0.0, 0.0
    d = 2.0 * cross
    i2, e2 = ui * ui + vi * vi, ue * ue + ve * ve
    ux, uy = (ve * i2 - vi * e2) / d, (ui * e2 - ue * i2) / d
    theta0 = math.atan2(-uy, -ux)
    to_end = (math.atan2(ve - uy, ue - ux) - theta0) % (2.0 * math.pi)
    to_mid = (math.atan2(vi - uy, ui - ux) - theta0) % (2.0 * math.pi)
    sweep = to_end if to_mid < to_end else to_end - 2.0 * math.pi
    return 1, ux, uy, math.hypot(ux, uy), theta0, math.degrees(sweep)


@njit(cache=True, nogil=True)
def _arc3(code, m, p0, p_val, p_line, p_col, line, col, ist, cx, cy, pen_down, pending, pen, write, k,
          o_x, o_y, o_line, o_col, o_start, o_pen, err):
    """``AT``/``RT`` from the pen at ``(cx, cy)`` (plotter units) through an intermediate point to an end point
    (user units, absolute or relative to the pen): drawn when the pen is down, else the pen only moves to the
    end.  Returns ``(k, cx, cy, pending, ok)``; not ``ok``: an error is recorded in ``err``."""
    if not (m == 4 or m == 5):
        _fail(err, E_ARGS, line, col, m, code)
        return k, cx, cy, pending, False
    ax, bx, ay, by = ist[I_AX], ist[I_BX], ist[I_AY], ist[I_BY]
    rel = code == C_RT
    if rel:
        ex, ey = cx + ax * p_val[p0 + 2], cy + ay * p_val[p0 + 3]
        ui, vi = p_val[p0], p_val[p0 + 1]
    else:
        ex, ey = ax * p_val[p0 + 2] + bx, ay * p_val[p0 + 3] + by
        ui, vi = (ax * p_val[p0] + bx - cx) / ax, (ay * p_val[p0 + 1] + by - cy) / ay
    for q in range(2):
        if not abs(ex if q == 0 else ey) <= MAX_COORD_PU:  # NaN too
            _fail(err, E_RANGE, p_line[p0 + 2 + q], p_col[p0 + 2 + q], p0 + 2 + q, 1 if rel else 0)
            return k, cx, cy, pending, False
    kind, ux, uy, radius, theta0, sweep = _three_points(ui, vi, (ex - cx) / ax, (ey - cy) / ay)
    if kind == 2:
        _fail(err, E_ARC_LINE, line, col, 0, code)
        return k, cx, cy, pending, False
    n = 1
    ccx, ccy = cx, cy
    if kind == 1:
        n_f = _chords(ist, sweep, radius, m == 5, p_val[p0 + 4] if m == 5 else 0.0)
        if n_f > MAX_ARC_CHORDS:
            _fail(err, E_CHORDS, line, col, int(min(n_f, 4e18)), code)
            return k, cx, cy, pending, False
        n = int(n_f)
        ccx, ccy = cx + ax * ux, cy + ay * uy
        if not (abs(ccx) + abs(ax * radius) <= MAX_COORD_PU and abs(ccy) + abs(ay * radius) <= MAX_COORD_PU):
            _fail(err, E_ARC_RANGE, line, col, 0, code)
            return k, cx, cy, pending, False
    if pen_down:
        if pending:
            k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, cx, cy, line, col, True, pen, write)
            pending = False
        sweep_rad = math.radians(sweep)
        for j in range(1, n):
            t = theta0 + sweep_rad * j / n
            k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, ccx + ax * radius * math.cos(t),
                      ccy + ay * radius * math.sin(t), line, col, False, pen, write)
        # an arc's points carry the command's place, a line's end its own (so G-code out fits no arc to it)
        el, ec = (line, col) if kind == 1 else (p_line[p0 + 2], p_col[p0 + 2])
        k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, ex, ey, el, ec, False, pen, write)
    return k, ex, ey, pending, True


@njit(cache=True, nogil=True)
def _sc(m, p0, p_val, line, col, ist, err):
    """``SC``: scaling on (its type and parameters) or off.  Returns False after recording an error in ``err``."""
    kind = p_val[p0 + 4] if m >= 5 else 0.0
    if not (m == 0 or m == 4 or m == 5 or (m == 7 and kind == 1)) or not (kind == 0 or kind == 1
                                                                           or kind == 2):
        _fail(err, E_ARGS, line, col, m, C_SC)
        return False
    ist[I_IWU] = 0.0  # an SC binds the window to the plotter units it stands at
    if m == 0:
        ist[I_SC] = 0.0
    else:
        a0, a1, a2, a3 = p_val[p0], p_val[p0 + 1], p_val[p0 + 2], p_val[p0 + 3]
        left = p_val[p0 + 5] if m == 7 else 50.0
        bottom = p_val[p0 + 6] if m == 7 else 50.0
        if (kind == 2 and (a1 == 0 or a3 == 0)) or (kind != 2 and (a0 == a1 or a2 == a3)) \
                or not (0 <= left <= 100 and 0 <= bottom <= 100):
            _fail(err, E_SCALE, line, col, 0, C_SC)
            return False
        ist[I_SC], ist[I_SCTYPE] = 1.0, kind
        ist[I_SC0], ist[I_SC1], ist[I_SC2], ist[I_SC3] = a0, a1, a2, a3
        ist[I_SC4], ist[I_SC5] = left, bottom
    _rescale(ist)
    return True


@njit(cache=True, nogil=True)
def _arc(code, m, p0, p_val, p_line, p_col, line, col, ist, cx, cy, pen_down, pending, pen, write, k,
         o_x, o_y, o_line, o_col, o_start, o_pen, err):
    """``CI``, ``AA`` or ``AR`` (``AT``, ``RT``: :func:`_arc3`) from the pen at ``(cx, cy)`` (plotter units): its
    points recorded from ``k`` (or only counted).  Returns ``(k, cx, cy, pending, ok)``; not ``ok``: an error is
    recorded in ``err``."""
    if code == C_AT or code == C_RT:
        return _arc3(code, m, p0, p_val, p_line, p_col, line, col, ist, cx, cy, pen_down, pending, pen, write, k,
                     o_x, o_y, o_line, o_col, o_start, o_pen, err)
    circle = code == C_CI
    if (circle and not (m == 1 or m == 2)) or (not circle and not (m == 3 or m == 4)):
        _fail(err, E_ARGS, line, col, m, code)
        return k, cx, cy, pending, False
    ax, ay = ist[I_AX], ist[I_AY]
    if circle:
        ccx, ccy = cx, cy
        radius = p_val[p0]
        sweep = 360.0
        theta0 = 0.0
        has_chord = m == 2
        chord = p_val[p0 + 1] if has_chord else 0.0
    else:
        if code == C_AA:
            ccx, ccy = ax * p_val[p0] + ist[I_BX], ay * p_val[p0 + 1] + ist[I_BY]
        else:
            ccx, ccy = cx + ax * p_val[p0], cy + ay * p_val[p0 + 1]
        ux, uy = (cx - ccx) / ax, (cy - ccy) / ay
        radius = math.hypot(ux, uy)
        theta0 = math.atan2(uy, ux)
        sweep = p_val[p0 + 2]
        has_chord = m == 4
        chord = p_val[p0 + 3] if has_chord else 0.0
    n_f = _chords(ist, sweep, radius, has_chord, chord)
    if n_f > MAX_ARC_CHORDS:
        _fail(err, E_CHORDS, line, col, int(min(n_f, 4e18)), code)
        return k, cx, cy, pending, False
    n = int(n_f)
    reach_x, reach_y = abs(ax * radius), abs(ay * radius)
    if not (abs(ccx) + reach_x <= MAX_COORD_PU and abs(ccy) + reach_y <= MAX_COORD_PU):
        _fail(err, E_ARC_RANGE, line, col, 0, code)
        return k, cx, cy, pending, False
    if circle:
        sx, sy = ccx + ax * radius, ccy  # a positive radius starts at 0 degrees, a negative one at 180
        ex, ey = sx, sy
    else:
        sx, sy = cx, cy
        t = theta0 + math.radians(sweep)
        ex, ey = ccx + ax * radius * math.cos(t), ccy + ay * radius * math.sin(t)
    draw = (circle or pen_down) and n > 0
    if draw and (write or ist[I_IW] != 0):  # clipped to a window: its points are counted as they are made
        if circle or pending:
            k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, sx, sy, line, col, True, pen, write)
        sweep_rad = math.radians(sweep)
        for j in range(1, n):
            t = theta0 + sweep_rad * j / n
            k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, ccx + ax * radius * math.cos(t),
                      ccy + ay * radius * math.sin(t), line, col, False, pen, write)
        k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, ex, ey, line, col, False, pen, write)
    elif draw:  # counted only (no window: one point a chord); the pen is where the last would be
        k += n + (1 if circle or pending else 0)
        ist[I_LX], ist[I_LY] = _turn(ex, ey, ist[I_RO])
        ist[I_LIN] = 1.0
    if circle:
        pending = pen_down  # the pen goes back to the centre up; down again there, it draws from the next move
    elif n > 0:
        cx, cy = ex, ey
        if draw:
            pending = False
    return k, cx, cy, pending, True


@njit(cache=True, nogil=True)
def _pairs(p0, m, p_val, p_line, p_col, ist, cx, cy, cl, cc, pen_down, pending, rel, pen, write, k,
           o_x, o_y, o_line, o_col, o_start, o_pen, err):
    """The coordinate pairs of a ``PU``/``PD``/``PA``/``PR`` (user units, absolute or ``rel``): the pen moves, and
    draws when down.  Returns ``(k, cx, cy, cl, cc, pending, ok)``; not ``ok``: an error is recorded in ``err``."""
    ax, bx, ay, by = ist[I_AX], ist[I_BX], ist[I_AY], ist[I_BY]
    for q in range(p0, p0 + m, 2):
        if pen_down and pending:
            k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, cx, cy, cl, cc, True, pen, write)
            pending = False
        if rel:
            cx += ax * p_val[q]
            cy += ay * p_val[q + 1]
        else:
            cx = ax * p_val[q] + bx
            cy = ay * p_val[q + 1] + by
        cl = p_line[q]
        cc = p_col[q]
        if not (abs(cx) <= MAX_COORD_PU and abs(cy) <= MAX_COORD_PU):  # NaN too
            bad = q if not abs(cx) <= MAX_COORD_PU else q + 1
            _fail(err, E_RANGE, p_line[bad], p_col[bad], bad, 1 if rel else 0)
            return k, cx, cy, cl, cc, pending, False
        if pen_down:
            k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, cx, cy, cl, cc, False, pen, write)
    return k, cx, cy, cl, cc, pending, True


@entry
@njit(cache=True, nogil=True)
def _interpret(c0, c1, c_code, c_line, c_col, c_p0, c_np, p_val, p_line, p_col, ist,
               o_x, o_y, o_line, o_col, o_start, o_pen, err, write, counts):
    """Pen-down points of commands ``c0`` to ``c1`` of a chunk; ``ist`` carries the plotter state between chunks
    (the ``I_`` slots).

    ``write``: record the points in the ``o_`` arrays (:data:`_POINT_DTYPES`); else only count them, each
    command's count in ``counts[ci - c0]`` (a circle's or an arc's chords are known before they are made).
    Returns the number of points.
    """
    pen_down = ist[I_DOWN] != 0
    rel = ist[I_REL] != 0
    pending = ist[I_PENDING] != 0
    cx, cy = ist[I_X], ist[I_Y]
    pen, cl, cc = int(ist[I_PEN]), int(ist[I_LINE]), int(ist[I_COL])
    k = 0
    for ci in range(c0, c1):
        k_before = k
        code = c_code[ci]
        p0 = c_p0[ci]
        m = c_np[ci]
        line, col = c_line[ci], c_col[ci]
        if code == C_IN or code == C_DF:  # parameters (a reset level some plotters take) are ignored
            if code == C_IN:
                pen_down = False
                pending = False
                cx, cy = _turn_to(0.0, ist, cx, cy)
            rel = False
            _reset(ist, code == C_IN)
        elif code == C_SP:
            v = p_val[p0] if m else 0.0
            if m > 1 or v < 0 or v != np.floor(v) or v > MAX_TOOL_NUMBER:
                _fail(err, E_SP, line, col, 0, 0)
                return k
            pen = int(v)
            pen_down = pending = False
        elif code == C_IP:
            if not _ip(m, p0, p_val, p_line, p_col, line, col, ist, err):
                return k
        elif code == C_SC:
            if not _sc(m, p0, p_val, line, col, ist, err):
                return k
        elif code == C_IW:
            if not _iw(m, p0, p_val, p_line, p_col, line, col, ist, err):
                return k
        elif code == C_CT or code == C_RO or code == C_IR:
            cx, cy, ok = _setting(code, m, p0, p_val, p_line, p_col, line, col, ist, cx, cy, err)
            if not ok:
                return k
        elif code == C_CI or code == C_AA or code == C_AR or code == C_AT or code == C_RT:
            k, cx, cy, pending, ok = _arc(code, m, p0, p_val, p_line, p_col, line, col, ist, cx, cy, pen_down, pending,
                                          pen, write, k, o_x, o_y, o_line, o_col, o_start, o_pen, err)
            if not ok:
                return k
            cl, cc = line, col
        elif _coord_cmd(code):
            if m % 2:
                _fail(err, E_ODD, p_line[p0 + m - 1], p_col[p0 + m - 1], m, 0)
                return k
            if code == C_PU:
                pen_down = False
                pending = False
            elif code == C_PD:
                if not pen_down:
                    k = _plot(ist, o_x, o_y, o_line, o_col, o_start, o_pen, k, cx, cy, cl if cl > 0 else line,
                              cc if cl > 0 else col, True, pen, write)
                    pen_down = True
                    pending = False
            elif code == C_PA:
                rel = False
            else:
                rel = True
            k, cx, cy, cl, cc, pending, ok = _pairs(p0, m, p_val, p_line, p_col, ist, cx, cy, cl, cc, pen_down, pending,
                                                    rel, pen, write, k, o_x, o_y, o_line, o_col, o_start, o_pen, err)
            if not ok:
                return k
        if not write:
            counts[ci - c0] = k - k_before
    ist[I_DOWN] = 1.0 if pen_down else 0.0
    ist[I_REL] = 1.0 if rel else 0.0
    ist[I_PENDING] = 1.0 if pending else 0.0
    ist[I_X] = cx
    ist[I_Y] = cy
    ist[I_PEN] = pen
    ist[I_LINE] = cl
    ist[I_COL] = cc
    return k


def _initial_state() -> np.ndarray:
    """The interpreter's state before the first command: pen up at plotter (0, 0), absolute moves, P1 and P2 at
    their defaults, scaling off, chord angles."""
    ist = np.zeros(N_IST, np.float64)
    ist[I_P1X], ist[I_P1Y] = DEFAULT_P1_PU
    ist[I_P2X], ist[I_P2Y] = DEFAULT_P2_PU
    ist[I_AX] = ist[I_AY] = 1.0
    return ist


@dataclass(frozen=True)
class HpglCommand:
    """One HPGL command as read from the file.

    Attributes:
        name: two-letter mnemonic in upper case (``"PA"``).
        params: numeric parameters, in order (``()`` for unknown commands, whose parameters are skipped).
        offset: byte offset of the mnemonic from the start of the file.
        line, column: where the mnemonic stands (1-based; columns count bytes).
        known: True for the commands `cam` interprets (:data:`KNOWN`).

    A coordinate command longer than a chunk comes as several commands with the same position.
    """

    name: str
    params: tuple[float, ...]
    offset: int
    line: int
    column: int
    known: bool


@dataclass
class _Block:
    n_cmd: int
    code: np.ndarray
    off: np.ndarray
    line: np.ndarray
    col: np.ndarray
    p0: np.ndarray
    np_: np.ndarray
    val: np.ndarray
    vline: np.ndarray
    vcol: np.ndarray


def _open(src: Source) -> tuple[BinaryIO, str, bool, Optional[int]]:
    """(binary-ish stream, source name, opened here, size in bytes or None)."""
    if isinstance(src, (str, os.PathLike)):
        p = Path(src)
        try:
            f = open(p, "rb")
        except FileNotFoundError:
            raise ParseError(f"{p}: file not found") from None
        except OSError as exc:
            raise ParseError(f"{p}: cannot read ({exc.strerror or exc})") from None
        try:
            size: Optional[int] = os.fstat(f.fileno()).st_size
        except OSError:
            size = None
        return f, str(p), True, size
    return src, str(getattr(src, "name", "<hpgl>")), False, None  # type: ignore[return-value]


def _token_text(buf: bytes, pos: int) -> str:
    end = pos
    while end < len(buf) and end - pos < 24 and buf[end] not in b",; \t\r\n":
        end += 1
    return buf[pos:max(end, pos + 1)].decode("latin-1")


def _chunks(src: Source, *, source: Optional[str] = None, progress: Optional[Progress] = None,
            chunk_bytes: int = CHUNK_BYTES) -> Iterator[_Block]:
    """Tokenized chunks of a file: each yields views into arrays reused by the next one.

    The tokenizer stops before a command that may continue in the next chunk and hands back
    where to resume; a coordinate command that fills a whole buffer is handed over pair by pair.
    """
    stream, name, opened, size = _open(src)
    name = source or name
    try:
        st = np.zeros(N_SLOTS, np.int64)
        st[S_LINE] = 1
        st[S_TERM] = 3
        cap = 0
        carry = b""
        done = 0
        ahead = stream.read(chunk_bytes)  # read one chunk ahead: the last one is parsed knowing it is the last
        while True:
            data = ahead
            if isinstance(data, str):
                data = data.encode("latin-1", "replace")
            ahead = stream.read(chunk_bytes) if data else b""
            final = not ahead
            done += len(data)
            buf = carry + data if carry else data
            if not buf:
                break
            need = len(buf) // 2 + 2
            if need > cap:
                cap = max(need, chunk_bytes // 2 + 2)
                cmds = _arrays(cap, _COMMAND_DTYPES)
                pars = _arrays(cap, _PARAM_DTYPES)
            base = int(st[S_BASE])
            arr = np.frombuffer(buf, np.uint8)
            nc = _tokenize(arr, final, st, *cmds, *pars)
            if st[S_ERR]:
                raise ParseError(_tokenize_message(st, buf, base, name))
            yield _Block(int(nc), *cmds, *pars)
            if progress is not None:
                progress(done, size)
            carry = buf[int(st[S_CONSUMED]):]
            if final:
                break
    finally:
        if opened:
            stream.close()


_TOKENIZE_ERRORS = {
    E_CHAR: "unexpected character {char}",
    E_MNEMONIC: "'{token}' is not an HPGL command (two letters expected)",
    E_NUMBER: "malformed number '{token}'",
    E_EMPTY: "empty parameter (a ',' with no number before it)",
    E_TRAIL: "'{mnemonic}': a number must follow ','",
    E_EOF_COMMA: "unterminated command '{mnemonic}' at the end of the file (a number must follow ',')",
    E_EOF_MNEMONIC: "unterminated command '{token}' at the end of the file",
    E_EOF_LABEL: "unterminated label 'LB' at the end of the file (no label terminator)",
    E_EOF_STRING: "unterminated quoted string in '{mnemonic}' at the end of the file",
}


def _tokenize_message(st: np.ndarray, buf: bytes, base: int, name: str) -> str:
    err = int(st[S_ERR])
    pos = int(st[S_ERRPOS]) - base
    text = _TOKENIZE_ERRORS[err].format(char=repr(buf[pos:pos + 1]), token=_token_text(buf, pos),
                                        mnemonic=_name(int(st[S_ERRAUX])))
    message = f"{name}:{int(st[S_ERRLINE])}:{int(st[S_ERRCOL])}: {text}"
    return message[:200] if err == E_CHAR else message


def iter_hpgl(src: Source, *, source: Optional[str] = None, progress: Optional[Progress] = None) -> Iterator[HpglCommand]:
    """The commands of an HPGL file, streamed (memory stays flat as the file grows).

    Args:
        src: a path, or an open binary (or text) file.
        source: the name used in messages (default: the path or the stream's name).
        progress: called as ``progress(bytes_read, total_bytes_or_None)`` after each chunk.

    Raises:
        ParseError: ``file:line:column: ...`` for malformed input (see the module docstring).

    >>> [(c.name, c.params, c.line) for c in iter_hpgl(io.BytesIO(b"IN;PU 10,-2.5\\nPD;LT;"))]
    [('IN', (), 1), ('PU', (10.0, -2.5), 1), ('PD', (), 2), ('LT', (), 2)]
    """
    for b in _chunks(src, source=source, progress=progress):
        for i in range(b.n_cmd):
            p0, m = int(b.p0[i]), int(b.np_[i])
            code = int(b.code[i])
            name = _name(code)
            yield HpglCommand(name, tuple(float(v) for v in b.val[p0:p0 + m]), int(b.off[i]), int(b.line[i]),
                              int(b.col[i]), name in KNOWN)


@dataclass
class PointBatch:
    """Consecutive pen-down points of a drawing, in file order: what the planner reads a batch at a time
    (:func:`point_batches` of a file, :meth:`HpglDrawing.point_batches` of a drawing held in memory).

    Attributes:
        x, y: ``(n,)`` float64 plotter units, HPGL frame (X right, Y up).
        line, col: ``(n,)`` int32 where in the file each point's coordinates stand.
        start: ``(n,)`` bool, the point starts a stroke (the pen went down there).
        pen: ``(n,)`` int32 the pen selected (``SP``) at each point; 0 = none selected.
    """

    x: np.ndarray
    y: np.ndarray
    line: np.ndarray
    col: np.ndarray
    start: np.ndarray
    pen: np.ndarray


class _Unknown:
    """First occurrence and count of each unknown mnemonic (bounded memory)."""

    def __init__(self) -> None:
        self.first: dict[int, tuple[int, int, int]] = {}
        self.count: dict[int, int] = {}

    def add(self, b: _Block) -> None:
        codes = b.code[:b.n_cmd]
        unknown = ~np.isin(codes, np.array([_code(m) for m in KNOWN]))
        if not unknown.any():
            return
        idx = np.flatnonzero(unknown)
        uniq, first, counts = np.unique(codes[idx], return_index=True, return_counts=True)
        for u, f, n in zip(uniq.tolist(), first.tolist(), counts.tolist()):
            if u not in self.first:
                j = idx[f]
                self.first[u] = (int(b.off[j]), int(b.line[j]), int(b.col[j]))
            self.count[u] = self.count.get(u, 0) + n

    def warnings(self, source: str) -> list[str]:
        out = []
        hints = {"LB": "label text is not cut", "CO": "comment", "PE": "encoded polyline is not cut",
                 "DT": "label terminator"}
        for code, (off, line, _col) in sorted(self.first.items(), key=lambda kv: kv[1][0]):
            name = _name(code)
            more = self.count[code] - 1
            hint = f"; {hints[name]}" if name in hints else ""
            out.append(f"{source}:{line}: unknown command '{name}' at byte {off} ignored{hint}"
                       + (f" ({more} more like it)" if more else ""))
        return out


def _raise(err: np.ndarray, b: _Block, name: str, scaled: bool) -> None:
    """The one-line :class:`ParseError` of the interpreter's error ``err``."""
    where = f"{name}:{int(err[1])}:{int(err[2])}"
    code, aux, aux2 = int(err[0]), int(err[3]), int(err[4])
    if code == E_SP:
        raise ParseError(f"{where}: 'SP' takes one pen number (a whole number 0..{MAX_TOOL_NUMBER})")
    limit = f"at most {MAX_COORD_PU:.0f} plotter units = {MAX_COORD_MM:g} mm either way"
    if code == E_RANGE:
        value = float(b.val[aux])
        number = f"{value:g}" if math.isfinite(value) else "of more than 300 digits"
        what = f"the pen position after the relative move {number} lies" if aux2 else f"the coordinate {number} is"
        raise ParseError(f"{where}: {what} out of range{' (scaled by SC)' if scaled else ''} ({limit})")
    mnemonic = _name(aux2)
    if code == E_ARGS:
        forms = {"SC": "none, 4 (xmin,xmax,ymin,ymax), 5 (with a type 0, 1 or 2) or 7 (type 1 with left,bottom)",
                 "IP": "none, 2 (P1) or 4 (P1 and P2)", "CI": "1 (radius) or 2 (with a chord angle)",
                 "AA": "3 (x,y centre, sweep) or 4 (with a chord angle)", "AR": "3 (dx,dy centre, sweep) or 4 "
                 "(with a chord angle)", "CT": "none, 0 (chord angles) or 1 (chord tolerance)",
                 "AT": "4 (xi,yi intermediate, xe,ye end) or 5 (with a chord angle)",
                 "RT": "4 (dxi,dyi intermediate, dxe,dye end) or 5 (with a chord angle)",
                 "RO": "none or 1 (an angle)", "IR": "none, 2 (P1) or 4 (P1 and P2)",
                 "IW": "none (no window) or 4 (xll,yll,xur,yur: the window's corners)"}
        raise ParseError(f"{where}: '{mnemonic}' takes {forms[mnemonic]} parameters, got {aux}")
    if code == E_VALUE:
        value = float(b.val[aux])
        what = "an angle of 0, 90, 180 or 270 degrees" if mnemonic == "RO" else "percentages 0..100"
        raise ParseError(f"{where}: '{mnemonic}' takes {what}, got {value:g}")
    if code == E_ARC_LINE:
        raise ParseError(f"{where}: '{mnemonic}' has its three points on one line with the intermediate point "
                         "outside the other two (a plotter draws two lines out to the page's edges); not cut")
    if code == E_SCALE:
        raise ParseError(f"{where}: 'SC' needs xmin != xmax and ymin != ymax (type 2: factors != 0), "
                         "left and bottom 0..100")
    if code == E_CHORDS:
        count = f"more than {aux:,}" if aux >= 4e18 else f"{aux:,}"
        raise ParseError(f"{where}: '{mnemonic}' would be drawn as {count} chords; at most {MAX_ARC_CHORDS:,} "
                         "chords a circle or arc (a smaller sweep, or a larger chord angle)")
    if code == E_ARC_RANGE:
        raise ParseError(f"{where}: the {'circle' if mnemonic == 'CI' else 'arc'} '{mnemonic}' reaches out of "
                         f"range ({limit})")
    raise ParseError(f"{where}: odd number of coordinates ({aux}): an x without its y")


def _points(src: Source, *, source: Optional[str], progress: Optional[Progress], unknown: _Unknown,
            counts: dict[int, int], chunk_bytes: int = CHUNK_BYTES) -> Iterator[PointBatch]:
    """Pen-down points per chunk (views into reused arrays; a chunk with circles and arcs may give several
    batches: their points are counted first, then made at most :data:`BATCH_POINTS` at a time)."""
    ist = _initial_state()
    err = np.zeros(5, np.int64)
    cap = 0
    name = source
    last_off = -1
    no_counts = np.zeros(1, np.int64)
    for b in _chunks(src, source=source, progress=progress, chunk_bytes=chunk_bytes):
        if name is None:
            name = source or (str(src) if isinstance(src, (str, os.PathLike)) else str(getattr(src, "name", "<hpgl>")))
        n_cmd = b.n_cmd
        if np.isin(b.code[:n_cmd], ARC_CODES).any() or ist[I_IW] or (b.code[:n_cmd] == C_IW).any():
            # circles and arcs, or clipping to a window (a segment may give two points): counted first
            per_cmd = np.zeros(max(n_cmd, 1), np.int64)
            probe = ist.copy()
            _interpret(0, n_cmd, b.code, b.line, b.col, b.p0, b.np_, b.val, b.vline, b.vcol, probe,
                       *_arrays(0, _POINT_DTYPES), err, False, per_cmd)
            if err[0]:
                _raise(err, b, name, bool(probe[I_SC]))
            ends = np.cumsum(per_cmd[:n_cmd])
            ranges = []
            c0 = 0
            while c0 < n_cmd:  # as many commands as make at most BATCH_POINTS points (one at least)
                base = int(ends[c0 - 1]) if c0 else 0
                c1 = max(c0 + 1, int(np.searchsorted(ends, base + BATCH_POINTS, side="right")))
                ranges.append((c0, c1, int(ends[c1 - 1]) - base))
                c0 = c1
        else:
            ranges = [(0, n_cmd, n_cmd + int(b.np_[:n_cmd].sum()) // 2 + 1)]
        for c0, c1, need in ranges:
            if need + 1 > cap:
                cap = max(need + 1, chunk_bytes // 4)
                out = _arrays(cap, _POINT_DTYPES)
            k = _interpret(c0, c1, b.code, b.line, b.col, b.p0, b.np_, b.val, b.vline, b.vcol, ist, *out, err, True,
                           no_counts)
            if err[0]:
                _raise(err, b, name, bool(ist[I_SC]))
            if len(ranges) > 1 and k == 0:
                continue
            yield PointBatch(*[a[:k] for a in out])
        unknown.add(b)
        offs = b.off[:n_cmd]
        fresh = offs != np.concatenate([[last_off], offs[:-1]])  # pieces of one long command share its offset
        if n_cmd:
            last_off = int(offs[-1])
        uniq, cnt = np.unique(b.code[:n_cmd][fresh], return_counts=True)
        for u, n in zip(uniq.tolist(), cnt.tolist()):
            counts[u] = counts.get(u, 0) + n


def point_batches(src: Source, *, source: Optional[str] = None,
                  chunk_bytes: int = CHUNK_BYTES) -> Iterator[PointBatch]:
    """The pen-down points of an HPGL file, a chunk of the file at a time (each batch its own arrays; chunks
    that draw nothing give none).  Memory stays flat as the file grows.

    Raises:
        ParseError: malformed input, ``file:line:column: ...``.
    """
    for pb in _points(src, source=_source_name(src, source), progress=None, unknown=_Unknown(), counts={},
                      chunk_bytes=chunk_bytes):
        if len(pb.x):
            yield PointBatch(*(a.copy() for a in (pb.x, pb.y, pb.line, pb.col, pb.start, pb.pen)))


def _source_name(src: Source, source: Optional[str]) -> str:
    if source:
        return source
    if isinstance(src, (str, os.PathLike)):
        return str(src)
    return str(getattr(src, "name", "<hpgl>"))


@dataclass
class HpglScan:
    """What a streamed pass over an HPGL file found (nothing per point is kept).

    Attributes:
        source: the file name.
        n_bytes: bytes read.
        command_counts: number of each command, by mnemonic.
        n_strokes, n_points: pen-down strokes and their points (each stroke's start included).
        pens: pen numbers that draw, in order of first use.
        extent_pu: ``(x_min, y_min, x_max, y_max)`` of the pen-down points in plotter units (HPGL frame,
            Y up), or None when nothing is drawn.
        warnings: unknown commands (byte offset and line).
    """

    source: str
    n_bytes: int
    command_counts: dict[str, int]
    n_strokes: int
    n_points: int
    pens: list[int]
    extent_pu: Optional[tuple[float, float, float, float]]
    warnings: list[str] = field(default_factory=list)

    def size_mm(self) -> tuple[float, float]:
        """(width, height) of the drawn extent in mm."""
        if self.extent_pu is None:
            return (0.0, 0.0)
        x0, y0, x1, y1 = self.extent_pu
        return ((x1 - x0) * PLOTTER_UNIT_MM, (y1 - y0) * PLOTTER_UNIT_MM)


def scan_hpgl(src: Source, *, source: Optional[str] = None, progress: Optional[Progress] = None,
              chunk_bytes: int = CHUNK_BYTES) -> HpglScan:
    """Stream an HPGL file once: counts, drawn extent, pens and warnings, in flat memory.

    Raises:
        ParseError: malformed input, ``file:line:column: ...``.

    >>> s = scan_hpgl(io.BytesIO(b"SP2;PU40,40;PD80,40;VS10;"), source="s.plt")
    >>> s.extent_pu, s.pens, s.n_points
    ((40.0, 40.0, 80.0, 40.0), [2], 2)
    """
    name = _source_name(src, source)
    unknown = _Unknown()
    counts: dict[int, int] = {}
    lo = np.array([np.inf, np.inf])
    hi = np.array([-np.inf, -np.inf])
    n_points = n_strokes = 0
    pens: list[int] = []
    n_bytes = [0]

    def track(done: int, total: Optional[int]) -> None:
        n_bytes[0] = done
        if progress is not None:
            progress(done, total)

    for pb in _points(src, source=name, progress=track, unknown=unknown, counts=counts, chunk_bytes=chunk_bytes):
        if len(pb.x) == 0:
            continue
        n_points += len(pb.x)
        n_strokes += int(np.count_nonzero(pb.start))
        lo = np.minimum(lo, [pb.x.min(), pb.y.min()])
        hi = np.maximum(hi, [pb.x.max(), pb.y.max()])
        if len(pens) < 256:
            used, first_use = np.unique(pb.pen[pb.start], return_index=True)
            for p in used[np.argsort(first_use)].tolist():
                if p not in pens:
                    pens.append(p)
    extent = None if n_points == 0 else (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    return HpglScan(name, n_bytes[0], {_name(c): n for c, n in sorted(counts.items())}, n_strokes, n_points,
                    pens, extent, unknown.warnings(name))


@dataclass
class HpglDrawing:
    """The pen-down strokes of an HPGL file, in plotter units.

    Attributes:
        points_pu: ``(N, 2)`` float64 ``(X, Y)`` plotter units, HPGL frame (X right, Y up), every stroke's
            points one after the other.
        stroke_start: ``(S,)`` int64 index in ``points_pu`` of each stroke's first point (where the pen went
            down); stroke k runs to ``stroke_start[k + 1]`` (or N).
        stroke_pen: ``(S,)`` int64 pen selected (``SP``) when each stroke began; 0 = none selected.
        point_line, point_col: ``(N,)`` int32 where in the file each point's coordinates stand.
        source: the file name; warnings: unknown commands; command_counts: commands by mnemonic.
    """

    points_pu: np.ndarray
    stroke_start: np.ndarray
    stroke_pen: np.ndarray
    point_line: np.ndarray
    point_col: np.ndarray
    source: str = "<hpgl>"
    warnings: list[str] = field(default_factory=list)
    command_counts: dict[str, int] = field(default_factory=dict)

    @property
    def n_strokes(self) -> int:
        return len(self.stroke_start)

    def strokes(self) -> Iterator[tuple[int, np.ndarray]]:
        """``(pen, (M, 2) points_pu)`` of each stroke, in file order."""
        ends = np.append(self.stroke_start[1:], len(self.points_pu))
        for pen, a, b in zip(self.stroke_pen.tolist(), self.stroke_start.tolist(), ends.tolist()):
            yield pen, self.points_pu[a:b]

    def extent_pu(self) -> Optional[tuple[float, float, float, float]]:
        """``(x_min, y_min, x_max, y_max)`` of the points (plotter units), None when empty."""
        if len(self.points_pu) == 0:
            return None
        lo, hi = column_range(self.points_pu)
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))

    def point_batches(self, batch_points: int) -> Iterator[PointBatch]:
        """The drawing's points as :class:`PointBatch` es of ``batch_points`` (the last: the rest), as
        :func:`point_batches` reads them from a file: views of the drawing's arrays."""
        n = len(self.points_pu)
        size = max(1, int(batch_points))
        start = np.zeros(n, bool)
        start[self.stroke_start] = True
        stroke = np.cumsum(start) - 1  # the stroke of each point
        pens = np.asarray(self.stroke_pen, np.int32)
        pen = np.where(stroke >= 0, pens[np.maximum(stroke, 0)] if len(pens) else 0, 0).astype(np.int32)
        for a in range(0, n, size):
            b = min(n, a + size)
            yield PointBatch(self.points_pu[a:b, 0], self.points_pu[a:b, 1], self.point_line[a:b],
                             self.point_col[a:b], start[a:b], pen[a:b])

    def summary(self) -> HpglScan:
        """What :func:`scan_hpgl` finds in the file the drawing was read from (``n_bytes`` 0: not known)."""
        pens = list(dict.fromkeys(int(p) for p in self.stroke_pen))
        return HpglScan(self.source, 0, dict(self.command_counts), self.n_strokes, len(self.points_pu), pens,
                        self.extent_pu(), list(self.warnings))


def load_hpgl(src: Source, *, source: Optional[str] = None, progress: Optional[Progress] = None,
              chunk_bytes: int = CHUNK_BYTES) -> HpglDrawing:
    """Read an HPGL file (streamed) into its pen-down strokes; see the module docstring for the dialect.

    Raises:
        ParseError: malformed input, ``file:line:column: ...``; a missing file.
    """
    name = _source_name(src, source)
    unknown = _Unknown()
    counts: dict[int, int] = {}
    parts: list[tuple[np.ndarray, ...]] = []
    for pb in _points(src, source=name, progress=progress, unknown=unknown, counts=counts, chunk_bytes=chunk_bytes):
        if len(pb.x):
            parts.append((np.column_stack([pb.x, pb.y]), pb.line.copy(), pb.col.copy(), pb.start.copy(), pb.pen.copy()))
    if parts:
        pts = np.concatenate([p[0] for p in parts])
        line = np.concatenate([p[1] for p in parts])
        col = np.concatenate([p[2] for p in parts])
        start = np.concatenate([p[3] for p in parts])
        pen = np.concatenate([p[4] for p in parts])
    else:
        pts = np.zeros((0, 2))
        line = col = pen = np.zeros(0, np.int32)
        start = np.zeros(0, bool)
    starts = np.flatnonzero(start).astype(np.int64)
    return HpglDrawing(pts, starts, pen[starts].astype(np.int64), line, col, name, unknown.warnings(name),
                       {_name(c): n for c, n in sorted(counts.items())})


def parse_hpgl(text: Union[str, bytes], *, source: str = "<hpgl>") -> HpglDrawing:
    """:func:`load_hpgl` of HPGL text held in memory."""
    data = text.encode("latin-1", "replace") if isinstance(text, str) else bytes(text)
    return load_hpgl(io.BytesIO(data), source=source)
