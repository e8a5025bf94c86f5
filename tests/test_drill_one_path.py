"""One drill planner (issue #28): the drilling job is made a piece per tool run (``DrillJobStream``) and
``plan_drill``'s toolpath is those pieces joined.  Checked against a plain reference that builds the job a point at
a time (the planner before it made pieces), and the pieces against the joined job: the mock pin log, the step
plan and the G-code out are the same."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cam
from cam.motion.chunks import plan_chunks
from cam.drive.ports import MockPort
from cam.drive.runner import run
from cam.formats.excellon import load_excellon, parse_excellon
from cam.kinds.gcode_export import gcode_pieces, to_gcode
from cam.job.drill import DrillJobStream, _machine_mm, _tool_runs, plan_drill
from cam.job.model import CUT, RETRACT, TRAVEL, JobLike
from cam.job.resume import plan_fingerprint
from conftest import SAMPLES
from support.pinlogs import pin_log_bytes as _pin_log_bytes

SETTINGS = cam.MachineSettings().replace(delay_xy_ms=0.05, delay_z_ms=0.05)
PER_MOVE = ("points_steps", "kind", "target", "pause")
MIXED = """M48
METRIC,TZ
T1C0.8
T2C1.0
T3C0.6
%
T2
X10.0Y5.0
X12.0Y5.0
T1
X1.0Y1.0
X3.0Y7.0
X2.0Y2.0
T2
X20.0Y3.0
T3
X4.0Y4.0
M30
"""


def _reference(holes, *, travel_height_mm: float, cut_depth_mm: float = 2.0, drill_order: str = "tour"):
    """The job a point at a time: a lift (or a point at the home) where the first tool pauses; per tool a pause at
    the safe height where the tool stands; per hole above it, down, up; home at the end."""
    s = cam.MachineSettings()
    machine_mm = _machine_mm(holes.holes_mm, None, False)
    steps_xy = np.rint(machine_mm / s.mm_per_step_xy).astype(np.int64)
    depth, safe = int(round(cut_depth_mm / s.mm_per_step_z)), -int(round(travel_height_mm / s.mm_per_step_z))
    points, kinds, pause, notes = [], [], [], []
    if safe != 0:
        points.append((0, 0, safe)), kinds.append(RETRACT), pause.append(False)
    for tool, idx in _tool_runs(holes, machine_mm, drill_order):
        if not points:
            points.append((0, 0, safe)), kinds.append(TRAVEL), pause.append(False)
        pause[-1] = True
        notes.append(f"tool change: T{tool} {float(holes.tools[tool]):.3f} mm ({len(idx)} holes)")
        for i in idx:
            x, y = (int(v) for v in steps_xy[i])
            points += [(x, y, safe), (x, y, depth), (x, y, safe)]
            kinds += [TRAVEL, CUT, RETRACT]
            pause += [False] * 3
    points.append((0, 0, safe)), kinds.append(TRAVEL), pause.append(False)
    if safe != 0:
        points.append((0, 0, 0)), kinds.append(TRAVEL), pause.append(False)
    return np.array(points, np.int64), np.array(kinds, np.uint8), np.array(pause, bool), notes


@pytest.fixture(scope="module")
def hole_lists():
    out = [load_excellon(SAMPLES / "board.drl"), parse_excellon(MIXED, source="mixed.drl")]
    out += [load_excellon(p) for p in sorted((SAMPLES / "drill").glob("*.drl"))[:3]]
    return out


@pytest.mark.parametrize("drill_order", ["tour", "file"])
@pytest.mark.parametrize("travel_height_mm", [1.0, 0.0])
def test_plan_drill_is_its_pieces_joined_and_the_reference(hole_lists, drill_order, travel_height_mm):
    for holes in hole_lists:
        dp = plan_drill(holes, drill_order=drill_order, travel_height_mm=travel_height_mm)
        pts, kind, pause, notes = _reference(holes, travel_height_mm=travel_height_mm, drill_order=drill_order)
        job = dp.toolpath
        np.testing.assert_array_equal(job.points_steps, pts)
        np.testing.assert_array_equal(job.kind, kind)
        np.testing.assert_array_equal(job.pause, pause)
        np.testing.assert_array_equal(job.target, kind == CUT)
        assert job.pause_notes == notes and job.warnings == list(holes.warnings) and job.safe_z_steps == 0
        assert [t for t, _, _ in dp.tool_sequence] == [int(n.split()[2][1:]) for n in notes]
        runs = _tool_runs(holes, _machine_mm(holes.holes_mm, None, False), drill_order)
        stream = DrillJobStream(runs, np.rint(_machine_mm(holes.holes_mm, None, False) / SETTINGS.mm_per_step_xy)
                                .astype(np.int64), [float(holes.tools[t]) for t, _ in runs], dp.depth_steps,
                                dp.safe_z_steps, cam.MachineSettings(), str(holes.source), list(holes.warnings))
        assert isinstance(stream, JobLike) and len(list(stream.pieces())) == len(dp.tool_sequence)
        joined = stream.joined()
        for name in PER_MOVE:
            np.testing.assert_array_equal(getattr(joined, name), getattr(job, name))
        assert joined.pause_notes == job.pause_notes and joined.warnings == job.warnings


def test_the_pieces_run_plan_and_export_as_the_joined_job(tmp_path):
    holes = parse_excellon(MIXED, source="mixed.drl")
    dp = plan_drill(holes, settings=SETTINGS)
    machine_mm = _machine_mm(holes.holes_mm, None, False)
    runs = _tool_runs(holes, machine_mm, "tour")
    stream = DrillJobStream(runs, np.rint(machine_mm / SETTINGS.mm_per_step_xy).astype(np.int64),
                            [float(holes.tools[t]) for t, _ in runs], dp.depth_steps, dp.safe_z_steps, SETTINGS,
                            str(holes.source), list(holes.warnings))
    whole = dp.toolpath
    assert _pin_log_bytes(stream, tmp_path, "s.csv") == _pin_log_bytes(whole, tmp_path, "w.csv")
    a, b = plan_chunks(stream), plan_chunks(whole)
    np.testing.assert_array_equal(a.pause_writes, b.pause_writes)
    assert a.pause_notes == b.pause_notes and plan_fingerprint(stream) == plan_fingerprint(whole)
    assert "".join(gcode_pieces(stream, title="mixed")) == to_gcode(whole, title="mixed")
