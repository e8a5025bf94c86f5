"""A file and its options, to a job ready to run: one entry point for every job kind.

The CLI and the web server are thin adapters over :func:`prepare_job`::

    job = prepare_job("gear.png", JobOptions(depth=(4,)))
    job.steps              # the StepPlan: every port write, timed
    job.kind               # "drawing", "digitized", "gcode", "excellon", "hpgl", "svg" or "dxf"
    job.size_mm, job.estimated_time_s, job.warnings, job.tool_changes
    job.preview_png()      # PNG bytes of the toolpath picture

The kind comes from the file name's suffix and, when the suffix is generic
(none, ``.txt``, ``.nc``, ``.cnc``), unknown or contradicted by the content,
from the file's first few kB (:func:`cam.kinds.job_kind`: each kind's module
has its sniffer); a suffix the content contradicts is a warning of the job.
A file neither tells is a :class:`~cam.errors.CamError` naming the file and
the accepted types.  The kind's module (:mod:`cam.kinds`) plans it
(:attr:`cam.kinds.Kind.prepare`); what is the same for every kind (the
options checked, placement by the file's own zero, levelling, the report's
common fields, resuming) is here.  Every job is planned relative to where the tool stands when it
starts (the job's home, (0, 0, 0) in machine steps); :attr:`PreparedJob.extent_steps`
says how far it reaches from there, so a caller that knows where the tool
stands can check the job against the machine travel before it starts.  A job
that has a real machine home (a G-code program's start, a drill, HPGL or SVG
file placed by its own zero: :func:`own_zero_home`) is checked against the
travel in the machine frame when it is planned; every other job (a drawing, a
relief, a file placed by its extent) is planned in its own frame, placed at the
work zero when it runs and checked there, and here only to fit the travel's
span on each axis (issue #45 point 4).
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping, Optional

import cv2
import numpy as np

from ..arrays import column_range
from ..choices import PROFILE_SUFFIXES
from ..motion.chunks import plan_chunks
from ..errors import CamError, PlanError
from ..options import JOB_OPTIONS, Option, MAX_DEPTH_PX, MAX_MM, MAX_PX, broken_rule, check_range, degenerate, own_zero  # noqa: F401 (the limits re-exported)
from ..tool import parse_tool, tool_of_settings
from ..render.picture import LEGEND_PX, depth_colours, encode_png
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..verify.pinlog import PinLog, decode_pin_log
from ..job.gcode_probing import ProbingProgram
from ..job.heightmap_level import check_map, level_job, load_height_map, outside_text
from ..job.model import Job
from ..job.resume import (Journal, JournalBase, check_journal, check_journal_numbers, job_identity, plan_fingerprint,
                          resume_pieces)
from . import forced_kind, has, job_kind, job_options, kind_defaults, kind_names, option_kinds, suffixes
from . import kind as kind_named

__all__ = [
    "JobOptions", "PreparedJob", "PlannedIn", "prepare_job", "own_zero_home", "resume_job", "job_kind", "accepted_suffixes",
    "origin_anchor_steps", "default_origin", "kind_defaults", "engraving", "line_depth_mm", "plan_chunks", "PROFILE_SUFFIXES",
]


def accepted_suffixes() -> dict[str, tuple[str, ...]]:
    """File name suffixes of each job kind (lower case, with the dot; :func:`cam.kinds.suffixes`)."""
    return suffixes()


_ANNOTATIONS = {
    "whole": "int", "number": "float", "wholes": "tuple[int, ...]", "numbers": "tuple[float, ...]", "choice": "str",
    "flag": "bool", "text": "str", "tool": "str", "points": "tuple[tuple[int, int], ...]",
    "digits": "tuple[int, int]", "size": "tuple[float, float]", "paths": "tuple[str, ...]",
}
"""The Python type of each schema type (:data:`cam.options.TYPES`)."""


def _schema_fields(cls: type) -> type:
    """Give ``cls`` one dataclass field per :data:`cam.options.JOB_OPTIONS` entry: its name, type and default."""
    annotations = {}
    for o in JOB_OPTIONS:
        kind = _ANNOTATIONS[o.type]
        annotations[o.name] = f"Optional[{kind}]" if o.default is None else kind
        setattr(cls, o.name, o.default)
    cls.__annotations__ = annotations
    return cls


@dataclass(frozen=True)
@_schema_fields
class JobOptions:
    """How to cut a file.  An option given for a kind it does not apply to is an error (:meth:`check_kind`).

    The fields, their types, defaults, ranges and kinds are those of :data:`cam.options.JOB_OPTIONS` (declared
    once there; the command-line flags and the page's form are made from the same declaration).

    Drawings and digitized matrices (pixel units):
        depth: Z pixels below the surface, one value for every object or one per object (None: 10 on a 2D
            drawing; on a 3D drawing one value cuts every layer at it, a flat-bottomed pocket, instead of a
            profile).
        passes: cut in this many passes of increasing depth (Repeat Drill).
        start: where each 2D object starts, "top", "min-distance" or "thesis" (nearest the origin).
        start_at: ``(x, y, z)`` pixel offset of the whole job (Start At).
        pause_at: drawing points ``(x, y)`` where the job pauses (Pause At).
        profile: path of a profile drawing or CSV (3D drawings); profile_expr: or an expression in k and n.
    Depths and heights in mm, one name for every kind:
        cut_depth_mm: drill depth of drill files (default 2.0), pen-down depth of HPGL (default 0.5), or a
            drawing's depth for every object instead of ``depth`` (converted to whole Z pixels).
        travel_height_mm: height above the surface between cuts, drill files and HPGL (default 1.0).
    Excellon drill files and HPGL:
        offset_mm (board or plotter origin from the job home; None = the top-left of what is cut at the
        home); drill files only: mirror_x, drill_order ("tour" or "file"), excellon_units
        ("inch"/"metric"), excellon_digits ``(integer, fraction)``, excellon_zeros ("LZ"/"TZ") for
        files that do not say.
    G-code:
        flip_y: machine Y = +Y mm instead of -Y mm.
        tool_table: a LinuxCNC tool table for G43 (lengths in mm); subroutine_path: folders where
        ``O<name> call`` finds ``name.ngc``; max_lines: the most lines a program may run (loops count each
        pass).  The first two name files on the machine that runs `cam`, so they are command-line options
        only: :meth:`from_mapping` (the web page's form) refuses them.
    SVG and DXF (also cut_depth_mm, default 0.5, travel_height_mm and offset_mm, the page's origin):
        scale: mm cut per mm of the drawing; fit_mm: or ``(width, height)`` mm to scale the drawing to fit.
    Drawings that are sketches or photos:
        trace: trace the image into a drawing first (see :func:`cam.digitize.sketch.trace`: dark lines on
        light paper to 1-pixel curves); trace_min_length_px: specks and spurs shorter than this go;
        trace_fill: the regions the curves enclose become red (a 3D drawing).
    Real cutters (drawings and digitized matrices):
        tool: ``point``, ``flat:D``, ``ball:D`` or ``v:ANGLE:TIP`` (mm, degrees; None: the machine's ``[tool]``,
            a point by default): 3D depths are limited so the tool never cuts below the relief.
        line_width_mm: a 2D drawing's engraved line width with a V bit: sets the depth (instead of ``depth``).
        stepdown_mm: rough a 3D relief in levels this far apart first (None: finish at once); stepover: the
            roughing rings' spacing, a fraction of the roughing tool's diameter; rough_tool: a larger
            roughing tool (a tool-change pause before finishing), None: the finishing tool.
    Levelling to a probed surface (every kind; :mod:`cam.job.heightmap_level`):
        level: a height map file (``cam probe grid --out MAP.json``): every move is split at its spacing and its Z
            offset by the surface under it, where the job runs (see :func:`prepare_job`'s ``machine_state``);
            a file on the machine that runs `cam`, so command-line and API only.
        level_extrapolate: level moves outside the probed area by the edge cells extended (else refused).
    """

    # the fields (names, defaults) are added from cam.options.JOB_OPTIONS by _schema_fields

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "options") -> "JobOptions":
        """Options from a JSON-like mapping (numbers, strings, lists, booleans), checked.

        Numbers may also be given as text (``"3"``, ``"3,4"`` for lists), as form fields send them.

        >>> JobOptions.from_mapping({"depth": "3,4", "passes": 2}).depth
        (3, 4)

        Raises:
            CamError: an unknown key or a bad value, naming the option.
        """
        if not isinstance(values, Mapping):
            raise CamError(f"{source}: options must be an object of name: value")
        known = {f.name for f in fields(cls)}
        out: dict[str, Any] = {}
        for key, value in values.items():
            if key not in known:
                raise CamError(f"{source}: unknown option '{key}' (known: {', '.join(sorted(known))})")
            parse = _PARSERS.get(key)
            if parse is None:
                raise CamError(f"{source}: option '{key}' names files on the machine: give it on the command line")
            try:
                out[key] = parse(value)
            except (TypeError, ValueError) as exc:
                raise CamError(f"{source}: option '{key}' {exc}, got {value!r}") from None
        return cls(**out).checked(source)

    def checked(self, source: str = "options") -> "JobOptions":
        """Range checks (:func:`cam.options.check_range`) and the rules between options (:func:`cam.options.broken_rule`:
        one depth, a scale or a size to fit, the options of a height map, a traced sketch or levelling only with
        it); returns self.  Raises CamError naming the option."""
        def bad(key: str, why: str) -> CamError:
            return CamError(f"{source}: option '{key}' {why}, got {getattr(self, key)!r}")

        declared = {o.name: o for o in job_options()}
        for f in fields(self):  # the ranges and choices of cam.options, as the command line checks them
            o = declared[f.name]
            value = getattr(self, o.name)
            if value is None:
                continue
            why = check_range(o, value)
            if why is None and o.choices and value not in o.choices:
                why = "must be " + " or ".join(f"'{c}'" for c in o.choices)
            if why is None and o.count is not None and o.type != "points" and len(value) != o.count:
                why = f"takes {o.count} values"
            if why is None and o.type == "wholes" and not value:
                why = "takes at least one whole number"
            if why is not None:
                raise bad(o.name, why)
        if self.tool is not None:
            parse_tool(self.tool, f"{source}: option 'tool'")
        if self.rough_tool is not None:
            parse_tool(self.rough_tool, f"{source}: option 'rough_tool'")
        if self.level is not None and not self.level.strip():
            raise bad("level", "must name a height map file")
        broken = broken_rule(lambda name: getattr(self, name))  # the rules between options (cam.options.RULES)
        if broken is not None:
            raise bad(*broken)
        odd = degenerate(lambda name: getattr(self, name))  # zero where zero is unsafe (cam.options)
        if odd is not None:
            raise bad(*odd)
        return self

    def check_kind(self, kind: str, source: str = "options") -> "JobOptions":
        """Refuse an option given for a job kind it does not apply to (the kinds of :data:`cam.options.JOB_OPTIONS`);
        returns self."""
        kinds_of = option_kinds()
        for f in fields(self):
            applies = kinds_of[f.name]
            if getattr(self, f.name) != f.default and kind not in applies:
                raise CamError(f"{source}: option '{f.name}' does not apply to a {kind} file; it applies to "
                               f"{' and '.join(sorted(applies))} files")
        return self


def _int(value: Any) -> int:
    if isinstance(value, bool):
        raise ValueError("must be a whole number")
    if isinstance(value, int):
        return value
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, str):
        try:
            return int(value.strip())
        except ValueError:
            pass
    raise ValueError("must be a whole number")


def _float(value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError("must be a number")
    try:
        out = float(value.strip() if isinstance(value, str) else value)
    except (TypeError, ValueError):
        raise ValueError("must be a number") from None
    except OverflowError:  # an integer too large for a float (10^400)
        raise ValueError("must be a finite number") from None
    if not math.isfinite(out):
        raise ValueError("must be a finite number")
    return out


def _bool(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    if value in ("true", "1", 1, "on", "yes"):
        return True
    if value in ("false", "0", 0, "off", "no", "", None):
        return False
    raise ValueError("must be true or false")


def _items(value: Any) -> list[Any]:
    if isinstance(value, str):
        return [v for v in value.replace(";", ",").split(",") if v.strip()]
    if isinstance(value, (list, tuple)):
        return list(value)
    return [value]


def _ints(n: Optional[int]):
    def parse(value: Any) -> tuple[int, ...]:
        out = tuple(_int(v) for v in _items(value))
        if n is not None and len(out) != n:
            raise ValueError(f"takes {n} whole numbers")
        if not out:
            raise ValueError("takes at least one whole number")
        return out

    return parse


def _floats(n: int):
    def parse(value: Any) -> tuple[float, ...]:
        out = tuple(_float(v) for v in _items(value))
        if len(out) != n:
            raise ValueError(f"takes {n} numbers")
        return out

    return parse


def _optional(parse):
    def wrapped(value: Any) -> Any:
        if value is None or (isinstance(value, str) and not value.strip()):
            return None
        return parse(value)

    return wrapped


def _text(value: Any) -> str:
    if not isinstance(value, str):
        raise ValueError("must be text")
    return value.strip()


def _points(value: Any) -> tuple[tuple[int, int], ...]:
    if isinstance(value, str):
        groups = [g for g in value.replace(";", " ").split() if g]
        return tuple(_ints(2)(g) for g in groups)  # type: ignore[misc]
    if isinstance(value, (list, tuple)):
        return tuple(_ints(2)(p) for p in value)  # type: ignore[misc]
    raise ValueError("must be a list of x,y points")


def _fit(value: Any) -> tuple[float, ...]:
    return _floats(2)(value.lower().replace("x", ",") if isinstance(value, str) else value)


def _digits(value: Any) -> tuple[int, ...]:
    """Excellon ``I:F`` digit counts, as the command line takes them (``2:4``; also ``2,4`` or a list)."""
    return _ints(2)(value.replace(":", ",") if isinstance(value, str) else value)


def _parser_of(o: Option) -> Any:
    """How :meth:`JobOptions.from_mapping` reads option ``o`` from JSON or form text (None: not from the page)."""
    if not o.web:
        return None
    if o.name == "excellon_zeros":
        base: Any = lambda v: _text(v).upper()  # noqa: E731
    else:
        base = {"whole": _int, "number": _float, "wholes": _ints(o.count), "numbers": _floats(o.count or 1),
                "choice": _text, "flag": _bool, "text": _text, "tool": _text, "points": _points,
                "digits": _digits, "size": _fit}[o.type]
    return _optional(base) if o.default is None else base


_PARSERS = {o.name: p for o in JOB_OPTIONS if (p := _parser_of(o)) is not None}
"""How the page's values of each option are read, from its schema type."""



Steps3 = tuple[int, int, int]


@dataclass(frozen=True)
class PlannedIn:
    """The machine state a job's plan holds for (issue #43 point 6), as far as the plan depends on it; positions in
    the machine frame, steps.  A G-code program runs from where the tool stands, in the work offsets: its plan holds
    there only.  A drill, HPGL or SVG file placed by its own zero is planned from the active work zero: its plan
    holds from any position (it travels there first), for that work zero only.

    Attributes:
        position_steps: where the tool stood (a G-code program); None: any position.
        offsets_steps: the work offsets the plan used, ``((name, zero), ...)`` (a program: every one, it may
            switch to any; a file placed by its own zero: the active one); empty: none known (planned without a
            machine state, in the home's frame).
        active_offset: the work offset active when it was planned (None: not known).
    """

    position_steps: Optional[Steps3]
    offsets_steps: tuple[tuple[str, Steps3], ...] = ()
    active_offset: Optional[str] = None

    @classmethod
    def of(cls, machine_state: Any, *, position: bool, every_offset: bool) -> "PlannedIn":
        """What a plan made in ``machine_state`` (a :class:`cam.drive.state.MachineState`) depends on: the
        tool's position when ``position``, every work offset when ``every_offset`` (else the active one)."""
        active = str(machine_state.active_offset)
        names = list(machine_state.offsets_steps) if every_offset else [active]
        return cls(tuple(int(v) for v in machine_state.position_steps) if position else None,  # type: ignore[arg-type]
                   tuple((n, tuple(int(v) for v in machine_state.offsets_steps[n])) for n in names),  # type: ignore[misc]
                   active)

    def differs(self, position_steps: Any, offsets_steps: Optional[Mapping[str, Any]] = None,
                active_offset: Optional[str] = None) -> str:
        """Why the plan does not hold with the tool at ``position_steps`` and these work offsets (None: not known,
        not compared), as one line ending in "plan it again"; "" when it holds."""
        here = tuple(int(v) for v in position_steps)
        if self.position_steps is not None and here != tuple(self.position_steps):
            return (f"the job was planned when the tool was at machine {list(self.position_steps)} steps, it is now "
                    f"at {list(here)}: plan it again from here")
        if offsets_steps is not None:
            for name, zero in self.offsets_steps:
                now = tuple(int(v) for v in offsets_steps.get(name, zero))
                if now != tuple(zero):
                    return (f"the job was planned with the {name} work zero at machine {list(zero)} steps, it is now "
                            f"at {list(now)}: plan it again")
        if active_offset is not None and self.active_offset is not None and active_offset != self.active_offset:
            return (f"the job was planned in work offset {self.active_offset}, {active_offset} is active now: plan it "
                    f"again")
        return ""


@dataclass
class PreparedJob:
    """A job ready to run.

    Attributes:
        source: the file it came from; name: what to call it; kind: its file kind's name (:func:`cam.kinds.kind_names`).
        plan: the step plan as a :class:`~cam.motion.chunks.ChunkedPlan` (machine frame, steps from the job
            home): made a chunk at a time, so a job of any length runs in bounded memory.
        steps: the same plan with every write at once, a :class:`~cam.motion.steps.StepPlan` (made on first
            use and kept: small jobs, pictures of every write, tests).
        settings: the machine settings of ``plan``.
        toolpath: the :class:`~cam.job.model.Job` when the kind has one (not G-code).
        size_mm: ``(width, height)`` of what is cut (XY extent of the tool below the surface), mm.
        depth_mm: deepest cut below the surface, mm.
        extent_steps: ``(3, 2)`` int64 min and max machine position (x, y, z) in steps the job
            reaches, relative to where it starts.
        estimated_time_s: machine time without pauses.
        warnings: planning and parsing warnings; tool_changes: what each pause of the job is for.
        summary: one line saying what the job is.
        report: JSON-able job report.
        digitized: the :class:`~cam.digitize.digitized.Digitized` matrix of a drawing job.
        drill_plan: the :class:`~cam.job.drill.DrillPlan` of a drill file (holes in drilling order, tools),
            which a MAXIMUS board drills by itself.
        identity: sha256 of the input's bytes, the options and the settings (:func:`cam.job.resume.job_identity`).
        plan_sha256: the toolpath's :func:`cam.job.resume.plan_fingerprint`.
        resumed: a resumed run's :class:`cam.job.resume.JournalBase` (None: a run from the start).
        origin: the point placed at the work zero its options chose (``JobOptions.origin``: "file" plans a drill,
            HPGL or SVG file from its own zero, :func:`own_zero_home`, as an ``offset_mm`` without an origin does,
            which then makes it "file" too, from the command line or the page alike); None: the kind's default
            (:func:`cam.drive.placement.origin_anchor`).
        home_steps: the machine position ``plan`` was checked against the travel from, its home: a G-code
            program's start, the work zero of a file placed by its own zero; None: planned in its own frame
            (placed when it runs, where the session checks it; at planning it is checked to fit the travel's span,
            :class:`~cam.job.model.TravelSpan`, issue #45 point 4).  A resumed run is checked so too
            (:func:`resume_job`).
        planned_in: the machine state the plan holds for (:class:`PlannedIn`: a G-code program's start and work
            offsets, the work zero of a file placed by its own zero); None: it holds anywhere (placed when it
            runs, or resumed from where the tool stands).  A machine session refuses it elsewhere.
        levelled_home_steps: a job levelled to a height map (``JobOptions.level``): the machine position of its
            home its levelling holds for, where the session places it
            (:func:`cam.drive.placement.placed_home`); None: not levelled.
        probing: a G-code program that probes (G38.2, G38.3): how a machine runs it, a part at a time from each
            probe's contact (:class:`~cam.job.gcode_probing.ProbingProgram`); its :attr:`plan` and :attr:`toolpath`
            are the program as if each probe touched at its target (pictures, reports, the checks made before
            anything moves), never run as they are.  None: no probe.
    """

    source: str
    kind: str
    plan: Any
    settings: MachineSettings
    toolpath: Any = None
    name: str = ""
    size_mm: tuple[float, float] = (0.0, 0.0)
    depth_mm: float = 0.0
    extent_steps: np.ndarray = field(default_factory=lambda: np.zeros((3, 2), np.int64))
    warnings: list[str] = field(default_factory=list)
    tool_changes: list[str] = field(default_factory=list)
    summary: str = ""
    report: dict[str, Any] = field(default_factory=dict)
    drawing_rgb: Optional[np.ndarray] = None
    drill_plan: Any = None
    digitized: Any = None
    identity: str = ""
    plan_sha256: str = ""
    resumed: Any = None
    origin: Optional[str] = None
    home_steps: Optional[tuple[int, int, int]] = None
    planned_in: Optional[PlannedIn] = None
    levelled_home_steps: Optional[tuple[int, int, int]] = None
    probing: Optional[ProbingProgram] = None
    _steps: Any = field(default=None, repr=False)

    @property
    def estimated_time_s(self) -> float:
        """Machine time without pauses: the plan's, worked out on first use (a pass over its ramps, kept; a run
        of the whole plan gives it for free)."""
        return float(self.plan.estimated_time_s)

    def full_report(self) -> dict[str, Any]:
        """:attr:`report` and the machine time (``estimated_time_s``, worked out here: a pass over the ramps unless
        a run has made one): what ``--report`` and ``cam info --json`` write."""
        return {**self.report, "estimated_time_s": round(self.estimated_time_s, 6)}

    @property
    def steps(self) -> Any:
        """Every write of :attr:`plan` at once (a :class:`~cam.motion.steps.StepPlan`, its chunks joined, made on
        first use: pictures of every write and tests; a run sends :attr:`plan` a chunk at a time)."""
        if self._steps is None:
            self._steps = self.plan.to_plan()
        return self._steps

    def positions_steps(self) -> np.ndarray:
        """``(M, 3)`` int64 machine position (x, y, z) in steps after each write of the plan."""

        plan = self.steps
        return decode_pin_log(PinLog(plan.t_ns, plan.data, plan.strobe), self.settings).position_steps

    def preview_picture(self) -> np.ndarray:
        """The preview as an ``(H, W, 3)`` uint8 RGB array (see :mod:`cam.render.picture`)."""
        hook = kind_named(self.kind).picture if self.kind in kind_names() else None
        own = hook(self) if hook is not None else None
        if own is not None:
            return own
        # the job's points, a piece at a time: the step plan moves in straight lines between them (its DDA
        # spreads the shorter axes evenly), so they draw the same picture as every write would, at a fraction
        # of the cost
        pieces = (lambda: (p.points_steps for p in self.toolpath.pieces())) if self.toolpath is not None else \
            self.positions_steps()
        return motion_picture(pieces, self.settings, legend=self._legend(), extent_steps=self.extent_steps,
                              holes=has(self.kind, "holes"))

    def preview_png(self) -> bytes:
        """PNG bytes of :meth:`preview_picture`."""

        return encode_png(self.preview_picture())

    def _legend(self) -> str:
        m, s = divmod(int(round(self.estimated_time_s)), 60)
        return (f"{self.size_mm[0]:.1f} x {self.size_mm[1]:.1f} mm   depth {self.depth_mm:.2f} mm   "
                f"time {m // 60}:{m % 60:02d}:{s:02d}")


def motion_picture(
    positions_steps: Any, settings: MachineSettings, *, legend: str = "", holes: bool = False,
    target_px: int = 800, extent_steps: Optional[np.ndarray] = None,
) -> np.ndarray:
    """Picture of decoded motion, seen from above, as an ``(H, W, 3)`` uint8 RGB array.

    Args:
        positions_steps: ``(M, 3)`` machine positions in steps (x right, y down the picture, +z deeper), or
            an iterable of such arrays, consecutive pieces of the motion (a job too large to hold at once:
            then ``extent_steps`` is needed).
        settings: for mm per step (X and Y are drawn to the same mm scale).
        legend: text under the picture; holes: mark each plunge with a ring (drill jobs).
        target_px: the longer side of the drawing area in picture pixels.
        extent_steps: ``(3, 2)`` min/max position of the motion (the start included); None: from the points.

    Moves with the tool below the surface (z > 0) are drawn coloured by depth
    (shallow yellow to deep purple), moves above it in thin grey.  Pieces are drawn one at a time: the
    memory is that of a piece.
    """
    if isinstance(positions_steps, np.ndarray) or not callable(positions_steps):
        held = [np.asarray(p, np.int64).reshape(-1, 3) for p in
                ([positions_steps] if isinstance(positions_steps, np.ndarray) else positions_steps)]
        pieces = lambda: iter(held)  # noqa: E731
    else:
        pieces = positions_steps
    if extent_steps is None:
        allp = np.vstack([np.zeros((1, 3), np.int64)] + list(pieces()))
        extent_steps = np.column_stack(column_range(allp))
    extent_steps = np.asarray(extent_steps, np.int64)
    lo = extent_steps[:2, 0]
    span = np.maximum(1, extent_steps[:2, 1] - lo)
    margin = 12
    k = (target_px - 2 * margin) / float(span.max())
    w = int(np.rint(span[0] * k)) + 2 * margin + 1
    h = int(np.rint(span[1] * k)) + 2 * margin + 1
    img = np.full((h + LEGEND_PX, max(w, 420), 3), 255, np.uint8)
    zmax = max(1, int(extent_steps[2, 1]))
    start_xy = np.rint((np.zeros(2) - lo) * k).astype(np.int64) + margin
    for layer in ("above", "below", "holes"):  # every grey line under every coloured one, the rings on top
        if layer == "holes" and not holes:
            break
        hole_seen: list[bool] = []  # a piece was judged: its last point is point 0 of the next
        prev_xy, prev_z, before_z = start_xy.copy(), 0, 0  # before_z: the kept point before prev (holes)
        for q, last in _with_last(np.asarray(p, np.int64).reshape(-1, 3) for p in pieces()):
            full_xy = np.vstack([prev_xy[None, :], np.rint((q[:, :2] - lo) * k).astype(np.int64) + margin])
            full_z = np.concatenate([[prev_z], q[:, 2]])
            keep = np.ones(len(full_xy), bool)
            keep[1:] = np.any(full_xy[1:] != full_xy[:-1], axis=1) | (full_z[1:] != full_z[:-1])
            keep[-1] |= last  # the motion's end is drawn even where it adds nothing
            xy, z = full_xy[keep], full_z[keep]
            below = (z[1:] > 0) & (z[:-1] > 0)
            if layer == "above":
                moved = np.any(xy[1:] != xy[:-1], axis=1)
                _draw_runs(img, xy, ~below & moved, np.zeros((len(xy), 3), np.uint8) + 170, 1, cv2.LINE_AA)
            elif layer == "below":
                _draw_runs(img, xy, below, depth_colours(np.maximum(z, 0), zmax), 2, cv2.LINE_8)
            else:  # a plunge's deepest point: judged once its next point is known (the last of a piece: in the
                # next piece, where it is point 0 and the point before it is carried)
                cols = depth_colours(np.maximum(z, 0), zmax)
                nxt = np.r_[z[1:], 0]
                deepest = np.flatnonzero((z > 0) & (nxt < z) & (np.r_[before_z, z[:-1]] <= z))
                deepest = deepest[(deepest > 0 if not len(hole_seen) else deepest >= 0)
                                  & ((deepest < len(z) - 1) | last)]
                for i in deepest:
                    cv2.circle(img, (int(xy[i, 0]), int(xy[i, 1])), 5, tuple(int(v) for v in cols[i]), 2, cv2.LINE_AA)
                hole_seen.append(True)
            before_z = int(z[-2]) if len(z) > 1 else before_z
            prev_xy, prev_z = xy[-1].copy(), int(z[-1])
    cv2.circle(img, (int(start_xy[0]), int(start_xy[1])), 6, (0, 170, 0), 2)
    img[h:] = 245
    cv2.putText(img, legend, (6, h + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "start/home", (6, h + 36), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 170, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "grey: above the surface", (100, h + 36), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (120, 120, 120), 1,
                cv2.LINE_AA)
    return img


def _draw_runs(img: np.ndarray, xy: np.ndarray, draw: np.ndarray, cols: np.ndarray, thickness: int,
               line_type: int) -> None:
    """Draw segment ``i`` (``xy[i]`` to ``xy[i + 1]``, ``(N, 2)`` picture pixels) where ``draw[i]``, in the colour
    of its end ``cols[i + 1]``: consecutive segments of one colour as one polyline (one OpenCV call for a run,
    not one a segment: the same pixels, a 50,000-circle halftone's picture in a fraction of the time)."""
    idx = np.flatnonzero(draw)
    if not len(idx):
        return
    colour_key = cols[idx + 1].astype(np.int64) @ np.array([1 << 16, 1 << 8, 1], np.int64)
    new_run = np.ones(len(idx), bool)
    new_run[1:] = (np.diff(idx) != 1) | (colour_key[1:] != colour_key[:-1])
    starts = np.flatnonzero(new_run)
    ends = np.r_[starts[1:], len(idx)]
    pts = xy.astype(np.int32)
    for r0, r1 in zip(starts.tolist(), ends.tolist()):
        run = pts[idx[r0]:idx[r1 - 1] + 2]
        colour = tuple(int(v) for v in cols[idx[r0] + 1])
        cv2.polylines(img, [run.reshape(-1, 1, 2)], False, colour, thickness, line_type)


def _with_last(arrays: Any) -> Any:
    """``(array, is_last)`` of the non-empty arrays of an iterable, one behind it (to know the last)."""
    held = None
    for a in arrays:
        if len(a):
            if held is not None:
                yield held, False
            held = a
    if held is not None:
        yield held, True


def _cut_extent(extent: np.ndarray, cut: np.ndarray, settings: MachineSettings) -> tuple[tuple[float, float], float]:
    """((width_mm, height_mm), depth_mm) of what is cut: the XY extent below the surface (the whole
    extent when nothing is), and the deepest Z."""
    use = cut if cut[2, 1] > 0 else extent
    span = use[:2, 1] - use[:2, 0]
    depth = max(0, int(extent[2, 1]))
    x, y, _ = settings.mm_per_step_axes
    return ((round(float(span[0]) * x, 3), round(float(span[1]) * y, 3)),
            round(depth * settings.mm_per_step_z, 4))


def _finish(job: PreparedJob) -> PreparedJob:
    """Fill the fields every kind computes the same way from the step plan."""

    job.extent_steps, cut = job.plan.motion_extent()  # one pass over the chunks
    if job.size_mm == (0.0, 0.0):
        job.size_mm, job.depth_mm = _cut_extent(job.extent_steps, cut, job.settings)
        surface = int(job.report.get("surface_z_steps", 0))  # a G-code program's Z = 0 below or above its start
        if surface:
            job.depth_mm = round(max(0, int(job.extent_steps[2, 1]) - surface) * job.settings.mm_per_step_z, 4)
    job.tool_changes = list(job.plan.pause_notes or [])
    for w in job.plan.warnings:
        if w not in job.warnings:
            job.warnings.append(w)
    job.report.setdefault("source", job.source)
    job.report.update({
        "kind": job.kind,
        "size_mm": list(job.size_mm),
        "depth_mm": job.depth_mm,
        "steps": {a: int(v) for a, v in zip("xyz", job.plan.steps_total)},
        "periods": int(job.plan.n_periods),
        "ramp": job.plan.settings.ramp,
        "tool_changes": list(job.tool_changes),
        "warnings": list(job.warnings),
    })
    return job


def own_zero_home(kind: str, options: JobOptions, machine_state: Optional[Any] = None
                  ) -> Optional[tuple[int, int, int]]:
    """Where (machine frame, steps) a drill, HPGL or SVG file placed by its own zero is planned from (issue #29
    point 1): with ``origin`` "file", or an ``offset_mm`` and no origin, the file's zero (or the point
    ``offset_mm`` from it) goes to the active work zero of ``machine_state`` (None: the home, a new machine's
    work zero), and its travel is checked in the machine frame from there, as a G-code program's is.  None for
    every other job (planned in its own frame, placed at the work zero by its extent when it runs)."""
    if not has(kind, "placed") or not own_zero(lambda name: getattr(options, name)):
        return None
    return (0, 0, 0) if machine_state is None else tuple(int(v) for v in machine_state.work_zero_steps())


def line_depth_mm(cutter: Any, width_mm: float) -> float:
    """The depth at which ``cutter`` (a V bit) cuts a line ``width_mm`` wide, at most :data:`MAX_MM`: CamError
    naming ``--line-width`` for a deeper one (a very sharp bit), so no depth downstream overflows."""
    depth_mm = cutter.depth_for_width_mm(width_mm)
    if not (math.isfinite(depth_mm) and depth_mm <= MAX_MM):
        raise CamError(f"--line-width: a {width_mm:g} mm line of a {cutter.describe()} is {depth_mm:.3g} mm deep, "
                       f"more than {MAX_MM:g} mm")
    return depth_mm


def engraving(options: JobOptions, settings: MachineSettings, default_depth_mm: float
              ) -> tuple[float, dict[str, Any]]:
    """A vector file's cut depth (mm) and the report's tool and line width: ``--line-width`` with a V bit sets
    the depth; a tool's groove at the depth is the line width."""
    cutter = parse_tool(options.tool, "--tool") if options.tool else tool_of_settings(settings.tool)
    depth_mm = default_depth_mm if options.cut_depth_mm is None else options.cut_depth_mm
    if options.line_width_mm is not None:
        depth_mm = line_depth_mm(cutter, options.line_width_mm)
    if cutter.is_point:
        return depth_mm, {}
    return depth_mm, {"tool": cutter.describe(), "line_width_mm": round(cutter.width_at_depth_mm(depth_mm), 4)}


def prepare_job(
    path: str | os.PathLike, options: Optional[JobOptions] = None, settings: MachineSettings = DEFAULT_SETTINGS,
    *, name: Optional[str] = None, progress: Optional[Any] = None, machine_state: Optional[Any] = None,
) -> PreparedJob:
    """Read a job file and plan it into steps.

    Args:
        path: a drawing, a digitized matrix, a G-code, Excellon, HPGL, SVG or DXF file (kind by suffix).
        options: how to cut it (:class:`JobOptions`); None = the defaults.
        settings: the machine settings.
        name: the name the summary gives the file (default: its file name).
        progress: ``progress(bytes_read, total_bytes)`` while an HPGL file streams in (large files).
        machine_state: G-code: the machine state (:class:`cam.drive.state.MachineState`) the program runs in:
            it starts where the tool stands, in the state's work offsets (None: at the home, offsets 0).  A
            drill, HPGL or SVG file placed by its own zero (``origin`` "file", or an ``offset_mm``): the state
            whose active work zero that zero goes to (:func:`own_zero_home`).  A job levelled to a height map
            (``options.level``): where it runs (placed at that state's active work zero; None: its home at the
            machine's (0, 0, 0)), the frame the map's X and Y are in.

    Returns:
        The :class:`PreparedJob`, planned relative to where the tool stands when it starts.

    A drawing larger than the machine's travel holds at its steps per pixel
    (:func:`cam.job.drawing.check_drawing_size`) is refused from its file's header, before it is decoded and
    traced.

    Raises:
        CamError: unknown file type, unreadable or bad file (file:line), bad options, travel exceeded.
    """
    p = Path(path)
    if not p.is_file() and p.suffix == "":
        raise CamError(f"{p}: file not found")
    kind_warnings: list[str] = []
    kind = forced_kind(options.kind) if options is not None and options.kind else job_kind(p, kind_warnings)
    the_kind = kind_named(kind)
    opts = (options or JobOptions()).checked().check_kind(kind, p.name)
    if "holes" not in the_kind.all_traits and settings.mm_per_step_axes[1] != settings.mm_per_step_xy:
        raise CamError(f"{p.name}: {the_kind.noun} is planned with one step for X and Y, and this "
                       f"machine's differ (X {settings.mm_per_step_xy:g} mm, Y {settings.mm_per_step_axes[1]:g} mm "
                       f"per step): only drill files run on it")
    home = own_zero_home(kind, opts, machine_state)
    if home is not None and opts.offset_mm is None:
        opts = dataclasses.replace(opts, offset_mm=(0.0, 0.0))  # the file's own zero at the work zero
    _refuse_surface_travel(opts, settings)
    if not p.is_file():
        raise CamError(f"{p}: file not found")
    height_map = _height_map(opts)  # a bad map: one line, before the file is planned
    job = the_kind.prepare(p, opts, settings, home=home, progress=progress, machine_state=machine_state)
    _refuse_nothing(job, opts, settings)
    job.warnings[:0] = kind_warnings
    job.name = name or p.name
    job.summary = job.name + job.summary[len(p.name):]
    job.identity = identity_of(p, opts, settings)
    # a drill, HPGL or SVG file placed by its own zero (origin "file", or an offset_mm and no origin) keeps that
    # origin where it runs, whichever front end asked (issue #45 point 5: the API placed offset_mm [0, 0] by the
    # holes' upper-left corner, the command line's --offset 0,0 by the file's zero)
    job.origin = "file" if home is not None else opts.origin
    if home is not None:
        job.home_steps = home
    if the_kind.runs_in_place:  # a program: from where the tool stood, in the work offsets it was planned in
        job.planned_in = PlannedIn((0, 0, 0)) if machine_state is None else \
            PlannedIn.of(machine_state, position=True, every_offset=True)
    elif home is not None and machine_state is not None:  # from the active work zero, wherever the tool stands
        job.planned_in = PlannedIn.of(machine_state, position=False, every_offset=False)
    if height_map is not None and job.probing is not None:
        raise PlanError(f"{p.name}: --level: the program probes ({job.probing.probes[0]}): its moves after a probe "
                        "are planned from where the probe touches, when it runs, and cannot be levelled before; "
                        "level it without its probes, or let its probes find the surface")
    if height_map is not None:  # where the job goes is known now: level it there (issue #46 point 2)
        _level(job, height_map, opts, settings, machine_state)
    job.plan_sha256 = job.plan.job_sha256 or plan_fingerprint(job.toolpath)  # (made in the planning pass)
    return _finish(job)


def default_origin(kind: str) -> str:
    """The point of a job of file kind ``kind`` placed at the work zero when no ``origin`` is chosen: the kind's
    :attr:`cam.kinds.Kind.default_origin` ("file" for drawings and digitized matrices, the thesis's top-left pixel),
    "upper-left" for moves of no file kind."""
    return kind_named(kind).default_origin if kind in kind_names() else "upper-left"


def origin_anchor_steps(kind: str, origin: Optional[str], plan: Any) -> tuple[int, int]:
    """The ``(x, y)`` point of a job of file ``kind`` (its own frame, steps) that ``origin`` puts at the work zero
    (:func:`cam.drive.placement.origin_anchor`): ``file`` its frame's zero, ``upper-left``, ``lower-left`` or
    ``center`` of what its ``plan`` (a :class:`~cam.motion.chunks.ChunkedPlan`) cuts, the XY extent of the tool
    below the surface (the whole extent when nothing is); None: ``file`` for drawings and digitized matrices,
    ``upper-left`` for the other kinds."""
    origin = origin or default_origin(kind)
    if origin == "file":
        return 0, 0
    extent, cut = plan.motion_extent()
    box = cut if cut[2, 1] > 0 else extent
    (x0, x1), (y0, y1) = (int(v) for v in box[0]), (int(v) for v in box[1])
    if origin == "upper-left":
        return x0, y0
    if origin == "lower-left":
        return x0, y1
    return (x0 + x1) // 2, (y0 + y1) // 2


def _height_map(options: JobOptions) -> Any:
    """The height map ``options.level`` names, read and checked (:func:`cam.job.heightmap_level.check_map`), or
    None."""
    if options.level is None:
        return None
    return check_map(load_height_map(options.level))


def _level(job: PreparedJob, hmap: Any, options: JobOptions, settings: MachineSettings,
           machine_state: Optional[Any]) -> None:
    """Level a prepared job to the height map ``hmap`` (of ``options.level``) where it runs (issue #46 point 2), in
    place: its toolpath becomes its levelled moves (:func:`cam.job.heightmap_level.level_job`: a piece at a time
    for a job kept as pieces) and its plan is made again from them.

    Where it runs, machine frame: a G-code program from where the tool stands, a file placed by its own zero from
    the active work zero (their ``home_steps``); any other job placed at the active work zero of ``machine_state``
    by its origin (:func:`origin_anchor_steps`, of the XY extent levelling leaves as it is), or without
    a machine state from the machine's (0, 0, 0), where a session without a state file starts.  The plan then
    holds there only (:attr:`PreparedJob.planned_in`; :attr:`PreparedJob.levelled_home_steps` is where the session
    places it).  A job reaching outside the probed area is refused here, before a move is levelled, naming how
    far outside and past which edge (unless ``level_extrapolate``: then a warning says so).
    """
    own_frame = job.home_steps is None  # planned in its own frame: placed at the work zero when it runs
    if not own_frame:
        home = tuple(int(v) for v in job.home_steps)  # type: ignore[union-attr]
    elif machine_state is None:
        home = (0, 0, 0)
    else:  # placed as cam.drive.placement.placed_home places it: its origin's anchor at the active work zero
        zero = machine_state.work_zero_steps()
        ax, ay = origin_anchor_steps(job.kind, job.origin, job.plan)
        home = (int(zero[0]) - ax, int(zero[1]) - ay, int(zero[2]))
    extent, _ = job.plan.motion_extent()
    mx, my, _ = settings.mm_per_step_axes
    xs = (home[0] + np.asarray(extent[0], np.int64)) * mx  # the job's XY extent (its start included), machine mm
    ys = (home[1] + np.asarray(extent[1], np.int64)) * my
    outside = outside_text(hmap, xs, ys, name_point=False)
    where = f"the job placed with its home at machine {list(home)} steps"
    if outside is not None and not options.level_extrapolate:
        raise PlanError(f"{options.level}: {outside} ({where}; the map covers X {hmap.x_mm[0]:g}..{hmap.x_mm[-1]:g}, "
                        f"Y {hmap.y_mm[0]:g}..{hmap.y_mm[-1]:g} mm): probe a larger area, or --level-extrapolate "
                        f"(the edge cells extended)")
    if outside is not None:
        job.warnings.append(f"levelled outside the probed area by extending its edge cells: {outside}")
    toolpath = level_job(job.toolpath, hmap, home, extrapolate=bool(options.level_extrapolate))
    plan_from = None if own_frame and machine_state is None else home
    job.plan = plan_chunks(toolpath, start_steps=plan_from, fingerprint=True)  # type: ignore[arg-type]
    job.toolpath = toolpath
    job.levelled_home_steps = home  # type: ignore[assignment]
    job.drill_plan = None  # a MAXIMUS board drills every hole at its own Z stroke: it cannot run a levelled job
    if plan_from is not None:
        job.home_steps = home  # type: ignore[assignment]
    if job.planned_in is None:  # the levelling holds where the job was levelled
        job.planned_in = PlannedIn.of(machine_state, position=False, every_offset=False) \
            if machine_state is not None else PlannedIn((0, 0, 0))
    off = hmap.offsets_mm()
    job.report["level"] = {
        "map": str(options.level), "points": int(off.size), "spacing_mm": hmap.spacing_mm,
        "area_mm": [float(hmap.x_mm[0]), float(hmap.y_mm[0]), float(hmap.x_mm[-1]), float(hmap.y_mm[-1])],
        "offset_mm": [round(float(off.min()), 4), round(float(off.max()), 4)], "home_steps": list(home),
        "extrapolated": outside is not None}
    job.summary += f", levelled to {Path(str(options.level)).name}"


def _refuse_surface_travel(options: JobOptions, settings: MachineSettings) -> None:
    """Refuse a travel height that rounds to 0 Z steps, the surface (issue #33 point 8), unless
    ``allow_surface_travel``: ``travel_height_mm`` 0 is refused with the options (:func:`cam.options.degenerate`),
    a height under half a Z step here, where the machine's step is known."""
    height = options.travel_height_mm
    if height is None or height <= 0 or options.allow_surface_travel:
        return
    if int(round(height / settings.mm_per_step_z)) == 0:
        raise CamError(f"a travel height of {height:g} mm is less than half a Z step ({settings.mm_per_step_z:g} mm): "
                       "the tool would travel between cuts at the surface, across the work; give a height of at "
                       "least one Z step, or --allow-surface-travel (the page: allow_surface_travel) if that is "
                       "meant")


def _refuse_nothing(job: PreparedJob, options: JobOptions, settings: MachineSettings) -> None:
    """Refuse a job that its scale or the machine's step size rounds to nothing (issue #33 point 8): the whole
    job moves 0 steps, or a drill, SVG or HPGL job of several holes or strokes puts them all on one X/Y step."""
    total = np.asarray(job.plan.steps_total, np.int64)
    cuts = "holes" if has(job.kind, "holes") else "strokes" if has(job.kind, "strokes") else ""
    n_cuts = int(job.report.get(cuts, 0)) if cuts else 0
    if total.any() and not (n_cuts > 1 and not total[:2].any()):
        return
    if options.scale is not None:
        cause = f"--scale {options.scale:g} makes it smaller than one step"
    elif options.fit_mm is not None:
        cause = f"--fit {options.fit_mm[0]:g}x{options.fit_mm[1]:g} makes it smaller than one step"
    else:
        cause = (f"the machine's steps ({settings.mm_per_step_xy:g} mm per X/Y step, {settings.mm_per_step_z:g} mm "
                 "per Z step) are larger than it")
    what = "moves 0 steps" if not total.any() else f"puts all its {n_cuts} {cuts} on one X/Y step"
    raise CamError(f"{job.source}: the job {what}: {cause}, so nothing would be cut as drawn")


def file_sha256(path: str | os.PathLike) -> str:
    """sha256 (hex) of a file's bytes, read in chunks (bounded memory)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            for chunk in iter(lambda: handle.read(1 << 20), b""):
                h.update(chunk)
    except OSError as exc:
        raise CamError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return h.hexdigest()


def identity_of(path: str | os.PathLike, options: JobOptions, settings: MachineSettings) -> str:
    """The identity of a job file planned with ``options`` and ``settings`` (:func:`cam.job.resume.job_identity`):
    the files an option names (a profile, a tool table) count by their bytes, not their paths."""
    values = asdict(options)
    files = {}
    for key in ("profile", "tool_table", "level"):
        if values.get(key):
            files[key] = file_sha256(values.pop(key))
    return job_identity(file_sha256(path), values, settings, files)


def resume_job(job: PreparedJob, journal: Journal, *, position_steps: Optional[tuple[int, int, int]] = None,
               where: str = "journal") -> PreparedJob:
    """The resumed run of a prepared job after the stop ``journal`` records (see :mod:`cam.job.resume`).

    Args:
        job: the same file planned again with the same options and settings (:func:`prepare_job`).
        journal: what the interrupted run's journal says (:func:`cam.drive.journal.read_journal`).
        position_steps: where the tool stands, steps from the job's home (default: the journal's position).
        where: what messages call the journal (its file name).

    Returns:
        A :class:`PreparedJob` planned relative to where the tool stands; its ``resumed`` says how its points
        map onto the job's moves, and its report gives ``resumed_at_move`` and ``start_position_steps``.

    Raises:
        CamError: the journal was written for another input, options, settings or plan, or its job finished.
    """
    if job.probing is not None:
        raise CamError(f"{job.name}: a program that probes cannot be resumed ({job.probing.probes[0]}): its moves "
                       "after a probe depend on where the probe touched in the run that stopped; run it again from "
                       "its start")
    start = tuple(int(v) for v in (journal.position_steps if position_steps is None else position_steps))
    # every number against the travel before anything is planned from them (a tampered journal: one line, at once)
    check_journal_numbers(dataclasses.replace(journal, position_steps=start), job.settings, where)
    check_journal(journal, job.identity, job.plan_sha256, where)
    if job.toolpath is None:
        raise CamError(f"{job.name}: a {job.kind} job has no moves to resume")
    resumed, move_index, j = resume_pieces(job.toolpath, journal.last_move, start,  # type: ignore[arg-type]
                                           pause_pending=journal.pause_pending)
    # a job held in memory is resumed in memory (its run reads every move at once: linear40 ramps, the
    # pictures); a job made a piece at a time is resumed a piece at a time
    toolpath = resumed.joined() if isinstance(job.toolpath, Job) else resumed
    # checked in the machine frame when the job was (a program's start, a work zero: its home_steps); a job planned
    # in its own frame by its span, and where it runs by the session (its extent from where the tool stands)
    steps = plan_chunks(toolpath, start_steps=None if job.home_steps is None else
                        tuple(h + s for h, s in zip(job.home_steps, start)))  # type: ignore[arg-type]
    base = JournalBase(identity=job.identity, plan_sha256=job.plan_sha256, source=job.source,
                       moves=resumed.job_moves, move_index=move_index, last_move=journal.last_move,
                       pause_pending=journal.pause_pending, resumed_at_move=j,
                       start_position_steps=start)  # type: ignore[arg-type]
    report = dict(job.report)
    report.update(resumed_at_move=j, start_position_steps=list(start), resumed_from_state=journal.state)
    out = PreparedJob(
        source=job.source, kind=job.kind, plan=steps, settings=job.settings, toolpath=toolpath, name=job.name,
        size_mm=job.size_mm, depth_mm=job.depth_mm, warnings=list(job.warnings),
        summary=f"{job.summary}, resumed at move {j} of {resumed.job_moves}", report=report,
        drawing_rgb=job.drawing_rgb, identity=job.identity, plan_sha256=job.plan_sha256, resumed=base,
        origin=job.origin, home_steps=job.home_steps, levelled_home_steps=job.levelled_home_steps,
    )
    return _finish(out)
