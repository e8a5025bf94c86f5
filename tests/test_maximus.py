"""The MAXIMUS board: host (cam.drive.maximus) against the firmware emulator over a real pty and pyserial."""
from __future__ import annotations

import signal
import threading
import time

import numpy as np
import pytest
import serial

from cam.errors import PlanError, PortError  # noqa: E402
from cam.settings import Maximus  # noqa: E402
from cam.drive.maximus.board import (  # noqa: E402
    LinkFault, MaximusBoard, close_drill_packet, drill_moves, drill_packet, init_packet, jog_exit_packet, jog_packet,
    offset_packet, open_maximus, start_drill_packet,
)
from cam.drive.maximus._link import SLOWER_FACTOR  # noqa: E402
from cam.drive.maximus.packets import drill_time_ns, switch_time_ns  # noqa: E402
from cam.drive.maximus.protocol import (  # noqa: E402
    BANNER, HOME_SWITCH_Y, ONEHOLEDRILLED, PORT_B, PORT_D, STEPSBACKATLIMIT,
)
from cam.sim.maximus import (  # noqa: E402
    DRILL_MODE1_INPUT, JOG_DATA_INPUT, MODE_SELECTION, POWER_UP, PortLog, start_emulator,
)
from support.maximus_host import GUARD_MARGIN_S, record_reads, silent_read  # noqa: E402
from support.maximus_log import decode_port_log, drilled_holes, hole_strokes  # noqa: E402

# over 1.3 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_late_reply'}

TIMEOUT_S = GUARD_MARGIN_S  # the reply margin: a failure guard (every wait ends as its reply comes)
SILENT_MARGIN_S = 0.5  # the margin of the one exchange a test makes go unanswered: the host finds it that soon
HOLES = np.array([[10, 5], [40, 5], [40, 30], [100, -20], [0, 50], [-30, -10]])
FAST = Maximus(delay_x=1, delay_y=1, delay_z_up=1, delay_z_down=1)  # 5000 pulses/s on every axis


@pytest.fixture
def board(emu):
    b = MaximusBoard(emu.device_path, FAST, timeout_s=TIMEOUT_S)
    yield b
    b.close()


def raw_port(emu) -> "serial.Serial":
    """The emulator's line, as a host opens it; a read waits for its byte (the timeout is a failure guard)."""
    return serial.Serial(emu.device_path, 115200, timeout=TIMEOUT_S)


def no_answer(emu, ser: "serial.Serial") -> None:
    """The firmware read every byte sent and answered none: once it waits for the next byte (everything sent is
    acted on), nothing has come."""
    assert emu.wait_until_idle()
    ser.timeout = 0.05  # bytes written by now: only the pseudo-terminal's own delivery
    try:
        assert ser.read(1) == b""
    finally:
        ser.timeout = TIMEOUT_S


def hole_packets(emu) -> list[bytes]:
    """Drill Data Packets that move (CDF set, SDF clear) the firmware has read."""
    return [p for kind, p in emu.packet_log() if kind == "drill" and p[0] & 0xC0 == 0x80]


def spindle_at_writes(emu) -> np.ndarray:
    """RB2 (the spindle) after each port write."""
    level, out = 0, []
    for _, port, value in emu.port_log():
        if port == "B":
            level = (value >> 2) & 1
        out.append(level)
    return np.array(out)


def final_ports(emu) -> dict[int, int]:
    out = {}
    for _, port, value in emu.port_log():
        out[ord(port)] = value
    return out


# ---------------------------------------------------------------------- pure parts
def test_packet_bytes_are_the_listed_layouts():
    assert jog_packet("x", 300, delay=5) == bytes([0x50, 0x2C, 0x01, 5])
    assert jog_packet("y", -2, delay=7, half_step=True, spindle=True) == bytes([0xA1, 2, 0, 7])
    assert jog_packet("z", -1, delay=1) == bytes([0xD0, 1, 0, 1])  # z down: DIR_Z = 1
    assert jog_exit_packet() == bytes(4)
    assert offset_packet(-3, 4, -5, delay_x=1, delay_y=2, delay_z=3) == bytes([0x06, 3, 0, 4, 0, 5, 0, 1, 2, 3])
    assert init_packet(0x102, 7, delay_x=1, delay_y=2, delay_z_up=3, delay_z_down=4, half_step=True) == \
        bytes([0x07, 0x02, 0x01, 7, 0, 1, 2, 3, 4])
    assert drill_packet(-1, 65535) == bytes([0x82, 1, 0, 0xFF, 0xFF])
    assert start_drill_packet() == bytes([0xC0, 0, 0, 0, 0])
    assert close_drill_packet() == bytes(5)
    assert drill_moves(np.array([[5, 5], [5, 9]])).tolist() == [[5, 5], [0, 4]]
    with pytest.raises(PlanError):
        jog_packet("x", 70000)
    with pytest.raises(PlanError):
        jog_packet("q", 1)
    with pytest.raises(PlanError):
        drill_moves(np.array([[0, 0], [66000, 0]]))


def test_decoder_reads_a_hand_built_log():
    # X: one step +, one step -; Z: one step down; a step with ENABLE low does not count.
    rows = [
        (0, "B", 0xF0), (0, "D", 0xFF),
        (1, "D", 0xFD), (2, "D", 0xFF),                  # STEP_X low-high, DIR_X = 1: x + 1
        (3, "D", 0xFB), (4, "D", 0xF9), (5, "D", 0xFB),  # DIR_X = 0, pulse: x - 1
        (6, "B", 0xD0), (7, "B", 0xF0),                  # STEP_Z pulse, DIR_Z = 1: z - 1
        (8, "B", 0x70), (9, "B", 0x50), (10, "B", 0x70),  # ENABLE_Z low: no step
        (11, "B", 0x30), (12, "B", 0x10), (13, "B", 0xB0),  # DIR_Z = 0, enabled again: z + 1
    ]
    pos = decode_port_log(rows)
    assert pos.shape == (len(rows), 3)
    assert pos[:, 0].tolist() == [0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    assert pos[-1].tolist() == [0, 0, 0]
    assert pos[8].tolist() == [0, 0, -1] and pos[7].tolist() == [0, 0, 0]
    assert drilled_holes(rows) == [(0, 0)]
    assert hole_strokes(rows).tolist() == [[0, 0, 0, -1, 0]]
    log = PortLog.from_rows(rows)
    assert list(log)[1] == (0, "D", 0xFF) and len(log) == len(rows)


# ---------------------------------------------------------------------- firmware behaviour
def wait_for_power_ups(emu, n: int) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while emu.power_ups < n and time.monotonic() < deadline:
        time.sleep(0.002)
    assert emu.wait_for_state(POWER_UP)


def test_banner_and_handshake(emu):
    wait_for_power_ups(emu, 1)
    with raw_port(emu) as ser:
        ser.reset_input_buffer()
        emu.reset()  # power-up banner printed after the port is open
        assert ser.read(len(BANNER)) == BANNER == b"MAXIMUS_V1.0"
        wait_for_power_ups(emu, 2)
        ser.write(bytes([0x00, 0x63, 0x80]))  # anything but ISMACHINEREADY: no answer
        no_answer(emu, ser)
        assert emu.state == POWER_UP
        ser.write(b"\x61")
        assert ser.read(1) == b"\x62"
        assert emu.wait_for_state(MODE_SELECTION)
        ser.write(b"\x61")  # asked again at mode selection
        assert ser.read(1) == b"\x62"
        no_answer(emu, ser)
    board = MaximusBoard("maximus:" + emu.device_path, timeout_s=TIMEOUT_S, handshake=False)
    try:
        emu.reset()
        wait_for_power_ups(emu, 3)
        board.handshake()
        assert board.banner == "MAXIMUS_V1.0" and board.in_step
        assert emu.wait_for_state(MODE_SELECTION)
    finally:
        board.close()
    # the power-up port writes come first
    assert list(emu.port_log())[:2] == [(0, "B", 0xF0), (0, "D", 0xFF)]


def test_unknown_byte_at_mode_selection_falls_into_jog_mode(emu, board):
    with raw_port(emu) as ser:
        ser.write(b"\x00")
        no_answer(emu, ser)  # no reply ...
        assert emu.state == JOG_DATA_INPUT  # ... but the firmware is now in Jog mode
        ser.write(jog_packet("x", 3, delay=1))
        assert ser.read(1) == b"\x66"  # JOGMODEDONE
        ser.write(jog_exit_packet())
        assert ser.read(1) == b"\x65"  # JOGMODEOFF
    assert emu.position_pulses == (3, 0, 0)


def test_jog_moves_the_decoded_position_with_the_listed_timing(emu, board):
    board.jog("x", 120, delay=3)
    board.jog("y", -50, delay=1)
    board.jog("z", 30, delay=2)
    board.jog("z", -10, delay=2)
    log = emu.port_log()
    assert decode_port_log(log)[-1].tolist() == [120, -50, 20]
    assert emu.position_pulses == (120, -50, 20)
    # STEP_X rising edges of the first jog: period 2 * delay * 100 us
    d = log.value.astype(int)
    is_d = log.port == PORT_D
    idx = np.flatnonzero(is_d)
    rise = idx[1:][((d[idx[1:]] >> 1) & 1 == 1) & ((d[idx[:-1]] >> 1) & 1 == 0)]
    periods = np.diff(log.t_ns[rise[:120]])
    assert set(periods.tolist()) == {2 * 3 * 100_000}
    assert emu.wait_for_state(MODE_SELECTION)


def test_listed_drill_mode_drifts_with_the_pc_programs_init_values_and_dog_legs(emu, board):
    """Raw protocol, PC-program values Zup = 10, Zdown = 30: Init lowers 10, each hole -20 then +10."""
    with raw_port(emu) as ser:
        ser.write(b"\x67")
        assert ser.read(1) == b"\x68"
        ser.write(offset_packet(0, 0, 0, delay_x=1, delay_y=1, delay_z=1))
        assert ser.read(1) == b"\x75"
        ser.write(init_packet(10, 30 - 10, delay_x=2, delay_y=5, delay_z_up=1, delay_z_down=1))
        assert ser.read(1) == b"\x6a"
        ser.write(start_drill_packet())
        assert ser.read(1) == b"\x69"
        n0 = len(emu.port_log())
        ser.write(drill_packet(30, 4))
        assert ser.read(1) == b"\x69"
        ser.write(drill_packet(-30, -4))
        assert ser.read(1) == b"\x69"
        ser.write(close_drill_packet())
        assert ser.read(1) == b"\x70"
    log = emu.port_log()
    strokes = hole_strokes(log)
    assert strokes.tolist() == [[30, 4, -10, -30, -20], [0, 0, -20, -40, -30]]
    # dog-leg: 4 pulses on both axes at max(2, 5) = 5, then 26 on X alone at 2
    hole = PortLog(log.t_ns[n0:], log.port[n0:], log.value[n0:])
    pos = decode_port_log(hole)
    t = hole.t_ns
    moved = np.flatnonzero(np.any(np.diff(pos, axis=0) != 0, axis=1)) + 1
    xy = [i for i in moved if pos[i, 2] == pos[0, 2]]
    y_steps = [i for i in xy if pos[i, 1] != pos[i - 1, 1]]
    assert len(y_steps) == 4 and all(pos[i, 0] == k + 1 for k, i in enumerate(y_steps))
    x_only = [i for i in xy if pos[i, 0] != pos[i - 1, 0] and i not in y_steps and pos[i, 1] == 4]
    assert len(x_only) == 26
    assert set(np.diff(t[x_only]).tolist()) == {2 * 2 * 100_000}
    assert emu.wait_for_state(MODE_SELECTION)


# ---------------------------------------------------------------------- the host's drill job
def test_drill_six_holes_in_two_tool_groups(emu, board):
    board.jog("x", 7, delay=1)  # the start is not the power-up position
    start = decode_port_log(emu.port_log())[-1]
    calls = []
    n = board.drill(HOLES, z_down_steps=25, tool_changes=[(0, "T1 0.8 mm"), (3, "T2 1.0 mm")],
                    on_tool_change=lambda i, m: calls.append((i, m, emu.position_pulses, spindle_at_writes(emu)[-1])))
    assert n == len(HOLES)
    assert [c[:2] for c in calls] == [(0, "T1 0.8 mm"), (3, "T2 1.0 mm")]
    assert calls[1][2] == (start[0] + HOLES[2][0], start[1] + HOLES[2][1], start[2])  # over hole 2, Z up
    assert [c[3] for c in calls] == [0, 0]  # the spindle is off at every tool change
    log = emu.port_log()
    strokes = hole_strokes(log)
    got = strokes[:, :2] - start[:2]
    assert got.tolist() == HOLES.tolist()  # each hole once, in order
    assert (strokes[:, 2] == start[2]).all()  # every stroke starts at the start height (Z up 0)
    # ... and ends there, but for the last hole of T1: the next Drill mode session's Offset packet lifts the
    # head 25 pulses before the Init packet lowers it 25 again (the firmware quirk, see MaximusBoard.drill)
    assert strokes[:, 4].tolist() == [start[2]] * 2 + [start[2] + 25] + [start[2]] * 3
    assert (strokes[:, 3] == start[2] - 25).all()  # all to the same depth
    assert decode_port_log(log)[-1].tolist() == start.tolist()  # back where it started, Z included
    assert len(hole_packets(emu)) == len(HOLES) + 1  # and one XY move back to the start
    assert emu.wait_for_state(MODE_SELECTION) and board.in_step
    # the spindle runs at the bottom of every hole (the emulator's hole log) and is off at the end
    rows = emu.hole_log()
    assert [r[4] for r in rows] == [1] * len(HOLES)
    assert [(r[1] - 7, r[2], r[3]) for r in rows] == [(x, y, -25) for x, y in HOLES.tolist()]  # half steps
    assert spindle_at_writes(emu)[-1] == 0 and board.spindle_on is False


def test_drill_with_the_spindle_off_and_a_z_up_stroke(emu, board):
    """Z Drill Up 10, Down 30 below the start: travel 10 below, holes to 30, back at the start height."""
    n = board.drill(HOLES[:3], z_up_steps=10, z_down_steps=30, spindle=False)
    assert n == 3
    strokes = hole_strokes(emu.port_log())
    assert strokes[:, 2:].tolist() == [[-10, -30, -10]] * 2 + [[-10, -30, 0]]  # the last one ends raised
    assert decode_port_log(emu.port_log())[-1].tolist() == [0, 0, 0]
    assert spindle_at_writes(emu).max() == 0


def test_bad_drill_arguments_send_nothing(emu, board):
    before = len(emu.rx_log())
    with pytest.raises(PlanError):
        board.drill(np.array([[0, 0], [70000, 0]]), z_down_steps=5)
    with pytest.raises(PlanError):
        board.drill(HOLES, z_down_steps=0)
    with pytest.raises(PlanError):
        board.drill(HOLES, z_up_steps=5, z_down_steps=5)
    with pytest.raises(PlanError):
        board.drill(HOLES, z_down_steps=5, tool_changes=[(6, "too late")])
    assert len(emu.rx_log()) == before
    with MaximusBoard(emu.device_path, Maximus(invert_z=True), timeout_s=TIMEOUT_S) as inverted:
        before = len(emu.rx_log())
        with pytest.raises(PlanError, match="invert_z"):
            inverted.drill(HOLES, z_down_steps=5)
    assert len(emu.rx_log()) == before


# ---------------------------------------------------------------------- faults
def assert_stopped_at(emu, hole_index: int) -> None:
    """No Drill Data Packet was read after the faulted hole's (once the firmware has acted on every byte sent)."""
    assert emu.wait_until_idle()
    assert len(hole_packets(emu)) == hole_index + 1


def silent_hole_deadline_s(dx: int, dy: int, z_down_steps: int) -> float:
    """How long the host waits for an unanswered hole of ``FAST`` from :data:`SILENT_MARGIN_S`: the hole's move
    (10 % more), a limit switch's debounce and back-off at Delay 1, the margin."""
    init = init_packet(z_down_steps, z_down_steps, delay_x=1, delay_y=1, delay_z_up=1, delay_z_down=1)
    move_ns = drill_time_ns(drill_packet(dx, dy), init)
    return (move_ns * SLOWER_FACTOR + switch_time_ns(1)) / 1e9 + SILENT_MARGIN_S


def quiet_from_hole(board, index: int):
    """A ``before_hole`` callback: the reply margin is :data:`SILENT_MARGIN_S` from the hole of ``index`` on."""
    def before_hole(i: int) -> None:
        if i >= index:
            board.timeout_s = SILENT_MARGIN_S
    return before_hole


def test_dropped_reply_times_out_and_nothing_follows(emu, board):
    emu.drop_next_reply(match=ONEHOLEDRILLED, skip=2)  # the SDF answer, hole 0, then hole 1's is lost
    reads = record_reads(board)
    with pytest.raises(LinkFault, match=r"link fault during hole 2: the MAXIMUS board did not answer within "
                                        r"[0-9.]+ s .*nothing more sent.*last known position X=10 Y=5.*switch the "
                                        r"machine off") as info:
        board.drill(HOLES, z_down_steps=10, before_hole=quiet_from_hole(board, 1))
    # the silent board is found as soon as the host's margin allows after the move: it waited for the move, a
    # switch's allowance and the margin, and no longer (timed against the margin, not the wall clock)
    silent = silent_read(reads)
    assert reads[-1] is silent and silent.timeout_s == pytest.approx(silent_hole_deadline_s(30, 0, 10))
    assert silent.waited_s >= silent.timeout_s - 0.005
    assert f"within {silent.timeout_s:.1f} s" in str(info.value)
    assert "\n" not in str(info.value)
    assert_stopped_at(emu, 1)
    assert 0x80 not in [b for _, b, _ in emu.rx_log()]  # no stop byte: nothing
    assert emu.wait_for_state(DRILL_MODE1_INPUT)  # the firmware waits for the next packet: nothing moves
    assert not board.position_known
    with pytest.raises(PortError, match="out of step"):
        board.jog("x", 1)
    assert_stopped_at(emu, 1)


def test_corrupted_reply_is_refused(emu, board):
    emu.corrupt_next_reply(match=ONEHOLEDRILLED, skip=3)
    with pytest.raises(LinkFault, match=r"link fault during hole 3: the board answered unknown byte \(0x96\) "
                                        r"instead of ONEHOLEDRILLED \(0x69\)"):
        board.drill(HOLES, z_down_steps=10)
    assert_stopped_at(emu, 2)
    assert not board.in_step


def test_late_reply(emu, board):
    emu.delay_next_reply(0.3, match=ONEHOLEDRILLED, skip=1)  # late but inside the margin: fine
    assert board.drill(HOLES[:2], z_down_steps=5) == 2
    n_before = len(hole_packets(emu))
    reads = record_reads(board)
    late_s = 3 * silent_hole_deadline_s(60, -50, 5)
    emu.delay_next_reply(late_s, match=ONEHOLEDRILLED, skip=4)  # hole 4 answers long after its deadline
    with pytest.raises(LinkFault, match=r"during hole 4: the MAXIMUS board did not answer within [0-9.]+ s"):
        board.drill(HOLES, z_down_steps=5, before_hole=quiet_from_hole(board, 3))
    # found at its deadline (the move's few ms, a switch's 0.44 s, the margin), not at the late reply
    silent = silent_read(reads)
    assert silent.timeout_s == pytest.approx(silent_hole_deadline_s(60, -50, 5))
    assert emu.wait_until_idle()  # the late reply went out; nothing was sent after the fault, no stop byte:
    assert len(hole_packets(emu)) - n_before == 4
    assert bytes(b for _, b, _ in emu.rx_log()[-5:]) == hole_packets(emu)[-1]  # the last byte read is hole 4's


def test_limit_switch_at_the_travel_end_ends_the_job():
    emu = start_emulator(speed=None, travel_x_pulses=(-1000, 150))
    try:
        with MaximusBoard(emu.device_path, FAST, timeout_s=TIMEOUT_S) as board:
            holes = np.array([[20, 0], [60, 10], [100, 10], [300, 10], [0, 0]])
            with pytest.raises(PortError, match=r"limit switch LIMIT_SWITCH_X \(0x02\) tripped during hole 4; "
                                                r".*last known position X=100 Y=10"):
                board.drill(holes, z_down_steps=5)
            assert_stopped_at(emu, 3)
            assert emu.wait_for_state(MODE_SELECTION) and board.in_step
            # tripped on the first pulse past 150, backed off STEPSBACKATLIMIT pulses
            assert decode_port_log(emu.port_log())[-1][0] == 151 - STEPSBACKATLIMIT
            replies = [r[1] for r in emu.tx_log()]
            switch = replies.index(0x02)
            assert 0x69 not in replies[switch:]  # the switch byte, no ONEHOLEDRILLED
            assert replies[switch + 1:] == [0x64, 0x66, 0x65]  # then Jog mode: the spindle off, and out again
            assert spindle_at_writes(emu)[-1] == 0
            board.jog("x", 100, delay=1)  # the board is usable again
    finally:
        emu.stop()
    assert emu.error is None


def test_injected_limit_switch_during_a_jog(emu, board):
    emu.trip_limit_switch(HOME_SWITCH_Y)
    with pytest.raises(PortError, match=r"limit switch HOME_SWITCH_Y \(0x04\) tripped during jog y -40"):
        board.jog("y", -40, delay=2)
    assert emu.position_pulses[1] == -1 + STEPSBACKATLIMIT  # one pulse, then the back-off in +Y
    assert emu.wait_for_state(MODE_SELECTION)  # the host left Jog mode with the exit packet
    assert board.in_step


def wait_for(condition, timeout_s: float = TIMEOUT_S) -> None:
    """Wait for ``condition()`` (``timeout_s``: a failure guard)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.002)


def test_emergency_stop_during_a_move():
    emu = start_emulator(speed=1.0)  # real timing: the long move takes 0.4 s
    try:
        board = MaximusBoard(emu.device_path, FAST, timeout_s=TIMEOUT_S)
        holes = np.array([[5, 0], [2005, 0], [2010, 0]])
        result: dict[str, BaseException] = {}

        def job() -> None:
            try:
                board.drill(holes, z_down_steps=5)
            except BaseException as exc:  # noqa: BLE001 - handed to the test thread
                result["error"] = exc

        worker = threading.Thread(target=job)
        worker.start()
        wait_for(lambda: emu.position_pulses[0] >= 300)
        assert board.emergency_stop() is True
        worker.join(TIMEOUT_S)
        assert not worker.is_alive()
        error = result["error"]
        assert isinstance(error, PortError)
        assert "emergency stop during hole 2" in str(error) and "MACHINESTOPPED" in str(error)
        assert_stopped_at(emu, 1)
        x = emu.position_pulses[0]
        assert 300 <= x < 2005
        assert emu.wait_until_idle() and emu.position_pulses[0] == x  # nothing moves any more
        # MACHINESTOPPED came right after the stop byte cut the drivers (ENABLE_X, _Y, _Z low); then the host
        # switched the spindle off, with a Jog packet of no pulses (it energises the motors again, standing still)
        ports, cut = {}, False
        for _, port, value in emu.port_log():
            ports[ord(port)] = value
            cut = cut or (ports.get(PORT_D, 0xFF) & 0x88 == 0 and ports.get(PORT_B, 0xF0) & 0x80 == 0)
        assert cut
        assert spindle_at_writes(emu)[-1] == 0 and board.spindle_on is False
        assert emu.wait_for_state(MODE_SELECTION) and board.in_step
        board.close()
    finally:
        emu.stop()
    assert emu.error is None


def test_ctrl_c_during_a_move_then_emergency_stop_like_the_cli():
    emu = start_emulator(speed=1.0)
    main_ident = threading.get_ident()
    # Ctrl-C as a terminal delivers it: Python's own SIGINT handler, whatever earlier tests in this process left
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        board = MaximusBoard(emu.device_path, FAST, timeout_s=TIMEOUT_S)

        def press_ctrl_c() -> None:
            deadline = time.monotonic() + TIMEOUT_S
            while emu.position_pulses[0] < 300 and time.monotonic() < deadline:
                time.sleep(0.002)
            signal.pthread_kill(main_ident, signal.SIGINT)

        presser = threading.Thread(target=press_ctrl_c)
        presser.start()
        with pytest.raises(KeyboardInterrupt):  # a 3 s move: Ctrl-C comes at 300 pulses, long before its end
            board.drill(np.array([[15000, 0]]), z_down_steps=5)
        presser.join()
        assert board.emergency_stop() is True
        assert emu.position_pulses[0] < 15000
        assert emu.wait_for_state(MODE_SELECTION) and board.in_step
        board.close()
    finally:
        signal.signal(signal.SIGINT, previous)
        emu.stop()


def test_emergency_stop_between_moves_sends_no_stop_byte(emu, board):
    answers = []

    def tool_change(index: int, message: str) -> None:
        answers.append(board.emergency_stop())  # the head is between holes

    with pytest.raises(PortError, match=r"emergency stop before hole 4: no move was running; job closed"):
        board.drill(HOLES, z_down_steps=10, tool_changes=[(3, "T2")], on_tool_change=tool_change)
    assert answers == [False]
    assert 0x80 not in [b for _, b, _ in emu.rx_log()]
    assert_stopped_at(emu, 2)
    drill_packets = [p for kind, p in emu.packet_log() if kind == "drill"]
    assert drill_packets[-1] == bytes(5)  # Drill mode was closed by the packet that moves nothing
    assert spindle_at_writes(emu)[-1] == 0  # and the spindle switched off before the tool change
    assert emu.wait_for_state(MODE_SELECTION) and board.in_step


def test_emergency_stop_with_nothing_running_is_harmless(emu, board):
    assert board.emergency_stop() is False
    board.jog("x", 2, delay=1)
    assert emu.position_pulses == (2, 0, 0)


def test_open_maximus_url_and_bad_device(emu):
    board = open_maximus("maximus:" + emu.device_path, timeout_s=TIMEOUT_S)
    assert board.in_step
    board.close()
    with pytest.raises(PortError, match="cannot open MAXIMUS port"):
        MaximusBoard("maximus:/dev/does-not-exist-maximus")


def test_ctrl_c_at_a_tool_change_prompt_closes_drill_mode(emu, board):
    def prompt(index: int, message: str) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        board.drill(HOLES, z_down_steps=10, tool_changes=[(2, "T2")], on_tool_change=prompt)
    assert board.emergency_stop() is False  # nothing was moving; the job is already closed
    assert_stopped_at(emu, 1)
    assert [p for kind, p in emu.packet_log() if kind == "drill"][-1] == bytes(5)
    assert spindle_at_writes(emu)[-1] == 0
    assert emu.wait_for_state(MODE_SELECTION) and board.in_step
