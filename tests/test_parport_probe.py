"""Probing on a PC parallel port (issue #46 point 3): ``[inputs] probe`` read from the status register by
:class:`cam.drive.ports.ParallelPort`, stepping Z down at the probe feed on the real clock until the pin changes,
the e-stop pin still served.

The parallel port is a stand-in for pyparallel's ``Parallel`` (Linux ppdev) wired to a simulated machine: each
byte written to the data register moves the simulated axes (the mock port's own step/dir decoding and its
simulated surface), and ``PPRSTATUS`` reads back the status register as the hardware gives it (BUSY, pin 11,
inverted).  Everything above the register is ``cam``'s code as it runs on a real port: the session opens
``/dev/parport0`` by name, runs in real time and polls the inputs between writes."""
from __future__ import annotations

import sys
import threading
import time
import types

import numpy as np
import pytest

from cam.drive.ports import MockPort, SwitchSchedule, surface_height_mm
from cam.drive.probing import ProbeError, step_dir_feed
from cam.drive.session import MachineSession
from cam.settings import INPUT_BITS, settings_from_mapping

SURFACE = (-0.6, 0.002, 0.0, 0.0, 0.0, 0.0)  # 0.6 mm below the work zero at X 0, rising 2 µm a mm in X
MACHINE = {"inputs": {"probe": "!13", "estop": "!15"}, "travel": {"z_min_steps": -2000, "z_max_steps": 2000},
           "mock": {"probe_surface": ",".join(str(v) for v in SURFACE)}}


class _WiredParallel:
    """pyparallel's ``Parallel`` on a simulated machine: the data register steps the mock's axes, the status
    register reads its switches (the probe on the surface; the e-stop pressed once ``estop_after`` bytes came)."""

    instances: list["_WiredParallel"] = []
    settings = None
    estop_after: int | None = None

    def __init__(self, port):
        self.device = port
        self.mock = MockPort(switches=SwitchSchedule(self.settings, (0, 0, 0)))
        self.t0_ns = time.monotonic_ns()
        self.writes = 0
        self.z_at_s: list[tuple[float, int]] = []  # (wall s, Z steps) after each byte
        self.lock = threading.Lock()
        _WiredParallel.instances.append(self)

    def setData(self, value):
        with self.lock:
            self.writes += 1
            t_ns = time.monotonic_ns() - self.t0_ns
            self.mock.write(int(value), 0, t_ns)
            self.z_at_s.append((t_ns / 1e9, int(self.mock.switches.position_steps[2])))

    def setDataStrobe(self, level):
        pass

    def PPRSTATUS(self):
        with self.lock:
            levels = self.mock.read_inputs()
            if self.estop_after is not None and self.writes >= self.estop_after:
                levels &= ~(1 << INPUT_BITS[15])  # "!15": the e-stop pressed pulls its pin low
        return levels ^ 0x80  # the hardware inverts BUSY (pin 11) in the register

    @property
    def position_steps(self) -> tuple[int, int, int]:
        return tuple(int(v) for v in self.mock.switches.position_steps)


@pytest.fixture
def parport(monkeypatch):
    settings = settings_from_mapping(MACHINE)
    monkeypatch.setitem(sys.modules, "parallel", types.SimpleNamespace(Parallel=_WiredParallel))
    monkeypatch.setattr(_WiredParallel, "instances", [])
    monkeypatch.setattr(_WiredParallel, "settings", settings)
    monkeypatch.setattr(_WiredParallel, "estop_after", None)
    return settings


def test_parallel_port_probe_steps_down_until_the_pin_changes_and_lifts_back(parport):
    s = parport
    session = MachineSession("/dev/parport0", s)
    assert session.realtime  # a real port runs on the real clock
    r = session.probe_z(max_depth_steps=200)
    wired = _WiredParallel.instances[-1]
    assert wired.device == "/dev/parport0"
    assert r.touched and r.start_steps == (0, 0, 0)
    height_mm = -r.contact_steps[2] * s.mm_per_step_z
    surface_mm = float(surface_height_mm(SURFACE, 0.0, 0.0))
    # the first step at or below the surface: at most one step below it, never above
    assert surface_mm - s.mm_per_step_z - 1e-9 < height_mm <= surface_mm + 1e-9, (height_mm, surface_mm)
    # lifted back where it began, on the register's own count of steps too
    assert session.position_steps() == (0, 0, 0) == wired.position_steps
    # down at the probe feed, on the wall clock: from the first step down to the contact takes its time
    feed_mm_s = step_dir_feed(s, None) / 60.0
    t_s, z = np.array([t for t, _ in wired.z_at_s]), np.array([v for _, v in wired.z_at_s])
    first, contact = int(np.argmax(z > 0)), int(np.argmax(z >= r.contact_steps[2]))
    down_mm = (r.contact_steps[2] - 1) * s.mm_per_step_z
    assert t_s[contact] - t_s[first] >= 0.95 * down_mm / feed_mm_s, (t_s[contact] - t_s[first], down_mm / feed_mm_s)


def test_parallel_port_probe_that_never_touches_is_one_line_and_lifts_back(parport):
    s = parport
    session = MachineSession("/dev/parport0", s)
    with pytest.raises(ProbeError) as err:
        session.probe_z(max_depth_steps=10)  # the surface is 0.6 mm down: 10 steps never reach it
    assert "\n" not in str(err.value) and "no contact" in str(err.value)
    assert session.position_steps() == (0, 0, 0) == _WiredParallel.instances[-1].position_steps


def test_parallel_port_e_stop_pin_ends_probing_at_once(parport):
    s = parport
    _WiredParallel.estop_after = 6  # pressed while Z steps down, well above the surface
    session = MachineSession("/dev/parport0", s)
    with pytest.raises(ProbeError) as err:
        session.probe_z(max_depth_steps=200)
    assert "\n" not in str(err.value) and "emergency stop" in str(err.value) and "pin 15" in str(err.value)
    assert session.wait_idle(5) and session.last_run["status"] == "emergency-stopped"
    wired = _WiredParallel.instances[-1]
    # the pin is read between writes: at most one byte more once it reads pressed, and no lift after it
    assert wired.writes <= _WiredParallel.estop_after + 1
    assert 0 < wired.position_steps[2] < 0.6 / s.mm_per_step_z  # stopped on the way down, not at the surface
    assert session.position_steps() == wired.position_steps  # booked where the register's steps left it
