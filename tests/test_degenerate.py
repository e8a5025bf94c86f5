"""Zero is a choice, not an accident (issue #33 point 8): values in range that cannot be meant as given -- a
travel height at the surface, a scale or a machine step size that rounds the whole job to nothing -- are refused
in one line (exit code 2 from the command line, 400 with the message from the page), or need an explicit
``--allow-...`` option declared in :mod:`cam.options` where a user could truly want them."""
from __future__ import annotations

from pathlib import Path

import pytest

import cam
from cam.errors import CamError
from cam.kinds.jobs import JobOptions, prepare_job
from cam.options import OPTIONS, degenerate

from conftest import SAMPLES, run_cli
from test_web import FAST, Server, compiled_kernels, fast, servers  # noqa: F401 (fixtures)

# over 1.3 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_the_page_refuses_a_travel_height_at_the_surface_with_a_400'}


def refused(out, *fragments: str) -> str:
    """The one line of a refused command (exit code 2), which names every fragment."""
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, (out.returncode, out.stderr)
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


# -- a travel height at the surface ------------------------------------------------------------------


def test_the_allow_option_is_declared_once_for_the_travel_heights_kinds():
    from cam.kinds import option_kinds

    allow, height = OPTIONS["allow_surface_travel"], OPTIONS["travel_height_mm"]
    assert allow.type == "flag" and allow.default is False and allow.traits == height.traits
    assert option_kinds()["allow_surface_travel"] == option_kinds()["travel_height_mm"] == {"excellon", "hpgl", "svg",
                                                                                          "dxf"}
    assert allow.flag == "--allow-surface-travel"


@pytest.mark.parametrize("name", ["board.drl", "logo.svg", "extended.plt"])
def test_a_travel_height_at_the_surface_is_refused_in_one_line(name, tmp_path):
    path = SAMPLES / name
    line = refused(run_cli("drill", path, "--travel-height", "0", "--yes"), "--travel-height", "0 mm",
                   "--allow-surface-travel")
    assert "surface" in line
    # the same for preview (nothing is planned before the refusal)
    refused(run_cli("preview", path, "--travel-height=0", "-o", tmp_path / "p.png"), "--travel-height")


def test_a_travel_height_at_the_surface_runs_when_allowed(tmp_path):
    out = run_cli("drill", SAMPLES / "board.drl", "--travel-height", "0", "--allow-surface-travel", "--yes",
                  "--report", tmp_path / "r.json")
    assert out.returncode == 0, out.stderr
    assert "job finished" in out.stdout
    # a height above the surface needs nothing
    assert run_cli("drill", SAMPLES / "board.drl", "--travel-height", "0.1", "--yes").returncode == 0


def test_the_allow_option_applies_to_the_kinds_of_the_travel_height_only():
    refused(run_cli("drill", SAMPLES / "gear.png", "--allow-surface-travel"), "--allow-surface-travel",
            "does not apply")


def test_joboptions_refuse_a_travel_height_at_the_surface_unless_allowed():
    with pytest.raises(CamError, match="travel_height_mm.*allow_surface_travel"):
        JobOptions(travel_height_mm=0.0).checked()
    with pytest.raises(CamError, match="travel_height_mm"):
        JobOptions.from_mapping({"travel_height_mm": "0"})
    assert JobOptions(travel_height_mm=0.0, allow_surface_travel=True).checked().travel_height_mm == 0.0
    assert degenerate({"travel_height_mm": 1.0}.get) is None
    assert degenerate({}.get) is None


def test_the_page_refuses_a_travel_height_at_the_surface_with_a_400(fast):
    status, r = fast.upload("board.drl", (SAMPLES / "board.drl").read_bytes())
    assert status == 200, r
    status, bad = fast.call("POST", "/api/plan", {"job": r["job"], "options": {"travel_height_mm": 0}})
    assert status == 400 and "travel_height_mm" in bad["error"] and "allow_surface_travel" in bad["error"]
    status, ok = fast.call("POST", "/api/plan", {"job": r["job"],
                                                 "options": {"travel_height_mm": 0, "allow_surface_travel": True}})
    assert status == 200, ok


# -- a scale or a step size that rounds the job to nothing -------------------------------------------------


@pytest.mark.parametrize("flags, fragment", [(["--scale", "1e-9"], "--scale 1e-09"),
                                             (["--fit", "1e-9x1e-9"], "--fit 1e-09x1e-09")])
def test_an_svg_scale_that_puts_every_stroke_on_one_step_is_refused(flags, fragment):
    refused(run_cli("drill", SAMPLES / "logo.svg", *flags, "--yes"), "logo.svg", "on one X/Y step", fragment)
    assert run_cli("drill", SAMPLES / "logo.svg", "--scale", "0.01", "--yes").returncode == 0  # small, not nothing


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_the_smallest_scales_are_refused_too():
    """--scale 1e-308 (issue #33): refused as nothing to cut.  (cam/job/svg.py's corner test divides by a
    product of segment lengths that underflows to 0 there and warns on the way: its owner's to fix.)"""
    for options in (JobOptions(scale=1e-308), JobOptions(fit_mm=(1e-300, 1e-300))):
        with pytest.raises(CamError, match="on one X/Y step"):
            prepare_job(SAMPLES / "logo.svg", options)
    out = run_cli("drill", SAMPLES / "logo.svg", "--scale", "1e-308", "--yes")
    assert out.returncode == 2 and "cam: error:" in out.stderr and "on one X/Y step" in out.stderr


def _coarse_machine(tmp_path: Path) -> Path:
    path = tmp_path / "coarse.toml"
    path.write_text("mm_per_step_xy = 100.0\nmm_per_step_z = 100.0\n")
    return path


def test_a_machine_whose_steps_make_the_whole_job_0_steps_is_refused(tmp_path):
    program = tmp_path / "small.ngc"
    program.write_text("G21 G90\nG0 X0.01 Y-0.01\nG1 Z-0.02 F100\nG1 X0.03 Y-0.02\nG0 Z0\nM2\n")
    line = refused(run_cli("drill", program, "--machine", _coarse_machine(tmp_path), "--yes"), "small.ngc",
                   "moves 0 steps", "100 mm per X/Y step")
    assert "nothing would be cut" in line
    with pytest.raises(CamError, match="moves 0 steps"):
        prepare_job(program, JobOptions(), cam.MachineSettings().replace(mm_per_step_xy=100.0, mm_per_step_z=100.0))
    assert run_cli("drill", program, "--yes").returncode == 0  # the thesis machine's steps cut it


def test_the_page_refuses_a_scale_that_rounds_the_job_to_nothing(fast):
    status, r = fast.upload("logo.svg", (SAMPLES / "logo.svg").read_bytes())
    assert status == 200, r
    status, bad = fast.call("POST", "/api/plan", {"job": r["job"], "options": {"scale": 1e-9}})
    assert status == 400 and "on one X/Y step" in bad["error"], bad


@pytest.mark.parametrize("name", ["logo.svg", "bolt_plate.ngc", "board.drl"])
def test_a_machine_step_too_fine_to_count_is_refused_in_one_line(name, tmp_path):
    """``mm_per_step_xy = 1e-308`` made any coordinate more steps than a number holds (an OverflowError
    traceback): the machine file is refused, naming the setting."""
    machine = tmp_path / "fine.toml"
    machine.write_text("mm_per_step_xy = 1e-308\n")
    refused(run_cli("drill", SAMPLES / name, "--machine", machine, "--yes"), "fine.toml", "mm_per_step_xy", "1e-308")


# -- a serial port that cannot be opened or is lost ---------------------------------------------------------


class _LostSerial:
    """A serial port whose device went away once opened (unplugged): every call fails as pyserial's do."""

    def __init__(self, *args, **kwargs) -> None:
        self._timeout = kwargs.get("timeout")

    def _gone(self, *args):
        import serial

        raise serial.SerialException(5, "device reports readiness to read but returned no data (device "
                                        "disconnected or multiple access on port?)")

    read = write = flush = _gone

    @property
    def timeout(self):
        return self._timeout

    @timeout.setter
    def timeout(self, value):  # pyserial reconfigures the port: termios fails on a device that is gone
        self._gone()

    @property
    def in_waiting(self):
        self._gone()

    def close(self) -> None:
        pass


def test_a_serial_port_that_cannot_be_opened_is_one_line_saying_what_to_check():
    line = refused(run_cli("drill", SAMPLES / "board.drl", "--port", "maximus:/dev/ttyS77", "--yes"),
                   "cannot open MAXIMUS port /dev/ttyS77", "No such file or directory", "plugged in", "dialout")
    assert "Errno" not in line


@pytest.mark.parametrize("call", ["handshake", "read", "write"])
def test_a_lost_serial_port_is_one_line_saying_what_to_check(monkeypatch, call):
    """The device goes away mid-job: every read, write and the handshake end in a PortError (a CamError: one
    line from the command line) that names the port and what to check, never a SerialException."""
    import serial

    from cam.drive.maximus import board as board_module
    from cam.errors import PortError

    monkeypatch.setattr(serial, "Serial", _LostSerial)
    b = board_module.MaximusBoard("maximus:/dev/ttyUSB0", handshake=False)
    action = {"handshake": b.handshake, "read": lambda: b._read_byte(0.5), "write": lambda: b._write(b"\x61")}[call]
    with pytest.raises(PortError) as caught:
        action()
    message = str(caught.value)
    assert "MAXIMUS port /dev/ttyUSB0" in message and "check the cable" in message and "\n" not in message
    assert "position is unknown" in message and not b.in_step


@pytest.mark.parametrize("name", ["board.drl", "logo.svg", "extended.plt"])
def test_a_travel_height_that_rounds_to_the_surface_is_refused_too(name):
    """0.005 mm is less than half the thesis machine's Z step (0.0157 mm): 0 steps, the surface."""
    step = cam.MachineSettings().mm_per_step_z
    refused(run_cli("drill", SAMPLES / name, "--travel-height", "0.005", "--yes"), "0.005 mm",
            "less than half a Z step", "--allow-surface-travel")
    with pytest.raises(CamError, match="less than half a Z step"):
        prepare_job(SAMPLES / name, JobOptions(travel_height_mm=step / 3))
    assert prepare_job(SAMPLES / name, JobOptions(travel_height_mm=step / 3, allow_surface_travel=True))
    assert prepare_job(SAMPLES / name, JobOptions(travel_height_mm=step))
