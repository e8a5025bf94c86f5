"""Benchmark rows (issue #46 point 6): probing a board and levelling a cut to it, on the mock's warped surface.

    python benchmarks/bench_probe.py            # the 100 x 80 mm board at 10 mm (about 10 s)
    python benchmarks/bench_probe.py --quick    # a 30 x 20 mm board, a small drawing (a few seconds)

The surface: ``[mock] probe_surface`` tilted 0.36 mm along X and 0.08 mm along Y and bowed 0.2 mm from its centre
to its corners (0.5 mm of tilt and bow over the board at machine X 20..120, Y 20..100 mm; ``tests/test_level.py``'s
``WARP``), on the built-in machine (0.0289 mm X/Y steps, 0.0157 mm Z steps, its speeds and ramps; a probe input).
The work zero: machine X 30, Y 30 mm, its Z the surface there (as ``cam probe z`` finds it); every procedure starts
there, 5 mm above it.

(a) Probing the board every 10 mm (11 x 9 = 99 points).  Three procedures, each run on the same mock (cam's planner
plans every move, with this machine's ramps; a probe is a seek at the probe feed that stops on the step the probe
closes; machine time is the mock's simulated clock):

* ``cam``: ``MachineSession.probe_grid`` as ``cam probe grid --area 20,20,120,100 --machine-coords`` runs it
  (defaults: safe height 2 mm above the work Z zero, probe feed 20 mm/min, at most 4 mm down; serpentine order): the
  first point probed from the safe height; each later one (``cam.drive.probe_grid.GridApproach``) travelled to at
  0.5 mm above the previous contact plus the map's neighbour limit (1 mm) or above the highest contact so far, a
  rapid down to the guard height (the previous contact plus the limit), a guarded move (stopped by the probe) at
  Z's start speed (47 mm/min) down to 0.3 mm above the previous contact, the probe from there at most to 1 mm below
  the previous contact, a lift back to where it began.
* bCNC (``vlachoudis/bCNC`` at 23103b0, ``bCNC/CNC.py`` ``Probe.scan``; defaults from ``bCNC/bCNC.ini``
  ``[Probe]`` ``zmax = 5.0``, ``zmin = -10.0``, ``feed = 10.0``, ``cmd = G38.2``, and ``CNC.vars["safe"] = 3.0``):
  ``G0 Z3``, ``G0`` to the first point, then per point ``G0 Z5``, ``G0 X Y``, ``G38.2 Z-10 F10``, serpentine rows
  (its ``xstep`` changes sign each row); at the end ``G0 Z5`` and back to the first point.
* OpenCNCPilot (``martin2250/OpenCNCPilot`` at 09c47c6, ``MainWindow.ProbingTab.xaml.cs``; defaults from
  ``Properties/Settings.settings``: ``ProbeSafeHeight`` 5, ``ProbeMinimumHeight`` 1, ``ProbeMaxDepth`` 5,
  ``ProbeFeed`` 20 mm/min, ``ProbeXAxisWeight`` 0.95): ``G0 Z5``, then per point the nearest unprobed point
  (X distances weighted by 0.95; ties in row order here, .NET's sort leaves them open), ``G0 X Y`` at the height
  it stands, ``G38.3 Z-5 F20``, ``G91 G0 Z1 G90`` (1 mm above the contact); at the end ``G0 Z5``.

Columns: points, moves (straight moves that move the tool), machine time; the ratio is cam / reference (below 1:
cam is quicker).  One run each: the mock's clock is exact, so the median of repeats is the run.  Where the time
goes: each probe runs at the probe feed from where it starts, so the time is mostly the height it starts from:
bCNC 5 mm above the work zero at 10 mm/min, OpenCNCPilot 1 mm above the previous contact at 20 mm/min, cam 0.3 mm
above the previous contact at 20 mm/min (it travels higher than OpenCNCPilot, 1.5 mm above the previous contact, and
comes down with a rapid and a guarded move at 47 mm/min before it probes).

(b) The depth error levelling removes: an HPGL isolation drawing (an 80 x 60 mm outline, a track round a pad, a
diagonal) cut 8 Z steps (0.1256 mm) deep from the work zero, on the mock, decoded from its pin log; once levelled
(``--level``) by the map probed in (a), once not.  The error is the depth below the formula's surface minus the asked
depth at every write while cutting (the tool below the travel height and moving in X/Y); max and mean of its size,
levelled (cam) against not levelled (reference).
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cam  # noqa: E402
from cam.motion.chunks import plan_chunks  # noqa: E402
from cam.drive.homing import seek  # noqa: E402
from cam.drive.placement import placed_home  # noqa: E402
from cam.drive.ports import MockPort, SwitchSchedule, surface_height_mm  # noqa: E402
from cam.drive.probe_grid import GridApproach  # noqa: E402
from cam.drive.probing import DEFAULT_FEED_MM_MIN, grid_axis_mm, serpentine  # noqa: E402
from cam.drive.runner import Controller, run  # noqa: E402
from cam.drive.session import MachineSession  # noqa: E402
from cam.drive.state import MachineState  # noqa: E402
from cam.job.heightmap_level import HeightMap, save_height_map  # noqa: E402
from cam.job.model import CUT, travel_job  # noqa: E402
from cam.settings import settings_from_mapping  # noqa: E402
from cam.verify.pinlog import decode_pin_log  # noqa: E402

WARP = (0.1, 0.0036, -0.001, 0.2 / (50 ** 2 + 40 ** 2), 70.0, 60.0)
"""``z0, ax, ay, b, cx, cy`` of the mock's surface (mm; ``tests/test_level.py``'s WARP)."""
BOARD_MM = (20.0, 20.0, 120.0, 100.0)
QUICK_BOARD_MM = (20.0, 20.0, 50.0, 40.0)
WORK_ZERO_MM = (30.0, 30.0)
SPACING_MM = 10.0
START_ABOVE_MM = 5.0
CUT_STEPS = 8
HPGL = ("IN;SP1;PU0,0;PD3200,0,3200,2400,0,2400,0,0;PU400,400;PD2800,400,2800,2000,400,2000,400,400;"
        "PU400,400;PD2800,2000;PU1600,0;PD1600,2400;PU;SP0;")
QUICK_HPGL = "IN;SP1;PU0,0;PD800,0,800,400,0,400,0,0;PU0,0;PD800,400;PU;SP0;"
"""20 x 10 mm: an outline and a diagonal (40 plotter units a mm)."""


def machine() -> cam.MachineSettings:
    return settings_from_mapping({"inputs": {"probe": "!13"}, "travel": {"z_min_steps": -2000, "z_max_steps": 2000},
                                  "mock": {"probe_surface": ",".join(repr(v) for v in WARP)}})


def surface_mm(x_mm, y_mm):
    return surface_height_mm(WARP, x_mm, y_mm)


class Procedure:
    """A probing procedure's moves on the mock, one straight move at a time (machine frame, steps)."""

    def __init__(self, s: cam.MachineSettings, start: tuple[int, int, int]) -> None:
        self.s = s
        self.port = MockPort(switches=SwitchSchedule(s, start))
        self.pos = np.asarray(start, np.int64)
        self.moves = 0

    def rapid(self, target) -> None:
        """A ``G0`` to ``target`` (steps, machine frame): one straight move at the machine's speeds and ramps."""
        rel = np.asarray(target, np.int64) - self.pos
        if not rel.any():
            return
        result = run(plan_chunks(travel_job(rel.reshape(1, 3), self.s, source="G0"), start_steps=tuple(self.pos)),
                     self.port, controller=Controller())
        self.port.time_offset_ns += int(round(result.machine_time_s * 1e9)) + int(self.s.delay_xy_ns)
        self.pos = self.pos + np.asarray(result.position_steps, np.int64)
        self.moves += 1

    def probe(self, down_to_z: int, feed_mm_min: float) -> int:
        """A ``G38.2``/``G38.3`` down to machine ``down_to_z`` at most: where the probe closed (Z steps)."""
        result = seek(self.port, self.s, 2, int(down_to_z) - int(self.pos[2]), feed_mm_min / 60.0,
                      until=("probe", True), source="probe")
        self.pos = self.pos + np.asarray(result.position_steps, np.int64)
        self.moves += 1
        assert result.status == "switched", result.status
        return int(self.pos[2])

    @property
    def time_s(self) -> float:
        return self.port.time_offset_ns / 1e9


def grid_points(s, board) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, x1, y1 = board
    mx, my, _ = s.mm_per_step_axes
    return (np.rint(grid_axis_mm(x0, x1, SPACING_MM) / mx).astype(np.int64),
            np.rint(grid_axis_mm(y0, y1, SPACING_MM) / my).astype(np.int64))


def work_zero(s) -> tuple[int, int, int]:
    mx, my, mz = s.mm_per_step_axes
    zx, zy = round(WORK_ZERO_MM[0] / mx), round(WORK_ZERO_MM[1] / my)
    return zx, zy, int(np.ceil(-float(surface_mm(zx * mx, zy * my)) / mz - 1e-9))  # the first step at or below


def by_cam(s, board) -> dict:
    """cam probe grid's run (the session's own probing) and the same moves counted."""
    mz = s.mm_per_step_z
    zero = work_zero(s)
    start = (zero[0], zero[1], zero[2] - round(START_ABOVE_MM / mz))
    xs, ys = grid_points(s, board)
    order = serpentine(len(xs), len(ys))
    points = [(int(xs[i]), int(ys[j])) for i, j in order]
    safe = zero[2] - round(2.0 / mz)
    port = MockPort()
    session = MachineSession(port, s)
    session.set_position(start)
    approach = GridApproach.of(s)  # as cam probe grid probes (MachineSession.probe_map)
    results = session.probe_grid(points, safe, round(4.0 / mz), DEFAULT_FEED_MM_MIN, approach=approach)
    heights = np.zeros((len(ys), len(xs)))
    for (i, j), r in zip(order, results):
        heights[j, i] = r.height_mm(s)
    # its moves, as the session's worker makes them (cam.drive.probing.probe_worker): the first point from the safe
    # height (up or down to it as it crosses); each later one up to its travel height, across, down to where its
    # probe starts (cam.drive.probe_grid.GridApproach.heights); each probe, then its lift
    moves = 0
    pos = np.asarray(start)
    contacts = [int(r.contact_steps[2]) for r in results]
    for k, (x, y) in enumerate(points):
        travel = guard = start_z = safe
        if k:
            travel, guard, start_z, _ = approach.heights(contacts[:k], safe + round(4.0 / mz))
        moves += int(pos[2] > travel) + int((x, y) != tuple(pos[:2])) + int(min(travel, pos[2]) < guard)
        moves += int(guard < start_z) + 2  # the guarded move down; the probe, its lift
        pos = np.array([x, y, start_z])
    return dict(points=len(points), moves=moves, time_s=port.time_offset_ns / 1e9, heights=heights, xs=xs, ys=ys,
                zero=zero)


def by_bcnc(s, board) -> dict:
    mz = s.mm_per_step_z
    zero = work_zero(s)
    p = Procedure(s, (zero[0], zero[1], zero[2] - round(START_ABOVE_MM / mz)))
    z_safe, z_max, z_min = (zero[2] - round(h / mz) for h in (3.0, 5.0, -10.0))
    xs, ys = grid_points(s, board)
    p.rapid((p.pos[0], p.pos[1], z_safe))
    p.rapid((xs[0], ys[0], z_safe))
    n = 0
    for i, j in serpentine(len(xs), len(ys)):
        p.rapid((p.pos[0], p.pos[1], z_max))
        p.rapid((xs[i], ys[j], z_max))
        p.probe(z_min, 10.0)
        n += 1
    p.rapid((p.pos[0], p.pos[1], z_max))
    p.rapid((xs[0], ys[0], z_max))
    return dict(points=n, moves=p.moves, time_s=p.time_s)


def by_opencncpilot(s, board) -> dict:
    mx, my, mz = s.mm_per_step_axes
    zero = work_zero(s)
    p = Procedure(s, (zero[0], zero[1], zero[2] - round(START_ABOVE_MM / mz)))
    xs, ys = grid_points(s, board)
    p.rapid((p.pos[0], p.pos[1], zero[2] - round(5.0 / mz)))
    left = [(int(xs[i]), int(ys[j])) for j in range(len(ys)) for i in range(len(xs))]
    n = 0
    while left:
        here = p.pos[:2]
        left.sort(key=lambda q: float(np.hypot((q[0] - here[0]) * mx * 0.95, (q[1] - here[1]) * my)))
        x, y = left.pop(0)
        p.rapid((x, y, p.pos[2]))
        contact = p.probe(zero[2] + round(5.0 / mz), 20.0)
        p.rapid((x, y, contact - round(1.0 / mz)))
        n += 1
    p.rapid((p.pos[0], p.pos[1], min(int(p.pos[2]), zero[2] - round(5.0 / mz))))
    return dict(points=n, moves=p.moves, time_s=p.time_s)


def cut_errors(s, job_file: Path, state: MachineState, map_file: Path | None) -> tuple[np.ndarray, np.ndarray]:
    """The depth error (mm: below the formula's surface minus the asked depth) ``(at the job's cut points, at every
    write while cutting)``: its points of kind CUT below the travel height (a pen-down point or a split point of a
    levelled move), and each decoded position below it that moves in X/Y."""
    mx, my, mz = s.mm_per_step_axes
    options = cam.JobOptions(cut_depth_mm=float(f"{CUT_STEPS * mz:.6f}"), level=None if map_file is None
                             else str(map_file))
    job = cam.prepare_job(job_file, options, s, machine_state=state)
    home = np.asarray(job.levelled_home_steps if map_file is not None else placed_home(job, state, None), np.int64)
    plain = dataclasses.replace(s, inputs=cam.MachineSettings().inputs, mock=cam.MachineSettings().mock)
    motion = decode_pin_log(run(dataclasses.replace(job.plan, settings=plain)).pin_log(), plain)
    pos = motion.position_steps + home
    pos = pos[np.r_[True, np.any(pos[1:] != pos[:-1], axis=1)]]
    prev = np.vstack([pos[:1], pos[:-1]])
    low = state.work_zero_steps()[2] - 30  # below the travel height (64 steps up) less the warp (+-20 steps)
    writes = pos[(pos[:, 2] > low) & np.any(pos[:, :2] != prev[:, :2], axis=1)]
    toolpath = job.toolpath.joined()
    cuts = toolpath.points_steps[toolpath.kind == CUT] + home
    cuts = cuts[cuts[:, 2] > low]

    def error(p: np.ndarray) -> np.ndarray:
        return surface_mm(p[:, 0] * mx, p[:, 1] * my) + p[:, 2] * mz - CUT_STEPS * mz  # the tip is -z mz high

    return error(cuts), error(writes)


def rows(quick: bool) -> tuple[list[dict], dict]:
    s = machine()
    board = QUICK_BOARD_MM if quick else BOARD_MM
    t0 = time.perf_counter()
    ours = by_cam(s, board)
    refs = {"bCNC": by_bcnc(s, board), "OpenCNCPilot": by_opencncpilot(s, board)}
    w, h = board[2] - board[0], board[3] - board[1]
    out = []
    for name, ref in refs.items():
        out.append(dict(name=f"probe {w:g} x {h:g} mm every {SPACING_MM:g} mm vs {name}", points=(ours["points"],
                        ref["points"]), moves=(ours["moves"], ref["moves"]), cam=ours["time_s"], ref=ref["time_s"],
                        unit="s machine time"))
    # (b) levelled by the map cam probed, or not
    mz = s.mm_per_step_z
    zero = ours["zero"]
    offsets = dict(MachineState().offsets_steps)
    offsets["G54"] = zero
    state = MachineState(position_steps=zero, offsets_steps=offsets)
    with tempfile.TemporaryDirectory() as tmp:
        mx, my, _ = s.mm_per_step_axes
        map_file = save_height_map(HeightMap(ours["xs"] * mx, ours["ys"] * my, ours["heights"],
                                             reference_mm=-zero[2] * mz, spacing_mm=SPACING_MM),
                                   Path(tmp) / "map.json")
        job_file = Path(tmp) / "iso.plt"
        job_file.write_text(QUICK_HPGL if quick else HPGL)
        lv_cuts, lv_writes = (np.abs(e) for e in cut_errors(s, job_file, state, map_file))
        no_cuts, no_writes = (np.abs(e) for e in cut_errors(s, job_file, state, None))
    what = f"HPGL isolation cut {CUT_STEPS * mz:.4f} mm deep, levelled vs not"
    at_cuts, at_writes = (len(lv_cuts), len(no_cuts), "cut points"), (len(lv_writes), len(no_writes), "writes")
    out += [dict(name=f"{what}: max depth error at its cut points", cam=float(lv_cuts.max()),
                 ref=float(no_cuts.max()), unit="mm", n=at_cuts),
            dict(name=f"{what}: max depth error while cutting", cam=float(lv_writes.max()),
                 ref=float(no_writes.max()), unit="mm", n=at_writes),
            dict(name=f"{what}: mean depth error while cutting", cam=float(lv_writes.mean()),
                 ref=float(no_writes.mean()), unit="mm", n=at_writes),
            dict(name=f"{what}: median depth error while cutting", cam=statistics.median(lv_writes.tolist()),
                 ref=statistics.median(no_writes.tolist()), unit="mm", n=at_writes)]
    return out, dict(wall_s=time.perf_counter() - t0, warp_mm=_warp(board))


def _warp(board) -> float:
    gx, gy = np.meshgrid(np.linspace(board[0], board[2], 101), np.linspace(board[1], board[3], 81))
    z = surface_mm(gx, gy)
    return float(z.max() - z.min())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a 30 x 20 mm board and a small drawing")
    args = ap.parse_args(argv)
    table, info = rows(args.quick)
    print(f"cam probing and levelling, {'quick' if args.quick else 'full'} workload, the mock's surface warped "
          f"{info['warp_mm']:.3f} mm over the board (wall {info['wall_s']:.1f} s)")
    print()
    print("| workload | points cam / ref | moves cam / ref | cam | reference | cam / reference |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for r in table:
        pts = "{} / {}".format(*r["points"]) if "points" in r else ""
        moves = "{} / {}".format(*r["moves"]) if "moves" in r else "{} / {} {}".format(*r["n"])
        fmt = "{:.1f} s" if r["unit"].endswith("time") else "{:.4f} mm"
        ratio = r["cam"] / r["ref"] if r["ref"] else float("nan")
        print(f"| {r['name']} | {pts} | {moves} | {fmt.format(r['cam'])} | {fmt.format(r['ref'])} | {ratio:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
