"""Size never changes the result, for every job kind (issue #28 point 3).

Every consumer of a job reads its pieces (``cam.job.model.JobLike``).  Here the job of every input kind is cut
into pieces of 1, 3 and 1000 moves (a stand-in for a planner that makes small pieces) and given to the step
planner, the runner, the G-code writer, the preview and the journal's fingerprint: each must give exactly what
the job in one piece gives (pin-log bytes, G-code text, picture bytes, fingerprint).
"""
from __future__ import annotations

import numpy as np
import pytest

import cam
from cam.motion.chunks import plan_chunks
from cam.kinds.gcode_export import to_gcode
from cam.kinds.jobs import JobOptions, motion_picture, prepare_job
from cam.job.model import JobLike
from cam.job.resume import plan_fingerprint
from cam.render.picture import encode_png
from cam.verify.pinlog import write_pin_log
from conftest import SAMPLES
from test_resume_one_path import Sliced  # a Job cut into pieces of a given size

SLOW_CASES = {
    'test_the_planning_pass_gives_the_journals_fingerprint[pyramid.png]',
    'test_every_consumer_gives_the_same_for_any_piece_size[1-ellipse.png]',
    'test_every_consumer_gives_the_same_for_any_piece_size[1-board.drl]',
    'test_every_consumer_gives_the_same_for_any_piece_size[1000-pyramid.png]'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

SETTINGS = cam.MachineSettings().replace(delay_xy_ms=0.05, delay_z_ms=0.05)
PER_MOVE = ("points_steps", "kind", "target", "pause", "period_ns", "periods", "move_start", "rest")

CASES = [
    ("ellipse.png", JobOptions(depth=(5,))),
    ("pyramid.png", JobOptions(depth=(4,), passes=2)),
    ("board.drl", JobOptions()),
    ("extended.plt", JobOptions()),
    ("logo.svg", JobOptions()),
    ("bolt_plate.ngc", JobOptions()),
]


def _pin_log_bytes(job: object, tmp_path, name: str) -> bytes:
    path = tmp_path / name
    write_pin_log(cam.run(job).pin_log(), path)
    return path.read_bytes()


SLOW = {"pyramid.png", "bolt_plate.ngc", "logo.svg"}  # many moves: pieces of 1 and 3 moves run in the slow tier


@pytest.mark.parametrize("name,options,size", [
    pytest.param(name, options, size, id=f"{size}-{name}",
                 marks=[pytest.mark.slow] if name in SLOW and size < 1000 else [])
    for size in (1, 3, 1000) for name, options in CASES])
def test_every_consumer_gives_the_same_for_any_piece_size(tmp_path, name, options, size):
    prepared = prepare_job(SAMPLES / name, options, SETTINGS)
    job = prepared.toolpath.joined()
    sliced = Sliced(job, size)
    assert isinstance(sliced, JobLike)
    joined = sliced.joined()
    for f in PER_MOVE:
        a, b = getattr(joined, f), getattr(job, f)
        assert (a is None) == (b is None) and (a is None or np.array_equal(a, b)), f
    assert joined.pause_notes == job.pause_notes

    assert _pin_log_bytes(sliced, tmp_path, "sliced.csv") == _pin_log_bytes(job, tmp_path, "whole.csv")
    whole_plan, sliced_plan = plan_chunks(job), plan_chunks(sliced)
    np.testing.assert_array_equal(sliced_plan.pause_writes, whole_plan.pause_writes)
    assert sliced_plan.pause_notes == whole_plan.pause_notes
    np.testing.assert_array_equal(sliced_plan.full_point_write(), whole_plan.full_point_write())
    assert to_gcode(sliced) == to_gcode(job)
    assert plan_fingerprint(sliced) == plan_fingerprint(job)
    extent, _ = whole_plan.motion_extent()
    pictures = [encode_png(motion_picture(lambda j=j: (p.points_steps for p in j.pieces()), SETTINGS,
                                          extent_steps=extent, holes=name.endswith(".drl")))
                for j in (sliced, job)]
    assert pictures[0] == pictures[1]


@pytest.mark.parametrize("name,options", CASES, ids=[name for name, _ in CASES])
def test_the_planning_pass_gives_the_journals_fingerprint(name, options):
    """prepare_job takes a job's fingerprint from the step planner's own pass over its pieces (no pass of its
    own): the same sha256 that a pass of plan_fingerprint gives, whole or in pieces of 3 moves."""
    prepared = prepare_job(SAMPLES / name, options, SETTINGS)
    assert prepared.plan.job_sha256 is not None
    assert prepared.plan_sha256 == prepared.plan.job_sha256 == plan_fingerprint(prepared.toolpath)
    job = prepared.toolpath.joined()
    assert plan_chunks(Sliced(job, 3), fingerprint=True).job_sha256 == prepared.plan_sha256
    assert plan_chunks(job).job_sha256 is None  # only when asked: the hashing is not free
