"""Every flow on every machine (issue #45 point 3): finding the work again after an emergency stop, a limit stop or a
fault, without restarting anything.

* a jog is allowed while the position is unknown, soft limits off and said so, the position still unknown after
  it; go-tos and jobs stay refused (mock, grbl, MAXIMUS; the session, the CLI and the API);
* the page recovers after an emergency stop: Set position (``/api/set-position``) or Home, then it moves again;
* Home on a step/dir machine runs through the session (the page and ``cam home`` share it);
* ``cam where --set`` while ``cam serve`` drives the machine is one line naming the server and the page;
* ``cam.run`` runs a job on grbl and on the MAXIMUS board through a session.

Checked on what the machine did: the mock's decoded pin log, the grbl emulator's executed blocks, the MAXIMUS
emulator's port writes.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.drive.grbl_machine import close_grbl_machines, mpos_to_steps
from cam.drive.maximus.board import MAXIMUS_SETTINGS
from cam.drive.session import UNKNOWN_JOG_LINE, MachineSession
from cam.drive.state import MachineState, PositionUnknownError, StateHold, read_state, write_state
from cam.errors import CamError, CapabilityError, TravelError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.settings import load_settings
from cam.sim.grbl import start_emulator as start_grbl
from cam.sim.maximus import start_emulator as start_maximus
from cam.verify.command_log import commands_to_step_log
from cam.verify.pinlog import decode_pin_log, read_pin_log
from conftest import ROOT, SAMPLES, drawing_from_rows, run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from support.maximus_log import decode_port_log, hole_strokes
from test_web import EXCELLON, FAST, Server, _open, browser, page  # noqa: F401 (fixtures)

S = cam.MachineSettings()
GRBL_FAST = {110: 5000.0, 111: 5000.0, 112: 5000.0, 120: 500.0, 121: 500.0, 122: 500.0,
             100: 1 / S.mm_per_step_xy, 101: 1 / S.mm_per_step_xy, 102: 1 / S.mm_per_step_z}
LOST = "an emergency stop ended the test's job (steps may have been lost)"

SWITCHES = """
[inputs]
home_x = "!10"
home_y = "!11"
home_z = "!12"
estop = "!15"

[homing]
search_speed_z_mm_s = 0.5
latch_speed_z_mm_s = 0.05
offset_x_mm = 0.289
offset_z_mm = -3.14

[mock]
home_x_steps = 0
home_y_steps = 0
home_z_steps = -200
"""


def _wait(condition, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "the condition never held"
        time.sleep(0.01)


class _Machine:
    """A machine of one kind whose position is unknown: its port, settings, and where it says the tool is (x
    steps from where it started, read from what it did)."""

    def __init__(self, kind: str) -> None:
        self.kind, self.emu, self.settings = kind, None, S
        if kind == "grbl":
            self.emu = start_grbl(speed=20.0, settings=GRBL_FAST)
            self.port = f"grbl:{self.emu.device_path}"
        elif kind == "maximus":
            self.emu = start_maximus(speed=None)
            self.port, self.settings = f"maximus:{self.emu.device_path}", MAXIMUS_SETTINGS
        elif kind == "cmd":  # seed 004's command-byte unit, logged (issue #45 point 2)
            self.port, self.settings = "cmd:mock", load_settings(Path(__file__).parent.parent / "profiles" /
                                                                 "seed004-controller.toml")
        else:
            self.port = "mock"

    def moved_x(self, session: MachineSession) -> int:
        """The steps X moved in the last activity, from what the machine did."""
        if self.kind in ("mock", "cmd"):
            log = session.last_result.pin_log()
            if self.kind == "cmd":
                log = commands_to_step_log(log, self.settings)
            return int(decode_pin_log(log, self.settings).final_steps[0])  # steps from where the run started
        if self.kind == "grbl":
            b = [b for b in self.emu.executed() if b.kind in ("G0", "G1")][-1]
            return int(mpos_to_steps(b.end_mm, S)[0] - mpos_to_steps(b.start_mm, S)[0])
        return int(decode_port_log(self.emu.port_log())[-1][0])  # the board: pulses from power-up (it started at 0)

    def close(self) -> None:
        close_grbl_machines()
        if self.emu is not None:
            self.emu.stop()


@pytest.fixture(params=["mock", "grbl", "maximus", "cmd"])
def unknown_machine(request, tmp_path):
    m = _Machine(request.param)
    yield m
    m.close()


def test_jog_allowed_with_position_unknown_soft_limits_off(unknown_machine, tmp_path):
    m = unknown_machine
    state = tmp_path / "m.json"
    lo, hi = m.settings.travel.bounds_steps()[0]
    write_state(state, MachineState(position_steps=(hi - 20, 0, 0)).lost(LOST))  # near the X+ soft limit
    hold = StateHold(state, m.settings, "test", port=m.port)
    try:
        session = MachineSession(m.port, m.settings, state=hold)
        session.jog("x", 50)  # 30 steps beyond the soft limit: allowed, the position being unknown
        assert session.wait_idle(30)
        assert session.last_run["status"] == "finished", session.last_run
        assert m.moved_x(session) == 50
        texts = [line["text"] for line in session.state()["log"]]
        assert UNKNOWN_JOG_LINE in texts
        st = read_state(state, m.settings)
        assert not st.position_known and st.unknown_reason == LOST  # a jog does not make it known
        assert not session.where()["position_known"]
        for move in (lambda: session.go_to((0, 0, 0)), lambda: session.go_to_origin(),
                     lambda: session.zero("XYZ")):
            with pytest.raises(PositionUnknownError, match="unknown"):
                move()
        session.jog("x", -10)  # again: still allowed, still unknown
        assert session.wait_idle(30) and session.last_run["status"] == "finished", session.last_run
        assert not read_state(state, m.settings).position_known
        if m.kind in ("maximus", "cmd"):  # no switches cam reads: one line, nothing sent
            with pytest.raises(CapabilityError, match="cannot home|no switches"):
                session.home()
        session.set_position((0, 0, 0))  # the explicit recovery: known, soft limits back
        assert read_state(state, m.settings).position_known
        if m.kind != "maximus":  # the MAXIMUS travel is the board's whole range
            with pytest.raises(TravelError, match="travel"):
                session.jog("x", lo - 5)
    finally:
        hold.close()


def test_cli_jog_with_position_unknown_says_soft_limits_are_off(tmp_path):
    state = tmp_path / "m.json"
    write_state(state, MachineState().lost(LOST))
    r = run_cli("jog", "X-", "40", "--state", state, "--pin-log", tmp_path / "p.csv")
    assert r.returncode == 0, r.stderr
    assert UNKNOWN_JOG_LINE in r.stderr and "still unknown" in r.stdout
    assert decode_pin_log(read_pin_log(tmp_path / "p.csv"), S).position_steps[-1][0] == -40  # beyond X's limit 0
    st = read_state(state, S)
    assert not st.position_known and st.unknown_reason == LOST
    r = run_cli("goto", "1,1,0", "--state", state)
    assert r.returncode == 2 and "position is unknown" in r.stderr and "Traceback" not in r.stderr


# -- the page ------------------------------------------------------------------------------------------------


def _server_with_state(tmp_path: Path, settings=FAST, **config) -> Server:
    return Server(tmp_path, settings=settings, realtime=False, state_file=str(tmp_path / "m.json"), **config)


@pytest.mark.parametrize("port", ["mock", "cmd:mock"])
def test_page_recovers_after_estop_with_set_position_then_moves(tmp_path, port):
    """On the mock and on seed 004's command-byte unit (issue #45 point 3: every flow on every machine, from the
    page): an e-stop mid-job, a jog while unknown, Set position, a jog and a go-to, with no restart."""
    settings = FAST if port == "mock" else load_settings(ROOT / "profiles" / "seed004-controller.toml")
    s = _server_with_state(tmp_path, settings, machine_port=port)
    try:
        drl = tmp_path / "two.drl"
        drl.write_text(EXCELLON)
        status, up = s.upload("two.drl", drl.read_bytes())
        assert status == 200, up
        status, planned = s.call("POST", "/api/plan", {"job": up["job"], "options": {}})
        assert status == 200, planned
        status, st = s.call("POST", "/api/start", {"job": planned["job"]})
        assert status == 200, st
        _wait(lambda: s.session.state()["prompt"] is not None)  # mid-job: it waits at its tool change
        assert s.call("POST", "/api/estop", {})[0] == 200
        st = s.wait_idle()
        assert st["last"]["status"] == "emergency-stopped" and not st["where"]["position_known"], st["last"]
        status, err = s.call("POST", "/api/goto", {"xyz": [0, 0, 0]})
        assert status == 400 and "position is unknown" in err["error"] and "\n" not in err["error"]
        for said in ("Home on the page", "Set position on the page", "cam where --set X,Y,Z", "a jog is allowed"):
            assert said in err["error"], err  # what works, the page's own words first
        # a jog finds the work again (soft limits off), the position still unknown
        status, st = s.call("POST", "/api/jog", {"axis": "z", "steps": -5})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and not st["where"]["position_known"]
        assert any(UNKNOWN_JOG_LINE in line["text"] for line in st["log"])
        # Set position: known again, no restart; then it moves as before
        status, st = s.call("POST", "/api/set-position", {"xyz": [1, 2, 0], "unit": "mm"})
        assert status == 200 and st["where"]["position_known"] and not st["where"]["homed"], st
        assert st["where"]["machine_steps"] == [round(1 / settings.mm_per_step_xy), round(2 / settings.mm_per_step_xy), 0]
        assert read_state(tmp_path / "m.json", settings).position_known
        status, st = s.call("POST", "/api/jog", {"axis": "x", "steps": 10})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and st["where"]["machine_steps"][0] == round(1 / settings.mm_per_step_xy) + 10
        assert not any("soft limits are off" in line["text"] for line in st["log"][-2:])
        status, st = s.call("POST", "/api/goto", {"xyz": [0, 0, 0], "machine": True})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and st["where"]["machine_steps"] == [0, 0, 0]
        if port.startswith("cmd:"):  # the control unit has no switches cam reads: the page's Home says so
            status, err = s.call("POST", "/api/home", {})
            assert status in (400, 409) and "no switches" in err["error"] and "\n" not in err["error"], err
    finally:
        s.close()


def test_page_home_works_on_step_dir(tmp_path):
    machine = tmp_path / "switches.toml"
    machine.write_text(SWITCHES)
    settings = load_settings(machine)
    write_state(tmp_path / "m.json", MachineState(position_steps=(300, 200, 100)).lost(LOST))
    s = _server_with_state(tmp_path, settings)
    try:
        status, err = s.call("POST", "/api/goto", {"xyz": [0, 0, 0]})
        assert status == 400 and "position is unknown" in err["error"]
        status, st = s.call("POST", "/api/home", {})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and st["last"]["activity"] == "home", st["last"]
        where = st["where"]
        assert where["position_known"] and where["homed"] and where["machine_steps"] == [10, 0, -200], where
        texts = [line["text"] for line in st["log"]]
        assert any(t.startswith("homing Z: latch") for t in texts) and any(t.startswith("homed ZXY") for t in texts)
        saved = read_state(tmp_path / "m.json", settings)
        assert saved.position_known and saved.homed and saved.position_steps == (10, 0, -200)
        status, st = s.call("POST", "/api/goto", {"xyz": [1, 1, 0], "machine": True})  # moves again
        assert status == 200, st
        assert s.wait_idle()["last"]["status"] == "finished"
    finally:
        s.close()


def test_page_home_on_the_mock_without_switches_is_one_line(tmp_path):
    s = _server_with_state(tmp_path)
    try:
        status, err = s.call("POST", "/api/home", {})
        assert 400 <= status < 500 and "home switches" in err["error"] and "\n" not in err["error"], err
        assert not s.session.busy
    finally:
        s.close()


def test_api_set_position_checks_numbers(tmp_path):
    s = _server_with_state(tmp_path)
    try:
        before = read_state(tmp_path / "m.json", FAST) if (tmp_path / "m.json").exists() else None
        for body, words in (({"xyz": [1, "a", 0]}, "xyz Y must be a number"),
                            ({"xyz": [1, 10 ** 400, 0]}, "xyz Y must be a finite number"),
                            ({"xyz": [True, 0, 0]}, "xyz X must be a number"),
                            ({"xyz": "000"}, "xyz must be a list of 3 numbers"),
                            ({"xyz": [1, 2]}, "xyz must be a list of 3 numbers"),
                            ({}, "xyz must be a list of 3 numbers"),
                            ({"xyz": [1e308, 0, 0]}, "xyz X"),
                            ({"xyz": [0.5, 0, 0], "unit": "steps"}, "xyz X must be a whole number"),
                            ({"xyz": [1, 0, 0], "unit": "inch"}, "unit must be 'mm' or 'steps'"),
                            ({"xyz": [1, 0, 0], "unit": ["mm"]}, "unit must be 'mm' or 'steps'"),
                            ({"xyz": [-10, 0, 0]}, "outside the X travel")):
            status, err = s.call("POST", "/api/set-position", body)
            assert 400 <= status < 500 and words in err["error"] and "\n" not in err["error"], (body, status, err)
            assert s.session.position_steps() == (0, 0, 0)
            now = read_state(tmp_path / "m.json", FAST) if (tmp_path / "m.json").exists() else None
            assert now == before, body  # nothing written
        status, st = s.call("POST", "/api/set-position", {"xyz": [10, 20, 5], "unit": "steps"})
        assert status == 200 and st["where"]["machine_steps"] == [10, 20, 5]
        assert read_state(tmp_path / "m.json", FAST).position_steps == (10, 20, 5)
    finally:
        s.close()


def test_where_set_while_serve_runs_is_one_line(tmp_path):
    s = _server_with_state(tmp_path)
    try:
        r = run_cli("where", "--set", "0,0,0", "--state", tmp_path / "m.json")
        lines = [line for line in r.stderr.splitlines() if line.strip() and "first run only" not in line]
        assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
        assert f"cam serve (pid {os.getpid()})" in lines[0] and "Set position" in lines[0], lines[0]
    finally:
        s.close()
    assert run_cli("where", "--set", "0,0,0", "--state", tmp_path / "m.json").returncode == 0  # the server gone


# -- cam.run on every machine ---------------------------------------------------------------------------------


def test_cam_run_runs_on_grbl_and_maximus(tmp_path):
    d = cam.digitize(drawing_from_rows(["......", ".##...", ".##.#.", "......"]))
    job = cam.plan(d, depth=[3] * len(d.objects), settings=S)
    emu = start_grbl(speed=20.0, settings=GRBL_FAST)
    try:
        result = cam.run(job, port=f"grbl:{emu.device_path}")
        assert result.status == "finished" and result.writes > 0, result
        assert any(b.kind == "G1" for b in emu.executed())
        assert result.position_steps == tuple(int(v) for v in job.points_steps[-1])  # grbl's word: the job's end
        with pytest.raises(CamError, match="keeps no pin log"):
            result.pin_log()
    finally:
        close_grbl_machines()
        emu.stop()
    drl = tmp_path / "two.drl"
    drl.write_text("M48\nMETRIC\nT1C0.800\n%\nT1\nX1.0Y1.0\nX1.5Y1.0\nM30\n")
    board = start_maximus(speed=None)
    try:
        drill = prepare_job(drl, JobOptions(), MAXIMUS_SETTINGS)
        result = cam.run(drill, port=f"maximus:{board.device_path}")
        assert result.status == "finished" and result.writes == 2, result
        assert len(hole_strokes(board.port_log())) == 2
    finally:
        board.stop()


# -- the page in Chromium ---------------------------------------------------------------------------------------


@pytest.mark.browser
def test_page_set_position_button_makes_the_position_known(page, tmp_path):  # noqa: F811
    write_state(tmp_path / "m.json", MachineState().lost(LOST))
    s = _server_with_state(tmp_path)
    try:
        _open(page, s)
        page.wait_for_function("document.getElementById('pos-known').dataset.known === 'no'")
        page.fill("#setpos-x", "1")
        page.fill("#setpos-y", "2")
        page.fill("#setpos-z", "0")
        page.click("#set-position")
        page.wait_for_function("document.getElementById('pos-known').dataset.known === 'yes'")
        assert s.session.where()["machine_steps"] == [round(1 / FAST.mm_per_step_xy), round(2 / FAST.mm_per_step_xy), 0]
        page.click("button.jog[data-axis='x'][data-dir='1']")
        page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
        assert s.wait_idle()["last"]["status"] == "finished"
    finally:
        s.close()
