"""Bounded memory (#15 point 2, #28 point 4): peak RSS and speed of whole `cam drill` processes on the mock.

    python benchmarks/bounded_memory.py            # full size
    python benchmarks/bounded_memory.py --quick    # 1/16 of each (1/10 of the 10^9-period job)

Jobs: the 200 MB HPGL file and the 4096^2 relief with ``--pin-log``; HPGL files of 40,000 and 80,000 strokes
alternating two pens (SP1/SP2: a tool-change pause each) inside 40 x 30 mm with the default look-ahead
ramps, with and without ``--pin-log``, and the 40,000 on a machine file of long ramps (0.05 ms step delays,
600 mm/s top speeds, 50 mm/s^2: a stop from full speed takes 128,000 periods, so each look-ahead window holds
2.3M periods); and a job of 10^9 step periods (5,000 HPGL strokes across the travel,
constant ramps, no pin log: it would be 30 GB).  Besides the peak RSS, each row gives the job's step periods
per second of planning and simulating (the report's ``periods`` over its ``planning_s`` + ``run_s``: reading,
planning and the simulated run of the process, its start-up imports not counted) and of the whole process.

Each job is generated in a temporary folder and run as a whole process; its
peak RSS (``ru_maxrss`` of the child) is compared with the floor measured in
the same run: a process that only imports `cam`, numpy and OpenCV.  The
goal: under 500 MB for each job.  The HPGL job runs with constant ramps (its
pin log is about 37 GB at full size: the look-ahead ramps would take far longer);
a file of over a million points is planned from the file a piece at a time
(:mod:`cam.job.hpgl_stream`).  ``bench_rows`` gives the rows for
``benchmarks/run.py`` (row group 16).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GOAL_MB = 500.0
GOAL_RATE = 10e6
"""Step periods per second of planning and simulating (the report's ``planning_s`` + ``run_s``, #28 point 4)."""

MACHINE_TOML = """
steps_per_px_xy = 1
steps_per_px_z = 1

[travel]
x_max_steps = 200000
y_max_steps = 200000
z_min_steps = -2000
z_max_steps = 2000
"""

LONG_RAMPS_TOML = """
delay_xy_ms = 0.05
delay_z_ms = 0.05
max_speed_x_mm_s = 600
max_speed_y_mm_s = 600
max_speed_z_mm_s = 600
"""
"""A machine file whose ramps are long in periods: short step delays, high top speeds, the default 50 mm/s^2."""


def write_hpgl(path: Path, size_bytes: int) -> int:
    """An HPGL file of about ``size_bytes``: the same short zigzag polyline (moves of about 3 steps), pen
    down, over and over; returns its number of points."""
    zigzag = "PU0,0;PD" + ",".join(f"{3 * i},{3 * (i % 2)}" for i in range(1, 12)) + ";"
    block = zigzag * 4096
    n = 0
    with open(path, "w") as f:
        f.write("IN;SP1;")
        written = 7
        while written < size_bytes:
            f.write(block)
            written += len(block)
            n += 4096 * 11
        f.write("PU0,0;")
    return n


def write_pen_changes(path: Path, n_strokes: int, seed: int = 1) -> int:
    """An HPGL file of ``n_strokes`` short strokes (3 points) alternating pens 1 and 2 inside 40 x 30 mm (1600 x
    1200 plotter units), as a two-pen plot exports; returns its number of points."""
    rng = np.random.default_rng(seed)
    start = rng.integers(0, (1500, 1100), size=(n_strokes, 2))
    jumps = rng.integers(-60, 61, size=(n_strokes, 2, 2))
    with open(path, "w") as f:
        f.write("IN;\n")
        for i in range(n_strokes):
            x, y = (int(v) for v in start[i])
            pts = np.clip(np.array([x, y]) + jumps[i], 0, (1600, 1200))
            f.write(f"SP{1 + i % 2};PU{x},{y};PD{pts[0, 0]},{pts[0, 1]},{pts[1, 0]},{pts[1, 1]};\n")
        f.write("PU;SP0;\n")
    return 3 * n_strokes


def write_long_strokes(path: Path, n_strokes: int, length_pu: int) -> None:
    """An HPGL file of ``n_strokes`` pen-down strokes ``length_pu`` plotter units long, back and forth."""
    with open(path, "w") as f:
        f.write("IN;SP1;PU0,0;")
        for i in range(n_strokes):
            f.write(f"PD{length_pu if i % 2 == 0 else 0},{i % 2};")
        f.write("PU0,0;\n")


def write_relief(path: Path, size_px: int) -> None:
    """A ``size_px`` square 3D drawing: a red disc with a black rim (a dome with --profile-expr)."""
    img = np.full((size_px, size_px, 3), 255, np.uint8)
    c = size_px // 2
    cv2.circle(img, (c, c), c - 6, (0, 0, 255), -1)
    cv2.circle(img, (c, c), c - 6, (0, 0, 0), 1)
    cv2.imwrite(str(path), img)


LAUNCHER = (
    "import os, subprocess, sys\n"
    "p = subprocess.Popen(sys.argv[1:], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)\n"
    "_, status, usage = os.wait4(p.pid, 0)\n"
    "print(os.waitstatus_to_exitcode(status), usage.ru_maxrss)\n"
)
"""Starts the measured process from a small interpreter of its own: a child's ``ru_maxrss`` starts at its
parent's RSS at the fork, and ``benchmarks/run.py`` has grown to gigabytes by the time it gets here."""


def peak_rss_mb(argv: list[str], cwd: Path) -> tuple[float, float]:
    """``(peak RSS in MB, wall seconds)`` of one whole process (``wait4``'s ``ru_maxrss``, from a small
    launcher); raises on a failed run."""
    # the mock's state file and lock in the run's folder: a cam command elsewhere (or a killed run of this one) on
    # the default mock does not make a row refuse to start
    env = dict(os.environ, PYTHONPATH=str(ROOT), XDG_STATE_HOME=str(cwd / "state"))
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", LAUNCHER, *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                         capture_output=True, text=True)
    wall_s = time.perf_counter() - t0
    code, maxrss_kb = (int(v) for v in out.stdout.split()[-2:])
    if code != 0:
        raise RuntimeError(f"{' '.join(argv)}: exit {code}: {out.stderr[-400:]}")
    return maxrss_kb / 1024.0, wall_s


def _jobs(tmp: Path, quick: bool) -> list[tuple[str, list[str]]]:
    """``(name, cam drill arguments)`` of each measured job, its input written into ``tmp``."""
    hpgl_bytes = (200 << 20) // (16 if quick else 1)
    relief_px = 1024 if quick else 4096
    n_points = write_hpgl(tmp / "big.plt", hpgl_bytes)
    write_relief(tmp / "relief.png", relief_px)
    drill = ["-m", "cam", "drill"]
    common = ["--machine", "machine.toml", "--yes", "--no-progress"]
    jobs = [
        (f"HPGL {hpgl_bytes / 2**20:.0f} MB, {n_points / 1e6:.1f}M points (constant ramps, --pin-log)",
         [*drill, "big.plt", *common, "--ramp", "constant", "--pin-log", "big.csv", "--report", "big.json"]),
        (f"relief {relief_px}^2 dome (constant ramps, --pin-log)",
         [*drill, "relief.png", *common, "--profile-expr", "1 + k // 8", "--ramp", "constant",
          "--pin-log", "relief.csv", "--report", "relief.json"]),
    ]
    for n in (40_000, 80_000):
        n = n // (16 if quick else 1)
        write_pen_changes(tmp / f"pens{n}.plt", n)
        name = f"HPGL {n:,} strokes alternating SP1/SP2 in 40 x 30 mm (look-ahead ramps"
        jobs.append((name + ")", [*drill, f"pens{n}.plt", "--yes", "--no-progress", "--report", f"pens{n}.json"]))
        jobs.append((name + ", --pin-log)", [*drill, f"pens{n}.plt", "--yes", "--no-progress", "--pin-log",
                                             f"pens{n}.csv", "--report", f"pens{n}-log.json"]))
        if n == 40_000 // (16 if quick else 1):
            jobs.append((name + ", a machine file of long ramps: 0.05 ms delays, 600 mm/s, 50 mm/s^2)",
                         [*drill, f"pens{n}.plt", "--yes", "--no-progress", "--machine", "long_ramps.toml",
                          "--report", f"pens{n}-long.json"]))
    strokes = 5_031 // (10 if quick else 1)
    write_long_strokes(tmp / "long.plt", strokes, 230_000)
    jobs.append((f"10^{8 if quick else 9} step periods: {strokes:,} strokes across the travel (constant ramps)",
                 [*drill, "long.plt", *common, "--ramp", "constant", "--report", "long.json"]))
    return jobs


def bench_rows(quick: bool, repeats: int = 1, only: tuple[str, ...] = ()) -> list[dict]:
    """One row per job: peak RSS of the whole process against the import floor, and the job's step periods per
    second of that process (medians of ``repeats`` runs: this shared machine's speed varies by +-15 % from one
    minute to the next).  ``only``: the jobs whose names hold one of these strings (all when empty)."""
    tmp = Path(tempfile.mkdtemp(prefix="cam-mem-"))
    try:
        (tmp / "machine.toml").write_text(MACHINE_TOML)
        (tmp / "long_ramps.toml").write_text(LONG_RAMPS_TOML)
        py = sys.executable
        floor = statistics.median(peak_rss_mb([py, "-c", "import cam, numpy, cv2"], tmp)[0] for _ in range(repeats))
        rows = []
        for name, argv in _jobs(tmp, quick):
            if only and not any(o in name for o in only):
                continue
            runs, rates = [], []
            try:
                for _ in range(repeats):
                    runs.append(peak_rss_mb([py, *argv], tmp))
                    report = json.loads((tmp / argv[argv.index("--report") + 1]).read_text())
                    rates.append(report["periods"] / max(1e-9, report["planning_s"] + report["run_s"]))
            except RuntimeError as exc:
                rows.append(dict(name=f"memory: cam drill {name} on the mock, peak RSS", cam=None, ref=floor,
                                 ratio="failed", target=f"< {GOAL_MB:.0f} MB", met=False, note=str(exc)[-200:]))
                continue
            peak = statistics.median(r[0] for r in runs)
            wall_s = statistics.median(r[1] for r in runs)
            periods = report["periods"]
            rate = statistics.median(rates)
            note = (f"{periods / 1e6:.1f}M periods, planning and simulating at {rate / 1e6:.1f}M periods/s "
                    f"(the whole process, imports and reading included: {periods / wall_s / 1e6:.1f}M/s)")
            if repeats > 1:
                note += f"; medians of {repeats} runs, rates {min(rates) / 1e6:.1f}-{max(rates) / 1e6:.1f}M/s"
            if "--pin-log" in argv:
                note += f", pin log {(tmp / argv[argv.index('--pin-log') + 1]).stat().st_size / 2**20:.0f} MB"
                (tmp / argv[argv.index("--pin-log") + 1]).unlink()
            rows.append(dict(name=f"memory: cam drill {name} on the mock, peak RSS (MB) vs import floor",
                             cam=peak, ref=floor, ratio=f"{peak:.0f} MB = {peak / floor:.1f}x floor",
                             target=f"< {GOAL_MB:.0f} MB, >= {GOAL_RATE / 1e6:.0f}M periods/s",
                             met=peak < GOAL_MB and rate >= GOAL_RATE, note=note))
            print(f"  {rows[-1]['name']}: {rows[-1]['ratio']} ({note})", file=sys.stderr, flush=True)
        return rows
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1/16 of the HPGL file, a 1024^2 relief")
    ap.add_argument("--repeats", type=int, default=1, metavar="N", help="runs of each job (medians; default 1)")
    ap.add_argument("--only", action="append", default=[], metavar="TEXT",
                    help="only the jobs whose names hold TEXT (repeatable), e.g. --only 'strokes alternating'")
    args = ap.parse_args(argv)
    print("| workload | cam peak RSS (MB) | floor (MB) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in bench_rows(args.quick, max(1, args.repeats), tuple(args.only)):
        cam_mb = "" if r["cam"] is None else f"{r['cam']:.0f}"
        print(f"| {r['name']} | {cam_mb} | {r['ref']:.0f} | {r['ratio']} ({r['note']}) | {r['target']} | "
              f"{'yes' if r['met'] else '**no**'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
