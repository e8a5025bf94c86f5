"""Bounded memory (#15 point 2): peak RSS of whole `cam drill ... --pin-log` processes on the mock.

    python benchmarks/bounded_memory.py            # the 200 MB HPGL file and the 4096^2 relief
    python benchmarks/bounded_memory.py --quick    # 1/16 of each

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
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GOAL_MB = 500.0

MACHINE_TOML = """
steps_per_px_xy = 1
steps_per_px_z = 1

[travel]
x_max_steps = 200000
y_max_steps = 200000
z_min_steps = -2000
z_max_steps = 2000
"""


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


def peak_rss_mb(argv: list[str], cwd: Path) -> float:
    """Peak RSS in MB of one whole process (``wait4``'s ``ru_maxrss``, from a small launcher); raises on a
    failed run."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", LAUNCHER, *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                         capture_output=True, text=True)
    code, maxrss_kb = (int(v) for v in out.stdout.split()[-2:])
    if code != 0:
        raise RuntimeError(f"{' '.join(argv)}: exit {code}: {out.stderr[-400:]}")
    return maxrss_kb / 1024.0


def bench_rows(quick: bool, repeats: int = 1) -> list[dict]:
    """One row per job: peak RSS of the whole process against the import floor (medians of ``repeats``)."""
    tmp = Path(tempfile.mkdtemp(prefix="cam-mem-"))
    try:
        (tmp / "machine.toml").write_text(MACHINE_TOML)
        hpgl_bytes = (200 << 20) // (16 if quick else 1)
        relief_px = 1024 if quick else 4096
        n_points = write_hpgl(tmp / "big.plt", hpgl_bytes)
        write_relief(tmp / "relief.png", relief_px)
        py = sys.executable
        floor = statistics.median(peak_rss_mb([py, "-c", "import cam, numpy, cv2"], tmp) for _ in range(repeats))
        jobs = [
            (f"HPGL {hpgl_bytes / 2**20:.0f} MB, {n_points / 1e6:.1f}M points (streamed, constant ramps)",
             [py, "-m", "cam", "drill", "big.plt", "--machine", "machine.toml", "--yes", "--no-progress",
              "--ramp", "constant", "--pin-log", "big.csv"]),
            (f"relief {relief_px}^2 dome",
             [py, "-m", "cam", "drill", "relief.png", "--machine", "machine.toml", "--yes", "--no-progress",
              "--profile-expr", "1 + k // 8", "--ramp", "constant", "--pin-log", "relief.csv"]),
        ]
        rows = []
        for name, argv in jobs:
            try:
                peak = statistics.median(peak_rss_mb(argv, tmp) for _ in range(repeats))
            except RuntimeError as exc:
                rows.append(dict(name=f"memory: cam drill {name} on the mock, peak RSS", cam=None, ref=floor,
                                 ratio="failed", target=f"< {GOAL_MB:.0f} MB", met=False, note=str(exc)[-200:]))
                continue
            log_mb = (tmp / argv[-1]).stat().st_size / 2**20
            rows.append(dict(name=f"memory: cam drill {name} on the mock, peak RSS (MB) vs import floor",
                             cam=peak, ref=floor, ratio=f"{peak:.0f} MB = {peak / floor:.1f}x floor",
                             target=f"< {GOAL_MB:.0f} MB", met=peak < GOAL_MB,
                             note=f"pin log {log_mb:.0f} MB"))
        return rows
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1/16 of the HPGL file, a 1024^2 relief")
    args = ap.parse_args(argv)
    print("| workload | cam peak RSS (MB) | floor (MB) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in bench_rows(args.quick):
        cam_mb = "" if r["cam"] is None else f"{r['cam']:.0f}"
        print(f"| {r['name']} | {cam_mb} | {r['ref']:.0f} | {r['ratio']} ({r['note']}) | {r['target']} | "
              f"{'yes' if r['met'] else '**no**'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
