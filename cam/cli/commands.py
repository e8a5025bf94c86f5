"""The command line: ``python -m cam COMMAND ...``.

A thin adapter: it parses options, calls the library, and turns any
:class:`~cam.errors.CamError` into one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from .. import __version__
from ..digitize import START_RULES, digitize
from ..digitize.digitized import Digitized, load_digitized, save_digitized
from ..digitize.drawing import load_image
from ..drive.ports import MockPort, open_port
from ..drive.runner import Controller, run
from ..drive.steps import StepPlan, plan_steps
from ..verify.pinlog import write_pin_log
from ..drive.runner import FINISHED, RunResult
from ..errors import CamError
from ..fileio import atomic_write_text
from ..formats.gcode_export import save_gcode
from ..formats.gcode import GCODE_SUFFIXES
from ..job.jobs import EXCELLON_SUFFIXES, HPGL_SUFFIXES
from ..digitize.profile import Profile, load_profile, profile_from_expr
from ..render.report import format_report, image_report, job_report
from ..settings import RAMP_MODES, MachineSettings, load_settings
from ..job.drawing import plan
from ..job.moves import goto, jog

__all__ = ["main", "build_parser"]

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


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
        return values

    return parse


def _float_pair(name: str) -> Callable[[str], list[float]]:
    def parse(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes two numbers separated by a comma, got '{text}'") from None
        if len(values) != 2 or any(not (v > 0) for v in values):
            raise argparse.ArgumentTypeError(f"{name} takes two positive numbers XY,Z, got '{text}'")
        return values

    return parse


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
    p.add_argument(
        "--start", choices=START_RULES, default="top",
        help="2D: where each object starts: first pixel in scan order (top) or nearest the tool (min-distance)",
    )


def _add_profile_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("3D depth profile (for drawings with a red interior)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--profile", metavar="PROFILE",
                   help="profile drawing (blue curve over black axes, red origin) or CSV of depths per layer")
    x.add_argument("--profile-expr", metavar="EXPR",
                   help="depth of layer k as arithmetic in k and n (layers), e.g. '30*sqrt(1-((n-k)/n)**2)'")


DRILL_SUFFIXES = EXCELLON_SUFFIXES


def _float_list(n: int, name: str) -> Callable[[str], list[float]]:
    def parse(text: str) -> list[float]:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} takes {n} numbers separated by commas, got '{text}'") from None
        if len(values) != n:
            raise argparse.ArgumentTypeError(f"{name} takes {n} comma-separated numbers, got '{text}'")
        return values

    return parse


def _add_drill_file_options(d: argparse.ArgumentParser) -> None:
    g = d.add_argument_group("drill files (Excellon: .drl .xln .exc .drd)")
    g.add_argument("--drill-depth", type=float, default=2.0, metavar="MM", help="drill depth below the surface (2.0)")
    g.add_argument("--travel-height", type=float, default=1.0, metavar="MM", help="height above the surface between holes (1.0)")
    g.add_argument("--offset", type=_float_list(2, "--offset"), metavar="X,Y",
                   help="machine position (mm from where the tool stands) of the board origin; "
                   "default: the board's top-left hole extent at the start position")
    g.add_argument("--mirror-x", action="store_true", help="mirror the board for drilling from the back side")
    g.add_argument("--drill-order", choices=("tour", "file"), default="tour", help="short tour per tool (default) or file order")
    g.add_argument("--excellon-units", choices=("inch", "metric"), help="units when the file does not say")
    g.add_argument("--excellon-format", metavar="I:F", help="integer:fraction digits when the file does not say (e.g. 2:4)")
    g.add_argument("--excellon-zeros", choices=("LZ", "TZ"), help="zero suppression when the file does not say")


def _excellon_digits(args: argparse.Namespace) -> Optional[tuple[int, int]]:
    if not args.excellon_format:
        return None
    try:
        a, b = (int(v) for v in args.excellon_format.split(":"))
    except ValueError:
        raise CamError(f"--excellon-format takes I:F such as 2:4, got '{args.excellon_format}'") from None
    return (a, b)


def _add_hpgl_options(p: argparse.ArgumentParser) -> None:
    h = p.add_argument_group("HPGL (.plt .hpgl .hpg; --travel-height and --offset apply too)")
    h.add_argument("--cut-depth", type=float, default=0.5, metavar="MM", help="pen-down cutting depth below the surface (0.5)")


FILE_JOB_SUFFIXES = DRILL_SUFFIXES + GCODE_SUFFIXES + HPGL_SUFFIXES
"""Files that are jobs already (not drawings): planned by :func:`cam.job.jobs.prepare_job`."""


def _is_file_job(args: argparse.Namespace) -> bool:
    return bool(getattr(args, "image", None)) and Path(args.image).suffix.lower() in FILE_JOB_SUFFIXES


def _prepare_file_job(args: argparse.Namespace, settings: Optional[MachineSettings] = None):
    """A G-code, drill or HPGL file planned with the command's options (progress bar by bytes read)."""
    from ..job.jobs import prepare_job

    with _reading_bar(args) as progress:
        return prepare_job(args.image, _job_options(args), settings or _settings(args), name=args.image,
                           progress=progress)


def _load_drill_file(args: argparse.Namespace):
    from ..formats.excellon import load_excellon

    return load_excellon(args.image, units=args.excellon_units, digits=_excellon_digits(args),
                         zeros=args.excellon_zeros)


def _port_settings(args: argparse.Namespace, port: str) -> MachineSettings:
    """The machine settings for ``port``: a MAXIMUS board has its own resolution, step mode and 16-bit travel
    unless --machine says else."""
    if port.startswith("maximus:") and not args.machine:
        from ..drive.maximus.board import MAXIMUS_SETTINGS

        return MAXIMUS_SETTINGS
    return _settings(args)


def _drill_maximus(args: argparse.Namespace, dp, settings: MachineSettings, summary: str) -> int:
    from ..drive.maximus.board import MaximusBoard, drill_arguments

    board = MaximusBoard(args.port)
    previous = signal.getsignal(signal.SIGINT)

    def on_tool_change(index: int, message: str) -> None:
        print(f"{message}: press Enter when the drill is in", file=sys.stderr)
        if not args.yes and sys.stdin.readline() == "":
            print("no answer at the tool change (stdin closed): stopping", file=sys.stderr)
            board.emergency_stop()

    signal.signal(signal.SIGINT, lambda *a: board.emergency_stop())
    t0 = time.monotonic()
    try:
        board.drill(**drill_arguments(dp, settings), on_tool_change=on_tool_change)
    finally:
        signal.signal(signal.SIGINT, previous)
        board.close()
    print(f"job finished: {summary}; total time {_format_duration(time.monotonic() - t0)}")
    return 0


def _add_job_options(d: argparse.ArgumentParser) -> None:
    """Options that say what to cut and how deep (shared by drill and export)."""
    d.add_argument("image", nargs="?", metavar="IMAGE", help="the drawing (PNG, BMP, JPEG, ...)")
    d.add_argument("--load-digitized", metavar="FILE", help="reuse a saved digitized matrix instead of digitizing")
    _add_digitize_options(d)
    d.add_argument(
        "--depth", metavar="N|N1,N2,...", type=_int_list(None, "--depth", 0), default=[10],
        help="2D cutting depth in Z pixels: one value for all objects, or one per object (0 skips one); default 10",
    )
    _add_profile_options(d)
    d.add_argument("--passes", type=int, default=1, metavar="N", help="Repeat Drill: cut in N passes of increasing depth")
    d.add_argument("--start-at", metavar="X,Y,Z", type=_int_list(3, "--start-at"), default=[0, 0, 0],
                   help="offset the whole job by this many pixels")
    d.add_argument("--pause-at", metavar="X,Y", type=_int_list(2, "--pause-at"), action="append", default=[],
                   help="pause when the tool reaches this drawing point (repeatable); Enter resumes")
    _add_machine_options(d)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command (used by ``main`` and the docs)."""
    parser = _Parser(
        prog="cam",
        description="Turn drawings into exact, safe step/dir motion for a small 3-axis stepper machine.",
        epilog="Run 'cam COMMAND --help' for the options of a command. Errors exit with code 2.",
    )
    parser.add_argument("--version", action="version", version=f"cam {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    d = sub.add_parser(
        "drill", help="cut a drawing, G-code, drill (Excellon) or HPGL file (mock port by default)",
        description="Digitize a drawing (or reuse a saved digitized matrix), plan the depth-sorted toolpath "
        "and send it to a port. A G-code file (.ngc, .nc, .gcode, .tap) runs as programmed; an Excellon drill "
        "file (.drl, .xln, .exc, .drd) is drilled tool by tool in a short order, also on the MAXIMUS board "
        "(--port maximus:/dev/ttyUSB0); an HPGL file (.plt, .hpgl, .hpg) is cut pen-down at --cut-depth. "
        "The default port is the logging mock, so nothing moves unless you name a real port.",
    )
    _add_job_options(d)
    g = d.add_argument_group("port and outputs")
    g.add_argument("--port", default="mock", help="'mock' (default: logs, moves nothing), a device like /dev/parport0, or maximus:/dev/ttyUSB0 (drill files)")
    g.add_argument("--realtime", action="store_true", help="run the mock in real time, sleeping like the real port")
    g.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log (t_ns,data,strobe)")
    g.add_argument("--save-digitized", metavar="FILE", help="save the digitized matrix")
    g.add_argument("--report", metavar="FILE.json", help="write the job report as JSON")
    g.add_argument("--preview", metavar="OUT.png", help="write the toolpath picture before cutting")
    g.add_argument("--flip-y", action="store_true", help="G-code input: machine Y = +Y mm instead of -Y mm")
    g.add_argument("--yes", action="store_true", help="answer every prompt (tool changes, pauses) with Enter")
    _add_drill_file_options(d)
    _add_hpgl_options(d)
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    d.set_defaults(func=cmd_drill)

    e = sub.add_parser(
        "export", help="write the job as RS-274/NGC G-code (grbl, LinuxCNC)",
        description="Plan a job exactly as 'drill' would and write it as G-code in mm. Machine Y grows upward, "
        "image rows downward: by default Y = -row (the drawing stays upright); --flip-y writes Y = +row.",
    )
    _add_job_options(e)
    _add_drill_file_options(e)
    _add_hpgl_options(e)
    e.add_argument("-o", "--output", required=True, metavar="FILE.ngc", help="where to write the G-code")
    e.add_argument("--flip-y", action="store_true", help="write Y = +row (mirrored) instead of Y = -row")
    e.add_argument("--safe-height", type=float, default=1.0, metavar="MM", help="travel height above the surface (mm)")
    e.set_defaults(func=cmd_export)

    pv = sub.add_parser(
        "preview", help="draw the job (or the surface it would cut) as PNG or SVG",
        description="Draw the job over its drawing: cutting moves coloured by depth, moves above the surface "
        "dashed, start and end marked, size, depth range and time in a legend. --surface draws the surface "
        "the job would cut (run on the mock, decoded, carved with a point tool) as a shaded depth map.",
    )
    _add_job_options(pv)
    _add_drill_file_options(pv)
    _add_hpgl_options(pv)
    pv.add_argument("--flip-y", action="store_true", help="G-code input: machine Y = +Y mm instead of -Y mm")
    pv.add_argument("-o", "--output", required=True, metavar="OUT.png|OUT.svg", help="picture to write")
    pv.add_argument("--surface", action="store_true", help="draw the cut surface instead of the toolpath")
    pv.add_argument("--scale", type=int, metavar="N", help="picture pixels per drawing pixel (default: automatic)")
    pv.set_defaults(func=cmd_preview)

    z = sub.add_parser("digitize", help="digitize a drawing and save the digitized matrix",
                       description="Digitize a drawing and save its digitized matrix for later jobs (--load-digitized).")
    z.add_argument("image", metavar="IMAGE")
    z.add_argument("-o", "--output", required=True, metavar="FILE", help="where to write the matrix")
    _add_digitize_options(z)
    z.set_defaults(func=cmd_digitize)

    i = sub.add_parser("info", help="print the report of a drawing, drill file or HPGL file",
                       description="Digitize a drawing and print its size in pixels and mm, its object count and "
                       "warnings; for a drill file its tools (diameter, hole count), extent and warnings; for an "
                       "HPGL file its strokes, pens, extent and unknown commands.")
    i.add_argument("image", metavar="IMAGE")
    _add_digitize_options(i)
    _add_machine_options(i)
    _add_profile_options(i)
    i.add_argument("--json", action="store_true", help="print the report as JSON")
    _add_drill_file_options(i)
    i.set_defaults(func=cmd_info)

    pr = sub.add_parser("profile", help="print a Z profile's layer count and depth range",
                        description="Read a profile drawing or CSV and print its layer count and depth range.")
    pr.add_argument("profile", metavar="PROFILE")
    _add_machine_options(pr)
    pr.set_defaults(func=cmd_profile)

    jg = sub.add_parser("jog", help="move one axis by a number of steps (to set the board origin)",
                        description="Jog one axis, as the MAXIMUS jog screen does: 'cam jog X+ 100' moves X by "
                        "+100 steps. On a MAXIMUS board (--port maximus:/dev/ttyUSB0) this is its Jog mode.")
    jg.add_argument("axis", metavar="AXIS", help="X+, X-, Y+, Y-, Z+ or Z-")
    jg.add_argument("steps", type=int, metavar="STEPS", help="how many steps (> 0)")
    jg.add_argument("--port", default="mock", help="'mock' (default), /dev/parport0 or maximus:/dev/ttyUSB0")
    _add_machine_options(jg)
    jg.add_argument("--realtime", action="store_true", help="run the mock in real time")
    jg.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log")
    jg.add_argument("--no-progress", action="store_true", help="no progress bar")
    jg.set_defaults(func=cmd_jog)

    em = sub.add_parser("emulate-maximus", help="run the MAXIMUS firmware emulator on a pseudo-terminal",
                        description="Serve the MAXIMUS PIC firmware emulator on a pty and print its device path; "
                        "point --port maximus:PATH at it. Ctrl-C ends it.")
    em.add_argument("--speed", type=float, default=1.0, help="firmware time per real time (1 = real time)")
    em.set_defaults(func=cmd_emulate)

    gt = sub.add_parser("goto", help="move the tool to X,Y,Z pixels and stop there",
                        description="Go To: travel at Z=0 to X,Y, then move Z, and stop (thesis 4.1.2).")
    gt.add_argument("position", metavar="X,Y,Z", type=_int_list(3, "X,Y,Z"))
    _add_machine_options(gt)
    gt.add_argument("--port", default="mock", help="'mock' (default) or a device like /dev/parport0")
    gt.add_argument("--realtime", action="store_true", help="run the mock in real time")
    gt.add_argument("--pin-log", metavar="FILE.csv", help="write the mock's pin log")
    gt.add_argument("--no-progress", action="store_true", help="no progress bar")
    gt.set_defaults(func=cmd_goto)

    sv = sub.add_parser(
        "serve", help="control the machine from a web page (phone or desktop)",
        description="Start the web server: upload a drawing, G-code, Excellon or HPGL file, see its preview, "
        "size and time, start / pause / resume / stop it, jog, answer tool changes and watch it live. Listens "
        "on 127.0.0.1:8000; any other --host needs a token (one is made and printed in the URL). The machine "
        "port is the logging mock unless --machine-port names a real one.",
    )
    sv.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1; 0.0.0.0 = every network, needs a token)")
    sv.add_argument("--port", type=int, default=8000, help="TCP port of the web page (default 8000)")
    sv.add_argument("--token", help="token every request must carry (default: none on localhost, a new random one otherwise)")
    sv.add_argument("--jobs-dir", metavar="DIR", help="folder for uploaded files (default: a new temporary folder)")
    sv.add_argument("--max-upload-mb", type=float, default=50.0, metavar="MB", help="larger uploads are refused (default 50)")
    sv.add_argument("--machine-port", default="mock", metavar="PORT",
                    help="'mock' (default: logs, moves nothing), a device like /dev/parport0, or maximus:/dev/ttyUSB0")
    _add_machine_options(sv)
    clock = sv.add_mutually_exclusive_group()
    clock.add_argument("--realtime", dest="realtime", action="store_true", default=True,
                       help="run the mock in real time, so the page shows live progress (default)")
    clock.add_argument("--simulated", dest="realtime", action="store_false",
                       help="run the mock on the simulated clock (jobs end at once); real ports are always real time")
    sv.set_defaults(func=cmd_serve)
    return parser


def _settings(args: argparse.Namespace) -> MachineSettings:
    s = load_settings(args.machine)
    changes: dict[str, Any] = {}
    if args.steps_per_pixel:
        changes["steps_per_px_xy"], changes["steps_per_px_z"] = args.steps_per_pixel
    if args.delay:
        changes["delay_xy_ms"], changes["delay_z_ms"] = args.delay
    if getattr(args, "ramp", None):
        changes["ramp"] = args.ramp
    return s.replace(**changes) if changes else s


def _load_job_input(args: argparse.Namespace) -> Digitized:
    if args.load_digitized:
        d = load_digitized(args.load_digitized)
        if args.image:
            drawing = load_image(args.image)
            if (drawing.width_px, drawing.height_px) != (d.width_px, d.height_px):
                raise CamError(
                    f"{args.load_digitized}: matrix is for a {d.width_px}x{d.height_px} image, "
                    f"{args.image} is {drawing.width_px}x{drawing.height_px}"
                )
        return d
    if not args.image:
        raise CamError("drill needs an IMAGE or --load-digitized FILE")
    return digitize(load_image(args.image), start=args.start)


def _format_duration(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _execute(job: Any, args: argparse.Namespace, prompt_at_pause: bool = False) -> RunResult:
    """Run a toolpath or step plan with a progress bar; Ctrl-C stops cleanly (tool lifted, position reported)."""
    steps = job if isinstance(job, StepPlan) else plan_steps(job)
    port = open_port(args.port)  # before the progress bar: a bad port is one clean line
    controller = Controller()

    def on_pause(position: tuple[int, int, int], note: str) -> None:
        print(f"{note}: paused at X={position[0]} Y={position[1]} Z={position[2]} steps; press Enter to resume",
              file=sys.stderr)
        if getattr(args, "yes", False):
            return
        if sys.stdin.readline() == "":  # nobody can answer: stop rather than carry on blindly
            print("no answer at the pause (stdin closed): stopping", file=sys.stderr)
            controller.stop()
    previous = signal.getsignal(signal.SIGINT)

    def interrupt(signum: int, frame: Any) -> None:
        controller.stop()

    bar = None
    progress = None
    if not args.no_progress:
        from tqdm import tqdm

        total_s = steps.estimated_time_s
        bar = tqdm(
            total=round(total_s, 3), unit="s", unit_scale=False, desc="cutting", file=sys.stderr,
            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} machine s [{elapsed}<{remaining}]",
            mininterval=0.2,
        )

        def progress(done: int, total: int, t_ns: int) -> None:
            bar.update(round(t_ns / 1e9, 3) - bar.n)

    signal.signal(signal.SIGINT, interrupt)
    try:
        result = run(
            steps, port, realtime=args.realtime, controller=controller, progress=progress,
            on_pause=on_pause if prompt_at_pause else None,
        )
    finally:
        signal.signal(signal.SIGINT, previous)
        if bar is not None:
            bar.close()
        if not isinstance(port, MockPort):
            port.close()
    if args.pin_log:
        if not isinstance(result.port, MockPort):
            raise CamError("--pin-log needs the mock port")
        write_pin_log(result.pin_log(), args.pin_log)
    return result


def _plan_job(args: argparse.Namespace) -> tuple[Digitized, Any]:
    settings = _settings(args)
    if args.passes < 1:
        raise CamError(f"--passes must be >= 1, got {args.passes}")
    digitized = _load_job_input(args)
    depth = args.depth[0] if len(args.depth) == 1 else args.depth
    job = plan(
        digitized, depth=depth, settings=settings, passes=args.passes,
        start_at=tuple(args.start_at), pause_at=[tuple(p) for p in args.pause_at],
        profile=_profile(args, digitized),
    )
    return digitized, job


def _export_file_job(args: argparse.Namespace) -> int:
    import numpy as np

    if Path(args.image).suffix.lower() in GCODE_SUFFIXES:
        raise CamError(f"{args.image} is G-code already; run it with 'cam drill', or preview it")
    job = _prepare_file_job(args)
    at = np.flatnonzero(job.toolpath.pause) + 1  # a tool change comes before the point after its pause
    if job.drill_plan is not None:
        changes = {int(i): (tool, f"T{tool} {dia:.3f} mm, {n} holes")
                   for i, (tool, dia, n) in zip(at, job.drill_plan.tool_sequence)}
    else:  # HPGL: "tool change: pen N"
        changes = {int(i): (int(note.split()[-1]), note) for i, note in zip(at, job.toolpath.pause_notes or [])
                   if note.split()[-1].isdigit()}
    save_gcode(job.toolpath, args.output, flip_y=args.flip_y, safe_height_mm=args.travel_height,
               title=f"cam: {args.image}", tool_changes=changes)
    print(f"{args.output}: {job.summary}, {len(changes)} tool change(s)")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    if _is_file_job(args):
        return _export_file_job(args)
    digitized, job = _plan_job(args)
    if args.safe_height <= 0:
        raise CamError(f"--safe-height must be > 0 mm, got {args.safe_height}")
    save_gcode(job, args.output, flip_y=args.flip_y, safe_height_mm=args.safe_height,
               title=f"cam: {args.image or args.load_digitized}")
    print(f"{args.output}: {job.n_targets} points, {job.n_retracts} retracts")
    return 0


def _write_preview(args: argparse.Namespace, job: Any, path: str, surface: bool = False) -> None:
    from ..drive.runner import simulate_surface
    from ..render.picture import save_picture, surface_picture, toolpath_picture, toolpath_svg

    if args.scale is not None and not (1 <= args.scale <= 64):
        raise CamError(f"--scale must be 1..64, got {args.scale}")
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg"):
        raise CamError(f"{path}: pictures are written as .png or .svg")
    time_s = plan_steps(job).estimated_time_s
    if surface:
        if suffix != ".png":
            raise CamError(f"{path}: the surface picture is written as .png")
        s = simulate_surface(job)
        st = job.settings
        legend = (f"cut surface, decoded from the mock pin log: depth 0..{st.px_to_mm_z(int(s.max()) / st.steps_per_px_z):.2f} mm"
                  f" ({int(s.max())} Z steps)")
        save_picture(surface_picture(s, scale=args.scale, legend=legend), path)
    elif suffix == ".svg":
        save_picture(toolpath_svg(job, scale=args.scale, estimated_time_s=time_s), path)
    else:
        rgb = load_image(args.image).to_rgb() if args.image else None
        save_picture(toolpath_picture(job, drawing_rgb=rgb, scale=args.scale, estimated_time_s=time_s), path)


def cmd_preview(args: argparse.Namespace) -> int:
    if _is_file_job(args):
        if args.surface:
            raise CamError("--surface draws the surface a drawing's job cuts; for this file draw its toolpath")
        if args.scale is not None and not (1 <= args.scale <= 64):
            raise CamError(f"--scale must be 1..64, got {args.scale}")
        _write_file_job_preview(_prepare_file_job(args), args.output, scale=args.scale)
        print(f"{args.output}: toolpath picture")
        return 0
    _, job = _plan_job(args)
    _write_preview(args, job, args.output, surface=args.surface)
    print(f"{args.output}: {'cut surface' if args.surface else 'toolpath'} picture")
    return 0


def _finish(args: argparse.Namespace, result: RunResult, report: dict, summary: str) -> int:
    report["status"] = result.status
    ramp = report["ramp"]
    if args.report:
        atomic_write_text(args.report, json.dumps(report, indent=2) + "\n")
    if result.status != FINISHED:
        for m in result.messages:
            print(m, file=sys.stderr)
        return EXIT_INTERRUPTED
    print(
        f"job finished: {summary}; total time {_format_duration(result.machine_time_s)} "
        f"({result.machine_time_s:.1f} s machine time, {ramp} ramps"
        f"{'' if args.realtime or args.port != 'mock' else ', simulated'})"
    )
    return 0


def _job_options(args: argparse.Namespace):
    """The drill command's options for files that are not drawings, as :class:`cam.job.jobs.JobOptions`."""
    from ..job.jobs import JobOptions

    return JobOptions(
        drill_depth_mm=args.drill_depth, travel_height_mm=args.travel_height,
        offset_mm=tuple(args.offset) if args.offset else None, mirror_x=args.mirror_x,
        drill_order=args.drill_order, excellon_units=args.excellon_units,
        excellon_digits=_excellon_digits(args), excellon_zeros=args.excellon_zeros,
        flip_y=getattr(args, "flip_y", False), depth_mm=getattr(args, "cut_depth", 0.5),
    )


def _reading_bar(args: argparse.Namespace):
    """A progress bar by bytes read (large HPGL files), on a terminal only; yields its callback or None."""
    import contextlib

    if getattr(args, "no_progress", False):
        return contextlib.nullcontext(None)
    from tqdm import tqdm

    @contextlib.contextmanager
    def bar_callback():
        total = Path(args.image).stat().st_size if Path(args.image).is_file() else None
        with tqdm(total=total, unit="B", unit_scale=True, desc="reading", file=sys.stderr, mininterval=0.2,
                  leave=False, disable=None) as bar:  # None: only on a terminal, so an error stays one line in logs
            yield lambda done, total_bytes: bar.update(done - bar.n)

    return bar_callback()


def _write_file_job_preview(job: Any, path: str, scale: Optional[int] = None) -> None:
    """The job's preview (.png, the picture the web page shows: bounded in size at any resolution), or
    the toolpath of a drill or HPGL job as .svg."""
    from ..render.picture import save_picture, toolpath_svg

    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".svg") or (suffix == ".svg" and job.toolpath is None):
        raise CamError(f"{path}: pictures are written as .png" + (" or .svg" if job.toolpath is not None else ""))
    if suffix == ".png":
        save_picture(job.preview_picture(), path)
    else:
        save_picture(toolpath_svg(job.toolpath, scale=scale, estimated_time_s=job.estimated_time_s), path)


def _drill_file(args: argparse.Namespace) -> int:
    """G-code, Excellon and HPGL files: planned by :func:`cam.job.jobs.prepare_job`, then run."""
    settings = _port_settings(args, args.port)
    maximus = args.port.startswith("maximus:")
    job = _prepare_file_job(args, settings)
    for w in job.warnings:
        print(f"warning: {w}", file=sys.stderr)
    summary = job.summary[len(args.image) + 2:] if job.summary.startswith(f"{args.image}: ") else job.summary
    if maximus:
        if job.kind != "excellon":
            raise CamError(f"{args.port}: the MAXIMUS board drills drill files (Excellon) only")
        return _drill_maximus(args, job.drill_plan, settings, summary)
    if args.preview:
        _write_file_job_preview(job, args.preview)
    result = _execute(job.steps, args, prompt_at_pause=True)
    return _finish(args, result, job.report, f"{summary} from {args.image}" if job.kind == "hpgl" else summary)


def cmd_drill(args: argparse.Namespace) -> int:
    if _is_file_job(args):
        return _drill_file(args)
    digitized, job = _plan_job(args)
    if args.preview:
        args.scale = None
        _write_preview(args, job, args.preview)
    if args.save_digitized:
        save_digitized(digitized, args.save_digitized)
    steps = plan_steps(job)
    report = job_report(digitized, job, steps)
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    result = _execute(steps, args, prompt_at_pause=bool(args.pause_at))  # planned once, above
    return _finish(args, result, report,
                   f"{report['objects']} object(s), {report['points']} points, {report['retracts']} retracts")


def _profile(args: argparse.Namespace, digitized: Digitized) -> Optional[Profile]:
    if args.profile:
        return load_profile(args.profile)
    if args.profile_expr:
        return profile_from_expr(args.profile_expr, max(1, digitized.n_layers))
    return None


def cmd_profile(args: argparse.Namespace) -> int:
    settings = _settings(args)
    prof = load_profile(args.profile)
    lo, hi = int(prof.depth_px.min()), int(prof.depth_px.max())
    print(f"{args.profile}: {prof.n_layers} layers, depth {lo}..{hi} Z px = "
          f"{settings.px_to_mm_z(lo):.3f}..{settings.px_to_mm_z(hi):.3f} mm")
    return 0


def cmd_digitize(args: argparse.Namespace) -> int:
    d = digitize(load_image(args.image), start=args.start)
    for w in d.warnings:
        print(f"warning: {w}", file=sys.stderr)
    save_digitized(d, args.output)
    print(f"{args.output}: {len(d.objects)} object(s), {d.n_points} points")
    return 0


def _info_excellon(args: argparse.Namespace) -> int:
    holes = _load_drill_file(args)
    x0, y0, x1, y1 = holes.extent_mm()
    lines = [f"{args.image}: {len(holes.holes_mm)} holes, board extent X {x0:.3f}..{x1:.3f} mm, "
             f"Y {y0:.3f}..{y1:.3f} mm ({x1 - x0:.2f} x {y1 - y0:.2f} mm)"]
    for tool, dia, count in holes.tool_table():
        lines.append(f"  T{tool}: {dia:.3f} mm, {count} holes")
    lines += [f"warning: {w}" for w in holes.warnings]
    print("\n".join(lines))
    return 0


def _info_hpgl(args: argparse.Namespace) -> int:
    from ..formats.hpgl import PLOTTER_UNIT_MM, scan_hpgl

    args.no_progress = getattr(args, "no_progress", True)
    with _reading_bar(args) as progress:
        scan = scan_hpgl(args.image, progress=progress)
    if args.json:
        print(json.dumps({**scan.__dict__, "size_mm": scan.size_mm()}, indent=2))
        return 0
    lines = [f"{args.image}: {scan.n_strokes} pen-down strokes, {scan.n_points} points, pens "
             f"{', '.join(map(str, scan.pens)) or 'none selected'}"]
    if scan.extent_pu is not None:
        x0, y0, x1, y1 = scan.extent_pu
        w, h = scan.size_mm()
        lines.append(f"  extent X {x0:g}..{x1:g}, Y {y0:g}..{y1:g} plotter units ({w:.2f} x {h:.2f} mm at "
                     f"{PLOTTER_UNIT_MM} mm per unit)")
    lines.append("  commands: " + ", ".join(f"{k} {n}" for k, n in scan.command_counts.items()))
    lines += [f"warning: {w}" for w in scan.warnings]
    print("\n".join(lines))
    return 0


def _info_gcode(args: argparse.Namespace) -> int:
    args.flip_y = getattr(args, "flip_y", False)
    job = _prepare_file_job(args)
    if args.json:
        print(json.dumps(job.report, indent=2))
        return 0
    w, h = job.size_mm
    lines = [f"{args.image}: {job.report.get('moves', 0)} moves, cut area {w:.2f} x {h:.2f} mm, depth "
             f"{job.depth_mm:.3f} mm, machine time {_format_duration(job.estimated_time_s)}"]
    lines += [f"  {note}" for note in job.tool_changes]
    lines += [f"warning: {w}" for w in job.warnings]
    print("\n".join(lines))
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    if Path(args.image).suffix.lower() in HPGL_SUFFIXES:
        return _info_hpgl(args)
    if Path(args.image).suffix.lower() in DRILL_SUFFIXES:
        return _info_excellon(args)
    if Path(args.image).suffix.lower() in GCODE_SUFFIXES:
        return _info_gcode(args)
    settings = _settings(args)
    d = digitize(load_image(args.image), start=args.start)
    rep = image_report(d, settings)
    prof = _profile(args, d)
    if prof is not None and d.mode == "3d":
        depth_px = int(prof.depth_of(d.levels).max())
        rep["depth_px"] = depth_px
        rep["depth_mm"] = round(settings.px_to_mm_z(depth_px), 4)
    print(json.dumps(rep, indent=2) if args.json else format_report(rep))
    return 0


def cmd_goto(args: argparse.Namespace) -> int:
    settings = _settings(args)
    job = goto(tuple(args.position), settings=settings)
    result = _execute(job, args)
    if result.status != FINISHED:
        for m in result.messages:
            print(m, file=sys.stderr)
        return EXIT_INTERRUPTED
    x, y, z = result.position_steps
    print(f"at X={x} Y={y} Z={z} steps")
    return 0


def cmd_jog(args: argparse.Namespace) -> int:
    axis = args.axis.upper()
    if len(axis) != 2 or axis[0] not in "XYZ" or axis[1] not in "+-":
        raise CamError(f"axis must be X+, X-, Y+, Y-, Z+ or Z-, got '{args.axis}'")
    if args.steps <= 0:
        raise CamError(f"steps must be > 0, got {args.steps}")
    n = args.steps if axis[1] == "+" else -args.steps
    if args.port.startswith("maximus:"):
        from ..drive.maximus.board import MaximusBoard

        with MaximusBoard(args.port) as board:
            board.jog(axis[0].lower(), n, half_step=_port_settings(args, args.port).half_step)
        print(f"jogged {axis[0]} by {n} steps")
        return 0
    settings = _settings(args)
    bounds = settings.travel.bounds_steps()
    lo, hi = bounds["XYZ".index(axis[0])]
    if abs(n) > hi - lo:
        raise CamError(f"a jog of {n} steps is longer than the {axis[0]} travel ({hi - lo} steps)")
    # the CLI does not know where the tool stands: a jog fits when it fits from one end of the travel
    start = [b_lo for b_lo, _ in bounds]
    if n < 0:
        start["XYZ".index(axis[0])] = hi
    plan = plan_steps(jog(axis[0], n, settings=settings), start_steps=tuple(start))
    result = _execute(plan, args)
    if result.status != FINISHED:
        return EXIT_INTERRUPTED
    print(f"jogged {axis[0]} by {n} steps")
    return 0


def cmd_serve(args: argparse.Namespace) -> int:
    from ..web.server import ServerConfig, serve

    if not (0 <= args.port <= 65535):
        raise CamError(f"--port must be 0..65535, got {args.port}")
    if not (args.max_upload_mb > 0):
        raise CamError(f"--max-upload-mb must be > 0, got {args.max_upload_mb}")
    settings = _port_settings(args, args.machine_port)
    config = ServerConfig(host=args.host, port=args.port, token=args.token, jobs_dir=args.jobs_dir,
                          max_upload_bytes=int(args.max_upload_mb * 1024 * 1024), settings=settings,
                          machine_port=args.machine_port, realtime=args.realtime)
    return serve(config, announce=lambda line: print(line, flush=True))


def cmd_emulate(args: argparse.Namespace) -> int:
    from ..sim import maximus as maximus_emulator

    return int(maximus_emulator.main(["--speed", str(args.speed)]) or 0)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of ``python -m cam``; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_BAD_INPUT
    try:
        return int(args.func(args))
    except CamError as exc:
        print(f"cam: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("cam: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # e.g. `cam info board.drl | head`: the reader left; that is not an error
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
