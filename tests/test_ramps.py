"""Speed ramps: the look-ahead planner, the seed's 40-step ramp, and the pin-log checker that proves them."""
import dataclasses
import json

import numpy as np
import pytest

import cam
from cam.motion.ramps import RAMP_STEPS_LINEAR40, ramp_periods
from cam.verify.ramps import check_axis_steps, check_ramps
from cam.pins import axis_bits
from cam.motion.steps import plan_steps
from cam.errors import SettingsError
from cam.settings import DEFAULT_SETTINGS, settings_from_mapping

from conftest import ROOT, SAMPLES, assert_surface_equal, drawing_from_rows, expected_surface_2d

S = DEFAULT_SETTINGS  # lookahead
CONSTANT = S.replace(ramp="constant")
LINEAR40 = S.replace(ramp="linear40")
STEP_MM, V_START, V_MAX, ACC = S.axis_limits()


def toolpath(points, settings=S, pause=None):
    pts = np.asarray(points, np.int64)
    scale = np.array([settings.steps_per_px_xy, settings.steps_per_px_xy, settings.steps_per_px_z])
    return cam.Job(points_steps=pts * scale, kind=np.zeros(len(pts), np.uint8), target=np.zeros(len(pts), bool),
                   pause=np.zeros(len(pts), bool) if pause is None else np.asarray(pause, bool), settings=settings)


def run_and_check(plan, settings):
    """Run a step plan on the mock, decode, check the ramp rules on the pin log."""
    result = cam.run(plan)
    log = result.pin_log()
    return check_ramps(log, settings, pause_writes=plan.pause_writes), cam.decode_pin_log(log, settings), log


def axis_steps(log, settings, axis):
    """Times (ns) and + direction of the steps of one axis, decoded here independently of the checker."""
    clock, dirbit = axis_bits(settings)
    data = log.data
    prev = np.concatenate([[0], data[:-1]]).astype(np.uint8)
    rising = ((data & clock[axis]) != 0) & ((prev & clock[axis]) == 0)
    return log.t_ns[rising], (data[rising] & dirbit[axis]) != 0


def assert_stops_at_start_speed(log, settings, pause_writes=()):
    """Independent of the checker: the first and last interval around every rest is at or below the start speed."""
    step_mm, v_start, _, _ = settings.axis_limits()
    pause_t = log.t_ns[np.asarray(pause_writes, np.int64)] if len(pause_writes) else np.zeros(0, np.int64)
    for a in range(3):
        t, up = axis_steps(log, settings, a)
        if len(t) < 2:
            continue
        rest = np.zeros(len(t) + 1, bool)  # rest[j]: a rest right before step j (rest[n]: after the last)
        rest[0] = rest[-1] = True
        rest[1:-1] = up[1:] != up[:-1]
        for p in pause_t:
            rest[1:-1] |= (t[:-1] <= p) & (p < t[1:])
        d_s = np.diff(t) / 1e9
        for j in range(len(t) - 1):
            if rest[j + 1]:
                continue
            if rest[j] or rest[j + 2]:  # first or last interval of a run
                assert step_mm[a] / d_s[j] <= v_start[a] * (1 + 1e-6), (a, j, step_mm[a] / d_s[j])


# ------------------------------------------------------------------ the checker on hand-made step times


def check_times(t_ns, axis_settings=(0.0289, 1.445, 5.78, 50.0), slots=None, brk=None):
    t = np.asarray(t_ns, np.int64)
    slot_t = t if slots is None else np.asarray(slots, np.int64)
    slot_of = np.searchsorted(slot_t, t).astype(np.int64)
    r1, r2, r3 = (np.zeros(len(t)) for _ in range(3))
    b = np.zeros(len(t), bool) if brk is None else np.asarray(brk, bool)
    check_axis_steps(t, slot_of, slot_t, b, *axis_settings, r1, r2, r3)
    return r1, r2, r3


def constant_accel_times(v0, v1, acc, s=0.0289):
    """Exact step times (ns) of a motor starting at v0 and accelerating at acc up to v1 (mm/s), then cruising."""
    x = np.arange(0, 60) * s
    t = (-v0 + np.sqrt(v0 ** 2 + 2 * acc * x)) / acc
    t_acc = (v1 - v0) / acc
    x_acc = v0 * t_acc + acc * t_acc ** 2 / 2
    t = np.where(x <= x_acc, t, t_acc + (x - x_acc) / v1)
    return np.round(t * 1e9).astype(np.int64)


def test_checker_accepts_constant_acceleration_and_rejects_a_faster_one():
    r1, r2, r3 = check_times(constant_accel_times(1.445, 5.78, 49.0)[1:])
    assert not r1.any() and not r2.any()
    r1, r2, r3 = check_times(constant_accel_times(1.445, 5.78, 60.0)[1:])
    assert r2.any() and not r1.any()


def test_checker_top_speed_and_stops():
    t = np.arange(10) * 4_000_000  # 0.0289 mm / 4 ms = 7.2 mm/s > 5.78
    r1, r2, r3 = check_times(t)
    assert r1[:-1].all() and r3[0] > 0 and r3[-2] > 0 and not r3[1:-2].any()
    slow = np.arange(10) * 20_000_000  # 1.445 mm/s: at the start speed everywhere
    assert not any(r.any() for r in check_times(slow))


def test_checker_quantisation_tolerance_covers_a_dda_line_but_not_a_burst():
    period = 5_000_000
    slots = np.arange(400) * period
    # a minor axis at 2/3 of the slots (DDA of a 2:3 line): intervals of 1 and 2 slots, mean 3.85 mm/s
    k = np.arange(1, 301)
    minor = slots[np.flatnonzero(np.diff((k * 2) // 3, prepend=0))]
    _, r2, _ = check_times(minor[10:], slots=slots)
    assert not r2.any()
    # the same pattern without the free slots (no other axis stepping there) breaks the rule
    _, r2, _ = check_times(minor[10:], slots=minor[10:])
    assert r2.any()
    # an axis that steps in 8 consecutive slots then rests 8 (8-step pixel staircase) at full speed: broken
    burst = np.concatenate([slots[i:i + 8] for i in range(0, 384, 16)])
    _, r2, _ = check_times(burst, slots=slots)
    assert r2.any()


# ------------------------------------------------------------------ look-ahead on real jobs

SAMPLES_2D = ["ellipse.png", "two_curves.png", "gear.png", "word.png", "stamp.png"]
SAMPLES_3D = ["disc.png", "pyramid.png", "heart.png", "dumbbell.png", "ring.png"]


@pytest.mark.parametrize("name", SAMPLES_2D)
def test_lookahead_passes_the_checker_and_carves_every_2d_sample(name):
    drawing = cam.load_image(SAMPLES / name)
    d = cam.digitize(drawing)
    depths = [3 + 2 * i for i in range(len(d.objects))]
    job = cam.plan(d, depth=depths)
    plan = plan_steps(job)
    report, motion, log = run_and_check(plan, job.settings)
    report.raise_if_broken()
    assert_stops_at_start_speed(log, job.settings, plan.pause_writes)
    assert max(report.max_speed_mm_s) <= V_MAX[0] * (1 + 1e-6)
    surface = cam.carve(motion, (job.height_px, job.width_px), job.settings, origin_px=job.origin_px)
    assert_surface_equal(surface, expected_surface_2d(d, depths, job.settings))
    # never faster than the thesis's constant delay, and much faster than the seed's per-move ramp
    t_const = plan_steps(dataclasses.replace(job, settings=CONSTANT)).estimated_time_s
    t_lin = plan_steps(cam.plan(d, depth=depths, settings=LINEAR40)).estimated_time_s
    assert t_const <= plan.estimated_time_s < t_lin


@pytest.mark.parametrize("name", SAMPLES_3D)
def test_lookahead_passes_the_checker_and_carves_every_3d_sample(name):
    from cam.digitize.peel3d import peel_layers

    drawing = cam.load_image(SAMPLES / name)
    d = cam.digitize(drawing)
    profile = cam.load_profile(ROOT / "profiles" / "dome.png")
    job = cam.plan(d, profile=profile)
    plan = plan_steps(job)
    report, motion, log = run_and_check(plan, job.settings)
    report.raise_if_broken()
    assert report.steps[2] > 0 and report.pairs[2] > 0  # Z moved and was judged too
    surface = cam.carve(motion, (job.height_px, job.width_px), job.settings, origin_px=job.origin_px)
    layer = peel_layers(drawing.classes)
    want = np.where(layer > 0, profile.depth_px[np.maximum(layer, 1) - 1], 0) * job.settings.steps_per_px_z
    assert_surface_equal(surface, want)


def test_the_checker_fails_the_thesis_constant_delay():
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    job = cam.plan(d, depth=1, settings=CONSTANT)
    plan = plan_steps(job)
    report, _, _ = run_and_check(plan, CONSTANT)
    assert not report.ok
    # 5 ms steps from rest = 5.78 mm/s, 4x the start speed: every start and stop breaks R3, and so does every
    # restart of an axis after it stood still at a corner (a standstill is a stop and a start)
    assert report.counts["R3 stop"] > 0
    assert "R3 stop" in report.summary() or "R2" in report.summary()
    with pytest.raises(AssertionError):
        report.raise_if_broken()


def test_gcode_job_with_dwell_and_tool_changes_passes_and_decelerates_at_each():
    from cam.formats.gcode import parse_gcode
    from cam.job.gcode import plan_gcode

    from test_gcode_in import DRILLING, ENGRAVING

    for text in (DRILLING, ENGRAVING):
        plan = plan_steps(plan_gcode(parse_gcode(text)))
        report, _, log = run_and_check(plan, S)
        report.raise_if_broken()
        assert_stops_at_start_speed(log, S, plan.pause_writes)
    plan = plan_steps(plan_gcode(parse_gcode(DRILLING)))
    assert len(plan.pause_writes) == 2
    per = np.diff(plan.t_ns[0::2])
    for w in plan.pause_writes:  # each tool change comes after "G0 Z3": Z arrives at its start speed
        k = int(w) // 2  # periods before the pause
        assert STEP_MM[2] / (per[k - 1] / 1e9) <= V_START[2] * (1 + 1e-6)
        assert STEP_MM[2] / (per[k] / 1e9) <= V_START[2] * (1 + 1e-6) or not (plan.data[2 * k + 1] & 1)
    # the dwell (G4 P0.2) is a rest too: the periods on both sides of it are at the start speed
    dwell = int(np.flatnonzero(per == 200_000_000)[0])
    for k in (dwell - 1, dwell + 1):
        stepping = [a for a in range(3) if plan.data[2 * k + 1] & axis_bits(S)[0][a]]
        assert all(STEP_MM[a] / (per[k] / 1e9) <= V_START[a] * (1 + 1e-6) for a in stepping)


def test_drill_job_with_a_tool_change_passes():
    from cam.job.drill import plan_drill
    from cam.formats.excellon import HoleList

    holes = HoleList(holes_mm=np.array([[0.0, 0.0], [12.0, -3.0], [4.0, -20.0], [30.0, -8.0]]),
                     tool_of_hole=np.array([1, 1, 2, 2]), tools={1: 0.8, 2: 1.0},
                     line_of_hole=np.arange(1, 5), source="t.drl")
    dp = plan_drill(holes, drill_order="file")
    plan = plan_steps(dp.toolpath)
    assert len(plan.pause_writes) == 2
    report, motion, log = run_and_check(plan, dp.toolpath.settings)
    report.raise_if_broken()
    assert_stops_at_start_speed(log, dp.toolpath.settings, plan.pause_writes)
    assert motion.final_steps == (0, 0, 0)
    const = plan_steps(dataclasses.replace(dp.toolpath, settings=dp.toolpath.settings.replace(ramp="constant")))
    assert plan.estimated_time_s > const.estimated_time_s


def test_a_pause_at_point_decelerates_to_the_start_speed():
    rows = ["." * 62, "." + "#" * 60 + ".", "." * 62]
    d = cam.digitize(drawing_from_rows(rows))
    job = cam.plan(d, depth=2, pause_at=[(31, 1)])
    free = cam.plan(d, depth=2)
    plan, plan_free = plan_steps(job), plan_steps(free)
    assert len(plan.pause_writes) == 1
    report, _, log = run_and_check(plan, job.settings)
    report.raise_if_broken()
    assert_stops_at_start_speed(log, job.settings, plan.pause_writes)
    k = int(plan.pause_writes[0]) // 2  # the period that reaches the pause point
    per, per_free = np.diff(plan.t_ns[0::2]), np.diff(plan_free.t_ns[0::2])
    v_in = STEP_MM[0] / (per[k - 1] / 1e9)
    assert v_in <= V_START[0] * (1 + 1e-6)  # arrives at (or below) the start speed
    assert STEP_MM[0] / (per_free[k - 1] / 1e9) == pytest.approx(V_MAX[0])  # without the pause: full speed
    assert plan.estimated_time_s > plan_free.estimated_time_s


def test_a_contour_of_thousands_of_one_step_moves_keeps_full_speed():
    # an 8-connected staircase in the step domain (1 step per pixel): X every period, Y every other
    unit = S.replace(steps_per_px_xy=1)
    moves = np.tile([[1, 0], [1, 1]], (2000, 1))
    pts = np.column_stack([np.cumsum(moves, axis=0), np.zeros(len(moves), np.int64)])
    ramped = plan_steps(toolpath(pts, unit))
    const = plan_steps(toolpath(pts, unit.replace(ramp="constant")))
    report, _, _ = run_and_check(ramped, unit)
    report.raise_if_broken()
    per = np.diff(ramped.t_ns[0::2])
    assert np.mean(per == unit.delay_xy_ns) > 0.98  # full speed everywhere but the two ends
    assert ramped.estimated_time_s - const.estimated_time_s < 0.2  # one speed-up and one slow-down


def test_reversal_stops_the_reversing_axis():
    plan = plan_steps(toolpath([[30, 0, 0], [0, 0, 0]]))
    report, _, log = run_and_check(plan, S)
    report.raise_if_broken()
    t, up = axis_steps(log, S, 0)
    turn = int(np.flatnonzero(up[1:] != up[:-1])[0])
    d = np.diff(t) / 1e9
    assert STEP_MM[0] / d[turn - 1] <= V_START[0] * (1 + 1e-6)  # last interval before the reversal
    assert STEP_MM[0] / d[turn + 1] <= V_START[0] * (1 + 1e-6)  # first after it
    assert STEP_MM[0] / d[len(d) // 4] == pytest.approx(V_MAX[0])  # cruising at full speed between


# ------------------------------------------------------------------ the seed's 40-step ramp and constant


def test_linear40_is_the_seeds_ramp_on_every_move():
    # 004 section 3.5.2: delay falls linearly over the first 40 steps, rises over the last 40
    job = toolpath([[20, 0, 0], [20, 3, 0]], LINEAR40)  # 160 X steps, then 24 Y steps
    plan = plan_steps(job)
    per = np.diff(plan.t_ns[0::2])
    nominal, start = S.delay_xy_ns, STEP_MM[0] / V_START[0] * 1e9  # 5 ms, 20 ms (1.445 mm/s)
    for first, n in ((0, 160), (160, 24)):
        i = np.arange(n)
        r = np.minimum(np.minimum(i, n - 1 - i), RAMP_STEPS_LINEAR40)
        want = nominal + np.ceil((start - nominal) * (RAMP_STEPS_LINEAR40 - r) / RAMP_STEPS_LINEAR40)
        assert np.array_equal(per[first:first + n], want.astype(np.int64))
    long = per[:160]
    assert long[0] == long[-1] == 20_000_000 and np.all(long[40:120] == nominal)
    steps = np.diff(long[:41].astype(np.float64))
    assert np.all(steps < 0) and np.ptp(steps) <= 1  # linear (up to the 1 ns rounding)
    assert cam.decode_pin_log(cam.PinLog(plan.t_ns, plan.data, plan.strobe)).final_steps == (160, 24, 0)


def test_constant_mode_is_the_thesis_timing_and_ramps_only_lengthen_periods():
    rng = np.random.default_rng(5)
    pts = np.abs(np.cumsum(rng.integers(-3, 4, size=(200, 3)), axis=0)) + 5
    const = plan_steps(toolpath(pts, CONSTANT))
    per_c = np.diff(const.t_ns[0::2])
    assert set(per_c.tolist()) == {S.delay_xy_ns}
    for mode in ("lookahead", "linear40"):
        p = plan_steps(toolpath(pts, S.replace(ramp=mode)))
        assert np.array_equal(p.data, const.data)  # same writes, same path
        assert np.all(np.diff(p.t_ns[0::2]) >= per_c)
    assert np.array_equal(ramp_periods(const.data[1::2], per_c, CONSTANT), per_c)


# ------------------------------------------------------------------ settings, report, CLI


def test_settings_keys_and_errors():
    s = settings_from_mapping({"ramp": "linear40", "accel_z_mm_s2": 20, "start_speed_y_mm_s": 1.0})
    assert s.ramp == "linear40" and s.accel_z_mm_s2 == 20.0 and s.axis_limits()[1] == (1.445, 1.0, 0.785)
    for table, key in (({"ramp": "fast"}, "ramp"), ({"ramp": 1}, "ramp"),
                       ({"start_speed_x_mm_s": 6.0}, "start_speed_x_mm_s"), ({"max_speed_z_mm_s": 0}, "max_speed_z_mm_s"),
                       ({"accel_y_mm_s2": -1}, "accel_y_mm_s2"), ({"accel_q_mm_s2": 1.0}, "accel_q_mm_s2")):
        with pytest.raises(SettingsError, match=f"'{key}'"):
            settings_from_mapping(table, source="m.toml")
    assert cam.settings.load_settings(ROOT / "profiles" / "thesis-machine.toml") == DEFAULT_SETTINGS


def test_report_and_cli_name_the_ramp(tmp_path, capsys):
    from cam.cli import main

    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    job = cam.plan(d, depth=1)
    rep = cam.job_report(d, job, plan_steps(job))
    from cam.render.report import format_report

    assert rep["ramp"] == "lookahead" and "(lookahead ramps)" in format_report(rep)
    times = {}
    for mode in ("constant", "linear40", "lookahead"):
        out = tmp_path / f"{mode}.json"
        assert main(["drill", str(SAMPLES / "ellipse.png"), "--depth", "1", "--no-progress", "--ramp", mode,
                     "--report", str(out)]) == 0
        line = capsys.readouterr().out.strip().splitlines()[-1]
        assert f"{mode} ramps" in line
        rep = json.loads(out.read_text())
        assert rep["ramp"] == mode
        times[mode] = rep["estimated_time_s"]
    assert times["constant"] < times["lookahead"] < times["linear40"]


@pytest.mark.parametrize("name", ["seed_tools.plt", "extended.plt", "inkscape_star.plt"])
def test_lookahead_passes_the_checker_on_hpgl_drawings(name):
    from cam.formats.hpgl import load_hpgl
    from cam.job.hpgl import plan_hpgl

    job = plan_hpgl(load_hpgl(SAMPLES / name))
    plan = plan_steps(job)
    assert len(plan.pause_writes) >= 1  # pen selections: tool-change pauses, judged as rests
    report, motion, log = run_and_check(plan, job.settings)
    report.raise_if_broken()
    assert_stops_at_start_speed(log, job.settings, plan.pause_writes)
    assert motion.final_steps == tuple(int(v) for v in job.points_steps[-1])


def test_a_stop_lifts_z_no_faster_than_its_start_speed():
    """Controller.stop halts within one period (the safety rule) and lifts Z from rest at its start speed."""
    from cam.drive.runner import STOPPED, Controller

    job = toolpath([(0, 0, 20), (1000, 0, 20), (1000, 1000, 20), (0, 0, 20)])
    plan = plan_steps(job)
    ctl = Controller()
    half = len(plan) // 2

    def progress(done, total, t_ns):
        if done >= half:
            ctl.stop()

    result = cam.run(plan, controller=ctl, progress=progress)
    assert result.status == STOPPED
    log = result.pin_log()
    t, up = axis_steps(log, S, 2)
    lift = t[~up]  # steps up (-Z): the lift after the stop
    assert len(lift) == 20
    assert np.diff(lift).min() >= STEP_MM[2] / V_START[2] * 1e9 - 1
    assert cam.decode_pin_log(log, S).position_steps[-1][2] == 0


def test_linear40_reaches_the_start_speed_before_a_dwell():
    """The seed's ramp ends a G-code move at its start speed when a dwell (G4) follows: the dwell is a
    segment of its own, not the tail of the move."""
    from cam.formats.gcode import parse_gcode
    from cam.job.gcode import plan_gcode

    program = parse_gcode("G21 G90\nG1 X5 F600\nG4 P0.5\nG1 X10\nM2\n", source="dwell.ngc")
    plan = plan_steps(plan_gcode(program, LINEAR40))
    per = np.diff(plan.t_ns[0::2])
    dwell = int(np.argmax(per))
    assert per[dwell] == 500_000_000
    # the move ends on the slowest period of its ramp (as it starts), at about the start speed
    assert per[dwell - 1] == per[:dwell].max() == per[0]
    assert per[dwell - 1] >= 0.99 * STEP_MM[0] / V_START[0] * 1e9
    assert per[dwell + 1] == per[dwell + 1:].max()  # and the next move starts from it
