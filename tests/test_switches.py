"""Switches on the parallel port's input pins and ``cam home`` (issue #29 point 5).

The machine file's ``[inputs]`` wires home, limit and e-stop switches to pins 10, 11, 12, 13, 15; the runner
samples them before every write; the mock simulates them at the ``[mock]`` places (machine frame).  A limit
switch or the e-stop stops the motion before the next step and the position becomes unknown; ``cam home``
seeks each home switch, backs off, latches slowly and sets the machine's zero.  Checked on the mock's decoded
pin log.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.drive.homing import HomingError, home
from cam.drive.ports import IDLE_INPUTS, MockPort, SwitchSchedule, input_mask
from cam.motion.chunks import plan_chunks
from cam.drive.runner import LIMIT_STOPPED, Controller, SwitchWatch, run
from cam.job.model import travel_job
from cam.settings import load_settings, settings_from_mapping
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import SAMPLES, run_cli

MACHINE = """
[inputs]
home_x = "!10"
home_y = "!11"
home_z = "!12"
limit_x_max = "!13"
estop = "!15"

[homing]
search_speed_z_mm_s = 0.5
latch_speed_z_mm_s = 0.05
offset_x_mm = 0.289
offset_z_mm = -3.14

[mock]
home_x_steps = 0
home_y_steps = 0
home_z_steps = -200
limit_x_max_steps = 400
"""


def machine(tmp_path: Path, text: str = MACHINE) -> Path:
    f = tmp_path / "m.toml"
    f.write_text(text)
    return f


def one_line(proc, *fragments: str) -> str:
    lines = [line for line in proc.stderr.splitlines() if line.strip() and "first run only" not in line]
    assert proc.returncode == 2 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def where(tmp_path: Path, m: Path) -> dict:
    proc = run_cli("where", "--json", "--machine", m, "--state", tmp_path / "s.json")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def steps_after(log, settings) -> tuple[np.ndarray, np.ndarray]:
    """``(positions (N, 3) after each write, step (N,) bool: the write makes a step)``."""
    motion = decode_pin_log(log, settings)
    d = log.data.astype(np.int64)
    clocks = sum(1 << settings.pins.bit(n) for n in ("clock_x", "clock_y", "clock_z"))
    rising = (d & ~np.concatenate([[0], d[:-1]])) & clocks
    return np.asarray(motion.position_steps), rising != 0


# -- the machine file ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("table, key", [
    ('[inputs]\nhome_x = "9"\n', "inputs.home_x"),
    ('[inputs]\nhome_x = 10\n', "inputs.home_x"),
    ('[inputs]\nestop = "!!15"\n', "inputs.estop"),
    ('[inputs]\nhome_x = "!10"\nhome_y = "!10"\n', "inputs.home_y"),
    ('[inputs]\nlimit_x_max = "!13"\nestop = "!13"\n', "inputs.estop"),
    ('[inputs]\nlimit_x_max = "13"\nlimit_y_max = "!13"\n', "inputs.limit_y_max"),
    ('[inputs]\nhome_x = "!10"\nlimit_y_min = "!10"\n', "inputs.limit_y_min"),
    ('[inputs]\nswitch_x = "!10"\n', "inputs.switch_x"),
    ('[homing]\norder = "xx"\n', "homing.order"),
    ('[homing]\nsearch_speed_x_mm_s = 5.0\n', "homing.search_speed_x_mm_s"),
    ('[homing]\nlatch_speed_z_mm_s = 0.9\n', "homing.latch_speed_z_mm_s"),
    ('[homing]\ndirection_y = "up"\n', "homing.direction_y"),
    ('[homing]\noffset_x_mm = -5.0\n', "homing.offset_x_mm"),
    ('[mock]\nlimit_x_max_steps = 2000000000\n', "mock.limit_x_max_steps"),
])
def test_a_bad_inputs_or_homing_key_is_one_line_naming_it(tmp_path, table, key):
    m = machine(tmp_path, table)
    one_line(run_cli("where", "--machine", m, "--state", tmp_path / "s.json"), f"'{key}'", str(m))


def test_homing_speeds_follow_the_start_speeds_by_default():
    s = settings_from_mapping({"start_speed_z_mm_s": 0.2})  # a slow Z: no [homing] key needs changing
    assert s.homing.speeds_mm_s(s, "z") == (0.2, pytest.approx(0.02))
    assert s.homing.speeds_mm_s(s, "x") == (s.start_speed_x_mm_s, pytest.approx(s.start_speed_x_mm_s / 10))


def test_inputs_read_as_pins_and_levels():
    s = settings_from_mapping({"inputs": {"home_x": "!10", "limit_x_min": " !10", "limit_x_max": "10 ".replace(
        "10", "11"), "estop": "15"}})
    assert s.inputs.wired() == {"home_x": (10, False), "limit_x_min": (10, False), "limit_x_max": (11, True),
                                "estop": (15, True)}
    assert [input_mask(p) for p in (10, 11, 12, 13, 15)] == [64, 128, 32, 16, 8]  # the status register's bits
    assert cam.settings.DEFAULT_SETTINGS.inputs.wired() == {}  # nothing wired: nothing sampled


class _FakePpdev:
    """pyparallel's ppdev port as far as the inputs go: the status register as the hardware gives it."""

    def __init__(self, status: int) -> None:
        self.status = status

    def PPRSTATUS(self) -> int:  # noqa: N802 - pyparallel's name
        return self.status


class _FakeOther:
    """pyparallel elsewhere: each pin's level (getInBusy already undoes BUSY's inversion)."""

    def getInAcknowledge(self): return False  # noqa: E704,N802
    def getInBusy(self): return True  # noqa: E704,N802
    def getInPaperOut(self): return False  # noqa: E704,N802
    def getInSelected(self): return True  # noqa: E704,N802
    def getInError(self): return False  # noqa: E704,N802


def test_the_parallel_port_reads_its_status_register_as_pin_levels():
    from cam.drive.ports import ParallelPort

    port = object.__new__(ParallelPort)
    port.name = "/dev/parport0"
    port._port = _FakePpdev(0x70)  # BUSY bit 0 (pin 11 high: the hardware inverts it), ACK, PAPER-OUT, SELECT high
    assert port.reads_inputs and port.read_inputs() == IDLE_INPUTS & ~input_mask(15)  # ERROR (pin 15) low
    port._port = _FakeOther()
    assert port.read_inputs() == input_mask(11) | input_mask(13)


def test_the_real_time_check_is_the_batch_rule():
    s = settings_from_mapping({"inputs": {"limit_x_max": "!13", "limit_y_min": "!13", "estop": "!15",
                                          "home_x": "!10"}})
    rng = np.random.default_rng(7)
    for _ in range(200):
        levels = rng.choice([IDLE_INPUTS, IDLE_INPUTS & ~16, IDLE_INPUTS & ~8, IDLE_INPUTS & ~24], 30,
                            p=[.7, .15, .05, .1]).astype(np.int64)
        data = rng.integers(0, 256, 30)
        batch, one = SwitchWatch(s), SwitchWatch(s)
        k = batch.first(levels, data)
        assert k == next((i for i in range(30) if one.check(int(levels[i]), int(data[i]))), 30)
        assert batch.tripped == one.tripped


# -- a limit switch and the e-stop stop the motion -----------------------------------------------------------

def test_a_limit_switch_closing_mid_move_stops_before_the_next_step():
    s = settings_from_mapping({"inputs": {"limit_x_max": "!13"}})
    job = travel_job(np.array([[1000, 300, 0]]), s)
    port = MockPort(switches=SwitchSchedule(s, (0, 0, 0), {"limit_x_max": 500}))
    r = cam.run(job, port)
    assert r.status == LIMIT_STOPPED and r.switch == "limit_x_max"
    assert len(r.messages) == 1 and "limit switch limit_x_max (pin 13) closed" in r.messages[0]
    pos, step = steps_after(r.pin_log(), s)
    closed = int(np.argmax(pos[:, 0] >= 500))  # the write after which the switch is closed
    assert pos[-1, 0] == 500 and not step[closed + 1:].any()  # not one step more, on any axis
    assert r.position_steps == tuple(pos[-1])


def test_without_switches_the_simulated_run_samples_nothing():
    s = settings_from_mapping({"inputs": {"limit_x_max": "!13"}})
    job = travel_job(np.array([[1000, 0, 0]]), s)
    r = cam.run(job, MockPort())  # no schedule: the mock reads no inputs, the run is as before
    assert r.status == "finished" and r.position_steps == (1000, 0, 0)
    assert MockPort().read_inputs() == IDLE_INPUTS and not MockPort().reads_inputs


def test_a_limit_closed_at_the_start_stops_only_steps_toward_it():
    s = settings_from_mapping({"inputs": {"limit_x_max": "!13"}})

    def from_500(points):
        plan = plan_chunks(travel_job(np.array(points), s), start_steps=(500, 0, 0))
        return run(plan, MockPort(switches=SwitchSchedule(s, (500, 0, 0), {"limit_x_max": 500})))

    toward = from_500([[10, 0, 0]])
    assert toward.status == LIMIT_STOPPED and toward.position_steps == (0, 0, 0)
    assert "no step toward it was sent" in toward.messages[0]
    away = from_500([[-100, 0, 0]])
    assert away.status == "finished" and away.position_steps == (-100, 0, 0)
    back = from_500([[-100, 0, 0], [0, 0, 0]])
    assert back.status == LIMIT_STOPPED and back.position_steps == (0, 0, 0)  # it opened, then closed again


def test_the_watch_books_the_first_switch():
    s = settings_from_mapping({"inputs": {"limit_x_max": "!13", "estop": "!15"}})
    w = SwitchWatch(s)
    idle = IDLE_INPUTS
    assert w.first(np.array([idle, idle, idle & ~8, idle & ~8]), np.zeros(4, np.int64)) == 2 and w.tripped == "estop"


def test_the_lift_after_a_stop_samples_the_switches_too():
    s = settings_from_mapping({"inputs": {"limit_z_min": "!13"}})
    job = travel_job(np.array([[0, 0, 100], [2000, 0, 100]]), s)
    job.pause[0] = True  # stopped at the pause, 100 steps deep: the lift up meets limit_z_min at Z=50
    ctl = Controller()
    port = MockPort(switches=SwitchSchedule(s, (0, 0, 0), {"limit_z_min": 50}))
    r = run(plan_chunks(job), port, controller=ctl, on_pause=lambda position, note: ctl.stop())
    assert r.status == LIMIT_STOPPED and r.position_steps == (0, 0, 50) and "limit_z_min" in r.messages[0]
    pos, step = steps_after(r.pin_log(), s)
    peak = int(np.argmax(pos[:, 2] == 100))
    closed = peak + int(np.argmax(pos[peak:, 2] <= 50))
    assert tuple(pos[-1]) == (0, 0, 50) and not step[closed + 1:].any()


def test_a_limit_switch_mid_move_makes_the_position_unknown_until_home_or_where_set(tmp_path):
    m, st = machine(tmp_path), tmp_path / "s.json"
    proc = run_cli("goto", "600,0,0", "--unit", "steps", "--machine", m, "--state", st, "--pin-log",
                   tmp_path / "p.csv")
    assert proc.returncode != 0 and "limit switch limit_x_max (pin 13) closed" in proc.stderr
    pos, step = steps_after(read_pin_log(tmp_path / "p.csv"), load_settings(m))
    assert pos[-1, 0] == 400 and not step[int(np.argmax(pos[:, 0] >= 400)) + 1:].any()
    rep = where(tmp_path, m)
    assert not rep["position_known"] and "limit_x_max" in rep["unknown_reason"] and rep["machine_steps"] == [400, 0, 0]
    one_line(run_cli("goto", "0,0,0", "--machine", m, "--state", st), "position is unknown", "cam home",
             "cam where --set")
    assert run_cli("where", "--set", "11.56,0,0", "--machine", m, "--state", st).returncode == 0
    assert run_cli("jog", "X-", "100", "--machine", m, "--state", st).returncode == 0  # off the switch
    assert where(tmp_path, m)["machine_steps"] == [300, 0, 0]


def test_a_limit_switch_closing_mid_job_stops_the_drill_within_one_period(tmp_path):
    text = MACHINE.replace('limit_x_max = "!13"', 'limit_x_max = "!13"\nlimit_y_max = "!13"')
    m, st = machine(tmp_path, text.replace("limit_x_max_steps = 400", "limit_y_max_steps = 700")), tmp_path / "s.json"
    proc = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--machine", m, "--state", st, "--pin-log",
                   tmp_path / "p.csv", "--report", tmp_path / "r.json")
    assert proc.returncode == 130 and "limit switch limit_x_max/limit_y_max (pin 13) closed" in proc.stderr, \
        proc.stderr  # one pin for both: it cannot tell which
    assert json.loads((tmp_path / "r.json").read_text())["status"] == LIMIT_STOPPED
    s = load_settings(m)
    log = read_pin_log(tmp_path / "p.csv")
    pos, step = steps_after(log, s)
    closed = int(np.argmax(pos[:, 1] >= 700))
    assert pos[closed, 1] == 700 and closed == len(pos) - 1 and not step[closed + 1:].any()
    assert 1000 < len(pos) < 14457  # mid-job: the whole ellipse is 14457 writes
    rep = where(tmp_path, m)
    assert not rep["position_known"] and rep["machine_steps"] == [int(v) for v in pos[-1]]
    one_line(run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--machine", m, "--state", st),
             "position is unknown", "limit_y_max")


def test_a_limit_switch_stops_the_travel_to_the_work_zero_too(tmp_path):
    m, st = machine(tmp_path), tmp_path / "s.json"
    assert run_cli("zero", "XY", "--at", "14.45,0,0", "--machine", m, "--state", st).returncode == 0  # X=500 steps
    proc = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--machine", m, "--state", st)
    assert proc.returncode == 130 and "limit switch limit_x_max (pin 13) closed" in proc.stderr, proc.stderr
    rep = where(tmp_path, m)
    assert not rep["position_known"] and rep["machine_steps"] == [400, 0, 0]


def test_the_e_stop_input_stops_the_job_and_the_position_is_unknown(tmp_path):
    m, st = machine(tmp_path, MACHINE + "estop_after_s = 0.5\n"), tmp_path / "s.json"
    proc = run_cli("goto", "300,300,0", "--unit", "steps", "--machine", m, "--state", st, "--pin-log",
                   tmp_path / "p.csv")
    assert proc.returncode != 0 and "e-stop input (pin 15) is closed" in proc.stderr
    log = read_pin_log(tmp_path / "p.csv")
    assert log.t_ns[-1] < 500_000_000 and len(log.t_ns) > 10  # not one write at or after the e-stop closed
    rep = where(tmp_path, m)
    assert not rep["position_known"] and "emergency stop" in rep["unknown_reason"]
    one_line(run_cli("goto", "0,0,0", "--machine", m, "--state", st), "position is unknown")  # a jog is allowed


# -- homing ----------------------------------------------------------------------------------------------------

def test_cam_home_searches_backs_off_latches_and_sets_machine_zero(tmp_path):
    m, st = machine(tmp_path), tmp_path / "s.json"
    s = load_settings(m)
    assert run_cli("goto", "300,200,100", "--unit", "steps", "--machine", m, "--state", st).returncode == 0
    proc = run_cli("home", "--machine", m, "--state", st, "--pin-log", tmp_path / "h.csv")
    assert proc.returncode == 0, proc.stderr
    assert "homed ZXY" in proc.stdout and "homing Z: latch" in proc.stderr
    log = read_pin_log(tmp_path / "h.csv")
    pos, step = steps_after(log, s)
    t = log.t_ns[step]
    moves = np.diff(np.vstack([[0, 0, 0], pos]), axis=0)[step]
    axis = np.argmax(moves != 0, axis=1)
    sign = moves[np.arange(len(moves)), axis]
    runs = []  # (axis, sign, steps, median step interval ns) of each stretch of one axis one way
    k = 0
    while k < len(axis):
        e = k
        while e + 1 < len(axis) and axis[e + 1] == axis[k] and sign[e + 1] == sign[k]:
            e += 1
        runs.append(("xyz"[axis[k]], int(sign[k]), e - k + 1, float(np.median(np.diff(t[k:e + 1]))) if e > k else 0))
        k = e + 1
    assert [(a, d) for a, d, _, _ in runs] == [("z", -1), ("z", 1), ("z", -1), ("x", -1), ("x", 1), ("x", -1),
                                               ("y", -1), ("y", 1), ("y", -1)]
    z_search, z_back, z_latch = runs[0], runs[1], runs[2]
    assert z_search[2] == 300  # from Z=100 up to the switch at -200
    assert z_back[2] == 1 + round(0.5 / s.mm_per_step_z)  # until it opened, then backoff_z_mm more
    assert z_latch[2] == z_back[2]  # back to where it closed
    assert z_search[3] == pytest.approx(s.mm_per_step_z / 0.5 * 1e9, rel=0.01)  # search speed 0.5 mm/s
    assert z_latch[3] == pytest.approx(s.mm_per_step_z / 0.05 * 1e9, rel=0.01)  # latch speed, ten times slower
    assert runs[3][2] == 300 and runs[6][2] == 200
    assert np.all(np.diff(log.t_ns) >= 0)  # one time line over the phases
    rep = where(tmp_path, m)
    assert rep["homed"] and rep["position_known"] and rep["machine_steps"] == [10, 0, -200]  # the offsets
    assert run_cli("goto", "0,0,0", "--unit", "steps", "--machine", m, "--state", st).returncode == 0


def test_cam_home_after_a_limit_stop_makes_the_position_known(tmp_path):
    m, st = machine(tmp_path), tmp_path / "s.json"
    assert run_cli("goto", "600,0,0", "--unit", "steps", "--machine", m, "--state", st).returncode != 0
    assert not where(tmp_path, m)["position_known"]
    assert run_cli("home", "--axes", "x", "--machine", m, "--state", st).returncode == 0
    rep = where(tmp_path, m)
    assert rep["position_known"] and rep["homed"] and rep["machine_steps"] == [10, 0, 0]


def test_a_home_switch_sharing_its_limit_pin_does_not_stop_homing():
    s = settings_from_mapping({"inputs": {"home_x": "!10", "limit_x_min": "!10"}, "homing": {"order": "x"}})
    port = MockPort(switches=SwitchSchedule(s, (200, 0, 0), {"home_x": 0}))
    assert home(port, s, (200, 0, 0)).position_steps == (0, 0, 0)
    plan = plan_chunks(travel_job(np.array([[-5, 0, 0]]), s), start_steps=(5, 0, 0))  # past the switch at 0:
    r = run(plan, MockPort(switches=SwitchSchedule(s, (5, 0, 0), {"home_x": 0})))  # its limit stops it there
    assert r.status == LIMIT_STOPPED and r.position_steps == (-5, 0, 0)


def test_homing_stops_at_a_limit_switch_and_at_a_switch_that_never_closes():
    s = settings_from_mapping({"inputs": {"home_x": "!10", "limit_x_min": "!11"}, "homing": {"order": "x"}})
    port = MockPort(switches=SwitchSchedule(s, (200, 0, 0), {"home_x": 0, "limit_x_min": 50}))
    with pytest.raises(HomingError, match="limit switch limit_x_min"):
        home(port, s, (200, 0, 0))
    t = settings_from_mapping({"inputs": {"home_x": "!10"}, "homing": {"order": "x"}, "travel": {"x_max_steps": 50}})
    with pytest.raises(HomingError, match="home_x did not close"):
        home(MockPort(switches=SwitchSchedule(t, (20, 0, 0), {})), t, (20, 0, 0))


def test_cam_home_refuses_in_one_line(tmp_path):
    st = tmp_path / "s.json"
    one_line(run_cli("home", "--state", st), "no home switches", "[inputs]")
    m = machine(tmp_path, '[inputs]\nhome_x = "!10"\n')
    one_line(run_cli("home", "--machine", m, "--state", st), "inputs.home_z")
    one_line(run_cli("home", "--axes", "x", "--machine", m, "--state", st), "[mock]")
    one_line(run_cli("home", "--axes", "xq", "--state", st), "--axes")
    one_line(run_cli("home", "--axes", "x", "--machine", m, "--port", "maximus:/dev/null", "--state", st),
             "step/dir port")
    assert "search speed" in run_cli("home", "--help").stdout


@pytest.mark.realtime
def test_a_limit_switch_stops_a_real_time_run_on_the_mock():
    s = settings_from_mapping({"inputs": {"limit_y_max": "!12"}, "delay_xy_ms": 1.0, "delay_z_ms": 1.0,
                               "ramp": "constant"})
    job = travel_job(np.array([[0, 200, 0]]), s)
    port = MockPort(switches=SwitchSchedule(s, (0, 0, 0), {"limit_y_max": 40}))
    r = cam.run(job, port, realtime=True)
    assert r.status == LIMIT_STOPPED and r.position_steps == (0, 40, 0)
    pos, step = steps_after(r.pin_log(), s)
    assert not step[int(np.argmax(pos[:, 1] >= 40)) + 1:].any()
    assert r.wall_time_s < 1.0  # it ended there, not after the whole move


@pytest.mark.realtime
def test_a_limit_switch_ends_a_real_time_lift():
    s = settings_from_mapping({"inputs": {"limit_z_min": "!13"}, "delay_xy_ms": 1.0, "delay_z_ms": 1.0,
                               "ramp": "constant"})
    job = travel_job(np.array([[0, 0, 100], [2000, 0, 100]]), s)
    ctl = Controller()
    port = MockPort(switches=SwitchSchedule(s, (0, 0, 0), {"limit_z_min": 50}))
    r = run(plan_chunks(job), port, realtime=True, controller=ctl,
            progress=lambda done, total, t_ns: ctl.stop() if done > 300 else None)
    assert r.status == LIMIT_STOPPED and r.position_steps[2] == 50, r.messages


@pytest.mark.realtime
def test_the_e_stop_input_stops_a_real_time_homing():
    s = settings_from_mapping({"inputs": {"home_z": "!12", "estop": "!15"}, "homing": {"order": "z"}})
    cam.run(travel_job(np.array([[0, 2, 0]]), s), MockPort(), realtime=True)  # the runner's first-run costs
    port = MockPort(switches=SwitchSchedule(s, (0, 0, 100), {"home_z": -1000, "estop": 0.5}))
    with pytest.raises(HomingError, match="e-stop input .pin 15. is closed"):
        home(port, s, (0, 0, 100), realtime=True)
    t = port.pin_log().t_ns
    period_ns = s.mm_per_step_z / s.homing.speeds_mm_s(s, "z")[0] * 1e9
    assert 0.5e9 - 2 * period_ns < t[-1] < 0.5e9  # sampled before every write: none after it closed
    assert not port.read_inputs() & input_mask(15)  # still pressed: pin 15 pulled low
