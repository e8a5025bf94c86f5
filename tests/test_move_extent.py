"""The extent of a job's motion from its moves (:func:`cam.motion.chunks.move_extent`) equals the extent of its
decoded writes, and the machine time without writes equals the writes' last time, for every ramp mode."""
import dataclasses

import numpy as np
import pytest

from cam.motion.chunks import plan_chunks
from cam.job.model import travel_job
from cam.settings import DEFAULT_SETTINGS
from cam.verify.pinlog import motion_extent


@pytest.mark.parametrize("ramp", ["constant", "linear40", "lookahead"])
def test_extent_and_time_from_moves_equal_the_writes(ramp):
    rng = np.random.default_rng(7)
    settings = dataclasses.replace(DEFAULT_SETTINGS, ramp=ramp)
    for trial in range(120):
        n = int(rng.integers(1, 30))
        pts = np.cumsum(rng.integers(-7, 8, size=(n, 3)), axis=0)
        pts[:, :2] = np.abs(pts[:, :2])
        pts[:, 2] = np.clip(pts[:, 2], -50, 50)  # moves that enter and leave the work (z > 0) on a slant
        job = travel_job(pts, settings)
        if trial % 2:  # moves stretched over more periods than steps (the DDA's floor at other ratios)
            job = dataclasses.replace(job, periods=rng.integers(0, 20, size=n))
        plan = plan_chunks(job)
        extent, cut = plan.motion_extent()
        whole = plan_chunks(job).to_plan()
        want_extent, want_cut = motion_extent(whole.data, settings)
        assert np.array_equal(extent, want_extent), (trial, pts)
        assert np.array_equal(cut, want_cut), (trial, pts)
        assert plan.estimated_time_s == whole.estimated_time_s
