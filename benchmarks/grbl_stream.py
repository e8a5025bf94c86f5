"""Benchmark row: a job streamed to grbl through the machine session (issue #30 point 2) at 115200 baud, in real
time on the grbl emulator: does grbl's planner ever run dry?

    python benchmarks/grbl_stream.py            # ellipse drawing and dome relief, two feeds each (about 2 min)
    python benchmarks/grbl_stream.py --quick    # the ellipse only

Workloads: ``samples/ellipse.png`` planned 3 Z px deep, and the relief ``samples/disc.png`` under
``profiles/dome.png``, with step periods of 1 ms and 0.25 ms (feeds of 1.7 and 6.9 m/min over this machine's
0.0289 mm steps).  ``cam`` path: ``MachineSession("grbl:PTY").start(job)``: the job's moves as ``G53`` lines, runs
joined, character counting.  Reference, in the same run: the same lines sent one at a time, each after the
previous ``ok`` (send-and-wait, what a naive sender does).  Columns: lines and bytes streamed, the job's machine
time at its feeds, the wall time of each way (one run each: real time), their ratio (reference / cam), and the
emulator's planner starvations each way (goal 0 for cam).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cam  # noqa: E402
from cam.drive.grbl_link import GrblLink  # noqa: E402
from cam.drive.grbl_machine import close_grbl_machines, job_lines  # noqa: E402
from cam.drive.session import MachineSession  # noqa: E402
from cam.sim.grbl import start_emulator  # noqa: E402


def grbl_settings(s: cam.MachineSettings) -> dict[int, float]:
    """grbl's $100-$122 for this machine: its steps/mm, rates well above the job's feeds, a router's accelerations."""
    return {100: 1 / s.mm_per_step_xy, 101: 1 / s.mm_per_step_xy, 102: 1 / s.mm_per_step_z,
            110: 12000.0, 111: 12000.0, 112: 12000.0, 120: 1000.0, 121: 1000.0, 122: 1000.0}


def with_cam(job, s: cam.MachineSettings) -> tuple[float, int]:
    emu = start_emulator(speed=1.0, settings=grbl_settings(s), baud=115200)
    try:
        session = MachineSession(f"grbl:{emu.device_path}", s)
        t0 = time.monotonic()
        session.start(job)
        session.wait_idle(None)
        wall = time.monotonic() - t0
        assert session.last_run["status"] == "finished", session.last_run
        return wall, emu.starvation_count
    finally:
        close_grbl_machines()
        emu.stop()


def with_send_and_wait(lines: list[str], s: cam.MachineSettings) -> tuple[float, int]:
    emu = start_emulator(speed=1.0, settings=grbl_settings(s), baud=115200)
    try:
        with GrblLink(f"grbl:{emu.device_path}") as link:
            t0 = time.monotonic()
            for line in ["G21G90G94", *lines]:
                link.command(line, timeout_s=30)
            link.wait_idle()
            return time.monotonic() - t0, emu.starvation_count
    finally:
        emu.stop()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the ellipse drawing only")
    args = ap.parse_args(argv)
    print("| job | step period ms | lines | bytes | machine s | wall s cam | wall s send-and-wait | ratio "
          "| starvations cam | starvations send-and-wait |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for period_ms in (1.0, 0.25):
        s = cam.MachineSettings().replace(delay_xy_ms=period_ms, delay_z_ms=period_ms, ramp="constant")
        jobs = [("ellipse drawing", cam.plan(cam.digitize(cam.load_image(ROOT / "samples" / "ellipse.png")),
                                             depth=3, settings=s))]
        if not args.quick:
            jobs.append(("dome relief", cam.plan(cam.digitize(cam.load_image(ROOT / "samples" / "disc.png")),
                                                 profile=cam.load_profile(ROOT / "profiles" / "dome.png"),
                                                 settings=s)))
        for name, job in jobs:
            lines = [x for x in job_lines(job, (0, 0, 0), (0, 0, 0), s) if isinstance(x, str)]
            machine_s = cam.plan_steps(job).estimated_time_s
            wall_cam, starved_cam = with_cam(job, s)
            wall_ref, starved_ref = with_send_and_wait(lines, s)
            print(f"| {name} | {period_ms:g} | {len(lines)} | {sum(len(x) + 1 for x in lines)} | {machine_s:.1f} "
                  f"| {wall_cam:.1f} | {wall_ref:.1f} | {wall_ref / wall_cam:.2f} | {starved_cam} | {starved_ref} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
