"""Jobs of every kind on grbl 1.1h's own firmware (issue #45 point 6): ``../shared/grbl_avr`` runs grbl's avr-gcc
build on a simulated ATmega328P behind a pty and logs its step pins.  A drawing, a drill file (its tool change
answered), an HPGL file and a G-code program are streamed by the session; the path the firmware stepped
(decoded from its pins) must follow the job's own: every stepped position within a step and a half of the job's
polyline, every point of the job reached within a step, the end where the job ends, and the machine time planned
(grbl's own rules, cam.drive.grbl_time) within 10 % of the firmware's time in motion.  A reset of the board
mid-job (its reset button) stops the stream with one line, and the position is unknown.

All slow: the simulator runs grbl at 16 MHz of simulated time, about as fast as a real Uno."""
from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.drive import grbl_machine as gm
from cam.drive.grbl_link import GrblLink
from cam.drive.grbl_machine import GrblMachine
from cam.drive.session import MachineSession
from cam.drive.state import StateHold
from cam.settings import Travel
from conftest import drawing_from_rows
from support.grbl import quick_thread_switches  # noqa: F401 (autouse)
from test_grbl_link_faults import GRBL_AVR, _have_grbl_avr, firmware_rig, uart_events

pytestmark = [pytest.mark.realtime,
              pytest.mark.skipif(not _have_grbl_avr(), reason="needs ../shared/grbl_avr (grbl 1.1h on simavr)")]

PER_MM = 250.0  # grbl's $100-$102 after --fresh
SPAN_STEPS = 50000
SETTINGS = cam.MachineSettings().replace(
    mm_per_step_xy=1 / PER_MM, mm_per_step_z=1 / PER_MM, delay_xy_ms=0.2, delay_z_ms=0.2, steps_per_px_xy=25,
    steps_per_px_z=25, max_speed_x_mm_s=50.0, max_speed_y_mm_s=50.0, max_speed_z_mm_s=50.0, accel_x_mm_s2=200.0,
    accel_y_mm_s2=200.0, accel_z_mm_s2=200.0,
    travel=Travel(x_min_steps=-SPAN_STEPS, x_max_steps=SPAN_STEPS, y_min_steps=-SPAN_STEPS, y_max_steps=SPAN_STEPS,
                  z_min_steps=-SPAN_STEPS, z_max_steps=SPAN_STEPS))
FAST_GRBL = {110: 3000, 111: 3000, 112: 3000, 120: 200, 121: 200, 122: 200}  # the machine file's speeds, in $$

DRAWING = ["..........", ".####.....", ".#..#..##.", ".####..##.", ".........."]
DRILL = """M48
METRIC,TZ
T1C0.800
T2C1.000
%
T1
X1.0Y1.0
X4.0Y1.0
T2
X4.0Y4.0
X1.0Y4.0
M30
"""
HPGL = "IN;SP1;PU0,0;PD200,0,200,200,0,200,0,0;PU300,0;PD400,100;PU;SP0;\n"
GCODE = """G21 G90 G17
G0 Z2
G0 X0 Y0
G1 Z-0.5 F300
G1 X5 F1200
G2 X8 Y3 I0 J3
G1 Y5
G0 Z2
M2
"""


def open_firmware_session(device: str, state=None) -> MachineSession:
    """A session on the firmware's pty, its speeds set to the machine file's first (the firmware starts from
    grbl's defaults: 500 mm/min, 10 mm/s^2)."""
    url = f"grbl:{device}"
    link = GrblLink(url, welcome_timeout_s=0.5)
    for key, value in FAST_GRBL.items():
        link.command(f"${key}={value}")
    link.read_settings()
    gm._MACHINES[device] = GrblMachine(url, SETTINGS, link=link)
    return MachineSession(url, SETTINGS, state=state, on_prompt=lambda prompt: "continue")


def decode_points(out: Path) -> list:
    """grbl_avr's decoder: ``(t_s, x, y, z)`` in grbl's steps after every step of the firmware's pin log."""
    sys.path.insert(0, str(GRBL_AVR))
    import decode  # grbl_avr's pin decoder

    return decode.points(str(out / "pins.csv"))


def stepped_steps(out: Path) -> np.ndarray:
    """``(N, 3)`` the firmware's position after every step, in cam's machine steps (grbl's Y and Z turned
    round), from its pin log."""
    rows = decode_points(out)
    pts = np.array([(int(p[1]), -int(p[2]), -int(p[3])) for p in rows], np.int64).reshape(-1, 3)
    return np.vstack([np.zeros((1, 3), np.int64), pts])


def distance_to_path(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """The distance (steps) of each of ``points`` ``(N, 3)`` to the polyline through ``vertices`` ``(M, 3)``."""
    a = vertices[:-1].astype(np.float64)
    d = (vertices[1:] - vertices[:-1]).astype(np.float64)
    length2 = np.maximum((d * d).sum(axis=1), 1e-12)
    best = np.full(len(points), np.inf)
    for start in range(0, len(points), 2000):
        p = points[start:start + 2000].astype(np.float64)[:, None, :]
        t = np.clip(((p - a) * d).sum(axis=2) / length2, 0.0, 1.0)
        near = a + t[..., None] * d
        best[start:start + 2000] = np.sqrt(((p - near) ** 2).sum(axis=2)).min(axis=1)
    return best


def job_vertices(prepared) -> np.ndarray:
    pts = np.concatenate([np.asarray(p.points_steps, np.int64) for p in prepared.plan.job.pieces()])
    return np.vstack([np.zeros((1, 3), np.int64), pts])


def write_input(tmp_path: Path, kind: str) -> Path:
    if kind == "drawing":
        path = tmp_path / "drawing.png"
        import cv2

        cv2.imwrite(str(path), drawing_from_rows(DRAWING))
        return path
    name, text = {"drill": ("small.drl", DRILL), "hpgl": ("small.plt", HPGL), "gcode": ("small.ngc", GCODE)}[kind]
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("kind", ["drawing", "drill", "hpgl", "gcode"])
def test_every_job_kind_on_grbls_own_firmware_steps_the_jobs_path(kind, tmp_path):
    prepared = cam.prepare_job(str(write_input(tmp_path, kind)), settings=SETTINGS)
    with firmware_rig(tmp_path) as (out, proxy):
        session = open_firmware_session(proxy.device_path)
        session.start(prepared)
        assert session.wait_idle(600), "the job never ended"
        assert session.last_run["status"] == "finished", session.last_run
    stepped = stepped_steps(out)
    vertices = job_vertices(prepared)
    off = distance_to_path(stepped, vertices)
    assert off.max() <= 1.5, (kind, float(off.max()), stepped[int(off.argmax())])
    reached = distance_to_path(vertices, stepped)  # each job point against the stepped polyline
    assert reached.max() <= 1.0, (kind, float(reached.max()), vertices[int(reached.argmax())])
    assert np.abs(stepped[-1] - vertices[-1]).max() <= 1, (stepped[-1], vertices[-1])
    # the planned machine time is grbl's own, within 10 % of what the firmware took to step (its time in motion:
    # the waits at a tool change are the host's)
    step_t_s = np.array([float(row[0]) for row in decode_points(out)])
    gaps_s = np.diff(step_t_s)
    moving_s = float(gaps_s[gaps_s < 0.25].sum())
    planned_s = session.last_run["machine_time_s"]
    assert abs(planned_s - moving_s) <= 0.10 * moving_s, (kind, planned_s, moving_s)
    stats = json.loads((out / "stats.json").read_text())
    assert stats["rx_overflow"] == 0, stats
    uart = uart_events(out / "uart.log")
    opened = next(t for t, d, text in uart if d == "*" and "opened" in text)  # a blank EEPROM's error:7 before
    refused = [text for t, d, text in uart if d == "<" and t > opened and text.startswith(("error:", "ALARM:"))]
    assert not refused, refused


def test_a_reset_of_the_board_mid_job_stops_the_stream_with_one_line(tmp_path):
    prepared = cam.prepare_job(str(write_input(tmp_path, "drawing")), settings=SETTINGS)
    with firmware_rig(tmp_path) as (out, proxy):
        hold = StateHold(tmp_path / "m.json", SETTINGS, "test")
        hold.record(replace(hold.state, position_known=True))
        session = open_firmware_session(proxy.device_path, state=hold)
        session.start(prepared)
        deadline = time.monotonic() + 120
        while json.loads((out / "stats.json").read_text()).get("pin_rows", 0) < 400:  # well under way
            assert time.monotonic() < deadline and session.busy, "the job did not get under way"
            time.sleep(0.05)
        pid = int((out / "pid").read_text().split()[0])
        os.kill(pid, signal.SIGUSR1)  # the Uno's reset button, the port left open
        assert session.wait_idle(120)
        run = session.last_run
        assert run["status"] == "error", run
        msg = run["messages"][0]
        assert "reset itself" in msg and "position is unknown" in msg and "\n" not in msg, msg
        assert not hold.state.position_known
        hold.close()
    uart = uart_events(out / "uart.log")
    t_reset = next(t for t, d, text in uart if d == "*" and "reset" in text and t > 0.2)
    lines_after = [text for t, d, text in uart if d == ">" and t > t_reset and not text.startswith("RT")]
    assert not lines_after, lines_after  # no G-code line went out after the board restarted
