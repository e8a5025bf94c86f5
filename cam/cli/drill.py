"""``cam drill``: plan a drawing, G-code, drill or HPGL file and send it to a port."""
from __future__ import annotations

import argparse
import json
import sys
import time

from ..digitize.digitized import save_digitized
from ..drive.maximus.board import drill_stroke
from ..drive.ports import port_kind
from ..fileio import atomic_write_text
from .common import format_duration, port_settings
from .execute import Outcome, check_port_options, execute
from .parser import EXIT_INTERRUPTED
from .planning import prepare, summary_of, write_job_preview

__all__ = ["cmd_drill"]


def _finish(args: argparse.Namespace, outcome: Outcome, report: dict, summary: str, wall_s: float) -> int:
    report["status"] = outcome.status
    report.update(outcome.timing)
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


def board_report(job, settings) -> dict:
    """What a MAXIMUS board is sent besides the holes: its Delay bytes, the Z stroke, the spindle."""
    m = settings.maximus
    z_up, z_down = drill_stroke(job.drill_plan, settings)
    return {"delays": {"x": m.delay_x, "y": m.delay_y, "z_up": m.delay_z_up, "z_down": m.delay_z_down},
            "z_up_steps": z_up, "z_down_steps": z_down, "spindle": m.spindle,
            "half_step": {"x": m.half_step_x, "y": m.half_step_y, "z": m.half_step_z}}


def cmd_drill(args: argparse.Namespace) -> int:
    check_port_options(args)
    settings = port_settings(args, args.port)
    check_port_options(args, settings)
    job = prepare(args, settings)
    for w in job.warnings:
        if w not in getattr(args, "kind_warnings", ()):  # check_args said it already
            print(f"warning: {w}", file=sys.stderr)
    if args.preview:
        args.scale = None
        write_job_preview(args, job, args.preview)
    if args.save_digitized:
        save_digitized(job.digitized, args.save_digitized)
    if port_kind(args.port) == "maximus":
        job.report["board"] = board_report(job, settings)
    t0 = time.monotonic()
    outcome = execute(job, args, settings)
    summary = summary_of(job)
    return _finish(args, outcome, job.report, f"{summary} from {args.image}" if job.kind == "hpgl" else summary,
                   time.monotonic() - t0)
