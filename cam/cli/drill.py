"""``cam drill``: plan a drawing, G-code, drill or HPGL file and send it to a port."""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time

from ..digitize.digitized import save_digitized
from ..drive.maximus.board import MaximusBoard, drill_arguments
from ..drive.runner import FINISHED, RunResult
from ..drive.steps import plan_steps
from ..errors import CamError
from ..fileio import atomic_write_text
from ..render.report import job_report
from ..settings import MachineSettings
from .common import format_duration, port_settings
from .execute import execute
from .parser import EXIT_INTERRUPTED
from .planning import is_file_job, plan_job, prepare_file_job, write_file_job_preview, write_preview

__all__ = ["cmd_drill"]


def _drill_maximus(args: argparse.Namespace, dp, settings: MachineSettings, summary: str) -> int:
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
    print(f"job finished: {summary}; total time {format_duration(time.monotonic() - t0)}")
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
        f"job finished: {summary}; total time {format_duration(result.machine_time_s)} "
        f"({result.machine_time_s:.1f} s machine time, {ramp} ramps"
        f"{'' if args.realtime or args.port != 'mock' else ', simulated'})"
    )
    return 0


def _drill_file(args: argparse.Namespace) -> int:
    """G-code, Excellon and HPGL files: planned by :func:`cam.job.jobs.prepare_job`, then run."""
    settings = port_settings(args, args.port)
    maximus = args.port.startswith("maximus:")
    job = prepare_file_job(args, settings)
    for w in job.warnings:
        print(f"warning: {w}", file=sys.stderr)
    summary = job.summary[len(args.image) + 2:] if job.summary.startswith(f"{args.image}: ") else job.summary
    if maximus:
        if job.kind != "excellon":
            raise CamError(f"{args.port}: the MAXIMUS board drills drill files (Excellon) only")
        return _drill_maximus(args, job.drill_plan, settings, summary)
    if args.preview:
        write_file_job_preview(job, args.preview)
    result = execute(job.steps, args, prompt_at_pause=True)
    return _finish(args, result, job.report, f"{summary} from {args.image}" if job.kind == "hpgl" else summary)


def cmd_drill(args: argparse.Namespace) -> int:
    if is_file_job(args):
        return _drill_file(args)
    digitized, job = plan_job(args)
    if args.preview:
        args.scale = None
        write_preview(args, job, args.preview)
    if args.save_digitized:
        save_digitized(digitized, args.save_digitized)
    steps = plan_steps(job)
    report = job_report(digitized, job, steps)
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    result = execute(steps, args, prompt_at_pause=bool(args.pause_at))  # planned once, above
    return _finish(args, result, report,
                   f"{report['objects']} object(s), {report['points']} points, {report['retracts']} retracts")
