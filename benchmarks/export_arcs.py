"""Benchmark row: G-code out with lines and arcs fitted (issue #30 point 4) against the same job one G1 a point.

    python benchmarks/export_arcs.py            # the traced sketch and the dome relief, tolerances 0.01 and 0.05
    python benchmarks/export_arcs.py --quick    # the ellipse drawing instead of the traced sketch

Workloads: ``samples/sketch.jpg`` traced (``cam.trace``, as ``--trace``) and planned 3 Z px deep; the relief
``samples/disc.png`` under ``profiles/dome.png``.  Reference: the same job written by ``cam export --post grbl
--arc-tolerance 0`` (one ``G1`` a point, the feed written only where it changes, as the grbl post does).
Columns: lines and bytes of each program and their ratio (reference / fitted), the arcs written, the largest
deviation of the fitted path from the reference path below the surface (both decoded here from the G-code, arcs
split into 2 micrometre chords), and the median time to write each program (3 runs).
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
from cam.formats.gcode_export import to_gcode  # noqa: E402


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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the ellipse drawing instead of the traced sketch")
    args = ap.parse_args(argv)
    if args.quick:
        drawing = cam.load_image(ROOT / "samples" / "ellipse.png")
        first = ("ellipse drawing", cam.plan(cam.digitize(drawing), depth=3))
    else:
        traced = cam.trace(cam.load_sketch(ROOT / "samples" / "sketch.jpg"))
        first = ("traced sketch", cam.plan(cam.digitize(traced), depth=3))
    relief = cam.plan(cam.digitize(cam.load_image(ROOT / "samples" / "disc.png")),
                      profile=cam.load_profile(ROOT / "profiles" / "dome.png"))
    print("| job | tolerance mm | lines ref | lines fitted | ratio | bytes ref | bytes fitted | ratio | arcs "
          "| max deviation mm | write s ref | write s fitted |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, job in (first, ("dome relief", relief)):
        ref, t_ref = timed(job)
        for tol in (0.01, 0.05):
            fit, t_fit = timed(job, arc_tolerance_mm=tol)
            n_ref, n_fit = len(ref.splitlines()), len(fit.splitlines())
            arcs = sum(ln.startswith(("G2 ", "G3 ")) for ln in fit.splitlines())
            print(f"| {name} | {tol:g} | {n_ref} | {n_fit} | {n_ref / n_fit:.2f} | {len(ref)} | {len(fit)} "
                  f"| {len(ref) / len(fit):.2f} | {arcs} | {deviation_mm(fit, ref):.4f} | {t_ref:.3f} | {t_fit:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
