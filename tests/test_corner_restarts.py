"""An axis that stands still at a corner starts again at or below its start speed (issue #32 point 1): the ramp
checker counts a standstill between two steps as a stop and a start, and the look-ahead planner plans so."""
import dataclasses

import numpy as np

import cam
from cam.pins import axis_bits
from cam.motion.steps import plan_steps
from cam.settings import DEFAULT_SETTINGS
from cam.verify.pinlog import PinLog, rising_edges
from cam.verify.ramps import STANDSTILL_STEPS, check_ramps

from conftest import SAMPLES

# X may start at full speed (its start speed is its top speed), so only Y is judged
SETTINGS = dataclasses.replace(DEFAULT_SETTINGS, start_speed_x_mm_s=DEFAULT_SETTINGS.max_speed_x_mm_s)
PERIOD_NS = 6_700_000


def _log(y_periods: list[int], n_periods: int = 30) -> PinLog:
    """X steps in every period of ``PERIOD_NS``; Y in ``y_periods``; both forward (a DDA's writes)."""
    clock, dirbit = axis_bits(SETTINGS)
    dirs = int(dirbit[0] | dirbit[1])
    t, d = [0], [dirs]
    for k in range(n_periods):
        clk = int(clock[0]) | (int(clock[1]) if k in y_periods else 0)
        t += [k * PERIOD_NS + PERIOD_NS // 2, (k + 1) * PERIOD_NS]
        d += [dirs | clk, dirs]
    return PinLog(np.array(t, np.int64), np.array(d, np.uint8), np.zeros(len(t), np.uint8))


def test_a_restart_after_a_standstill_above_the_start_speed_breaks_r3():
    # Y waits 17 periods (114 ms, over STANDSTILL_STEPS steps at its start speed: 20 ms a step), then steps
    # every period: 4.3 mm/s from a standstill, three times its start speed
    assert 17 * PERIOD_NS > STANDSTILL_STEPS * SETTINGS.mm_per_step_xy / SETTINGS.start_speed_y_mm_s * 1e9
    report = check_ramps(_log([0, 17, 18, 19, 23]), SETTINGS)
    assert not report.ok and report.counts["R3 stop"] >= 1, report.summary()


def test_a_restart_at_the_start_speed_passes():
    report = check_ramps(_log([0, 17, 20, 23]), SETTINGS)  # 20.1 ms intervals after the wait: 1.44 mm/s
    assert report.ok, report.summary()


def test_the_look_ahead_plan_restarts_no_axis_above_its_start_speed():
    """The thesis ellipse (Fig. 5.1): 69 such restarts before; now none, and the checker passes."""
    job = cam.plan(cam.digitize(cam.load_image(SAMPLES / "ellipse.png")), depth=1)
    plan = plan_steps(job)
    s = job.settings
    clock, _ = axis_bits(s)
    s_mm, v_start, _, _ = s.axis_limits()
    for a in range(3):
        t = plan.t_ns[rising_edges(plan.data, int(clock[a]))]
        d = np.diff(t)
        step_ns = s_mm[a] / v_start[a] * 1e9
        fast_restarts = (d[:-1] > STANDSTILL_STEPS * step_ns) & (d[1:] + 1 < step_ns)
        assert not fast_restarts.any(), ("XYZ"[a], int(fast_restarts.sum()))
    report = check_ramps(PinLog(plan.t_ns, plan.data, plan.strobe), s, pause_writes=plan.pause_writes)
    assert report.ok, report.summary()
