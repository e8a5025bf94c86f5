"""Benchmark row: G-code out with lines and arcs fitted (issue #30 point 4) against the same job one G1 a point.

    python benchmarks/export_arcs.py            # the traced sketch and the dome relief, tolerances 0.01 and 0.05
    python benchmarks/export_arcs.py --quick    # the ellipse drawing instead of the traced sketch

Workloads: ``samples/sketch.jpg`` traced (``cam.trace``, as ``--trace``) and planned 3 Z px deep; the relief
``samples/disc.png`` under ``profiles/dome.png``.  Reference: the same job written by ``cam export --post grbl
--arc-tolerance 0`` (one ``G1`` a point, the feed written only where it changes, as the grbl post does).
Columns: lines and bytes of each program and their ratio (reference / fitted), the arcs written, the largest
deviation of the fitted path from the reference path below the surface (both decoded here from the G-code, arcs
split into 2 micrometre chords), the median time to write each program (3 runs), and (``--grbl``) the machine
time of each program on the grbl emulator (``cam.sim.grbl``: grbl's accelerations and junction speeds, a router's
rates; streamed by ``cam.drive.grbl_link`` with character counting at 1 Mbaud, the emulator 10x sped up so the
rows take minutes, not hours) with its planner starvations.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cam  # noqa: E402
from cam.drive.grbl_link import GrblLink  # noqa: E402
from cam.kinds.gcode_export import to_gcode  # noqa: E402
from cam.sim.grbl import start_emulator  # noqa: E402

GRBL = {110: 3000.0, 111: 3000.0, 112: 1500.0, 120: 200.0, 121: 200.0, 122: 200.0}
"""A small router's $110-$122 (the feeds of these programs are the thesis machine's 347 mm/min)."""


def path_of(text: str, chord_mm: float = 0.002) -> np.ndarray:
    """``(K, 3)`` mm points of a program's path (G0/G1 lines, G2/G3 XY arcs by I/J), densely sampled."""
    pos = np.zeros(3)
    out = [pos.copy()[None, :]]
    motion = 0
    for raw in text.splitlines():
        line = raw.split("(")[0].strip()
        if not line or line[0] not in "GXYZ":
            continue
        words = {w[0]: float(w[1:]) for w in line.split() if w[0] in "XYZIJ"}
        for w in line.split():
            if w in ("G0", "G1", "G2", "G3"):
                motion = int(w[1])
        if not any(k in words for k in "XYZ"):
            continue
        end = np.array([words.get("X", pos[0]), words.get("Y", pos[1]), words.get("Z", pos[2])])
        if motion in (0, 1):
            n = max(1, int(math.ceil(np.linalg.norm(end - pos) / chord_mm)))
            out.append(pos + (end - pos) * (np.arange(1, n + 1) / n)[:, None])
        else:
            cx, cy = pos[0] + words["I"], pos[1] + words["J"]
            a0 = math.atan2(pos[1] - cy, pos[0] - cx)
            a1 = math.atan2(end[1] - cy, end[0] - cx)
            sweep = (a1 - a0) % (2 * math.pi) if motion == 3 else -((a0 - a1) % (2 * math.pi))
            r = math.hypot(pos[0] - cx, pos[1] - cy)
            n = max(2, int(math.ceil(abs(sweep) * r / chord_mm)))
            t = np.arange(1, n + 1) / n
            a = a0 + sweep * t
            out.append(np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), pos[2] + (end[2] - pos[2]) * t]))
        pos = end
    return np.concatenate(out)


def deviation_mm(fitted: str, reference: str) -> float:
    """The Hausdorff distance between the two paths below the surface (Z < 0)."""
    a, b = path_of(fitted), path_of(reference)
    a, b = a[a[:, 2] < -1e-6], b[b[:, 2] < -1e-6]
    return float(max(cKDTree(b).query(a)[0].max(), cKDTree(a).query(b)[0].max()))


def timed(job, **options) -> tuple[str, float]:
    times, text = [], ""
    for _ in range(3):
        t0 = time.perf_counter()
        text = to_gcode(job, post="grbl", **options)
        times.append(time.perf_counter() - t0)
    return text, statistics.median(times)


def grbl_machine_s(text: str) -> tuple[float, int]:
    """(simulated machine seconds, planner starvations) of a program on the grbl emulator."""
    emu = start_emulator(speed=10.0, settings=GRBL, baud=1_000_000)
    try:
        with GrblLink(f"grbl:{emu.device_path}?baud=1000000") as link:
            t0 = emu.time_s
            link.stream([ln for ln in text.splitlines() if not ln.startswith("M0")])
            return emu.executed()[-1].t_end_s - t0, emu.starvation_count
    finally:
        emu.stop()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the ellipse drawing instead of the traced sketch")
    ap.add_argument("--grbl", action="store_true", help="also each program's machine time on the grbl emulator")
    args = ap.parse_args(argv)
    if args.quick:
        drawing = cam.load_image(ROOT / "samples" / "ellipse.png")
        first = ("ellipse drawing", cam.plan(cam.digitize(drawing), depth=3))
    else:
        traced = cam.trace(cam.load_sketch(ROOT / "samples" / "sketch.jpg"))
        first = ("traced sketch", cam.plan(cam.digitize(traced), depth=3))
    relief = cam.plan(cam.digitize(cam.load_image(ROOT / "samples" / "disc.png")),
                      profile=cam.load_profile(ROOT / "profiles" / "dome.png"))
    extra = " grbl s ref | grbl s fitted | ratio | starved ref/fitted |" if args.grbl else ""
    print("| job | tolerance mm | lines ref | lines fitted | ratio | bytes ref | bytes fitted | ratio | arcs "
          "| max deviation mm | write s ref | write s fitted |" + extra)
    print("|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|---|---|---|" if args.grbl else ""))
    for name, job in (first, ("dome relief", relief)):
        ref, t_ref = timed(job)
        for tol in (0.01, 0.05):
            fit, t_fit = timed(job, arc_tolerance_mm=tol)
            n_ref, n_fit = len(ref.splitlines()), len(fit.splitlines())
            arcs = sum(ln.startswith(("G2 ", "G3 ")) for ln in fit.splitlines())
            row = (f"| {name} | {tol:g} | {n_ref} | {n_fit} | {n_ref / n_fit:.2f} | {len(ref)} | {len(fit)} "
                   f"| {len(ref) / len(fit):.2f} | {arcs} | {deviation_mm(fit, ref):.4f} | {t_ref:.3f} | {t_fit:.3f} |")
            if args.grbl:
                (m_ref, s_ref), (m_fit, s_fit) = grbl_machine_s(ref), grbl_machine_s(fit)
                row += f" {m_ref:.1f} | {m_fit:.1f} | {m_ref / m_fit:.2f} | {s_ref}/{s_fit} |"
            print(row, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
