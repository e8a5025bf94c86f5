"""A faulty world between ``cam`` and a grbl board (issue #43 points 1-3): a fault-injecting proxy
(:class:`support.serial_proxy.PtyProxy`) edits the lines between the link and the grbl emulator (and, in the
``firmware`` tests, grbl 1.1h's own firmware on a simulated ATmega328P, ``../shared/grbl_avr``).

Every fault mid-job must stop the machine first: a feed hold, then a soft reset, so no block queued before
the fault runs; the activity ends with one line and the position is unknown.  The proxy refuses a line (it
turns one into ``G5``, which grbl answers ``error:20``), loses an ``ok``, doubles ``ok``s, and garbles status
reports."""
from __future__ import annotations

import math
import os
import random
import shutil
import subprocess
import sys
import time
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterator, Optional

import numpy as np
import pytest

import cam
from cam.drive import grbl_machine as gm
from cam.drive.grbl_link import GrblError, GrblLink, parse_status
from cam.drive.grbl_machine import GrblMachine, close_grbl_machines
from cam.drive.session import MachineSession
from cam.drive.state import StateHold
from cam.job.model import CUT, TRAVEL, Job
from cam.settings import Travel
from cam.sim.grbl import start_emulator
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from support.serial_proxy import PtyProxy

SETTINGS = cam.MachineSettings()
STEPS_PER_MM = {100: 1 / SETTINGS.mm_per_step_xy, 101: 1 / SETTINGS.mm_per_step_xy,
                102: 1 / SETTINGS.mm_per_step_z}
FAST = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0, **STEPS_PER_MM}
GRBL_AVR = Path(__file__).resolve().parents[2] / "shared" / "grbl_avr"
REALTIME = set(b"?!~\x18")


def zigzag_job(settings: cam.MachineSettings, segments: int = 40, step_mm: float = 1.0,
               feed_mm_min: float = 300.0) -> Job:
    """A cut of ``segments`` short moves (X on, Y to and fro): many lines, each its own grbl block."""
    per_mm = 1.0 / settings.mm_per_step_xy
    pts = [(0, 0, int(round(0.5 / settings.mm_per_step_z)))]
    for k in range(1, segments + 1):
        pts.append((int(round(k * step_mm * per_mm)), int(round((k % 2) * step_mm * per_mm)), pts[0][2]))
    pts.append((pts[-1][0], pts[-1][1], 0))
    pts_steps = np.asarray(pts, np.int64)
    d = np.diff(np.vstack([[0, 0, 0], pts_steps]), axis=0)
    length_mm = np.hypot(d[:, 0] * settings.mm_per_step_xy, d[:, 1] * settings.mm_per_step_xy)
    length_mm = np.hypot(length_mm, d[:, 2] * settings.mm_per_step_z)
    n = np.maximum(1, np.abs(d).max(axis=1))
    period_ns = np.maximum(1, length_mm / (feed_mm_min / 60.0) / n * 1e9).astype(np.int64)
    kind = np.full(len(pts_steps), CUT, np.uint8)
    kind[-1] = TRAVEL
    false = np.zeros(len(pts_steps), bool)
    return Job(pts_steps, kind, false.copy(), false.copy(), settings=settings, period_ns=period_ns)


def refuse_line(k: int, seen: Optional[list] = None) -> Callable[[int, bytes], bytes]:
    """A host-line filter that turns the ``k``-th motion line (``G53G1``, from 1) into ``G5`` padded to the
    same length (grbl drops spaces: it answers ``error:20``, and the byte count stays right)."""
    count = [0]

    def edit(n: int, line: bytes) -> bytes:
        if line.startswith(b"G53G1"):
            count[0] += 1
            if count[0] == k:
                if seen is not None:
                    seen.append(line)
                return b"G5".ljust(len(line) - 1) + b"\n"
        return line
    return edit


@contextmanager
def emulator_rig(speed: Optional[float] = 20.0, settings: Optional[dict] = None,
                 **proxy_options) -> Iterator[tuple[object, PtyProxy]]:
    emu = start_emulator(speed=speed, settings={**FAST, **(settings or {})})
    proxy = PtyProxy(emu.device_path, **proxy_options)
    try:
        yield emu, proxy
    finally:
        close_grbl_machines()
        proxy.close()
        emu.stop()


def open_session(proxy: PtyProxy, settings: cam.MachineSettings = SETTINGS, *, state=None,
                 reply_margin_s: Optional[float] = None) -> MachineSession:
    """A session on the proxy's pty.  The proxy opened the board (it reset then), so no welcome comes when
    cam opens the proxy: a short welcome wait, then the link's soft reset gets one."""
    url = f"grbl:{proxy.device_path}"
    link = GrblLink(url, welcome_timeout_s=0.3)
    if reply_margin_s is not None:
        link.reply_margin_s = reply_margin_s
    gm._MACHINES[proxy.device_path] = GrblMachine(url, settings, link=link)
    return MachineSession(url, settings, state=state)


def fault_message(session: MachineSession) -> str:
    run = session.last_run
    assert run["status"] == "error", run
    msg = run["messages"][0]
    assert "\n" not in msg
    return msg


def event_time(emu, predicate: Callable[[str], bool], after_s: float = -1.0) -> float:
    return next(t for t, text in emu.events if t >= after_s and predicate(text))


def assert_stopped_by_hold_then_reset(emu) -> None:
    """The emulator saw a feed hold, then a soft reset; no block ran to its end after the hold but the one
    it was decelerating in, and the hold had ended before the reset (no ALARM:3: nothing was moving)."""
    t_hold = event_time(emu, lambda text: text == "feed hold")
    t_reset = event_time(emu, lambda text: text.startswith("soft reset"), t_hold)
    assert t_reset >= t_hold
    after = [b for b in emu.executed() if b.t_end_s > t_hold + 1e-9]
    assert len(after) <= 1 and all(b.halted for b in after), after
    assert not any("ALARM:3" in text for _, text in emu.events), emu.events


def assert_no_line_after(proxy: PtyProxy, offset: int) -> None:
    """After the host had read the fault (``offset`` bytes sent by then), it sent only real-time bytes, but for
    at most the one line it was writing as the fault crossed the wire."""
    later = bytes(b for b in proxy.to_board[offset:] if b not in REALTIME)
    assert later.count(b"\n") <= 1 and len(later) <= 80, later


def run_to_end(session: MachineSession, job: Job, timeout_s: float = 120.0) -> None:
    session.start(job)
    assert session.wait_idle(timeout_s), "the activity never ended: a hang"


def zigzag_from_a_known_position(proxy, tmp_path: Path) -> tuple[StateHold, str]:
    """The zigzag job run to its end through ``proxy`` by a session whose machine state says the position is known;
    the state's hold (still open) and the line the session said of the fault."""
    hold = StateHold(tmp_path / "m.json", SETTINGS, "test")
    hold.record(replace(hold.state, position_known=True))
    session = open_session(proxy, state=hold)
    run_to_end(session, zigzag_job(SETTINGS))
    return hold, fault_message(session)


# ---------------------------------------------------------------------------------------------- error:N
def test_error_mid_job_holds_then_resets_grbl_before_exiting(tmp_path):
    """Issue #43 point 1: grbl refuses a line mid-job; cam stops the machine (feed hold, soft reset) so the
    blocks queued before the fault never run, and says so in one line; the position is unknown."""
    seen: list = []
    marks: dict = {}
    with emulator_rig() as (emu, proxy):
        proxy.host_line_filter = refuse_line(25, seen)  # past the planner's 15 blocks: mid-motion

        def mark(line: bytes) -> bytes:
            if line.startswith(b"error:") and "error" not in marks:
                marks["error"] = len(proxy.to_board)
            return line
        proxy.board_line_filter = mark
        hold, msg = zigzag_from_a_known_position(proxy, tmp_path)
        assert "error:20" in msg and "feed hold and a soft reset" in msg and "position is unknown" in msg, msg
        assert seen, "the proxy never refused a line"
        assert_stopped_by_hold_then_reset(emu)
        assert_no_line_after(proxy, marks["error"])
        t_error = event_time(emu, lambda text: text.startswith("error:20"))
        assert t_error <= event_time(emu, lambda text: text == "feed hold")
        # the zigzag did not go on: grbl stopped short of the job's end
        assert emu.machine_position_mm[0] < 39.0 * 1.0
        assert not hold.state.position_known
        hold.close()


@pytest.mark.realtime
def test_at_real_speed_error_mid_job_stops_within_the_deceleration():
    """The same fault with the emulator at the wall clock's speed (a sped-up emulator once hid a fixed
    timeout): still a hold then a reset, and nothing queued runs."""
    with emulator_rig(speed=1.0) as (emu, proxy):
        proxy.host_line_filter = refuse_line(22)
        session = open_session(proxy)
        run_to_end(session, zigzag_job(SETTINGS, segments=30))
        assert "error:20" in fault_message(session)
        assert_stopped_by_hold_then_reset(emu)
        assert any(not b.halted for b in emu.executed()[1:])  # it was cutting when the fault came
        assert emu.machine_position_mm[0] < 29.0


def push_at_ok(k: int, push: bytes, keep_ok: bool = True) -> Callable[[bytes], bytes]:
    """A board-line filter that puts ``push`` (a line grbl sends unasked) at the ``k``-th ``ok``, before it or (a
    welcome: a reset answers nothing) instead of it; grbl itself goes on running its queue, so only cam's own stop
    can keep the queued blocks from running."""
    count = [0]

    def edit(line: bytes) -> bytes:
        if line.strip() == b"ok":
            count[0] += 1
            if count[0] == k:
                return push + b"\r\n" + (line if keep_ok else b"")
        return line
    return edit


@pytest.mark.parametrize("push, keep_ok, words", [(b"ALARM:1", True, ("ALARM:1 (hard limit",)),
                                                  (b"Grbl 1.1h ['$' for help]", False, ("reset itself",))],
                         ids=["ALARM mid-job", "a reset cam did not ask for"])
def test_an_alarm_or_a_reset_mid_job_holds_then_resets_grbl(tmp_path, push, keep_ok, words):
    """Issue #43 point 1 for grbl's push messages: an ``ALARM:n`` or a welcome line (grbl reset) mid-job.  Here the
    emulator has not stopped by itself (the proxy says it), so the test sees cam's own stop: a feed hold, then a
    soft reset, no block queued before the fault runs to its end, one line, and the position is unknown."""
    marks: dict = {}
    with emulator_rig() as (emu, proxy):
        filt = push_at_ok(25, push, keep_ok)

        def mark(line: bytes) -> bytes:
            out = filt(line)
            if out != line and "fault" not in marks:
                marks["fault"] = len(proxy.to_board)
            return out
        proxy.board_line_filter = mark
        hold, msg = zigzag_from_a_known_position(proxy, tmp_path)
        assert all(w in msg for w in words) and "soft reset" in msg and "position is unknown" in msg, msg
        assert "fault" in marks, "the proxy never sent the push"
        assert_stopped_by_hold_then_reset(emu)
        assert_no_line_after(proxy, marks["fault"])
        assert emu.machine_position_mm[0] < 39.0
        assert not hold.state.position_known
        hold.close()


# ---------------------------------------------------------------------------------------------- counting
def drop_ok(k: int) -> Callable[[bytes], bytes]:
    count = [0]

    def edit(line: bytes) -> bytes:
        if line.strip() == b"ok":
            count[0] += 1
            if count[0] == k:
                return b""
        return line
    return edit


def double_ok(every: bool = False, k: int = 0) -> Callable[[bytes], bytes]:
    count = [0]

    def edit(line: bytes) -> bytes:
        if line.strip() == b"ok":
            count[0] += 1
            if every or count[0] == k:
                return line + line
        return line
    return edit


@pytest.mark.slow  # the answer is overdue after the queued moves' time three times over: about 8 s
def test_a_lost_ok_is_a_fault_in_bounded_time_not_a_hang():
    """Issue #43 point 2: one ``ok`` lost.  cam waits no longer than the queued moves could take plus its
    margin, then stops the machine with one line."""
    with emulator_rig() as (emu, proxy):
        proxy.board_line_filter = drop_ok(12)
        session = open_session(proxy, reply_margin_s=1.0)
        t0 = time.monotonic()
        run_to_end(session, zigzag_job(SETTINGS, feed_mm_min=3000.0))
        msg = fault_message(session)
        assert "has not answered" in msg and "a reply was lost" in msg and "soft reset" in msg, msg
        assert time.monotonic() - t0 < 60
        assert any(text.startswith("soft reset") for _, text in emu.events)


def go_silent(k: int) -> Callable[[bytes], bytes]:
    """A board-line filter that passes nothing from the ``k``-th ``ok`` on (a board whose transmit line died)."""
    count = [0]

    def edit(line: bytes) -> bytes:
        if line.strip() == b"ok":
            count[0] += 1
        return b"" if count[0] >= k else line
    return edit


@pytest.mark.slow  # the silence must last the link's timeout_s (5 s), then the hold's own wait
def test_a_board_gone_silent_is_one_line_after_a_hold_and_a_reset(tmp_path):
    """Issue #43 points 1 and 2, a timeout: grbl stops answering (nothing at all, status polls included) mid-job.
    After ``timeout_s`` cam says so in one line, still sends a feed hold then a soft reset (the port is open: only
    the answers are gone), says it could not confirm the stop, and the position is unknown."""
    marks: dict = {}
    with emulator_rig() as (emu, proxy):
        silent = go_silent(20)

        def mark(line: bytes) -> bytes:
            out = silent(line)
            if not out and "silent" not in marks:
                marks["silent"] = len(proxy.to_board)
            return out
        hold = StateHold(tmp_path / "m.json", SETTINGS, "test")
        hold.record(replace(hold.state, position_known=True))
        session = open_session(proxy, state=hold)
        proxy.board_line_filter = mark
        t0 = time.monotonic()
        run_to_end(session, zigzag_job(SETTINGS))
        msg = fault_message(session)
        assert "stopped answering" in msg and "could not reach grbl" in msg and "position is unknown" in msg, msg
        assert time.monotonic() - t0 < 60
        later = bytes(proxy.to_board[marks["silent"]:])
        assert b"!" in later and b"\x18" in later[later.index(b"!"):], later  # a hold, then a reset
        assert_no_line_after(proxy, marks["silent"])
        assert any(text.startswith("soft reset") for _, text in emu.events)
        assert not hold.state.position_known
        hold.close()


def test_an_ok_with_nothing_outstanding_is_a_fault_never_credit():
    """Issue #43 point 2: one duplicated ``ok``.  It is found out at the latest when the count runs dry (an
    ``ok`` with no line outstanding), and the machine is stopped."""
    with emulator_rig() as (emu, proxy):
        proxy.board_line_filter = double_ok(k=20)
        session = open_session(proxy)
        run_to_end(session, zigzag_job(SETTINGS))
        msg = fault_message(session)
        assert "no line waiting for an answer" in msg and "soft reset" in msg, msg
        assert any(text.startswith("soft reset") for _, text in emu.events)


def test_every_ok_doubled_is_found_before_grbl_overflows():
    """Issue #43 point 2: every ``ok`` doubled.  cam turns grbl's buffer report on (``$10`` 1 -> 3: ``Bf:`` in
    every status report); a report that shows more bytes in grbl's receive buffer than cam counts unanswered
    is a fault; the machine stops and no byte sent was lost."""
    with emulator_rig() as (emu, proxy):
        session = open_session(proxy)
        assert emu.settings[10] == 3
        assert any("turned on grbl's buffer report" in e["text"] for e in session.state()["log"])
        proxy.board_line_filter = double_ok(every=True)
        run_to_end(session, zigzag_job(SETTINGS, segments=120, step_mm=0.3))
        msg = fault_message(session)
        assert ("receive buffer" in msg or "no line waiting" in msg) and "soft reset" in msg, msg
        assert any(text.startswith("soft reset") for _, text in emu.events)
        assert emu.overflow_bytes == 0, emu.events


def double_oks(numbers: set) -> Callable[[bytes], bytes]:
    count = [0]

    def edit(line: bytes) -> bytes:
        if line.strip() == b"ok":
            count[0] += 1
            if count[0] in numbers:
                return line + line
        return line
    return edit


@pytest.mark.parametrize("doubled", [{20, 21, 22}, {20, 22, 24, 26}, set(range(20, 40))],
                         ids=["three in a row", "every other", "twenty in a row"])
def test_duplicated_oks_never_overflow_grbls_receive_buffer(doubled):
    """Issue #43 point 2: ``ok``s doubled mid-stream while grbl's buffer is full (three in a row lost 33 bytes and
    merged lines before).  What cam sends is bounded by the last buffer report plus every line byte written
    after the ``?`` it answers, whatever the ``ok``s say: no byte is lost, and the extra ``ok`` is a fault."""
    with emulator_rig() as (emu, proxy):
        session = open_session(proxy)
        proxy.board_line_filter = double_oks(doubled)
        run_to_end(session, zigzag_job(SETTINGS, segments=120, step_mm=0.3))
        msg = fault_message(session)
        assert "soft reset" in msg, msg
        assert emu.overflow_bytes == 0, (emu.overflow_bytes, emu.events)
        refused = [answer for _, _, answer in emu.lines() if answer.startswith("error")]
        assert not refused, refused  # no line merged with another


# ---------------------------------------------------------------------------------------------- reports
def garble_status(k: int, text: bytes) -> Callable[[bytes], bytes]:
    count = [0]

    def edit(line: bytes) -> bytes:
        if line.startswith(b"<"):
            count[0] += 1
            if count[0] == k:
                return text + b"\r\n"
        return line
    return edit


BAD_REPORTS = [
    b"<Run|MPos:nan,0.000,0.000|FS:300,0>",
    b"<Run|MPos:inf,0.000,0.000|FS:300,0>",
    b"<Run|MPos:1e308,0.000,0.000|FS:300,0>",
    b"<Run|MPos:1.000,2.000|FS:300,0>",
    b"<Run|WPos:1.000,2.000,-inf>",
    b"<Run|FS:300,0>",
    b"<|MPos:0,0,0>",
    b"<Run|MPos:1.000,0.0",  # cut short, and no reset after it
]
HARMLESS_REPORTS = [
    b"<Run|MPos:1.000,0.000,0.000|Bf:15|FS:300,0>",
    b"<Run|MPos:1.000,0.000,0.000|Ov:100,100|FS:300,0>",
    b"<Run|MPos:1.000,0.000,0.000,0.000|FS:300,0|Pn:XYZ|A:SF|Ln:99|T:3>",
]


@pytest.mark.parametrize("report", BAD_REPORTS, ids=lambda r: r.decode())
def test_an_impossible_status_report_is_a_link_fault_and_the_machine_stops(report):
    """Issue #43 point 3: a report with an impossible position is a link fault: no reader thread dies, the
    job ends at once with one line, and grbl is stopped."""
    with emulator_rig() as (emu, proxy):
        session = open_session(proxy)
        proxy.board_line_filter = garble_status(6, report)
        run_to_end(session, zigzag_job(SETTINGS))
        msg = fault_message(session)
        assert "status report" in msg and "soft reset" in msg, msg
        assert session.grbl.link._reader.is_alive()


@pytest.mark.parametrize("report", HARMLESS_REPORTS, ids=lambda r: r.decode())
def test_fields_cam_does_not_need_are_ignored_when_malformed(report):
    """Issue #43 point 3: a malformed ``Bf``/``Ov`` or fields of grblHAL and FluidNC (a 4th axis, ``Pn``,
    ``A``, ``Ln``, ``T``) are ignored: the job finishes."""
    with emulator_rig() as (emu, proxy):
        session = open_session(proxy)
        proxy.board_line_filter = garble_status(6, report)
        run_to_end(session, zigzag_job(SETTINGS, segments=20))
        assert session.last_run["status"] == "finished", session.last_run


def test_status_report_fuzz_parses_or_refuses_never_crashes():
    """Issue #43 point 3, a fuzz test: 20,000 mutations of real reports (grbl, grblHAL, FluidNC) are parsed into
    finite positions or refused with a GrblError; nothing else is ever raised."""
    seeds = ["<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>",
             "<Run|MPos:12.500,-3.250,-1.000|Bf:14,100|FS:500,8000|Ov:100,100,100|A:S>",
             "<Hold:0|WPos:1.000,2.000,3.000,4.000|F:300|Pn:PXZ|Ln:12>",
             "<Jog|MPos:-1.000,-2.000,-3.000|FS:600,0|WCO:10.000,20.000,0.000|T:2|H:0,0>"]
    alphabet = "0123456789.,-+e|:<>naifINFMPosWXYZBfOv "
    rng = random.Random(43)
    parsed = refused = 0
    for _ in range(20000):
        text = list(rng.choice(seeds))
        for _ in range(rng.randint(1, 4)):
            op, at = rng.random(), rng.randrange(len(text) + 1)
            if op < 0.4 and text:
                text[min(at, len(text) - 1)] = rng.choice(alphabet)
            elif op < 0.7:
                text.insert(at, rng.choice(alphabet))
            elif text:
                del text[min(at, len(text) - 1)]
        try:
            status = parse_status("".join(text))
        except GrblError:
            refused += 1
            continue
        parsed += 1
        for value in (*status.mpos_mm, *status.wpos_mm, *status.wco_mm):
            assert math.isfinite(value)
        assert len(status.mpos_mm) == 3 and len(status.wpos_mm) == 3
    assert parsed > 1000 and refused > 1000


# ---------------------------------------------------------------------------------------------- firmware
def _have_grbl_avr() -> bool:
    return (GRBL_AVR / "run.sh").is_file() and sys.platform.startswith("linux")


@contextmanager
def firmware_rig(tmp_path: Path, **proxy_options) -> Iterator[tuple[Path, PtyProxy]]:
    """grbl 1.1h's own firmware on simavr (``../shared/grbl_avr``, built and started by its run.sh), behind
    the proxy.  Yields the folder of its logs (pins.csv, uart.log, stats.json)."""
    out, pty = tmp_path / "avr", tmp_path / "ttyGRBL"
    env = dict(os.environ, GRBL_AVR_WORK=str(tmp_path / "work"))
    if os.environ.get("GRBL_AVR_BIN_CACHE"):
        env["GRBL_AVR_WORK"] = os.environ["GRBL_AVR_BIN_CACHE"]
    subprocess.run(["bash", str(GRBL_AVR / "run.sh"), "start", "--pty", str(pty), "--out", str(out), "--fresh",
                    "--", "--quiet"], check=True, env=env, capture_output=True, timeout=600)
    try:
        deadline = time.monotonic() + 60
        while not pty.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        proxy = PtyProxy(str(pty), **proxy_options)
        try:
            yield out, proxy
        finally:
            close_grbl_machines()
            proxy.close()
    finally:
        subprocess.run(["bash", str(GRBL_AVR / "run.sh"), "stop", "--out", str(out)], env=env,
                       capture_output=True, timeout=60)


def uart_events(path: Path) -> list[tuple[float, str, str]]:
    rows = []
    for raw in path.read_text(errors="replace").splitlines():
        t, _, rest = raw.partition(",")
        direction, _, text = rest.partition(",")
        try:
            rows.append((float(t), direction, text))
        except ValueError:
            continue
    return rows


@pytest.mark.realtime
@pytest.mark.skipif(not _have_grbl_avr(), reason="needs ../shared/grbl_avr (grbl 1.1h on simavr)")
def test_real_grbl_firmware_error_mid_job_stops_within_its_deceleration(tmp_path):
    """Issue #43 point 1 on grbl 1.1h's own firmware: a line grbl refuses mid-job (the proxy turns a motion
    line into ``G5``).  cam sends a feed hold and a soft reset; the steps on the firmware's pins after the hold
    are no more than its deceleration from the feed (v^2 / 2a, grbl's default $120 = 10 mm/s^2), and the
    queued zigzag never finishes."""
    sys.path.insert(0, str(GRBL_AVR))
    import decode  # grbl_avr's pin decoder

    per_mm = 250.0  # grbl's defaults ($100-$102) after --fresh
    settings = SETTINGS.replace(mm_per_step_xy=1 / per_mm, mm_per_step_z=1 / per_mm,
                                travel=Travel(x_min_steps=-50000, x_max_steps=50000, y_min_steps=-50000,
                                              y_max_steps=50000, z_min_steps=-50000, z_max_steps=50000))
    feed_mm_min = 300.0
    with firmware_rig(tmp_path) as (out, proxy):
        proxy.host_line_filter = refuse_line(25)  # past the planner's 15 blocks
        session = open_session(proxy, settings)
        job = zigzag_job(settings, segments=40, step_mm=1.0, feed_mm_min=feed_mm_min)
        run_to_end(session, job, timeout_s=300)
        msg = fault_message(session)
        assert "error:20" in msg and "soft reset" in msg, msg
    uart = uart_events(out / "uart.log")
    t_error = next(t for t, d, text in uart if d == "<" and text.startswith("error:20"))
    t_hold = next(t for t, d, text in uart if d == ">" and t >= t_error and text.startswith("RT")
                  and ("!" in text or "0x21" in text))
    t_reset = next(t for t, d, text in uart if d == ">" and t >= t_hold and text.startswith("RT")
                   and "0x18" in text)
    steps = decode.points(str(out / "pins.csv"))
    at_hold = [p for p in steps if float(p[0]) <= t_hold]
    after = [p for p in steps if float(p[0]) > t_hold]
    assert at_hold and at_hold[-1][1] > 2 * per_mm, "the fault came before the zigzag was under way"
    x0, y0, z0 = at_hold[-1][1:4]
    path_mm = 0.0
    for p in after:
        path_mm += math.sqrt((p[1] - x0) ** 2 + (p[2] - y0) ** 2 + (p[3] - z0) ** 2) / per_mm
        x0, y0, z0 = p[1:4]
    v_mm_s, accel_mm_s2 = feed_mm_min / 60.0, 10.0
    assert path_mm <= v_mm_s ** 2 / (2 * accel_mm_s2) + 0.05, (path_mm, t_error, t_hold, t_reset)
    assert not [p for p in steps if float(p[0]) > t_reset]  # nothing moved after the reset
    end_x_mm = steps[-1][1] / per_mm
    assert end_x_mm < 30.0  # the queued zigzag never finished (it ends at X 40; the refused line is X 25)
