"""Benchmark (issue #19 point 6): reliefs cut with real tools, `cam` against LinuxCNC's image-to-gcode.

    python benchmarks/tools_vs_i2g.py            # the relief benchmark's 512^2 dome and five 3D samples
    python benchmarks/tools_vs_i2g.py --quick    # its 128^2 dome and samples/disc.png with the dome profile

For each relief (the dome of the relief rows 4 and 6 of ``benchmarks/run.py``
and the 3D samples with a profile) and each tool -- ball 1 mm, flat 1 mm and a
sharp 60 degree V bit (its cone 3.175 mm across, the 1/8 inch shank; image-to-gcode's
V bits are sharp) -- both programs cut the same target at the same pixel size
(8 x 0.0289 = 0.2312 mm) and are carved with the same tool and the same code:

* `cam`: ``cam.plan(..., tool=...)``, run on the mock, the pin log decoded, every
  step position carved by :func:`cam.verify.toolcarve.carve_tool`;
* image-to-gcode: the target as its grey image (exact levels: grey = 255 - depth in
  Z pixels, depth = 255 Z pixels), mm units, its tool of the same shape and
  diameter, every row (stepover 1 pixel: its finest surface), the border extended
  with the surface (else it leaves a tool's width uncut), no roughing (`cam` has
  none here either), safety height one Z step (`cam` travels at the surface; at
  0 its arc entries become zero-length arcs that rs274 refuses), tolerance
  half a Z step (its default, 0.001 in, would let its path simplification cut up
  to 1.6 Z steps into the relief); its G-code through rs274's canonical path, split
  into the step positions the same stepper machine passes through
  (``tests/support/lcnc.py``), carved by the same ``carve_tool``.

Compared with the target (:func:`cam.verify.toolcarve.compare_surface`): the
largest gouge (cut below the target; `cam` must have none), the rest material's
mean and 95th percentile over the pixels with a target below the surface
(`cam`'s no larger than image-to-gcode's), and the machine time: `cam`'s step
plan's estimate (with its speed ramps), image-to-gcode's canonical path at the
machine's top speeds with no acceleration at all (each segment takes its
longest axis's travel at that axis's speed, as the step plan times a move),
which only flatters image-to-gcode.  Goal: `cam` <= 0.6x.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # tests/support: the LinuxCNC reference

import cam  # noqa: E402
from cam.tool import Tool, parse_tool  # noqa: E402
from cam.verify.toolcarve import carve_tool, compare_surface, least_rest_steps  # noqa: E402

ITG = Path("/usr/bin/image-to-gcode")
SYSTEM_PYTHON = Path("/usr/bin/python3")

TOOLS = [  # (cam spec, image-to-gcode tool_type, its diameter in mm)
    ("ball:1", 0, 1.0),
    ("flat:1", 1, 1.0),
    ("v:60:0:3.175", 4, 3.175),
]

RUNNER = textwrap.dedent('''
    import importlib.machinery, importlib.util, io, json, sys, time
    loader = importlib.machinery.SourceFileLoader("itg", "/usr/bin/image-to-gcode")
    spec = importlib.util.spec_from_loader("itg", loader)
    itg = importlib.util.module_from_spec(spec)
    image, out, options = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
    sys.argv = ["image-to-gcode", image]
    loader.exec_module(itg)
    itg.ui = lambda im, nim, name: options
    real_stdout = sys.stdout
    sys.stdout = io.StringIO()
    t0 = time.perf_counter()
    itg.main()
    elapsed = time.perf_counter() - t0
    gcode = sys.stdout.getvalue()
    sys.stdout = real_stdout
    open(out, "w").write(gcode)
    print(elapsed)
''')


@dataclass
class Outcome:
    """One program's cut of one relief with one tool."""

    time_s: float
    max_gouge_mm: float
    rest_mean_mm: float
    rest_p95_mm: float
    wall_s: float


def reliefs(quick: bool) -> list[tuple[str, "cam.Digitized", "cam.Profile"]]:
    """``(name, digitized, profile)`` of the benchmark's reliefs."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from run import _relief_job  # type: ignore  # the relief rows' own dome

    size = 128 if quick else 512
    _, d, profile = _relief_job(size)
    out = [(f"relief {size}^2 dome", d, profile)]
    samples = [("disc.png", "dome.png")] if quick else [
        ("disc.png", "dome.png"), ("pyramid.png", "pyramid.png"), ("heart.png", "cone.png"),
        ("ring.png", "dome.png"), ("dumbbell.png", "cone.png")]
    for drawing, prof in samples:
        out.append((f"{drawing} + {prof}", cam.digitize(cam.load_image(ROOT / "samples" / drawing)),
                    cam.load_profile(ROOT / "profiles" / prof)))
    return out


def target_steps(d, profile, settings) -> np.ndarray:
    """The relief at each pixel centre, Z steps below the surface: the point tool's plan simulated (the point
    planner cuts each pixel exactly to its depth, as the test suite checks)."""
    return np.asarray(cam.simulate_surface(cam.plan(d, profile=profile, settings=settings)), np.float64)


def cut_by_cam(d, profile, tool: Tool, target: np.ndarray, settings) -> Outcome:
    t0 = time.perf_counter()
    job = cam.plan(d, profile=profile, tool=tool, settings=settings)
    plan = cam.plan_steps(job)
    wall = time.perf_counter() - t0
    motion = cam.decode_pin_log(cam.run(plan).pin_log(), settings)
    carved = carve_tool(motion, target.shape, tool, settings, origin_px=job.origin_px)
    c = compare_surface(carved.depth_steps, target, settings)
    return Outcome(plan.estimated_time_s, c.max_gouge_mm, c.rest_mean_mm, c.rest_p95_mm, wall)


def cut_by_itg(target: np.ndarray, tool: Tool, tool_type: int, diameter_mm: float, settings, tmp: Path, *,
               shift_px: tuple[int, int] = (0, 0)) -> Outcome:
    """image-to-gcode's cut of ``target`` (Z steps) with its tool ``tool_type`` of ``diameter_mm``, carved with
    ``tool``; ``shift_px`` moves its path by whole pixels (x, y) (a test that the frames meet shifts it)."""
    from support.lcnc import canonical_motion, canonical_time_s, parse_canonical, run_rs274

    s = settings
    zpx_steps = s.steps_per_px_z
    depth_zpx = np.rint(target / zpx_steps).astype(np.int64)
    if depth_zpx.max() > 255:
        raise ValueError("a relief deeper than 255 Z pixels does not fit image-to-gcode's 8-bit image exactly")
    h, w = target.shape
    image = tmp / "relief.png"
    cv2.imwrite(str(image), (255 - depth_zpx).astype(np.uint8))
    px_mm = s.px_to_mm_xy(1)
    options = dict(invert=False, normalize=False, expand=1, pixel_size=px_mm, depth=255 * s.px_to_mm_z(1),
                   pixelstep=1, tool_diameter=diameter_mm, safety_height=s.mm_per_step_z, tool_type=tool_type,
                   tolerance=s.mm_per_step_z / 2, feed_rate=s.max_speed_x_mm_s * 60,
                   plunge_feed_rate=s.max_speed_z_mm_s * 60, units=1, pattern=0, converter=0, bounded=0,
                   contact_angle=45, spindle_speed=1000, roughing_offset=0, roughing_depth=0)
    script = tmp / "itg.py"
    script.write_text(RUNNER)
    ngc = tmp / "relief.ngc"
    out = subprocess.run([str(SYSTEM_PYTHON), str(script), str(image), str(ngc), json.dumps(options)],
                         capture_output=True, text=True, timeout=7200)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-500:])
    wall = float(out.stdout.strip().splitlines()[-1])
    moves = parse_canonical(run_rs274(str(ngc)))
    # image-to-gcode's frame: the tool's window starts at padded pixel (j, i) and its axis is dia/2 pixels in
    # (dia = its tool's width in pixels); the image is padded by dia on every side; X = i x pixel, Y = (rows of
    # the padded image - dia - j) x pixel.  In cam's frame (pixel centres at whole numbers, rows down):
    dia = max(2, int(diameter_mm / px_mm + .5))
    spp = s.steps_per_px_xy
    offset = ((shift_px[0] - dia / 2) * spp, (shift_px[1] + h + dia - dia / 2) * spp, 0.0)
    motion = canonical_motion(moves, s, offset_steps=offset, max_chord_mm=s.mm_per_step_z)
    carved = carve_tool(motion, target.shape, tool, s)
    c = compare_surface(carved.depth_steps, target, s)
    return Outcome(canonical_time_s(moves, s), c.max_gouge_mm, c.rest_mean_mm, c.rest_p95_mm, wall)


def _um(v_mm: float) -> str:
    return f"{v_mm * 1000:.2f}"


def _times(a: float, b: float) -> str:
    """``a`` as a multiple of ``b`` (for what a goal misses by)."""
    return f"{a / b:.1f}x" if b > 0 else ("equal" if a == 0 else "more, against none")


def bench_rows(quick: bool) -> list[dict]:
    """Rows in the format of ``benchmarks/run.py``: one per relief and tool, machine times in the time columns."""
    settings = cam.MachineSettings()
    if not (ITG.exists() and SYSTEM_PYTHON.exists() and shutil.which("rs274")):
        return [dict(name="tools vs image-to-gcode", cam=None, ref=None, ratio="n/a", target="", met=None,
                     note="image-to-gcode or rs274 not installed")]
    rows = []
    tmp = Path(tempfile.mkdtemp())
    try:
        for name, d, profile in reliefs(quick):
            target = target_steps(d, profile, settings)
            for spec, tool_type, dia in TOOLS:
                tool = parse_tool(spec)
                ours = cut_by_cam(d, profile, tool, target, settings)
                theirs = cut_by_itg(target, tool, tool_type, dia, settings, tmp)
                ratio = ours.time_s / theirs.time_s
                gouge_ok = ours.max_gouge_mm == 0
                rest_ok = ours.rest_mean_mm <= theirs.rest_mean_mm and ours.rest_p95_mm <= theirs.rest_p95_mm
                time_ok = ratio <= 0.6
                missed = []
                if not gouge_ok:
                    missed.append(f"gouge {_um(ours.max_gouge_mm)} um")
                for what, a, b in (("rest mean", ours.rest_mean_mm, theirs.rest_mean_mm),
                                   ("rest p95", ours.rest_p95_mm, theirs.rest_p95_mm)):
                    if a > b:
                        missed.append(f"{what} {_times(a, b)} image-to-gcode's" if b > 0 else
                                      f"{what} {_um(a)} um against none")
                if not rest_ok:  # is less rest possible at all without a gouge, on this machine?
                    floor = least_rest_steps(target, tool, settings)[target > 0] * settings.mm_per_step_z
                    f_mean, f_p95 = float(floor.mean()), float(np.percentile(floor, 95))
                    only_by_gouging = f_mean > theirs.rest_mean_mm or f_p95 > theirs.rest_p95_mm
                    missed.append(f"no cut without a gouge leaves less than {_um(f_mean)} um mean, {_um(f_p95)} um "
                                  f"p95 on this machine (every step position, brute force)"
                                  + ("; image-to-gcode's is less only by its gouge" if only_by_gouging else ""))
                if not time_ok:
                    missed.append(f"time {ratio:.2f}x")
                text = (f"time {ratio:.2f}x; rest mean {_um(ours.rest_mean_mm)} vs {_um(theirs.rest_mean_mm)} um, "
                        f"p95 {_um(ours.rest_p95_mm)} vs {_um(theirs.rest_p95_mm)} um; max gouge "
                        f"{_um(ours.max_gouge_mm)} vs {_um(theirs.max_gouge_mm)} um")
                note = (f"cam vs image-to-gcode; conversion {ours.wall_s:.2f} s vs {theirs.wall_s:.1f} s"
                        + (f"; misses: {', '.join(missed)}" if missed else ""))
                rows.append(dict(name=f"tool {tool.describe()}: {name}, machine time", cam=ours.time_s,
                                 ref=theirs.time_s, ratio=text, target="gouge 0, rest <= i2g, time <= 0.6x",
                                 met=not missed, note=note))
                print(f"  ... {rows[-1]['name']}: {text}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=(__doc__ or "").strip().splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small reliefs only (under a minute)")
    quick = ap.parse_args(argv).quick
    print("| workload | cam (machine s) | image-to-gcode (machine s) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in bench_rows(quick):
        met = {True: "yes", False: "**no**", None: "n/a"}[r["met"]]
        cam_s = "" if r["cam"] is None else f"{r['cam']:.1f}"
        ref_s = "" if r["ref"] is None else f"{r['ref']:.1f}"
        print(f"| {r['name']} | {cam_s} | {ref_s} | {r['ratio']} ({r['note']}) | {r['target']} | {met} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
