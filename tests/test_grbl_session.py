"""A grbl board driven through the machine session (issue #30 point 2): every job kind streamed as G-code to
the grbl emulator (cam.sim.grbl) on a pty, the cut surface carved from what the emulator executed and compared
with what the input asks for, pixel by pixel; pause, stop, emergency stop, an alarm mid-job, a tool change
prompt, zero/offsets mirrored to grbl, homing, the feed override.

The emulator runs sped up (``speed``) except in the ``realtime`` test."""
from __future__ import annotations

import dataclasses
import time

import cv2
import numpy as np
import pytest

import cam
from cam.drive.grbl_machine import PATH_TOLERANCE_STEPS, close_grbl_machines, job_lines, mpos_to_steps
from cam.drive.session import MachineSession
from cam.drive.state import MachineState, StateHold, write_state
from cam.errors import CapabilityError, TravelError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.settings import Travel
from cam.sim.grbl import start_emulator
from cam.verify.pinlog import Motion
from conftest import ROOT, SAMPLES, assert_surface_equal, drawing_from_rows, expected_surface_2d, run_cli
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
    deadline = time.monotonic() + 30
    while session.state()["state"] != "paused":
        assert time.monotonic() < deadline, session.state()["state"]
        time.sleep(0.01)
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
    with pytest.raises(cam.CamError, match="unknown|home"):  # a jog is allowed (soft limits off), a go-to is not
        session.go_to([1, 1, 0], "mm")
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
    r = run_cli("drill", str(f), "--port", url(grbl), "--yes", "--state", str(known_at_home(tmp_path / "s.json")),
                cwd=tmp_path)  # its journal (a real port keeps one) beside the file, not in the repository
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
                    "--state", str(known_at_home(tmp_path / "s.json")), cwd=tmp_path)
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


# -- a stock machine whose space is negative (issue #45 point 4) ----------------------------------------------------

PROFILE_3018 = ROOT / "profiles" / "grbl-3018.toml"
GRBL_3018 = {100: 800.0, 101: 800.0, 102: 800.0, 110: 3000.0, 111: 3000.0, 112: 3000.0, 120: 500.0, 121: 500.0,
             122: 500.0, 130: 300.0, 131: 180.0, 132: 45.0}
"""grbl's own settings of the 3018 profile's machine: X travel -240000..0, Y 0..144000, Z 0..36000 steps."""


def small_files(tmp_path) -> dict[str, list]:
    """A file of each placed kind, small enough to run in a second on the emulator, and its ``cam drill`` options:
    a drawing (two lines 12 px long, 5 px apart), an HPGL star, an SVG stroke and a drill file."""
    png = tmp_path / "lines.png"
    img = np.full((8, 14), 255, np.uint8)
    img[1, 1:13] = img[6, 1:13] = 0
    cv2.imwrite(str(png), img)
    svg = tmp_path / "stroke.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="12mm" height="6mm" viewBox="0 0 12 6">'
                   '<path d="M1 1 L11 1 L11 5 L4 5" stroke="black" fill="none"/></svg>')
    drl = tmp_path / "holes.drl"
    drl.write_text("M48\nMETRIC\nT1C0.8\nT2C1.0\n%\nT1\nX1.0Y-1.0\nX9.0Y-2.0\nT2\nX4.0Y-5.0\nM30\n")
    return {"drawing": [png, "--depth", "2"], "hpgl": [SAMPLES / "inkscape_star.plt"], "svg": [svg], "drill": [drl]}


def _3018_cli(emu, state) -> list:
    return ["--port", url(emu), "--machine", PROFILE_3018, "--state", state]


def _state_of(path) -> dict:
    import json

    return json.loads(path.read_text())


def test_negative_machine_space_runs_a_drawing_hpgl_svg_and_drill_file_at_the_work_zero(tmp_path):
    """grbl's machine space is negative (its machine zero is the homing corner): X -300..0 mm.  Every job planned in
    its own frame (a drawing, and HPGL, SVG and drill files placed by their extent) used to be checked as if its
    home were machine (0, 0, 0) and was refused ("job leaves the machine travel at point 0 (x=134, ...)").  Placed
    at a work zero inside the space, each runs to its end: what grbl executed lies inside the travel, the travel to
    the job ends at the work zero, the cut lies right of and in front of it (its upper-left corner there for the
    vector files), and the job ends back where it started."""
    from cam.settings import load_settings

    s = load_settings(PROFILE_3018)
    lo = np.array([b[0] for b in s.travel.bounds_steps()])
    hi = np.array([b[1] for b in s.travel.bounds_steps()])
    emu = start_emulator(speed=200.0, settings=GRBL_3018)
    state = tmp_path / "s.json"
    try:
        for args in (("where", "--set=-150,20,10"), ("zero", "XYZ")):
            r = run_cli(*args, *_3018_cli(emu, state))
            assert r.returncode == 0, (args, r.stderr)
            close_grbl_machines()  # as a new process
        zero = np.array([-120000, 16000, 8000])
        assert _state_of(state)["offsets_steps"]["G54"] == zero.tolist()
        for kind, (path, *options) in small_files(tmp_path).items():
            start = np.array(_state_of(state)["position_steps"])
            n0 = len(emu.executed())
            r = run_cli("drill", path, "--yes", *options, *_3018_cli(emu, state), cwd=tmp_path)
            close_grbl_machines()
            assert r.returncode == 0 and "Traceback" not in r.stderr, (kind, r.stderr)
            blocks = [b for b in emu.executed()[n0:] if b.kind in ("G0", "G1", "jog")]
            assert blocks, kind
            base = start - np.array(mpos_to_steps(blocks[0].start_mm, s))
            ends = np.array([mpos_to_steps(b.end_mm, s) for b in blocks]) + base  # cam's machine frame
            assert np.all((ends >= lo) & (ends <= hi)), (kind, ends.min(axis=0), ends.max(axis=0))
            assert any((e == zero).all() for e in ends), kind  # the travel to the work zero ended there
            cut = ends[ends[:, 2] > zero[2]]  # below the work zero's surface
            assert len(cut) and np.all(cut[:, :2] >= zero[:2]), kind
            if kind != "drawing":  # placed by the upper-left corner of what they cut
                assert cut[:, :2].min(axis=0).tolist() == zero[:2].tolist(), kind
            assert ends[-1].tolist() == zero.tolist(), kind  # the job's home, where it started
            assert _state_of(state)["position_steps"] == zero.tolist(), kind
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None


def test_a_job_too_big_for_the_travel_span_is_refused_at_planning(tmp_path):
    """A job planned in its own frame is checked where it can be: its extent, its home included, fits the travel
    on each axis, or it is refused when it is planned in one line naming the axis, the travel and the job's
    extent in steps and mm (a drawing's pixel, an HPGL point's file:line:column, a drill file's hole and line),
    whatever the work zero: on the 3018 profile, whose space is negative, as on the default machine."""
    from cam.settings import load_settings

    s = load_settings(PROFILE_3018)
    files = small_files(tmp_path)
    travel = r"X travel is -240000\.\.0 steps \(-300\.\.0 mm, 300 mm\) and the job spans X 0\.\."
    cases = [
        ("drawing", JobOptions(depth=(2,), start_at=(3000, 0, 0)),
         r"^job leaves the machine travel at point \d+ \(x=3001, y=1, z=0 px = 240080, 80, 0 steps\): " + travel
         + r"240080 steps \(0\.\.300\.1 mm, 300\.1 mm\) from its home: it does not fit the machine wherever it is "
           r"placed$"),
        ("hpgl", JobOptions(scale=20.0),
         r"inkscape_star\.plt:1:10: point X1200 Y2200 \(plotter units\) lies outside the machine travel: " + travel),
        ("svg", JobOptions(scale=40.0), r"stroke\.svg: the drawing is 400\.00 x 160\.00 mm .*the travel is "
                                        r"300 x 180 mm \(make it smaller with --fit or --scale\)$"),
        ("drill", JobOptions(cut_depth_mm=50.0),
         r"^drill depth 50 mm and safe height 1 mm need Z -800\.\.40000 steps \(51\.000 mm\) from the surface, "
         r"more than the Z travel holds wherever the work zero is: the Z travel is 0\.\.36000 steps \(45\.000 mm\)$"),
    ]
    for kind, options, message in cases:
        path = files[kind][0]
        with pytest.raises(TravelError, match=message):
            prepare_job(path, options, s)
    wide = tmp_path / "wide.drl"
    wide.write_text("M48\nMETRIC\nT1C0.8\n%\nT1\nX1.0Y-1.0\nX150.0Y-2.0\nX310.0Y-2.0\nM30\n")
    with pytest.raises(TravelError, match=r"wide\.drl:8: hole 3 at X310\.000 Y-2\.000 mm lies outside the machine "
                                          r"travel: X travel is -240000\.\.0 steps "
                                          r"\(-300\.\.0 mm, 300 mm\) and the job spans X 0\.\.247200 steps"):
        prepare_job(wide, None, s)
    relief = JobOptions(heightmap=True, pixel_size_mm=3.0)  # 14 px of 3 mm: 42 mm wide, fits; 1.4 m does not
    assert prepare_job(files["drawing"][0], relief, s).plan.motion_extent()[0][0, 1] > 0
    with pytest.raises(TravelError, match=r"^job leaves the machine travel at point 1 \(x=13, y=7, z=\d+ px = "
                                          r"1040000, 560000, \d+ steps\): X travel is -240000\.\.0 steps"):
        prepare_job(files["drawing"][0], dataclasses.replace(relief, pixel_size_mm=100.0), s)
    # the command line: exit 2, one line, nothing sent to the machine (no port needed to plan)
    r = run_cli("drill", wide, "--yes", "--machine", PROFILE_3018, "--port", "mock", "--state", tmp_path / "m.json")
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "hole 3" in r.stderr, r.stderr


def test_a_job_placed_where_it_leaves_the_travel_is_refused_before_anything_moves(tmp_path):
    """Planned in its own frame, a job is checked where it runs: placed at a work zero 0.5 mm from the X travel's end
    (and, for the vector files, 0.5 mm below the top of Z, under their 1 mm travel height), every kind is refused
    in one line naming the axis, before anything moves: grbl executes nothing and gets no motion line."""
    emu = start_emulator(speed=200.0, settings=GRBL_3018)
    state = tmp_path / "s.json"
    files = small_files(tmp_path)
    try:
        for where, kinds, axis in (("--set=-0.5,20,10", ("drawing", "hpgl", "svg", "drill"), "X"),
                                   ("--set=-150,20,0.5", ("hpgl", "svg", "drill"), "Z")):
            for args in (("where", where), ("zero", "XYZ")):
                r = run_cli(*args, *_3018_cli(emu, state))
                assert r.returncode == 0, (args, r.stderr)
                close_grbl_machines()
            for kind in kinds:
                path, *options = files[kind]
                n_lines, n_blocks = len(emu.lines()), len(emu.executed())
                r = run_cli("drill", path, "--yes", *options, *_3018_cli(emu, state), cwd=tmp_path)
                close_grbl_machines()
                assert r.returncode == 2 and "Traceback" not in r.stderr, (kind, r.stderr)
                error = [line for line in r.stderr.splitlines() if not line.startswith("warning:")]
                assert len(error) == 1 and f"leaves the {axis} travel" in error[0] and "work zero" in error[0], \
                    (kind, r.stderr)
                assert len(emu.executed()) == n_blocks, kind
                sent = [text for _, text, _ in emu.lines()[n_lines:]]
                assert not [t for t in sent if t[:1] in "GXYZ" or t.startswith("$J")], (kind, sent)
    finally:
        close_grbl_machines()
        emu.stop()
    assert emu.error is None


def test_a_plan_made_in_its_own_frame_is_checked_from_where_it_starts(grbl):
    """A prepared job's plan planned in its own frame is not checked against the travel from the machine's (0, 0, 0)
    any more; started alone, without the prepared job's extent (its ChunkedPlan, its StepPlan, the pieces grbl
    runs), it is checked from where the tool stands before anything moves: on the 3018 profile, from grbl's
    machine zero (its corner), a job to the right of the tool leaves the X travel."""
    from cam.settings import load_settings

    s = load_settings(PROFILE_3018)
    prepared = prepare_job(SAMPLES / "inkscape_star.plt", None, s)
    for job in (prepared.plan, prepared.steps):
        with pytest.raises(TravelError, match="leaves the X travel|X travel"):
            MachineSession("mock", s).start(job)
    from cam.job.hpgl_stream import stream_hpgl

    session = MachineSession(url(grbl), s)
    pieces = stream_hpgl(SAMPLES / "inkscape_star.plt", settings=s, piece_points=8)  # a job kept as pieces
    for job in (prepared.plan, prepared.plan.job, prepared, pieces):
        with pytest.raises(TravelError, match="travel"):
            session.start(job)
    assert not grbl.executed()
