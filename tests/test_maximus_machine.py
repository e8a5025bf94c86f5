"""The MAXIMUS board as a machine: the session (CLI, web page, API) against the emulated firmware, checked on the
emulator's decoded port log and its hole log.  The emulator runs as fast as it can here; real speed is in
test_maximus_realtime.py."""
from __future__ import annotations

import json

import numpy as np
import pytest

from cam.cli import main  # noqa: E402
from cam.drive.maximus.board import MAXIMUS_SETTINGS  # noqa: E402
from cam.drive.maximus.packets import drill_packet, drill_time_ns, init_packet, jog_packet, jog_time_ns  # noqa: E402
from cam.drive.session import MachineSession  # noqa: E402
from cam.errors import CapabilityError, PlanError  # noqa: E402
from cam.sim.maximus import MODE_SELECTION  # noqa: E402
from support.maximus_log import decode_port_log, hole_strokes  # noqa: E402

from conftest import SAMPLES  # noqa: E402

MM = MAXIMUS_SETTINGS.mm_per_step_xy  # 0.004375 mm per pulse (a half step)


def session_on(emu, settings=MAXIMUS_SETTINGS) -> MachineSession:
    return MachineSession(f"maximus:{emu.device_path}", settings)


def head_here_is(port: str, *more: str, steps=(0, 0, 0)) -> None:
    """Say where the head stands (machine ``steps``) with ``cam where --set``: the first command on a new
    machine, whose state file is missing (its position unknown on a real port: issue #43 point 5)."""
    from cam.drive.state import steps_to_mm
    mm = ",".join(f"{v:g}" for v in steps_to_mm(steps, MAXIMUS_SETTINGS))
    assert main(["where", "--set", mm, "--port", port, *more]) == 0


def run(session: MachineSession, call, *args) -> dict:
    call(*args)
    assert session.wait_idle(30)
    assert session.last_run["status"] == "finished", session.last_run
    return session.last_run


def head(emu) -> list[int]:
    """Where the head is, decoded from the port writes: x, y up, z height, pulses from power-up."""
    return decode_port_log(emu.port_log())[-1].tolist()


# ---------------------------------------------------------------------- deadlines come from the board's speed
def test_reply_times_are_the_firmware_pulse_rates():
    # seed 003: "Step frekansı = 1 / (2 * Delay * 100 us)": Delay 10 is 500 pulses a second
    assert jog_time_ns(jog_packet("x", 2000, delay=10)) == 4_000_000_000
    assert jog_time_ns(jog_packet("z", -500, delay=1)) == 100_000_000
    # a hole: the dog-leg XY move, then Z down and up by the stroke (both Init fields, 400 pulses)
    init = init_packet(400, 400, delay_x=10, delay_y=10, delay_z_up=10, delay_z_down=10)
    assert drill_time_ns(drill_packet(1000, -300), init) == (1000 + 800) * 2_000_000
    # a board that is much slower than its move is found soon after the move should have ended: see test_maximus


# ---------------------------------------------------------------------- directions and the origin
def test_session_jogs_move_the_head_the_way_the_step_dir_machine_does(emu):
    """cam's frame: +x right, +y toward the operator, +z down; the firmware's: Y up, Z height."""
    s = session_on(emu)
    start = head(emu)
    for axis, n, board_delta in (("x", 120, (120, 0, 0)), ("x", -20, (-20, 0, 0)), ("y", 50, (0, -50, 0)),
                                 ("y", -80, (0, 80, 0)), ("z", -100, (0, 0, 100)), ("z", 40, (0, 0, -40))):
        before = head(emu)
        run(s, s.jog, axis, n)
        assert [a - b for a, b in zip(head(emu), before)] == list(board_delta), (axis, n)
    assert s.position_steps() == (100, -30, -60)
    assert [a - b for a, b in zip(head(emu), start)] == [100, 30, 60]
    assert emu.wait_for_state(MODE_SELECTION)


def test_jog_units_are_the_jog_screens(emu):
    s = session_on(emu)
    run(s, s.jog, "x", 1, "mm")  # 1 mm / 4.375 um
    run(s, s.jog, "y", -2, "0.1mm")
    run(s, s.jog, "z", -1, "0.1in")  # 2.54 mm up
    run(s, s.jog, "x", 3, "full-steps")  # half-step mode: 2 pulses a full step
    assert s.position_steps() == (229 + 6, -46, -581)
    assert head(emu) == [235, 46, 581]
    with pytest.raises(PlanError, match="unit"):
        s.jog("x", 1, "furlong")
    with pytest.raises(PlanError, match="whole"):
        s.jog("x", 1.5, "steps")


def xy_moves_at(emu, first_row: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions after each write from ``first_row`` and the rows where X or Y moved."""
    pos = decode_port_log(emu.port_log())[first_row:]
    moved = np.flatnonzero(np.any(pos[1:, :2] != pos[:-1, :2], axis=1)) + 1
    return pos, moved


@pytest.mark.parametrize("z", [200, -150])
def test_origin_goes_up_first_then_xy_in_one_move_then_down(emu, z):
    """From a lowered head (z > 0) the origin lifts first; from above (z < 0) it travels, then lowers."""
    s = session_on(emu)
    run(s, s.jog, "x", 500)
    run(s, s.jog, "y", 300)
    run(s, s.jog, "z", z)
    at = head(emu)
    assert at[:2] == [500, -300] and at[2] == -z
    n0 = len(emu.port_log())
    run(s, s.go_to_origin)
    pos, moved = xy_moves_at(emu, n0 - 1)
    assert pos[-1].tolist() == [0, 0, 0] and s.position_steps() == (0, 0, 0)
    travel_z = max(-z, 0)  # the head travels at the origin's height or above it
    assert (pos[moved, 2] == travel_z).all()  # X and Y move only with the head up
    first, last = moved[0], moved[-1]
    assert (pos[:first, 2] == np.sort(pos[:first, 2])).all()  # before: Z only goes up
    assert (pos[last:, 2] == np.sort(pos[last:, 2])[::-1]).all()  # after: Z only goes down
    # one XY move, never a sum of increments: X and Y step together (the firmware's dog-leg), each
    # monotonic, straight to the origin
    xs, ys = pos[first - 1:last + 1, 0], pos[first - 1:last + 1, 1]
    assert (np.diff(xs) <= 0).all() and (np.diff(ys) >= 0).all()
    k = int(np.flatnonzero(ys == 0)[0])
    assert xs[k] == 200  # Y's 300 pulses went together with X's first 300; X then went on alone
    assert emu.wait_for_state(MODE_SELECTION)


def test_set_offset_makes_this_the_origin(emu):
    s = session_on(emu)
    run(s, s.jog, "x", 70)
    run(s, s.jog, "z", -30)
    s.set_offset()
    assert s.position_steps() == (0, 0, 0)
    run(s, s.jog, "x", 5)
    run(s, s.go_to_origin)
    assert head(emu) == [70, 0, 30]


def test_the_web_page_jogs_and_goes_to_the_origin_on_the_board(tmp_path, emu):
    from test_web import Server

    s = Server(tmp_path, settings=MAXIMUS_SETTINGS, machine_port=f"maximus:{emu.device_path}", realtime=True)
    try:
        for body, expected in (({"axis": "z", "steps": -10}, [0, 0, 10]),  # "Z− up" lifts the head
                               ({"axis": "y", "steps": 10}, [0, -10, 10]),  # "Y+" toward the operator
                               ({"axis": "x", "steps": 1, "unit": "mm"}, [229, -10, 10]),
                               ({"axis": "z", "steps": 30}, [229, -10, -20])):  # "Z+ down"
            status, r = s.call("POST", "/api/jog", body)
            assert status == 200, r
            s.wait_idle(20)
            assert head(emu) == expected, body
        n0 = len(emu.port_log())
        assert s.call("POST", "/api/origin", {})[0] == 200
        st = s.wait_idle(20)
        assert st["position_steps"] == [0, 0, 0] and head(emu) == [0, 0, 0]
        pos, moved = xy_moves_at(emu, n0 - 1)
        assert (pos[moved, 2] == 0).all() and pos[:moved[0], 2].max() == 0  # lifted to 0 first, no lower
        # Set Offset and Z Drill Up / Down from the page
        assert s.call("POST", "/api/jog", {"axis": "z", "steps": 40})[0] == 200
        s.wait_idle(20)
        assert s.call("POST", "/api/drill-z", {"which": "up"})[0] == 200
        assert s.call("POST", "/api/jog", {"axis": "z", "steps": 60})[0] == 200
        s.wait_idle(20)
        assert s.call("POST", "/api/drill-z", {"which": "down"})[0] == 200
        assert s.call("POST", "/api/drill-z", {"which": "sideways"})[0] == 400
        m = s.session.settings.maximus
        assert (m.drill_z_up_steps, m.drill_z_down_steps) == (40, 100)
        assert s.call("POST", "/api/offset", {})[0] == 200
        assert s.session.state()["position_steps"] == [0, 0, 0]
    finally:
        s.close()


def test_z_drill_up_and_down_set_by_jogging_drive_the_drill_stroke(emu, tmp_path):
    board = tmp_path / "two.drl"
    board.write_text("M48\nMETRIC\nT1C0.800\n%\nT1\nX1.0Y1.0\nX1.5Y1.0\nM30\n")
    from cam.kinds.jobs import JobOptions, prepare_job

    s = session_on(emu)
    run(s, s.jog, "z", 300)  # down 300 below the origin: where the head travels between holes
    s.set_drill_z("up")
    run(s, s.jog, "z", 120)
    s.set_drill_z("down")
    run(s, s.jog, "z", -200)
    with pytest.raises(PlanError, match="below Z Drill Up"):
        s.set_drill_z("down")  # 220 is above Z Drill Up (300)
    run(s, s.go_to_origin)
    start = head(emu)
    n0 = len(emu.port_log())
    job = prepare_job(board, JobOptions(), s.settings)
    s.on_prompt = lambda prompt: "continue"
    run(s, s.start, job)
    log = emu.port_log()
    strokes = hole_strokes(list(log)[n0 - 1:])
    # the first hole lies under the start (the board's top-left corner): its descent begins at the start
    assert strokes[1:, 2].tolist() == [-300] and (strokes[:, 3] == -420).all()  # Z up, Z down below the start
    assert [r[3] for r in emu.hole_log()] == [start[2] - 420] * 2
    assert head(emu) == start
    with pytest.raises(CapabilityError):
        MachineSession("mock", MAXIMUS_SETTINGS).set_drill_z("up")


# ---------------------------------------------------------------------- the command line
def small_board(tmp_path, lines: list[str], name: str = "small.drl"):
    path = tmp_path / name
    path.write_text("\n".join(["M48", "METRIC", "T1C1.000", "T2C0.800", "%", *lines, "M30"]) + "\n")
    return path


def test_offset_0_0_drills_from_the_board_origin_as_the_pc_program(emu, tmp_path, capsys):
    """Holes measured from the origin set by jogging (Y up from it, as the firmware counts): all inside."""
    path = small_board(tmp_path, ["T1", "X2.0Y1.0", "X2.5Y1.5", "T2", "X3.0Y1.0"])
    head_here_is(f"maximus:{emu.device_path}")
    code = main(["drill", str(path), "--yes", "--offset", "0,0", "--port", f"maximus:{emu.device_path}",
                 "--travel-height", "0.2", "--cut-depth", "0.3"])
    assert code == 0, capsys.readouterr().err
    rows = emu.hole_log()
    expected = {(2.0, 1.0), (2.5, 1.5), (3.0, 1.0)}
    got = {(round(r[1] * MM, 3), round(r[2] * MM, 3)) for r in rows}
    assert len(rows) == 3 and all(min(abs(gx - x) + abs(gy - y) for x, y in expected) <= 2 * MM for gx, gy in got)
    assert head(emu) == [0, 0, 0]


def test_drill_order_file_keeps_the_files_order_of_tools(emu, tmp_path, capsys):
    path = small_board(tmp_path, ["T2", "X1.0Y1.0", "X2.0Y1.0", "T1", "X1.5Y1.0", "T2", "X3.0Y1.0"])
    head_here_is(f"maximus:{emu.device_path}")
    code = main(["drill", str(path), "--yes", "--drill-order", "file", "--offset", "0,0",
                 "--port", f"maximus:{emu.device_path}", "--travel-height", "0.1", "--cut-depth", "0.1"])
    err = capsys.readouterr().err
    assert code == 0, err
    prompts = [line.split(":")[1].split()[0] for line in err.splitlines() if line.startswith("tool change")]
    assert prompts == ["T2", "T1", "T2"]  # T2 (smaller) stays before T1 and comes back
    xs = [round(r[1] * MM, 2) for r in emu.hole_log()]
    assert xs == [1.0, 2.0, 1.5, 3.0]
    assert "drilling hole 4 of 4" in err


def test_preview_report_and_delay_on_the_board(emu, tmp_path, capsys):
    path = small_board(tmp_path, ["T1", "X1.0Y1.0", "X1.2Y1.0", "T2", "X1.4Y1.2"])
    preview, report = tmp_path / "p.png", tmp_path / "r.json"
    head_here_is(f"maximus:{emu.device_path}")
    code = main(["drill", str(path), "--yes", "--port", f"maximus:{emu.device_path}", "--preview", str(preview),
                 "--report", str(report), "--delay", "0.4,1.0", "--spindle", "off"])
    assert code == 0, capsys.readouterr().err
    assert preview.stat().st_size > 1000 and preview.read_bytes()[:4] == b"\x89PNG"
    rep = json.loads(report.read_text())
    assert rep["status"] == "finished" and rep["holes"] == 3
    assert rep["board"]["delays"] == {"x": 2, "y": 2, "z_up": 5, "z_down": 5}
    assert rep["board"]["spindle"] is False
    # --delay 0.4,1.0 ms per pulse is Delay 2 for X and Y, 5 for Z, in every packet the board read
    packets = emu.packet_log()
    assert all(p[3] in (2, 5) for kind, p in packets if kind == "jog" and p[0] >> 6)
    assert {p[5:9] for kind, p in packets if kind == "init"} == {bytes([2, 2, 5, 5])}
    assert {r[4] for r in emu.hole_log()} == {0}  # --spindle off: a dry run


def test_pin_log_on_the_board_is_refused_before_anything_is_sent(emu, tmp_path, capsys):
    before = len(emu.rx_log())
    code = main(["drill", str(SAMPLES / "board.drl"), "--yes", "--port", f"maximus:{emu.device_path}",
                 "--pin-log", str(tmp_path / "p.csv")])
    assert code == 2 and "pin log" in capsys.readouterr().err
    assert len(emu.rx_log()) == before and not (tmp_path / "p.csv").exists()


@pytest.mark.slow
def test_emulator_log_file_from_the_command_line(tmp_path, monkeypatch):
    import subprocess
    import sys

    log = tmp_path / "holes.csv"
    proc = subprocess.Popen([sys.executable, "-m", "cam", "emulate-maximus", "--speed", "1000", "--log", str(log)],
                            stdout=subprocess.PIPE, text=True)
    try:
        device = proc.stdout.readline().strip()
        # an emulator 1000 times faster than the firmware answers sooner than a board could: the host is told
        monkeypatch.setenv("CAM_MAXIMUS_EMULATOR_SPEEDS", f"{device}=1000")
        path = small_board(tmp_path, ["T1", "X1.0Y1.0", "X1.5Y1.0"])
        assert main(["where", "--set", "0,0,0", "--port", f"maximus:{device}"]) == 0  # a new machine (#43 point 5)
        assert main(["drill", str(path), "--yes", "--offset", "0,0", "--port", f"maximus:{device}",
                     "--travel-height", "0.1", "--cut-depth", "0.2"]) == 0  # each hole logged before its reply
    finally:
        proc.terminate()
        proc.wait(10)
    lines = log.read_text().splitlines()
    assert lines[0] == "hole,x_halfsteps,y_halfsteps,z_bottom_halfsteps,spindle"
    rows = [line.split(",", 1) for line in lines[1:]]
    assert [r[0] for r in rows] == ["1", "2"]  # numbered as drilled
    # the tour's order is its own (a closed tour back home: either order is as short here)
    assert sorted(r[1] for r in rows) == ["229,229,-69,1", "343,229,-69,1"]


def test_goto_and_jog_from_the_command_line(emu, tmp_path, capsys):
    """Go To travels at Z = 0 with X and Y in one move, then moves Z; jog takes the Jog screen's units; --port
    maximus opens the machine file's serial port."""
    port = f"maximus:{emu.device_path}"
    head_here_is(port)
    assert main(["goto", "40,25,3", "--port", port]) == 0, capsys.readouterr().err  # pixels: 8 steps XY, 1 Z
    pos, moved = xy_moves_at(emu, 0)
    assert pos[-1].tolist() == [320, -200, -3]  # Y toward the operator is the board's -Y; Z +3 is down
    assert (pos[moved, 2] == 0).all() and pos[moved[-1]:, 2].min() == -3
    ys = pos[moved[0] - 1:moved[-1] + 1, 1]
    assert pos[moved[0] - 1 + int(np.flatnonzero(ys == -200)[0]), 0] == 200  # together, then X alone
    machine = tmp_path / "m.toml"
    machine.write_text(f'[maximus]\nserial_port = "{emu.device_path}"\n')
    # "maximus" is another port name, whose state file is its own: say where the head is there too
    head_here_is("maximus", "--machine", str(machine), steps=(320, 200, 3))
    assert main(["jog", "--port", "maximus", "--machine", str(machine), "Y-", "0.5", "--unit", "mm"]) == 0
    assert head(emu) == [320, -200 + 114, -3]
    # without --machine: the machine file the port's state file records (issue #43 point 5), so its serial_port
    assert main(["jog", "--port", "maximus", "Y-", "1"]) == 0
    assert head(emu) == [320, -200 + 115, -3]
    capsys.readouterr()
    assert main(["jog", "--port", "maximus", "--state", str(tmp_path / "new.json"), "Y-", "1"]) == 2  # none recorded
    assert "serial_port" in capsys.readouterr().err
