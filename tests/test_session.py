"""The machine session every front end drives: ports by name, one capability check, checks before moving."""
import numpy as np
import pytest

import cam
from cam.drive import machines
from cam.drive.session import MachineSession
from cam.errors import BusyError, CapabilityError, PortError, TravelError
from cam.job.moves import jog

from conftest import SAMPLES, assert_surface_equal, drawing_from_rows, expected_surface_2d

SLOW = cam.MachineSettings().replace(delay_xy_ms=2.0, delay_z_ms=2.0, ramp="constant")


def test_ports_are_chosen_by_name_in_one_place():
    assert [machines.port_kind(n) for n in ("mock", "/dev/parport0", "maximus:/dev/ttyUSB0")] == \
        ["mock", "parport", "maximus"]
    for bad in ("com1", "maximus:", "parport0"):
        with pytest.raises(PortError, match="unknown port"):
            machines.port_kind(bad)


def test_one_capability_check_says_what_a_port_cannot_do():
    machines.require("mock", "pause")
    machines.require("mock", "pin_log")
    with pytest.raises(CapabilityError, match="cannot pause") as pause:
        machines.require("maximus:/dev/ttyUSB0", "pause")
    with pytest.raises(CapabilityError, match="pin log"):
        machines.require("/dev/parport0", "pin_log")
    # the session raises the very same message (the web page shows it as a 409, the CLI as one line)
    session = MachineSession("maximus:/dev/ttyUSB0", SLOW)
    with pytest.raises(CapabilityError) as again:
        session.pause()
    assert str(again.value) == str(pause.value)


def test_a_session_runs_a_drawing_and_the_pin_log_carves_exactly():
    d = cam.digitize(drawing_from_rows(["..........", ".#####....", "......###."]))
    job = cam.plan(d, depth=[3, 2], settings=SLOW)
    session = MachineSession("mock", SLOW)
    info = session.run(job)
    assert info["status"] == "finished" and session.position_steps() == (0, 0, 0)
    motion = cam.decode_pin_log(session.last_result.pin_log(), SLOW)
    assert_surface_equal(cam.carve(motion, (d.height_px, d.width_px), SLOW), expected_surface_2d(d, [3, 2], SLOW))


def test_jobs_are_checked_against_the_travel_from_where_the_tool_stands():
    session = MachineSession("mock", SLOW)
    session.jog("x", 40)
    session.wait_idle()
    assert session.position_steps() == (40, 0, 0)
    with pytest.raises(TravelError, match="travel"):
        session.jog("x", -41)  # would pass X = 0
    with pytest.raises(TravelError, match="travel"):
        session.start(jog("y", -1, settings=SLOW))
    assert session.last_run["status"] == "finished" and session.position_steps() == (40, 0, 0)  # nothing ran
    session.go_to_origin()
    session.wait_idle()
    assert session.position_steps() == (0, 0, 0)


@pytest.mark.realtime
def test_one_activity_at_a_time_and_stop_lifts_the_tool():
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    job = cam.plan(d, depth=5, settings=SLOW)
    session = MachineSession("mock", SLOW, realtime=True)
    session.start(job)
    try:
        with pytest.raises(BusyError, match="busy"):
            session.jog("x", 5)
        with pytest.raises(BusyError):
            session.start(job)
    finally:
        session.stop()
        session.wait_idle()
    assert session.last_run["status"] == "stopped"
    assert session.position_steps()[2] <= 0  # the tool was lifted out of the material
    with pytest.raises(BusyError, match="nothing is paused"):
        session.resume()


def test_prompts_go_to_the_callback_and_can_stop_the_job():
    d = cam.digitize(drawing_from_rows([".....", ".###.", "....."]))
    job = cam.plan(d, depth=2, settings=SLOW, pause_at=[(2, 1)])
    seen = []
    session = MachineSession("mock", SLOW, on_prompt=lambda p: seen.append(p.note) or "stop")
    session.run(job)
    assert seen == ["Pause At"] and session.last_run["status"] == "stopped"
    surface = cam.carve(cam.decode_pin_log(session.last_result.pin_log(), SLOW), (3, 5), SLOW)
    assert surface[1, 3] == 0 and np.all(surface[1, 1:3] <= 2)  # stopped at the pause: the rest was not cut
