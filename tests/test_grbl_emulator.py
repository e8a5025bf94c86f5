"""The grbl 1.1 emulator (cam.sim.grbl) on a pty, driven by the host link (cam.drive.grbl_link) and by raw
pyserial: welcome and $$, character-counting flow control against the 128-byte receive buffer, planner
starvation, feed hold and resume, soft reset, an alarm mid-job, a lost link (issue #30 points 1 and 3).

The emulator runs sped up here (``speed``: machine time per wall time), except the ``realtime`` test."""
from __future__ import annotations

import math
import threading
import time

import pytest
import serial

from cam.drive.grbl_link import GrblAlarm, GrblError, GrblLink, parse_grbl_url, parse_status, settings_mismatches
from cam.errors import CamError, PortError
from cam.settings import MachineSettings, Travel
from cam.sim.grbl import DEFAULT_SETTINGS, LOG_HEADER, WELCOME, start_emulator
from conftest import run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)

# grbl's defaults (500 mm/min, 10 mm/s^2) would cap these feeds; a small router's rates and accelerations
FAST = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0}




@pytest.fixture
def emulator(request):
    options = getattr(request, "param", {})
    emu = start_emulator(**{"speed": 5.0, "settings": FAST, **options})
    yield emu
    emu.stop()
    assert emu.error is None


def connect(emu, **options) -> GrblLink:
    return GrblLink(f"grbl:{emu.device_path}?baud=115200", welcome_timeout_s=1.0, **options)


def short_segments(n: int, step_mm: float = 0.15, feed_mm_min: float = 3000.0) -> tuple[list[str], tuple]:
    """A gentle spiral of ``n`` chords of ``step_mm``: 3 ms each at 50 mm/s, lines of about 20 bytes."""
    lines = ["G21 G90", f"G1 F{feed_mm_min:g}"]
    x = y = 0.0
    for i in range(n):
        heading = i * 0.02
        x += step_mm * math.cos(heading)
        y += step_mm * math.sin(heading)
        lines.append(f"G1 X{x:.3f} Y{y:.3f}")
    return lines, (round(x, 3), round(y, 3), 0.0)


def test_build_info_is_the_boards_identity():
    """``$I`` answers grbl 1.1h's ``[VER:...:build info]`` and ``[OPT:...]``; ``$I=`` stores the build info as grbl's
    pre-parser leaves it (upper case, no spaces), kept across a reset; the link reads it (issue #44 point 5)."""
    emu = start_emulator(speed=None, build_info="MILL-A")
    try:
        with connect(emu) as link:
            assert link.command("$I") == ["[VER:1.1h.20190830:MILL-A]", "[OPT:V,15,128]"]
            assert link.read_identity() == link.identity == "[VER:1.1h.20190830:MILL-A] [OPT:V,15,128]"
            link.command("$I=mill b")
            link.soft_reset()
            assert link.read_identity() == "[VER:1.1h.20190830:MILLB] [OPT:V,15,128]"
    finally:
        emu.stop()
    with pytest.raises(CamError, match="build_info"):
        start_emulator(speed=None, build_info="two words")


def test_welcome_and_settings():
    emu = start_emulator(speed=None, settings={100: 80.0, 22: 1})
    try:
        with connect(emu) as link:
            assert link.welcome == WELCOME
            expected = {**DEFAULT_SETTINGS, 100: 80.0, 22: 1.0}
            assert link.settings == pytest.approx(expected)
            # homing enabled: grbl starts locked in alarm and says how to unlock
            assert "[MSG:'$H'|'$X' to unlock]" in link.messages
            assert link.status().state == "Alarm"
            with pytest.raises(GrblError, match=r"error:9 \(G-code is locked out"):
                link.command("G0 X-1")
            link.unlock()
            assert link.status().state == "Idle"
            link.command("$H", timeout_s=10)
            status = link.wait_idle()
            assert status.mpos_mm == pytest.approx((-1.0, -1.0, -1.0))   # the pull-off $27 from the switches
    finally:
        emu.stop()


def test_a_board_that_does_not_restart_on_open_is_asked_for_its_welcome():
    emu = start_emulator(speed=None, reset_on_open=False)
    try:
        with GrblLink(f"grbl:{emu.device_path}", welcome_timeout_s=0.05) as link:   # then a soft reset
            assert link.welcome == WELCOME and link.settings[110] == 500.0
        assert [text for _, text in emu.events if "reset" in text] == ["soft reset"]
    finally:
        emu.stop()


def test_200_lines_with_flow_control_never_overflow(emulator):
    lines, end = short_segments(200)
    with connect(emulator) as link:
        report = link.stream(lines)
        assert report.lines == 202 and report.max_outstanding_bytes <= 128
        assert report.max_outstanding_bytes > 100        # it did fill grbl's buffer, not send-and-wait
    assert emulator.overflow_bytes == 0
    assert emulator.max_rx_bytes <= 128
    executed = emulator.executed()
    assert executed[-1].end_mm == pytest.approx(end, abs=1e-9)
    assert executed[-1].line == 203 and not any(b.halted for b in executed)
    assert [answer for _, _, answer in emulator.lines()][-202:] == ["ok"] * 202
    # consecutive blocks join exactly: each starts where the one before ended
    assert all(a.end_mm == b.start_mm for a, b in zip(executed, executed[1:]))


def test_the_emulator_counts_an_overflow(emulator):
    """A host that ignores the buffer (the whole program at once) loses bytes, and the emulator says so."""
    lines, _ = short_segments(40)
    with serial.Serial(emulator.device_path, 115200, timeout=0.5) as ser:
        ser.readline()
        ser.write(("\n".join(lines) + "\n").encode())
        assert emulator.wait_for(lambda e: e.overflow_bytes > 0, 2.0)
    assert any("overflow" in text for _, text in emulator.events)


def send_and_wait(device: str, lines: list[str]) -> None:
    """The naive streamer: one line, then wait for its ok."""
    with serial.Serial(device, 115200, timeout=2.0) as ser:
        time.sleep(0.1)               # the restart on open, if the emulator saw the port closed in between
        ser.reset_input_buffer()
        ser.write(b"\x18")            # a soft reset: the welcome line, at once
        assert ser.readline().strip().decode() == WELCOME
        for line in lines:
            ser.write((line + "\n").encode())
            answer = ser.readline().strip()
            assert answer == b"ok", answer


@pytest.mark.parametrize("emulator", [{"speed": 2.0, "latency_s": 0.008}], indirect=True)
def test_no_starvation_with_character_counting_but_with_send_and_wait(emulator):
    """115200 baud, a USB adapter that holds each answer 8 ms (an FTDI's latency timer is 16 ms by default),
    3 ms segments: with 128 bytes in flight the planner keeps blocks to look ahead to; one line per round
    trip leaves it with none behind the running block, line after line."""
    lines, end = short_segments(100)
    with connect(emulator) as link:
        link.stream(lines)
        assert emulator.executed()[-1].end_mm == pytest.approx(end)
        assert emulator.starvation_count == 0, emulator.events
        link.stream(["G0 X0 Y0"])     # back to the start: the second run has no long move to queue behind
    emulator.wait_for(lambda e: e.state == "Idle")
    send_and_wait(emulator.device_path, lines[:32])
    assert emulator.wait_for(lambda e: e.state == "Idle" and e.planner_blocks == 0)
    assert emulator.starvation_count >= 15, emulator.events        # about one a line: 22-27 of 30 seen


def wait_status(link: GrblLink, predicate, timeout_s: float = 5.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status = link.status()
        if predicate(status):
            return status
        time.sleep(0.005)
    raise AssertionError(f"status never matched; last {status}")


@pytest.mark.parametrize("emulator", [{"speed": 10.0}], indirect=True)
def test_feed_hold_and_resume_mid_job(emulator):
    with connect(emulator) as link:
        link.command("G1 X40 F1200")                 # 20 mm/s: 2 s of machine time
        wait_status(link, lambda s: s.state == "Run" and s.mpos_mm[0] > 5)
        link.hold()
        held = wait_status(link, lambda s: s.state == "Hold:0")
        assert 5 < held.mpos_mm[0] < 40
        time.sleep(0.05)                             # half a second of machine time: it stays put
        again = link.status()
        assert again.state == "Hold:0" and again.mpos_mm == held.mpos_mm and again.feed_mm_min == 0
        link.resume()
        done = link.wait_idle()
        assert done.mpos_mm == pytest.approx((40.0, 0.0, 0.0))
    (block,) = emulator.executed()
    assert block.end_mm == (40.0, 0.0, 0.0) and not block.halted


@pytest.mark.parametrize("emulator", [{"speed": 10.0}], indirect=True)
def test_soft_reset_mid_job_alarms_and_x_unlocks(emulator):
    with connect(emulator) as link:
        link.command("G1 X40 F1200")
        wait_status(link, lambda s: s.state == "Run" and s.mpos_mm[0] > 5)
        assert link.soft_reset() == WELCOME
        assert "ALARM:3" in link.messages
        stopped = link.status()
        assert stopped.state == "Alarm" and 5 < stopped.mpos_mm[0] < 40
        with pytest.raises(GrblError, match="error:9"):
            link.command("G1 X0")
        link.unlock()
        assert link.status().state == "Idle"
        link.stream(["G0 X0"])
        assert link.status().mpos_mm == (0.0, 0.0, 0.0)
    assert emulator.executed()[0].halted


def test_an_alarm_mid_job_is_one_line(emulator):
    lines, _ = short_segments(200)
    emulator.trip_hard_limit(after_blocks=60)
    with connect(emulator) as link:
        with pytest.raises(GrblAlarm) as caught:
            link.stream(lines)
        message = str(caught.value)
        assert "\n" not in message and "ALARM:1" in message and "hard limit" in message
        assert caught.value.code == 1
        link.soft_reset()
        assert link.status().state == "Alarm"
    executed = emulator.executed()
    assert len(executed) == 61 and executed[-1].halted


def test_a_refused_line_is_one_line_with_its_number_and_meaning(emulator):
    with connect(emulator) as link:
        with pytest.raises(GrblError, match=r"^grbl refused line 2 'G1 X1': error:22 \(feed rate not set\)$"):
            link.stream(["G21", "G1 X1", "G1 X2"])


def test_a_lost_link_is_one_line(emulator):
    lines, _ = short_segments(400, step_mm=0.5, feed_mm_min=600)   # 50 ms a segment: 4 s at speed 5
    with connect(emulator) as link:
        threading.Timer(0.2, emulator.unplug).start()
        with pytest.raises(PortError) as caught:
            link.stream(lines)
    message = str(caught.value)
    assert "\n" not in message and "lost" in message and emulator.device_path in message


def test_work_offsets_and_status_positions(emulator):
    with connect(emulator) as link:
        link.stream(["G0 X10 Y20 Z-5"])
        reports = [link.status().raw for _ in range(3)]
        assert [("WCO:" in r) for r in reports] == [False, False, False]   # the first report had it, idle: every 30th
        link.command("G10 L20 P1 X0 Y0 Z0")                          # (stream() would poll a report itself)
        status = link.status()                                       # an offset changed: WCO in the next report
        assert status.mpos_mm == (10.0, 20.0, -5.0) and "WCO:10.000,20.000,-5.000" in status.raw
        assert status.wco_mm == (10.0, 20.0, -5.0) and status.wpos_mm == (0.0, 0.0, 0.0)
        assert "WCO:" not in link.status().raw
        assert "[G54:10.000,20.000,-5.000]" in link.command("$#")
        link.stream(["G55", "G10 L2 P2 X1", "G0 X0", "G53 G0 X3"])
        assert link.status().mpos_mm == (3.0, 20.0, -5.0)
        assert link.command("$G")[0].startswith("[GC:G0 G55 G17 G21 G90 G94")
        link.command("$10=0")                                        # WPos reports
        status = link.status()
        assert "WPos:2.000,20.000,-5.000" in status.raw and status.mpos_mm == (3.0, 20.0, -5.0)


@pytest.mark.parametrize("emulator", [{"speed": 20.0}], indirect=True)
def test_stored_positions_pause_jog_check_mode_and_soft_limits(emulator):
    with connect(emulator) as link:
        link.stream(["G0 X-10 Y-10", "G28.1", "G0 X-20 Y-5 Z-3", "G30.1", "G0 X0 Y0 Z0", "G28"])
        assert link.status().mpos_mm == (-10.0, -10.0, 0.0)
        link.stream(["G30 X-1"])                                     # via X-1, then to the G30 position
        assert link.status().mpos_mm == (-20.0, -5.0, -3.0)
        assert [b.end_mm for b in emulator.executed()[-2:]] == [(-1.0, -10.0, 0.0), (-20.0, -5.0, -3.0)]
        link.stream(["G92 X0 Y0"])
        assert link.status().wpos_mm == (0.0, 0.0, -3.0)
        link.stream(["G92.1"])
        paused = []

        def resume_when_paused():
            paused.append(emulator.wait_for(lambda e: e.state == "Hold:0" and e.planner_blocks == 0, 5.0))
            paused.append(emulator.machine_position_mm)
            link.resume()

        threading.Thread(target=resume_when_paused).start()
        link.stream(["G1 X-5 F600", "M0", "G0 X-6"])                  # M0 pauses until cycle start
        assert paused == [True, (-5.0, -5.0, -3.0)] and link.status().mpos_mm == (-6.0, -5.0, -3.0)
        link.command("$J=G91 X-30 F600")
        wait_status(link, lambda s: s.state == "Jog" and s.mpos_mm[0] < -7)
        link.jog_cancel()
        stopped = wait_status(link, lambda s: s.state == "Idle")
        assert -36 < stopped.mpos_mm[0] < -7 and emulator.executed()[-1].halted
        assert link.command("$C") == ["[MSG:Enabled]"]
        link.stream(["G0 X-100"])                                    # checked, not moved
        assert link.command("$C") == ["[MSG:Disabled]"] and link.status().mpos_mm == stopped.mpos_mm
        link.command("$22=1")
        link.command("$20=1")
        with pytest.raises(GrblAlarm, match=r"ALARM:2 \(motion target beyond the machine travel"):
            link.stream(["G0 X10"])


def test_arcs_and_overrides(emulator):
    with connect(emulator) as link:
        link.override(0x91)                                          # feed +10 %
        link.stream(["G1 X10 F3000", "G2 X20 Y0 I5 J0 K0"])          # a K word in G17: taken, as grbl does
        assert link.status().overrides in (None, (110, 100, 100))
    arc = [b for b in emulator.executed() if b.kind == "G2"]
    assert len(arc) > 10
    for block in arc:   # every chord end on the circle of centre (15, 0), radius 5, above the X axis
        x, y, _ = block.end_mm
        assert math.hypot(x - 15, y) == pytest.approx(5.0, abs=1e-9) and y >= -1e-9
    assert arc[-1].end_mm == (20.0, 0.0, 0.0)


@pytest.mark.parametrize("emulator", [{"speed": None}], indirect=True)
@pytest.mark.parametrize("radius, top_mm", [(6, 2.6834), (-6, 9.3166)])   # R < 0: the arc over 180 degrees
def test_radius_arcs_go_the_way_grbl_documents(emulator, radius, top_mm):
    with connect(emulator) as link:
        link.stream(["G1 F3000", f"G2 X10 Y0 R{radius}"])                # clockwise from (0, 0): above the chord
    ends = [b.end_mm for b in emulator.executed()]
    centre_y = -math.sqrt(11.0) if radius > 0 else math.sqrt(11.0)   # the centre below, or above, (5, 0)
    assert all(math.hypot(x - 5, y - centre_y) == pytest.approx(6.0, abs=1e-9) for x, y, _ in ends)
    assert max(y for _, y, _ in ends) == pytest.approx(top_mm, abs=2e-3) and ends[-1] == (10.0, 0.0, 0.0)


def test_settings_read_from_grbl_against_the_machine_file():
    emu = start_emulator(speed=None, settings={100: 260.0})
    try:
        with connect(emu) as link:
            grbl = link.settings
    finally:
        emu.stop()
    same = MachineSettings().replace(
        mm_per_step_xy=0.004, mm_per_step_z=0.004, max_speed_x_mm_s=500 / 60, max_speed_y_mm_s=500 / 60,
        max_speed_z_mm_s=500 / 60, accel_x_mm_s2=10.0, accel_y_mm_s2=10.0, accel_z_mm_s2=10.0,
        travel=Travel(0, 50000, 0, 50000, -10000, 40000))                # 200 mm on each axis
    assert settings_mismatches(grbl, same) == ["X steps/mm $100=260 vs 250"]
    assert len(settings_mismatches(grbl, MachineSettings())) == 12          # the thesis machine: all differ


def test_url_and_status_parsing():
    assert parse_grbl_url("grbl:/dev/ttyUSB0?baud=250000") == ("/dev/ttyUSB0", 250000)
    with pytest.raises(PortError, match="baud must be a whole number"):
        parse_grbl_url("grbl:/dev/ttyUSB0?baud=fast")
    with pytest.raises(PortError, match="cannot open grbl port /nonexistent/tty"):
        GrblLink("grbl:/nonexistent/tty")
    status = parse_status("<Hold:0|WPos:1.000,2.000,3.000|FS:0,0>", (1.0, 1.0, 1.0))
    assert status.state == "Hold:0" and status.mpos_mm == (2.0, 3.0, 4.0)


def test_log_comments_and_bad_lines(tmp_path):
    log = tmp_path / "grbl.csv"
    emu = start_emulator(speed=None, log_path=str(log))
    try:
        with connect(emu) as link:
            link.stream(["G0 X-1 (where? here!)", "", "G0 Y-2 ; a comment~"])
            assert [text for _, text, _ in emu.lines()][-2:] == ["G0 X-1", "G0 Y-2"]
            with pytest.raises(GrblError, match=r"^line 1 'G0 X1!' holds '!', which grbl would take as a real-time"):
                link.stream(["G0 X1!"])
            with pytest.raises(GrblError, match=r"^grbl refused '\$5=-1': error:4 \(negative value"):
                link.command("$5=-1")
    finally:
        emu.stop()
    rows = log.read_text().splitlines()
    assert rows[0] == LOG_HEADER                     # line numbers count every line: line 1 was the link's $$
    assert rows[1].split(",")[:8] == ["2", "G0", "0.0000", "0.0000", "0.0000", "-1.0000", "0.0000", "0.0000"]
    assert rows[2].split(",")[:2] == ["3", "G0"] and rows[2].split(",")[5:8] == ["-1.0000", "-2.0000", "0.0000"]


def test_emulate_grbl_refuses_a_bad_setting_in_one_line():
    run = run_cli("emulate-grbl", "--set", "999=1")
    assert run.returncode == 2 and run.stderr.strip().count("\n") == 0 and "$999" in run.stderr


@pytest.mark.realtime
def test_a_job_at_real_speed():
    emu = start_emulator(speed=1.0, settings=FAST)
    try:
        lines, end = short_segments(150)          # about half a second of machine time
        with connect(emu) as link:
            report = link.stream(lines)
            assert link.status().mpos_mm == pytest.approx(end)
        assert report.max_outstanding_bytes <= 128 and emu.overflow_bytes == 0
        assert emu.starvation_count == 0, emu.events
        assert emu.executed()[-1].end_mm == pytest.approx(end, abs=1e-9)
    finally:
        emu.stop()
