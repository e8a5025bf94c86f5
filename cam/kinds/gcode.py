"""G-code programs (RS-274/NGC as LinuxCNC reads it): run as programmed, from where the tool stands, in the machine
state's work offsets (:mod:`cam.formats.gcode`, :mod:`cam.job.gcode`)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

from ..errors import CamError, TravelError
from . import Head, Kind
from .excellon import excellon_or_gcode

__all__ = ["KIND", "probe_lines"]


def _sniff(head: Head) -> bool:
    return head.plain_text and excellon_or_gcode(head.lines) == "gcode"


def _open(path: Any, options: Any, settings: Any, machine_state: Any = None) -> Any:
    """The program interpreted with the options' tool table, subroutine folders and line limit, from
    ``machine_state`` (its position and work offsets; None: the home, offsets 0)."""
    from ..formats.gcode import load_tool_table, open_gcode
    from ..job.gcode import steps_to_gcode_mm

    s = settings
    frame: dict[str, Any] = {}
    if machine_state is not None:
        start = tuple(int(v) for v in machine_state.position_steps)
        frame = dict(start_mm=steps_to_gcode_mm(start, s, flip_y=options.flip_y),
                     work_offsets_mm={k: steps_to_gcode_mm(v, s, flip_y=options.flip_y)
                                      for k, v in machine_state.offsets_steps.items()},
                     active_offset=machine_state.active_offset)
    return open_gcode(
        path, home_g28_mm=(s.g28_x_mm, s.g28_y_mm, s.g28_z_mm), home_g30_mm=(s.g30_x_mm, s.g30_y_mm, s.g30_z_mm),
        tool_lengths_mm=load_tool_table(options.tool_table) if options.tool_table else None,
        subroutine_path=options.subroutine_path, max_lines=options.max_lines, **frame)


def _prepare(path: Path, options: Any, settings: Any, *, home: Any = None, progress: Any = None,
             machine_state: Any = None) -> Any:
    """``machine_state``: a :class:`cam.drive.state.MachineState` (the tool's machine position, the work offsets,
    the active one): the program runs as a G-code sender runs it from there (None: from the home, offsets 0)."""
    from ..job.gcode import STREAM_MOVES, gcode_mm_to_steps, stream_gcode
    from ..job.gcode_probing import ProbingProgram
    from .jobs import PreparedJob, plan_chunks

    s = settings
    start = (0, 0, 0) if machine_state is None else tuple(int(v) for v in machine_state.position_steps)
    program = _open(path, options, settings, machine_state)
    stream = stream_gcode(program, settings, flip_y=options.flip_y, spill=True, home_steps=start)
    # one planner whatever the size: a job of over STREAM_MOVES moves is kept as its pieces (bounded memory), the
    # file interpreted once, a line at a time, and the pieces kept in a temporary file for the later passes; a
    # smaller one is held joined
    held = stream.held(STREAM_MOVES)
    toolpath = stream if held is None else held
    # after a whole pass (held's or this) the program's moves and warnings are known; the travel checked in the
    # machine frame, from where the tool stands
    steps = plan_chunks(toolpath, start_steps=start, fingerprint=True)  # type: ignore[arg-type]
    if stream.n_motions == 0 and not any(int(v) for v in steps.steps_total):
        raise CamError(f"{path}: the program makes no moves (no G0, G1, G2, G3, G5 or canned cycle that goes "
                       "anywhere): there is nothing to run")
    probes = stream.probes or []  # G38.2/G38.3: as if each touched at its target; a machine runs it from the contact
    probing = ProbingProgram(program, settings, bool(options.flip_y), start, tuple(probes),  # type: ignore[arg-type]
                             tuple(stream.probe_feeds_mm_min)) if probes else None
    return PreparedJob(
        source=str(path), kind="gcode", plan=steps, settings=settings, toolpath=toolpath, warnings=stream.warnings,
        home_steps=start, probing=probing,  # type: ignore[arg-type]
        summary=f"{path.name}: {stream.n_program_moves} moves" + (f", {len(probes)} probe(s)" if probes else ""),
        report={"moves": stream.n_program_moves, "motions": stream.n_motions, "start_steps": list(start),
                **({"probes": probes} if probes else {}),
                # the program's Z = 0 (the active work zero's), from where it starts: depths are below it
                "surface_z_steps": 0 if machine_state is None else int(machine_state.work_zero_steps()[2]) - start[2],
                # the work offsets as the program left them (G10 L2/L20), machine steps: cam drill --keep-offsets
                # (after a probe they depend on its contact: not known before the run)
                "work_offsets_end_steps": {} if probes else {k: list(gcode_mm_to_steps(v, s, flip_y=options.flip_y))
                                                             for k, v in (program.end_offsets_mm or {}).items()}},
    )


def probe_lines(probes: list) -> list[str]:
    """What ``cam info`` and ``cam preview`` say of a program that probes (G38.2/G38.3): each probe, and that the
    moves after it depend on the contact."""
    return [f"  probe {p}" for p in probes] + [
        "  the moves after a probe depend on where it touches: shown and planned here as if each touched at its "
        "target (its deepest); a machine that probes plans them from the contact as it runs (the MAXIMUS board and "
        "cmd: have no probe)"]


def _info(path: Any, options: Any, settings: Any, *, prepare: Any, progress: Any = None) -> dict:
    """A program's report as planned where it would run now (``prepare()``: planned in the machine state), its
    extent in its own frame and where its work zero may stand; a program that leaves the travel from the work
    zero it would run from now is not refused (its size is what a user needs to choose a zero)."""
    from ..job.gcode import program_extent_mm, work_zero_range_mm

    travel_error: Optional[str] = None
    job = None
    try:
        job = prepare()
    except TravelError as exc:
        travel_error = str(exc)
    rep = job.full_report() if job is not None else {"source": str(path), "kind": "gcode"}
    # the extent in the program's own frame (run from its work zero, offsets 0): nothing is planned, so a program
    # that does not fit where it would run now still has one
    extent = program_extent_mm(_open(path, options, settings))
    if extent is not None:
        lo, hi = extent
        zero_lo, zero_hi = work_zero_range_mm(extent, settings, flip_y=options.flip_y)
        rep["extent_program_mm"] = [[round(float(v), 4) for v in lo], [round(float(v), 4) for v in hi]]
        rep["work_zero_fits_machine_mm"] = [[round(float(v), 4) for v in zero_lo], [round(float(v), 4) for v in zero_hi]]
    if travel_error is not None:
        rep["travel_error"] = travel_error
    return rep


def _info_lines(rep: dict, name: str) -> list[str]:
    from ..values import format_duration

    if "travel_error" not in rep:
        w, h = rep["size_mm"]
        lines = [f"{name}: {rep.get('moves', 0)} moves, cut area {w:.2f} x {h:.2f} mm, depth "
                 f"{rep['depth_mm']:.3f} mm, machine time {format_duration(rep['estimated_time_s'])}"]
    else:
        lines = [f"{name}: G-code program, not planned where it would run now: {rep['travel_error']}"]
    if "extent_program_mm" in rep:
        lo, hi = rep["extent_program_mm"]
        zero_lo, zero_hi = rep["work_zero_fits_machine_mm"]
        size = [b - a for a, b in zip(lo, hi)]
        lines.append(f"  extent in the program's own frame (G-code mm from its zero, +Y up, +Z up): "
                     f"X {lo[0]:.3f}..{hi[0]:.3f}, Y {lo[1]:.3f}..{hi[1]:.3f}, Z {lo[2]:.3f}..{hi[2]:.3f} mm "
                     f"({size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} mm)")
        too_large = [f"{'XYZ'[a]}" for a in range(3) if zero_lo[a] > zero_hi[a]]
        if too_large:
            lines.append(f"  it does not fit the machine travel on {', '.join(too_large)} wherever its zero is")
        else:
            lines.append(f"  fits the machine travel with its work zero at machine X {zero_lo[0]:.3f}..{zero_hi[0]:.3f}, "
                         f"Y {zero_lo[1]:.3f}..{zero_hi[1]:.3f}, Z {zero_lo[2]:.3f}..{zero_hi[2]:.3f} mm (the machine "
                         "frame of cam where, cam zero --at and cam goto: from the home, +Y toward the operator, "
                         "+Z deeper)")
    if "travel_error" not in rep:
        lines += probe_lines(rep["probes"]) if rep.get("probes") else []
        lines += [f"  {note}" for note in rep.get("tool_changes", [])]
        lines += [f"warning: {w}" for w in rep.get("warnings", [])]
    return lines


KIND = Kind(
    name="gcode", noun="G-code", title="G-code", suffixes=(".ngc", ".nc", ".gcode", ".gc", ".g", ".tap", ".cnc"),
    traits=frozenset(), prepare=_prepare, sniff=_sniff, sniff_rank=70, info=_info, info_lines=_info_lines,
    job_noun=None, listed_as="a G-code file", export_refusal="is G-code already; run it with 'cam drill', or preview it",
    help="runs as programmed",
)
