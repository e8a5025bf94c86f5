"""The machine's tool table (issue #47 point 4): the cutters kept with the machine, by number.

Each tool has a number (0..:data:`~cam.limits.MAX_TOOL_NUMBER`), a shape (``flat``, ``ball`` or ``v``), a diameter
in mm (a V bit's: the width of its tip, as "30 degrees 0.2 mm" engraving bits are sold), a V bit's included angle
and, where it is known, its length offset in mm.

Where the table lives: beside the machine file, ``mill.toml`` -> ``mill.tools.toml`` (:func:`tool_table_path`).
The tools are part of the machine as its axes are: the table travels, is backed up and is versioned with the
machine file, and one machine file driven on two ports (or a mock and the real machine) shares one rack.  The
state folder is for what changes with every run (where the tool stands) and belongs to the port; a machine with
no machine file (the built-in settings) keeps its table there, ``{state folder}/default.tools.toml``.  The file
is written atomically (:func:`cam.fileio.atomic_write_text`): a failed write leaves the old one.

How jobs use it (:func:`annotate_tool_change`, :func:`tool_table_warnings`):

* a drill file's tool numbers are the file's own (KiCad numbers each file's sizes from T1), so **the drill file's
  diameter wins**: the holes are drilled as the file says; the tool-change prompt names the table's tool of that
  number, and a table tool of another size is a warning (naming a table tool of the file's size, if there is one);
* a G-code program's ``T3 M6`` means tool 3 of the machine: the prompt names the table's T3 (a tool not in the
  table is a warning).

Frames and units: mm and degrees throughout.
"""
from __future__ import annotations

import math
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .errors import CamError
from .fileio import atomic_write_text, state_dir
from .limits import MAX_TOOL_NUMBER
from .tool import MAX_MM, MAX_V_ANGLE_DEG, MIN_MM, MIN_V_ANGLE_DEG, V_SHANK_MM, Tool

__all__ = ["TABLE_SHAPES", "MAX_LENGTH_MM", "TableTool", "ToolTable", "ToolTableError", "tool_table_path",
           "read_tool_table", "write_tool_table", "annotate_tool_change", "tool_table_warnings",
           "job_tool_warnings", "tool_from_mapping"]

TABLE_SHAPES = ("flat", "ball", "v")
"""The shapes a table tool may have."""
MAX_LENGTH_MM = 1000.0
"""The largest length offset accepted either way (mm)."""
_SHAPE_NAMES = {"flat": "flat end mill", "ball": "ball end mill", "v": "V bit"}


class ToolTableError(CamError):
    """A bad tool (the message, one line, names the field and what it may be) or an unreadable table file."""


def _number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ToolTableError(f"tool: {name} must be a number, got {str(value)[:40]!r}")
    try:
        number = float(value)
    except OverflowError:  # a whole number of thousands of digits
        raise ToolTableError(f"tool: {name} is out of range: {str(value)[:20]}...") from None
    if not math.isfinite(number):
        raise ToolTableError(f"tool: {name} must be a finite number, got {number}")
    return number


@dataclass(frozen=True)
class TableTool:
    """One tool of the table.

    Attributes:
        number: the tool number (``T3``), 0..:data:`~cam.limits.MAX_TOOL_NUMBER`.
        shape: ``"flat"``, ``"ball"`` or ``"v"``.
        diameter_mm: the cutting diameter; a V bit's tip width (0: sharp).
        angle_deg: a V bit's included angle (1..179 degrees); 0 for the others.
        length_mm: the length offset (G43's, mm); None: not known.
    """

    number: int
    shape: str
    diameter_mm: float
    angle_deg: float = 0.0
    length_mm: Optional[float] = None

    def __post_init__(self) -> None:
        n = self.number
        if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= MAX_TOOL_NUMBER:
            raise ToolTableError(f"tool: number must be a whole number 0..{MAX_TOOL_NUMBER}, got {str(n)[:40]!r}")
        if self.shape not in TABLE_SHAPES:
            raise ToolTableError(f"tool T{n}: shape must be one of {', '.join(TABLE_SHAPES)}, got "
                                 f"{str(self.shape)[:40]!r}")
        dia = _number(self.diameter_mm, "diameter_mm")
        low = 0.0 if self.shape == "v" else MIN_MM
        if not (low <= dia <= MAX_MM) or 0 < dia < MIN_MM:
            raise ToolTableError(f"tool T{n}: diameter must be {low:g}..{MAX_MM:g} mm"
                                 f"{' (a V bit tip: 0 sharp)' if self.shape == 'v' else ''}, got {dia:g}")
        angle = _number(self.angle_deg, "angle_deg")
        if self.shape == "v" and not MIN_V_ANGLE_DEG <= angle <= MAX_V_ANGLE_DEG:
            raise ToolTableError(f"tool T{n}: a V bit's angle must be {MIN_V_ANGLE_DEG:g}..{MAX_V_ANGLE_DEG:g} "
                                 f"degrees, got {angle:g}")
        if self.shape != "v" and angle:
            raise ToolTableError(f"tool T{n}: an angle is for a V bit only, not a {self.shape} one")
        if self.length_mm is not None and not abs(_number(self.length_mm, "length_mm")) <= MAX_LENGTH_MM:
            raise ToolTableError(f"tool T{n}: length must be -{MAX_LENGTH_MM:g}..{MAX_LENGTH_MM:g} mm, got "
                                 f"{self.length_mm:g}")
        if self.length_mm is not None:
            object.__setattr__(self, "length_mm", float(self.length_mm))
        object.__setattr__(self, "diameter_mm", dia)
        object.__setattr__(self, "angle_deg", angle)

    def describe(self) -> str:
        """One line naming the tool.

        >>> TableTool(3, "v", 0.2, 30, 12.3).describe()
        'T3: V bit 30 degrees, tip 0.2 mm, length 12.3 mm'
        >>> TableTool(1, "flat", 0.8).describe()
        'T1: flat end mill 0.8 mm'
        """
        size = (f"{self.angle_deg:g} degrees, tip {self.diameter_mm:g} mm" if self.shape == "v"
                else f"{self.diameter_mm:g} mm")
        length = "" if self.length_mm is None else f", length {self.length_mm:g} mm"
        return f"T{self.number}: {_SHAPE_NAMES[self.shape]} {size}{length}"

    def cutter(self) -> Tool:
        """The cutter's shape for the planners (:class:`cam.tool.Tool`): a V bit's diameter is its tip, its cone
        ending at a 1/8 inch shank (:data:`cam.tool.V_SHANK_MM`)."""
        if self.shape == "v":
            return Tool("v", diameter_mm=max(V_SHANK_MM, 2 * self.diameter_mm), angle_deg=self.angle_deg,
                        tip_mm=self.diameter_mm)
        return Tool(self.shape, diameter_mm=self.diameter_mm)

    def to_json(self) -> dict[str, Any]:
        """JSON-able fields, with ``text`` (:meth:`describe`)."""
        return {"number": self.number, "shape": self.shape, "diameter_mm": self.diameter_mm,
                "angle_deg": self.angle_deg, "length_mm": self.length_mm, "text": self.describe()}


@dataclass(frozen=True)
class ToolTable:
    """The tools by number (a new table for every change: :meth:`with_tool`, :meth:`without`)."""

    tools: Mapping[int, TableTool] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.tools)

    def get(self, number: int) -> Optional[TableTool]:
        """Tool ``number``, or None."""
        return self.tools.get(number)

    def sorted(self) -> list[TableTool]:
        """The tools by number."""
        return [self.tools[k] for k in sorted(self.tools)]

    def with_tool(self, tool: TableTool) -> "ToolTable":
        """The table with ``tool`` set (replacing the tool of its number)."""
        return ToolTable({**self.tools, tool.number: tool})

    def without(self, number: int) -> "ToolTable":
        """The table without tool ``number`` (ToolTableError, one line, when there is none)."""
        if number not in self.tools:
            have = ", ".join(f"T{k}" for k in sorted(self.tools)) or "none"
            raise ToolTableError(f"no tool T{number} in the tool table (it has {have})")
        return ToolTable({k: t for k, t in self.tools.items() if k != number})

    def of_diameter(self, diameter_mm: float, tolerance_mm: float = 0.0005) -> Optional[TableTool]:
        """The first tool (by number) whose diameter is ``diameter_mm`` within ``tolerance_mm``, or None."""
        return next((t for t in self.sorted() if abs(t.diameter_mm - diameter_mm) <= tolerance_mm), None)

    def to_toml(self, machine: str = "") -> str:
        """The file's text: a ``[tool.N]`` table per tool."""
        lines = [f"# cam's tool table{' of ' + machine if machine else ''}: cam tools, or the page's Tools section",
                 "# (a V bit's diameter_mm is its tip; length_mm is the length offset, left out when not known)"]
        for t in self.sorted():
            lines += ["", f"[tool.{t.number}]", f'shape = "{t.shape}"', f"diameter_mm = {t.diameter_mm!r}"]
            if t.shape == "v":
                lines.append(f"angle_deg = {t.angle_deg!r}")
            if t.length_mm is not None:
                lines.append(f"length_mm = {float(t.length_mm)!r}")
        return "\n".join(lines) + "\n"


def tool_table_path(machine_file: Optional[str | os.PathLike], environ: Optional[Mapping[str, str]] = None) -> Path:
    """Where the tool table of ``machine_file`` is kept: beside it, ``NAME.tools.toml`` for ``NAME.toml``; with
    no machine file (None or ""), ``{state folder}/default.tools.toml`` (:func:`cam.fileio.state_dir`).

    >>> tool_table_path("shop/mill.toml").as_posix()
    'shop/mill.tools.toml'
    >>> tool_table_path(None, {"XDG_STATE_HOME": "/s"}).as_posix()
    '/s/cam/default.tools.toml'
    """
    if machine_file:
        p = Path(machine_file)
        return p.with_name(f"{p.stem}.tools.toml")
    return state_dir(environ) / "default.tools.toml"


def _tool_of(key: str, values: Any, where: str) -> TableTool:
    if not isinstance(values, dict):
        raise ToolTableError(f"{where}: [tool.{key}] must be a table")
    unknown = set(values) - {"shape", "diameter_mm", "angle_deg", "length_mm"}
    if unknown:
        raise ToolTableError(f"{where}: [tool.{key}]: unknown key '{sorted(unknown)[0]}' (known: shape, "
                             "diameter_mm, angle_deg, length_mm)")
    if not key.isdigit():
        raise ToolTableError(f"{where}: [tool.{key}]: a tool number must be a whole number")
    try:
        return TableTool(int(key), values.get("shape", ""), values.get("diameter_mm", 0.0),
                         values.get("angle_deg", 0.0), values.get("length_mm"))
    except ToolTableError as exc:
        raise ToolTableError(f"{where}: {exc}") from None


def read_tool_table(path: str | os.PathLike) -> ToolTable:
    """The table in ``path`` (a missing file: an empty table).

    Raises:
        ToolTableError: the file cannot be read or is not a tool table (one line naming the file).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        return ToolTable()
    except (OSError, UnicodeDecodeError) as exc:
        raise ToolTableError(f"{p}: cannot read the tool table ({exc})") from None
    try:
        values = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise ToolTableError(f"{p}: not a valid tool table ({str(exc).splitlines()[0]})") from None
    extra = set(values) - {"tool"}
    if extra:
        raise ToolTableError(f"{p}: unknown key '{sorted(extra)[0]}' (a tool table has [tool.N] tables only)")
    tools = values.get("tool", {})
    if not isinstance(tools, dict):
        raise ToolTableError(f"{p}: 'tool' must be tables [tool.N]")
    return ToolTable({t.number: t for t in (_tool_of(k, v, str(p)) for k, v in tools.items())})


def write_tool_table(path: str | os.PathLike, table: ToolTable, machine: str = "") -> Path:
    """Write ``table`` to ``path`` atomically (its folder made when missing); returns the path."""
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ToolTableError(f"{p}: cannot make its folder ({exc.strerror or exc})") from None
    atomic_write_text(p, table.to_toml(machine))
    return p


_DRILL_NOTE = re.compile(r"^tool change: T(\d+)(?: = T\d+)* (\d+(?:\.\d+)?) mm")
"""A drill file's tool-change prompt (:mod:`cam.job.drill`): ``tool change: T3 0.800 mm (12 holes)``."""
_GCODE_NOTE = re.compile(r"^tool change: T(\d+) \(line \d+\)")
"""A G-code program's ``M6`` prompt (:mod:`cam.formats.gcode`): ``tool change: T3 (line 12)``."""


def _drill_says(table: ToolTable, number: int, file_mm: float) -> tuple[str, Optional[str]]:
    """(what the prompt adds, the warning or None) for a drill file's tool ``number`` of ``file_mm``."""
    tool = table.get(number)
    same = table.of_diameter(file_mm)
    other = f"; the table's {same.describe()} has that size" if same is not None and same is not tool else ""
    if tool is None:
        return (f" [tool table: no T{number}{other}]", None)
    if abs(tool.diameter_mm - file_mm) <= 0.0005:
        return (f" [tool table {tool.describe()}]", None)
    warning = (f"T{number}: the drill file's {file_mm:g} mm wins (its holes are drilled at that size), not the tool "
               f"table's {tool.describe()}: put in a {file_mm:g} mm tool at the prompt{other}")
    return (f" [tool table {tool.describe()}: NOT the file's {file_mm:g} mm, put in a {file_mm:g} mm tool{other}]",
            warning)


def annotate_tool_change(note: str, table: ToolTable) -> str:
    """A tool-change prompt with the table's tool named (``note`` unchanged when it is no tool change of a
    drill file or a G-code program, or the table is empty).

    >>> t = ToolTable().with_tool(TableTool(3, "flat", 0.8))
    >>> annotate_tool_change("tool change: T3 0.800 mm (12 holes)", t)
    'tool change: T3 0.800 mm (12 holes) [tool table T3: flat end mill 0.8 mm]'
    >>> annotate_tool_change("tool change: T3 (line 7)", t)
    'tool change: T3 (line 7) [tool table T3: flat end mill 0.8 mm]'
    """
    if not len(table):
        return note
    m = _DRILL_NOTE.match(note)
    if m is not None:
        return note + _drill_says(table, int(m.group(1)), float(m.group(2)))[0]
    m = _GCODE_NOTE.match(note)
    if m is not None:
        tool = table.get(int(m.group(1)))
        return note + (f" [tool table {tool.describe()}]" if tool is not None
                       else f" [tool table: no T{m.group(1)}]")
    return note


def tool_table_warnings(tool_changes: Iterable[str], table: ToolTable,
                        drill_tools: Iterable[tuple[int, float, int]] = ()) -> list[str]:
    """The warnings of a job planned for a machine with ``table`` (none for an empty table): a drill file's tool
    (``drill_tools``: the plan's ``tool_sequence``, ``(tool, diameter_mm, holes)``) whose table tool has another
    size (the file's size wins), a G-code program's tool change to a tool the table does not have.

    >>> t = ToolTable().with_tool(TableTool(3, "v", 0.2, 30))
    >>> tool_table_warnings([], t, [(3, 0.8, 12)])[0][:40]
    "T3: the drill file's 0.8 mm wins (its ho"
    >>> tool_table_warnings(["tool change: T4 (line 9)"], t)
    ['T4 M6 (line 9): tool T4 is not in the tool table (cam tools set 4 ...)']
    """
    if not len(table):
        return []
    out: list[str] = []
    for number, dia, _ in drill_tools:
        warning = _drill_says(table, int(number), float(dia))[1]
        if warning is not None and warning not in out:
            out.append(warning)
    for note in tool_changes:  # only a program's tool changes read "T4 (line 9)"
        m = _GCODE_NOTE.match(note)
        if m is not None and table.get(int(m.group(1))) is None:
            line = note.split("(", 1)[1].rstrip(")")
            text = f"T{m.group(1)} M6 ({line}): tool T{m.group(1)} is not in the tool table " \
                   f"(cam tools set {m.group(1)} ...)"
            if text not in out:
                out.append(text)
    return out


def job_tool_warnings(job: Any, table: ToolTable) -> list[str]:
    """:func:`tool_table_warnings` of a prepared job (:class:`cam.kinds.jobs.PreparedJob`: its kind, tool changes and
    drill plan), those it has not yet."""
    plan = getattr(job, "drill_plan", None)
    found = tool_table_warnings(job.tool_changes, table, plan.tool_sequence if plan is not None else ())
    return [w for w in found if w not in job.warnings]


def tool_from_mapping(values: Any) -> TableTool:
    """A tool from a form or JSON: ``number``, ``shape``, ``diameter_mm``, ``angle_deg`` (default 0) and
    ``length_mm`` (None or ``""``: not known), each number given as a number or as its text.

    >>> tool_from_mapping({"number": "3", "shape": "v", "diameter_mm": "0.2", "angle_deg": 30, "length_mm": ""})
    TableTool(number=3, shape='v', diameter_mm=0.2, angle_deg=30.0, length_mm=None)

    Raises:
        ToolTableError: not an object, a field missing or bad (one line naming it).
    """
    if not isinstance(values, Mapping):
        raise ToolTableError("a tool must be an object: number, shape, diameter_mm, angle_deg, length_mm")
    unknown = set(values) - {"number", "shape", "diameter_mm", "angle_deg", "length_mm"}
    if unknown:
        raise ToolTableError(f"tool: unknown field {sorted(unknown)[0][:40]!r} (known: number, shape, diameter_mm, "
                             "angle_deg, length_mm)")

    def num(name: str, default: Any = None) -> Any:
        v = values.get(name, default)
        if isinstance(v, str):
            if not v.strip():
                return default
            try:
                return float(v)
            except ValueError:
                raise ToolTableError(f"tool: {name} must be a number, got {v[:40]!r}") from None
        return v

    if values.get("number") in (None, ""):
        raise ToolTableError("tool: number is missing (the tool number, T3: 3)")
    n = num("number")
    if isinstance(n, float) and n.is_integer():
        n = int(n)
    if "diameter_mm" not in values or values.get("diameter_mm") in (None, ""):
        raise ToolTableError("tool: diameter_mm is missing (mm; a V bit's tip, 0 sharp)")
    return TableTool(n, values.get("shape", ""), num("diameter_mm"), num("angle_deg", 0.0) or 0.0,
                     num("length_mm"))
