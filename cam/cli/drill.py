"""``cam drill``: plan a drawing, G-code, drill or HPGL file and send it to a port."""
from __future__ import annotations

import argparse
import json
import sys
import time

from ..digitize.digitized import save_digitized
from ..drive.ports import port_kind
from ..drive.steps import plan_steps
from ..fileio import atomic_write_text
from ..render.report import job_report
from .common import format_duration, port_settings
from .execute import Outcome, check_port_options, execute
from .parser import EXIT_INTERRUPTED
from .planning import is_file_job, plan_job, prepare_file_job, write_file_job_preview, write_preview

__all__ = ["cmd_drill"]


def _finish(args: argparse.Namespace, outcome: Outcome, report: dict, summary: str, wall_s: float) -> int:
    report["status"] = outcome.status
    ramp = report["ramp"]
    if args.report:
        atomic_write_text(args.report, json.dumps(report, indent=2) + "\n")
    if not outcome.finished:
        for m in outcome.messages:
            print(m, file=sys.stderr)
        return EXIT_INTERRUPTED
    if port_kind(args.port) == "maximus":  # the board keeps its own time
        print(f"job finished: {summary}; total time {format_duration(wall_s)}")
        return 0
    print(
        f"job finished: {summary}; total time {format_duration(outcome.machine_time_s)} "
        f"({outcome.machine_time_s:.1f} s machine time, {ramp} ramps"
        f"{'' if args.realtime or args.port != 'mock' else ', simulated'})"
    )
    return 0


def _drill_file(args: argparse.Namespace) -> int:
    """G-code, Excellon and HPGL files: planned by :func:`cam.job.jobs.prepare_job`, then run."""
    settings = port_settings(args, args.port)
    check_port_options(args)
    job = prepare_file_job(args, settings)
    for w in job.warnings:
        print(f"warning: {w}", file=sys.stderr)
    summary = job.summary[len(args.image) + 2:] if job.summary.startswith(f"{args.image}: ") else job.summary
    if args.preview:
        write_file_job_preview(job, args.preview)
    t0 = time.monotonic()
    outcome = execute(job, args, settings)
    return _finish(args, outcome, job.report, f"{summary} from {args.image}" if job.kind == "hpgl" else summary,
                   time.monotonic() - t0)


def cmd_drill(args: argparse.Namespace) -> int:
    if is_file_job(args):
        return _drill_file(args)
    check_port_options(args)
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
    t0 = time.monotonic()
    outcome = execute(steps, args, job.settings)  # planned once, above
    return _finish(args, outcome, report,
                   f"{report['objects']} object(s), {report['points']} points, {report['retracts']} retracts",
                   time.monotonic() - t0)
