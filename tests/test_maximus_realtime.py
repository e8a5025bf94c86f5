"""The MAXIMUS board at the firmware's own speed (the emulator at --speed 1): replies that take longer than the
2 s a fixed timeout used to allow, a small two-tool board from the command line and from the web page, and
Ctrl-C.  Each test takes a few seconds of real time; none measures time except that the job must end."""
from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cam.cli import main  # noqa: E402
from cam.drive.maximus.board import MAXIMUS_SETTINGS  # noqa: E402
from cam.sim.maximus import MODE_SELECTION, start_emulator  # noqa: E402
from support.maximus_host import GUARD_MARGIN_S, guard_machine_file  # noqa: E402
from support.maximus_log import decode_port_log  # noqa: E402

MM = MAXIMUS_SETTINGS.mm_per_step_xy  # mm per half step (a clock pulse in half-step mode)
ROOT = Path(__file__).resolve().parents[1]

# Five holes, two tools, measured from the board origin (Y up, as the PC program counts): the first hole is
# 5 mm from the origin, a move of 1143 pulses, 2.3 s at the default Delay 10 (500 pulses a second).
HOLES_MM = {1: [(5.0, 0.3), (5.3, 0.3), (5.3, 0.6)], 2: [(5.6, 0.3), (5.6, 0.6)]}
TOOLS_MM = {1: 1.0, 2: 0.8}

pytestmark = pytest.mark.realtime  # the emulator at the firmware's own speed


def write_board(tmp_path: Path) -> Path:
    lines = ["M48", "METRIC", *(f"T{t}C{d:.3f}" for t, d in TOOLS_MM.items()), "%"]
    for t, holes in HOLES_MM.items():
        lines += [f"T{t}", *(f"X{x:.2f}Y{y:.2f}" for x, y in holes)]
    path = tmp_path / "small.drl"
    path.write_text("\n".join(lines + ["M30"]) + "\n")
    return path


def cli(*argv: str) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-m", "cam", *argv], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def assert_board_drilled(emu, travel_mm: float, cut_mm: float) -> None:
    """Every hole once, within one half step of the file's, to the same depth, spindle running; the head back
    at the origin at the start height (the travel height above the board: raised)."""
    rows = emu.hole_log()
    expected = np.array([xy for holes in HOLES_MM.values() for xy in holes]) / MM
    got = np.array([(r[1], r[2]) for r in rows], float)
    assert len(got) == len(expected)
    d = np.abs(got[:, None, :] - expected[None, :, :]).max(axis=2)
    assert sorted(d.argmin(axis=1).tolist()) == list(range(len(expected))), "every hole once"
    assert d.min(axis=1).max() <= 1.0, "a hole more than a half step off"
    depth = round(travel_mm / MM) + round(cut_mm / MM)
    assert [r[3] for r in rows] == [-depth] * len(rows)
    assert [r[4] for r in rows] == [1] * len(rows), "the spindle runs in every hole"
    pos = decode_port_log(emu.port_log())
    assert pos[-1].tolist() == [0, 0, 0], "back at the origin, Z raised to the start height"
    xy_moved = np.flatnonzero(np.any(pos[1:, :2] != pos[:-1, :2], axis=1)) + 1
    assert (pos[xy_moved, 2] >= 0).all(), "X and Y only move with the head at the start height or above"
    spindle = [(v >> 2) & 1 for _, port, v in emu.port_log() if port == "B"]
    assert spindle[-1] == 0, "the spindle is off at the end"


@pytest.fixture
def emu(tmp_path):
    e = start_emulator(speed=1.0, log_path=tmp_path / "holes.csv")  # the firmware's own timing
    yield e
    e.stop()
    assert e.error is None, repr(e.error)


def test_a_jog_whose_reply_takes_longer_than_2_s(emu, capsys):
    """Issue #14 reproduction 1: 1100 pulses at Delay 10 take 2.2 s; the reply deadline follows the move."""
    assert main(["where", "--set", "0,0,0", "--port", f"maximus:{emu.device_path}"]) == 0  # a new machine (#43)
    assert main(["jog", "--port", f"maximus:{emu.device_path}", "X+", "1100"]) == 0, capsys.readouterr().err
    assert decode_port_log(emu.port_log())[-1].tolist() == [1100, 0, 0]
    assert emu.wait_for_state(MODE_SELECTION)


def test_a_small_two_tool_board_from_the_command_line(emu, tmp_path):
    """The seed's workflow at real speed: holes measured from the origin (--offset 0,0), the first reply after
    2.3 s of XY move, tool prompts, the head back at the origin."""
    assert main(["where", "--set", "0,0,0", "--port", f"maximus:{emu.device_path}"]) == 0  # a new machine (#43)
    proc = cli("drill", str(write_board(tmp_path)), "--yes", "--offset", "0,0", "--port",
               f"maximus:{emu.device_path}", "--travel-height", "0.1", "--cut-depth", "0.2", "--delay", "2,0.4")
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "job finished: 5 holes" in out
    assert err.index("T2 0.800 mm") < err.index("T1 1.000 mm")  # the smaller tool first
    assert "drilling hole 5 of 5" in err
    assert_board_drilled(emu, 0.1, 0.2)
    lines = (tmp_path / "holes.csv").read_text().splitlines()  # the emulator's own record, as it drilled
    assert lines[0] == "hole,x_halfsteps,y_halfsteps,z_bottom_halfsteps,spindle" and len(lines) == 6


def test_a_small_two_tool_board_from_the_web_page(emu, tmp_path):
    from test_web import Server

    fast = dataclasses.replace(MAXIMUS_SETTINGS.maximus, delay_x=2, delay_y=2, delay_z_up=2, delay_z_down=2)
    s = Server(tmp_path, settings=MAXIMUS_SETTINGS.replace(maximus=fast), machine_port=f"maximus:{emu.device_path}",
               realtime=True)
    try:
        status, r = s.upload("small.drl", write_board(tmp_path).read_bytes())
        assert status == 200, r
        options = {"offset_mm": "0,0", "travel_height_mm": "0.1", "cut_depth_mm": "0.2"}
        status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": options})
        assert status == 200, plan
        assert s.call("POST", "/api/start", {"job": plan["job"]})[0] == 200
        answered, details, ids = [], set(), set()
        deadline = time.monotonic() + 60
        while s.session.busy:
            assert time.monotonic() < deadline, "the job did not end"
            st = s.session.state()
            details.add(st["detail"])
            if st["prompt"] and st["prompt"]["id"] not in ids:  # an answered prompt shows until the board goes on
                ids.add(st["prompt"]["id"])
                answered.append(st["prompt"]["note"].split(":")[1].split()[0])
                assert s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})[0] == 200
            time.sleep(0.01)
        st = s.session.state()
        assert st["last"]["status"] == "finished", st["last"]
        assert answered == ["T2", "T1"] and st["position_steps"] == [0, 0, 0]
        assert "drilling hole 5 of 5" in {e["text"] for e in st["log"]}
    finally:
        s.close()
    assert_board_drilled(emu, 0.1, 0.2)


def wait_for(condition, timeout_s: float = 30.0) -> None:
    """Wait for ``condition()`` (``timeout_s``: a failure guard)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


def test_ctrl_c_during_a_jog_stops_the_board_and_the_next_jog_works(emu, tmp_path, capsys):
    """Issue #14 reproduction 4 and issue #20: the stop byte, MACHINESTOPPED, exit 130 at once, board ready."""
    port = ["--port", f"maximus:{emu.device_path}", "--machine", guard_machine_file(tmp_path)]  # replies all come
    assert main(["where", "--set", "0,0,0", *port]) == 0  # a new machine (#43)
    proc = cli("jog", *port, "X+", "3000")  # 6 s at Delay 10
    wait_for(lambda: emu.position_pulses[0] > 100)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "MACHINESTOPPED" in err and "jog stopped: moved X=" in err
    x = emu.position_pulses[0]
    assert 100 < x < 3000 and emu.wait_for_state(MODE_SELECTION)
    assert 0x80 in [b for _, b, where in emu.rx_log() if where == "isr"]  # the firmware's stop byte
    # the stop left the position unknown (the machine state): the user says where the head is, then jogs
    assert main(["where", "--set", "0,0,0", *port]) == 0, capsys.readouterr().err
    assert main(["jog", *port, "X-", "50"]) == 0, capsys.readouterr().err
    # a stop between a pulse's falling and rising edge leaves STEP_X low, and the listing's next X move would make
    # one rising edge more than it asks (cam.sim.maximus point 14): the host ended that pulse as it stopped
    assert emu.position_pulses[0] == x - 50


def test_ctrl_c_during_a_drill_move_exits_130_at_once_with_the_spindle_off(emu, tmp_path, capsys):
    port = ["--port", f"maximus:{emu.device_path}", "--machine", guard_machine_file(tmp_path)]  # replies all come
    assert main(["where", "--set", "0,0,0", *port]) == 0  # a new machine (#43)
    proc = cli("drill", str(write_board(tmp_path)), "--yes", "--offset", "0,0", *port, "--travel-height", "0.1",
               "--cut-depth", "0.2")
    wait_for(lambda: emu.position_pulses[0] > 100, 20)  # on the way to the first hole, spindle running
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "MACHINESTOPPED" in err and "hole 1" in err
    spindle = [(v >> 2) & 1 for _, port, v in emu.port_log() if port == "B"]
    assert 1 in spindle and spindle[-1] == 0
    assert emu.wait_for_state(MODE_SELECTION) and emu.hole_log() == []
    assert main(["where", "--set", "0,0,0", *port]) == 0, capsys.readouterr().err
    assert main(["jog", *port, "Z-", "10"]) == 0, capsys.readouterr().err


def test_the_web_pages_stop_during_a_jog_stops_the_board_and_the_next_jog_works(emu, tmp_path):
    from test_web import Server

    guard = dataclasses.replace(MAXIMUS_SETTINGS.maximus, reply_margin_s=GUARD_MARGIN_S)  # its replies all come
    s = Server(tmp_path, settings=MAXIMUS_SETTINGS.replace(maximus=guard), machine_port=f"maximus:{emu.device_path}",
               realtime=True)
    try:
        assert s.call("POST", "/api/jog", {"axis": "x", "steps": 2000})[0] == 200  # 4 s at Delay 10
        wait_for(lambda: emu.position_pulses[0] > 50)
        assert s.call("POST", "/api/stop", {})[0] == 200
        st = s.wait_idle(20)
        assert "MACHINESTOPPED" in st["last"]["messages"][0], st["last"]
        x = emu.position_pulses[0]
        assert 50 < x < 2000 and emu.wait_for_state(MODE_SELECTION)
        assert s.call("POST", "/api/jog", {"axis": "z", "steps": -5})[0] == 200  # the board is ready
        st = s.wait_idle(20)
        assert st["last"]["status"] == "finished" and emu.position_pulses == (x, 0, 5)
    finally:
        s.close()
