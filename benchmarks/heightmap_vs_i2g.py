"""Benchmark (issue #31 point 7): grey-level reliefs, `cam drill --heightmap` against LinuxCNC's image-to-gcode.

    python benchmarks/heightmap_vs_i2g.py            # LinuxCNC's torus.png (400 x 400), three tools
    python benchmarks/heightmap_vs_i2g.py --quick    # the torus shrunk to 120 x 120

The image is LinuxCNC's own image-to-gcode sample, ``ncfiles/torus.png``
(``/usr/share/linuxcnc/ncfiles/torus.png``; where it is missing, a torus height
map made here).  Both programs read the same image, black deepest, with the
same tool (ball 1 mm, flat 1 mm, a sharp 60 degree V bit 3.175 mm across),
the same pixel (the machine's drawing pixel, 8 x 0.0289 = 0.2312 mm), the same
rows (image-to-gcode's "Rows", alternating, its stepover in pixels = `cam`'s
row spacing: half the tool's diameter) and the same depth: 255 Z steps (4.0 mm),
so every grey level is one Z step and both cut exactly the same target
(image-to-gcode: no normalising, the border extended with white, tolerance half
a Z step, safety height one Z step, as ``tools_vs_i2g.py`` runs it, with
Debian's ``/usr/bin/python3``).

Both cuts are carved with the same tool by the same code
(:func:`cam.verify.toolcarve.carve_tool`): `cam`'s from its decoded mock pin log,
image-to-gcode's from rs274's canonical path split into the step positions the
machine passes through.  Columns: machine time (`cam`: its step plan with its
speed ramps; image-to-gcode: its canonical path at the top speeds without any
acceleration, which flatters it, and `cam`'s timed the same way too), the largest gouge (cut below the height
map, and on what share of the pixels by over 1 um), the rest material (mean and 95th percentile over the
pixels asked to be cut; where a program gouges, less rest is no merit) and the
planning time (median of ``--repeat`` runs each; image-to-gcode's own
``main()``, `cam`'s ``prepare_job``).  Ratios are cam / image-to-gcode.
"""
from __future__ import annotations

import dataclasses
import json
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
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import cam  # noqa: E402
from cam.job.heightmap import depth_steps_of, load_heightmap, row_spacing_px  # noqa: E402
from cam.motion.chunks import plan_chunks  # noqa: E402
from cam.kinds.jobs import JobOptions, prepare_job  # noqa: E402
from cam.tool import parse_tool  # noqa: E402
from cam.verify.toolcarve import carve_tool, compare_surface  # noqa: E402
from tools_vs_i2g import ITG, RUNNER, SYSTEM_PYTHON, TOOLS  # noqa: E402  (its way of running i2g)
from tools_vs_i2g import Outcome as _Outcome  # noqa: E402


@dataclasses.dataclass
class Outcome(_Outcome):
    """One program's cut, and the share of the pixels it cut below the height map."""

    gouged_share: float = 0.0

TORUS = Path("/usr/share/linuxcnc/ncfiles/torus.png")
STEPOVER = 0.5


def torus_image(n: int = 400) -> np.ndarray:
    """A torus height map (a white ridge on black), ``(n, n)`` uint8: for a machine without LinuxCNC's sample."""
    yy, xx = np.mgrid[0:n, 0:n] - (n - 1) / 2
    r = np.hypot(xx, yy)
    big, small = n * 0.3, n * 0.15
    h = np.sqrt(np.clip(small * small - (r - big) ** 2, 0, None)) / small
    return np.rint(h * 200).astype(np.uint8)


def the_image(tmp: Path, quick: bool) -> Path:
    """The benchmark's image as an 8-bit grey PNG in ``tmp`` (both programs read this file)."""
    img = cv2.imread(str(TORUS), cv2.IMREAD_GRAYSCALE) if TORUS.exists() else torus_image()
    if quick:
        img = cv2.resize(img, (120, 120), interpolation=cv2.INTER_AREA)
    path = tmp / "relief.png"
    cv2.imwrite(str(path), img)
    return path


def cut_by_cam(image: Path, spec: str, max_depth_mm: float, target: np.ndarray, settings, repeat: int
               ) -> tuple[Outcome, int, float]:
    opts = JobOptions(heightmap=True, tool=spec, max_depth_mm=max_depth_mm, stepover=STEPOVER)
    walls = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        job = prepare_job(image, opts, settings)
        walls.append(time.perf_counter() - t0)
    motion = cam.decode_pin_log(cam.run(job.plan).pin_log(), settings)
    carved = carve_tool(motion, target.shape, parse_tool(spec), settings)
    c = compare_surface(carved.depth_steps, target, settings)
    # the same path timed as image-to-gcode's is: at the top speeds, no acceleration
    flat_out = plan_chunks(dataclasses.replace(job.toolpath, settings=settings.replace(ramp="constant"))
                           ).estimated_time_s
    return Outcome(job.estimated_time_s, c.max_gouge_mm, c.rest_mean_mm, c.rest_p95_mm,
                   statistics.median(walls), float(np.mean(c.gouge_mm > 0.001))), len(job.toolpath), flat_out


def cut_by_itg(image: Path, spec: str, tool_type: int, diameter_mm: float, max_depth_mm: float, step_px: int,
               target: np.ndarray, settings, tmp: Path, repeat: int) -> Outcome:
    from support.lcnc import canonical_motion, canonical_time_s, parse_canonical, run_rs274

    s = settings
    px_mm = s.px_to_mm_xy(1)
    options = dict(invert=False, normalize=False, expand=1, pixel_size=px_mm, depth=max_depth_mm,
                   pixelstep=step_px, tool_diameter=diameter_mm, safety_height=s.mm_per_step_z, tool_type=tool_type,
                   tolerance=s.mm_per_step_z / 2, feed_rate=s.max_speed_x_mm_s * 60,
                   plunge_feed_rate=s.max_speed_z_mm_s * 60, units=1, pattern=0, converter=2, bounded=0,
                   contact_angle=45, spindle_speed=1000, roughing_offset=0, roughing_depth=0)
    script = tmp / "itg.py"
    script.write_text(RUNNER)
    ngc = tmp / "relief.ngc"
    walls = []
    for _ in range(repeat):
        out = subprocess.run([str(SYSTEM_PYTHON), str(script), str(image), str(ngc), json.dumps(options)],
                             capture_output=True, text=True, timeout=7200)
        if out.returncode != 0:
            raise RuntimeError(out.stderr[-500:])
        walls.append(float(out.stdout.strip().splitlines()[-1]))
    moves = parse_canonical(run_rs274(str(ngc)))
    h = target.shape[0]
    dia = max(2, int(diameter_mm / px_mm + .5))  # its frame, as tools_vs_i2g.cut_by_itg places it
    spp = s.steps_per_px_xy
    offset = ((-dia / 2) * spp, (h + dia - dia / 2) * spp, 0.0)
    motion = canonical_motion(moves, s, offset_steps=offset, max_chord_mm=s.mm_per_step_z)
    carved = carve_tool(motion, target.shape, parse_tool(spec), s)
    c = compare_surface(carved.depth_steps, target, s)
    return Outcome(canonical_time_s(moves, s), c.max_gouge_mm, c.rest_mean_mm, c.rest_p95_mm,
                   statistics.median(walls), float(np.mean(c.gouge_mm > 0.001)))


def bench_rows(quick: bool, repeat: int = 3) -> list[dict]:
    """One row per tool, in the format of ``benchmarks/run.py`` (machine times in the time columns)."""
    settings = cam.MachineSettings()
    if not (ITG.exists() and SYSTEM_PYTHON.exists() and shutil.which("rs274")):
        return [dict(name="heightmap vs image-to-gcode", cam=None, ref=None, ratio="n/a", target="", met=None,
                     note="image-to-gcode or rs274 not installed")]
    max_depth_mm = 255 * settings.mm_per_step_z  # a grey level is a Z step: both cut the same target exactly
    rows = []
    tmp = Path(tempfile.mkdtemp())
    try:
        image = the_image(tmp, quick)
        target = depth_steps_of(load_heightmap(image), max_depth_mm, settings).astype(np.float64)
        name = ("torus.png" if TORUS.exists() else "a torus") + f" {target.shape[1]}x{target.shape[0]}"
        for spec, tool_type, dia in TOOLS:
            tool = parse_tool(spec)
            step_px = row_spacing_px(tool, settings.px_to_mm_xy(1), STEPOVER)
            ours, n_points, flat_out_s = cut_by_cam(image, spec, max_depth_mm, target, settings, repeat)
            theirs = cut_by_itg(image, spec, tool_type, dia, max_depth_mm, step_px, target, settings, tmp, repeat)
            ratio = ours.time_s / theirs.time_s
            text = (f"machine time {ratio:.2f}x ({flat_out_s / theirs.time_s:.2f}x without ramps, as "
                    f"image-to-gcode's is timed); max gouge {ours.max_gouge_mm * 1000:.1f} vs "
                    f"{theirs.max_gouge_mm * 1000:.1f} um (on {ours.gouged_share:.1%} vs {theirs.gouged_share:.1%} of the "
                    f"pixels); rest mean {ours.rest_mean_mm * 1000:.1f} vs "
                    f"{theirs.rest_mean_mm * 1000:.1f} um, p95 {ours.rest_p95_mm * 1000:.1f} vs "
                    f"{theirs.rest_p95_mm * 1000:.1f} um; planning {ours.wall_s:.2f} vs {theirs.wall_s:.2f} s "
                    f"({ours.wall_s / theirs.wall_s:.2f}x)")
            met = ours.max_gouge_mm == 0 and ratio <= 1.0
            rows.append(dict(name=f"heightmap {tool.describe()}: {name}, rows {step_px} px apart, machine time",
                             cam=ours.time_s, ref=theirs.time_s, ratio=text, target="gouge 0, time <= 1x",
                             met=met, note=f"cam vs image-to-gcode, {n_points} cam points"))
            print(f"  ... {rows[-1]['name']}: {text}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=(__doc__ or "").strip().splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the torus shrunk to 120 x 120 (about a minute)")
    ap.add_argument("--repeat", type=int, default=3, help="planning runs per program (the median is shown)")
    args = ap.parse_args(argv)
    print("| workload | cam (machine s) | image-to-gcode (machine s) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in bench_rows(args.quick, max(1, args.repeat)):
        met = {True: "yes", False: "**no**", None: "n/a"}[r["met"]]
        cam_s = "" if r["cam"] is None else f"{r['cam']:.1f}"
        ref_s = "" if r["ref"] is None else f"{r['ref']:.1f}"
        print(f"| {r['name']} | {cam_s} | {ref_s} | {r['ratio']} ({r['note']}) | {r['target']} | {met} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
