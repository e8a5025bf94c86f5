"""``cam drill``: plan a drawing, G-code, drill or HPGL file and send it to a port."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Optional

from ..digitize.digitized import save_digitized
from ..drive.maximus.board import drill_stroke, require_drilling
from ..drive.maximus.resume import resume_board_job
from ..drive.journal import read_journal
from ..drive.state import StateHold, check_in_travel, read_state
from ..drive.machines import can
from ..errors import CamError
from ..kinds import kind
from ..kinds.jobs import resume_job
from ..job.resume import resume_start
from .checks import check_output_path, job_kind_of
from ..fileio import atomic_write_text
from ..tool_table import job_tool_warnings, read_tool_table, tool_table_path
from ..drive.activities import run_timing_text
from .common import format_duration, port_settings
from .execute import Outcome, check_port_options, execute
from .machine_state import hold_machine, state_path_of
from .parser import EXIT_INTERRUPTED
from .planning import placed_by_own_zero, prepare, summary_of, write_job_preview

__all__ = ["cmd_drill", "journal_path"]


def _finish(args: argparse.Namespace, outcome: Outcome, report: dict, summary: str, wall_s: float) -> int:
    report["status"] = outcome.status
    report.update(outcome.timing)
    ramp = report["ramp"]
    report_error = None
    if args.report:
        try:
            atomic_write_text(args.report, json.dumps(report, indent=2) + "\n")
        except CamError as exc:  # the job has run: what it did is said first, then that its report is missing
            report_error = f"the report was not written: {exc}"
    if not outcome.finished:
        for m in outcome.messages:
            print(m, file=sys.stderr)
        _raise_unwritten(report_error, outcome.state_error)
        return EXIT_INTERRUPTED
    _finished_line(args, outcome, ramp, summary, wall_s)
    _raise_unwritten(report_error, outcome.state_error)
    return 0


def _raise_unwritten(report_error: Optional[str], state_error: Optional[str]) -> None:
    """After the run's own outcome: one error line for what was not written (the state file first: where the tool
    is matters more than the report)."""
    errors = [e for e in (state_error, report_error) if e is not None]
    if errors:
        raise CamError("; and ".join(errors))


def _finished_line(args: argparse.Namespace, outcome: Outcome, ramp: str, summary: str, wall_s: float) -> None:
    if can(args.port, "drills_alone"):  # the board keeps its own time
        print(f"job finished: {summary}; total time {format_duration(wall_s)}", flush=True)
        return
    simulated = not args.realtime and can(args.port, "simulated")
    print(finish_line(summary, outcome, ramp, wall_s, simulated=simulated), flush=True)


def finish_line(summary: str, outcome: Outcome, ramp: str, wall_s: float, *, simulated: bool) -> str:
    """The line a finished step/dir job ends with: the machine time and, in real time, how long the run took
    and, when it ran late, by how much and how many stalls (a late write moves the rest of the run later)."""
    return f"job finished: {summary}; " + run_timing_text(outcome.machine_time_s, wall_s, outcome.timing, ramp,
                                                          simulated=simulated)


def board_report(job, settings) -> dict:
    """What a MAXIMUS board is sent besides the holes: its Delay bytes, the Z stroke, the spindle."""
    m = settings.maximus
    z_up, z_down = drill_stroke(job.drill_plan, settings)
    return {"delays": {"x": m.delay_x, "y": m.delay_y, "z_up": m.delay_z_up, "z_down": m.delay_z_down},
            "z_up_steps": z_up, "z_down_steps": z_down, "spindle": m.spindle,
            "half_step": {"x": m.half_step_x, "y": m.half_step_y, "z": m.half_step_z}}


def journal_path(args: argparse.Namespace) -> Optional[str]:
    """Where ``cam drill`` keeps the job's journal: --journal; else the journal it resumes; else next to
    --report or --pin-log (``NAME.journal.json``); else, on a real port, ``IMAGE.journal.json`` in the current
    folder; else (the mock without outputs) nowhere."""
    if getattr(args, "journal", None):
        return args.journal
    if getattr(args, "resume", None):
        return args.resume
    for output in (getattr(args, "report", None), getattr(args, "pin_log", None)):
        if output:
            p = Path(output)
            return str(p.with_name(p.stem + ".journal.json"))
    if not can(args.port, "simulated"):
        return Path(getattr(args, "load_digitized", None) or args.image).name + ".journal.json"
    return None


def _resumed(args: argparse.Namespace, job, hold: StateHold, reported_stop: Optional[tuple[int, int, int]]):
    """The prepared job resumed after the stop its journal (--resume) records; says so on stderr.  A journal that
    may be behind the stop (not closed) is not trusted for the position: the run goes on from where the machine
    state has the tool, refused while that is unknown (:func:`cam.job.resume.resume_start`, issue #43 point 7)."""
    journal = read_journal(args.resume)
    if can(args.port, "drills_alone"):  # the board drills by itself: it goes on from the next hole
        if journal.state == "running":
            resume_start(journal, hold.state, where=args.resume, reported_stop_steps=reported_stop)  # known, or refused
        resumed = resume_board_job(job, journal, where=args.resume)
        if journal.state == "running":
            print(f"warning: journal {args.resume} was not closed (its run ended without a word): the board may "
                  f"have moved on after its last hole; reset it and check the head", file=sys.stderr)
        print(f"resuming at hole {journal.holes_done + 1} of {len(job.drill_plan.holes_steps)} from "
              f"{list(journal.position_steps)} steps ({journal.state})", file=sys.stderr)
        return resumed, journal.position_steps
    start = resume_start(journal, hold.state, where=args.resume, reported_stop_steps=reported_stop)
    resumed = resume_job(job, journal, position_steps=start, where=args.resume)
    if journal.state == "running":
        print(f"note: journal {args.resume} was not closed (its run ended without its last write), so it may be "
              f"behind the stop: resuming from where the machine state has the tool, machine "
              f"{list(hold.state.position_steps)} steps", file=sys.stderr)
    print(f"resuming at move {resumed.report['resumed_at_move']} of {len(job.toolpath)} from "
          f"{list(start)} steps ({journal.state})", file=sys.stderr)
    return resumed, start


def _reported_stop(args: argparse.Namespace, settings) -> Optional[tuple[int, int, int]]:
    """Where the machine state file recorded the tool at the stop of the run a --resume goes on from, when it
    recorded one with the position unknown (an emergency stop, a fault while moving: the machine's last word),
    read before the machine is held; None when it recorded none (a run that ended without recording, killed or
    its disk full: its running marker) or the position is known (then it is used)."""
    try:
        state = read_state(state_path_of(args), settings)
    except CamError:
        return None
    if state.running is not None or state.position_known or "without recording" in state.unknown_reason:
        return None  # a marker left behind (turned into an unknown position by an earlier hold: its wording)
    return state.position_steps


def _machine_hold(args: argparse.Namespace, settings) -> tuple[Optional[StateHold], Optional[tuple[int, int, int]]]:
    """The machine's hold, taken before the job is planned when it is planned in the machine state
    (:func:`_gcode_hold`) or resumed (where the tool stands decides where the run goes on), and where the state
    file recorded the last stop (:func:`_reported_stop`, a resume's)."""
    reported = _reported_stop(args, settings) if getattr(args, "resume", None) else None
    hold = _gcode_hold(args, settings)
    if hold is None and getattr(args, "resume", None):
        hold = hold_machine(args, settings, "cam drill")
    return hold, reported


def _gcode_hold(args: argparse.Namespace, settings) -> Optional[StateHold]:
    """A G-code program runs as a sender runs it, from where the machine state says the tool stands and in its
    work offsets (issue #29 point 4): the machine's hold is taken before the program is planned, and
    ``args.machine_state`` is what it is planned in (a resumed run's: the journal's start).  None for other
    kinds (planned from their own zero, placed at the work zero when they run) but a drill, HPGL or SVG file
    placed by its own zero (--origin file: planned from the work zero as a program is) and a job levelled to a
    height map (--level: levelled where it will run, at the active work zero, issue #46 point 2)."""
    name = job_kind_of(args)
    if name is None or not kind(name).runs_in_place:  # placed at the work zero, unlike a G-code program
        if getattr(args, "keep_offsets", False):
            raise CamError("--keep-offsets keeps the work offsets a G-code program sets (G10 L2/L20); this is not "
                           "a G-code program")
        if not placed_by_own_zero(args) and not getattr(args, "level", None):
            return None
    hold = hold_machine(args, settings, "cam drill")
    try:
        if getattr(args, "resume", None):
            args.machine_state = hold.state.moved_to(read_journal(args.resume).home_steps)
        else:
            hold.require_known()
            args.machine_state = hold.state
    except BaseException:
        hold.close()
        raise
    return hold


def _offsets_kept(args: argparse.Namespace, job, hold: Optional[StateHold]) -> dict:
    """The work offsets the program changed (G10 L2/L20), machine steps, checked against the travel before
    anything moves when --keep-offsets keeps them; says on stderr when they are not kept."""
    if getattr(args, "keep_offsets", False) and job.probing is not None:
        raise CamError(f"--keep-offsets: {job.name} probes ({job.probing.probes[0]}): the offsets it sets after a "
                       "probe depend on where the probe touches, known only as it runs; set them after the run with "
                       "cam zero")
    if hold is None:
        return {}
    ends = job.report.get("work_offsets_end_steps") or {}
    changed = {k: tuple(v) for k, v in ends.items() if tuple(v) != tuple(hold.state.offsets_steps[k])}
    if not changed:
        return {}
    names = ", ".join(changed)
    if not getattr(args, "keep_offsets", False):
        print(f"note: the program sets work offset {names} (G10) for itself only; --keep-offsets keeps it",
              file=sys.stderr)
        return {}
    for name, zero in changed.items():
        check_in_travel(zero, hold.settings, f"work offset {name} as the program sets it (--keep-offsets)")
    return changed


def cmd_drill(args: argparse.Namespace) -> int:
    check_port_options(args)
    if getattr(args, "resume", None):
        check_output_path(args.resume, "--resume")
        read_journal(args.resume)  # a bad journal: one line, before anything is planned
    settings = port_settings(args, args.port)
    check_port_options(args, settings)
    hold, reported_stop = _machine_hold(args, settings)
    try:
        return _drill(args, settings, hold, reported_stop)
    finally:
        if hold is not None:
            hold.close()


def _drill(args: argparse.Namespace, settings, hold: Optional[StateHold],
           reported_stop: Optional[tuple[int, int, int]] = None) -> int:
    planning_t0 = time.monotonic()
    job = prepare(args, settings)
    planning_s = time.monotonic() - planning_t0
    start_steps = None
    if getattr(args, "resume", None):
        assert hold is not None  # taken before planning (_machine_hold)
        job, start_steps = _resumed(args, job, hold, reported_stop)
    table_path = tool_table_path(args.machine)  # the machine's tool table: named at each tool change (issue #47)
    args.tool_table_path = str(table_path)
    job.warnings += job_tool_warnings(job, read_tool_table(table_path))
    for w in job.warnings:
        if w not in getattr(args, "kind_warnings", ()):  # check_args said it already
            print(f"warning: {w}", file=sys.stderr)
    if args.preview:
        args.scale = None
        write_job_preview(args, job, args.preview)
    if args.save_digitized:
        save_digitized(job.digitized, args.save_digitized)
    if can(args.port, "drills_alone"):
        require_drilling(job, args.port)  # slots or milled holes: a milling tool path, which the board cannot run
        job.report["board"] = board_report(job, settings)
    journal = journal_path(args)
    if journal is not None and job.probing is not None:  # its moves after a probe depend on the contact: no resume
        print(f"note: no journal kept: {job.name} probes, so a stopped run is run again from its start",
              file=sys.stderr)
        journal = None
    if journal is not None:
        job.report["journal"] = journal
    kept = _offsets_kept(args, job, hold)
    t0 = time.monotonic()
    outcome = execute(job, args, settings, start_steps=start_steps, journal=journal, hold=hold,
                      state_error_in_outcome=True)
    if kept and outcome.finished and hold is not None and outcome.state_error is None:
        state = hold.state
        for name, zero in kept.items():
            state = state.with_offset(name, zero)
        hold.record(state)
        print(f"work offset {', '.join(kept)} kept as the program set it (--keep-offsets)", file=sys.stderr)
    summary = summary_of(job)
    report = job.full_report()  # after the run: the run's pass over the ramps gave the machine time
    run_s = time.monotonic() - t0
    report.update(planning_s=round(planning_s, 3), run_s=round(run_s, 3))  # wall times of this process
    return _finish(args, outcome, report, summary, run_s)
