"""Benchmarks: `cam` against references measured in the same process and the same run.

    python benchmarks/run.py            # full workloads (several minutes)
    python benchmarks/run.py --quick    # small workloads, under a minute

Each row gives `cam`'s median, the reference's median, and their ratio.
Machines here are shared and noisy, so every time is the median of several
repeats; nothing in the test suite asserts a time.
"""
from __future__ import annotations

import argparse
import datetime
import gc
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # tests/support: the LinuxCNC reference

import cam  # noqa: E402
from cam.digitize.drawing import BLACK, RED, WHITE, Drawing  # noqa: E402
from cam.motion.chunks import plan_chunks  # noqa: E402


def median_time(fn, repeats: int) -> tuple[float, object]:
    """Median wall time of ``fn()`` over ``repeats`` runs (after one warm-up), and its last result."""
    out = fn()
    times = []
    for _ in range(repeats):
        gc.collect()
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


# ---------------------------------------------------------------- workloads


def drawing_2d(size_px: int, n_curves: int, seed: int = 1) -> np.ndarray:
    """Black mask with closed curves and open arcs, kept apart so each is one 1-pixel curve."""
    rng = np.random.default_rng(seed)
    mask = np.zeros((size_px, size_px), np.uint8)
    taken = np.zeros_like(mask)
    placed = 0
    scale = size_px / 4096
    while placed < n_curves:
        r = int(rng.integers(int(30 * scale) + 6, int(70 * scale) + 8))
        c = (int(rng.integers(r + 4, size_px - r - 4)), int(rng.integers(r + 4, size_px - r - 4)))
        box = taken[c[1] - r - 3:c[1] + r + 4, c[0] - r - 3:c[0] + r + 4]
        if box.any():
            continue
        box[:] = 1
        if placed % 2:
            cv2.circle(mask, c, r, 1, 1, cv2.LINE_8)
        else:
            cv2.ellipse(mask, c, (r, max(4, r // 2)), int(rng.integers(0, 180)), 0, int(rng.integers(90, 300)), 1, 1,
                        cv2.LINE_8)
        placed += 1
    return mask


def disc_classes(size_px: int, radius_px: int) -> np.ndarray:
    mask = np.zeros((size_px, size_px), np.uint8)
    cv2.circle(mask, (size_px // 2, size_px // 2), radius_px, 1, -1)
    inner = cv2.erode(mask, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8))
    classes = np.where(mask > 0, RED, WHITE).astype(np.uint8)
    classes[(mask > 0) & (inner == 0)] = BLACK
    return classes


def row(name: str, cam_s: float | None, ref_s: float | None, ratio_text: str, target: str, met: bool | None,
        note: str = "") -> dict:
    return dict(name=name, cam=cam_s, ref=ref_s, ratio=ratio_text, target=target, met=met, note=note)


def bench_trace_2d(quick: bool) -> dict:
    size, n = (1024, 40) if quick else (4096, 400)
    mask = drawing_2d(size, n)
    drawing = Drawing(classes=np.where(mask > 0, BLACK, WHITE).astype(np.uint8))
    reps = 5 if quick else 7
    t_cam, d = median_time(lambda: cam.digitize(drawing), reps)
    t_ref, _ = median_time(lambda: cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE), reps)
    r = t_cam / t_ref
    return row(f"2D trace {size}^2, {int(mask.sum())} px, {len(d.objects)} curves", t_cam, t_ref, f"{r:.2f}x",
               "<= 3x cv2.findContours", r <= 3)


def bench_peel_3d(quick: bool) -> dict:
    from scipy.ndimage import distance_transform_cdt

    size, radius = (512, 250) if quick else (2048, 1000)
    classes = disc_classes(size, radius)
    drawing = Drawing(classes=classes)
    mask = (classes != WHITE).astype(np.uint8)
    reps = 3 if quick else 5
    t_cam, d = median_time(lambda: cam.digitize(drawing), reps)
    t_ref, _ = median_time(lambda: distance_transform_cdt(mask, metric="taxicab"), reps)
    r = t_cam / t_ref
    return row(f"3D peel {size}^2 disc, {int(mask.sum())} px, {d.n_layers} layers", t_cam, t_ref, f"{r:.2f}x",
               "<= 3x scipy cdt", r <= 3)


def _rgb_2d(size_px: int, n_curves: int) -> np.ndarray:
    return np.where(drawing_2d(size_px, n_curves)[..., None] > 0, 0, 255).astype(np.uint8).repeat(3, axis=2)


def _rgb_3d(size_px: int) -> np.ndarray:
    palette = np.array([[255, 255, 255], [0, 0, 0], [255, 0, 0]], np.uint8)
    return palette[disc_classes(size_px, size_px // 2 - 24)]


def _black_mask(rgb: np.ndarray) -> np.ndarray:
    return cv2.inRange(rgb, (0, 0, 0), (127, 127, 127))


def bench_whole_path(quick: bool) -> list[dict]:
    """Rows 11-14 (#17): an RGB array or a PNG file to a digitized matrix (loading, classifying, rule checks,
    tracing or peeling) against cv2.inRange (the black mask) + cv2.findContours or scipy's cdt."""
    from scipy.ndimage import distance_transform_cdt

    size, n = (512, 40) if quick else (2048, 300)
    reps = 5 if quick else 9
    tmp = Path(tempfile.mkdtemp())
    rows = []
    for kind, rgb in (("2D", _rgb_2d(size, n)), ("3D", _rgb_3d(size))):
        if kind == "2D":
            def ref_of(img):
                return cv2.findContours(_black_mask(img), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
            ref_name = "cv2.inRange + cv2.findContours"
            what = f"{n} thin curves"
        else:
            def ref_of(img):
                return distance_transform_cdt(cv2.inRange(img, (0, 0, 0), (255, 127, 127)), metric="taxicab")
            ref_name = "cv2.inRange + scipy cdt"
            what = "red disc, black contour"
        path = tmp / f"{kind}.png"
        cv2.imwrite(str(path), rgb[:, :, ::-1])
        for source in ("array", "PNG file"):
            if source == "array":
                t_cam, d = median_time(lambda: cam.digitize(cam.load_image(rgb)), reps)
                t_ref, _ = median_time(lambda: ref_of(rgb), reps)
                ref_text = ref_name
            else:
                t_cam, d = median_time(lambda: cam.digitize(cam.load_image(path)), reps)
                t_ref, _ = median_time(lambda: ref_of(cv2.imread(str(path))), reps)
                ref_text = "cv2.imread + " + ref_name
            r = t_cam / t_ref
            rows.append(row(f"{kind} RGB {source} -> digitized matrix {size}^2, {what}, {len(d.objects)} objects",
                            t_cam, t_ref, f"{r:.2f}x", f"<= 3x {ref_text}", r <= 3))
    shutil.rmtree(tmp, ignore_errors=True)
    return rows


def bench_cold_start(quick: bool) -> list[dict]:
    """Row 15 (#17 point 2, #48 point 5): whole processes, the README's first command with an empty kernel cache
    (numba compiles the kernels it uses into the cache, saying so once on stderr), the run after it (loads them)
    and warm runs: ``benchmarks/bench_cold_start.py``, one round."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_cold_start as cold  # type: ignore

    runs = cold.one_round(2 if quick else 3)
    wall = {name: statistics.median(w for w, _ in values) for name, values in runs.items()}
    command = "cam " + " ".join(cold.COMMAND)
    return [row(f"cold start: {command}, first run with an empty kernel cache (compiles, note on stderr)",
                wall["cold"], wall["warm"], f"{wall['cold']:.0f} s, {wall['cold'] / wall['warm']:.1f}x warm",
                f"<= {cold.COLD_GOAL_S:.0f} s", wall["cold"] <= cold.COLD_GOAL_S),
            row(f"cold start: {command}, second run (loads the kernel cache) vs warm", wall["second"], wall["warm"],
                f"{wall['second'] / wall['warm']:.2f}x warm", f"<= {cold.SECOND_GOAL_X:.0f}x warm",
                wall["second"] <= cold.SECOND_GOAL_X * wall["warm"])]


def bench_planning(quick: bool) -> dict:
    size, radius = (512, 250) if quick else (2048, 1000)
    d = cam.digitize(Drawing(classes=disc_classes(size, radius)))
    profile = cam.Profile(np.full(d.n_layers, 1, np.int64))
    reps = 3

    big = cam.MachineSettings().replace(travel=cam.settings.Travel(x_max_steps=10**6, y_max_steps=10**6))

    def full_plan():
        # the path a job takes (cam.prepare_job, cam drill): the step plan made a chunk at a time, every
        # chunk's writes made and timed; the in-memory plan_steps makes the same writes but faults in a
        # gigabyte of fresh pages, which costs more than the arithmetic on some machines
        job = cam.plan(d, profile=profile, settings=big)
        plan = plan_chunks(job)
        for _ in plan.chunks():
            pass
        return plan

    t_cam, plan = median_time(full_plan, reps)
    steps = int(plan.steps_total[:2].sum())
    rate = steps / t_cam
    return row(f"planning {size}^2 disc -> step plan in chunks, {steps / 1e6:.1f}M X/Y steps", t_cam, None,
               f"{rate / 1e6:.1f}M steps/s", ">= 10M steps/s", rate >= 10e6)


def image_to_gcode_options(depth_in: float) -> dict:
    """image-to-gcode's dialog for the relief rows: a point-like ball (one pixel wide), every row, inches."""
    return dict(invert=False, normalize=False, expand=0, pixel_size=.006, depth=depth_in, pixelstep=1,
                tool_diameter=.006, safety_height=.012, tool_type=0, tolerance=.001, feed_rate=12,
                plunge_feed_rate=12, units=0, pattern=0, converter=0, bounded=0, contact_angle=45,
                spindle_speed=1000, roughing_offset=.1, roughing_depth=.25)


def _relief_job(size_px: int):
    classes = disc_classes(size_px, size_px // 2 - 6)
    d = cam.digitize(Drawing(classes=classes))
    n = d.n_layers
    depth = np.rint(1 + (n // 3) * np.sqrt(np.clip(1 - ((n - np.arange(1, n + 1)) / n) ** 2, 0, 1))).astype(int)
    return classes, d, cam.Profile(depth)


def bench_relief(quick: bool) -> tuple[dict, dict]:
    """Rows 4 and 6: relief conversion time and machine path length against LinuxCNC's image-to-gcode."""
    from cam.digitize.peel3d import peel_layers

    size = 128 if quick else 512
    classes, d, profile = _relief_job(size)
    layer = peel_layers(classes)
    target = np.where(layer > 0, profile.depth_px[np.maximum(layer, 1) - 1], 0)  # Z px
    reps = 3

    def convert():
        dd = cam.digitize(Drawing(classes=classes))
        return cam.plan(dd, profile=profile)

    t_cam, job = median_time(convert, reps)
    if not (Path("/usr/bin/image-to-gcode").exists() and Path("/usr/bin/python3").exists()):
        return (row(f"relief {size}^2 dome: conversion", t_cam, None, "n/a", ">= 50x faster", None,
                    "image-to-gcode not installed"), row("relief path length", None, None, "n/a", "<= 0.6x", None))
    tmp = Path(tempfile.mkdtemp())
    dmax = int(target.max())
    grey = np.rint(255 * (1 - target / dmax)).astype(np.uint8)
    cv2.imwrite(str(tmp / "relief.png"), grey)
    depth_in = dmax * 0.006  # one Z pixel = one pixel size, in inches (image-to-gcode's default units)
    from tools_vs_i2g import RUNNER  # image-to-gcode's own main() with its dialog's answers, timed

    script = tmp / "itg.py"
    script.write_text(RUNNER)
    times = []
    for _ in range(1 if not quick else 1):
        out = subprocess.run(["/usr/bin/python3", str(script), str(tmp / "relief.png"),
                              str(tmp / "relief.png.ngc"), json.dumps(image_to_gcode_options(depth_in))],
                             capture_output=True, text=True, timeout=3600)
        if out.returncode != 0:
            return (row("relief conversion", t_cam, None, "error", ">= 50x faster", None, out.stderr[-200:]),
                    row("relief path length", None, None, "n/a", "<= 0.6x", None))
        times.append(float(out.stdout.strip().splitlines()[-1]))
    t_ref = statistics.median(times)
    r4 = row(f"relief {size}^2 dome: conversion vs image-to-gcode", t_cam, t_ref, f"{t_ref / t_cam:.0f}x faster",
             ">= 50x faster", t_ref / t_cam >= 50)
    # row 6: path length (cutting + travel) and surface error of both, in pixels
    from support.lcnc import canonical_polyline_mm, parse_canonical, run_rs274

    pts = np.vstack([[0, 0, 0], job.points_px()]).astype(np.float64)
    cam_len_euclid = float(np.linalg.norm(np.diff(pts[:, :2], axis=0), axis=1).sum())
    ours = cam.simulate_surface(job)
    cam_err = int(np.abs(ours - target * job.settings.steps_per_px_z).max())
    canon = parse_canonical(run_rs274(str(tmp / "relief.png.ngc")))
    poly, feed = canonical_polyline_mm(canon, max_chord_mm=0.05)
    px_mm = 0.006 * 25.4
    xy = poly[:, :2] / px_mm
    itg_len = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
    # their surface: sample feed moves on the pixel grid (row = -Y)
    theirs = np.zeros_like(target)
    for i in np.flatnonzero(feed):
        a, b = poly[i - 1], poly[i]
        n = max(2, int(np.ceil(np.abs((b - a)[:2]).max() / px_mm * 4)) * 2)
        t = np.concatenate([(np.arange(n) + 0.5) / n, [1.0]])
        seg = a + (b - a) * t[:, None]
        seg = seg[seg[:, 2] < 0]
        col = np.floor(seg[:, 0] / px_mm + 0.5).astype(int)
        rw = (size - 1) - np.floor(seg[:, 1] / px_mm + 0.5).astype(int)  # image-to-gcode: Y up from the last row
        ok = (col >= 0) & (col < size) & (rw >= 0) & (rw < size)
        np.maximum.at(theirs, (rw[ok], col[ok]), np.rint(-seg[ok, 2] / px_mm).astype(int))
    their_err = int(np.abs(theirs - target).max())
    ratio = cam_len_euclid / itg_len
    r6 = row(f"relief {size}^2 dome: path length vs image-to-gcode", cam_len_euclid, itg_len, f"{ratio:.2f}x",
             "<= 0.6x, cam surface exact", ratio <= 0.6 and cam_err == 0,
             f"max surface error: cam {cam_err} Z px, image-to-gcode {their_err} Z px; lengths in pixels")
    shutil.rmtree(tmp, ignore_errors=True)
    return r4, r6


def bench_memory(quick: bool) -> dict:
    size, radius = (1024, 500) if quick else (4096, 2000)
    code = textwrap.dedent(f'''
        import resource, sys
        sys.path.insert(0, {str(ROOT)!r})
        sys.path.insert(0, {str(ROOT / "benchmarks")!r})
        import numpy as np, cam
        from run import disc_classes
        from cam.digitize.drawing import Drawing
        cam.digitize(Drawing(classes=disc_classes(64, 20)))  # imports and compiled kernels loaded
        classes = disc_classes({size}, {radius})
        drawing = Drawing(classes=classes)
        def status_kb(key):
            return int([l for l in open("/proc/self/status") if l.startswith(key)][0].split()[1])
        # reset the peak-RSS mark: a child's ru_maxrss starts at its parent's RSS at fork time
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        rss_kb = status_kb("VmRSS")
        peak0 = status_kb("VmHWM")
        d = cam.digitize(drawing)
        peak = status_kb("VmHWM")
        print(rss_kb, peak0, peak)
    ''')
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=1800)
    rss_kb, peak0_kb, peak_kb = (int(v) for v in out.stdout.split())
    per_px = ((peak_kb - rss_kb) * 1024) / (size * size)
    return row(f"memory: 3D peel {size}^2, peak RSS growth of cam.digitize", None, None, f"{per_px:.1f} B/px",
               "<= 40 B/px", per_px <= 40,
               f"RSS {rss_kb / 1024:.0f} MB before (drawing loaded), peak {peak_kb / 1024:.0f} MB during")


def bench_drill_tour(quick: bool) -> dict:
    try:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import drill_tour  # type: ignore
    except ImportError:
        return row("drill tour", None, None, "n/a", "<= 1.03x OR-tools, <= 1 s", None, "benchmarks/drill_tour.py missing")
    return drill_tour.bench_row(quick)


def bench_tsplib(quick: bool) -> list[dict]:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import drill_tour  # type: ignore

    return drill_tour.tsplib_rows(quick)


def bench_realtime(quick: bool) -> dict:
    seconds = 2.0 if quick else 10.0
    s = cam.MachineSettings().replace(delay_xy_ms=1.0, delay_z_ms=1.0, ramp="constant")
    n = int(seconds * 1000)
    job = cam.Job(points_steps=np.array([[n, 0, 0]]), kind=np.zeros(1, np.uint8), target=np.zeros(1, bool),
                  pause=np.zeros(1, bool), settings=s.replace(travel=cam.settings.Travel(x_max_steps=n)))
    plan = cam.plan_steps(job)
    # the other core is kept busy by a separate process (a thread here would only fight for the GIL)
    procs = [subprocess.Popen([sys.executable, "-c", "import time\nt=time.time()\nwhile time.time()-t<%f: pass" % (seconds + 2)])]
    try:
        result = cam.run(plan, realtime=True)
    finally:
        for p in procs:
            p.wait()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from machine_first import interval_lateness  # type: ignore

    late = interval_lateness(result.pin_log().t_ns, plan.t_ns)
    p50, p99, mx, shortest = late["p50_us"], late["p99_us"], late["max_us"], late["min_ratio"]
    return row(f"real-time mock 1 kHz steps for {seconds:.0f} s, other core busy", None, None,
               f"lateness of a write p50 {p50:.0f} us, p99 {p99:.0f} us, max {mx:.0f} us; shortest interval "
               f"{shortest:.3f}x planned", "p99 <= 100 us, no interval under the planned one",
               p99 <= 100 and shortest >= 1.0)


def bench_machine_first(quick: bool) -> list[dict]:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import machine_first  # type: ignore

    return machine_first.bench_rows(quick)


def bench_ramps(quick: bool) -> dict:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import ramps  # type: ignore

    return ramps.bench_row(quick)


def bench_bounded_memory(quick: bool) -> list[dict]:
    """Row group 16 (#15 point 2): peak RSS of whole `cam drill` processes on the mock against the import floor."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bounded_memory  # type: ignore

    return bounded_memory.bench_rows(quick)


def bench_tools_vs_i2g(quick: bool) -> list[dict]:
    """Row group 17 (#19 point 6): reliefs cut with ball 1 mm, flat 1 mm and V 60 degree tools, cam against
    image-to-gcode with the same tool: gouge, rest material and machine time (benchmarks/tools_vs_i2g.py)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import tools_vs_i2g  # type: ignore

    return tools_vs_i2g.bench_rows(quick)


def _cell(value) -> str:
    """A time or count for the table: milliseconds-scale times keep their digits, counts none."""
    if value is None:
        return ""
    if isinstance(value, float) and value < 1e5:
        return f"{value:.6f}" if value < 0.01 else f"{value:.3f}"
    return f"{value:.0f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small workloads (under a minute)")
    ap.add_argument("--only", help="comma-separated row groups to run (1..17; 10: the machine first, 4 rows, "
                                   "14: cold start, and 16: bounded memory, whole processes, and 17: tools against "
                                   "image-to-gcode are left out of --quick unless named; "
                                   "11: the RGB array or PNG file to a digitized matrix, 4 rows; "
                                   "12: closed tours on TSPLIB instances; "
                                   "17: reliefs cut with real tools against image-to-gcode, machine times)")
    args = ap.parse_args(argv)
    benches = {
        1: bench_trace_2d, 2: bench_peel_3d, 3: bench_planning, 4: None, 5: bench_memory, 7: bench_drill_tour,
        8: bench_realtime, 9: bench_ramps, 10: bench_machine_first, 11: bench_whole_path, 12: bench_tsplib,
        14: bench_cold_start, 16: bench_bounded_memory, 17: bench_tools_vs_i2g,
    }
    everything = set(benches) | {6}
    only = ({int(v) for v in args.only.split(",")} if args.only
            else (everything - {10, 14, 16, 17} if args.quick else everything))
    rows: list[dict] = []
    for k in sorted(only):
        if k in (4, 6):
            if 4 in only or 6 in only:
                if not any(r.get("_relief") for r in rows):
                    r4, r6 = bench_relief(args.quick)
                    r4["_relief"] = r6["_relief"] = True
                    rows += [r4, r6]
            continue
        got = benches[k](args.quick)
        for r in got if isinstance(got, list) else [got]:
            rows.append(r)
            print(f"  ... {r['name']}: {r['ratio']}", file=sys.stderr, flush=True)
    print(f"cam benchmarks, {datetime.date.today().isoformat()}, {'quick' if args.quick else 'full'} workloads, "
          f"{os.cpu_count()} cores")
    print()
    print("| workload | cam (median s) | reference (median s) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in rows:
        c, f = _cell(r["cam"]), _cell(r["ref"])
        met = {True: "yes", False: "**no**", None: "n/a"}[r["met"]]
        note = f" ({r['note']})" if r["note"] else ""
        print(f"| {r['name']} | {c} | {f} | {r['ratio']}{note} | {r['target']} | {met} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
