"""Machines as one protocol (issue #45 points 1 and 2): one registry of back ends, capabilities instead of port
names, and seed 004's command-byte control unit (``cmd:``) as the proof that a new machine is one module."""
import re

import numpy as np
import pytest

import cam
from cam.drive.machines import CAPABILITY_MEANINGS, REGISTRY, backend_of, can, open_port, port_kind
from cam.drive.session import MachineSession
from cam.errors import CapabilityError, PortError
from cam.settings import load_settings
from cam.verify.command_log import commands_to_step_log

from conftest import ROOT, SAMPLES, assert_surface_equal, drawing_from_rows, expected_surface_2d, ok, one_line_error, \
    run_cli

SEED004 = ROOT / "profiles" / "seed004-controller.toml"


def test_the_command_line_the_page_and_the_session_never_name_a_port():
    """The issue's own check: ``grep -rnE '"(grbl|maximus|parport|mock)"' cam/cli cam/web cam/drive/session.py``
    finds nothing (they ask the registry for capabilities)."""
    pattern = re.compile(r'"(grbl|maximus|parport|mock)"')
    files = [*sorted((ROOT / "cam" / "cli").rglob("*")), *sorted((ROOT / "cam" / "web").rglob("*")),
             ROOT / "cam" / "drive" / "session.py"]
    found = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in files if p.is_file() and p.suffix in (".py", ".js", ".html")
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert not found, "\n".join(found)


@pytest.mark.parametrize("name, kind", [
    ("mock", "mock"), ("/dev/parport0", "parport"), ("cmd:/dev/parport0", "cmd"), ("cmd:mock", "cmd"),
    ("maximus:/dev/ttyUSB0", "maximus"), ("maximus", "maximus"), ("grbl:/dev/ttyACM0?baud=115200", "grbl"),
])
def test_every_port_name_picks_one_back_end(name, kind):
    assert port_kind(name) == kind
    assert sum(b.matches(name) for b in REGISTRY) >= 1
    assert backend_of(name) is next(b for b in REGISTRY if b.matches(name))


@pytest.mark.parametrize("name", ["bogus", "cmd:", "grbl:", "COM3", ""])
def test_an_unknown_port_is_one_line_listing_every_back_end(name):
    with pytest.raises(PortError) as e:
        backend_of(name)
    text = str(e.value)
    assert "\n" not in text and all(b.example in text for b in REGISTRY)


def test_every_capability_is_explained_and_every_back_end_is_one_module():
    kinds = {b.kind for b in REGISTRY}
    assert kinds == {"mock", "parport", "cmd", "maximus", "grbl"}
    for b in REGISTRY:
        assert b.capabilities <= set(CAPABILITY_MEANINGS), (b.kind, b.capabilities - set(CAPABILITY_MEANINGS))
        assert type(b).__module__.startswith("cam.drive.machines."), type(b).__module__
    # what a front end asks, per machine
    assert can("mock", "pin_log") and can("cmd:mock", "pin_log") and not can("cmd:/dev/parport0", "pin_log")
    assert can("cmd:mock", "simulated") and not can("cmd:/dev/parport0", "simulated")
    assert can("maximus:/dev/ttyUSB0", "drills_alone") and not can("grbl:/dev/ttyUSB0", "drills_alone")
    assert can("grbl:/dev/ttyUSB0", "homes_itself") and can("grbl:/dev/ttyUSB0", "reports_position")
    assert not can("cmd:mock", "home_switches") and can("/dev/parport0", "home_switches")
    with pytest.raises(ValueError):
        can("mock", "teleport")


def test_the_session_state_lists_the_capabilities_the_page_asks_for():
    session = MachineSession("mock")
    state = session.state()
    assert "pin_log" in state["capabilities"] and "drills_alone" not in state["capabilities"]


def _seed004() -> cam.MachineSettings:
    return load_settings(SEED004)


def test_a_drawing_on_the_command_mock_carves_what_it_asks_for():
    """The strongest check, on seed 004's machine: a drawing run on ``cmd:mock`` by name, its log of command bytes
    read back into steps, decoded, carved with a point tool, equals the surface the drawing asks for, pixel by
    pixel (and every byte is one the machine file declares)."""
    s = _seed004()
    d = cam.digitize(drawing_from_rows(["..........", ".#####....", "......###.", "..#......."]))
    job = cam.plan(d, depth=[3, 2, 4], settings=s)
    result = cam.run(job, "cmd:mock")
    log = result.pin_log()
    assert set(np.unique(log.data[log.strobe == 1]).tolist()) <= set(s.commands.declared().values())
    motion = cam.decode_pin_log(commands_to_step_log(log, s), s)
    assert motion.final_steps == (0, 0, 0)
    assert_surface_equal(cam.carve(motion, (d.height_px, d.width_px), s), expected_surface_2d(d, [3, 2, 4], s))


def test_cam_drill_on_cmd_mock_writes_the_bytes_and_the_same_motion_as_step_dir(tmp_path):
    """``cam drill --port cmd:mock --pin-log``: the CSV holds command bytes with strobe pulses; read back they are
    the step/dir run's motion (the same machine file on ``--port mock``)."""
    common = [SAMPLES / "ellipse.png", "--depth", "5", "--machine", SEED004, "--yes", "--no-progress"]
    ok(run_cli("drill", *common, "--port", "cmd:mock", "--pin-log", tmp_path / "c.csv", "--state",
               tmp_path / "c.json", cwd=tmp_path))
    ok(run_cli("drill", *common, "--pin-log", tmp_path / "m.csv", "--state", tmp_path / "m.json", cwd=tmp_path))
    s = _seed004()
    cmd_log, step_log = cam.read_pin_log(tmp_path / "c.csv"), cam.read_pin_log(tmp_path / "m.csv")
    assert cmd_log.data[0] == s.commands.init and set(np.unique(cmd_log.strobe).tolist()) == {0, 1}
    got, want = cam.decode_pin_log(commands_to_step_log(cmd_log, s), s), cam.decode_pin_log(step_log, s)
    assert got.final_steps == want.final_steps
    assert got.step_counts.tolist() == want.step_counts.tolist()
    assert np.array_equal(np.unique(got.position_steps, axis=0), np.unique(want.position_steps, axis=0))


def test_a_job_needing_an_undeclared_command_is_refused_before_anything_moves(tmp_path):
    """A machine file without ``z_minus`` (the lift): the job is refused in one line naming the key, exit 2, and no
    pin log is written."""
    text = SEED004.read_text(encoding="utf-8")
    machine = tmp_path / "no-lift.toml"
    machine.write_text(re.sub(r"(?m)^z_minus\s*=.*$", "", text), encoding="utf-8")
    proc = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "5", "--machine", machine, "--port", "cmd:mock",
                   "--pin-log", tmp_path / "c.csv", "--state", tmp_path / "s.json", "--yes", cwd=tmp_path)
    assert proc.returncode == 2
    one_line_error(proc, "z_minus")
    assert not (tmp_path / "c.csv").exists()


def test_cmd_jogs_and_refuses_homing_in_one_line(tmp_path):
    state = ["--machine", SEED004, "--port", "cmd:mock", "--state", tmp_path / "s.json"]
    proc = ok(run_cli("jog", "X+", "100", *state, cwd=tmp_path))
    assert "X=100" in proc.stdout
    proc = run_cli("home", *state, cwd=tmp_path)
    assert proc.returncode == 2
    one_line_error(proc, "no switches")


def test_a_cmd_port_on_a_missing_device_is_the_parallel_port_message(tmp_path):
    proc = run_cli("drill", SAMPLES / "ellipse.png", "--port", "cmd:/dev/parport97", "--machine", SEED004, "--yes",
                   cwd=tmp_path)
    assert proc.returncode == 2
    one_line_error(proc, "/dev/parport97", "parallel port")


def test_open_port_by_name_opens_the_back_ends_port():
    s = _seed004()
    port = open_port("cmd:mock", s)
    assert port_kind(port) == "cmd" and port.name == "cmd:mock"
    assert port_kind(open_port("mock")) == "mock"
    with pytest.raises(CapabilityError, match="drill"):
        open_port("maximus:/dev/ttyUSB0")


def test_a_new_back_end_is_one_class_and_one_registry_line(monkeypatch):
    """What adding a machine takes: a Backend subclass and its registration; the session then runs on it."""
    from cam.drive import machines
    from cam.drive.machines.stepdir import MockBackend

    class Recorder(MockBackend):
        kind, example = "recorder", "recorder:NAME"

        def matches(self, name):
            return name.startswith("recorder:")

    backend_of("mock")
    monkeypatch.setattr(machines, "REGISTRY", [Recorder(), *machines.REGISTRY])
    session = MachineSession("recorder:x")
    assert session.backend.kind == "recorder"
    session.jog("x", 10)
    session.wait_idle(None)
    assert session.position_steps() == (10, 0, 0)


@pytest.mark.realtime
def test_cmd_emergency_stop_then_resume_carves_as_an_uninterrupted_run(tmp_path):
    """Every flow a step/dir port has, on seed 004's unit: a job in real time on ``cmd:mock`` (its runner process
    opens the port by name), an emergency stop, the journal, the resumed rest (planned time not 0 s); the two
    command logs read back and carved equal one uninterrupted run."""
    from cam.drive.journal import read_journal
    from cam.kinds.jobs import resume_job
    from cam.verify.pinlog import write_pin_log
    from test_resume import _check_union, _prepared, estop_run

    args = ["drill", str(SAMPLES / "ellipse.png"), "--depth", "2", "--steps-per-pixel", "2,1", "--machine", str(SEED004)]
    job, _ = _prepared(args)
    s = job.settings
    journal, first, second = tmp_path / "run.journal.json", tmp_path / "run1.csv", tmp_path / "run2.csv"
    estop_run(job, journal, first, 0.4, port="cmd:mock", as_steps=lambda log: commands_to_step_log(log, s))
    record = read_journal(journal)
    resumed = resume_job(_prepared(args)[0], record)
    again = MachineSession("cmd:mock", s, on_prompt=lambda prompt: "continue")
    again.set_position(record.position_steps)
    again.start(resumed)
    assert again.state()["remaining_s"] > 0 or again.last_run.get("machine_time_s", 0) > 0  # planned, never 0 s
    again.wait_idle(None)
    assert again.last_run["status"] == "finished", again.last_run
    write_pin_log(commands_to_step_log(again.last_job_pin_log, s), second)
    _check_union("2d", tmp_path, _prepared(args)[0], first, second, record.position_steps)


def test_one_typed_job_crosses_into_a_machine():
    """The session, its parts, placement and the back ends read a MachineJob's typed fields: no attribute probing
    of a job (``getattr(job, ...)``, ``hasattr(job, ...)``) is left there (issue #45 point 1)."""
    from cam.drive.machine_job import MachineJob, machine_job

    drive = ROOT / "cam" / "drive"
    files = [drive / "session.py", drive / "placement.py", *sorted(drive.glob("_session_*.py")),
             *sorted((drive / "machines").glob("*.py"))]
    probing = re.compile(r"\b(getattr|hasattr)\((job|mj)\b")
    found = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in files
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if probing.search(line)]
    assert not found, "\n".join(found)
    d = cam.digitize(drawing_from_rows(["..#..", ".###."]))
    job = cam.plan(d, depth=[2], settings=cam.MachineSettings())
    mj = machine_job(job)
    assert isinstance(mj, MachineJob) and mj.moves is job and mj.plan is None and mj.kind == "moves"
    assert machine_job(mj) is mj
    with pytest.raises(CapabilityError, match="cannot run a str"):
        machine_job("job.png")


def test_the_session_keeps_what_every_machine_shares():
    """The session and its parts reach a machine only through its back end: no branch on the grbl board (its jobs,
    moves, homing, feed override and state, set position, work zeros and offsets, a jog while unknown, probing's Z
    zero are the grbl back end's, :mod:`cam.drive.machines.grbl`)."""
    drive = ROOT / "cam" / "drive"
    files = [drive / "session.py", *sorted(drive.glob("_session_*.py"))]
    board = re.compile(r"\b(self|session)\.grbl\b(?!: Any = None)|\bself\.kind\s*[!=]=")
    found = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in files
             for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if board.search(line)]
    assert not found, "\n".join(found)
