"""One port, one user; a lost position is never made known by accident (issue #43 points 4 and 5).

* Every command and the page lock the device itself (:class:`cam.drive.state.DeviceLock`), whatever state file
  they keep: a second opener of a grbl port is refused in one line naming the holder, and sends nothing.
* On a real port a missing state file is a position unknown; the port's state file records its machine file, a
  command without ``--machine`` uses the recorded one, and another one is refused unless ``--machine-changed``.
* A homing that fails never makes the position known, not even for a moment (grbl's ``$H`` with homing
  disabled: ``error:5``).
"""
from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import threading

import pytest

import cam
from cam.drive.session import MachineSession
from cam.drive.state import (
    MachineState, StateBusyError, StateHold, default_state_path, read_state, write_state,
)
from cam.sim.grbl import start_emulator
from conftest import ok, one_line_error, ROOT, run_cli
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from test_grbl_session import FAST, SETTINGS, url

# over 2 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES: set[str] = set()

FAKE_PARPORT = "/dev/cam-test-parport-43"  # a parallel port name no test machine has: nothing is ever opened
NEW_DEVICE = "/dev/null"  # a device that is there (a new machine's), never opened as a port by these tests


@pytest.fixture
def grbl():
    from cam.drive.grbl_machine import close_grbl_machines

    emu = start_emulator(speed=20.0, settings=FAST)
    yield emu
    close_grbl_machines()
    emu.stop()
    assert emu.error is None


def mill(tmp_path, name: str = "mill.toml", x_max_steps: int = 12000):
    """A machine file whose X travel (0..x_max_steps) tells it from the built-in settings (0..10000)."""
    path = tmp_path / name
    path.write_text(f"[travel]\nx_max_steps = {x_max_steps}\n")
    return path


# -- point 5: a missing state file on a real port ------------------------------------------------------------

def test_missing_state_file_on_real_port_is_position_unknown(tmp_path, state_home):
    # the first command on a new machine says in one line how to set its position, and opens nothing
    for argv in (["goto", "1,1,0"], ["zero"]):  # a jog is allowed (issue #45 point 3): test_recovery.py
        one_line_error(run_cli(*argv, "--port", NEW_DEVICE), "position is unknown", "no state file",
                       "cam home", "cam where --set X,Y,Z")
    # ... unless the device is not there at all: a typo in --port comes first
    for argv in (["jog", "X+", "10"], ["goto", "1,1,0"]):
        one_line_error(run_cli(*argv, "--port", FAKE_PARPORT), "cannot open parallel port", FAKE_PARPORT,
                       "No such file or directory", "modprobe ppdev")
    rep = json.loads(ok(run_cli("where", "--json", "--port", FAKE_PARPORT)).stdout)  # where opens nothing
    assert rep["position_known"] is False and "no state file" in rep["unknown_reason"]
    assert rep["state_file"] == str(state_home / "dev-cam-test-parport-43.json")
    # a typo in --state is a new (missing) file: position unknown too, nothing written
    typo = tmp_path / "mil.json"
    one_line_error(run_cli("goto", "1,1,0", "--port", NEW_DEVICE, "--state", typo), "position is unknown",
                   "typo in --state")
    assert not typo.exists()
    # the MAXIMUS board and grbl are real ports too; the mock, a simulated machine, starts at its home
    for port in ("maximus:/dev/cam-test-board", "grbl:/dev/cam-test-board"):
        assert not read_state(tmp_path / "none.json", SETTINGS, port).position_known
        with StateHold(tmp_path / "none.json", SETTINGS, "the test", port=port) as hold:
            assert not hold.state.position_known and not hold.existed
    with StateHold(tmp_path / "none.json", SETTINGS, "the test", port="mock") as hold:
        assert hold.state.position_known and hold.state.position_steps == (0, 0, 0)
    ok(run_cli("jog", "X+", "10"))
    # said once, the position is known and kept in the port's file
    ok(run_cli("where", "--set", "0,0,0", "--port", FAKE_PARPORT))
    st = read_state(state_home / "dev-cam-test-parport-43.json", SETTINGS)
    assert st.position_known and st.position_steps == (0, 0, 0) and st.machine is not None


def test_forgotten_machine_flag_uses_recorded_machine_file(grbl, tmp_path, state_home):
    """The issue's case: ``cam jog X+ 9000 --machine mill.toml``, then ``cam jog X+ 9000`` with --machine forgotten:
    the second runs with mill.toml (recorded in the port's state file), from where the first left the tool, and
    the travel check refuses it: 18,000 steps on an axis of 12,000."""
    from cam.drive.grbl_machine import close_grbl_machines

    machine = mill(tmp_path)
    port = url(grbl)
    ok(run_cli("where", "--set", "0,0,0", "--port", port, "--machine", machine))  # a new machine: say where
    ok(run_cli("jog", "X+", "9000", "--port", port, "--machine", machine))
    close_grbl_machines()  # as a new process
    moves = len(grbl.executed())
    one_line_error(run_cli("jog", "X+", "9000", "--port", port), "X travel (0..12000", "at X=9000",
                   "reaches 9000..18000")
    assert len(grbl.executed()) == moves and not any(t.startswith(("G53G0", "G53G1", "$J")) for _, t, _ in
                                                     grbl.lines()[-1:])  # no move was sent for it
    rep = json.loads(ok(run_cli("where", "--json", "--port", port)).stdout)
    assert rep["machine_file"] == str(machine) and rep["machine_steps"][0] == 9000 and rep["position_known"]
    # one state file for the port, whatever --machine said
    assert sorted(p.name for p in state_home.glob("*.json")) == [default_state_path(None, port).name]
    # a recorded machine file that is gone is one line naming it
    machine.unlink()
    one_line_error(run_cli("jog", "X-", "10", "--port", port), str(machine), "not there any more", "--machine")


def test_other_machine_file_on_real_port_refused_unless_changed(tmp_path, state_home):
    a, b = mill(tmp_path, "a.toml"), mill(tmp_path, "b.toml", 11000)
    ok(run_cli("where", "--set", "1,0,0", "--port", FAKE_PARPORT, "--machine", a))
    for argv in (["jog", "X+", "10"], ["where", "--set", "0,0,0"], ["zero"], ["goto", "1,1,0"]):
        one_line_error(run_cli(*argv, "--port", FAKE_PARPORT, "--machine", b), "refused", str(a), str(b),
                       "--machine-changed")
    rep = json.loads(ok(run_cli("where", "--json", "--port", FAKE_PARPORT)).stdout)  # the recorded one, untouched
    assert rep["machine_file"] == str(a) and rep["position_known"] and rep["machine_steps"][0] == 35
    # the user says the machine changed: b is recorded, and its position is unknown until said
    one_line_error(run_cli("goto", "1,1,0", "--port", FAKE_PARPORT, "--machine", b, "--machine-changed"),
                   "position is unknown", "the machine changed", str(a), str(b))
    rep = json.loads(ok(run_cli("where", "--json", "--port", FAKE_PARPORT)).stdout)
    assert rep["machine_file"] == str(b) and not rep["position_known"]
    one_line_error(run_cli("jog", "X+", "10", "--port", FAKE_PARPORT, "--machine", a), str(b), str(a))
    # the built-in settings (no --machine) are another machine too: only with --machine-changed
    ok(run_cli("where", "--set", "0,0,0", "--port", FAKE_PARPORT, "--machine-changed"))
    rep = json.loads(ok(run_cli("where", "--json", "--port", FAKE_PARPORT)).stdout)
    assert "built-in" in rep["machine_file"] and rep["position_known"]
    one_line_error(run_cli("jog", "X+", "10", "--port", FAKE_PARPORT, "--machine", b), "built-in", str(b))
    assert "--machine-changed" in ok(run_cli("jog", "--help")).stdout
    # on the mock, a simulated machine, another machine file is recorded as it comes
    st = tmp_path / "mock.json"
    ok(run_cli("jog", "X+", "10", "--state", st, "--machine", a))
    ok(run_cli("jog", "X+", "10", "--state", st, "--machine", b))
    assert read_state(st, cam.load_settings(b)).machine.path == str(b)


# -- point 5: a failed home --------------------------------------------------------------------------------

@pytest.mark.parametrize("before", ["unknown", "known"])
def test_failed_home_never_marks_position_known(grbl, tmp_path, before):
    """grbl with homing disabled answers $H with error:5: from the start of homing to its end, and after it, the
    session, its snapshot (what the page shows) and the state file never say the position is known; a go-to
    then is refused (a jog is allowed: issue #45 point 3)."""
    path = tmp_path / "m.json"
    state = MachineState(position_steps=(100, 0, 0))
    write_state(path, state if before == "known" else state.lost("an emergency stop ended the job"))
    hold = StateHold(path, SETTINGS, "the test", port=url(grbl))
    try:
        session = MachineSession(url(grbl), SETTINGS, state=hold)
        records = []
        save = hold.save
        hold.save = lambda st: (records.append(st.position_known), save(st))[1]  # every record, in order
        seen, done = [], threading.Event()

        def watch():
            while not done.is_set():
                snap = session.state()
                seen.append((snap["where"]["position_known"], snap["state"]))
                seen.append((read_state(path, SETTINGS).position_known, "file"))

        session.home()  # from here on (before: the known case is known), never known
        watcher = threading.Thread(target=watch)
        watcher.start()
        try:
            assert session.wait_idle(30)
        finally:
            done.set()
            watcher.join()
        assert session.last_run["status"] == "error" and "error:5" in session.last_run["messages"][0]
        assert records and not any(records), records
        assert seen and not any(known for known, _ in seen), [s for s in seen if s[0]][:5]
        assert not session.state()["where"]["position_known"] and not hold.state.homed
        assert "homing" in hold.state.unknown_reason
        with pytest.raises(cam.CamError, match="unknown"):
            session.go_to((0, 0, 0))
    finally:
        hold.close()
    assert not read_state(path, SETTINGS).position_known


# -- point 4: one port, one user ----------------------------------------------------------------------------

def test_second_opener_of_a_grbl_port_is_refused(grbl, tmp_path, state_home):
    port = url(grbl)
    write_state(tmp_path / "job.json", MachineState())
    holder = StateHold(tmp_path / "job.json", SETTINGS, "cam drill part.png", port=port)
    try:
        assert grbl.wait_for(lambda e: any("host opened" in text for _, text in e.events), 10)
        lines, events = len(grbl.lines()), len(grbl.events)
        # another state file (no --machine: the port's default one), in this process and in another one
        line = one_line_error(run_cli("where", "--port", port), "cam where refused", grbl.device_path,
                              f"pid {os.getpid()}", "cam drill part.png")
        assert "in use" in line
        proc = subprocess.run([sys.executable, "-m", "cam", "where", "--port", port], capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
        one_line_error(proc, "refused", f"pid {os.getpid()}", "cam drill part.png")
        for argv in (["jog", "X+", "10"], ["zero"], ["where", "--set", "0,0,0"], ["home"]):
            one_line_error(run_cli(*argv, "--port", port, "--state", tmp_path / "other.json"), "refused",
                           f"pid {os.getpid()}")
        with pytest.raises(StateBusyError, match="in use"):
            StateHold(tmp_path / "other.json", SETTINGS, "the test", port=port)
        assert grbl.wait_for(lambda e: len(e.events) == events and len(e.lines()) == lines, 0.2)  # nothing sent
        assert not (tmp_path / "other.json").exists() and not default_state_path(None, port).exists()
    finally:
        holder.close()
    # another program that locks the device (pyserial's exclusive=True) keeps cam out too
    fd = os.open(grbl.device_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        one_line_error(run_cli("where", "--port", port), "refused", "another program")
    finally:
        os.close(fd)
    # free again: a session takes it, and a second one (the page's, say) is refused while it runs a jog
    write_state(tmp_path / "page.json", MachineState())
    with StateHold(tmp_path / "page.json", SETTINGS, "cam serve", port=port) as hold:
        session = MachineSession(port, SETTINGS, state=hold)
        session.jog("x", 400)
        one_line_error(run_cli("where", "--port", port), "refused", "cam serve")
        assert session.wait_idle(30) and session.last_run["status"] == "finished", session.last_run
        assert hold.state.position_known and hold.state.position_steps == (400, 0, 0)


def test_the_page_locks_the_device_and_a_second_page_or_command_is_refused(grbl, tmp_path, state_home):
    """Point 4 through ``cam serve``'s own app (create_app): while the page holds a grbl port, a command with
    another state file, and a second page, are refused in one line naming the holder; the lock goes with the
    page."""
    from test_web import Server

    port = url(grbl)
    write_state(tmp_path / "page.json", MachineState())
    s = Server(tmp_path, settings=SETTINGS, machine_port=port, state_file=str(tmp_path / "page.json"))
    try:
        lines = len(grbl.lines())
        one_line_error(run_cli("where", "--port", port), "refused", "cam serve", f"pid {os.getpid()}")
        one_line_error(run_cli("jog", "X+", "10", "--port", port, "--state", tmp_path / "other.json"), "refused",
                       "cam serve")
        with pytest.raises(StateBusyError, match="cam serve"):
            Server(tmp_path, settings=SETTINGS, machine_port=port, state_file=str(tmp_path / "second.json"))
        assert len(grbl.lines()) == lines or all(t.startswith("?") for _, t, _ in grbl.lines()[lines:])
        assert not (tmp_path / "other.json").exists() and not (tmp_path / "second.json").exists()
    finally:
        s.close()
    ok(run_cli("where", "--port", port, "--state", tmp_path / "page.json"))  # the page gone, the port is free


def test_a_failed_home_from_the_cli_or_the_page_leaves_the_position_unknown(grbl, tmp_path):
    """Point 5, the issue's case from each front end: grbl with homing disabled answers ``$H`` with ``error:5``
    after an emergency stop; ``cam home`` is one line and the page's Home ends in an error, the position stays
    unknown, and a jog sent then is not booked as known."""
    from cam.drive.grbl_machine import close_grbl_machines
    from test_web import Server

    port, path = url(grbl), tmp_path / "m.json"
    write_state(path, MachineState(position_steps=(100, 0, 0)).lost("an emergency stop ended the job"))
    r = run_cli("home", "--port", port, "--state", path)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "error:5" in r.stderr.splitlines()[-1] and "position unknown" in r.stderr.splitlines()[-1], r.stderr
    assert not read_state(path, SETTINGS).position_known
    close_grbl_machines()  # as a new process
    s = Server(tmp_path, settings=SETTINGS, machine_port=port, state_file=str(path))
    try:
        status, st = s.call("POST", "/api/home", {})
        st = s.wait_idle(30) if status == 200 else st
        assert (status >= 400 and "error:5" in st["error"]) or \
            (st["last"]["status"] == "error" and "error:5" in st["last"]["messages"][0]), (status, st)
        status, st = s.call("GET", "/api/state")
        assert not st["where"]["position_known"], st["where"]
        status, st = s.call("POST", "/api/jog", {"axis": "x", "steps": 10, "unit": "steps"})
        assert status == 200, st
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and not st["where"]["position_known"], (st["last"], st["where"])
        assert not read_state(path, SETTINGS).position_known
    finally:
        s.close()


# -- issue #44 point 5: a state file names the machine, not only the device path --------------------------

ADAPTER = "usb-1a86_USB2.0-Serial-if00-port0"  # a CH340 adapter without a serial number, as udev names it


def by_id_folder(tmp_path, monkeypatch, **links):
    """A stand-in for /dev/serial/by-id (``$CAM_SERIAL_BY_ID``): a folder of links ``name -> device``."""
    folder = tmp_path / "by-id"
    folder.mkdir(exist_ok=True)
    for name, device in links.items():
        (folder / name).unlink(missing_ok=True)
        (folder / name).symlink_to(device)
    monkeypatch.setenv("CAM_SERIAL_BY_ID", str(folder))
    return folder


def board_state(state_home, name: str = ADAPTER) -> dict:
    return json.loads((state_home / f"grbl-by-id-{name}.json").read_text())


def test_state_file_named_after_serial_by_id_when_present(grbl, tmp_path, state_home, monkeypatch):
    from cam.drive.grbl_machine import close_grbl_machines

    folder = by_id_folder(tmp_path, monkeypatch, **{"usb-other-board-if00": tmp_path / "gone", ADAPTER:
                                                    grbl.device_path})
    # the device path given: the state file is named after the link in by-id that points at it
    ok(run_cli("where", "--set", "0,0,0", "--port", url(grbl)))
    ok(run_cli("jog", "X+", "400", "--port", url(grbl)))
    assert sorted(p.name for p in state_home.glob("*.json")) == [f"grbl-by-id-{ADAPTER}.json"]
    assert board_state(state_home)["position_steps"] == [400, 0, 0]
    # the by-id path given directly: the same state file, the same position (and one link to the device)
    close_grbl_machines()
    by_id_port = f"grbl:{folder / ADAPTER}?baud=115200"
    ok(run_cli("jog", "X+", "100", "--port", by_id_port))
    rep = json.loads(ok(run_cli("where", "--json", "--port", url(grbl))).stdout)
    assert rep["state_file"] == str(state_home / f"grbl-by-id-{ADAPTER}.json")
    assert rep["position_known"] and rep["machine_steps"][0] == 500
    assert sorted(p.name for p in state_home.glob("*.json")) == [f"grbl-by-id-{ADAPTER}.json"]
    # a MAXIMUS board's state is named the same way (it cannot say which board it is: the name is all there is)
    assert default_state_path(None, f"maximus:{grbl.device_path}").name == f"maximus-by-id-{ADAPTER}.json"
    # no link to the device: the state file is named after the device path, a new machine: position unknown
    (folder / ADAPTER).unlink()
    rep = json.loads(ok(run_cli("where", "--json", "--port", url(grbl))).stdout)
    assert rep["state_file"] == str(state_home / f"grbl{grbl.device_path.replace('/', '-')}.json")
    assert not rep["position_known"] and "no state file" in rep["unknown_reason"]


@pytest.fixture
def boards():
    """Start grbl emulators (``boards(build_info)``), each stopped at the end."""
    from cam.drive.grbl_machine import close_grbl_machines

    started = []

    def start(build_info: str):
        started.append(start_emulator(speed=20.0, settings=FAST, build_info=build_info))
        return started[-1]
    yield start
    close_grbl_machines()
    for emu in started:
        emu.stop()
        assert emu.error is None


def board_session(port: str, state_home):
    """A session on ``port`` with the port's default state file (the page's, or the Python API's)."""
    hold = StateHold(default_state_path(None, port), SETTINGS, "the test", port=port)
    return hold, MachineSession(port, SETTINGS, state=hold)


def board_lines(session) -> list[str]:
    return [e["text"] for e in session.state()["log"] if "another board" in e["text"]]


def test_a_different_grbl_board_on_the_same_path_is_position_unknown(boards, tmp_path, state_home, monkeypatch):
    """Two boards behind adapters with one by-id name (cheap CH340s have no serial number) on different days:
    their state file is one, and grbl's $I build info tells them apart."""
    from cam.drive.grbl_machine import close_grbl_machines

    mill_a = boards("MILL-A")
    folder = by_id_folder(tmp_path, monkeypatch, **{ADAPTER: mill_a.device_path})
    port = f"grbl:{folder / ADAPTER}"
    ok(run_cli("where", "--set", "0,0,0", "--port", port))
    ok(run_cli("jog", "X+", "400", "--port", port))
    recorded = board_state(state_home)
    assert recorded["board"] == "[VER:1.1h.20190830:MILL-A] [OPT:V,15,128]" and recorded["position_known"]
    close_grbl_machines()  # another day: mill A is unplugged, mill B is plugged in
    mill_a.stop()
    mill_b = boards("MILL-B")
    by_id_folder(tmp_path, monkeypatch, **{ADAPTER: mill_b.device_path})
    hold, session = board_session(port, state_home)
    try:
        lines = board_lines(session)  # said in one line, naming both boards
        assert len(lines) == 1 and "\n" not in lines[0], session.state()["log"]
        assert "MILL-A" in lines[0] and "MILL-B" in lines[0] and str(folder / ADAPTER) in lines[0], lines
        assert not session.state()["where"]["position_known"] and not hold.state.position_known
        moves = len(mill_b.executed())
        with pytest.raises(cam.CamError, match="position is unknown.*MILL-B.*MILL-A"):
            session.go_to((1, 0, 0))  # a jog is allowed (issue #45 point 3), a go-to is not
        assert len(mill_b.executed()) == moves
    finally:
        hold.close()
    st = board_state(state_home)
    assert st["board"] == "[VER:1.1h.20190830:MILL-B] [OPT:V,15,128]" and not st["position_known"]
    assert "MILL-A" in st["unknown_reason"] and "MILL-B" in st["unknown_reason"]
    # the command line says it in its one refusal line; once the position is said, mill B goes on as itself
    one_line_error(run_cli("goto", "1,0,0", "--port", port), "position is unknown", "another board", "MILL-A",
                   "MILL-B")
    ok(run_cli("where", "--set", "1,0,0", "--port", port))
    ok(run_cli("jog", "X+", "10", "--port", port))
    assert board_state(state_home)["position_known"]
    # a board renamed with $I= is another board too
    from cam.drive.grbl_machine import grbl_machine
    grbl_machine(port, SETTINGS).link.command("$I=mill b2")
    assert mill_b.build_info == "MILLB2"  # grbl's pre-parser: upper case, no spaces
    close_grbl_machines()
    one_line_error(run_cli("goto", "1,0,0", "--port", port), "position is unknown", "MILL-B]", "MILLB2")


def test_the_same_grbl_board_keeps_its_position(boards, tmp_path, state_home, monkeypatch):
    from cam.drive.grbl_machine import close_grbl_machines

    mill = boards("MILL-A")
    folder = by_id_folder(tmp_path, monkeypatch, **{ADAPTER: mill.device_path})
    port = f"grbl:{folder / ADAPTER}"
    ok(run_cli("where", "--set", "0,0,0", "--port", port))
    ok(run_cli("jog", "X+", "400", "--port", port))
    for again in ("the port opened again (grbl restarts)", "the same board on another device (power-cycled)"):
        close_grbl_machines()
        if again.startswith("the same board"):
            mill.stop()
            mill = boards("MILL-A")  # the same build info: the same board, re-enumerated on a new device
            by_id_folder(tmp_path, monkeypatch, **{ADAPTER: mill.device_path})
        hold, session = board_session(port, state_home)
        try:
            assert not board_lines(session), (again, session.state()["log"])
            where = session.state()["where"]
            assert where["position_known"], (again, where)
            assert hold.state.position_steps == (400, 0, 0)
            assert hold.state.board == "[VER:1.1h.20190830:MILL-A] [OPT:V,15,128]"
            session.jog("x", 100)
            assert session.wait_idle(30) and session.last_run["status"] == "finished", session.last_run
            assert hold.state.position_known and hold.state.position_steps == (500, 0, 0)
            session.jog("x", -100)
            assert session.wait_idle(30) and hold.state.position_steps == (400, 0, 0)
        finally:
            hold.close()
    assert board_state(state_home)["position_known"]
