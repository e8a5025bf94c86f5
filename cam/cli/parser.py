"""The argument parser of every command: argparse and light constants only.

``cam --help`` and ``cam COMMAND --help`` finish here, so this module imports
nothing heavier than the standard library, :mod:`cam.settings` (for the ramp
modes), :mod:`cam.choices` (file suffixes) and :mod:`cam.options` (the job
options: every job option's flag, type, range and help is made from its one
declaration there, by :func:`_add_option`): no numpy, numba, OpenCV or web
stack.  The commands themselves live in the modules that
:data:`cam.cli.COMMANDS` names.
"""
from __future__ import annotations

import argparse
import math
import re
from typing import Callable, Optional, Sequence

from .. import __version__
from ..kinds import kind, kinds, job_options
from ..choices import (
    IMAGE_SUFFIXES, PROFILE_SUFFIXES, DEFAULT_PORT, POSTS,
)
from ..drive.maximus.switch_options import add_maximus_switch_options
from ..options import MAX_MM, OPTIONS, Option, check_range
from ..settings import RAMP_MODES

JOG_UNIT_NAMES = ("steps", "full-steps", "0.1mm", "mm", "0.1in")
"""The jog units (the same as :data:`cam.job.moves.JOG_UNITS`, kept here so that --help loads no numpy)."""

__all__ = ["build_parser", "EXIT_BAD_INPUT", "EXIT_INTERRUPTED"]

EXIT_BAD_INPUT = 2
"""Exit code of bad input (options, files, ports): one line on stderr, never a traceback."""
EXIT_INTERRUPTED = 130
"""Exit code of a job stopped before its end (Ctrl-C, a stop at a prompt)."""


def _listed(suffixes: Sequence[str]) -> str:
    return " ".join(suffixes)


def _words(items: Sequence[str]) -> str:
    """``a, b or c``."""
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " or " + items[-1]


def _kinds_with(trait: str) -> list:
    return [k for k in kinds() if trait in k.all_traits]


def _suffixes_of(trait: str) -> str:
    """The suffixes of the kinds with ``trait``, for a group's title."""
    return " ".join(_listed(k.suffixes) for k in _kinds_with(trait))


def _titles_of(trait: str) -> str:
    """``SVG and DXF``: the titles of the kinds with ``trait``."""
    titles = [k.title for k in _kinds_with(trait)]
    return titles[0] if len(titles) == 1 else ", ".join(titles[:-1]) + " and " + titles[-1]


def _file_kinds_help() -> str:
    """The files a job command or info takes as its positional argument, by kind (every kind of
    :mod:`cam.kinds` but the digitized matrix, which each command names on its own)."""
    return _words([f"{k.listed_as} ({_listed(k.suffixes)})" for k in kinds() if k.name != "digitized"])


def _drill_description() -> str:
    """What ``cam drill`` does with each kind (each kind's :attr:`cam.kinds.Kind.help`)."""
    said = "; ".join(f"{k.listed_as} ({_listed(k.suffixes)}) {k.help}" for k in kinds() if k.name != "digitized")
    return said[:1].upper() + said[1:] + "."


NEGATIVE_VALUE = re.compile(r"^-\.?\d[0-9.,;:eE+-]*$")
"""A word argparse takes as a value, not an option, though it starts with ``-``: a negative number or a list
of numbers that starts with one (``-200,20,0``, ``-1.5,-2``, ``-1e3``, ``-1,-1;2,2``).  argparse's own rule
takes only a single plain negative number (``-5``, ``-.5``), so ``cam where --set -200,20,0`` and ``cam goto
-10,0,0`` were refused as unknown options (issue #44 point 7).  No flag of cam starts with ``-`` and a digit."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2), and values that start with a negative number
    (:data:`NEGATIVE_VALUE`) taken as values after an option or as positionals, never as unknown options."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._negative_number_matcher = NEGATIVE_VALUE

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


MAX_WHOLE = 10**9
"""The largest whole number any option takes (pixels, steps, passes): beyond it no machine has travel."""


def _whole(name: str, lo: int, hi: int = MAX_WHOLE) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes a whole number, got '{text}'") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be {lo}..{hi}, got {value}")
        return value

    return parse


def _number(name: str, lo: float, hi: float, *, above: bool = False) -> Callable[[str], float]:
    """A finite number in ``lo..hi`` (``above``: greater than ``lo``, not equal to it), so no inf or nan reaches a
    plan, a file or a report."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes a number, got '{text}'") from None
        if not math.isfinite(value) or not (lo < value if above else lo <= value) or not value <= hi:
            wanted = f"> {lo:.15g} and at most {hi:.15g}" if above else f"a number {lo:g}..{hi:g}"
            raise argparse.ArgumentTypeError(f"{name} must be {wanted}, got '{text}'")
        return value

    return parse


def _int_list(n: Optional[int], name: str, minimum: Optional[int] = None) -> Callable[[str], list[int]]:
    def parse(text: str) -> list[int]:
        try:
            values = [int(v) for v in text.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes whole numbers separated by commas, got '{text}'") from None
        if n is not None and len(values) != n:
            raise argparse.ArgumentTypeError(f"{name} takes {n} comma-separated numbers, got '{text}'")
        if minimum is not None and any(v < minimum for v in values):
            raise argparse.ArgumentTypeError(f"{name} values must be >= {minimum}, got '{text}'")
        if any(abs(v) > MAX_WHOLE for v in values):
            raise argparse.ArgumentTypeError(f"{name} values must be at most {MAX_WHOLE} either way, got '{text}'")
        return values

    return parse


def _float_pair(name: str) -> Callable[[str], list[float]]:
    def parse(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes two numbers separated by a comma, got '{text}'") from None
        if len(values) != 2 or any(not (0 < v <= 60_000) for v in values):
            raise argparse.ArgumentTypeError(f"{name} takes two positive numbers XY,Z, got '{text}'")
        return values

    return parse


# -- the job options of cam.options, as flags ------------------------------------------------------


def _in_range(o: Option, flag: str, value: object, text: str) -> None:
    """Refuse a value out of ``o``'s range: :func:`cam.options.check_range`, the one range check (JobOptions asks
    it too), in its words."""
    why = check_range(o, value)
    if why is not None:
        raise argparse.ArgumentTypeError(f"{flag} {why}, got '{text}'")


def _schema_number(o: Option, flag: str, whole: bool = False) -> Callable[[str], float]:
    """A number (``whole``: a whole number) in ``o``'s range (finite: no inf or nan reaches a plan, a file or a
    report)."""
    def parse(text: str) -> float:
        try:
            value = int(text) if whole else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} takes a {'whole ' if whole else ''}number, got '{text}'") \
                from None
        _in_range(o, flag, value, text)
        return value

    return parse


def _schema_list(o: Option, flag: str, whole: bool, separator: str = ",",
                 shape: str = "") -> Callable[[str], list]:
    """``o.count`` (or one or more) numbers separated by ``separator``, each in ``o``'s range."""
    what = "whole numbers" if whole else "numbers"
    shape = shape or separator.join("N" * (o.count or 1))

    def parse(text: str) -> list:
        parts = text.lower().split(separator) if separator != "," else text.split(",")
        try:
            values = [int(v) if whole else float(v) for v in parts]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} takes {what} as {shape}, got '{text}'") from None
        if o.count is not None and len(values) != o.count:
            raise argparse.ArgumentTypeError(f"{flag} takes {o.count} {what} as {shape}, got '{text}'")
        _in_range(o, flag, values, text)
        return values

    return parse


def _add_option(container: argparse._ActionsContainer, name: str, flag: Optional[str] = None,
                hidden: Sequence[str] = (), **overrides: object) -> argparse.Action:
    """Add the job option ``name`` of :data:`cam.options.OPTIONS` as its flag: its type and range, metavar and
    help come from the schema (``overrides``: argparse keywords that differ on this command, such as its help;
    ``hidden``: old spellings this command still accepts, besides the option's own aliases)."""
    o = next(o for o in job_options() if o.name == name)  # its kinds and choices from the file kinds (cam.kinds)
    flag = flag or o.flag
    kw: dict = {"help": o.help}
    if o.metavar:
        kw["metavar"] = o.metavar
    if o.type == "whole":
        kw["type"] = _schema_number(o, flag, whole=True)
    elif o.type == "number":
        kw["type"] = _schema_number(o, flag)
    elif o.type in ("wholes", "numbers"):
        kw["type"] = _schema_list(o, flag, o.type == "wholes")
    elif o.type == "points":
        kw.update(type=_schema_list(o, flag, True), action="append")
    elif o.type == "digits":
        kw["type"] = _schema_list(o, flag, True, ":", "I:F")
    elif o.type == "size":
        kw["type"] = _schema_list(o, flag, False, "x", "WIDTHxHEIGHT in mm, such as 80x40")
    elif o.type == "choice":
        kw["choices"] = o.choices
    elif o.type == "flag":
        kw["action"] = "store_true"
    elif o.type == "tool":
        kw["type"] = _tool_text
    elif o.type == "paths":
        kw["action"] = "append"
    kw.update(overrides)
    action = container.add_argument(flag, **kw)
    for alias in (*(o.aliases if flag == o.flag else ()), *hidden):
        # an older spelling: still accepted (same dest, type and range), not shown in --help, so the help and
        # the docs have one name per setting
        container.add_argument(alias, **{**kw, "dest": action.dest, "default": action.default,
                                         "help": argparse.SUPPRESS})
    return action


# -- option groups shared by several commands -----------------------------------------------------


def _add_machine_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("machine")
    g.add_argument("--machine", metavar="FILE.toml", help="machine settings file (default: the thesis machine)")
    g.add_argument(
        "--steps-per-pixel", metavar="XY,Z", type=_int_list(2, "--steps-per-pixel", 1),
        help="motor steps per drawing pixel for X/Y and for Z (default 8,1)",
    )
    g.add_argument(
        "--delay", metavar="XY_MS,Z_MS", type=_float_pair("--delay"),
        help="step period of the X/Y and of the Z motors in ms (default 5,5)",
    )
    g.add_argument(
        "--ramp", choices=RAMP_MODES,
        help="speed ramps: lookahead (default: accelerate and keep speed through the path), linear40 "
        "(the standalone controller's 40-step delay ramp per move) or constant (the thesis: no ramp)",
    )


def _add_digitize_options(p: argparse.ArgumentParser) -> None:
    _add_option(p, "start")


def _add_profile_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("3D depth profile (for drawings with a red interior; one of the two)")
    _add_option(g, "profile")  # not both: a rule of cam.options.RULES, checked by cam.cli.checks
    _add_option(g, "profile_expr")


def _tool_text(text: str) -> str:
    """--tool: checked here so a bad one is a usage error naming the option."""
    from ..errors import CamError
    from ..tool import parse_tool

    try:
        parse_tool(text, "--tool")
    except CamError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--tool: ")) from None
    return text


def _add_tool_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(f"the cutter (drawings; --tool and --line-width also {_titles_of('strokes')})")
    for name in ("tool", "line_width_mm", "stepdown_mm", "stepover", "rough_tool"):
        _add_option(g, name)


def _add_excellon_options(d: argparse.ArgumentParser) -> None:
    g = d.add_argument_group(f"drill files that do not say their number format (Excellon: "
                             f"{_listed(kind('excellon').suffixes)})")
    for name in ("excellon_units", "excellon_digits", "excellon_zeros"):
        _add_option(g, name)
    for name in ("kind", "strict", "mill_holes_over_mm"):  # issue #31: the kind forced, bad tools, large holes
        _add_option(g, name)


def _add_svg_options(d: argparse.ArgumentParser, scale: bool = True) -> None:
    g = d.add_argument_group(f"{_titles_of('layers')} files ({_suffixes_of('layers')}; --cut-depth default "
                             f"{OPTIONS['cut_depth_mm'].default_for({'strokes'})}, --offset places the page or "
                             "drawing origin)")
    if scale:
        _add_option(g, "scale")
    _add_option(g, "fit_mm")
    for name in ("layers", "pause_between_layers", "keep_duplicates"):  # issue #31 point 6
        _add_option(g, name)


def _add_cut_options(d: argparse.ArgumentParser) -> None:
    g = d.add_argument_group("depths and heights in mm (one name on every file kind and on the web page)")
    _add_option(g, "cut_depth_mm")
    _add_option(g, "travel_height_mm")
    _add_option(g, "allow_surface_travel")
    f = d.add_argument_group(f"{_titles_of('placed')} files ({_suffixes_of('placed')})")
    for name in ("offset_mm", "mirror_x", "drill_order"):
        _add_option(f, name)
    _add_excellon_options(d)


def _add_progress_options(g: argparse._ActionsContainer) -> None:
    bar = g.add_mutually_exclusive_group()
    bar.add_argument("--progress", action="store_true",
                     help="show the progress bar even when stderr is not a terminal (default: on a terminal only)")
    bar.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_state_option(g: argparse._ActionsContainer, holds: bool = True) -> None:
    """--state: the machine state file (every command that moves the machine or reads where it is); ``holds``:
    the command holds the machine (and takes --machine-changed)."""
    g.add_argument("--state", metavar="FILE.json",
                   help="the machine state file: where the machine stands, its work offsets and its machine file, "
                   "kept from one command to the next and locked while one drives the machine (default: "
                   "$XDG_STATE_HOME/cam/ or ~/.local/state/cam/: on a real port named after the port, e.g. "
                   "grbl-dev-ttyUSB0.json; on the mock after --machine too, e.g. default-mock.json). On a real "
                   "port a missing file means the position is unknown")
    if holds:
        g.add_argument("--machine-changed", action="store_true",
                       help="the machine on this port changed: record this --machine (or the built-in settings) in "
                       "the port's state file instead of the one it records, the position then unknown (without "
                       "it another machine file on a real port is refused; without --machine the recorded one is "
                       "used)")


def _add_view_state(p: argparse.ArgumentParser) -> None:
    """--port and --state of info, preview and export: a G-code program (or a file placed by its own zero, or a job
    levelled to a height map) is planned from that machine's active work zero, as cam drill would run it (its state
    file is read, never changed)."""
    g = p.add_argument_group("the machine it would run on")
    g.add_argument("--port", default=DEFAULT_PORT, help="names the default state file, as cam drill's --port")
    _add_state_option(g, holds=False)


def _float_triple(name: str) -> Callable[[str], list[float]]:
    """X,Y,Z: three finite numbers, each at most MAX_WHOLE either way."""
    def parse(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes three numbers separated by commas, got '{text}'") from None
        if len(values) != 3 or not all(math.isfinite(v) and abs(v) <= MAX_WHOLE for v in values):
            raise argparse.ArgumentTypeError(f"{name} takes three numbers X,Y,Z (at most {MAX_WHOLE} either way), "
                                             f"got '{text}'")
        return values

    return parse


def _add_job_options(d: argparse.ArgumentParser) -> None:
    """Options that say what to cut and how deep (shared by drill, export and preview)."""
    d.add_argument("image", nargs="?", metavar="IMAGE",
                   help=f"the file: {_file_kinds_help()}; a digitized matrix ({_listed(kind('digitized').suffixes)}) "
                   "goes with --load-digitized")
    d.add_argument("--load-digitized", metavar="FILE",
                   help=f"reuse a saved digitized matrix ({_listed(kind('digitized').suffixes)}) instead of digitizing")
    _add_digitize_options(d)
    _add_option(d, "depth")
    _add_profile_options(d)
    _add_tool_options(d)
    for name in ("passes", "start_at", "pause_at", "origin"):
        _add_option(d, name)
    sk = d.add_argument_group("sketches and photos (drawings)")
    _add_option(sk, "trace", default=None)
    _add_option(sk, "trace_min_length_px")
    _add_option(sk, "trace_fill", default=None)
    hm = d.add_argument_group("grey-level reliefs (height maps)")
    for name in ("heightmap", "invert", "max_depth_mm", "pixel_size_mm", "heightmap_order"):
        _add_option(hm, name)
    lv = d.add_argument_group("levelling to a probed surface (every file kind)")
    for name in ("level", "level_extrapolate"):
        _add_option(lv, name)
    _add_machine_options(d)
    _add_gcode_options(d)


def _add_gcode_options(d: argparse.ArgumentParser) -> None:
    """Options of G-code programs (LinuxCNC's tool table, subroutine files, the line limit)."""
    g = d.add_argument_group("G-code programs")
    for name in ("tool_table", "subroutine_path", "max_lines"):
        _add_option(g, name)


# -- one function per command ------------------------------------------------------------------------


def _add_drill(sub: argparse._SubParsersAction) -> None:
    d = sub.add_parser(
        "drill", help=f"cut {_words([k.title for k in kinds() if k.name != 'digitized'])} files (mock port by "
        "default)",
        description="Plan a file's job in machine steps and send it to a port (a saved digitized matrix is cut as "
        f"its drawing). {_drill_description()} "
        "The default port is the logging mock, so nothing moves unless you name a real port.",
    )
    _add_job_options(d)
    g = d.add_argument_group("port and outputs")
    g.add_argument("--port", default=DEFAULT_PORT, help="'mock' (default: logs, moves nothing), a device like /dev/parport0, "
                   "maximus:/dev/ttyUSB0 (drill files), or grbl:/dev/ttyUSB0[?baud=115200] (a grbl board: the job "
                   "streams to it as G-code)")
    g.add_argument("--realtime", action="store_true", help="run the mock in real time, sleeping like the real port")
    g.add_argument("--feed-override", type=_number("--feed-override", 10, 200), metavar="PERCENT",
                   help="grbl ports: grbl's feed override for this job, 10..200 %% (its real-time override bytes; "
                   "the page can change it while the job runs)")
    _add_state_option(g)
    g.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log (t_ns,data,strobe)")
    g.add_argument("--save-digitized", metavar="FILE", help="save the digitized matrix")
    g.add_argument("--report", metavar="FILE.json", help="write the job report as JSON")
    g.add_argument("--journal", metavar="FILE.json",
                   help="keep the job's journal here (how far it got, where the tool stands), updated as it runs, "
                   "for --resume; default: next to --report or --pin-log (NAME.journal.json), on a real port "
                   "IMAGE.journal.json in the current folder, on the mock without outputs none")
    g.add_argument("--resume", metavar="JOURNAL",
                   help="go on with a job that was stopped: give the same file and options; the tool lifts, travels "
                   "to the first uncut point and plunges there (the journal keeps being updated)")
    g.add_argument("--preview", metavar="OUT.png", help="write the toolpath picture before cutting")
    _add_option(g, "flip_y")
    g.add_argument("--yes", action="store_true", help="answer every prompt (tool changes, pauses) with Enter")
    g.add_argument("--spindle", choices=("on", "off"),
                   help="MAXIMUS board: run the spindle while drilling (default on; off for a dry run)")
    g.add_argument("--keep-offsets", action="store_true",
                   help="G-code: keep the work offsets the program sets (G10 L2/L20) in the machine state after it "
                   "finishes (default: they hold for the program only)")
    _add_cut_options(d)
    _add_svg_options(d)
    _add_progress_options(g)


def _add_export(sub: argparse._SubParsersAction) -> None:
    e = sub.add_parser(
        "export", help="write the job as RS-274/NGC G-code (grbl, LinuxCNC)",
        description="Plan a job exactly as 'drill' would and write it as G-code in mm. Machine Y grows upward, "
        "image rows downward: by default Y = -row (the drawing stays upright); --flip-y writes Y = +row.",
    )
    _add_job_options(e)
    _add_cut_options(e)
    _add_svg_options(e)
    e.add_argument("-o", "--output", required=True, metavar="FILE.ngc", help="where to write the G-code")
    _add_option(e, "flip_y", help="write Y = +row (mirrored) instead of Y = -row (every file kind)")
    _add_view_state(e)  # where a --level job is levelled: that machine's active work zero
    t = e.add_argument_group("the target (issue #30 point 4; docs/file-formats.md)")
    t.add_argument("--post", choices=POSTS, default="generic",
                   help="the controller the program is for: tool changes as T<n> M6 (linuxcnc, generic) or a "
                   "comment and an M0 pause (grbl); default generic")
    t.add_argument("--feed", type=_number("--feed", 0, 1e6, above=True), metavar="MM_PER_MIN",
                   help="X/Y feed in mm/min (default: the machine settings' X/Y rate)")
    t.add_argument("--plunge-feed", type=_number("--plunge-feed", 0, 1e6, above=True), metavar="MM_PER_MIN",
                   help="Z feed in mm/min (default: the machine settings' Z rate)")
    t.add_argument("--spindle-rpm", type=_number("--spindle-rpm", 0, 1e6, above=True), metavar="RPM",
                   help="start the spindle with M3 S<RPM> before the first move, stop it with M5 at the end")
    t.add_argument("--snap", action="store_true",
                   help="write every point at this machine's steps, even where the file gives it exactly")
    t.add_argument("--arc-tolerance", type=_number("--arc-tolerance", 0, 10), default=0.01, metavar="MM",
                   help="fit lines and G2/G3 arcs to the cutting moves within this many mm (default 0.01; "
                   "0: one G1 a point)")


def _add_preview(sub: argparse._SubParsersAction) -> None:
    pv = sub.add_parser(
        "preview", help="draw the job (or the surface it would cut) as PNG or SVG",
        description="Draw the job over its drawing: cutting moves coloured by depth, moves above the surface "
        "dashed, start and end marked, size, depth range and time in a legend. --surface draws the surface "
        "the job would cut (run on the mock, decoded, carved with a point tool) as a shaded depth map. A height map "
        "(cam probe grid --out MAP.json) is drawn as a colour scale of its heights with the probed points, and with "
        "--over FILE the job's cuts over it.",
    )
    _add_job_options(pv)
    _add_cut_options(pv)
    _add_option(pv, "flip_y")
    pv.add_argument("-o", "--output", required=True, metavar="OUT.png|OUT.svg", help="picture to write")
    pv.add_argument("--surface", action="store_true", help="draw the cut surface instead of the toolpath")
    pv.add_argument("--over", metavar="FILE",
                    help="with a height map (cam probe grid --out MAP.json) as the file: draw this job's cuts over the "
                    "map where cam drill would run it (the active work zero, --origin as drill's)")
    _add_view_state(pv)
    _add_option(pv, "scale", metavar="N",
                help="picture pixels per drawing pixel, 1..64 (default: automatic); for an SVG file, its scale "
                "as in drill")
    _add_svg_options(pv, scale=False)


def _add_digitize(sub: argparse._SubParsersAction) -> None:
    z = sub.add_parser("digitize", help="digitize a drawing and save the digitized matrix",
                       description="Digitize a drawing and save its digitized matrix for later jobs (--load-digitized).")
    z.add_argument("image", metavar="IMAGE", help=f"the drawing ({_listed(kind('drawing').suffixes)})")
    z.add_argument("-o", "--output", required=True, metavar="FILE",
                   help=f"where to write the matrix ({_listed(kind('digitized').suffixes)})")
    _add_digitize_options(z)


def _add_info(sub: argparse._SubParsersAction) -> None:
    readers = [k for k in kinds() if k.info is not None]
    i = sub.add_parser("info", help=f"print the report of {_words([k.listed_as for k in readers])}",
                       description="Print what a file holds: for a drawing its size in pixels and mm, its object "
                       "count and warnings; for a drill file its tools (diameter, hole count), extent and warnings; "
                       "for a plotter file its strokes, pens, extent and unknown commands; for a vector drawing its "
                       "strokes, layers and size; for a G-code file its moves, cut area, depth and machine time "
                       f"(the files: {_words([f'{k.listed_as} ({_listed(k.suffixes)})' for k in readers])}); for a "
                       "height map (cam probe grid --out MAP.json) its grid, area, heights and largest neighbour "
                       "difference. "
                       f"A saved digitized matrix ({_listed(kind('digitized').suffixes)}) is not read here: cut it with "
                       "'cam drill --load-digitized FILE'.")
    i.add_argument("image", metavar="IMAGE",
                   help=f"{_file_kinds_help()}; not a digitized matrix ({_listed(kind('digitized').suffixes)})")
    _add_digitize_options(i)
    _add_machine_options(i)
    _add_profile_options(i)
    _add_gcode_options(i)
    i.add_argument("--json", action="store_true", help="print the report as JSON (every file kind)")
    _add_excellon_options(i)
    _add_view_state(i)


def _add_trace(sub: argparse._SubParsersAction) -> None:
    t = sub.add_parser(
        "trace", help="turn a scanned sketch or a photo of a drawing into a drawing (1-pixel black curves)",
        description="Trace a pencil or ink sketch (a scan or a phone photo: dark lines on light paper) into a "
        "drawing that follows the thesis rules: the paper's uneven light is flattened, the lines are found by an "
        "adaptive threshold and thinned to 1-pixel centre lines, specks and spurs shorter than --trace-min-length "
        "are removed, junctions are split so that no pixel has more than two black neighbours, and nothing "
        "touches the border. --trace-fill makes every closed region red (a 3D drawing). The result is ready for "
        "'cam drill' (whose --trace does the same in one step, with the same two options).",
    )
    t.add_argument("image", metavar="PHOTO", help=f"the sketch ({_listed(IMAGE_SUFFIXES)})")
    t.add_argument("-o", "--output", required=True, metavar="DRAWING.png",
                   help="where to write the drawing (.png, .bmp or .tif: never JPEG, which blurs 1-pixel lines)")
    # the job options of 'drill --trace', under the same names (--min-length and --fill: their old spellings)
    _add_option(t, "trace_min_length_px", hidden=("--min-length",), default=OPTIONS["trace_min_length_px"].default,
                help="remove specks and spurs shorter than this many pixels (default 10)")
    _add_option(t, "trace_fill", hidden=("--fill",), help="make the regions enclosed by curves red (3D drawing)")
    t.add_argument("--max-side", type=_whole("--max-side", 16, 32768), default=1000, metavar="PX",
                   help="shrink a larger photo to this many pixels on its longer side first (default 1000)")


def _add_profile(sub: argparse._SubParsersAction) -> None:
    pr = sub.add_parser("profile", help="print a Z profile's layer count and depth range",
                        description="Read a profile drawing or CSV and print its layer count and depth range.")
    pr.add_argument("profile", metavar="PROFILE",
                    help=f"a profile drawing or a CSV of depths ({_listed(PROFILE_SUFFIXES)})")
    _add_machine_options(pr)


def _add_jog(sub: argparse._SubParsersAction) -> None:
    jg = sub.add_parser("jog", help="move one axis by a number of steps (to set the board origin)",
                        description="Jog one axis, as the MAXIMUS jog screen does: 'cam jog X+ 100' moves X by "
                        "+100 steps from where the machine state file says the tool stands (refused when it would "
                        "leave the travel), and records where it ended. On a MAXIMUS board "
                        "(--port maximus:/dev/ttyUSB0) this is its Jog mode.")
    jg.add_argument("axis", metavar="AXIS", help="X+, X-, Y+, Y-, Z+ (down) or Z- (up)")
    jg.add_argument("steps", type=_number("STEPS", 0.0, float(MAX_WHOLE)), metavar="STEPS",
                    help="how far (> 0), in --unit")
    jg.add_argument("--unit", choices=JOG_UNIT_NAMES, default="steps",
                    help="steps (default: machine steps, a MAXIMUS clock pulse), full-steps (motor steps), "
                    "0.1mm, mm or 0.1in (2.54 mm): the MAXIMUS Jog screen's units")
    jg.add_argument("--port", default=DEFAULT_PORT, help="'mock' (default), /dev/parport0, maximus:/dev/ttyUSB0 or "
                    "grbl:/dev/ttyUSB0")
    _add_state_option(jg)
    _add_machine_options(jg)
    jg.add_argument("--realtime", action="store_true", help="run the mock in real time")
    jg.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log")
    _add_progress_options(jg)


def _add_emulate_maximus(sub: argparse._SubParsersAction) -> None:
    em = sub.add_parser("emulate-maximus", help="run the MAXIMUS firmware emulator on a pseudo-terminal",
                        description="Serve the MAXIMUS PIC firmware emulator on a pty and print its device path; "
                        "point --port maximus:PATH at it. Ctrl-C ends it.")
    em.add_argument("--speed", type=_number("--speed", 1e-3, 1e6), default=1.0, help="firmware time per real time (1 = real time)")
    em.add_argument("--log", metavar="FILE.csv",
                    help="write one row per drilled hole: hole,x_halfsteps,y_halfsteps,z_bottom_halfsteps,spindle "
                    "(half steps from the emulator's power-up position, Y up, Z height)")
    add_maximus_switch_options(em)  # the simulator's limit switches


def _add_emulate_grbl(sub: argparse._SubParsersAction) -> None:
    em = sub.add_parser("emulate-grbl", help="run a grbl 1.1 controller emulator on a pseudo-terminal",
                        description="Serve a grbl 1.1 emulator on a pty and print its device path; point "
                        "--port grbl:PATH at it. Ctrl-C ends it (docs/grbl.md).")
    em.add_argument("--speed", type=_number("--speed", 1e-3, 1e6), default=1.0, help="machine time per real time (1 = real time)")
    em.add_argument("--set", action="append", default=[], metavar="N=VALUE", help="a $ setting, e.g. --set 22=1 (repeatable)")
    em.add_argument("--log", metavar="FILE.csv", help="write one row per executed block (machine coordinates, mm)")
    em.add_argument("--probe-surface", metavar="Z0,AX,AY,B,CX,CY",
                    help="the surface its probe touches (G38.2): z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2), grbl's "
                    "machine mm, missing trailing values 0 (write --probe-surface=-5,0.01)")


def _add_goto(sub: argparse._SubParsersAction) -> None:
    gt = sub.add_parser("goto", help="move the tool to X,Y,Z of the active work offset and stop there",
                        description="Go To (thesis 4.1.2): from where the machine state file says the tool stands, "
                        "lift to the work zero's Z (or stay higher), travel to X,Y, then move Z, and stop. X,Y,Z are "
                        "in the active work offset's frame (cam zero, cam where), or the machine's with "
                        "--machine-coords; +Y toward the operator, +Z deeper. Checked against the machine travel "
                        "before anything moves.")
    gt.add_argument("position", metavar="X,Y,Z", type=_float_triple("X,Y,Z"))
    gt.add_argument("--unit", choices=("px", "mm", "steps"), default="px",
                    help="unit of X,Y,Z: px (default: drawing pixels, --steps-per-pixel), mm or machine steps")
    gt.add_argument("--machine-coords", action="store_true",
                    help="X,Y,Z in the machine frame (from the machine's home) instead of the active work offset's")
    _add_machine_options(gt)
    gt.add_argument("--port", default=DEFAULT_PORT, help="'mock' (default), a device like /dev/parport0, "
                    "maximus:/dev/ttyUSB0 or grbl:/dev/ttyUSB0")
    _add_state_option(gt)
    gt.add_argument("--realtime", action="store_true", help="run the mock in real time")
    gt.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log")
    _add_progress_options(gt)


OFFSET_CHOICES = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
"""The work offsets (the same as :data:`cam.drive.state.OFFSET_NAMES`, kept here so that --help loads nothing)."""


def _add_state_machine(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", default=DEFAULT_PORT, help="'mock' (default), /dev/parport0, maximus:/dev/ttyUSB0 or "
                   "grbl:/dev/ttyUSB0: names the default state file (on grbl: the board is asked where it stands, "
                   "cam zero also sets grbl's own offset with G10 L20, cam where --set unlocks it there)")
    _add_state_option(p)
    _add_machine_options(p)


def _add_where(sub: argparse._SubParsersAction) -> None:
    w = sub.add_parser("where", help="where the machine stands: machine and work position, offsets, homed",
                       description="Print where the machine state file says the tool stands, in the machine frame "
                       "(from the machine's home) and in the active work offset's, in mm and steps; whether the "
                       "position is known and the machine homed. --set declares where the tool is.")
    w.add_argument("--json", action="store_true", help="print it as JSON")
    w.add_argument("--set", type=_float_triple("--set"), metavar="X,Y,Z",
                   help="the tool is at X,Y,Z machine mm (+Z deeper): recorded, the position known again (after "
                   "a killed command, a power cut or an emergency stop)")
    w.add_argument("--use", choices=OFFSET_CHOICES, metavar="G54..G59.3",
                   help="make this work offset the active one (nothing moves)")
    _add_state_machine(w)


def _add_zero(sub: argparse._SubParsersAction) -> None:
    z = sub.add_parser("zero", help="set the work zero where the tool stands (or --at a machine point)",
                       description="Set the zero of the active work offset (or --offset) on the given axes where "
                       "the tool stands now: 'cam zero' then 'cam goto 0,0,0' comes back here. Nothing moves.")
    z.add_argument("axes", nargs="?", default="XYZ", metavar="AXES", help="X, Y, Z, XY or XYZ (default XYZ)")
    z.add_argument("--offset", choices=OFFSET_CHOICES, metavar="G54..G59.3",
                   help="the work offset to set (default: the active one; it does not become active: cam where --use)")
    z.add_argument("--at", type=_float_triple("--at"), metavar="X,Y,Z",
                   help="set the zero at X,Y,Z machine mm instead of where the tool stands")
    _add_state_machine(z)


def _add_home(sub: argparse._SubParsersAction) -> None:
    h = sub.add_parser("home", help="find the home switches and set the machine's zero there",
                       description="Home the machine (LinuxCNC's pattern): each axis of [homing] order in the "
                       "machine file (Z first by default) seeks its home switch ([inputs] home_x, ...) at its search "
                       "speed, backs off until it opens, comes back at the slow latch speed, and the machine "
                       "coordinate there is its [homing] offset. The position is then known and homed. Works while "
                       "the position is unknown. On the mock the switches are simulated at the machine file's "
                       "[mock] places.")
    h.add_argument("--axes", type=_axes_text, metavar="AXES",
                   help="home only these axes, in this order (e.g. Z, XY; default: [homing] order)")
    h.add_argument("--port", default=DEFAULT_PORT, help="'mock' (default: [mock] simulated switches), /dev/parport0, or "
                   "grbl:/dev/ttyUSB0 (grbl's own homing cycle $H)")
    _add_state_option(h)
    _add_machine_options(h)
    h.add_argument("--realtime", action="store_true", help="run the mock in real time")
    h.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log of every homing move")


def _area(text: str) -> list[float]:
    """--area X0,Y0,X1,Y1: four finite numbers, the low corner first."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 4 or not all(math.isfinite(v) and abs(v) <= MAX_MM for v in values):
        raise argparse.ArgumentTypeError(f"--area takes four numbers X0,Y0,X1,Y1 in mm, got '{text}'")
    if values[0] > values[2] or values[1] > values[3]:
        raise argparse.ArgumentTypeError(f"--area X0,Y0,X1,Y1: X0 must not exceed X1 nor Y0 Y1, got '{text}'")
    return values


def _add_probe_machine(p: argparse.ArgumentParser) -> None:
    """The options both probe commands share: the port, its state file and machine, the feed, the mock."""
    p.add_argument("--feed", type=_number("--feed", 0.0, 100_000, above=True), metavar="MM_MIN",
                   help="the probe feed in mm/min (default 20, on a step/dir machine at most Z's start speed: it stops "
                   "on the step the probe closes)")
    p.add_argument("--port", default=DEFAULT_PORT, help="'mock' (default: its [mock] probe_surface simulated), "
                   "/dev/parport0 ([inputs] probe) or grbl:/dev/ttyUSB0 (G38.2); the MAXIMUS board and cmd: have no "
                   "probe")
    _add_state_option(p)
    _add_machine_options(p)
    p.add_argument("--realtime", action="store_true", help="run the mock in real time")
    p.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log of every probing move")


def _add_probe(sub: argparse._SubParsersAction) -> None:
    pb = sub.add_parser("probe", help="find the work's surface with a touch probe (Z zero, height map)",
                        description="Probe the work's surface: Z moves down (+Z) at the probe feed until the probe "
                        "touches, at most a bounded depth, then lifts back. 'cam probe z' sets the work Z zero on the "
                        "surface; 'cam probe tool' keeps it for a new tool after a tool change; 'cam probe grid' "
                        "writes a height map of an area. The e-stop, Ctrl-C (a stop) and the limit switches are "
                        "served while it probes.")
    what = pb.add_subparsers(dest="probe_what", metavar="WHAT", parser_class=_Parser, required=True)
    z = what.add_parser("z", help="probe down here and set the work Z zero on the surface",
                        description="Probe down where the tool stands, set the active work offset's Z zero on the "
                        "surface (--plate: that much below the contact), and lift back to where it began.")
    z.add_argument("--plate", type=_number("--plate", 0.0, 1000.0), default=0.0, metavar="MM",
                   help="the thickness of a touch plate laid on the work (the zero goes that much below the contact; "
                   "default 0)")
    z.add_argument("--depth", type=_number("--depth", 0.0, 1000.0, above=True), default=5.0, metavar="MM",
                   help="probe at most this far down (default 5): a probe that touches nothing stops there and lifts")
    _add_probe_machine(z)
    t = what.add_parser("tool", help="after a tool change: probe the new tool and keep the work Z for it",
                        description="After a tool change: go (lifted) to where the tool that set the work Z with "
                        "'cam probe z' touched the plate or sensor, probe the new tool there, and shift the active "
                        "work offset's Z by the difference of the two contacts, so the new tool's tip is at the same "
                        "work Z. The tool stays lifted over the plate.")
    t.add_argument("--plate", type=_number("--plate", 0.0, 1000.0), metavar="MM",
                   help="the plate's thickness now (default: the one 'cam probe z' was given)")
    t.add_argument("--clearance", type=_number("--clearance", 0.0, 1000.0, above=True), default=5.0, metavar="MM",
                   help="start this far above the old tool's contact and probe at most this far below it (default 5: "
                   "a new tool up to 5 mm longer or shorter)")
    _add_probe_machine(t)
    g = what.add_parser("grid", help="probe a grid over an area and write a height map",
                        description="Probe a grid of points over an area (--area, or --over a job's file where it "
                        "would run), row by row in serpentine order: the first point probed from the safe height, "
                        "each later one travelled to above the contacts before it, approached with a rapid and a "
                        "guarded move to just above the surface expected there, probed, lifted back. Writes the height map (JSON, "
                        "machine frame, heights in mm up positive) to --out; a progress line per point on stderr.")
    where = g.add_mutually_exclusive_group(required=True)
    where.add_argument("--area", type=_area, metavar="X0,Y0,X1,Y1",
                       help="the area in mm, in the active work offset's X, Y (--machine-coords: the machine's)")
    where.add_argument("--over", metavar="FILE", help=f"the XY extent of what this job cuts where it would run ("
                       f"{_file_kinds_help()}), placed at the active work zero as cam drill places it")
    g.add_argument("--origin", choices=("file", "upper-left", "lower-left", "center"),
                   help="with --over: which point of the file goes to the work zero (as cam drill's --origin)")
    g.add_argument("--machine-coords", action="store_true", help="--area is in the machine frame")
    g.add_argument("--spacing", type=_number("--spacing", 0.0, MAX_MM, above=True), default=10.0, metavar="MM",
                   help="the distance between grid points (default 10)")
    g.add_argument("--margin", type=_number("--margin", 0.0, MAX_MM), default=0.0, metavar="MM",
                   help="grow the area by this much on every side (default 0)")
    g.add_argument("--safe-height", type=_number("--safe-height", 0.0, MAX_MM), default=2.0, metavar="MM",
                   help="the height above the work Z zero the first probe starts from (default 2); the later "
                   "points are approached from the contacts before them")
    g.add_argument("--depth", type=_number("--depth", 0.0, MAX_MM, above=True), metavar="MM",
                   help="no probe goes deeper than this far below the safe height (default: the safe height + 2)")
    g.add_argument("--out", required=True, metavar="MAP.json", help="where to write the height map")
    _add_probe_machine(g)


def _axes_text(text: str) -> str:
    axes = text.lower()
    if not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
        raise argparse.ArgumentTypeError(f"--axes takes X, Y, Z or several of them, each once (ZXY), got '{text}'")
    return axes


def _add_serve(sub: argparse._SubParsersAction) -> None:
    sv = sub.add_parser(
        "serve", help="control the machine from a web page (phone or desktop)",
        description="Start the web server: upload a drawing, G-code, Excellon or HPGL file, see its preview, "
        "size and time, start / pause / resume / stop it, jog, answer tool changes and watch it live. Listens "
        "on 127.0.0.1:8000; any other --host needs a token (one is made and printed in the URL). The machine "
        "port is the logging mock unless --port names a real one. Needs the web extra: "
        "pip install 'cam[web]'.",
    )
    sv.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0 = every network, needs a token)")
    sv.add_argument("--http-port", type=_whole("--http-port", 0, 65535), default=8000, metavar="N", help="TCP port of the web page (default 8000)")
    sv.add_argument("--token", help="token every request must carry, at least 16 characters (default: none on "
                    "localhost, a new random one of 128 bits otherwise, printed in the page's URL)")
    sv.add_argument("--allow-host", action="append", metavar="NAME",
                    help="with a token: a name the page may be opened by besides localhost, an IP address and this "
                    "computer's own name (repeatable; e.g. a DNS name of this computer)")
    sv.add_argument("--jobs-dir", metavar="DIR", help="folder for uploaded files (default: a new temporary folder)")
    sv.add_argument("--max-upload-mb", type=_number("--max-upload-mb", 0.001, 100_000), default=50.0, metavar="MB", help="larger uploads are refused (default 50)")
    sv.add_argument("--port", default=DEFAULT_PORT, metavar="PORT",
                    help="'mock' (default: logs, moves nothing), a device like /dev/parport0, maximus:/dev/ttyUSB0, or "
                    "grbl:/dev/ttyUSB0 (Home and a feed override appear on the page)")
    _add_machine_options(sv)
    _add_state_option(sv)
    clock = sv.add_mutually_exclusive_group()
    clock.add_argument("--realtime", dest="realtime", action="store_true", default=True,
                       help="run the mock in real time, so the page shows live progress (default)")
    clock.add_argument("--simulated", dest="realtime", action="store_false",
                       help="run the mock on the simulated clock (jobs end at once); real ports are always real time")
    lim = sv.add_argument_group("limits (the machine comes first: nothing a client asks may hold it up)")
    lim.add_argument("--max-connections", type=_whole("--max-connections", 2, 100_000), metavar="N",
                     help="connections kept at once; the oldest idle one is closed for a newcomer (default 100)")
    lim.add_argument("--max-event-streams", type=_whole("--max-event-streams", 1, 100_000), metavar="N",
                     help="pages following the machine live at once, below --max-connections (default 16)")
    lim.add_argument("--header-timeout", type=_number("--header-timeout", 0.1, 3600), metavar="S",
                     help="a request's head must arrive whole within S seconds (default 5)")
    lim.add_argument("--body-timeout", type=_number("--body-timeout", 0.1, 3600), metavar="S",
                     help="the longest pause inside a request body (default 10)")
    lim.add_argument("--work-time-limit", type=_number("--work-time-limit", 0.001, 86_400), metavar="S",
                     help="the longest one planning, preview or pin-log export may take, in its worker process "
                          "(default 120)")
    lim.add_argument("--work-memory-limit", type=_number("--work-memory-limit", 256, 1 << 30), metavar="MB",
                     help="the memory that worker process may use (default: half the machine's, 2048 to 8192)")


def _add_tools(sub: argparse._SubParsersAction) -> None:
    tl = sub.add_parser("tools", help="the machine's tool table: list, set or remove a tool",
                        description="The tool table kept with the machine file (beside it, NAME.tools.toml; with no "
                        "--machine, default.tools.toml in the state folder): each tool's number, shape (flat, ball, "
                        "V), diameter (a V bit's tip) and length offset. Drill and G-code jobs name the table's tool "
                        "at each tool change (a drill file's own size wins, and a table tool of another size is a "
                        "warning). Without an action: list the tools.")
    tl.add_argument("--machine", metavar="FILE.toml", help="the machine file whose table this is (default: the "
                    "built-in settings' table in the state folder)")
    tl.add_argument("--json", action="store_true", help="list the tools as JSON")
    what = tl.add_subparsers(dest="tools_action", metavar="ACTION", parser_class=_Parser)
    what.add_parser("list", help="list the tools (the default)",
                    description="List the tools of the table, one a line (--json before the action: as JSON).")
    st = what.add_parser("set", help="add a tool, or change the tool of that number",
                         description="Add tool N to the table, or replace it: cam tools set 3 --shape v --diameter 0.2 "
                         "--angle 30 --length 12.3. The table is written atomically.")
    st.add_argument("number", type=_whole("N", 0, 999_999), metavar="N", help="the tool number (T3: 3)")
    st.add_argument("--shape", required=True, choices=("flat", "ball", "v"), help="the cutter's end: flat, ball or v")
    st.add_argument("--diameter", required=True, type=_number("--diameter", 0.0, 100.0), metavar="MM",
                    help="the cutting diameter in mm (a V bit: its tip, 0 sharp)")
    st.add_argument("--angle", type=_number("--angle", 0.0, 179.0), default=0.0, metavar="DEG",
                    help="a V bit's included angle in degrees (1..179)")
    st.add_argument("--length", type=_number("--length", -1000.0, 1000.0), metavar="MM",
                    help="the tool's length offset in mm (left out: not known)")
    rm = what.add_parser("remove", help="remove a tool from the table",
                         description="Remove tool N from the table (written atomically).")
    rm.add_argument("number", type=_whole("N", 0, 999_999), metavar="N", help="the tool number")


_COMMAND_PARSERS = (_add_drill, _add_export, _add_preview, _add_digitize, _add_trace, _add_info, _add_profile, _add_jog,
                    _add_emulate_maximus, _add_emulate_grbl, _add_goto, _add_where, _add_zero, _add_home, _add_probe,
                    _add_tools, _add_serve)
"""Each adds one command's subparser, in the order ``cam --help`` lists them."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command (used by :func:`cam.cli.main` and the docs).

    The chosen command's name is ``args.command`` (None when none is given).
    """
    parser = _Parser(
        prog="cam",
        description="Turn drawings into exact, safe step/dir motion for a small 3-axis stepper machine.",
        epilog="Run 'cam COMMAND --help' for the options of a command. Errors exit with code 2.",
    )
    parser.add_argument("--version", action="version", version=f"cam {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for add_command in _COMMAND_PARSERS:
        add_command(sub)
    return parser
