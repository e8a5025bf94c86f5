"""A grbl board driven through the machine session (issue #30 point 2): every job kind streamed as G-code to
the grbl emulator (cam.sim.grbl) on a pty, the cut surface carved from what the emulator executed and compared
with what the input asks for, pixel by pixel; pause, stop, emergency stop, an alarm mid-job, a tool change
prompt, zero/offsets mirrored to grbl, homing, the feed override.

The emulator runs sped up (``speed``) except in the ``realtime`` test."""
from __future__ import annotations

import time

import numpy as np
import pytest

import cam
from cam.drive.grbl_machine import PATH_TOLERANCE_STEPS, close_grbl_machines, job_lines, mpos_to_steps
from cam.drive.session import MachineSession
from cam.drive.state import MachineState, StateHold, write_state
from cam.errors import CapabilityError
from cam.settings import Travel
from cam.sim.grbl import start_emulator
from cam.verify.pinlog import Motion
from conftest import SAMPLES, assert_surface_equal, drawing_from_rows, expected_surface_2d, run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_every_job_kind_runs_on_grbl_through_its_own_points[board.drl]', 'test_every_job_kind_runs_on_grbl_through_its_own_points[inkscape_star.plt]', 'test_cli_home_on_grbl_then_a_move[grbl0]', 'test_home_outside_the_machine_files_travel_says_what_to_write[grbl0]', 'test_homing_enabled_grbl_needs_home_then_reads_back[grbl0]', 'test_every_job_kind_runs_on_grbl_through_its_own_points[bolt_plate.ngc]', 'test_an_alarm_mid_job_is_one_line', 'test_every_job_kind_runs_on_grbl_through_its_own_points[logo.svg]'}

SETTINGS = cam.MachineSettings()
STEPS_PER_MM = {100: 1 / SETTINGS.mm_per_step_xy, 101: 1 / SETTINGS.mm_per_step_xy,
                102: 1 / SETTINGS.mm_per_step_z}
HOMING = {22: 1, 130: 200.0, 131: 200.0, 132: 60.0}
HOMED_SETTINGS = SETTINGS.replace(travel=Travel(x_min_steps=-6920, x_max_steps=0, y_min_steps=0,
                                                    y_max_steps=6920, z_min_steps=0, z_max_steps=3821))
FAST = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0, **STEPS_PER_MM}




@pytest.fixture
def grbl(request):
    options = getattr(request, "param", {})
    emu = start_emulator(**{"speed": 20.0, "settings": FAST, **options})
    yield emu
    close_grbl_machines()
    emu.stop()
    assert emu.error is None


def url(emu) -> str:
    return f"grbl:{emu.device_path}"


def executed_motion(emu, start_steps=(0, 0, 0), base_mm=None) -> Motion:
    """What the emulator executed, as a point tool's positions in cam's steps from the job start: each block
    sampled at every step of its longest axis (the positions a step/dir drive passes through)."""
    blocks = [b for b in emu.executed() if b.kind in ("G0", "G1")]
    first = np.asarray(mpos_to_steps(base_mm if base_mm is not None else blocks[0].start_mm, SETTINGS), np.int64)
    pts = [np.zeros(3, np.int64)]
    for b in blocks:
        a = np.asarray(mpos_to_steps(b.start_mm, SETTINGS), np.float64) - first
        e = np.asarray(mpos_to_steps(b.end_mm, SETTINGS), np.float64) - first
        n = int(np.abs(e - a).max())
        for k in range(1, n + 1):
            pts.append(np.rint(a + (e - a) * k / n).astype(np.int64))
    pos = np.asarray(pts, np.int64) + np.asarray(start_steps, np.int64)
    return Motion(t_ns=np.arange(len(pos), dtype=np.int64), position_steps=pos, step_counts=np.zeros(3, np.int64))


DRAWING = ["..........", ".####.....", ".#..#..##.", ".####..##.", ".........."]


def depths(d) -> list[int]:
    return [3 + 2 * (i % 3) for i in range(len(d.objects))]


def two_d_job():
    d = cam.digitize(drawing_from_rows(DRAWING))
    job = cam.plan(d, depth=depths(d), settings=SETTINGS)
    return d, job


def test_a_drawing_cuts_on_grbl_exactly_what_it_asks(grbl):
    d, job = two_d_job()
    session = MachineSession(url(grbl), SETTINGS)
    start_mm = grbl.status_mpos() if hasattr(grbl, "status_mpos") else None
    session.start(job)
    assert session.wait_idle(60)
    assert session.last_run["status"] == "finished", session.last_run
    motion = executed_motion(grbl)
    got = cam.carve(motion, (job.height_px, job.width_px), SETTINGS, origin_px=job.origin_px)
    assert_surface_equal(got, expected_surface_2d(d, depths(d), SETTINGS))
    assert grbl.overflow_bytes == 0 and grbl.max_rx_bytes <= 128
    assert session.position_steps() == tuple(int(v) for v in job.points_steps[-1])
    del start_mm


def test_lines_join_runs_and_never_snap_off_the_steps():
    _, job = two_d_job()
    items = list(job_lines(job, (0, 0, 0), (0, 0, 0), SETTINGS))
    lines = [i for i in items if isinstance(i, str)]
    assert all(line.startswith(("G53G0", "G53G1")) for line in lines)
    assert len(lines) < len(job)  # collinear moves joined
    # every coordinate written is a whole number of steps
    for line in lines:
        for word in line[5:].replace("F", " F").split():
            pass
    assert all(len(line) < 70 for line in lines)


def test_pause_and_resume_mid_job(grbl):
    d, job = two_d_job()
    session = MachineSession(url(grbl), SETTINGS)
    session.start(job)
    assert grbl.wait_for(lambda e: len(e.executed()) >= 3, 20)
    session.pause()
    time.sleep(0.3)
    assert session.state()["state"] == "paused"
    n = len(grbl.executed())
    time.sleep(0.3)
    assert len(grbl.executed()) <= n + 1  # held: at most the block it was decelerating in
    session.resume()
    assert session.wait_idle(60)
    assert session.last_run["status"] == "finished"
    got = cam.carve(executed_motion(grbl), (job.height_px, job.width_px), SETTINGS, origin_px=job.origin_px)
    assert_surface_equal(got, expected_surface_2d(d, depths(d), SETTINGS))


def test_stop_keeps_the_position_and_sends_nothing_more(grbl):
    _, job = two_d_job()
    session = MachineSession(url(grbl), SETTINGS)
    session.start(job)
    assert grbl.wait_for(lambda e: len(e.executed()) >= 3, 20)
    session.stop()
    assert session.wait_idle(30)
    assert session.last_run["status"] == "stopped", session.last_run
    n_lines = len(grbl.lines())
    time.sleep(0.3)
    assert len(grbl.lines()) == n_lines
    # grbl kept its position (reset only once still): the session's is grbl's
    last = grbl.executed()[-1].end_mm
    assert session.position_steps() == mpos_to_steps(last, SETTINGS)
    assert not any("ALARM:3" in text for _, text in grbl.events)


def known_at_home(path):
    """A state file that says the tool stands at the home, position known (on a real port a missing one is a
    position unknown: issue #43 point 5); returns ``path``."""
    write_state(path, MachineState())
    return path


def running_with_state(grbl, tmp_path, blocks: int) -> tuple[MachineSession, StateHold]:
    """A session with a state file, running the small drawing on ``grbl`` once ``blocks`` blocks have executed."""
    _, job = two_d_job()
    hold = StateHold(known_at_home(tmp_path / "m.json"), SETTINGS, "test")
    session = MachineSession(url(grbl), SETTINGS, state=hold)
    session.start(job)
    assert grbl.wait_for(lambda e: len(e.executed()) >= blocks, 20)
    return session, hold


def test_emergency_stop_resets_at_once_and_the_position_is_unknown(grbl, tmp_path):
    session, hold = running_with_state(grbl, tmp_path, 2)
    session.emergency_stop()
    assert session.wait_idle(30)
    assert session.last_run["status"] == "emergency-stopped"
    assert not hold.state.position_known
    hold.close()


def test_an_alarm_mid_job_is_one_line(grbl):
    _, job = two_d_job()
    session = MachineSession(url(grbl), SETTINGS)
    grbl.trip_hard_limit(after_blocks=3)
    session.start(job)
    assert session.wait_idle(30)
    assert session.last_run["status"] == "error"
    msg = session.last_run["messages"][0]
    assert "ALARM:1" in msg and "hard limit" in msg and "\n" not in msg


def test_a_drill_file_prompts_at_the_tool_change(grbl, tmp_path):
    f = tmp_path / "two.drl"
    f.write_text("M48\nMETRIC\nT1C0.8\nT2C1.0\n%\nT1\nX1.0Y-1.0\nX2.0Y-1.0\nT2\nX3.0Y-2.0\nM30\n")
    prepared = cam.prepare_job(str(f), settings=SETTINGS)
    notes = []

    def on_prompt(p):
        notes.append(p.note)
        return "continue"

    session = MachineSession(url(grbl), SETTINGS, on_prompt=on_prompt)
    session.start(prepared)
    assert session.wait_idle(60)
    assert session.last_run["status"] == "finished", session.last_run
    assert len(notes) >= 1 and any("1.0" in n or "T2" in n for n in notes), notes
    # every hole is drilled: a feed move down at each hole's X, Y
    downs = [b for b in grbl.executed() if b.kind == "G1" and b.end_mm[2] < b.start_mm[2]]
    first = np.asarray(grbl.executed()[0].start_mm)
    xy = sorted({(round(b.end_mm[0] - first[0], 3), round(b.end_mm[1] - first[1], 3)) for b in downs})
    assert len(xy) == 3


def test_zero_offsets_and_goto_are_grbls_own(grbl, tmp_path):
    hold = StateHold(known_at_home(tmp_path / "m.json"), SETTINGS, "test")
    session = MachineSession(url(grbl), SETTINGS, state=hold)
    session.go_to((10, 5, 0), "mm", machine_coords=True)
    assert session.wait_idle(30) and session.last_run["status"] == "finished"
    session.zero("XY")
    session.go_to((2, 0, 0), "mm")
    assert session.wait_idle(30)
    w = session.where()
    assert w["work_mm"][0] == pytest.approx(2, abs=0.03) and w["work_mm"][1] == pytest.approx(0, abs=0.03)
    st = session.grbl.status()
    assert st.wpos_mm[0] == pytest.approx(2, abs=0.03)  # grbl's own G54 agrees (G10 L20)
    session.use_offset("G55")
    assert "G55" in " ".join(text for _, text, _ in grbl.lines())
    hold.close()


def test_feed_override_reaches_grbl(grbl):
    session = MachineSession(url(grbl), SETTINGS)
    session.feed_override(150)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and grbl._feed_ov != 150:
        time.sleep(0.05)
    assert grbl._feed_ov == 150
    with pytest.raises(cam.CamError, match="10..200"):
        session.feed_override(250)
    with pytest.raises(CapabilityError):
        MachineSession("mock", SETTINGS).feed_override(120)


@pytest.mark.parametrize("grbl", [{"settings": {**FAST, **HOMING}}], indirect=True)
def test_homing_enabled_grbl_needs_home_then_reads_back(grbl, tmp_path):
    hold = StateHold(tmp_path / "m.json", HOMED_SETTINGS, "test")
    session = MachineSession(url(grbl), HOMED_SETTINGS, state=hold)
    assert not hold.state.position_known
    with pytest.raises(cam.CamError, match="unknown|home"):
        session.jog("x", 10)
    session.home()
    assert session.wait_idle(60) and session.last_run["status"] == "finished", session.last_run
    assert hold.state.homed and hold.state.position_known and hold.state.running is None
    mpos = session.grbl.status().mpos_mm
    assert session.position_steps() == mpos_to_steps(mpos, HOMED_SETTINGS)
    hold.close()


def test_a_step_plan_is_refused_on_grbl(grbl):
    _, job = two_d_job()
    session = MachineSession(url(grbl), SETTINGS)
    with pytest.raises(CapabilityError, match="G-code"):
        session.start(cam.plan_steps(job))


def test_cli_drill_on_grbl(grbl, tmp_path):
    f = SAMPLES / "two_curves.png"
    r = run_cli("drill", str(f), "--port", url(grbl), "--yes", "--state", str(known_at_home(tmp_path / "s.json")))
    assert r.returncode == 0, r.stderr
    assert any(b.kind == "G1" for b in grbl.executed())


@pytest.mark.realtime
def test_a_drawing_at_real_speed_never_starves_grbls_planner():
    emu = start_emulator(speed=1.0, settings=FAST)
    try:
        d, job = two_d_job()
        session = MachineSession(url(emu), SETTINGS)
        session.start(job)
        assert session.wait_idle(120)
        assert session.last_run["status"] == "finished"
        got = cam.carve(executed_motion(emu), (job.height_px, job.width_px), SETTINGS, origin_px=job.origin_px)
        assert_surface_equal(got, expected_surface_2d(d, depths(d), SETTINGS))
        assert emu.overflow_bytes == 0
        assert emu.starvation_count == 0, emu.events
    finally:
        close_grbl_machines()
        emu.stop()


def test_cli_commands_chain_across_port_opens(grbl, tmp_path):
    """Each command opens the port anew (an Arduino restarts then: grbl's zero is where it stands); the state
    file carries the machine frame across, and grbl's own G54 is set by cam zero."""
    common = ["--port", url(grbl), "--state", str(known_at_home(tmp_path / "s.json"))]
    steps = []
    for args in (("goto", "3,2,0", "--unit", "mm", "--machine-coords"), ("zero", "XY"),
                 ("jog", "X+", "1", "--unit", "mm")):
        r = run_cli(*args, *common)
        assert r.returncode == 0, (args, r.stderr)
        steps.append(r.stdout)
        close_grbl_machines()  # as a new process: the next open restarts the board
    r = run_cli("where", "--use", "G55", *common)
    assert r.returncode == 0, r.stderr
    assert any(text == "G55" for _, text, _ in grbl.lines())
    close_grbl_machines()
    r = run_cli("where", "--json", "--use", "G54", *common)
    assert r.returncode == 0, r.stderr
    import json
    rep = json.loads(r.stdout)
    assert rep["machine_mm"][0] == pytest.approx(4, abs=0.03) and rep["machine_mm"][1] == pytest.approx(2, abs=0.03)
    assert rep["work_mm"][0] == pytest.approx(1, abs=0.03) and rep["work_mm"][1] == pytest.approx(0, abs=0.03)
    executed = [b for b in grbl.executed() if b.kind in ("G0", "G1")]
    assert executed, "nothing moved on grbl"


@pytest.mark.parametrize("grbl", [{"settings": {**FAST, **HOMING}}], indirect=True)
def test_cli_home_on_grbl_then_a_move(grbl, tmp_path):
    machine = tmp_path / "grbl.toml"
    t = HOMED_SETTINGS.travel
    machine.write_text(f"[travel]\nx_min_steps = {t.x_min_steps}\nx_max_steps = 0\ny_min_steps = 0\n"
                       f"y_max_steps = {t.y_max_steps}\nz_min_steps = 0\nz_max_steps = {t.z_max_steps}\n")
    common = ["--port", url(grbl), "--state", str(tmp_path / "s.json"), "--machine", str(machine)]
    r = run_cli("goto", "0,0,0", "--machine-coords", *common)  # a jog would be allowed (issue #45 point 3)
    assert r.returncode == 2 and "home" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = run_cli("home", *common)
    assert r.returncode == 0, r.stderr
    assert "homed" in r.stdout
    r = run_cli("jog", "X-", "1", "--unit", "mm", *common)
    assert r.returncode == 0, r.stderr
    mpos = grbl.executed()[-1].end_mm
    assert any(b.kind == "home" for b in grbl.executed())
    assert mpos[0] == pytest.approx(-1 - grbl.settings[27], abs=0.03)


@pytest.mark.parametrize("grbl", [{"settings": {**FAST, **HOMING}}], indirect=True)
def test_home_outside_the_machine_files_travel_says_what_to_write(grbl, tmp_path):
    r = run_cli("home", "--port", url(grbl), "--state", str(tmp_path / "s.json"))
    assert r.returncode == 2 and "x_min_steps = -6920" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_cli_feed_override_and_the_settings_warning(tmp_path):
    emu = start_emulator(speed=20.0, settings={110: 5000.0, 111: 5000.0, 112: 5000.0})  # grbl's own $100 = 250
    try:
        f = tmp_path / "two.drl"
        f.write_text("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y-1.0\nX2.0Y-1.0\nM30\n")
        r = run_cli("drill", str(f), "--port", url(emu), "--yes", "--feed-override", "150",
                    "--state", str(known_at_home(tmp_path / "s.json")))
        assert r.returncode == 0, r.stderr
        warning = [line for line in r.stderr.splitlines() if "grbl's settings differ" in line]
        assert len(warning) == 1 and "$100=250" in warning[0], r.stderr
        assert emu._feed_ov == 150
    finally:
        close_grbl_machines()
        emu.stop()
    r = run_cli("drill", str(f), "--yes", "--feed-override", "150")
    assert r.returncode == 2 and "grbl" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = run_cli("drill", str(f), "--yes", "--feed-override", "500")
    assert r.returncode == 2 and "--feed-override" in r.stderr


def test_cam_run_on_a_board_that_is_not_there_is_one_line():
    """cam.run runs on a board through a session (issue #45 point 3: test_recovery.py); a missing one is a
    PortError naming the device."""
    _, job = two_d_job()
    with pytest.raises(cam.errors.PortError, match="/dev/ttyUSB9"):
        cam.run(job, port="grbl:/dev/ttyUSB9")


def _on_path(points: np.ndarray, path: np.ndarray, tolerance_steps: float = 0.0) -> bool:
    """Every point of ``points`` ((N, 3) steps, in order) lies within ``tolerance_steps`` of the polyline ``path``
    ((M, 3) steps), in order (0: exactly on it)."""
    j = 0
    for p in points:
        while j + 1 < len(path):
            a, b = path[j].astype(np.float64), path[j + 1].astype(np.float64)
            ab, ap = b - a, p - a
            t = min(1.0, max(0.0, float(ap @ ab) / float(ab @ ab))) if ab.any() else 0.0
            if np.linalg.norm(ap - t * ab) <= tolerance_steps + 1e-9:
                break
            j += 1
        else:
            return bool(np.abs(p - path[-1]).max() <= tolerance_steps)
    return True


@pytest.mark.parametrize("name", ["inkscape_star.plt", "logo.svg", "bolt_plate.ngc", "board.drl", "matrix"])
def test_every_job_kind_runs_on_grbl_through_its_own_points(name, tmp_path):
    """HPGL, SVG, a G-code program, a drill file (tool changes answered) and a saved digitized matrix: grbl
    executes lines whose ends are the job's own points, in order, and every point of the job lies within
    PATH_TOLERANCE_STEPS of them (a staircase of steps goes out as the straight line it stands for, issue #45
    point 4), far fewer lines than points where the job has long straight or gently curved paths."""
    if name == "matrix":
        path = tmp_path / "ellipse.txt"
        cam.save_digitized(cam.digitize(cam.load_image(SAMPLES / "ellipse.png")), path)
    else:
        path = SAMPLES / name
    prepared = cam.prepare_job(str(path), settings=SETTINGS)
    emu = start_emulator(speed=200.0, settings=FAST)
    try:
        session = MachineSession(url(emu), SETTINGS, on_prompt=lambda p: "continue")
        session.start(prepared)
        assert session.wait_idle(120)
        assert session.last_run["status"] == "finished", session.last_run
        blocks = [b for b in emu.executed() if b.kind in ("G0", "G1")]
        first = np.asarray(mpos_to_steps(blocks[0].start_mm, SETTINGS), np.int64)
        executed = np.array([np.zeros(3, np.int64)] + [np.asarray(mpos_to_steps(b.end_mm, SETTINGS)) - first
                                                      for b in blocks])
        job = np.concatenate([np.asarray(p.points_steps, np.int64) for p in prepared.plan.job.pieces()])
        assert _on_path(job, executed, PATH_TOLERANCE_STEPS), name
        assert {tuple(p) for p in executed[1:]} <= {tuple(p) for p in job} | {(0, 0, 0)}  # no point of its own
        assert emu.overflow_bytes == 0
    finally:
        close_grbl_machines()
        emu.stop()


def test_a_lost_link_mid_job_is_one_line_and_the_position_unknown(grbl, tmp_path):
    session, hold = running_with_state(grbl, tmp_path, 3)
    grbl.unplug()
    assert session.wait_idle(30)
    assert session.last_run["status"] == "error", session.last_run
    msg = session.last_run["messages"][0]
    assert "lost" in msg and "\n" not in msg, msg
    assert not hold.state.position_known  # where grbl stopped is not known any more
    hold.close()


def test_closing_a_grbl_machine_stops_its_poller_before_the_link(grbl):
    """The poller's ``?`` never races the link's close: a write as the link closed raised a TypeError in
    pyserial, in a thread nobody saw (a warning in a CI run)."""
    from cam.drive.grbl_machine import GrblMachine

    m = GrblMachine(url(grbl), SETTINGS)
    time.sleep(0.4)  # a few polls
    close = m.link.close
    seen = []

    def closing():
        seen.append(m._poller.is_alive())
        close()

    m.link.close = closing
    m.close()
    assert seen == [False]


def test_a_grblhal_board_is_recognised_and_streamed_to_its_own_buffer():
    """grblHAL (issue #45 point 4): its banner ``GrblHAL 1.1f ['$' or '$HELP' for help]`` is a welcome, and its
    ``$I`` ``[OPT:VNMSL,35,1024]`` sizes the stream: more than grbl's 128 bytes go out unanswered, never more than
    its 1024, and the drawing cuts exactly what it asks."""
    emu = start_emulator(speed=20.0, settings=FAST, rx_buffer_bytes=1024, planner_blocks=35,
                         welcome="GrblHAL 1.1f ['$' or '$HELP' for help]")
    try:
        d, job = two_d_job()
        session = MachineSession(url(emu), SETTINGS)
        assert (session.grbl.link.rx_buffer_bytes, session.grbl.link.planner_blocks) == (1024, 35)
        session.start(job)
        assert session.wait_idle(60)
        assert session.last_run["status"] == "finished", session.last_run
        got = cam.carve(executed_motion(emu), (job.height_px, job.width_px), SETTINGS, origin_px=job.origin_px)
        assert_surface_equal(got, expected_surface_2d(d, depths(d), SETTINGS))
        # a job of many short lines: the planner's 35 blocks fill, then the receive buffer past grbl's 128 bytes
        from test_grbl_link_faults import zigzag_job

        zigzag = zigzag_job(SETTINGS, segments=300, step_mm=0.3, feed_mm_min=600.0)
        session.start(zigzag)
        assert session.wait_idle(120)
        assert session.last_run["status"] == "finished", session.last_run
        assert emu.overflow_bytes == 0 and 128 < emu.max_rx_bytes <= 1024, emu.max_rx_bytes
    finally:
        close_grbl_machines()
        emu.stop()
