"""MAXIMUS resumes (issue #32 point 8): a board job keeps a journal of the holes its board answered; `cam drill FILE
--port maximus:DEV --resume JOURNAL` lifts the head, travels to the first hole not drilled and goes on from there;
a journal of another file or options is refused in one line; hole numbers count from 1 in every message; `cam
emulate-maximus` has the simulator's limit-switch options.  The emulator's own hole log is the oracle: every hole
drilled exactly once.  Sped-up emulator here; the stop in the middle of a move at real speed at the end."""
from __future__ import annotations

import ctypes
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest
import serial

import cam.sim.maximus as maximus_sim
from cam.cli import main
from cam.drive.maximus.switch_options import MAXIMUS_SWITCHES
from cam.drive.journal import read_journal
from cam.drive.maximus.board import MAXIMUS_SETTINGS, MaximusBoard, maximus_holes
from cam.drive.maximus.packets import drill_moves, jog_packet
from cam.drive.maximus.resume import resumed_arguments
from cam.drive.session import MachineSession
from cam.errors import PlanError, PortError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.drive.maximus.protocol import (
    EMERGENCYSTOP, ISMACHINEREADY, JOGMODEON, LIMIT_SWITCH_X, LIMIT_SWITCH_Y, MACHINEREADY, MACHINESTOPPED, OPENJOGMODE,
)
from cam.sim._maximus_line import LineReader
from cam.sim.maximus import start_emulator
from conftest import run_cli
from support.maximus_host import GUARD_MARGIN_S, guard_machine_file
from support.maximus_log import decode_port_log

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ["--travel-height", "0.1", "--cut-depth", "0.2"]
OPTIONS = JobOptions(travel_height_mm=0.1, cut_depth_mm=0.2)
# two tools, holes 2 mm apart (457 pulses, 0.9 s at the default Delay 10): a stop lands in a move
HOLES = ["T1", "X1.0Y-1.0", "X3.0Y-1.0", "X5.0Y-1.0", "T2", "X5.0Y-3.0", "X3.0Y-3.0", "X1.0Y-3.0"]


def write_board(tmp_path: Path, holes=HOLES, name: str = "board.drl") -> Path:
    path = tmp_path / name
    path.write_text("M48\nMETRIC,TZ\nT1C0.8\nT2C1.0\n%\n" + "\n".join(holes) + "\nM30\n")
    return path


def planned_holes(path: Path) -> np.ndarray:
    """The board-frame pulses (from the job's home: the power-up position here) of every hole, drilling order."""
    return maximus_holes(prepare_job(path, OPTIONS, MAXIMUS_SETTINGS).drill_plan.holes_steps)


def assert_each_hole_once(emu, expected: np.ndarray, tolerance_pulses: int = 0) -> None:
    rows = emu.hole_log()
    got = np.array([(r[1], r[2]) for r in rows], np.int64).reshape(-1, 2)
    assert len(got) == len(expected), rows
    d = np.abs(got[:, None, :] - expected[None, :, :]).max(axis=2)
    assert sorted(d.argmin(axis=1).tolist()) == list(range(len(expected))), ("every hole exactly once", rows)
    assert d.min(axis=1).max() <= tolerance_pulses, rows
    assert all(r[4] == 1 for r in rows), "the spindle runs in every hole"


def stop_at_second_tool_change(emu, path: Path, journal: Path) -> list[str]:
    """Drill ``path`` on the board and answer the second tool-change prompt with stop; returns the details."""
    job = prepare_job(path, OPTIONS, MAXIMUS_SETTINGS)
    answers = iter(["continue", "stop"])
    ses = MachineSession(f"maximus:{emu.device_path}", MAXIMUS_SETTINGS, on_prompt=lambda prompt: next(answers))
    seen: list[str] = []
    ses.on_detail = seen.append
    ses.start(job, journal=str(journal))
    assert ses.wait_idle(60)
    assert ses.last_run["status"] == "emergency-stopped", ses.last_run
    return seen + ses.last_run["messages"]


# ---------------------------------------------------------------------- the journal, and resuming from it
def test_a_stopped_board_job_resumes_from_its_journal_and_drills_every_hole_once(emu, tmp_path):
    path, journal = write_board(tmp_path), tmp_path / "board.journal.json"
    seen = stop_at_second_tool_change(emu, path, journal)
    assert seen[-1].startswith("emergency stop before hole 4"), seen  # counted from 1, as the progress
    j = read_journal(journal)
    assert (j.holes_done, j.state, j.hole_order) == (3, "emergency-stopped", (0, 1, 2, 3, 4, 5))
    x, y, z = emu.position_pulses
    assert j.position_steps == (x, -y, -z)  # stopped between moves: where the board's replies put the head
    assert len(emu.hole_log()) == 3
    port = f"maximus:{emu.device_path}"
    out = run_cli("drill", path, "--port", port, "--resume", journal, "--yes", *FLAGS)
    assert out.returncode == 0, out.stderr
    assert "resuming at hole 4 of 6" in out.stderr and "drilling hole 4 of 6" in out.stderr
    assert "tool change: T2" in out.stderr  # the tool of the first hole left is asked for again
    assert_each_hole_once(emu, planned_holes(path))
    assert decode_port_log(emu.port_log())[-1].tolist() == [0, 0, 0], "back at the job's home, raised"
    j = read_journal(journal)
    assert (j.state, j.holes_done, j.resumed_at_move) == ("finished", 6, 3)
    again = run_cli("drill", path, "--port", port, "--resume", journal, "--yes", *FLAGS)
    assert again.returncode == 2 and "the job finished; there is nothing to resume" in again.stderr
    assert len(emu.hole_log()) == 6


def test_the_journal_is_written_after_each_hole_reply(emu, tmp_path):
    path, journal = write_board(tmp_path), tmp_path / "j.json"
    job = prepare_job(path, OPTIONS, MAXIMUS_SETTINGS)
    ses = MachineSession(f"maximus:{emu.device_path}", MAXIMUS_SETTINGS, on_prompt=lambda prompt: "continue")
    journals = []
    ses.on_detail = lambda text: journals.append(json.loads(journal.read_text()))  # as each hole's packet goes
    ses.start(job, journal=str(journal))
    assert ses.wait_idle(60) and ses.last_run["status"] == "finished", ses.last_run
    assert [j["holes_done"] for j in journals] == [0, 1, 2, 3, 4, 5]
    assert all(j["state"] == "running" for j in journals)
    holes = planned_holes(path)
    for j, (bx, by) in zip(journals[1:], holes):  # after each reply: the head above the hole just drilled
        assert j["position_steps"] == [int(bx), int(-by), 0]
    assert json.loads(journal.read_text())["state"] == "finished"


def test_a_journal_of_another_file_or_options_is_refused_in_one_line(emu, tmp_path):
    path, journal = write_board(tmp_path), tmp_path / "j.json"
    stop_at_second_tool_change(emu, path, journal)
    sent = len(emu.packet_log())
    port = f"maximus:{emu.device_path}"
    other = write_board(tmp_path, HOLES[:-1] + ["X1.0Y-3.5"], name="other.drl")
    cases = [
        ([other, *FLAGS], "was written for another input or options"),
        ([path, "--travel-height", "0.1", "--cut-depth", "0.3"], "was written for another input or options"),
        ([path, "--drill-order", "file", *FLAGS], "was written for another input or options"),
    ]
    step_journal = tmp_path / "step.json"
    assert run_cli("drill", path, "--journal", step_journal, "--yes", *FLAGS).returncode == 0  # the mock
    cases.append(([path, *FLAGS], "is a step/dir job's journal, not a MAXIMUS board job's"))
    for argv, why in cases:
        used = step_journal if "step/dir" in why else journal
        out = run_cli("drill", *argv, "--port", port, "--resume", used, "--yes")
        assert out.returncode == 2, (argv, out.stderr)
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1 and why in lines[0] and str(used) in lines[0], (argv, out.stderr)
    assert len(emu.packet_log()) == sent, "nothing was sent to the board"
    on_the_mock = run_cli("drill", path, "--resume", journal, "--yes", *FLAGS)  # the board's journal, a step/dir run
    assert on_the_mock.returncode == 2 and "is a MAXIMUS board job's journal" in on_the_mock.stderr, on_the_mock.stderr
    assert len(on_the_mock.stderr.strip().splitlines()) == 1
    assert read_journal(journal).holes_done == 3, "a refused resume leaves the journal as it was"


# ---------------------------------------------------------------------- hole numbers count from 1
def test_hole_numbers_count_from_1_in_every_message(emu, tmp_path):
    path = write_board(tmp_path)
    job = prepare_job(path, OPTIONS, MAXIMUS_SETTINGS)
    ses = MachineSession(f"maximus:{emu.device_path}", MAXIMUS_SETTINGS, on_prompt=lambda prompt: "continue")
    seen: list[str] = []
    ses.on_detail = seen.append
    emu.trip_limit_switch(LIMIT_SWITCH_X, skip_moves=4)  # the spindle's jog, the offset move, holes 1 and 2
    ses.run(job)
    assert seen[-1] == "drilling hole 3 of 6", seen
    error = ses.last_run["messages"][0]
    assert "tripped during hole 3;" in error and "index" not in error, error  # the hole the progress named
    assert len(emu.hole_log()) == 2


def test_a_board_job_numbers_its_holes_from_first_number(emu):
    board = MaximusBoard(emu.device_path, MAXIMUS_SETTINGS.maximus, timeout_s=GUARD_MARGIN_S)
    try:
        emu.trip_limit_switch(LIMIT_SWITCH_Y, skip_moves=3)  # spindle, offset, the first hole: the second one
        with pytest.raises(PortError, match=r"tripped during hole 12;"):
            board.drill(np.array([[0, 10], [0, 20], [0, 30]]), z_down_steps=5, first_number=11)
    finally:
        board.close()
    with pytest.raises(PlanError, match="the move to hole 2 is longer than 65535 pulses"):
        drill_moves(np.array([[0, 0], [70000, 0]]))


def test_resumed_arguments_carry_the_tool_and_start_where_the_head_stands():
    args = {"holes_steps": np.array([[0, 0], [100, 0], [200, 0], [200, -50]]),
            "tool_changes": [(0, "T1"), (3, "T2")], "z_up_steps": 0, "z_down_steps": 9, "spindle": True}
    run, lift = resumed_arguments(args, 2, (150, 7, 4))
    assert run["holes_steps"].tolist() == [[200, 0], [200, -50]]
    assert run["tool_changes"] == [(0, "T1"), (1, "T2")]  # the tool of hole 3 asked for again
    assert (run["start_steps"], run["first_number"], lift) == ((150, -7), 3, 4)  # board frame: y up, z height
    run, lift = resumed_arguments(args, 3, (200, 0, 0))
    assert run["tool_changes"] == [(0, "T2")] and lift == 0
    run, _ = resumed_arguments(args, 0, (0, 0, 0))
    assert run["tool_changes"] == args["tool_changes"] and run["first_number"] == 1


# ---------------------------------------------------------------------- the emulator's limit switches
def test_emulate_maximus_has_the_simulators_limit_switch_options(monkeypatch, capsys):
    served = []
    monkeypatch.setattr(maximus_sim, "serve_until_stopped", lambda emulator: served.append(emulator) or 0)
    assert main(["emulate-maximus", "--speed", "1e6", "--travel-x", "-100", "150", "--travel-z", "-500", "20",
                 "--axis-delay", "3", "--trip", "limit-y@1"]) == 0
    emu = served[0]
    try:
        assert emu.device_path in capsys.readouterr().out
        assert emu._axis_delay == 3
        board = MaximusBoard(emu.device_path, MAXIMUS_SETTINGS.maximus, timeout_s=GUARD_MARGIN_S)
        try:
            board.jog("z", -10)  # the first move: --trip limit-y@1 lets it go by
            with pytest.raises(PortError, match="LIMIT_SWITCH_Y"):
                board.jog("x", 20)  # pressed in the second move
            with pytest.raises(PortError, match="LIMIT_SWITCH_X"):
                board.jog("x", 300)  # past --travel-x's HIGH end
        finally:
            board.close()
    finally:
        emu.stop()
    assert set(maximus_sim.SWITCH_OPTIONS) == set(MAXIMUS_SWITCHES)  # every switch of the firmware, by name
    for bad in (["--travel-y", "5", "1"], ["--trip", "limit-w"], ["--trip", "home-z@x"], ["--axis-delay", "256"]):
        out = run_cli("emulate-maximus", *bad)
        assert out.returncode == 2 and bad[0] in out.stderr, (bad, out.stderr)
    assert len(served) == 1, "a bad option serves nothing"


# ---------------------------------------------------------------------- at real speed: a stop in a move
def wait_for(predicate, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


@pytest.mark.realtime
def test_at_real_speed_ctrl_c_in_a_move_then_resume_drills_every_hole_once(tmp_path):
    emu = start_emulator(speed=1.0)
    try:
        path, journal = write_board(tmp_path), tmp_path / "board.journal.json"
        port = f"maximus:{emu.device_path}"
        machine = ["--machine", guard_machine_file(tmp_path)]  # the built-in machine, its replies' margin a guard
        assert main(["where", "--set", "0,0,0", "--port", port, *machine]) == 0  # a new machine (#43 point 5)
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        proc = subprocess.Popen([sys.executable, "-m", "cam", "drill", str(path), "--yes", "--port", port, *machine,
                                 "--journal", str(journal), *FLAGS], cwd=tmp_path, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        holes = planned_holes(path)
        # on the way from hole 2 to hole 3, a third of the way there
        wait_for(lambda: len(emu.hole_log()) == 2 and emu.position_pulses[0] > holes[1][0] + 150)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
        assert proc.returncode == 130, err
        assert "emergency stop during hole 3" in err and "MACHINESTOPPED" in err, err
        assert "drilling hole 3 of 6" in err and "index" not in err, err
        j = read_journal(journal)
        assert (j.holes_done, j.state) == (2, "emergency-stopped")
        x, y, z = emu.position_pulses
        assert holes[1][0] + 150 < x < holes[2][0] and z == 0
        # the host's estimate of where the stop left the head (the firmware does not say), a pulse the stop left half
        # made ended and booked (cam.sim.maximus point 14): within the emulator's resolution, a pulse, unless the
        # host says in its message that a busy computer made it less sure
        said = re.search(r"known within ±(\d+) pulses", err)
        bound = max(1, int(said.group(1)) if said else 0)
        assert np.abs(np.subtract(j.position_steps, (x, -y, -z))).max() <= bound, (j.position_steps, (x, y, z), err)
        assert [v for _, p, v in emu.port_log() if p == "D"][-1] & 0x02, "STEP_X is high again: no edge left over"
        code = main(["drill", str(path), "--yes", "--port", port, *machine, "--resume", str(journal), *FLAGS])
        assert code == 0
        # the holes after the stop are as far off as that estimate, no more
        assert_each_hole_once(emu, holes, tolerance_pulses=bound)
        assert read_journal(journal).state == "finished"
        pos = decode_port_log(emu.port_log())
        assert np.abs(pos[-1]).max() <= 2 and pos[-1][2] == 0, pos[-1]
        xy_moved = np.flatnonzero(np.any(pos[1:, :2] != pos[:-1, :2], axis=1)) + 1
        assert (pos[xy_moved, 2] >= 0).all(), "X and Y only move with the head at the start height"
    finally:
        emu.stop()
    assert emu.error is None, repr(emu.error)


@pytest.mark.realtime
def test_a_late_emulator_thread_still_stops_at_the_stop_bytes_arrival(monkeypatch):
    """The emulator plays a PIC, which takes a byte as it arrives: its thread, late on a busy computer (here on
    purpose: held 20 ms at the 50th pulse, the stop byte written 10 ms into that), catches up with the pulses
    due until the stop byte's arrival and stops there, neither where it happened to look nor later."""
    emu = start_emulator(speed=1.0)
    try:
        with serial.Serial(emu.device_path, 115200, timeout=GUARD_MARGIN_S) as line:
            line.write(bytes([ISMACHINEREADY]))
            assert line.read_until(bytes([MACHINEREADY])).endswith(bytes([MACHINEREADY]))
            line.write(bytes([OPENJOGMODE]))
            assert line.read(1) == bytes([JOGMODEON])
            stop: list[float] = []
            step = emu._after_step

            def late_step() -> None:
                step()
                if emu.position_pulses[0] == 50 and not stop:
                    time.sleep(0.010)  # the thread is late...
                    stop.append(time.monotonic())
                    os.write(line.fileno(), bytes([EMERGENCYSTOP]))  # ...as the stop byte arrives
                    stop.append(time.monotonic())
                    time.sleep(0.010)

            monkeypatch.setattr(emu, "_after_step", late_step)
            t0 = time.monotonic()
            line.write(jog_packet("x", 400, delay=10))  # 2 ms a pulse
            t1 = time.monotonic()
            assert line.read(1) == bytes([MACHINESTOPPED])
        earliest, latest = int((stop[0] - t1) / 0.002), int((stop[1] - t0) / 0.002)  # pulses due by its arrival
        x = emu.position_pulses[0]
        assert 55 <= x and earliest - 1 <= x <= latest + 1, (earliest, x, latest)
    finally:
        emu.stop()
    assert emu.error is None, repr(emu.error)


def hold_the_gil(us: int) -> None:
    """Keep this process busy ``us`` microseconds with the GIL held: libc's usleep called through ctypes.PyDLL,
    which does not release it, so no other thread of the process runs meanwhile (a deliberate lateness)."""
    ctypes.PyDLL(None).usleep(ctypes.c_uint(us))


@pytest.mark.realtime
def test_the_line_stamps_a_byte_as_it_arrives_while_the_emulators_process_holds_the_gil():
    """The emulator's line reader is a process of its own: a byte written while the emulator's process holds the
    GIL (50 ms here) is stamped as it arrived, not when a thread of that process could run again."""
    master, slave = os.openpty()
    tty.setraw(slave)
    reader = LineReader(master).start()
    try:
        assert reader.alive, "the reader process started"
        before = time.monotonic()
        os.write(slave, bytes([EMERGENCYSTOP]))
        hold_the_gil(50_000)
        held_until = time.monotonic()
        chunks = reader.collect()
        assert [data for _, data in chunks] == [bytes([EMERGENCYSTOP])]
        # stamped as it came, not when this process's threads could run again (a thread reader's stamp)
        assert before <= chunks[0][0] < held_until - 0.025, (chunks[0][0] - before, held_until - before)
        assert reader.collect() == [], "collected once"
    finally:
        reader.stop()
        os.close(master)
        os.close(slave)
    assert not reader.alive


@pytest.mark.realtime
def test_a_busy_emulator_process_still_stops_at_the_stop_bytes_arrival(monkeypatch):
    """As test_a_late_emulator_thread_still_stops_at_the_stop_bytes_arrival, but the emulator's whole process is
    busy as the stop byte arrives (the GIL held 20 ms at the 50th pulse, 10 pulses): its reader process stamps
    the byte as it comes, so the firmware stops there, not 10 pulses later when a thread of it could look."""
    emu = start_emulator(speed=1.0)
    try:
        with serial.Serial(emu.device_path, 115200, timeout=GUARD_MARGIN_S) as line:
            line.write(bytes([ISMACHINEREADY]))
            assert line.read_until(bytes([MACHINEREADY])).endswith(bytes([MACHINEREADY]))
            line.write(bytes([OPENJOGMODE]))
            assert line.read(1) == bytes([JOGMODEON])
            stop: list[float] = []
            step = emu._after_step

            def busy_step() -> None:
                step()
                if emu.position_pulses[0] == 50 and not stop:
                    stop.append(time.monotonic())
                    os.write(line.fileno(), bytes([EMERGENCYSTOP]))
                    stop.append(time.monotonic())
                    hold_the_gil(20_000)

            monkeypatch.setattr(emu, "_after_step", busy_step)
            t0 = time.monotonic()
            line.write(jog_packet("x", 400, delay=10))  # 2 ms a pulse
            t1 = time.monotonic()
            assert line.read(1) == bytes([MACHINESTOPPED])
        earliest, latest = int((stop[0] - t1) / 0.002), int((stop[1] - t0) / 0.002)  # pulses due by its arrival
        x = emu.position_pulses[0]
        assert 50 <= x <= 55 and earliest - 1 <= x <= latest + 1, (earliest, x, latest)
    finally:
        emu.stop()
    assert emu.error is None, repr(emu.error)


@pytest.mark.slow  # the page's server and its worker process: 3 s
def test_the_pages_resume_job_goes_on_from_the_next_hole(emu, tmp_path):
    from test_web import Server

    s = Server(tmp_path, settings=MAXIMUS_SETTINGS, machine_port=f"maximus:{emu.device_path}", realtime=True)
    try:
        status, r = s.upload("board.drl", write_board(tmp_path).read_bytes())
        assert status == 200, r
        options = {"travel_height_mm": "0.1", "cut_depth_mm": "0.2"}
        status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": options})
        assert status == 200, plan

        def run(answers: list[str]) -> dict:
            deadline = time.monotonic() + 60
            ids = set()
            while s.session.busy:
                assert time.monotonic() < deadline, "the job did not end"
                st = s.session.state()
                if st["prompt"] and st["prompt"]["id"] not in ids:  # an answered prompt shows until the job goes on
                    ids.add(st["prompt"]["id"])
                    action = answers.pop(0)
                    assert s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": action})[0] == 200
                time.sleep(0.01)
            return s.session.state()

        assert s.call("POST", "/api/start", {"job": plan["job"]})[0] == 200
        st = run(["continue", "stop"])  # stopped at the second tool change: three holes drilled
        assert st["last"]["status"] == "emergency-stopped" and len(emu.hole_log()) == 3, st["last"]
        assert st["last"]["journal"], "the page's Resume job button is enabled by the journal the run names"
        status, st = s.call("POST", "/api/resume-job", {})
        assert status == 200, st
        st = run(["continue", "continue"])
        assert st["last"]["status"] == "finished", st["last"]
        assert "drilling hole 4 of 6" in {e["text"] for e in st["log"]}
    finally:
        s.close()
    assert_each_hole_once(emu, planned_holes(write_board(tmp_path)))


@pytest.mark.realtime
def test_a_stopped_xy_move_books_how_far_its_time_took_the_head():
    emu = start_emulator(speed=1.0)  # the firmware's own timing: the move takes 1.2 s
    try:
        board = MaximusBoard(emu.device_path, MAXIMUS_SETTINGS.maximus, timeout_s=GUARD_MARGIN_S)
        try:
            def stop_in_the_move() -> None:
                wait_for(lambda: emu.position_pulses[0] > 150)  # a quarter of the way (the X-and-Y part: to 300)
                board.emergency_stop()

            wait = threading.Thread(target=stop_in_the_move)
            wait.start()
            with pytest.raises(PortError, match="MACHINESTOPPED") as info:
                board.move(600, -300, 0)  # both axes at once: a Drill Data Packet, its XY move a dog-leg
            wait.join()
            x, y, z = emu.position_pulses
            assert 100 < x < 600 and -300 < y < 0, (x, y)
            # within a pulse, or the bound the host states when a busy computer left it less sure
            said = re.search(r"known within ±(\d+) pulses", str(info.value))
            bound = max(1, int(said.group(1)) if said else 0)
            assert np.abs(np.subtract(board.position_pulses, (x, y, z))).max() <= bound, (board.position_pulses, x, y,
                                                                                          str(info.value))
        finally:
            board.close()
    finally:
        emu.stop()


def step_x_as_stopped(emu) -> int:
    """STEP_X (port D bit 1) as the last emergency stop cut the drivers (the write that took ENABLE_X low)."""
    level, enabled = None, True
    for _, port, value in emu.port_log():
        if port == "D":
            if enabled and not value & 0x08:
                level = (value >> 1) & 1
            enabled = bool(value & 0x08)
    assert level is not None, "no stop cut the drivers"
    return level


@pytest.mark.realtime
def test_a_stop_between_a_pulses_edges_is_booked_where_the_head_ends_up():
    """A stop between a pulse's falling and rising edge leaves STEP_X low, and the listing's next X move makes one
    rising edge more than it asks, in its own direction (cam.sim.maximus point 14): a head booked by the stopped
    move's time alone would stand a pulse off after that move.  The host ends that pulse at once, in the stopped
    move's direction (a Jog packet of no pulses), and books it: after the stop, and after the next X move, the
    host's position is the emulator's own count of the head's pulses, exactly."""
    emu = start_emulator(speed=1.0)
    half_s = 255 * 100e-6  # Delay 255: each half of a pulse lasts 25.5 ms, a pulse 51 ms
    try:
        board = MaximusBoard(emu.device_path, MAXIMUS_SETTINGS.maximus, timeout_s=GUARD_MARGIN_S)
        try:
            low = 0
            for attempt in range(10):
                start = emu.position_pulses[0]

                def stop_between_edges() -> None:
                    def pin_fell() -> bool:
                        log = emu.port_log()
                        d = log.value[log.port == ord("D")]
                        return emu.position_pulses[0] >= start + 3 and not d[-1] & 0x02

                    deadline = time.monotonic() + GUARD_MARGIN_S
                    while not pin_fell():  # looked at often: the aim below starts from when it is seen
                        assert time.monotonic() < deadline, "the jog did not begin"
                        time.sleep(0.001)
                    # aim at the middle of the low half that began as the pin fell (a busy computer may miss it:
                    # the stop then lands in the high half after it, which this loop checks too, and tries again)
                    time.sleep(half_s / 2)
                    board.emergency_stop()

                stopper = threading.Thread(target=stop_between_edges)
                stopper.start()
                with pytest.raises(PortError, match="MACHINESTOPPED"):
                    board.jog("x", 40, delay=255)
                stopper.join()
                low += step_x_as_stopped(emu) == 0
                assert emu.wait_until_idle()
                assert board.position_pulses == emu.position_pulses, (attempt, board.position_pulses)
                board.jog("x", -5)  # the next X move, the other way
                assert board.position_pulses == emu.position_pulses, (attempt, board.position_pulses)
                if low:
                    break
            assert low, "no stop came between a pulse's falling and rising edge"
        finally:
            board.close()
    finally:
        emu.stop()
    assert emu.error is None, repr(emu.error)


def test_a_drill_file_with_slots_is_refused_on_the_board_in_one_line(emu, tmp_path):
    """The firmware drills only: slots (or holes milled with --mill-holes-over) make a milling tool path, refused
    before anything is sent (it was a traceback)."""
    f = tmp_path / "slot.drl"
    f.write_text("M48\nMETRIC\nT1C1.0\n%\nT1\nX5.0Y5.0\nX10.0Y5.0G85X15.0Y5.0\nM30\n")
    r = run_cli("drill", f, "--port", f"maximus:{emu.device_path}", "--yes", "--state", tmp_path / "s.json")
    assert r.returncode == 2 and "drills holes only" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = run_cli("drill", f, "--port", f"maximus:{emu.device_path}", "--yes", "--state", tmp_path / "s.json",
                "--mill-holes-over", "0.5")
    assert r.returncode == 2 and "drills holes only" in r.stderr, r.stderr
