"""Probing (issue #46 points 1 and 3): ``MachineSession.probe_z`` / ``probe_grid`` and ``cam probe z|grid``.

The mock simulates the probe on the machine file's ``[mock] probe_surface`` (the pin closes while the tool tip is
at or below ``z0 + ax*x + ay*y + b*((x-cx)^2 + (y-cy)^2)``): a contact must lie within one Z step below the
formula, a grid map equal it within one step at every point, and the pin log decoded back into motion must show
the serpentine order, each probe made from the safe height and no move between points below it.  A probe that
touches nothing is one line with the position known; the e-stop ends probing (the pin, and the page's button);
the MAXIMUS board and ``cmd:`` refuse in one line.  grbl probes with ``G38.2`` on the emulator (one test at real
speed) and, in the slow tier, on grbl 1.1h's own firmware (``../shared/grbl_avr``, ``--probe-surface``)."""
from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.drive.grbl_machine import close_grbl_machines
from cam.drive.grbl_probe import parse_prb
from cam.kinds.gcode_export import format_mm
from cam.drive.machines import can
from cam.drive.ports import MockPort, surface_height_mm
from cam.drive.probe_grid import TRAVEL_MARGIN_MM, GridApproach
from cam.drive.probing import ProbeError, grid_axis_mm, serpentine
from cam.drive.session import MachineSession
from cam.drive.state import StateHold, read_state
from cam.errors import CapabilityError, SettingsError
from cam.job.heightmap_level import load_height_map
from cam.settings import settings_from_mapping
from cam.sim.grbl import start_emulator
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import SAMPLES, one_line_error, ok, run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)

FLAT = (-0.8, 0.0, 0.0, 0.0, 0.0, 0.0)
WARPED = (-0.2, 0.003, -0.002, 0.00005, 20.0, 15.0)
"""Tilted (0.3 mm over 100 mm in X, -0.2 over 100 in Y) and bowed (0.05 mm at 32 mm from its centre)."""
MACHINE = {"inputs": {"probe": "!13", "estop": "!15"}, "travel": {"z_min_steps": -2000, "z_max_steps": 2000}}


def mock_settings(surface=WARPED, **mock) -> cam.MachineSettings:
    return settings_from_mapping({**MACHINE, "mock": {"probe_surface": ",".join(str(v) for v in surface), **mock}})


def machine_file(tmp_path: Path, surface=WARPED, extra: str = "") -> Path:
    path = tmp_path / "probe-machine.toml"
    path.write_text(f'[inputs]\nprobe = "!13"\nestop = "!15"\n[travel]\nz_min_steps = -2000\nz_max_steps = 2000\n'
                    f'[mock]\nprobe_surface = "{",".join(str(v) for v in surface)}"\n{extra}')
    return path


def surface_at(surface, settings, x_steps, y_steps) -> float:
    return float(surface_height_mm(surface, x_steps * settings.mm_per_step_xy, y_steps * settings.mm_per_step_xy))


def assert_within_a_step(height_mm: float, surface_mm: float, settings) -> None:
    """The contact is the first Z step at or below the surface: at most one step below it, never above."""
    assert surface_mm - settings.mm_per_step_z - 1e-9 < height_mm <= surface_mm + 1e-9, (height_mm, surface_mm)


# -- the mock ------------------------------------------------------------------------------------------------

def test_mock_probe_z_finds_a_flat_surface_and_lifts_back():
    s = mock_settings(FLAT)
    session = MachineSession(MockPort(), s)
    r = session.probe_z(max_depth_steps=200)
    assert r.touched and r.start_steps == r.end_steps == (0, 0, 0)
    assert_within_a_step(r.height_mm(s), FLAT[0], s)
    assert session.position_steps() == (0, 0, 0) and session.last_run["status"] == "finished"
    assert session.last_run["probe"][0]["contact_steps"] == list(r.contact_steps)


def test_mock_probes_a_tilted_and_bowed_surface_within_a_step_everywhere():
    s = mock_settings(WARPED)
    session = MachineSession(MockPort(), s)
    points = [(0, 0), (1384, 0), (1384, 1038), (0, 1038), (692, 519), (3000, 2500)]
    results = session.probe_grid(points, -100, 300)
    assert [r.start_steps[:2] for r in results] == points
    for (x, y), r in zip(points, results):
        assert r.contact_steps[:2] == (x, y) and r.end_steps == (x, y, -100)
        assert_within_a_step(r.height_mm(s), surface_at(WARPED, s, x, y), s)
    assert len({r.contact_steps[2] for r in results}) > 3  # the surface is not flat: the contacts differ


def test_a_probe_that_never_touches_is_one_line_and_the_position_stays_known(tmp_path):
    s = mock_settings(FLAT)  # the surface 0.8 mm down, 51 steps
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        session = MachineSession(MockPort(), s, state=hold)
        with pytest.raises(ProbeError) as err:
            session.probe_z(max_depth_steps=20)
        assert "\n" not in str(err.value) and "no contact within 0.314 mm" in str(err.value)
        assert "position known" in str(err.value)
        assert session.position_steps() == (0, 0, 0)  # lifted back
        assert hold.state.position_known and hold.state.position_steps == (0, 0, 0)
        r = session.last_probe[0]
        assert not r.touched and r.depth_steps == 20


def test_the_probe_closed_before_it_moves_is_refused_in_one_line():
    s = mock_settings(FLAT)
    session = MachineSession(MockPort(), s)
    session.set_position((0, 0, 60))  # below the surface already: the pin reads closed
    with pytest.raises(ProbeError, match="closed before probing"):
        session.probe_z(max_depth_steps=50)
    assert session.position_steps() == (0, 0, 60)


def test_the_e_stop_pin_ends_probing_and_nothing_more_is_sent(tmp_path):
    s = mock_settings(FLAT, estop_after_s=0.4)  # the e-stop pin closes 0.4 s into the probe's run
    s = s.replace(start_speed_z_mm_s=0.1)  # a probe at 6 mm/min: a Z step every 157 ms, the surface 51 steps down
    port = MockPort()
    with StateHold(tmp_path / "state.json", s, "test") as hold:
        session = MachineSession(port, s, state=hold)
        with pytest.raises(ProbeError, match="emergency stop|estop"):
            session.probe_z(feed_mm_min=6.0, max_depth_steps=200)
        assert session.last_run["status"] == "emergency-stopped"
        assert not hold.state.position_known  # an emergency stop: where the tool is, nobody says
    log = port.pin_log()
    assert log.t_ns[-1] < 0.4e9  # nothing was written once the e-stop had closed
    z = decode_pin_log(log, s).position_steps[:, 2]
    assert 0 < z.max() < 51  # it went down, and stopped above the surface


def test_the_emergency_stop_button_ends_a_real_time_probe():
    s = mock_settings(FLAT)
    port = MockPort()
    session = MachineSession(port, s, realtime=True)
    session.probe_z(feed_mm_min=20.0, max_depth_steps=200, wait=False)  # 21 steps a second
    deadline = time.monotonic() + 60
    while port.switches is None or port.switches.position_steps[2] < 3:  # under way: it has stepped down
        assert time.monotonic() < deadline and session.busy, session.last_run
        time.sleep(0.005)
    session.emergency_stop()
    assert session.wait_idle(60)
    assert session.last_run["status"] == "emergency-stopped", session.last_run
    stopped = session.position_steps()[2]
    assert 3 <= stopped < 51 and port.switches.position_steps[2] == stopped  # booked where the steps stopped


def test_a_stop_during_probing_lifts_back_and_keeps_the_position():
    s = mock_settings(FLAT)
    port = MockPort()
    session = MachineSession(port, s, realtime=True)
    session.probe_z(feed_mm_min=20.0, max_depth_steps=200, wait=False)
    deadline = time.monotonic() + 60
    while port.switches is None or port.switches.position_steps[2] < 3:
        assert time.monotonic() < deadline and session.busy, session.last_run
        time.sleep(0.005)
    session.stop()
    assert session.wait_idle(60)
    assert session.last_run["status"] == "stopped"
    assert session.position_steps() == tuple(int(v) for v in port.switches.position_steps) == (0, 0, 0)


@pytest.mark.parametrize("port", ["maximus:/dev/ttyUSB9", "cmd:mock"])
def test_machines_without_a_probe_refuse_in_one_line(port, tmp_path):
    assert not can(port, "probes")
    assert can("mock", "probes") and can("/dev/parport0", "probes") and can("grbl:/dev/ttyUSB0", "probes")
    proc = run_cli("probe", "z", "--port", port, "--state", tmp_path / "state.json")
    one_line_error(proc, port, "no probe input")
    if port == "cmd:mock":
        session = MachineSession(port, cam.MachineSettings())
        with pytest.raises(CapabilityError, match="no probe input"):
            session.probe_z()


def test_the_mock_needs_a_probe_input_and_a_surface(tmp_path):
    session = MachineSession(MockPort(), cam.MachineSettings())
    with pytest.raises(ProbeError, match=r"no probe input.*\[inputs\]"):
        session.probe_z()
    bare = settings_from_mapping({"inputs": {"probe": "!13"}})
    with pytest.raises(CapabilityError, match="probe_surface"):
        MachineSession(MockPort(), bare).probe_z()
    for table, key in (({"mock": {"probe_surface": "-1"}}, "needs the probe's input pin"),
                       ({"inputs": {"probe": "!13"}, "mock": {"probe_surface": "-1,x"}}, "1 to 6 numbers"),
                       ({"inputs": {"probe": "!15", "estop": "!15"}}, "a pin of their own")):
        with pytest.raises(SettingsError, match=key):
            settings_from_mapping(table)


def test_the_probe_feed_on_a_step_dir_machine_is_at_most_zs_start_speed():
    s = mock_settings(FLAT)  # Z starts at 0.785 mm/s = 47.1 mm/min
    with pytest.raises(ProbeError, match="faster than Z's start speed"):
        MachineSession(MockPort(), s).probe_z(feed_mm_min=100.0)


def test_grid_geometry():
    assert grid_axis_mm(0, 40, 10).tolist() == [0, 10, 20, 30, 40]
    assert grid_axis_mm(5, 5, 10).tolist() == [0, 10]
    assert serpentine(2, 3) == [(0, 0), (1, 0), (1, 1), (0, 1), (0, 2), (1, 2)]


# -- the command line --------------------------------------------------------------------------------------

def test_cli_probe_z_sets_the_work_z_zero_on_the_surface_less_the_plate(tmp_path):
    machine, state = machine_file(tmp_path, FLAT), tmp_path / "state.json"
    proc = ok(run_cli("probe", "z", "--machine", machine, "--state", state, "--depth", "3"))
    s = cam.load_settings(machine)
    st = read_state(state, s)
    contact = st.offsets_steps["G54"][2]
    assert_within_a_step(-contact * s.mm_per_step_z, FLAT[0], s)
    assert "G54 Z zero set on the surface" in proc.stdout and "probe 1/1" in proc.stderr
    assert st.position_steps == (0, 0, 0) and st.position_known
    ok(run_cli("probe", "z", "--machine", machine, "--state", state, "--plate", "0.5"))
    assert read_state(state, s).offsets_steps["G54"][2] == contact + round(0.5 / s.mm_per_step_z)


def test_cli_probe_grid_writes_the_map_probed_serpentine_from_the_safe_height(tmp_path):
    machine, state, out, log = (machine_file(tmp_path, WARPED), tmp_path / "state.json", tmp_path / "map.json",
                                tmp_path / "grid.csv")
    proc = ok(run_cli("probe", "grid", "--machine", machine, "--state", state, "--area", "0,0,40,30", "--spacing",
                      "10", "--safe-height", "1.5", "--out", out, "--pin-log", log))
    s = cam.load_settings(machine)
    m = json.loads(out.read_text())
    assert (m["cam_height_map"], m["frame"], m["units"], m["spacing_mm"]) == (1, "machine", "mm", 10.0)
    assert m["machine"] == str(machine.resolve()) and m["reference_mm"] == 0.0 and m["time"]
    nx, ny = len(m["x_mm"]), len(m["y_mm"])
    assert (nx, ny) == (5, 4) and np.all(np.diff(m["x_mm"]) > 0) and np.all(np.diff(m["y_mm"]) > 0)
    assert load_height_map(out).shape == (ny, nx)  # the levelling's own reader takes it
    xs = np.rint(np.array(m["x_mm"]) / s.mm_per_step_xy).astype(int)
    ys = np.rint(np.array(m["y_mm"]) / s.mm_per_step_xy).astype(int)
    for j in range(ny):
        for i in range(nx):
            assert_within_a_step(m["height_mm"][j][i], surface_at(WARPED, s, xs[i], ys[j]), s)
    assert proc.stderr.count("probe ") >= nx * ny and "probe 20/20" in proc.stderr
    # the pin log decoded: the first probe from the safe height; each later point (GridApproach) reached across at
    # its travel height, a rapid down to its guard height, a guarded move at Z's start speed down to where its probe
    # starts, the probe at the probe feed down to its contact, a lift back to where the probe began
    per = s.mm_per_step_z
    safe_z, floor_z = -round(1.5 / per), -round(1.5 / per) + round(3.5 / per)
    approach = GridApproach.of(s)
    motion = decode_pin_log(read_pin_log(log), s)
    pos, t_ns = motion.position_steps, motion.t_ns
    order = [(int(xs[i]), int(ys[j])) for i, j in serpentine(nx, ny)]
    contacts = [-round(m["height_mm"][j][i] / per) for i, j in serpentine(nx, ny)]
    edges = np.flatnonzero(np.r_[True, np.any(pos[1:, :2] != pos[:-1, :2], axis=1), True])
    visits = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if (int(pos[a, 0]), int(pos[a, 1])) in order]
    assert [(int(pos[a, 0]), int(pos[a, 1])) for a, _ in visits] == order  # serpentine, each point once
    s_per_step = {"probe": per / (20.0 / 60.0), "guarded": per / s.start_speed_z_mm_s}  # 20 mm/min; start speed

    def s_per_step_between(i: int, j: int) -> float:
        return (t_ns[j] - t_ns[i]) / 1e9 / max(1, abs(int(pos[j, 2]) - int(pos[i, 2])))

    for k, (a, b) in enumerate(visits):
        zs = pos[a:b, 2]
        deepest = int(np.argmax(zs))
        assert zs[deepest] == contacts[k]  # the map is the contact
        top = int(np.flatnonzero(zs == safe_z)[0]) if k == 0 else 0  # the first: from the safe height
        assert np.all(np.diff(zs[top:deepest + 1]) >= 0) and np.all(np.diff(zs[deepest:]) <= 0)  # down, then up
        if k == 0:
            continue
        travel_z, guard_z, start_z, depth = approach.heights(contacts[:k], floor_z)
        stood = safe_z if k == 1 else approach.heights(contacts[:k - 1], floor_z)[2]  # where the probe before began
        assert zs[0] == min(travel_z, stood)  # across at the travel height (or higher, where it stood)
        assert travel_z < guard_z < start_z < contacts[k] <= start_z + depth
        at_guard, at_start = (a + int(np.flatnonzero(zs == z)[0]) for z in (guard_z, start_z))
        assert start_z in zs[deepest:].tolist()  # the lift back to where the probe began
        rapid, guarded, probe = (s_per_step_between(a, at_guard), s_per_step_between(at_guard, at_start),
                                 s_per_step_between(at_start, a + deepest))
        assert rapid < 0.5 * s_per_step["guarded"], (k, rapid)
        assert 0.9 * s_per_step["guarded"] <= guarded < 0.9 * s_per_step["probe"], (k, guarded)
        assert probe >= 0.9 * s_per_step["probe"], (k, probe)
    last = approach.heights(contacts[:-1], floor_z)[2]
    assert read_state(state, s).position_steps == (int(xs[0]), int(ys[-1]), last)  # the last point, lifted back


def test_grid_travel_stays_above_the_surface_plus_the_margin_everywhere(tmp_path):
    """On the mock with a domed surface (rising 0.6 mm between two neighbouring points: a travel at a fixed height
    above the previous contact would cut through it), ``cam probe grid``'s pin log decoded: at every write that
    moves the tool in X or Y (every point of every travel), its tip is at least the travel margin above the
    formula's surface there; it never goes below the surface by more than the contact's step; and each probe
    starts above the surface there, within the approach plus the steepest step between two contacts before it."""
    dome = (0.0, 0.0, 0.0, -0.002, 20.0, 15.0)  # up to 1.25 mm high in the middle, 0.6 mm rise over 10 mm
    machine, state, out, log = (machine_file(tmp_path, dome), tmp_path / "state.json", tmp_path / "map.json",
                                tmp_path / "grid.csv")
    ok(run_cli("probe", "grid", "--machine", machine, "--state", state, "--area", "0,0,40,30", "--machine-coords",
               "--spacing", "10", "--safe-height", "3", "--out", out, "--pin-log", log))
    s = cam.load_settings(machine)
    mx, my, mz = s.mm_per_step_axes
    h = load_height_map(out).height_mm
    steepest = max(np.abs(np.diff(h, axis=0)).max(), np.abs(np.diff(h, axis=1)).max())
    assert 0.5 < steepest < 1.0  # steep, and still a map levelling takes
    pos = decode_pin_log(read_pin_log(log), s).position_steps
    tip_mm = -pos[:, 2] * mz
    above_mm = tip_mm - surface_height_mm(dome, pos[:, 0] * mx, pos[:, 1] * my)
    travel = np.r_[False, np.any(pos[1:, :2] != pos[:-1, :2], axis=1)]
    assert travel.sum() > 1000
    clearance = float(above_mm[travel].min())
    assert clearance >= TRAVEL_MARGIN_MM - mz, f"a travel {clearance:.4f} mm above the surface"
    assert float(above_mm.min()) > -mz  # the deepest: a contact, within its step
    print(f"\ntravel clearance over the dome: min {clearance:.3f} mm, mean {above_mm[travel].mean():.3f} mm")


def test_cli_probe_grid_over_a_job_covers_where_it_would_be_drilled(tmp_path):
    machine, state, out = machine_file(tmp_path, FLAT), tmp_path / "state.json", tmp_path / "map.json"
    ok(run_cli("zero", "--at", "20,15,0", "--machine", machine, "--state", state))
    ok(run_cli("probe", "grid", "--machine", machine, "--state", state, "--over", SAMPLES / "board.drl",
               "--spacing", "20", "--margin", "2", "--out", out))
    m = json.loads(out.read_text())
    s = cam.load_settings(machine)
    job = cam.prepare_job(str(SAMPLES / "board.drl"), settings=s)
    _, cut = job.plan.motion_extent()
    w, h = ((cut[a, 1] - cut[a, 0]) * s.mm_per_step_xy for a in (0, 1))  # its upper-left hole at the work zero
    x0, y0 = round(20 / s.mm_per_step_xy) * s.mm_per_step_xy, round(15 / s.mm_per_step_xy) * s.mm_per_step_xy
    assert m["x_mm"][0] <= x0 - 2 + 0.02 and m["x_mm"][-1] >= x0 + w + 2 - 0.02
    assert m["y_mm"][0] <= y0 - 2 + 0.02 and m["y_mm"][-1] >= y0 + h + 2 - 0.02
    assert m["x_mm"][0] > x0 - 2 - 20 and m["y_mm"][-1] < y0 + h + 2 + 20  # not more than a spacing beyond
    assert np.allclose(m["height_mm"], FLAT[0], atol=s.mm_per_step_z)


def test_cli_probe_bad_input_is_one_line_exit_2(tmp_path):
    machine, state = machine_file(tmp_path, FLAT), tmp_path / "state.json"
    base = ("--machine", machine, "--state", state)
    for args, fragment in (
            (("grid", "--area", "10,0,0,10", "--out", tmp_path / "m.json"), "X0 must not exceed X1"),
            (("grid", "--area", "0,0,10", "--out", tmp_path / "m.json"), "four numbers"),
            (("grid", "--area", "0,0,10,10", "--out", tmp_path / "m.txt"), "must end in .json"),
            (("grid", "--area", "0,0,10,10"), "--out"),
            (("grid", "--area", "0,0,10,10", "--over", "x.drl", "--out", tmp_path / "m.json"), "not allowed with"),
            (("grid", "--over", tmp_path / "none.drl", "--out", tmp_path / "m.json"), "no such file"),
            (("grid", "--area", "0,0,10,10", "--out", tmp_path / "m.json", "--spacing", "0"), "--spacing"),
            (("grid", "--area", "0,0,900,10", "--out", tmp_path / "m.json"), "outside the X travel"),
            (("z", "--feed", "500"), "faster than Z's start speed"),
            (("z", "--depth", "-1"), "--depth"),
            (("z", "--depth", "0.1"), "no contact within")):
        one_line_error(run_cli("probe", *args, *base), fragment)
    assert not (tmp_path / "m.json").exists()
    for what in ("z", "grid"):
        help_ = ok(run_cli("probe", what, "--help"))
        assert "--feed" in help_.stdout and "--port" in help_.stdout
    assert "--safe-height" in run_cli("probe", "grid", "--help").stdout
    assert run_cli("probe").returncode == 2


# -- grbl ------------------------------------------------------------------------------------------------

GRBL_SETTINGS = cam.MachineSettings()
STEPS_PER_MM = {100: 1 / GRBL_SETTINGS.mm_per_step_xy, 101: 1 / GRBL_SETTINGS.mm_per_step_xy,
                102: 1 / GRBL_SETTINGS.mm_per_step_z}
FAST = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0, **STEPS_PER_MM}
GRBL_SURFACE = (-0.9, 0.004, 0.002, 0.0001, 10.0, -5.0)
"""In grbl's machine frame (its Y is cam's -Y)."""


def grbl_surface_mm(s, x_steps, y_steps) -> float:
    return float(surface_height_mm(GRBL_SURFACE, x_steps * s.mm_per_step_xy, -y_steps * s.mm_per_step_xy))


@pytest.fixture
def grbl(request):
    emu = start_emulator(**{"speed": 20.0, "settings": FAST, "probe_surface": GRBL_SURFACE,
                            **getattr(request, "param", {})})
    yield emu
    close_grbl_machines()
    emu.stop()
    assert emu.error is None


def test_grbl_probes_a_grid_with_g38_2(grbl):
    s = GRBL_SETTINGS
    session = MachineSession(f"grbl:{grbl.device_path}", s)
    points = [(0, 0), (500, 0), (500, 400), (0, 400)]
    results = session.probe_grid(points, -40, 200, feed_mm_min=60.0)
    for (x, y), r in zip(points, results):
        assert r.contact_steps[:2] == (x, y) and r.end_steps == (x, y, -40)
        assert_within_a_step(r.height_mm(s), grbl_surface_mm(s, x, y), s)
    probes = [text for _, text, answer in grbl.lines() if "G38.2" in text]
    assert len(probes) == 4 and all(t.startswith("G91G38.2Z-") and "F60" in t for t in probes)
    # between probes grbl travelled at the safe height (machine Z -40 steps: grbl's +0.628 mm)
    travels = [b for b in grbl.executed() if b.kind == "G0" and b.start_mm[:2] != b.end_mm[:2]]
    assert travels and all(abs(b.start_mm[2] - 40 * s.mm_per_step_z) < 1e-3 for b in travels)


def test_grbl_probes_a_grid_approached_from_the_contacts_before_each_point(grbl):
    """grbl and a grid's approach (GridApproach, as cam probe grid probes): the first point G38.2 from the safe height,
    each later one a G0 down to its guard height, a guarded G38.3 at Z's start speed to just above the surface
    expected, then G38.2 from there with its depth bounded; every contact within a step of the surface, and no XY
    travel below the travel height the contacts before it give."""
    s = GRBL_SETTINGS
    session = MachineSession(f"grbl:{grbl.device_path}", s)
    points = [(0, 0), (346, 0), (692, 0), (692, 346), (346, 346), (0, 346)]  # 10 mm apart, serpentine
    approach = GridApproach.of(s)
    results = session.probe_grid(points, -100, 250, feed_mm_min=60.0, approach=approach)
    contacts = [r.contact_steps[2] for r in results]
    for (x, y), r in zip(points, results):
        assert r.contact_steps[:2] == (x, y)
        assert_within_a_step(r.height_mm(s), grbl_surface_mm(s, x, y), s)
    for k in range(1, len(points)):
        _, _, start_z, depth = approach.heights(contacts[:k], -100 + 250)
        assert results[k].start_steps == (*points[k], start_z) and results[k].depth_steps == depth
    sent = [text for _, text, answer in grbl.lines() if "G38" in text]
    assert [t[:9] for t in sent] == ["G91G38.2Z"] + ["G91G38.3Z", "G91G38.2Z"] * (len(points) - 1), sent
    guarded = format_mm(max(approach.feed_mm_min, 60.0))  # Z's start speed, or the probe's feed when faster
    assert all(t.endswith(f"F{guarded}") for t in sent[1::2]) and all(t.endswith("F60") for t in sent[::2])
    travels = [b for b in grbl.executed() if b.kind == "G0" and b.start_mm[:2] != b.end_mm[:2]]
    assert len(travels) == len(points) - 1
    for k, b in enumerate(travels, start=1):  # grbl's Z is up: machine Z steps = -Z / mm per step
        travel_z = approach.heights(contacts[:k], -100 + 250)[0]
        assert -b.start_mm[2] / s.mm_per_step_z <= travel_z + 0.5, (k, b.start_mm, travel_z)


def test_grbl_probe_at_real_speed(grbl_realtime):
    s = GRBL_SETTINGS
    session = MachineSession(f"grbl:{grbl_realtime.device_path}", s)
    session.jog("z", 40)  # 0.26 mm above the surface
    assert session.wait_idle(30) and session.position_steps() == (0, 0, 40)
    t0 = time.monotonic()
    r = session.probe_z(feed_mm_min=60.0, max_depth_steps=60)
    assert time.monotonic() - t0 >= 0.25  # 0.26 mm at 1 mm/s, at grbl's own pace
    assert_within_a_step(r.height_mm(s), grbl_surface_mm(s, 0, 0), s)
    assert r.end_steps == (0, 0, 40) and session.position_steps() == (0, 0, 40)


@pytest.fixture
def grbl_realtime():
    emu = start_emulator(speed=1.0, settings=FAST, probe_surface=GRBL_SURFACE)
    yield emu
    close_grbl_machines()
    emu.stop()
    assert emu.error is None


def test_grbl_alarm_5_is_one_line_and_the_position_is_grbls(grbl, tmp_path):
    s = GRBL_SETTINGS
    with StateHold(tmp_path / "state.json", s, "test", port=f"grbl:{grbl.device_path}") as hold:
        session = MachineSession(f"grbl:{grbl.device_path}", s, state=hold)
        session.set_position((0, 0, 0))
        with pytest.raises(ProbeError) as err:
            session.probe_z(max_depth_steps=20)
        line = str(err.value)
        assert "\n" not in line and "no contact" in line and "ALARM:5" in line and "position known" in line
        assert hold.state.position_known and session.position_steps() == (0, 0, 0)
        assert grbl.state == "Idle"  # unlocked: it moves again
        r = session.probe_z(max_depth_steps=200)
        assert_within_a_step(r.height_mm(s), grbl_surface_mm(s, 0, 0), s)


def test_grbl_alarm_4_the_probe_touching_before_it_moves(grbl):
    s = GRBL_SETTINGS
    session = MachineSession(f"grbl:{grbl.device_path}", s)
    session.jog("z", 80)  # below the surface (0.9 mm = 58 steps)
    assert session.wait_idle(30)
    with pytest.raises(ProbeError, match="ALARM:4.*closed before it moved"):
        session.probe_z(max_depth_steps=20)
    assert session.position_steps() == (0, 0, 80) and grbl.state == "Idle"


def test_grbl_e_stop_during_probing(grbl):
    session = MachineSession(f"grbl:{grbl.device_path}", GRBL_SETTINGS)
    session.probe_z(feed_mm_min=20.0, max_depth_steps=200, wait=False)
    assert grbl.wait_for(lambda e: e.machine_position_mm[2] < -0.2, 60)
    session.emergency_stop()
    assert session.wait_idle(60)
    assert session.last_run["status"] == "emergency-stopped"


def test_the_emulator_probes_as_grbl_1_1_does():
    """G38.3 short of the surface: no alarm, [PRB:<end>:0]; $# keeps the last probe; G38.4 from in contact: the
    first step out of it; a probe target where the carriage stands: error:33; a probe without a feed: error:22."""
    from cam.drive.grbl_link import GrblError, GrblLink

    emu = start_emulator(speed=50.0, probe_surface="-5,0.01,-0.005,0.0002,50,40")
    link = GrblLink(f"grbl:{emu.device_path}", welcome_timeout_s=0.5)
    try:
        link.stream(["G21G90G0X10Y20Z0"])
        assert parse_prb(link.command("G38.3Z-4F200")) == ((10.0, 20.0, -4.0), False)
        assert link.status().state == "Idle"
        assert parse_prb(link.command("G38.2Z-20F200")) == ((10.0, 20.0, -4.6), True)
        assert "[PRB:10.000,20.000,-4.600:1]" in link.command("$#")
        assert parse_prb(link.command("G38.4Z0F200")) == ((10.0, 20.0, -4.596), True)  # one step above the surface
        for line, code in (("G53G38.2Z-9F100", 30), ("G91G38.2Z0F100", 33)):  # G53 with a probe; no move
            with pytest.raises(GrblError, match=f"error:{code}"):
                link.command(line)
        link.soft_reset()  # no feed given since
        with pytest.raises(GrblError, match="error:22"):
            link.command("G38.2Z-9")
    finally:
        link.close()
        emu.stop()
    assert emu.error is None


def test_the_emulators_probe_reports_as_grbl_does():
    assert parse_prb(["ok", "[PRB:1.000,-2.500,-4.288:1]"]) == ((1.0, -2.5, -4.288), True)
    assert parse_prb(["[PRB:0.000,0.000,0.000:0]"]) == ((0.0, 0.0, 0.0), False)
    assert parse_prb(["[GC:G0 G54]"]) is None


# -- grbl 1.1h's own firmware ------------------------------------------------------------------------------

@pytest.mark.realtime
def test_real_grbl_firmware_probes_a_map_within_a_step(tmp_path):
    from test_grbl_link_faults import GRBL_AVR, _have_grbl_avr

    if not _have_grbl_avr():
        pytest.skip("needs ../shared/grbl_avr (grbl 1.1h on simavr)")
    from support.serial_proxy import PtyProxy
    from test_grbl_firmware import SETTINGS as FW, open_firmware_session

    surface = "-2.5,0.01,-0.005,0.0002,20,10"
    out, pty = tmp_path / "avr", tmp_path / "ttyGRBL"
    env = dict(os.environ, GRBL_AVR_WORK=str(tmp_path / "work"))
    if env.get("GRBL_AVR_BIN_CACHE"):
        env["GRBL_AVR_WORK"] = env["GRBL_AVR_BIN_CACHE"]
    subprocess.run(["bash", str(GRBL_AVR / "run.sh"), "start", "--pty", str(pty), "--out", str(out), "--fresh",
                    "--", "--quiet", f"--probe-surface={surface}"], check=True, env=env, capture_output=True,
                   timeout=600)
    proxy = None
    try:
        deadline = time.monotonic() + 60
        while not pty.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        proxy = PtyProxy(str(pty))  # a pty of its own, as the firmware tests open the rig's
        session = open_firmware_session(proxy.device_path)
        per = FW.mm_per_step_xy
        points = [(0, 0), (int(20 / per), 0), (int(20 / per), int(10 / per)), (0, int(10 / per))]
        results = session.probe_grid(points, 0, int(4 / FW.mm_per_step_z), feed_mm_min=100.0)
        k = [float(v) for v in surface.split(",")]
        for (x, y), r in zip(points, results):
            want = float(surface_height_mm(k, x * per, -y * per))  # grbl's Y is cam's -Y
            assert_within_a_step(r.height_mm(FW), want, FW)
            assert r.end_steps == (x, y, 0)
        # as cam probe grid probes (GridApproach: each later point by a G0 and a guarded G38.3 from the contacts
        # before it, then G38.2): the same map within a step
        again = session.probe_grid(points, 0, int(4 / FW.mm_per_step_z), feed_mm_min=100.0,
                                   approach=GridApproach.of(FW))
        for (x, y), r, first in zip(points, again, results):
            assert_within_a_step(r.height_mm(FW), float(surface_height_mm(k, x * per, -y * per)), FW)
            assert abs(r.contact_steps[2] - first.contact_steps[2]) <= 1
    finally:
        close_grbl_machines()
        if proxy is not None:
            proxy.close()
        subprocess.run(["bash", str(GRBL_AVR / "run.sh"), "stop", "--out", str(out)], env=env,
                       capture_output=True, timeout=60)


# -- cam probe tool: a new tool keeps the work Z ------------------------------------------------------------

LONGER_MM = 1.2
"""The second tool is this much longer: on the mock the tip of a longer tool touches the surface with the carriage
that much higher, the same as the surface that much higher under the first tool (z0 + 1.2 in the machine file)."""


def _raised(surface, by_mm):
    return (surface[0] + by_mm, *surface[1:])


def test_probe_tool_shifts_the_work_z_by_the_difference_of_contacts(tmp_path):
    """Tool 1 sets the work Z on the plate; the tool moves away; tool 2 (1.2 mm longer) is probed at the same XY
    (travel there lifted) and the work Z moves up by 1.2 mm within a step: tool 2's tip at work Z 0 is on the
    surface."""
    s1 = mock_settings(WARPED)
    state = tmp_path / "state.json"
    with StateHold(state, s1, "test") as hold:
        session = MachineSession(MockPort(), s1, state=hold)
        session.go_to((500, 400, 0), "steps")
        assert session.wait_idle(30) and session.last_run["status"] == "finished"
        r1 = session.probe_work_z(0.0, max_depth_steps=300)
        st = hold.state
        assert st.tool_probe.contact_steps == r1.contact_steps and st.tool_probe.plate_mm == 0
        assert st.work_zero_steps()[2] == r1.contact_steps[2]
        session.go_to((10, 5, -2), "mm")  # the tool change happens elsewhere
        assert session.wait_idle(30)
    assert read_state(state, s1).tool_probe.contact_steps == r1.contact_steps  # kept in the file
    s2 = mock_settings(_raised(WARPED, LONGER_MM))  # the longer tool
    with StateHold(state, s2, "test") as hold:
        session = MachineSession(MockPort(), s2, state=hold)
        zero_before = hold.state.work_zero_steps()
        r2 = session.probe_tool()
        assert r2.start_steps[:2] == r1.contact_steps[:2]  # the same XY
        assert r2.start_steps[2] <= r1.contact_steps[2] - round(5 / s2.mm_per_step_z)  # travelled there lifted
        assert session.last_run["status"] == "finished"
        zero = hold.state.work_zero_steps()
        assert zero[:2] == zero_before[:2]
        assert zero[2] == zero_before[2] + (r2.contact_steps[2] - r1.contact_steps[2])
        per = s2.mm_per_step_z
        assert abs((zero_before[2] - zero[2]) * per - LONGER_MM) <= per + 1e-9
        # the new tool's tip at work Z 0 over the probe point is on the surface it touches, within a step
        assert_within_a_step(-zero[2] * per, surface_at(_raised(WARPED, LONGER_MM), s2, *r1.contact_steps[:2]), s2)
        assert hold.state.tool_probe.contact_steps == r2.contact_steps
        assert any("probe tool: work Z shifted" in line["text"] for line in session.state()["log"])
        assert session.position_steps() == r2.end_steps == r2.start_steps  # lifted back over the plate


def test_probe_tool_counts_a_different_plate_and_needs_a_first_probe(tmp_path):
    """The first tool probed on a 0.5 mm plate (the mock's surface 0.5 mm higher: the plate's top), the same tool
    probed again on the work itself with --plate 0: the work Z stays within a step."""
    s = mock_settings(_raised(FLAT, 0.5))
    state = tmp_path / "state.json"
    with StateHold(state, s, "test") as hold:
        session = MachineSession(MockPort(), s, state=hold)
        with pytest.raises(cam.errors.PlanError, match="probe the first tool with cam probe z"):
            session.probe_tool()
        r1 = session.probe_work_z(0.5, max_depth_steps=300)
        per = s.mm_per_step_z
        assert hold.state.work_zero_steps()[2] == r1.contact_steps[2] + round(0.5 / per)
        z1 = hold.state.work_zero_steps()[2]
    s = mock_settings(FLAT)  # the plate taken away
    with StateHold(state, s, "test") as hold:
        session = MachineSession(MockPort(), s, state=hold)
        session.probe_tool(0.0)
        assert abs(hold.state.work_zero_steps()[2] - z1) <= 1
        with pytest.raises(cam.errors.PlanError, match="plate"):
            session.probe_tool(-1)
        session.set_position((0, 0, 0))  # a new machine frame: the old contact means nothing any more
        assert hold.state.tool_probe is None
        with pytest.raises(cam.errors.PlanError, match="said anew"):
            session.probe_tool()


def test_cli_probe_tool_keeps_the_work_z_for_a_longer_tool(tmp_path):
    machine, state = machine_file(tmp_path, FLAT), tmp_path / "state.json"
    one_line_error(run_cli("probe", "tool", "--machine", machine, "--state", state), "cam probe z")
    ok(run_cli("probe", "z", "--machine", machine, "--state", state, "--plate", "0.3"))
    s = cam.load_settings(machine)
    before = read_state(state, s)
    machine_file(tmp_path, _raised(FLAT, LONGER_MM))  # the longer tool in the spindle
    proc = ok(run_cli("probe", "tool", "--machine", machine, "--state", state))
    after = read_state(state, s)
    per = s.mm_per_step_z
    shift = before.work_zero_steps()[2] - after.work_zero_steps()[2]
    assert abs(shift * per - LONGER_MM) <= per + 1e-9 and f"Z zero moved {shift * per:+.4g} mm up" in proc.stdout
    # the tip at work Z 0 is the plate's thickness below the contact: on the work
    assert_within_a_step(-(after.work_zero_steps()[2] - round(0.3 / per)) * per, FLAT[0] + LONGER_MM, s)
    machine_file(tmp_path, _raised(FLAT, LONGER_MM - 0.5))  # a tool 0.5 mm shorter, 0.1 mm clearance
    proc = run_cli("probe", "tool", "--machine", machine, "--state", state, "--clearance", "0.1")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr  # the changed machine file's warning, then:
    assert proc.stderr.splitlines()[-1].startswith("cam: error: probe: no contact within"), proc.stderr
    assert read_state(state, s).work_zero_steps() == after.work_zero_steps()
    for args, fragment in ((("--plate", "-1"), "--plate"), (("--clearance", "0"), "--clearance")):
        one_line_error(run_cli("probe", "tool", "--machine", machine, "--state", state, *args), fragment)
    assert "--clearance" in ok(run_cli("probe", "tool", "--help")).stdout


def test_grbl_probe_z_and_probe_tool_set_grbls_own_work_z(grbl, tmp_path):
    """On grbl the work Z is set from the probe's end (G10 L2, grbl's G54 too): probe Z, then probe tool on the
    same tool keeps it."""
    s = GRBL_SETTINGS
    with StateHold(tmp_path / "state.json", s, "test", port=f"grbl:{grbl.device_path}") as hold:
        session = MachineSession(f"grbl:{grbl.device_path}", s, state=hold)
        if not hold.state.position_known:
            session.set_position((0, 0, 0))
        r = session.probe_work_z(0.0, 60.0, 200)
        assert session.last_run["status"] == "finished", session.last_run
        assert hold.state.work_zero_steps()[2] == r.contact_steps[2]
        assert any(t.startswith("G10L2P1Z") for _, t, _ in grbl.lines())
        session.probe_tool(None, 60.0, clearance_mm=2.0)
        assert session.last_run["status"] == "finished", session.last_run
        assert abs(hold.state.work_zero_steps()[2] - r.contact_steps[2]) <= 1
        assert hold.state.tool_probe is not None
