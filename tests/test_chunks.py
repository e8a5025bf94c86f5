"""The step plan made a chunk at a time (cam.motion.chunks) equals the whole plan, and runs in bounded memory."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import cam
from cam.motion.chunks import lookahead_margin, plan_chunks
from cam.drive.ports import MockPort
from cam.drive.runner import Controller, run
from cam.kinds.jobs import prepare_job
from cam.motion.steps import plan_steps
from cam.job.model import CUT, Job
from cam.verify.pinlog import PinLog, carve, decode_pin_log, read_pin_log
from cam.verify.ramps import check_ramps

BIG = cam.settings.Travel(x_max_steps=10**6, y_max_steps=10**6, z_min_steps=-10**4, z_max_steps=10**4)


def _zigzag(n_moves: int, settings, *, pause_every: int = 0, scale: int = 1) -> Job:
    """Moves of 1..40 steps (times ``scale``) in X and Y with plunges and lifts: ramps start and stop
    everywhere."""
    rng = np.random.default_rng(7)
    d = rng.integers(-40, 41, size=(n_moves, 3)) * scale
    d[:, 2] = np.where(rng.random(n_moves) < 0.1, rng.integers(-5, 6, n_moves), 0)
    pts = np.cumsum(d, axis=0) + np.array([5000, 5000, 0]) * scale
    pts[:, 2] = np.clip(pts[:, 2], 0, 50)
    pause = np.zeros(n_moves, bool)
    if pause_every:
        pause[pause_every::pause_every] = True
    return Job(points_steps=pts.astype(np.int64), kind=np.full(n_moves, CUT, np.uint8), target=np.zeros(n_moves, bool),
               pause=pause, settings=settings)


@pytest.mark.parametrize("ramp", ["lookahead", "linear40", "constant"])
@pytest.mark.parametrize("chunk", [257, 4000])
def test_chunked_plan_equals_whole_plan(ramp, chunk):
    s = cam.MachineSettings().replace(ramp=ramp, delay_xy_ms=1.0, delay_z_ms=2.0, travel=BIG)
    job = _zigzag(600, s, pause_every=97)
    whole = plan_steps(job)
    chunked = plan_chunks(job, chunk_periods=chunk)
    assert chunked.margin_periods >= lookahead_margin(s, s.delay_xy_ns)
    got = chunked.to_plan()
    assert len(got) == len(whole) == len(chunked)
    np.testing.assert_array_equal(got.t_ns, whole.t_ns)
    np.testing.assert_array_equal(got.data, whole.data)
    np.testing.assert_array_equal(got.strobe, whole.strobe)
    np.testing.assert_array_equal(got.point_write, whole.point_write)
    np.testing.assert_array_equal(got.pause_writes, whole.pause_writes)
    assert chunked.estimated_time_s == whole.estimated_time_s
    # chunk boundaries fall inside ramps: consecutive periods differ across many boundaries
    per = np.diff(whole.t_ns[::2])
    cuts = np.arange(chunk, len(per) - 1, chunk)
    if ramp == "lookahead":
        assert np.count_nonzero(per[cuts] != per[cuts - 1]) > 0
        assert check_ramps(PinLog(got.t_ns, got.data, got.strobe), s, pause_writes=got.pause_writes).ok


def test_chunked_plan_in_fast_moves_keeps_ramp_checker_passing():
    """Faster steps make long ramps (hundreds of periods) that cross many chunk boundaries."""
    s = cam.MachineSettings().replace(delay_xy_ms=0.5, delay_z_ms=1.0, travel=BIG)
    pts = np.array([[3000, 0, 0], [3000, 2000, 0], [0, 2000, 30], [6000, 6000, 0]], np.int64)
    job = Job(points_steps=pts, kind=np.zeros(4, np.uint8), target=np.zeros(4, bool), pause=np.zeros(4, bool),
              settings=s)
    whole = plan_steps(job)
    got = plan_chunks(job, chunk_periods=300).to_plan()
    np.testing.assert_array_equal(got.t_ns, whole.t_ns)
    np.testing.assert_array_equal(got.data, whole.data)
    assert check_ramps(PinLog(got.t_ns, got.data, got.strobe), s).ok


def test_a_job_larger_than_a_chunk_carves_the_same_surface(tmp_path):
    job = prepare_job("samples/ellipse.png").toolpath
    ref = decode_pin_log(run(plan_steps(job), MockPort()).pin_log(), job.settings)
    port = MockPort(pin_log_path=tmp_path / "pins.csv")
    result = run(plan_chunks(job, chunk_periods=1000), port)
    port.finish_pin_log()
    log = read_pin_log(tmp_path / "pins.csv")
    got = decode_pin_log(log, job.settings)
    np.testing.assert_array_equal(got.position_steps, ref.position_steps)
    shape = (job.height_px, job.width_px)
    np.testing.assert_array_equal(carve(got, shape, job.settings), carve(ref, shape, job.settings))
    assert result.position_steps == ref.final_steps
    assert not (tmp_path / "pins.csv.part").exists()


def test_a_stopped_chunked_run_lifts_the_tool():
    job = prepare_job("samples/ellipse.png").toolpath
    ctl = Controller()
    sent = []

    def progress(done, total, t_ns):
        sent.append(done)
        if len(sent) == 3:
            ctl.stop()

    result = run(plan_chunks(job, chunk_periods=2000), MockPort(), controller=ctl, progress=progress)
    assert result.status == "stopped"
    assert result.position_steps[2] <= job.safe_z_steps
    assert decode_pin_log(result.pin_log(), job.settings).final_steps == result.position_steps


def _peak_bytes(n_moves: int, scale: int = 1) -> int:
    s = cam.MachineSettings().replace(travel=BIG)
    job = _zigzag(n_moves, s, scale=scale)
    plan = plan_chunks(job, chunk_periods=20_000)
    tracemalloc.start()
    for _ in plan.chunks():
        pass
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def test_peak_memory_does_not_grow_with_the_job_length():
    """The same moves, 8 times longer: about 0.1M and 0.8M periods, and the same peak (what a plan keeps per
    move, a few numbers, is the job's own size; the ahead-of-time kernels' arrays are traced too)."""
    _peak_bytes(4_000, 8)  # kernels compiled or loaded, numba's lazy imports of every type seen done
    small, large = _peak_bytes(4_000, 1), _peak_bytes(4_000, 8)
    assert large < 1.5 * small, (small, large)


@pytest.mark.parametrize("chunk", [97, 1000])
def test_windows_end_at_rests_and_plan_what_the_whole_job_plans(chunk, monkeypatch):
    """A look-ahead window ends at the nearest rest outside its chunk: on a machine file of long ramps (a margin
    of about a million periods) a job of tool changes every few hundred periods is planned in windows of about
    its chunk's size, and the writes are those of the whole job planned at once."""
    from cam.motion import chunks as chunks_module

    s = cam.MachineSettings().replace(ramp="lookahead", delay_xy_ms=0.05, delay_z_ms=0.05, max_speed_x_mm_s=600.0,
                                      max_speed_y_mm_s=600.0, max_speed_z_mm_s=300.0, travel=BIG)
    job = _zigzag(300, s, pause_every=7)
    whole = plan_chunks(job, chunk_periods=1 << 30).to_plan()
    plan = plan_chunks(job, chunk_periods=chunk)
    assert plan.margin_periods > 500_000 > len(plan)  # without the rests, every window would be the whole job
    sizes = []
    planned = chunks_module._lookahead
    monkeypatch.setattr(chunks_module, "_lookahead", lambda high, *a: sizes.append(len(high)) or planned(high, *a))
    got = plan.to_plan()
    np.testing.assert_array_equal(got.t_ns, whole.t_ns)
    np.testing.assert_array_equal(got.data, whole.data)
    gaps = np.diff(np.concatenate([plan._stops, [plan.n_periods]]))  # between rests, after the long first move
    assert len(sizes) > 10 and max(sizes[len(sizes) // 2:]) <= chunk + 2 * int(gaps.max()) < plan.n_periods // 8
    assert sum(sizes) < len(sizes) * plan.n_periods / 4
