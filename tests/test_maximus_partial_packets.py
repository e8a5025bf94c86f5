"""The emulator keeps a half-received packet as the firmware does (issue #33 point 2; seed 000 Appendix 1:
every packet is read by consecutive getc() calls with interrupts off, and 0x80 is only a stop byte while
interrupts are on, during a move).  These are the facts docs/maximus.md's "When the link fails" rests on:
a packet that lost a byte waits, silent and still, for one more byte, and whatever byte comes next, the stop
byte included, completes it into the move its fields now say."""
from __future__ import annotations

import time

import pytest
import serial

from cam.drive.maximus.packets import drill_packet, init_packet, jog_packet, offset_packet, start_drill_packet
from cam.drive.maximus.protocol import (
    ATOFFSETPOS, DRILLMODE1DONE, DRILLMODE1INITIALIZED, DRILLMODE1ON, EMERGENCYSTOP, ISMACHINEREADY, JOGMODEDONE, JOGMODEON,
    MACHINEREADY, MACHINESTOPPED, ONEHOLEDRILLED, OPENDRILLMODE1, OPENJOGMODE,
)
from cam.sim.maximus import (
    DRILL_MODE1_INITIALIZE, DRILL_MODE1_INPUT, INITIALIZE_DRILL_MODE, JOG_DATA_INPUT, MODE_SELECTION, start_emulator,
)
from support.maximus_host import GUARD_MARGIN_S as GUARD_S


def ask(ser: "serial.Serial", data: bytes, reply: int) -> None:
    """Send ``data`` and read its reply (waited for: the timeout is a failure guard)."""
    ser.write(data)
    ser.timeout = GUARD_S
    got = ser.read(1)
    assert got == bytes([reply]), (data.hex(), got)


def unanswered(ser: "serial.Serial", emu, data: bytes, state: str) -> tuple[int, int, int]:
    """Send ``data``: the firmware reads it all and waits at ``state``, without an answer, with nothing moving."""
    at = emu.position_pulses
    ser.write(data)
    assert emu.wait_until_idle()  # it acted on every byte and waits for the next: an answer would be out by now
    assert emu.state == state and emu.position_pulses == at
    ser.timeout = 0.05  # only the pseudo-terminal's own delivery
    assert ser.read(1) == b"", data.hex()
    return at


@pytest.fixture
def port(emu):
    with serial.Serial(emu.device_path, 115200, timeout=GUARD_S) as ser:
        ser.reset_input_buffer()
        ser.write(bytes([ISMACHINEREADY]))
        assert ser.read_until(bytes([MACHINEREADY])).endswith(bytes([MACHINEREADY]))
        assert emu.wait_for_state(MODE_SELECTION)
        yield ser


def drill_mode(ser, emu, stroke: int = 20) -> None:
    ask(ser, bytes([OPENDRILLMODE1]), DRILLMODE1ON)
    ask(ser, offset_packet(0, 0, 0, delay_x=1, delay_y=1, delay_z=1), ATOFFSETPOS)
    ask(ser, init_packet(0, stroke, delay_x=1, delay_y=1, delay_z_up=1, delay_z_down=1), DRILLMODE1INITIALIZED)
    ask(ser, start_drill_packet(), ONEHOLEDRILLED)


@pytest.mark.parametrize("lost", [0, 1] + [pytest.param(k, marks=pytest.mark.slow) for k in (2, 3, 4)])
def test_a_drill_packet_that_lost_a_byte_waits_and_the_stop_byte_completes_it(emu, port, lost):
    drill_mode(port, emu)
    packet = drill_packet(300, 40)  # 83 2c 01 28 00
    assert unanswered(port, emu, packet[:lost] + packet[lost + 1:], DRILL_MODE1_INPUT) == (0, 0, 0)  # four bytes
    assert emu.hole_log() == []
    if lost == 0:  # the first field's low byte 0x2c is read as the configuration: CDF clear, Drill mode ends
        ask(port, bytes([EMERGENCYSTOP]), DRILLMODE1DONE)
        assert emu.position_pulses == (0, 0, 0) and emu.hole_log() == []
        return
    ask(port, bytes([EMERGENCYSTOP]), ONEHOLEDRILLED)  # the "stop" byte is the fifth byte: a hole, not a stop
    data = [p for kind, p in emu.packet_log() if kind == "drill"][-1]
    assert data == packet[:lost] + packet[lost + 1:] + bytes([EMERGENCYSTOP])
    assert MACHINESTOPPED not in [sent for _, _, sent in emu.tx_log()]
    assert len(emu.hole_log()) == 1
    assert emu.position_pulses[1] >= 0x8000  # 0x80 is Y's high byte: the hole is 143 mm or more away in Y


def test_a_jog_packet_that_lost_a_byte_waits_for_one_more(emu, port):
    ask(port, bytes([OPENJOGMODE]), JOGMODEON)
    packet = jog_packet("x", 300, delay=1)
    assert unanswered(port, emu, packet[:1] + packet[2:], JOG_DATA_INPUT) == (0, 0, 0)
    ask(port, bytes([EMERGENCYSTOP]), JOGMODEDONE)  # completed: X moves 0x0101 pulses at Delay 0x80
    assert emu.position_pulses[0] == 0x0101


@pytest.mark.parametrize("length,state", [(10, DRILL_MODE1_INITIALIZE), (9, INITIALIZE_DRILL_MODE)])
def test_offset_and_init_packets_that_lost_a_byte_wait(emu, port, length, state):
    ask(port, bytes([OPENDRILLMODE1]), DRILLMODE1ON)
    if length == 9:
        ask(port, offset_packet(0, 0, 0, delay_x=1, delay_y=1, delay_z=1), ATOFFSETPOS)
        packet = init_packet(30, 30, delay_x=1, delay_y=1, delay_z_up=1, delay_z_down=1)
    else:
        packet = offset_packet(30, 0, 0, delay_x=1, delay_y=1, delay_z=1)
    assert unanswered(port, emu, packet[:-1], state) == (0, 0, 0)


def test_bytes_during_a_move_are_read_and_forgotten_but_the_stop_byte():
    """Interrupts are on from just before a move until its answer: the UART ISR reads every byte; only 0x80
    does anything (serial_isr's switch)."""
    emu = start_emulator(speed=1.0)  # the move takes 0.4 s: the bytes come during it
    try:
        with serial.Serial(emu.device_path, 115200, timeout=GUARD_S) as ser:
            ser.write(bytes([ISMACHINEREADY]))
            assert ser.read_until(bytes([MACHINEREADY])).endswith(bytes([MACHINEREADY]))
            drill_mode(ser, emu)
            before = len(emu.rx_log())
            ser.write(drill_packet(2000, 0))
            deadline = time.monotonic() + GUARD_S
            while emu.position_pulses[0] == 0:  # the move has begun
                assert time.monotonic() < deadline
                time.sleep(0.002)
            ser.write(bytes([0x61, 0x00, 0x69]))
            assert ser.read(1) == bytes([ONEHOLEDRILLED])
            assert emu.wait_until_idle() and emu.state == DRILL_MODE1_INPUT
            assert [where for _, _, where in emu.rx_log()[before:]][-3:] == ["isr"] * 3
            ser.timeout = 0.05  # written by now if at all: only the pseudo-terminal's own delivery
            assert ser.read(1) == b"" and emu.position_pulses[0] == 2000
    finally:
        emu.stop()
    assert emu.error is None
