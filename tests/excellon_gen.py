"""Drill files for a known hole set, in the styles of several PCB programs (test data for cam.formats.excellon).

Each style writes the same kind of board (ICs, headers, connectors, vias and
mounting holes from a seeded RNG) the way one PCB program does: its header
comments, units, digit format, zero suppression, tool definition layout and
coordinate habits (modal coordinates, incremental moves, a tool selected
twice, ...).  A :class:`Generated` file carries the holes *as written* (mm,
board frame, after the file's rounding), so a reader must reproduce them
exactly, and the text gerbonara needs to read the same holes where it lacks a
feature (``gerbonara_text``, ``gerbonara_settings``).

Run as a script to (re)write ``samples/board.drl`` and the files in ``samples/drill/``::

    python tests/excellon_gen.py samples/board.drl samples/drill
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

MM_PER_INCH = 25.4


@dataclass
class Board:
    """Holes of a board design: ``holes_mm`` (N, 2) (x right, y up, mm, inside 0..size), ``tool`` (N,) index
    into ``diameters_mm``."""

    holes_mm: np.ndarray
    tool: np.ndarray
    diameters_mm: list[float]
    size_mm: tuple[float, float]
    kind: np.ndarray | None = None  # 0 via, 1 IC pin, 2 header, 3 connector, 4 mounting hole


def realistic_board(seed: int = 1, size_mm=(95.0, 75.0), n_ics: int = 6, n_headers: int = 4, n_vias: int = 120,
                    diameters_mm=(0.4, 0.8, 1.0, 1.3, 3.2)) -> Board:
    """A board with DIP ICs (0.8 mm), pin headers (1.0 mm), a few connectors (1.3 mm), vias (0.4 mm)
    and four mounting holes (3.2 mm) on a 0.127 mm placement grid; a few hundred holes by default.

    ``diameters_mm`` lists the tools (vias, IC pins, headers, connectors, mounting); a smaller list
    merges the later kinds into its last tool.
    """
    rng = np.random.default_rng(seed)
    w, h = size_mm
    holes, kinds = [], []
    grid = 0.127

    def snap(v):
        return np.round(np.asarray(v) / grid) * grid

    for x, y in [(4.0, 4.0), (w - 4.0, 4.0), (4.0, h - 4.0), (w - 4.0, h - 4.0)]:
        holes.append((x, y)); kinds.append(4)
    for _ in range(n_ics):
        pins = int(rng.choice([8, 14, 16, 20]))
        x0, y0 = snap(rng.uniform([10, 10], [w - 30, h - 15]))
        for i in range(pins // 2):
            holes.append((x0 + 2.54 * i, y0)); kinds.append(1)
        for i in range(pins // 2):
            holes.append((x0 + 2.54 * (pins // 2 - 1 - i), y0 + 7.62)); kinds.append(1)
    for _ in range(n_headers):
        n = int(rng.integers(3, 11))
        x0, y0 = snap(rng.uniform([8, 8], [w - 8, h - 8 - 2.54 * n]))
        for i in range(n):
            holes.append((x0, y0 + 2.54 * i)); kinds.append(2)
    for _ in range(2):
        x0, y0 = snap(rng.uniform([10, 10], [w - 20, h - 10]))
        for i in range(4):
            holes.append((x0 + 3.5 * i, y0)); kinds.append(3)
    for x, y in snap(rng.uniform([3, 3], [w - 3, h - 3], (n_vias, 2))):
        holes.append((x, y)); kinds.append(0)
    holes_mm = np.clip(np.array(holes, np.float64), 0.5, [w - 0.5, h - 0.5])
    kinds_arr = np.array(kinds, np.int64)
    return Board(holes_mm, np.minimum(kinds_arr, len(diameters_mm) - 1), list(diameters_mm), (w, h), kinds_arr)


@dataclass
class Generated:
    """One drill file and what it means.

    ``holes_mm`` (N, 2) and ``tool_of_hole`` (N,) in file order, ``tools`` number -> diameter mm as written;
    ``units``/``digits``/``zeros`` the format the file uses (``zeros`` in Excellon terms: LZ keeps leading
    zeros); ``states_format``: the file states everything needed to read it.  ``gerbonara_text`` is the text
    to give gerbonara (the same unless gerbonara lacks a feature this style uses) and ``gerbonara_settings``
    ``(unit, (int, frac), gerbonara_zeros)`` when gerbonara needs the format spelled out.
    """

    style: str
    text: str
    holes_mm: np.ndarray
    tool_of_hole: np.ndarray
    tools: dict[int, float]
    units: str
    digits: tuple[int, int]
    zeros: str
    states_format: bool = True
    gerbonara_text: str | None = None
    gerbonara_settings: tuple | None = None
    notes: list[str] = field(default_factory=list)


# -- numbers -----------------------------------------------------------------------------------------------

def _fmt(q: int, digits: tuple[int, int], mode: str) -> str:
    """Integer ``q`` (in units of 10^-frac) written as ``mode``: decimal, decimal_strip, TZ, LZ or full."""
    n_int, n_frac = digits
    sign = "-" if q < 0 else ""
    a = abs(int(q))
    if mode.startswith("decimal"):
        i, f = divmod(a, 10 ** n_frac)
        frac = str(f).rjust(n_frac, "0")
        if mode == "decimal_strip":
            frac = frac.rstrip("0") or "0"
        return f"{sign}{i}.{frac}"
    full = str(a).rjust(n_int + n_frac, "0")
    if len(full) > n_int + n_frac:
        raise ValueError(f"{q} does not fit {n_int}:{n_frac}")
    if mode == "TZ":  # leading zeros suppressed
        return sign + (full.lstrip("0") or "0")
    if mode == "LZ":  # trailing zeros suppressed
        return sign + (full.rstrip("0") or "0")
    return sign + full


def _quantize(v_mm: np.ndarray, units: str, n_frac: int) -> np.ndarray:
    scale = MM_PER_INCH if units == "inch" else 1.0
    return np.rint(np.asarray(v_mm) / scale * 10 ** n_frac).astype(np.int64)


def _to_mm(q: np.ndarray, units: str, n_frac: int) -> np.ndarray:
    scale = MM_PER_INCH if units == "inch" else 1.0
    return q * scale / 10 ** n_frac


# -- the generic writer --------------------------------------------------------------------------------------

def _write(style: str, board: Board, *, units: str, digits: tuple[int, int], mode: str, header: list[str],
           tool_def, tool_frac: int, body_start: list[str], end: list[str], origin_mm=(0.0, 0.0),
           y_sign: float = 1.0, modal: bool = False, incremental: bool = False, revisit: bool = False,
           def_in_body: bool = False, select_fmt="T{n}", zeros: str = "TZ", states_format: bool = True) -> Generated:
    n_frac = digits[1]
    xy_mm = np.column_stack([board.holes_mm[:, 0] + origin_mm[0], y_sign * board.holes_mm[:, 1] + origin_mm[1]])
    q = _quantize(xy_mm, units, n_frac)
    dia_q = {k + 1: int(round(d / (MM_PER_INCH if units == "inch" else 1.0) * 10 ** tool_frac))
             for k, d in enumerate(board.diameters_mm)}
    tools_mm = {n: float(_to_mm(np.int64(v), units, tool_frac)) for n, v in dia_q.items()}
    lines = list(header)
    if not def_in_body:
        lines += [tool_def(n, _fmt(v, (1, tool_frac), "decimal")) for n, v in dia_q.items()]
        lines.append("%")
    lines += body_start
    order, tools_out = [], []
    groups = []
    for n in dia_q:
        idx = np.flatnonzero(board.tool == n - 1)
        if revisit and len(idx) > 6 and n == 2:
            groups += [(n, idx[: len(idx) // 2]), ("later", n, idx[len(idx) // 2:])]
        else:
            groups.append((n, idx))
    groups = [g for g in groups if g[0] != "later"] + [g[1:] for g in groups if g[0] == "later"]
    last = [None, None]
    prev_q = np.zeros(2, np.int64)
    defined = set()
    for n, idx in groups:
        if len(idx) == 0:
            continue
        if def_in_body and n not in defined:
            lines.append(tool_def(n, _fmt(dia_q[n], (1, tool_frac), "decimal")))
            defined.add(n)
        else:
            lines.append(select_fmt.format(n=n))
        for i in idx:
            qx, qy = q[i]
            if incremental:
                dx, dy = qx - prev_q[0], qy - prev_q[1]
                words = ("X" + _fmt(dx, digits, mode) if dx else "") + ("Y" + _fmt(dy, digits, mode) if dy else "")
                if not words:
                    words = "X" + _fmt(0, digits, mode)
                prev_q = q[i]
            else:
                wx = "" if modal and last[0] == qx else "X" + _fmt(qx, digits, mode)
                wy = "" if modal and last[1] == qy else "Y" + _fmt(qy, digits, mode)
                words = wx + wy or "X" + _fmt(qx, digits, mode)
                last = [qx, qy]
            lines.append(words)
            order.append(i)
            tools_out.append(n)
    lines += end
    order_arr = np.array(order, np.int64)
    return Generated(
        style=style, text="\n".join(lines) + "\n", holes_mm=_to_mm(q[order_arr], units, n_frac),
        tool_of_hole=np.array(tools_out, np.int64), tools=tools_mm, units=units, digits=digits, zeros=zeros,
        states_format=states_format,
    )


def _kicad_header(units: str, fmt: str, zeros_line: str, version="7.0.10") -> list[str]:
    return ["M48", f"; DRILL file {{KiCad {version}}} date 2026-03-14T10:12:31+0100",
            f"; FORMAT={{{fmt}/ absolute / {units} / {zeros_line}}}",
            "; #@! TF.CreationDate,2026-03-14T10:12:31+01:00",
            f"; #@! TF.GenerationSoftware,Kicad,Pcbnew,{version}", "; #@! TF.FileFunction,Plated,1,2,PTH",
            "FMAT,2"]


def kicad_metric_decimal(board: Board) -> Generated:
    """KiCad's default: metric, decimal point, trailing zeros trimmed, Y negative (KiCad's page frame)."""
    g = _write("kicad_metric_decimal", board, units="metric", digits=(3, 3), mode="decimal_strip",
               header=_kicad_header("metric", "-:-", "decimal") + ["METRIC",
                                                                  "; #@! TA.AperFunction,Plated,PTH,ComponentDrill"],
               tool_def=lambda n, d: f"T{n}C{d}", tool_frac=3, body_start=["G90", "G05"], end=["T0", "M30"],
               origin_mm=(100.0, -150.0))
    return g


def kicad_inch_suppress_leading(board: Board) -> Generated:
    """KiCad, inch, 2:4, 'suppress leading zeros' (``INCH,TZ``)."""
    return _write("kicad_inch_suppress_leading", board, units="inch", digits=(2, 4), mode="TZ",
                  header=_kicad_header("inch", "2:4", "suppress leading zeros") + ["INCH,TZ"],
                  tool_def=lambda n, d: f"T{n}C{d}", tool_frac=4, body_start=["G90", "G05"], end=["T0", "M30"],
                  origin_mm=(20.0, -90.0), zeros="TZ")


def kicad_metric_suppress_trailing(board: Board) -> Generated:
    """KiCad, metric, 3:3, 'suppress trailing zeros' (``METRIC,LZ``): digits read from the left."""
    g = _write("kicad_metric_suppress_trailing", board, units="metric", digits=(3, 3), mode="LZ",
               header=_kicad_header("metric", "3:3", "suppress trailing zeros", "8.0.1") + ["METRIC,LZ"],
               tool_def=lambda n, d: f"T{n}C{d}", tool_frac=3, body_start=["G90", "G05"], end=["T0", "M30"],
               origin_mm=(110.0, -160.0), zeros="LZ")
    g.gerbonara_settings = ("metric", (3, 3), "trailing")  # gerbonara reads the format comment only for 'decimal'
    return g


def altium_inch_2_5(board: Board) -> Generated:
    """Altium: ``;FILE_FORMAT=2:5``, ``INCH,LZ``, ``T1F00S00C0.03150``, plating comments, modal coordinates."""
    header = ["M48", ";Layer_Color=9474304", ";FILE_FORMAT=2:5", "INCH,LZ", ";TYPE=PLATED"]
    n_tools = len(board.diameters_mm)

    def tool_def(n, d):
        return (";TYPE=NON_PLATED\n" if n == n_tools else "") + f"T{n}F00S00C{d}"

    g = _write("altium_inch_2_5", board, units="inch", digits=(2, 5), mode="LZ", header=header, tool_def=tool_def,
               tool_frac=5, body_start=[], end=["M30"], select_fmt="T{n:02d}", modal=True, zeros="LZ",
               origin_mm=(1.27, 1.27))
    return g


def eagle_inch_2_4(board: Board) -> Generated:
    """Old Eagle (``%`` then ``M48``, ``M72``): inch 2:4, leading zeros suppressed, format not stated."""
    g = _write("eagle_inch_2_4", board, units="inch", digits=(2, 4), mode="TZ", header=["%", "M48", "M72"],
               tool_def=lambda n, d: f"T{n:02d}C{d}", tool_frac=4, body_start=[], end=["M30"],
               select_fmt="T{n:02d}", zeros="TZ", states_format=False)
    return g


def eagle9_metric(board: Board) -> Generated:
    """Eagle 9: ``METRIC,TZ,000.000`` with ``ICI,OFF``, ``G90``, ``M71``; one tool selected twice."""
    header = ["M48", ";GenerationSoftware,Autodesk,EAGLE,9.6.2*%", ";CreationDate,2026-02-01T09:30:00Z*%", "FMAT,2",
              "ICI,OFF", "METRIC,TZ,000.000"]
    return _write("eagle9_metric", board, units="metric", digits=(3, 3), mode="TZ", header=header,
                  tool_def=lambda n, d: f"T{n}C{d}", tool_frac=3, body_start=["G90", "M71"], end=["M30"],
                  revisit=True, zeros="TZ")


def orcad_table_8_1(board: Board) -> Generated:
    """The OrCAD 9 Layout Plus file of seed 000 §8.1, Table 8-1: no header, ``%`` first, tools defined in the
    body with feed and speed (``T1C0.034F200S100``), six-digit inch coordinates (2:4, leading zeros kept)."""
    g = _write("orcad_table_8_1", board, units="inch", digits=(2, 4), mode="full", header=["%"],
               tool_def=lambda n, d: f"T{n}C{d}F200S100", tool_frac=3, body_start=[], end=["M30"],
               def_in_body=True, zeros="LZ", states_format=False)
    # gerbonara reads '%' as the header start and a definition does not select the tool: select explicitly
    g.gerbonara_text = "\n".join(
        line + (f"\nT{line[1:line.index('C')]}" if line.startswith("T") and "C" in line else "")
        for line in g.text.splitlines()) + "\n"
    g.gerbonara_settings = ("inch", (2, 4), "trailing")
    return g


def fritzing_inch(board: Board) -> Generated:
    """Fritzing: comments first, bare ``INCH``, six-digit coordinates (2:4, all zeros kept), ``T0`` at the end."""
    header = ["; NON-PLATED HOLES START AT T1", "; THROUGH (PLATED) HOLES START AT T2", "; FRITZING GENERATED",
              "M48", "INCH"]
    return _write("fritzing_inch", board, units="inch", digits=(2, 4), mode="full", header=header,
                  tool_def=lambda n, d: f"T{n}C{d}", tool_frac=6, body_start=[], end=["T0", "M30"],
                  zeros="TZ", states_format=False)


def metric_tz_implied(board: Board) -> Generated:
    """A plain ``METRIC,TZ`` file with implied decimals and no digit format (3:3 by convention)."""
    g = _write("metric_tz_implied", board, units="metric", digits=(3, 3), mode="TZ",
               header=["M48", "METRIC,TZ"], tool_def=lambda n, d: f"T{n}C{d}", tool_frac=2,
               body_start=["G05"], end=["M30"], zeros="TZ", states_format=False)
    g.gerbonara_settings = ("metric", (3, 3), "leading")
    return g


def incremental_g91(board: Board) -> Generated:
    """Metric decimal with ``G91``: each hole is a move from the previous one (modal axes left out)."""
    g = _write("incremental_g91", board, units="metric", digits=(3, 3), mode="decimal",
               header=["M48", "FMAT,2", "METRIC"], tool_def=lambda n, d: f"T{n:02d}C{d}", tool_frac=3,
               body_start=["G91", "G05"], end=["M30"], select_fmt="T{n:02d}", incremental=True)
    g.gerbonara_text = g.text.replace("\nG91\n", "\nICI,ON\n")  # gerbonara knows ICI, not G91
    return g


def fmat1_inch(board: Board) -> Generated:
    """Format 1 commands (``FMAT,1``): ``G81`` drill mode, ``M02`` end; ``INCH,TZ,00.0000``."""
    g = _write("fmat1_inch", board, units="inch", digits=(2, 4), mode="TZ",
               header=["M48", "FMAT,1", "INCH,TZ,00.0000"], tool_def=lambda n, d: f"T{n}C{d}", tool_frac=4,
               body_start=["G81"], end=["M02"], zeros="TZ")
    g.gerbonara_text = g.text.replace("FMAT,1", "FMAT,2").replace("\nG81\n", "\nG05\n").replace("\nM02\n", "\nM30\n")
    return g


MIL_MM = 0.0254


def apart(board: Board, clearance_mm: float = 0.15) -> Board:
    """``board`` without the holes (vias, in practice) that a real board could not have: each kept hole at least
    ``clearance_mm`` of copper from every hole kept before it (the board's own order: mounting holes first)."""
    keep: list[int] = []
    dia = np.asarray(board.diameters_mm)[board.tool]
    for i, (xy, d) in enumerate(zip(board.holes_mm, dia)):
        if keep:
            gap = np.hypot(*(board.holes_mm[keep] - xy).T) - 0.5 * (dia[keep] + d)
            if gap.min() < clearance_mm:
                continue
        keep.append(i)
    k = np.array(keep, np.int64)
    return Board(board.holes_mm[k], board.tool[k], list(board.diameters_mm), board.size_mm,
                 None if board.kind is None else board.kind[k])


def allegro_fixed_width(board: Board, *, digits: tuple[int, int] = (3, 5), name: str = "MinnowMax_RevA1_NCDRILL",
                        design: str = "MinnowMax_RevA1") -> Generated:
    """Cadence Allegro's NC drill tape as it writes it with ``nc_param.txt`` at ``FORMAT 3.5``, ``OUTPUT-UNITS
    ENGLISH`` and no zero suppression (issue #44 point 1): the paper-tape header comments (``;LEADER: 12``,
    ``;HEADER:``, ``;CODE  : ASCII``, ``;FILE  :``, ``;DESIGN:``), the tool sizes only in ``;T01 Holesize 1. =
    8.000000 Tolerance = ... PLATED MILS Quantity = 34`` comments (whole mils), ``%`` with no ``M48``, ``G90``,
    ``T01`` selections, every coordinate 8 digits wide (``X00130500Y00184500``), an axis equal to the last left
    out (``SUPPRESS-EQUAL YES``), ``M30``, CRLF line ends.  The format is in ``nc_param.txt`` only
    (:func:`allegro_nc_param`, :func:`allegro_ncdrill_log`): ``states_format`` is False."""
    mils = [int(round(d / MIL_MM)) for d in board.diameters_mm]
    sized = Board(board.holes_mm, board.tool, [m * MIL_MM for m in mils], board.size_mm, board.kind)
    counts = [int(np.count_nonzero(board.tool == k)) for k in range(len(mils))]
    header = [";LEADER: 12", ";HEADER:", ";CODE  : ASCII", f";FILE  : {name.lower()}.drl for ... layers TOP and BOTTOM",
              f";DESIGN: {design}.brd", ";DESCRIPTION: "]
    for k, (m, n) in enumerate(zip(mils, counts)):
        plating = "NON_PLATED" if m >= 100 else "PLATED"
        tol = "+3.000000/-3.000000" if m >= 100 else "+2.000000/-2.000000"
        header.append(f";T{k + 1:02d} Holesize {k + 1}. = {m:.6f} Tolerance = {tol} {plating} MILS Quantity = {n}")
    g = _write("allegro_fixed_width", sized, units="inch", digits=digits, mode="full", header=header,
               tool_def=lambda n, d: "", tool_frac=3, body_start=["G90"], end=["M30"], modal=True,
               select_fmt="T{n:02d}", def_in_body=False, zeros="TZ", states_format=False)
    lines = [ln for ln in g.text.splitlines() if ln != ""]  # no tool definitions: the sizes are comments
    g.text = "\r\n".join(lines) + "\r\n"
    g.tools = {k + 1: m * MIL_MM for k, m in enumerate(mils)}
    g.gerbonara_settings = ("inch", digits, "trailing")
    g.notes.append(name + ".drl")
    return g


def allegro_nc_param(digits: tuple[int, int] = (3, 5)) -> str:
    """The ``nc_param.txt`` Allegro writes beside :func:`allegro_fixed_width` (its NC Parameters form)."""
    rows = [("FORMAT", f"{digits[0]}.{digits[1]}"), ("OFFSETX", "0"), ("OFFSETY", "0"), ("FEEDRATE", "0"),
            ("COORDINATES", "ABSOLUTE"), ("OUTPUT-UNITS", "ENGLISH"), ("TOOL-ORDER", "INCREASING"),
            ("TOOL-SELECT", "YES"), ("REPEAT-CODES", "NO"), ("SUPPRESS-LEAD-ZEROES", "NO"),
            ("SUPPRESS-TRAIL-ZEROES", "NO"), ("SUPPRESS-EQUAL", "YES"), ("OPTIMIZE-DRILLING", "NO")]
    return "".join(f"{k:<26}{v}\r\n" for k, v in rows)


def allegro_ncdrill_log(g: Generated, digits: tuple[int, int] = (3, 5)) -> str:
    """The ``ncdrill.log`` Allegro writes with :func:`allegro_fixed_width`: a banner, the parameters used (the
    ``nc_param.txt`` lines, indented) and the tool table (``T01  1.  8.000000  +2.0/-2.0  PLATED  34``)."""
    lines = ["", "  Allegro PCB Editor NC drill log", "  --------------------------------",
             "  Design: MinnowMax_RevA1.brd", "  Date:   Tue Mar 11 10:15:02 2014", "", "  Parameters used:"]
    lines += ["    " + ln for ln in allegro_nc_param(digits).splitlines()]
    lines += ["", f"  Drill tape: {g.notes[0] if g.notes else 'ncdrill1.drl'}  for layers TOP and BOTTOM", "",
              "  Tool  Index  Holesize   Tolerance            Plating      Quantity"]
    for t, d in sorted(g.tools.items()):
        m = d / MIL_MM
        n = int(np.count_nonzero(g.tool_of_hole == t))
        plating = "NON_PLATED" if m >= 100 else "PLATED"
        lines.append(f"  T{t:02d}   {t}.   {m:.6f}   +2.000000/-2.000000  {plating:<12} {n}")
    lines += ["", "  NC drill complete."]
    return "\r\n".join(lines) + "\r\n"


def zuken_fdr(board: Board, *, digits: tuple[int, int] = (4, 4)) -> Generated:
    """Zuken CR-8000's ``.fdr`` drill data (issue #44 point 6): ``M48``, ``INCH,LZ``, ``ICI,OFF``, ``VER,1``,
    ``FMAT,2``, ``DETECT,ON``, ``ATC,ON``, tools ``T1C0.1260``, ``%``, ``M06`` before each ``T01``, every coordinate
    8 digits wide (4:4 inch, leading zeros kept: ``X00060236Y-00038189``), the board below the X axis, ending
    ``M06`` / ``T00`` / ``M00``.  The digits are in Zuken's ``.fdl`` log only: ``states_format`` is False."""
    header = ["M48", "INCH,LZ", "ICI,OFF", "VER,1", "FMAT,2", "DETECT,ON", "ATC,ON"]
    g = _write("zuken_fdr", board, units="inch", digits=digits, mode="full", header=header,
               tool_def=lambda n, d: f"T{n}C{d}", tool_frac=4, body_start=[], end=["M06", "T00", "M00"],
               select_fmt="M06\nT{n:02d}", y_sign=-1.0, origin_mm=(2.0, -1.0), zeros="LZ", states_format=False)
    g.gerbonara_settings = ("inch", digits, "trailing")
    return g


STYLES = {f.__name__: f for f in (
    kicad_metric_decimal, kicad_inch_suppress_leading, kicad_metric_suppress_trailing, altium_inch_2_5,
    eagle_inch_2_4, eagle9_metric, orcad_table_8_1, fritzing_inch, metric_tz_implied, incremental_g91, fmat1_inch,
)}
"""Style name -> writer(board) -> :class:`Generated`."""


def sample_board() -> Generated:
    """The committed ``samples/board.drl``: a KiCad-style metric board, three tools (0.8, 1.0, 3.2 mm),
    about 40 holes, inside 100 x 80 mm (board origin at the lower left corner)."""
    b = realistic_board(seed=SAMPLE_SEED, size_mm=(90.0, 70.0), n_ics=2, n_headers=2, n_vias=0)
    tool = np.array([0, 0, 1, 1, 2])[b.kind]  # IC pins 0.8, headers and connectors 1.0, mounting 3.2
    board = Board(b.holes_mm, tool, [0.8, 1.0, 3.2], b.size_mm, b.kind)
    return _write("kicad_metric_decimal", board, units="metric", digits=(3, 3), mode="decimal_strip",
                  header=_kicad_header("metric", "-:-", "decimal") + ["METRIC"],
                  tool_def=lambda n, d: f"T{n}C{d}", tool_frac=3, body_start=["G90", "G05"], end=["T0", "M30"])


SAMPLE_SEED = 11


DRILL_SAMPLE_STYLES = ("kicad_inch_suppress_leading", "altium_inch_2_5", "eagle_inch_2_4", "eagle9_metric",
                       "orcad_table_8_1", "fmat1_inch")
"""The styles shipped as ``samples/drill/<style>.drl`` (one small board each)."""


def drill_samples() -> dict[str, Generated]:
    """File name -> :class:`Generated` for ``samples/drill/``: a small five-tool board in several styles."""
    board = realistic_board(seed=2, size_mm=(60.0, 45.0), n_ics=1, n_headers=1, n_vias=10)
    return {f"{name}.drl": STYLES[name](board) for name in DRILL_SAMPLE_STYLES}


def _save(path: str, text: str) -> None:
    with open(path, "w", encoding="ascii", newline="\n") as fh:
        fh.write(text)


if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else "samples/board.drl"
    g = sample_board()
    _save(out, g.text)
    print(f"{out}: {len(g.holes_mm)} holes, tools {g.tools}")
    if len(sys.argv) > 2:  # python tests/excellon_gen.py samples/board.drl samples/drill
        for name, g in drill_samples().items():
            _save(f"{sys.argv[2]}/{name}", g.text)
            print(f"{sys.argv[2]}/{name}: {len(g.holes_mm)} holes")
