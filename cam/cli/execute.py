"""Running a planned job on a port from the command line: progress bar, pauses, Ctrl-C, pin log."""
from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

from tqdm import tqdm

from ..drive.ports import MockPort, open_port
from ..drive.runner import Controller, RunResult, run
from ..drive.steps import StepPlan, plan_steps
from ..errors import CamError
from ..verify.pinlog import write_pin_log
from .common import progress_wanted

__all__ = ["execute"]


def execute(job: Any, args: argparse.Namespace, prompt_at_pause: bool = False) -> RunResult:
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
    if progress_wanted(args):
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
