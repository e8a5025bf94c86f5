"""Pause, resume, stop and emergency stop on the real-time mock."""
import threading
import time

import numpy as np
import pytest

import cam
from cam.drive.runner import EMERGENCY_STOPPED, FINISHED, STOPPED
from cam.pins import axis_bits

from conftest import assert_surface_equal, drawing_from_rows, expected_surface_2d

# a 1-pixel-wide zig-zag long enough to take ~0.5 s at 1 ms periods
ROWS = ["." * 42] + ["." + "#" * 40 + "."] + ["." * 42]


@pytest.fixture
def rt_settings():
    """8 steps/pixel at 1 ms periods: the test job takes about 0.7 s (constant delay: these test the runner)."""
    return cam.MachineSettings().replace(delay_xy_ms=1.0, delay_z_ms=1.0, ramp="constant")


def _job(settings, **kw):
    d = cam.digitize(drawing_from_rows(ROWS))
    return d, cam.plan(d, depth=4, settings=settings, **kw)


def _start(job, controller):
    box = {}
    port = cam.MockPort()

    def target():
        box["result"] = cam.run(job, port, realtime=True, controller=controller)

    t = threading.Thread(target=target)
    t0 = time.monotonic_ns()
    t.start()
    return t, box, port, t0


def _into_the_job(port, writes: int = 40, timeout_s: float = 30.0) -> None:
    """Wait until the run has sent ``writes`` writes (a busy machine starts later; a fixed sleep would stop it
    before it began)."""
    deadline = time.monotonic() + timeout_s
    while port.n_writes + len(port._pending) < writes:  # real-time writes wait in the mock's pending batch
        assert time.monotonic() < deadline, "the run never got going"
        time.sleep(0.005)


def _rising(log, settings):
    clock, _ = axis_bits(settings)
    data = log.data
    prev = np.concatenate([[0], data[:-1]]).astype(np.uint8)
    return {a: ((data & clock[i]) != 0) & ((prev & clock[i]) == 0) for i, a in enumerate("xyz")}


@pytest.mark.realtime
def test_stop_halts_within_one_period_and_lifts(rt_settings):
    d, job = _job(rt_settings)
    ctl = cam.Controller()
    t, box, port, _ = _start(job, ctl)
    _into_the_job(port)
    stop_wall_ns = time.monotonic_ns()
    ctl.stop()
    t.join(5)
    result = box["result"]
    assert result.status == STOPPED
    stop_job_ns = stop_wall_ns - result.started_ns  # the request on the mock's clock
    log = port.pin_log()
    motion = cam.decode_pin_log(log, rt_settings)
    rising = _rising(log, rt_settings)
    period_ns = rt_settings.delay_xy_ns
    xy_edges = log.t_ns[rising["x"] | rising["y"]]
    assert xy_edges.max() <= stop_job_ns + period_ns
    z_down = log.t_ns[rising["z"] & ((log.data & axis_bits(rt_settings)[1][2]) != 0)]
    assert z_down.max() <= stop_job_ns + period_ns
    # after the stop only Z moves, only up, to the surface
    after = log.t_ns > stop_job_ns + period_ns
    assert np.all(motion.position_steps[after][:, :2] == motion.position_steps[~after][-1, :2])
    assert np.all(np.diff(motion.position_steps[after][:, 2]) <= 0)
    assert motion.final_steps[2] == 0
    assert result.position_steps == motion.final_steps
    assert 0 < result.writes < len(cam.plan_steps(job))


@pytest.mark.realtime
def test_emergency_stop_sends_nothing_more(rt_settings):
    d, job = _job(rt_settings)
    ctl = cam.Controller()
    t, box, port, _ = _start(job, ctl)
    _into_the_job(port)
    t_req = time.monotonic_ns()
    ctl.emergency_stop()
    t.join(5)
    result = box["result"]
    assert result.status == EMERGENCY_STOPPED
    log = port.pin_log()
    # nothing was written later than one step period after the request
    assert log.t_ns.max() <= (t_req - result.started_ns) + rt_settings.delay_xy_ns
    assert result.position_steps == cam.decode_pin_log(log, rt_settings).final_steps
    assert result.position_steps[2] > 0  # did not move again, not even to lift


@pytest.mark.realtime
def test_pause_and_resume_keep_the_carve_exact(rt_settings):
    d, job = _job(rt_settings)
    ctl = cam.Controller()
    t, box, port, _ = _start(job, ctl)
    _into_the_job(port)
    ctl.pause()
    time.sleep(0.02)  # let an in-flight write land
    n_paused = len(port.pin_log())
    time.sleep(0.2)
    assert len(port.pin_log()) == n_paused  # nothing sent while paused
    ctl.resume()
    t.join(10)
    assert box["result"].status == FINISHED
    log = port.pin_log()
    gaps = np.diff(log.t_ns)
    assert gaps.max() >= 0.2e9  # the pause shows in the measured times
    motion = cam.decode_pin_log(log, rt_settings)
    surface = cam.carve(motion, (d.height_px, d.width_px), rt_settings)
    assert_surface_equal(surface, expected_surface_2d(d, [4], rt_settings))
    assert motion.final_steps == (0, 0, 0)


def test_pause_at_point_calls_back_at_that_point():
    d = cam.digitize(drawing_from_rows(ROWS))
    job = cam.plan(d, depth=2, pause_at=[(10, 1)])
    seen = []
    result = cam.run(job, on_pause=lambda pos, note: seen.append((pos, note)))
    assert seen == [((80, 8, 2), "Pause At")]
    assert result.status == FINISHED and result.pauses == 1


def test_pause_at_with_controller_waits_for_resume():
    d = cam.digitize(drawing_from_rows(ROWS))
    job = cam.plan(d, depth=2, pause_at=[(10, 1)])
    ctl = cam.Controller()
    box = {}
    t = threading.Thread(target=lambda: box.update(r=cam.run(job, controller=ctl)))
    t.start()
    deadline = time.monotonic() + 5
    while not ctl.paused and time.monotonic() < deadline:
        time.sleep(0.005)
    assert ctl.paused and t.is_alive()
    ctl.stop()
    t.join(5)
    assert box["r"].status == STOPPED
    assert box["r"].position_steps == (80, 8, 0)  # lifted where it paused
