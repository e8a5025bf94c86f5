"""The job options, declared once: name, flag, type, unit, range, the kinds it applies to, defaults and help.

Issue #28 point 6.  Each :class:`Option` in :data:`JOB_OPTIONS` is the one
declaration of a setting of a job.  From it come:

* the fields of :class:`cam.kinds.jobs.JobOptions` (same names, same defaults)
  and their range checks (:meth:`JobOptions.checked`);
* the command-line flags of ``cam drill``, ``export``, ``preview`` (and the
  shared ones of ``info``, ``digitize`` and ``trace``): :mod:`cam.cli.parser`;
* which option applies to which file kind, for the command line's checks
  (:mod:`cam.cli.checks`), :meth:`JobOptions.check_kind` and the page: an
  option names traits (``pixels``, ``placed``, ``holes``, ``strokes``,
  ``layers``, ``every``, or a kind's own name) and each kind's module says
  its traits (:mod:`cam.kinds`), so a new kind takes the options of what it
  is with no line here;
* the value an option takes on a kind when it is not given, declared by trait
  (:attr:`Option.trait_defaults`: a drill file's 2.0 mm cut depth, a pen
  stroke's 0.5 mm): the planners' defaults, ``--help``, the page and
  :func:`cam.kinds.kind_defaults` read it;
* the web page's form: ``GET /api/options`` serves :func:`schema_json`, and ``app.js`` makes a field of
  each option from it (label, unit, range, help, the kinds it shows for, under its :attr:`Option.group`): a
  new option here is on the page with no page code.

The rules between options (one depth, a scale or a size to fit, the options that go with ``--heightmap``,
``--trace`` or ``--level`` only) are declared once too, as :data:`RULES`, and asked through one function,
:func:`broken_rule`: by the command line (:func:`cam.cli.checks.check_args`, naming flags),
:meth:`cam.kinds.jobs.JobOptions.checked` (the API and the page's server, naming options), the planners
(:func:`keyword_error`, naming their keywords) and the page itself (each option's record in :func:`schema_json`
carries its rules; ``app.js`` refuses a form that breaks one before sending it).  Ranges likewise have one check,
:func:`check_range`.

One name for one setting: the field is ``cut_depth_mm``, the flag
``--cut-depth`` (the field without its unit, ``_`` as ``-``), and the
planners, readers and the tracer take the field's name as their keyword, in
the field's unit (``plan(stepdown_mm=)``, ``load_excellon(excellon_digits=)``,
``trace(trace_min_length_px=)``; a planner that works in other units converts
in one place, e.g. :func:`cam.job.drawing_stream.stepdown_px_of`).  A flag
renamed so keeps its old spelling as a hidden alias, accepted but not shown in
``--help`` (``--excellon-format`` of ``--excellon-digits``; ``cam trace``'s
``--min-length`` and ``--fill``).  ``tests/test_options_schema.py`` fails on a
planner keyword or a shown flag that is a second name of an option.

Standard library and :mod:`cam.limits` only: ``cam --help`` loads it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

from .limits import DEFAULT_GCODE_LINES, MAX_GCODE_LINES

__all__ = [
    "Option", "JOB_OPTIONS", "OPTIONS", "OPTION_OF_DEST", "schema_json", "check_range", "degenerate",
    "Rule", "RULES", "RULE_KINDS", "broken_rule", "given", "keyword_error", "own_zero",
    "MAX_MM", "MAX_PX", "MAX_DEPTH_PX", "TYPES", "GROUPS",
]

MAX_MM = 10_000.0
"""The largest length in mm an option takes (10 m)."""
MAX_PX = 10**9
"""The largest pixel offset an option takes, either way (no machine has that much travel)."""
MAX_DEPTH_PX = 1_000_000
"""The deepest depth in Z pixels an option may ask for (the travel refuses far less)."""

TYPES = ("whole", "number", "wholes", "numbers", "choice", "flag", "text", "tool", "points", "digits", "size",
         "paths")
"""What an option's value is: a whole number, a number, a list of them (``count`` long, or any length), one of
``choices``, on/off, text, a cutter spec (:func:`cam.tool.parse_tool`), x,y points, Excellon ``I:F`` digit
counts, a ``WxH`` size, folders."""

_DRAWINGS = frozenset({"pixels"})
_VECTORS = frozenset({"placed"})
_EVERY = frozenset({"every"})
_STROKES = frozenset({"strokes"})
_LAYERS = frozenset({"layers"})
_HOLES = frozenset({"holes"})
# what an option applies to is said by traits (cam.kinds.TRAITS: every, pixels, placed, holes, strokes, layers)
# or a kind's own name; each kind module says its traits, so a new kind gets its options with no line here


@dataclass(frozen=True)
class Option:
    """One job option.

    Attributes:
        name: the :class:`cam.kinds.jobs.JobOptions` field and the planners' keyword (units in the name).
        flag: the command-line flag (``--cut-depth``); its argparse dest is :attr:`dest`.
        type: one of :data:`TYPES`.
        unit: what the numbers count ("mm", "px", "Z px", "" for none).
        traits: what it applies to: kinds having one of these traits (:data:`cam.kinds.TRAITS`) or names.
        default: the JobOptions default (None: the kind's own default, or not given).
        help: what it does, for ``--help`` and the page.
        lo, hi: the range of each number (None: no bound); lo_open: ``lo`` itself is refused (> lo).
        count: how many numbers a list takes (None: one or more).
        choices: the values a "choice" takes.
        metavar: the value's name in ``--help``.
        web: whether the page may set it (False: it names files on the machine that runs `cam`).
        aliases: older flags still accepted for it, hidden from ``--help`` (``--excellon-format``).
        group: what it is about, the heading of its fields on the page (:data:`GROUPS`).
        trait_defaults: ``((trait, value), ...)``: the value it takes, when not given, on a kind having the
            trait (the first that matches; the cut depth of drill files and of pen strokes), declared here once:
            the planners' defaults, ``--help``, the page and :func:`cam.kinds.kind_defaults` read it.
        kinds: the kinds it applies to, filled in by :func:`cam.kinds.job_options` from the kinds' traits.
    """

    name: str
    flag: str
    type: str
    unit: str
    traits: frozenset[str]
    default: Any
    help: str
    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    count: Optional[int] = None
    choices: tuple[str, ...] = ()
    metavar: Optional[str] = None
    web: bool = True
    aliases: tuple[str, ...] = ()
    group: str = "Other"
    trait_defaults: tuple[tuple[str, Any], ...] = ()
    kinds: frozenset[str] = frozenset()

    def default_for(self, traits: "frozenset[str] | set[str]") -> Any:
        """The value it takes on a kind with ``traits`` when not given: its first matching
        :attr:`trait_defaults`, else :attr:`default`.

        >>> OPTIONS["cut_depth_mm"].default_for({"holes"}), OPTIONS["cut_depth_mm"].default_for({"pixels"})
        (2.0, None)
        """
        return next((value for trait, value in self.trait_defaults if trait in traits), self.default)

    @property
    def label(self) -> str:
        """The option's name in words, without its unit, for the page (``cut_depth_mm`` -> "Cut depth")."""
        words = self.name.removesuffix("_mm").removesuffix("_px").replace("_", " ")
        return words[:1].upper() + words[1:]

    @property
    def dest(self) -> str:
        """The argparse dest of :attr:`flag` (``--cut-depth`` -> ``cut_depth``)."""
        return self.flag.lstrip("-").replace("-", "_")

    def range_text(self) -> str:
        """The range in words, the same in the CLI's and JobOptions' errors: ``1..1000``, ``> 0 and at most 10000``."""
        if self.lo is None or self.hi is None:
            return ""
        if self.lo_open:
            return f"> {self.lo:g} and at most {self.hi:g}"
        if self.type in ("whole", "wholes", "points", "digits"):
            return f"{int(self.lo)}..{int(self.hi)}"
        return f"{self.lo:g}..{self.hi:g}"

    def in_range(self, value: float) -> bool:
        """Whether one number lies in the range (finite, and within lo..hi; an integer too large for a float is
        not)."""
        value = _as_float(value)
        if not math.isfinite(value):
            return False
        if self.lo is not None and (value <= self.lo if self.lo_open else value < self.lo):
            return False
        return self.hi is None or value <= self.hi


def _as_float(value: Any) -> float:
    """``value`` as a float; an integer too large for one (10^400) as infinity (out of every range)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf


def check_range(option: Option, value: Any) -> Optional[str]:
    """Why ``value`` (a number, or a list or list of lists of them) is out of ``option``'s range, or None."""
    if value is None or option.lo is None or option.type not in ("whole", "number", "wholes", "numbers", "points",
                                                                  "digits", "size"):
        return None
    flat: list[float] = []
    stack = [value]
    while stack:
        v = stack.pop()
        v = v.tolist() if hasattr(v, "tolist") else v  # a numpy array or number, as a planner may be given
        if isinstance(v, (list, tuple)):
            stack.extend(v)
        else:
            flat.append(v)
    if all(option.in_range(v) for v in flat):
        return None
    unit = f" {option.unit}" if option.unit else ""
    each = "" if option.type in ("whole", "number") else "each value "
    return f"{each}must be {option.range_text()}{unit}"


def _opt(name: str, flag: str, type: str, unit: str, traits: frozenset[str] | set[str], default: Any, help: str,
         **more: Any) -> Option:
    return Option(name, flag, type, unit, frozenset(traits), default, help, **more)


def _in(group: str) -> Callable[..., Option]:
    """:func:`_opt` for the options of one group (what they are about: the page's headings)."""
    return lambda *args, **more: _opt(*args, group=group, **more)


GROUPS = ("Drawing", "Depth and placement", "Drill file", "Reading the file", "G-code", "SVG, DXF and HPGL",
          "Sketch or photo", "Cutter", "Height map", "Levelling")
"""What the options are about, in the page's order (each :attr:`Option.group` is one of them)."""
_drawing, _placing, _drill, _reading, _gcode, _vector, _sketch, _cutter, _relief, _level = map(_in, GROUPS)


JOB_OPTIONS: tuple[Option, ...] = (
    # drawings and digitized matrices, in pixels
    _drawing("depth", "--depth", "wholes", "Z px", _DRAWINGS, None,
         "cutting depth in Z pixels: one value for all objects, or one per object (0 skips one); default 10; on a "
         "3D drawing one value cuts every layer at N (a flat-bottomed pocket) instead of a profile",
         lo=0, hi=MAX_DEPTH_PX, metavar="N|N1,N2,..."),
    _drawing("passes", "--passes", "whole", "", _DRAWINGS, 1,
         "Repeat Drill: cut in N passes of increasing depth (default 1)", lo=1, hi=1000, metavar="N"),
    _drawing("start", "--start", "choice", "", {"drawing"}, "top",
         "2D: where each object starts: first pixel in scan order (top), nearest the tool (min-distance), or "
         "nearest the origin, the thesis's Min Distance rule (thesis)",
         choices=("top", "min-distance", "thesis")),
    _drawing("start_at", "--start-at", "wholes", "px", _DRAWINGS, (0, 0, 0),
         "offset the whole job by this many pixels", lo=-MAX_PX, hi=MAX_PX, count=3, metavar="X,Y,Z"),
    _drawing("pause_at", "--pause-at", "points", "px", _DRAWINGS, (),
         "pause when the tool reaches this drawing point (repeatable); Enter resumes",
         lo=-MAX_PX, hi=MAX_PX, count=2, metavar="X,Y"),
    _drawing("profile", "--profile", "text", "", _DRAWINGS, None,
         "profile drawing (blue curve over black axes, red origin) or CSV of depths per layer", metavar="PROFILE"),
    _drawing("profile_expr", "--profile-expr", "text", "", _DRAWINGS, None,
         "depth of layer k as arithmetic in k and n (layers), e.g. '30*sqrt(1-((n-k)/n)**2)'", metavar="EXPR"),
    # depths and heights in mm, one name on every kind
    _placing("cut_depth_mm", "--cut-depth", "number", "mm", _DRAWINGS | _VECTORS, None,
         "cutting depth below the surface: drill files (default 2.0: through a 1.6 mm board), HPGL, SVG and DXF "
         "pen-down depth (default 0.5), or a drawing's depth for every object instead of --depth",
         lo=0.0, hi=MAX_MM, lo_open=True, metavar="MM", trait_defaults=(("holes", 2.0), ("strokes", 0.5))),
    _placing("travel_height_mm", "--travel-height", "number", "mm", _VECTORS, None,
         "height above the surface between cuts (default 1.0): drill files, HPGL, SVG, DXF, and every file "
         "'cam export' writes; 0 (at the surface) needs --allow-surface-travel", lo=0.0, hi=MAX_MM, metavar="MM",
         trait_defaults=(("placed", 1.0),)),
    _placing("allow_surface_travel", "--allow-surface-travel", "flag", "", _VECTORS, False,
         "accept --travel-height 0: the tool travels between cuts touching the surface (a pen or a drag knife), "
         "which on a cutter scratches the work"),
    _placing("origin", "--origin", "choice", "", _DRAWINGS | _VECTORS, None,
         "which point of the job goes to the active work zero (cam zero): file (the file's own zero: a drawing's "
         "top-left pixel, a drill, HPGL, SVG or DXF file's 0,0), upper-left, lower-left or center of what is cut; "
         "default: file for drawings and digitized matrices (the thesis), upper-left for drill, HPGL, SVG and DXF files "
         "(file when --offset is given)",
         choices=("file", "upper-left", "lower-left", "center")),
    # drill files, HPGL and SVG
    _placing("offset_mm", "--offset", "numbers", "mm", _VECTORS, None,
         "where the board, plotter, SVG page or DXF drawing origin goes, mm from the work zero (cam export: from the "
         "program's zero); default: the top-left of what is cut there", lo=-MAX_MM, hi=MAX_MM, count=2, metavar="X,Y"),
    _drill("mirror_x", "--mirror-x", "flag", "", _HOLES, False,
         "drill files: mirror the board for drilling from the back"),
    _drill("drill_order", "--drill-order", "choice", "", _HOLES, "tour",
         "drill files: short tour per tool (default) or the file's order", choices=("tour", "file")),
    _drill("excellon_units", "--excellon-units", "choice", "", {"excellon"}, None,
         "units when the file does not say", choices=("inch", "metric")),
    _drill("excellon_digits", "--excellon-digits", "digits", "digits", {"excellon"}, None,
         "integer:fraction digits when the file does not say (e.g. 2:4)", lo=0, hi=8,
         count=2, metavar="I:F", aliases=("--excellon-format",)),
    _drill("excellon_zeros", "--excellon-zeros", "choice", "", {"excellon"}, None,
         "zero suppression when the file does not say", choices=("LZ", "TZ")),
    _reading("kind", "--kind", "choice", "", _EVERY, None,
         "read the file as this kind whatever its name and content say (matrix: a saved digitized matrix); with "
         "--kind excellon the --excellon-* flags apply (its choices: each kind's --kind name, cam.kinds)"),
    _drill("strict", "--strict", "flag", "", _HOLES, False,
         "drill files: refuse a file with a tool that cannot be drilled (zero size, too large) instead of leaving "
         "its holes out with a warning"),
    _drill("mill_holes_over_mm", "--mill-holes-over", "number", "mm", _HOLES, None,
         "drill files: mill holes larger than MM with an MM bit (circles at the cut depth, within the hole) "
         "instead of drilling them", lo=0.0, hi=100.0, lo_open=True, metavar="MM"),
    # G-code
    _gcode("flip_y", "--flip-y", "flag", "", {"gcode"}, False, "G-code input: machine Y = +Y mm instead of -Y mm"),
    # SVG
    _vector("scale", "--scale", "number", "", _STROKES, None,
         "SVG, DXF and HPGL: mm cut per mm of the drawing (default 1: its own size)", lo=0.0, hi=MAX_MM, lo_open=True,
         metavar="FACTOR"),
    _vector("fit_mm", "--fit", "size", "mm", _STROKES, None,
         "SVG, DXF and HPGL: scale the drawing to fit WIDTHxHEIGHT mm, keeping its proportions (e.g. 80x40)",
         lo=0.0, hi=MAX_MM, lo_open=True, count=2, metavar="WxH"),
    _vector("layers", "--layers", "text", "", _LAYERS, None,
         "SVG and DXF: cut only these layers, in this order (Inkscape layer names, 'parent/child' for a sublayer, or "
         "stroke colours such as '#ff0000' or red when the file has no layers; DXF layer names; 'cam info' lists "
         "them); default: every "
         "layer in file order", metavar="NAME,NAME"),
    _vector("pause_between_layers", "--pause-between-layers", "flag", "", _LAYERS, False,
         "SVG and DXF: pause before each layer after the first, to change the pen or the tool (Enter resumes)"),
    _vector("keep_duplicates", "--keep-duplicates", "flag", "", _LAYERS, False,
         "SVG and DXF: cut a segment that traces one already cut again (by default it is cut once)"),
    # G-code programs (the first two name files on the machine that runs cam: command line only)
    _gcode("tool_table", "--tool-table", "text", "", {"gcode"}, None,
         "LinuxCNC tool table (T1 P1 Z12.5 D3 ...; mm) for G43 H tool length offsets and G41/G42 D cutter radii",
         metavar="FILE.tbl", web=False),
    _gcode("subroutine_path", "--subroutine-path", "paths", "", {"gcode"}, (),
         "folder where 'O<name> call' finds name.ngc (repeatable, searched in order)", metavar="DIR", web=False),
    _gcode("max_lines", "--max-lines", "whole", "lines", {"gcode"}, DEFAULT_GCODE_LINES,
         f"stop a program that runs N lines more than its own length, loops and subroutine calls counted each "
         f"pass (default {DEFAULT_GCODE_LINES:,}): a loop that never ends is an error, not a hang; a long "
         "program runs whole", lo=1, hi=MAX_GCODE_LINES, metavar="N"),
    # sketches and photos traced into drawings
    _sketch("trace", "--trace", "flag", "", {"drawing"}, False,
         "the image is a scanned sketch or a photo of one: trace it into 1-pixel curves first (as 'cam trace' "
         "does)"),
    _sketch("trace_min_length_px", "--trace-min-length", "whole", "px", {"drawing"}, 10,
         "with --trace: specks and spurs shorter than this many pixels go (default 10)", lo=2, hi=10_000,
         metavar="PX"),
    _sketch("trace_fill", "--trace-fill", "flag", "", {"drawing"}, False,
         "with --trace: the regions the curves enclose become red (a 3D drawing)"),
    # real cutters
    _cutter("tool", "--tool", "tool", "", _DRAWINGS | _STROKES, None,
         "point (default, or the machine file's [tool]), flat:D, ball:D or v:ANGLE:TIP[:D] (mm, degrees): 3D "
         "reliefs are cut so the tool never goes below them anywhere", metavar="SHAPE"),
    _cutter("line_width_mm", "--line-width", "number", "mm", _DRAWINGS | _STROKES, None,
         "2D drawings, SVG, DXF and HPGL with a V bit: the engraved lines' width, which sets their depth",
         lo=0.0, hi=MAX_MM, lo_open=True, metavar="MM"),
    _cutter("stepdown_mm", "--stepdown", "number", "mm", _DRAWINGS, None,
         "3D reliefs: rough in levels this far apart before the finishing pass", lo=0.0, hi=MAX_MM, lo_open=True,
         metavar="MM"),
    _cutter("stepover", "--stepover", "number", "", _DRAWINGS, 0.5,
         "roughing rings' spacing as a fraction of the roughing tool's diameter (default 0.5)", lo=0.0, hi=1.0,
         lo_open=True, metavar="FRACTION"),
    _cutter("rough_tool", "--rough-tool", "tool", "", _DRAWINGS, None,
         "a larger roughing tool (as --tool); the job pauses at the home to change to --tool", metavar="SHAPE"),
    # grey-level reliefs (issue #31 point 7)
    _relief("heightmap", "--heightmap", "flag", "", {"drawing"}, False,
         "the image is a height map: each pixel's grey is its depth (black deepest), cut in rows with the tool "
         "by the drop-cutter rule (never below the depth asked)"),
    _relief("invert", "--invert", "flag", "", {"drawing"}, False,
         "with --heightmap: white is deepest instead of black"),
    _relief("max_depth_mm", "--max-depth", "number", "mm", {"drawing"}, None,
         "with --heightmap: the depth of the deepest grey (default 1.0)", lo=0.0, hi=100.0, lo_open=True,
         metavar="MM"),
    _relief("pixel_size_mm", "--pixel-size", "number", "mm", {"drawing"}, None,
         "with --heightmap: a pixel's width (default the machine's drawing pixel, rounded to whole steps)",
         lo=0.0, hi=100.0, lo_open=True, metavar="MM"),
    _relief("heightmap_order", "--heightmap-order", "choice", "", {"drawing"}, "rows",
         "with --heightmap: rows (zig-zag along X) or peel (the thesis's order: level by level, shallowest first)",
         choices=("rows", "peel")),
    # levelling to a probed surface (issue #46 point 2; a file on the machine that runs cam: command line only)
    _level("level", "--level", "text", "", _EVERY, None,
         "level the job to a height map probed on this machine (cam probe grid --out MAP.json): every move, rapids "
         "included, is split at the map's spacing and its Z offset by the surface under it (bilinear); the job is "
         "placed at the active work zero first, whose Z zero must be on the surface", metavar="MAP.json", web=False),
    _level("level_extrapolate", "--level-extrapolate", "flag", "", _EVERY, False,
         "with --level: level moves outside the probed area by extending the map's edge cells (without it such a "
         "job is refused, naming how far outside)", web=False),
)
"""Every job option, in the order of :class:`cam.kinds.jobs.JobOptions`' fields."""


def degenerate(value_of: Callable[[str], Any]) -> Optional[tuple[str, str]]:
    """The first value that is in range but cannot be meant as given, ``(option name, why)``, or None.

    ``value_of(name)`` gives an option's value (None: not given).  Zero is a choice, not an accident (issue #33
    point 8): a travel height at the surface needs ``allow_surface_travel``.  (A scale or a machine's step size
    that rounds a whole job to nothing is found once the job is planned: :func:`cam.kinds.jobs.prepare_job`.)
    The command line (:func:`cam.cli.checks.check_args`) and :meth:`cam.kinds.jobs.JobOptions.checked` (the page)
    both ask it.
    """
    height = value_of("travel_height_mm")
    if height is not None and height <= 0 and not value_of("allow_surface_travel"):
        return "travel_height_mm", (f"is {height:g} mm: the tool would travel between cuts at the surface, across "
                                    "the work; give a height above it (default 1.0 mm), or --allow-surface-travel "
                                    "(the page: allow_surface_travel) if that is meant")
    return None

OPTIONS: dict[str, Option] = {o.name: o for o in JOB_OPTIONS}
"""The options by name."""


OPTION_OF_DEST: dict[str, Option] = {o.dest: o for o in JOB_OPTIONS}
"""The options by their argparse dest (``cut_depth`` -> the ``cut_depth_mm`` option)."""


RULE_KINDS = ("not_with", "needs")
"""What a :class:`Rule` says: its option cannot be given together with another, or needs one of others given."""


@dataclass(frozen=True)
class Rule:
    """A rule between job options, about one of them (the one its message names first).

    Attributes:
        kind: one of :data:`RULE_KINDS`: "not_with": :attr:`option` cannot be given together with any of
            :attr:`others`; "needs": :attr:`option` needs one of :attr:`others` given.
        option: the option the rule is about: the one to leave out, or to give with what it needs.
        others: the options it goes against, or one of which it needs.
        why: what is wrong, said after the option's name: ``{name}`` of an option stands for it as the user
            names it (its flag on the command line, its name in the API and on the page), ``{other}`` for the
            one of :attr:`others` given (not_with) or for them all, joined by "or" (needs).
    """

    kind: str
    option: str
    others: tuple[str, ...]
    why: str

    def broken(self, value_of: Callable[[str], Any], term: Callable[[str], str] = str) -> Optional[str]:
        """Why the values ``value_of(name)`` (None: not given) break the rule, its :attr:`why` said in ``term``'s
        names, or None."""
        if not given(self.option, value_of(self.option)):
            return None
        with_ = [n for n in self.others if given(n, value_of(n))]
        if self.kind == "not_with" and with_:
            other = term(with_[0])
        elif self.kind == "needs" and not with_:
            other = " or ".join(term(n) for n in self.others)
        else:
            return None
        return self.why.format_map(_Terms(term, other))


class _Terms(dict):
    """The names a rule's :attr:`Rule.why` uses, as ``term`` says them (``{other}``: the partner it names)."""

    def __init__(self, term: Callable[[str], str], other: str) -> None:
        super().__init__(other=other)
        self.term = term

    def __missing__(self, name: str) -> str:
        return self.term(name)


def _plain(value: Any) -> Any:
    return tuple(_plain(v) for v in value) if isinstance(value, (list, tuple)) else value


def given(name: str, value: Any) -> bool:
    """Whether option ``name`` is given as ``value`` for its rules: not None, off or empty, nor its default (a
    value equal to the default changes nothing, and :class:`cam.kinds.jobs.JobOptions` cannot tell it from one left
    out; a list as the command line holds it is its tuple)."""
    if value is None or value is False or (isinstance(value, (str, list, tuple)) and not value):
        return False
    default = OPTIONS[name].default
    return default is None or bool(_plain(value) != _plain(default))


_HEIGHTMAP_DEPTH = "does not apply with {heightmap} (the grey of each pixel is its depth, down to {max_depth_mm})"

RULES: tuple[Rule, ...] = (
    Rule("not_with", "cut_depth_mm", ("depth",),
         "cannot be given together with {depth}: give the depth once, {depth} in Z pixels per object or "
         "{cut_depth_mm} in mm for every object"),
    Rule("not_with", "fit_mm", ("scale",), "cannot be given together with {scale}: give {scale} or {fit_mm}, not both"),
    Rule("not_with", "profile_expr", ("profile",),
         "cannot be given together with {profile}: give a profile file ({profile}) or an expression "
         "({profile_expr}), not both"),
    *(Rule("not_with", name, ("depth", "cut_depth_mm"),
           "cannot be given together with {other}: give a 3D drawing's depth once, a profile ({profile} or "
           "{profile_expr}) for a shaped relief or one depth for every layer ({depth} or {cut_depth_mm}, a "
           "flat-bottomed pocket)") for name in ("profile", "profile_expr")),
    Rule("not_with", "line_width_mm", ("depth", "cut_depth_mm", "profile", "profile_expr"),
         "cannot be given together with {other}: the line width sets the depth (of a 2D drawing's lines)"),
    *(Rule("not_with", name, ("heightmap",), _HEIGHTMAP_DEPTH)
      for name in ("trace", "trace_fill", "profile", "profile_expr", "depth", "cut_depth_mm", "line_width_mm",
                   "rough_tool", "pause_at")),
    *(Rule("needs", name, ("heightmap",), "applies with {heightmap} only (an image read as a height map)")
      for name in ("invert", "max_depth_mm", "pixel_size_mm", "heightmap_order")),
    *(Rule("needs", name, ("trace",), "applies with {trace} only (a sketch or a photo traced into a drawing first)")
      for name in ("trace_min_length_px", "trace_fill")),
    Rule("needs", "rough_tool", ("stepdown_mm",), "is for roughing in levels: it needs {stepdown_mm} (their spacing)"),
    Rule("needs", "stepover", ("stepdown_mm", "heightmap"),
         "spaces the roughing rings ({stepdown_mm}) or a height map's rows ({heightmap}): it needs one of them"),
    Rule("needs", "level_extrapolate", ("level",), "needs a height map to level by ({level})"),
)
"""Every rule between job options, declared once (issue #48 point 3), in the order they are asked: the command
line, :class:`cam.kinds.jobs.JobOptions`, the planners and the page all ask :func:`broken_rule` (or
:func:`keyword_error`), the page from the rules :func:`schema_json` gives each option."""


def own_zero(value_of: Callable[[str], Any]) -> bool:
    """Whether a drill, HPGL, SVG or DXF file is placed by its own zero: ``origin`` "file", or an ``offset_mm``
    given and no ``origin`` (an offset places the file's zero, so it makes the origin "file"), the one place this
    rule is written (:func:`cam.kinds.jobs.own_zero_home` asks it for those kinds, the G-code export's exact
    points too).  ``value_of(name)``: an option's value, None when not given."""
    origin = value_of("origin")
    return origin == "file" or (origin is None and value_of("offset_mm") is not None)


def broken_rule(value_of: Callable[[str], Any], term: Callable[[str], str] = str) -> Optional[tuple[str, str]]:
    """The first rule of :data:`RULES` the options break, ``(option name, why)``, or None.

    ``value_of(name)`` gives an option's value (None: not given); ``term(name)`` how the message names an option
    (the command line: its flag; by default its name, as the API and the page say it).  Like :func:`degenerate`,
    the caller puts the option before ``why``: ``--cut-depth cannot be given together with --depth: ...``.
    """
    for rule in RULES:
        why = rule.broken(value_of, term)
        if why is not None:
            return rule.option, why
    return None


def keyword_error(values: dict[str, Any]) -> Optional[str]:
    """Why a planner's keywords ``values`` (option names, as :data:`OPTIONS` has them; None: not given) cannot be
    planned, as one line naming the keyword: the first out of its option's range (:func:`check_range`), then the
    first rule of :data:`RULES` among these keywords broken; None when none is.  The planners ask it, so that a
    planner called by itself refuses what ``JobOptions`` refuses, in the same words."""
    for name, value in values.items():
        why = check_range(OPTIONS[name], value)
        if why is not None:
            return f"{name} {why}, got {value!r}"
    for rule in RULES:
        if rule.option in values and all(n in values for n in rule.others):
            why = rule.broken(values.get)
            if why is not None:
                return f"{rule.option} {why}"
    return None


def _json_value(value: Any) -> Any:
    return [_json_value(v) for v in value] if isinstance(value, (tuple, list)) else value


def schema_json(options: tuple[Option, ...], kind_defaults: Optional[dict[str, dict[str, Any]]] = None
                ) -> list[dict[str, Any]]:
    """The schema as JSON-able records (``GET /api/options``, :func:`cam.kinds.schema_json`): every field of each
    of ``options`` (their kinds filled in, :func:`cam.kinds.job_options`), kinds sorted, with its
    :attr:`~Option.label`, its range in words (``range``, as the errors say it) and ``defaults``, the value each
    kind it applies to takes when it is not given: ``kind_defaults[kind][name]`` where it depends on the kind (a
    drill file's cut depth, :func:`cam.kinds.kind_defaults`), else the option's default; and ``rules``, the
    :data:`RULES` about it (``kind``, ``others``, ``why``: the page says ``{name}`` as the name and ``{other}`` as
    the partner it finds, as the API does; ``index``: its place in :data:`RULES`, the order they are asked in).
    The page counts an option as given as :func:`given` does: set, and not to its default."""
    every = kind_defaults or {}
    return [{"name": o.name, "label": o.label, "group": o.group, "flag": o.flag, "type": o.type, "unit": o.unit,
             "kinds": sorted(o.kinds), "default": _json_value(o.default),
             "defaults": {k: _json_value(every.get(k, {}).get(o.name, o.default)) for k in sorted(o.kinds)},
             "help": o.help, "min": o.lo, "max": o.hi, "min_open": o.lo_open, "range": o.range_text(),
             "count": o.count, "choices": list(o.choices), "metavar": o.metavar, "web": o.web,
             "aliases": list(o.aliases),
             "rules": [{"kind": r.kind, "others": list(r.others), "why": r.why, "index": i}
                       for i, r in enumerate(RULES) if r.option == o.name]}
            for o in options]
