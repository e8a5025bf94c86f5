"""The machine state file (issue #29 points 2-3): where the machine stands outlives a command.

Every moving command (drill, goto, jog) starts where the state file says the tool stands and records where it
ended (also after Ctrl-C, SIGTERM and a fault); a killed command or an emergency stop leaves the position
unknown, and a move is then refused until ``cam where --set``; two commands never drive one machine at once;
``cam where`` and ``cam zero`` read and set it.  The motion is checked on the mock's decoded pin log.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.cli.execute import ended_state
from cam.drive.session import MachineSession
from cam.drive.state import (
    OFFSET_NAMES, MachineLock, MachineState, StateBusyError, StateError, StateHold, default_state_path,
    parse_state, read_state, state_dir, unknown_message, write_state,
)
from cam.drive.runner import Controller
from cam.job.model import CUT
from cam.job.moves import jog as jog_job
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import ok, one_line_error, ROOT, run_cli, SAMPLES, wait_for_progress

S = cam.MachineSettings()
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def state_of(path: Path) -> MachineState:
    return read_state(path, S)


def moved_by(pins: Path) -> tuple[int, int, int]:
    """Where the decoded pin log ends, relative to where its run started."""
    return tuple(int(v) for v in decode_pin_log(read_pin_log(pins), S).position_steps[-1])


# -- go to, jog, zero: the position is kept from one command to the next -------------------------------------

def test_goto_then_goto_back_moves_back(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("goto", "10,10,0", "--state", st, "--pin-log", tmp_path / "a.csv"))
    assert state_of(st).position_steps == (80, 80, 0)
    assert moved_by(tmp_path / "a.csv") == (80, 80, 0)
    out = ok(run_cli("goto", "0,0,0", "--state", st, "--pin-log", tmp_path / "b.csv")).stdout
    assert moved_by(tmp_path / "b.csv") == (-80, -80, 0)  # it moves: back to where the first started
    assert state_of(st).position_steps == (0, 0, 0) and "at X=0 Y=0 Z=0 steps in G54" in out
    again = ok(run_cli("goto", "0,0,0", "--state", st, "--pin-log", tmp_path / "c.csv")).stdout
    assert "there already" in again


def test_goto_lifts_to_the_work_zero_before_it_travels(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("goto", "10,10,5", "--state", st))
    ok(run_cli("goto", "20,10,3", "--state", st, "--pin-log", tmp_path / "p.csv"))
    pos = decode_pin_log(read_pin_log(tmp_path / "p.csv"), S).position_steps + np.array([80, 80, 5])
    x_moving = np.flatnonzero(np.diff(pos[:, 0]) != 0) + 1
    assert pos[x_moving, 2].max() == 0  # X travels at the surface (Z = 0), never in the material
    assert tuple(pos[-1]) == (160, 80, 3) == state_of(st).position_steps


def test_zero_then_goto_0_0_0_returns_to_the_zero(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("jog", "X+", "100", "--state", st))
    ok(run_cli("jog", "Y+", "1", "--unit", "mm", "--state", st))  # 1 mm / 0.0289 = 35 steps
    ok(run_cli("jog", "Z+", "7", "--state", st))
    assert state_of(st).position_steps == (100, 35, 7)
    ok(run_cli("zero", "--state", st))
    assert state_of(st).work_zero_steps() == (100, 35, 7)
    ok(run_cli("goto", "12,3,0", "--unit", "mm", "--state", st, "--pin-log", tmp_path / "a.csv"))
    assert state_of(st).position_steps == (100 + 415, 35 + 104, 7)
    rep = json.loads(ok(run_cli("where", "--json", "--state", st)).stdout)
    assert rep["work_steps"] == [415, 104, 0] and rep["work_mm"] == [pytest.approx(11.9935), pytest.approx(3.0056), 0]
    ok(run_cli("goto", "0,0,0", "--state", st, "--pin-log", tmp_path / "b.csv"))
    assert moved_by(tmp_path / "b.csv") == (-415, -104, 0)
    assert state_of(st).position_steps == (100, 35, 7)
    # --machine-coords: the machine frame, whatever the work zero
    ok(run_cli("goto", "0,0,0", "--machine-coords", "--state", st, "--pin-log", tmp_path / "c.csv"))
    assert moved_by(tmp_path / "c.csv") == (-100, -35, -7) and state_of(st).position_steps == (0, 0, 0)


def test_zero_one_axis_another_offset_and_at_a_point(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("goto", "500,300,20", "--unit", "steps", "--state", st))
    ok(run_cli("zero", "Z", "--state", st))
    assert state_of(st).offsets_steps["G54"] == (0, 0, 20)
    out = ok(run_cli("zero", "XY", "--offset", "G55", "--state", st)).stdout
    assert "the active offset is still G54" in out and "cam where --use G55" in out
    ok(run_cli("zero", "--offset", "G59.3", "--at", "2.89,0,0.157", "--state", st))
    s = state_of(st)
    assert s.offsets_steps["G55"] == (500, 300, 0) and s.offsets_steps["G59.3"] == (100, 0, 10)
    assert s.active_offset == "G54"
    ok(run_cli("where", "--use", "G55", "--state", st))
    ok(run_cli("goto", "0,0,0", "--state", st))
    assert state_of(st).position_steps == (500, 300, 0)  # the G55 zero (its Z zero is the machine's)
    one_line_error(run_cli("zero", "Q", "--state", st), "axes must be X, Y, Z")
    one_line_error(run_cli("zero", "XX", "--state", st), "axes must be")
    one_line_error(run_cli("zero", "--at", "999,0,0", "--state", st), "--at 999,0,0 mm", "X travel", "beyond")
    assert state_of(st).offsets_steps["G54"] == (0, 0, 20)  # nothing changed by the refused ones


def test_jog_keeps_the_state_and_is_checked_from_where_the_tool_is(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("jog", "X+", "100", "--state", st))
    out = ok(run_cli("jog", "X+", "100", "--state", st, "--pin-log", tmp_path / "p.csv")).stdout
    assert moved_by(tmp_path / "p.csv") == (100, 0, 0) and state_of(st).position_steps == (200, 0, 0)
    assert "jogged X by 100 steps" in out and "machine X=200" in out
    one_line_error(run_cli("jog", "X-", "300", "--state", st), "X travel", "X=200", "-100..200")
    one_line_error(run_cli("jog", "Z-", "700", "--state", st), "Z travel")
    assert state_of(st).position_steps == (200, 0, 0)


def test_goto_outside_the_travel_names_the_axis_and_by_how_much(tmp_path):
    st = tmp_path / "m.json"
    one_line_error(run_cli("goto", "1300,0,0", "--state", st), "X travel", "10400 is 400 steps beyond")
    one_line_error(run_cli("goto", "0,0,-700", "--unit", "steps", "--state", st), "Z travel", "60 steps beyond")
    one_line_error(run_cli("goto", "0.5,0,0", "--state", st), "whole numbers")
    one_line_error(run_cli("goto", "1,2", "--state", st), "X,Y,Z")
    assert not st.exists() or state_of(st).position_steps == (0, 0, 0)


def test_the_default_state_file_is_per_machine_file_and_port(tmp_path, state_home):
    ok(run_cli("jog", "X+", "10"))
    assert state_of(state_home / "default-mock.json").position_steps == (10, 0, 0)
    machine = tmp_path / "mill.toml"
    machine.write_text("[travel]\nx_max_steps = 500\n")
    ok(run_cli("jog", "Y+", "5", "--machine", machine))
    assert read_state(state_home / "mill-mock.json", cam.load_settings(machine)).position_steps == (0, 5, 0)
    assert state_of(state_home / "default-mock.json").position_steps == (10, 0, 0)
    env = {"XDG_STATE_HOME": "/s"}
    # a real port's state is the port's (issue #43 point 5: it records its machine file instead)
    assert default_state_path(None, "/dev/parport0", env).as_posix() == "/s/cam/dev-parport0.json"
    assert default_state_path("a/b.toml", "maximus:/dev/ttyUSB0", env).name == "maximus-dev-ttyUSB0.json"
    assert default_state_path("a/b.toml", "grbl:/dev/ttyUSB0?baud=9600", env).name == "grbl-dev-ttyUSB0.json"
    assert state_dir({"XDG_STATE_HOME": "relative"}) == Path.home() / ".local" / "state" / "cam"


# -- jobs: the state after a finished and a stopped job --------------------------------------------------------

def test_a_drawing_job_is_cut_at_the_work_zero_and_the_state_keeps_its_end(tmp_path):
    st = tmp_path / "m.json"
    ref = ok(run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--state", tmp_path / "fresh.json",
                     "--pin-log", tmp_path / "ref.csv"))
    assert "work zero" not in ref.stderr
    want = decode_pin_log(read_pin_log(tmp_path / "ref.csv"), S).position_steps
    ok(run_cli("goto", "100,50,0", "--state", st))  # the case: a go-to, then a job
    proc = ok(run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--state", st, "--pin-log",
                      tmp_path / "j.csv", "--tool", "point"))
    assert "going to the work zero first: machine [800, 400, 0] -> [0, 0, 0] steps" in proc.stderr
    assert np.array_equal(decode_pin_log(read_pin_log(tmp_path / "j.csv", part="job"), S).position_steps, want)
    s = state_of(st)
    assert s.position_steps == (0, 0, 0) and s.position_known and s.running is None and s.tool == "point"
    ok(run_cli("goto", "100,50,3", "--state", st))
    ok(run_cli("zero", "--state", st))  # a work zero 3 steps deep: the job is cut from there
    ok(run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--state", st, "--pin-log", tmp_path / "k.csv"))
    assert np.array_equal(decode_pin_log(read_pin_log(tmp_path / "k.csv", part="job"), S).position_steps, want)
    assert state_of(st).position_steps == (800, 400, 3)  # a job ends at its home: the work zero
    # placed where it does not fit: refused in the machine frame, naming the axis and by how much
    ok(run_cli("zero", "XY", "--at", "286,286,0", "--state", st))
    line = one_line_error(run_cli("drill", SAMPLES / "ellipse.png", "--depth", "2", "--state", st),
                          "the drawing job placed at the G54 work zero (machine [9896, 9896, 3] steps)",
                          "leaves the X travel", "steps beyond")
    assert state_of(st).position_steps == (800, 400, 3) and state_of(st).running is None, line


def test_a_job_stopped_at_a_prompt_records_where_it_stopped(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("goto", "10,10,0", "--state", st))
    ok(run_cli("zero", "--state", st))  # a drill file starts at the work zero: here
    proc = run_cli("drill", SAMPLES / "board.drl", "--state", st, "--pin-log", tmp_path / "p.csv")  # no answer
    assert proc.returncode == 130, proc.stderr
    end = tuple(a + b for a, b in zip((80, 80, 0), moved_by(tmp_path / "p.csv")))
    s = state_of(st)
    assert s.position_steps == end != (80, 80, 0) and s.position_known and s.running is None


def test_resume_goes_on_from_the_journal_and_refuses_a_tool_moved_since(tmp_path):
    st, journal = tmp_path / "m.json", tmp_path / "j.journal.json"
    ok(run_cli("goto", "10,10,0", "--state", st))
    ok(run_cli("zero", "--state", st))
    stopped = run_cli("drill", SAMPLES / "board.drl", "--state", st, "--journal", journal)  # no answer: stops
    assert stopped.returncode == 130, stopped.stderr
    where = state_of(st).position_steps
    ok(run_cli("jog", "X+", "10", "--state", st))
    refused = run_cli("drill", SAMPLES / "board.drl", "--yes", "--state", st, "--resume", journal)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr  # after cam drill's "resuming at" note:
    last = refused.stderr.strip().splitlines()[-1]  # the state is checked when the run starts
    for fragment in (f"has the tool at {[where[0] + 10, where[1], where[2]]} steps", f"left it at {list(where)}",
                     "go back there"):
        assert fragment in last, last
    ok(run_cli("jog", "X-", "10", "--state", st))
    proc = ok(run_cli("drill", SAMPLES / "board.drl", "--yes", "--state", st, "--resume", journal))
    assert "work zero" not in proc.stderr  # a resumed job goes on from where the tool is
    s = state_of(st)
    assert s.position_steps == (80, 80, 0) and s.position_known and s.running is None  # the job ends at its home


def test_a_drill_file_is_placed_at_the_work_zero(tmp_path):
    st, fresh = tmp_path / "m.json", tmp_path / "fresh.json"
    ref = ok(run_cli("drill", SAMPLES / "board.drl", "--yes", "--state", fresh, "--pin-log", tmp_path / "ref.csv"))
    assert "work zero" not in ref.stderr  # the tool stands at the work zero already
    ok(run_cli("goto", "1000,600,0", "--unit", "steps", "--state", st))
    ok(run_cli("zero", "--state", st))
    ok(run_cli("goto", "0,0,0", "--machine-coords", "--state", st))
    proc = ok(run_cli("drill", SAMPLES / "board.drl", "--yes", "--state", st, "--pin-log", tmp_path / "j.csv"))
    assert "going to the work zero first: machine [0, 0, 0] -> [1000, 600, 0] steps" in proc.stderr
    job = decode_pin_log(read_pin_log(tmp_path / "j.csv", part="job"), S).position_steps
    want = decode_pin_log(read_pin_log(tmp_path / "ref.csv"), S).position_steps
    assert np.array_equal(job, want)  # the same job, in its own frame: the pin log marks the job's part
    assert state_of(st).position_steps == tuple(int(z) + int(m) for z, m in zip((1000, 600, 0), want[-1]))
    # placed where it does not fit: refused in the machine frame, naming the axis and by how much
    ok(run_cli("zero", "--at", "285,0,0", "--state", st))  # 9862 steps
    line = one_line_error(run_cli("drill", SAMPLES / "board.drl", "--yes", "--state", st),
                          "the drill job placed at the G54 work zero",
                          "leaves the X travel", "steps beyond")
    assert "machine [9862, 0, 0] steps" in line
    assert state_of(st).running is None and state_of(st).position_known


def test_a_port_that_fails_before_sending_keeps_the_position_known(tmp_path):
    st = tmp_path / "m.json"
    write_state(st, MachineState(position_steps=(30, 40, 0)))
    one_line_error(run_cli("goto", "1,1,0", "--port", tmp_path / "no-such-parport", "--state", st))
    s = state_of(st)
    assert s.position_steps == (30, 40, 0) and s.position_known and s.running is None


def test_an_emergency_stop_makes_the_position_unknown():
    session = MachineSession("mock", S)
    session.set_position((100, 0, 0))
    job = jog_job("x", 2000, settings=S)
    job.kind[:] = CUT  # a job, run with the caller's controller
    ctl = Controller()
    ctl.emergency_stop()  # pressed as it starts
    session.start(job, controller=ctl)
    session.wait_idle(None)
    assert session.last_run["status"] == "emergency-stopped"
    after = ended_state(MachineState(position_steps=(100, 0, 0)), session, (100, 0, 0))
    assert not after.position_known and "emergency stop" in after.unknown_reason
    assert after.position_steps == session.position_steps()  # where it got to, kept as a guess
    finished = MachineSession("mock", S)
    finished.start(jog_job("y", 20, settings=S))
    finished.wait_idle(None)
    assert ended_state(MachineState(), finished, (0, 0, 0)).position_steps == (0, 20, 0)


# -- unknown position, two commands at once, a broken file -------------------------------------------------------

def test_a_running_marker_left_behind_makes_the_next_move_refused_until_where_set(tmp_path):
    st = tmp_path / "m.json"
    write_state(st, MachineState(position_steps=(50, 0, 0)))
    with StateHold(st, S) as hold:  # a command that starts driving, then vanishes without recording
        hold.mark_running("cam drill part.png")
    line = one_line_error(run_cli("goto", "1,1,0", "--state", st), "position is unknown", "cam drill part.png",
                          "home the machine (cam home)", "cam where --set X,Y,Z")
    assert "ended without recording" in line
    rep = json.loads(ok(run_cli("where", "--json", "--state", st)).stdout)
    assert rep["position_known"] is False and rep["running"] is None and rep["homed"] is False
    for argv in (["drill", SAMPLES / "ellipse.png", "--depth", "1"], ["zero"]):  # a jog is allowed (issue #45)
        one_line_error(run_cli(*argv, "--state", st), "position is unknown")
    ok(run_cli("where", "--set", "2.89,0,0", "--state", st))
    s = state_of(st)
    assert s.position_known and s.position_steps == (100, 0, 0)
    ok(run_cli("goto", "0,0,0", "--state", st, "--pin-log", tmp_path / "p.csv"))
    assert moved_by(tmp_path / "p.csv") == (-100, 0, 0)
    one_line_error(run_cli("where", "--set", "300,0,0", "--state", st), "--set 300,0,0 mm", "X travel")


def test_a_second_command_is_refused_while_one_drives_the_machine(tmp_path):
    st = tmp_path / "m.json"
    lock = MachineLock(st)
    lock.acquire()
    try:
        assert MachineLock(st).holder() == os.getpid()
        for argv in (["goto", "1,1,0"], ["jog", "X+", "1"], ["drill", SAMPLES / "ellipse.png", "--depth", "1"],
                     ["zero"], ["where", "--set", "0,0,0"]):
            one_line_error(run_cli(*argv, "--state", st), "refused", f"pid {os.getpid()}", "drives the machine")
        with pytest.raises(StateBusyError):
            StateHold(st, S)
        ok(run_cli("where", "--state", st))  # reading is never refused
    finally:
        lock.release()
    assert MachineLock(st).holder() is None
    ok(run_cli("goto", "1,1,0", "--state", st))


BROKEN = [
    ("{not json", "not JSON"),
    ('{"cam_machine_state": 2}', "not a cam machine state file"),
    ("position_steps: [10001, 0, 0]", "position_steps is outside the X travel", "1 steps beyond"),
    ("position_steps: [0, 0, true]", "position_steps must be 3 whole numbers"),
    ("position_steps: [0.5, 0, 0]", "position_steps must be 3 whole numbers"),
    ("position_known: 1", "position_known must be true or false"),
    ('active_offset: "G60"', "active_offset must be one of"),
    ('offsets_steps: {"G99": [0, 0, 0]}', "unknown work offset"),
    ('offsets_steps: {"G55": [0, 0, 99999]}', "offsets_steps.G55 is outside the Z travel"),
    ('running: {"pid": -3, "command": "x", "since": "y"}', "running.pid"),
    ("tool: 7", "tool must be a line of text"),
    ("extra: 1", "unknown key 'extra'"),
]


@pytest.mark.parametrize("case", BROKEN, ids=[c[1] for c in BROKEN])
def test_a_broken_state_file_is_one_line_naming_it(case, tmp_path):
    st = tmp_path / "m.json"
    change, *fragments = case
    if change.startswith("{"):
        st.write_text(change)
    else:
        values = json.loads(MachineState().to_json())
        key, value = change.split(": ", 1)
        values[key] = json.loads(value)
        st.write_text(json.dumps(values))
    for argv in (["where"], ["goto", "1,1,0"], ["zero"]):
        one_line_error(run_cli(*argv, "--state", st), f"machine state file {st} is broken", *fragments)
    with pytest.raises(StateError):
        parse_state(st.read_text(), S, st)


def test_state_file_round_trip_and_its_frames():
    s = MachineState(position_steps=(10, 20, 3)).with_offset("G55", (4, 5, 1))
    s = MachineState(**{**vars(s), "active_offset": "G55"})
    assert parse_state(s.to_json(), S, "x") == s
    assert s.to_work((10, 20, 3)) == (6, 15, 2) and s.to_machine((6, 15, 2)) == (10, 20, 3)
    assert s.to_work((10, 20, 3), "G54") == (10, 20, 3) and set(s.offsets_steps) == set(OFFSET_NAMES)
    lost = s.lost("an emergency stop")
    assert not lost.position_known and not lost.homed and lost.position_steps == (10, 20, 3)
    assert "(an emergency stop)" in unknown_message(lost) and "cam where --set X,Y,Z" in unknown_message(lost)
    assert lost.moved_to((1, 2, 3)).position_known and lost.moved_to((1, 2, 3)).unknown_reason == ""


def test_where_prints_both_frames_and_json(tmp_path):
    st = tmp_path / "m.json"
    ok(run_cli("goto", "200,100,10", "--unit", "steps", "--state", st))
    ok(run_cli("zero", "XY", "--state", st))
    ok(run_cli("jog", "X+", "20", "--state", st))
    rep = json.loads(ok(run_cli("where", "--json", "--state", st)).stdout)
    assert rep["machine_steps"] == [220, 100, 10] and rep["work_steps"] == [20, 0, 10]
    assert rep["machine_mm"] == [pytest.approx(6.358), pytest.approx(2.89), pytest.approx(0.157)]
    assert rep["active_offset"] == "G54" and rep["offsets_steps"]["G54"] == [200, 100, 0]
    assert rep["position_known"] is True and rep["homed"] is False and rep["state_file"] == str(st)
    text = ok(run_cli("where", "--state", st)).stdout
    assert "machine: X=6.358 Y=2.89 Z=0.157 mm (X=220 Y=100 Z=10 steps)" in text
    assert "work G54: " in text and "(X=20 Y=0 Z=10 steps)" in text and "position known; not homed" in text
    assert "work zeros (machine steps): G54 X=200 Y=100 Z=0" in text
    for command in ("where", "zero", "goto", "jog", "drill"):
        assert "--state" in ok(run_cli(command, "--help")).stdout
    one_line_error(run_cli("where", "--set", "1,2"), "--set")
    one_line_error(run_cli("where", "--use", "G53"), "--use")


# -- real processes: SIGTERM and SIGKILL during a long job, and one command refused meanwhile -------------------

def _long_job(st: Path, pins: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "cam", "drill", str(SAMPLES / "ellipse.png"), "--depth", "2",
                             "--realtime", "--progress", "--state", str(st), "--pin-log", str(pins)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)


@pytest.mark.realtime
def test_sigterm_during_a_job_records_where_it_stopped_and_a_second_command_is_refused(tmp_path):
    st, pins = tmp_path / "m.json", tmp_path / "p.csv"
    ok(run_cli("goto", "10,20,0", "--state", st))
    ok(run_cli("zero", "--state", st))  # the job is cut here
    proc = _long_job(st, pins)
    try:
        wait_for_progress(proc, 3)
        running = state_of(st).running
        assert running is not None and running.pid == proc.pid and "drill" in running.command
        one_line_error(run_cli("goto", "0,0,0", "--state", st), f"pid {proc.pid}", "drives the machine")
        where = ok(run_cli("where", "--state", st)).stdout
        assert f"driven now by pid {proc.pid}" in where
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 130
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    wait_for_progress.reader.join(10)
    s = state_of(st)
    end = tuple(a + b for a, b in zip((80, 160, 0), moved_by(pins)))
    assert s.running is None and s.position_known and s.position_steps == end != (80, 160, 0)
    assert end[2] <= 0  # the stop lifted the tool
    ok(run_cli("goto", "0,0,0", "--state", st, "--pin-log", tmp_path / "back.csv"))
    assert moved_by(tmp_path / "back.csv") == tuple(a - b for a, b in zip((80, 160, 0), end))


@pytest.mark.realtime
def test_sigkill_during_a_job_leaves_the_position_unknown(tmp_path):
    st, pins = tmp_path / "m.json", tmp_path / "p.csv"
    proc = _long_job(st, pins)
    try:
        wait_for_progress(proc, 3)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    wait_for_progress.reader.join(10)
    deadline = time.monotonic() + 10
    while MachineLock(st).holder() is not None and time.monotonic() < deadline:  # the kernel let the lock go
        time.sleep(0.05)
    one_line_error(run_cli("goto", "0,0,0", "--state", st), "position is unknown", f"pid {proc.pid}",
                   "cam where --set")
    rep = json.loads(ok(run_cli("where", "--json", "--state", st)).stdout)
    assert rep["position_known"] is False and f"pid {proc.pid}" in rep["unknown_reason"]
    ok(run_cli("where", "--set", "0,0,0", "--state", st))
    ok(run_cli("goto", "1,1,0", "--state", st))
    assert state_of(st).position_steps == (8, 8, 0)


@pytest.mark.realtime
def test_sigterm_on_the_way_to_the_work_zero_records_where_the_tool_stopped(tmp_path):
    st, pins = tmp_path / "m.json", tmp_path / "p.csv"
    write_state(st, MachineState(position_steps=(5000, 0, 0)))  # 5000 steps from the work zero: about 25 s
    proc = subprocess.Popen([sys.executable, "-m", "cam", "drill", str(SAMPLES / "board.drl"), "--yes", "--realtime",
                             "--state", str(st), "--pin-log", str(pins)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    try:
        deadline = time.monotonic() + 60
        while state_of(st).running is None:  # it drives the machine now
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.05)
        time.sleep(3)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    assert proc.returncode == 130, err
    assert b"going to the work zero first" in err and b"job finished" not in out
    s = state_of(st)
    assert s.position_known and s.running is None and 0 < s.position_steps[0] < 5000 and s.position_steps[1:] == (0, 0)
    # the pin log holds what the command did: the travel it stopped, and no job (the job itself never started)
    assert [part.name for part in read_pin_log(pins).parts] == ["travel"]
