"""The command-byte back end's pieces (issue #45 point 2; seed 004 section 3.5): ``[commands]``, the translation
of step/dir writes into command bytes (:mod:`cam.drive.cmd_port`), its ports, the checks before a job, and the
reverse (:mod:`cam.verify.command_log`) that decodes a command pin log into the same motion."""
from __future__ import annotations

import sys
import time
import types

import numpy as np
import pytest

import cam
from cam.drive.cmd_port import (CommandMockPort, CommandParallelPort, check_command_timing, check_commands,
                                needed_commands, step_writes_to_commands)
from cam.pins import axis_bits
from cam.drive.ports import MockPort
from cam.errors import CamError, CapabilityError, SettingsError
from cam.settings import Commands, MachineSettings, settings_from_mapping
from cam.verify.command_log import commands_to_step_log
from cam.verify.pinlog import PinLog

from conftest import ROOT, drawing_from_rows

PROFILE = ROOT / "profiles" / "seed004-controller.toml"

# the thesis pin map (the built-in one): Z clock/dir bits 0/1, Y 2/3, X 4/5
CX, DX, CY, DY, CZ, DZ = 0x10, 0x20, 0x04, 0x08, 0x01, 0x02
BYTES = dict(x_plus=0x4B, x_minus=0x4C, y_plus=0x59, y_minus=0x5A, z_plus=0x69, z_minus=0x6A)
ALL = MachineSettings(commands=Commands(**BYTES))
US = 1000  # ns


def _translate(t_ns, data, settings=ALL, prev=0, after_ns=None):
    t, d, s = step_writes_to_commands(np.asarray(t_ns, np.int64), np.asarray(data, np.uint8),
                                      np.zeros(len(data), np.uint8), prev, settings, after_ns=after_ns)
    return t.tolist(), d.tolist(), s.tolist()


# -- [commands] ---------------------------------------------------------------------------------------------

def test_the_seed_profile_declares_x_inc_and_distinct_placeholders():
    s = cam.load_settings(PROFILE)
    assert s.commands.x_plus == 0x4B  # seed 004 3.5.3: #define X_INC (0x4B)
    declared = s.commands.declared()
    assert list(declared) == ["x_plus", "x_minus", "y_plus", "y_minus", "z_plus", "z_minus", "spindle_on",
                              "spindle_off", "init"]
    assert len(set(declared.values())) == len(declared)
    assert s.mm_per_step_xy == s.mm_per_step_z == 0.0254 and s.ramp == "linear40"
    assert abs(s.max_speed_x_mm_s * 60 - 5000) < 1  # 5000 mm/min (3.5.2)
    assert abs(s.start_speed_x_mm_s - 0.0254 / 0.008) < 1e-9  # the slowest delay, 8000 us
    check_command_timing(s)


def test_commands_are_not_declared_by_default():
    assert MachineSettings().commands.declared() == {}
    assert Commands(x_plus=0x4B, init=0).declared() == {"x_plus": 0x4B, "init": 0}


@pytest.mark.parametrize("table, key", [
    ({"x_plus": 256}, "commands.x_plus"),
    ({"z_minus": -2}, "commands.z_minus"),
    ({"x_plus": 0x4B, "init": 0x4B}, "commands.init"),  # one byte, two commands
    ({"strobe_us": 0.0}, "commands.strobe_us"),
    ({"strobe_us": 30.0, "byte_gap_us": 20.0}, "commands.byte_gap_us"),  # the pulse would outlast the gap
    ({"spindle_on": 1.5}, "commands.spindle_on"),
    ({"x_inc": 0x4B}, "commands.x_inc"),
])
def test_a_bad_commands_table_is_one_line_naming_the_key(table, key):
    with pytest.raises(SettingsError, match=key.replace(".", r"\.")) as e:
        settings_from_mapping({"commands": table}, source="m.toml")
    assert "\n" not in str(e.value) and str(e.value).startswith("m.toml: ")


# -- the translation ------------------------------------------------------------------------------------------

def test_steps_become_command_bytes_each_with_a_strobe_pulse():
    t = [0, 1000 * US, 1500 * US, 2000 * US, 2500 * US, 3000 * US, 3500 * US]
    d = [DX,                   # direction only: nothing
         DX | CX,              # +X
         DX,                   # clock low: nothing
         DX | CX | CY,         # diagonal: +X, then -Y 20 us later
         DX,
         CX | CY | DY | CZ | DZ,  # -X, +Y, +Z
         DY | DZ]
    got_t, got_d, got_s = _translate(t, d)
    assert got_t == [1000 * US, 1010 * US,
                     2000 * US, 2010 * US, 2020 * US, 2030 * US,
                     3000 * US, 3010 * US, 3020 * US, 3030 * US, 3040 * US, 3050 * US]
    assert got_d == [0x4B, 0x4B, 0x4B, 0x4B, 0x5A, 0x5A, 0x4C, 0x4C, 0x59, 0x59, 0x69, 0x69]
    assert got_s == [1, 0] * 6


def test_a_clock_already_high_before_the_stretch_is_no_step():
    assert _translate([0, 10 * US], [CX, CX | DX], prev=CX) == ([], [], [])
    assert _translate([0], [CX], prev=CX | CY)[1] == []
    assert _translate([0], [CX | CY], prev=CX)[1] == [0x5A, 0x5A]


def test_a_byte_due_sooner_than_the_gap_waits_and_the_rest_move_with_it():
    # X steps at 0, Y 5 us later in a write of its own, Z 50 us later: Y waits for the gap, Z keeps its time
    t = [0, 5 * US, 6 * US, 50 * US]
    d = [CX | DX, CX | DX | CY | DY, DX | DY, DX | DY | CZ | DZ]
    got_t, got_d, _ = _translate(t, d)
    assert got_t[0::2] == [0, 20 * US, 50 * US] and got_d[0::2] == [0x4B, 0x59, 0x69]
    assert _translate([0], [CX | DX], after_ns=-15 * US)[0] == [5 * US, 15 * US]  # a byte sent before


def _stream():
    """Step/dir writes with every case: plain steps, diagonals, close writes, clocks held high, reversals."""
    rng = np.random.default_rng(45)
    data = rng.integers(0, 64, 40).astype(np.uint8)
    t = np.cumsum(rng.choice([3, 30, 400], 40)).astype(np.int64) * US
    return t, data


def test_a_stretch_translated_in_two_pieces_equals_it_translated_whole():
    t, d = _stream()
    whole = _translate(t, d)
    assert len(whole[0]) > 20
    for i in range(len(t) + 1):
        a = _translate(t[:i], d[:i])
        last = a[0][-2] if a[0] else None  # the last byte's time: the next piece waits the gap after it
        b = _translate(t[i:], d[i:], prev=int(d[i - 1]) if i else 0, after_ns=last)
        assert tuple(x + y for x, y in zip(a, b)) == whole, f"split at {i}"


def test_an_undeclared_command_is_refused_naming_the_key():
    s = MachineSettings(commands=Commands(x_plus=0x4B))
    assert _translate([0], [CX | DX], s)[1] == [0x4B, 0x4B]
    with pytest.raises(CapabilityError, match=r"^\[commands\] x_minus is not declared: the job steps toward -X"):
        _translate([0, 10 * US, 20 * US], [CX | DX, DX, CX], s)
    with pytest.raises(CapabilityError, match=r"^\[commands\] z_plus is not declared"):
        _translate([0], [CZ | DZ | CX | DX], s)


# -- the ports ------------------------------------------------------------------------------------------------

def test_the_mock_sends_init_once_before_the_first_byte_and_keeps_the_last_data():
    s = MachineSettings(commands=Commands(**BYTES, init=0x01))
    port = CommandMockPort(s)
    assert not port.reads_inputs and port.name == "cmd:mock"
    port.write_many(np.array([0, 100 * US]), np.array([CX | DX, CX | DX], np.uint8), np.zeros(2, np.uint8))
    port.write(DX, 0, 200 * US)
    port.write(DX | CX, 0, 300 * US)
    log = port.pin_log()
    assert log.t_ns.tolist() == [0, 10 * US, 20 * US, 30 * US, 300 * US, 310 * US]
    assert log.data.tolist() == [0x01, 0x01, 0x4B, 0x4B, 0x4B, 0x4B]
    assert log.strobe.tolist() == [1, 0, 1, 0, 1, 0]


def test_the_mock_logs_the_same_writes_given_one_by_one_or_in_a_batch():
    t, d = _stream()
    one, batch = CommandMockPort(ALL), CommandMockPort(ALL)
    for ti, di in zip(t.tolist(), d.tolist()):
        one.write(di, 0, ti)
    batch.write_many(t[:7], d[:7], np.zeros(7, np.uint8))
    batch.write_many(t[7:], d[7:], np.zeros(len(t) - 7, np.uint8))
    a, b = one.pin_log(), batch.pin_log()
    assert len(a) > 20
    assert a.t_ns.tolist() == b.t_ns.tolist() and a.data.tolist() == b.data.tolist()
    assert a.strobe.tolist() == b.strobe.tolist()


def test_the_mock_takes_no_switches():
    with pytest.raises(CapabilityError, match="reads no switches"):
        CommandMockPort(ALL, switches=object())


class _FakeParallel:
    """pyparallel's ``Parallel``, recording each call and when it came."""

    def __init__(self, port):
        self.calls = []

    def setData(self, value):
        self.calls.append(("data", value, time.monotonic_ns()))

    def setDataStrobe(self, level):
        self.calls.append(("strobe", level, time.monotonic_ns()))


def test_the_parallel_port_latches_each_byte_with_a_strobe_pulse(monkeypatch):
    monkeypatch.setitem(sys.modules, "parallel", types.SimpleNamespace(Parallel=_FakeParallel))
    s = MachineSettings(commands=Commands(**BYTES, init=0x01, strobe_us=50.0, byte_gap_us=200.0))
    port = CommandParallelPort("/dev/parport0", s)
    assert port.name == "cmd:/dev/parport0" and not port.reads_inputs
    port.write(DX, 0, 0)  # no step: only the init byte
    port.write(DX | CX | CY, 0, 1000 * US)  # +X, -Y
    calls = port._port.calls
    assert [(k, v) for k, v, _ in calls] == [("data", 0x01), ("strobe", 1), ("strobe", 0),
                                             ("data", 0x4B), ("strobe", 1), ("strobe", 0),
                                             ("data", 0x5A), ("strobe", 1), ("strobe", 0)]
    ns = [w for _, _, w in calls]
    for i in (1, 4, 7):  # each pulse lasts strobe_us
        assert ns[i + 1] - ns[i] >= 50 * US
    assert ns[4] - ns[1] >= 200 * US and ns[7] - ns[4] >= 200 * US  # bytes byte_gap_us apart


# -- before a job: the bytes it needs, the timing -------------------------------------------------------------

def test_needed_commands_are_the_signs_of_the_moves():
    pts = np.array([[2, 0, 0], [2, 3, 1], [0, 3, 1]])
    assert needed_commands(pts) == {"y_plus", "z_plus", "x_minus"}
    assert needed_commands(pts, from_steps=np.zeros(3)) == {"x_plus", "y_plus", "z_plus", "x_minus"}
    assert needed_commands(np.zeros((1, 3))) == set()


def _job(settings):
    drawing = drawing_from_rows(["..........",
                                 ".#####....",
                                 "......#...",
                                 ".......#..",
                                 "......#...",
                                 "..........",
                                 "...##.....",
                                 ".........."])
    digitized = cam.digitize(cam.load_image(drawing))
    return cam.plan(digitized, depth=[3] * len(digitized.objects), settings=settings)


def test_a_job_needing_an_undeclared_command_is_refused_before_anything_moves():
    job = _job(ALL)
    check_commands(job, ALL)
    check_commands(list(job.pieces()), ALL, start_steps=(100, 100, 0))
    no_y_minus = MachineSettings(commands=Commands(**{**BYTES, "y_minus": -1, "z_minus": -1}))
    with pytest.raises(CapabilityError, match=r"^\[commands\] y_minus is not declared \(nor z_minus\): the job "
                                              r"steps toward -Y") as e:
        check_commands(job, no_y_minus)
    assert "\n" not in str(e.value)
    plunge = np.array([[0, 0, 5], [0, 0, 6]])  # only deeper: a stop would lift the tool
    with pytest.raises(CapabilityError, match=r"z_minus is not declared: a stop lifts the tool"):
        check_commands(plunge, MachineSettings(commands=Commands(z_plus=0x69)))


def test_a_machine_faster_than_three_bytes_is_refused():
    s = cam.load_settings(PROFILE)
    check_command_timing(s)  # 304.8 us per step, 3 x 20 + 10 = 70 us of bytes
    slow_unit = s.replace(commands=Commands(**{**s.commands.declared(), "byte_gap_us": 120.0}))
    with pytest.raises(CapabilityError, match=r"^\[commands\] X steps every 304.8 us at its top speed "
                                              r"\(max_speed_x_mm_s = 83.33\).*370 us") as e:
        check_command_timing(slow_unit)
    assert "\n" not in str(e.value)
    constant = s.replace(ramp="constant", delay_z_ms=0.05, commands=s.commands)  # 508 mm/s by the delay
    with pytest.raises(CapabilityError, match=r"Z steps every 50 us .*delay_z_ms"):
        check_command_timing(constant)


# -- the reverse: a command pin log decoded -------------------------------------------------------------------

def _step_positions(motion):
    """(times, positions) of the writes that moved the tool."""
    p = motion.position_steps
    moved = np.flatnonzero((np.diff(np.vstack([np.zeros((1, 3), np.int64), p]), axis=0) != 0).any(axis=1))
    return motion.t_ns[moved], p[moved]


@pytest.mark.parametrize("settings", [
    pytest.param(cam.load_settings(PROFILE), id="seed004-linear40"),
    pytest.param(MachineSettings(commands=Commands(**BYTES)), id="thesis-lookahead"),
])
def test_a_job_on_the_command_mock_decodes_to_the_motion_of_the_step_dir_mock(settings):
    job = _job(settings)
    check_commands(job, settings)
    commands = cam.run(job, CommandMockPort(settings))
    step_dir = cam.run(job, MockPort())
    assert commands.position_steps == step_dir.position_steps
    cmd_log = commands.pin_log()
    if settings.commands.init >= 0:
        assert (cmd_log.data[0], cmd_log.strobe[0]) == (settings.commands.init, 1)
        assert np.count_nonzero((cmd_log.data == settings.commands.init) & (cmd_log.strobe == 1)) == 1
    want = cam.decode_pin_log(step_dir.pin_log(), settings)
    back = commands_to_step_log(cmd_log, settings)
    assert set(back.strobe.tolist()) == {1 if settings.half_step else 0}
    got = cam.decode_pin_log(back, settings)
    assert got.final_steps == want.final_steps
    assert got.step_counts.tolist() == want.step_counts.tolist()
    assert len(cmd_log) == 2 * int(want.step_counts.sum()) + (2 if settings.commands.init >= 0 else 0)
    # each step/dir step write's position, reached by its bytes before the next step write
    t_want, p_want = _step_positions(want)
    assert len(t_want) > 100
    before_next = np.searchsorted(got.t_ns, np.append(t_want[1:], np.iinfo(np.int64).max), "left") - 1
    np.testing.assert_array_equal(got.position_steps[before_next], p_want)
    assert set(map(tuple, p_want.tolist())) <= set(map(tuple, _step_positions(got)[1].tolist()))


def test_an_unknown_byte_in_a_command_log_is_refused_naming_the_write():
    log = PinLog(np.array([0, 10, 20, 30]), np.array([0x4B, 0x4B, 0x7F, 0x7F], np.uint8),
                 np.array([1, 0, 1, 0], np.uint8))
    with pytest.raises(CamError, match=r"write 2: byte 0x7F is no command"):
        commands_to_step_log(log, ALL)


def test_a_command_log_reads_back_with_held_directions_and_half_step():
    s = MachineSettings(half_step=True, commands=Commands(**BYTES, init=0x01, spindle_on=0x53))
    log = PinLog(np.arange(12) * 100_000, np.array([0x01, 0x01, 0x53, 0x53, 0x4B, 0x4B, 0x5A, 0x5A, 0x59, 0x59,
                                                    0x4C, 0x4C], np.uint8), np.array([1, 0] * 6, np.uint8))
    back = commands_to_step_log(log, s)  # bytes 100 us apart: each its own step time
    assert back.t_ns.tolist() == [400_000, 500_000, 600_000, 700_000, 800_000, 900_000, 1_000_000, 1_100_000]
    assert back.data.tolist() == [DX | CX, DX, DX | CY, DX, DX | DY | CY, DX | DY, DY | CX, DY]
    assert back.strobe.tolist() == [1] * 8
    assert cam.decode_pin_log(back, s).final_steps == (0, 0, 0)


def test_the_bytes_of_one_step_time_read_back_as_one_diagonal_step():
    """A diagonal step's X and Y bytes, one gap (20 us) apart, are one step/dir write with both clocks high (the
    motors take them as one step time); a later X byte of the same burst window starts a new step, and bytes
    further apart than the gap stay apart."""
    s = MachineSettings(commands=Commands(**BYTES))
    t = np.array([0, 10_000, 20_000, 30_000, 40_000, 50_000, 500_000, 510_000, 600_000, 610_000])
    data = np.array([0x4B, 0x4B, 0x59, 0x59, 0x4B, 0x4B, 0x4B, 0x4B, 0x59, 0x59], np.uint8)
    back = commands_to_step_log(PinLog(t, data, np.array([1, 0] * 5, np.uint8)), s)
    assert back.t_ns.tolist() == [0, 30_000, 40_000, 50_000, 500_000, 510_000, 600_000, 610_000]
    h = DX | DY  # both directions toward + from the first burst on
    assert back.data.tolist() == [h | CX | CY, h, h | CX, h, h | CX, h, h | CY, h]
    assert cam.decode_pin_log(back, s).final_steps == (3, 2, 0)
