"""The pin log holds every write of the command (issue #44 point 4): ``cam drill`` of a job placed at the work zero
travels there first, and its ``--pin-log`` holds that travel (part ``travel``) and the job (part ``job``), each
marked by a comment line, on one time line; ``part="job"`` reads the job alone, as a log of the job."""
import json

import numpy as np
import pytest

import cam
from cam.drive import placement
from cam.job.model import travel_job
from cam.verify.pinlog import (
    PinLog, PinLogPart, carve, decode_pin_log, iter_pin_log, join_pin_logs, read_pin_log, write_pin_log,
)

from conftest import SAMPLES, assert_surface_equal, expected_surface_2d, run_cli

S = cam.MachineSettings()


def ok(proc):
    assert proc.returncode == 0, (proc.stdout, proc.stderr)
    return proc


def machine_position(state) -> tuple[int, int, int]:
    where = json.loads(ok(run_cli("where", "--json", "--state", state)).stdout)
    return tuple(int(v) for v in where["machine_steps"])


def machine_motion(log: PinLog) -> np.ndarray:
    """``(M, 3)`` the whole log's positions in the machine frame (from where its first part started)."""
    return decode_pin_log(log, S).position_steps + np.array(log.parts[0].start_steps, np.int64)


def test_pin_log_holds_the_travel_to_the_work_zero_and_the_job(tmp_path):
    state, pins = tmp_path / "m.json", tmp_path / "p.csv"
    ok(run_cli("goto", "20,20,0", "--state", state))
    start = machine_position(state)
    assert start != (0, 0, 0)
    proc = ok(run_cli("drill", SAMPLES / "ellipse.png", "--depth", "5", "--start", "top", "--state", state,
                      "--pin-log", pins))
    assert "going to the work zero first" in proc.stderr
    lines = pins.read_text().splitlines()
    assert lines[0] == "t_ns,data,strobe" and lines[1] == f"# part travel from {','.join(map(str, start))} steps at 0 ns"

    whole = read_pin_log(pins)  # every row: the travel, then the job
    assert [p.name for p in whole.parts] == ["travel", "job"] and whole.parts[0].first_row == 0
    travel, job_part = whole.parts
    assert travel.start_steps == start and job_part.start_steps == (0, 0, 0)  # the work zero: at the home here
    pos = machine_motion(whole)
    k = job_part.first_row
    assert 0 < k < len(whole)
    assert tuple(pos[0]) == start or np.abs(pos[0] - start).sum() == 1  # the first write: at most its first step
    assert tuple(pos[k - 1]) == job_part.start_steps  # the travel ends where the job starts
    assert pos[:k, 2].max() <= 0  # lifted: never below the surface on the way
    assert np.all(np.diff(whole.t_ns) >= 0) and whole.t_ns[k] == job_part.t0_ns > whole.t_ns[k - 1]
    assert tuple(pos[-1]) == machine_position(state)

    job = read_pin_log(pins, part="job")  # the job alone, as a log of the job: from 0 ns, from its own zero
    assert len(job) == len(whole) - k and job.t_ns[0] == 0
    assert np.array_equal(job.data, whole.data[k:]) and np.array_equal(job.t_ns, whole.t_ns[k:] - job_part.t0_ns)
    drawing = cam.load_image(SAMPLES / "ellipse.png")
    d = cam.digitize(drawing, start="top")
    want = expected_surface_2d(d, [5] * len(d.objects), S)
    planned = cam.plan(d, depth=5)
    surface = carve(decode_pin_log(pins, S, part="job"), (planned.height_px, planned.width_px), S,
                    origin_px=planned.origin_px)
    assert_surface_equal(surface, want)
    # the streamed reader takes the same part, a few rows at a time
    pieces = list(iter_pin_log(pins, rows=1000, part="job"))
    assert np.array_equal(np.concatenate([p.t_ns for p in pieces]), job.t_ns)
    assert np.array_equal(np.concatenate([p.data for p in pieces]), job.data)
    assert sum(len(p) for p in iter_pin_log(pins, rows=1000)) == len(whole)


GCODE = "G21 G91\nG0 Z-0.5\nG0 X2 Y-1.5\nG1 Z0.6 F100\nG1 X1 F200\nG0 Z-0.6\nG0 X-3 Y1.5 Z0.5\nM2\n"
"""Incremental moves: the same motion from wherever the tool stands (cam's +Z is deeper, G-code's up)."""


@pytest.mark.parametrize("name, flags", [
    ("ellipse.png", ["--depth", "2"]),
    ("board.drl", ["--yes"]),
    ("inkscape_star.plt", ["--yes"]),
    ("relative.ngc", ["--yes"]),
])
def test_pin_log_job_part_decodes_alone_for_every_input_kind(tmp_path, name, flags):
    path = SAMPLES / name
    if name.endswith(".ngc"):
        path = tmp_path / name
        path.write_text(GCODE)
    ok(run_cli("drill", path, *flags, "--state", tmp_path / "fresh.json", "--pin-log", tmp_path / "ref.csv"))
    want = decode_pin_log(tmp_path / "ref.csv", S, part="job").position_steps  # from the home

    state, pins = tmp_path / "m.json", tmp_path / "p.csv"
    ok(run_cli("goto", "30,20,-4", "--state", state))  # a start elsewhere, above the surface
    start = machine_position(state)
    ok(run_cli("drill", path, *flags, "--state", state, "--pin-log", pins))
    whole = read_pin_log(pins)
    placed = not name.endswith(".ngc")  # a G-code program runs from where the tool stands: no travel
    assert [p.name for p in whole.parts] == (["travel", "job"] if placed else ["job"])
    assert whole.parts[0].start_steps == start
    job = decode_pin_log(pins, S, part="job").position_steps
    assert np.array_equal(job, want)  # the job's part, decoded alone: the job as it runs from its own start
    assert np.array_equal(decode_pin_log(whole, S).position_steps[whole.parts[-1].first_row:]
                          - (np.array(whole.parts[-1].start_steps) - start), job)
    assert tuple(machine_motion(whole)[-1]) == machine_position(state)


def test_a_travel_at_the_wrong_height_shows_in_the_pin_log(tmp_path, monkeypatch):
    state = tmp_path / "m.json"

    def travel(pins) -> tuple[np.ndarray, int]:
        """The XY moves of the travel to the work zero (machine frame) and the travel height it should keep."""
        ok(run_cli("goto", "20,20,-6", "--state", state))  # above the surface: the travel keeps this height
        start = machine_position(state)
        ok(run_cli("drill", SAMPLES / "board.drl", "--yes", "--state", state, "--pin-log", pins))
        log = read_pin_log(pins)
        pos = machine_motion(log)[:log.parts[1].first_row]
        moving = np.any(np.diff(np.vstack([[start], pos])[:, :2], axis=0) != 0, axis=1)
        assert moving.any()
        return pos[moving], start[2]

    pos, height = travel(tmp_path / "right.csv")
    assert height < 0 and np.all(pos[:, 2] == height)  # across at the travel height

    def too_low(start_steps, target_steps, safe_z_steps, settings):  # a bug: across 3 steps below the surface
        (x0, y0, z0), (x, y, z) = start_steps, target_steps
        rel = [(0, 0, 3 - z0), (x - x0, y - y0, 3 - z0), (x - x0, y - y0, z - z0)]
        return travel_job(np.array(rel, np.int64), settings, source="go to")

    monkeypatch.setattr(placement, "goto_path", too_low)
    pos, height = travel(tmp_path / "wrong.csv")
    assert np.all(pos[:, 2] == 3)  # the decoded travel shows the depth it crossed at


def test_parts_round_trip_through_the_csv_and_a_log_without_parts_is_the_job(tmp_path):
    a = PinLog(np.array([0, 5, 10]), np.array([1, 2, 3], np.uint8), np.zeros(3, np.uint8))
    b = PinLog(np.array([0, 7]), np.array([4, 5], np.uint8), np.ones(2, np.uint8))
    both = join_pin_logs([("travel", a, (1, 2, -3)), ("job", b, (4, 5, 0))], gap_ns=100)
    assert both.parts == (PinLogPart("travel", 0, (1, 2, -3), 0), PinLogPart("job", 3, (4, 5, 0), 110))
    assert list(both.t_ns) == [0, 5, 10, 110, 117]
    write_pin_log(both, tmp_path / "p.csv")
    back = read_pin_log(tmp_path / "p.csv")
    assert back.parts == both.parts and list(back.t_ns) == list(both.t_ns) and list(back.data) == [1, 2, 3, 4, 5]
    job = read_pin_log(tmp_path / "p.csv", part="job")
    assert list(job.t_ns) == [0, 7] and list(job.data) == [4, 5] and job.parts[0].start_steps == (4, 5, 0)
    assert list(read_pin_log(tmp_path / "p.csv", part="travel").data) == [1, 2, 3]
    write_pin_log(a, tmp_path / "old.csv")  # a log of one run, no parts: the job's own
    assert list(read_pin_log(tmp_path / "old.csv", part="job").data) == [1, 2, 3]
    with pytest.raises(cam.CamError, match="no travel part"):
        read_pin_log(tmp_path / "old.csv", part="travel")


def test_the_sessions_pin_log_holds_the_travel_and_the_page_exports_it(tmp_path):
    from cam.drive.session import MachineSession
    from cam.drive.state import StateHold
    from cam.kinds.jobs import JobOptions, prepare_job
    from cam.web.work import pin_log_csv, save_pin_log_raw

    job = prepare_job(SAMPLES / "board.drl", JobOptions(), S)
    want = decode_pin_log(cam.run(job.plan).pin_log(), S).position_steps  # the job from its own home
    hold = StateHold(tmp_path / "m.json", S, "the test")
    ses = MachineSession("mock", S, state=hold, on_prompt=lambda prompt: "continue")
    try:
        ses.go_to((300, 200, -5), unit="steps", machine_coords=True)
        assert ses.wait_idle(30) and ses.last_run["status"] == "finished"
        ses.start(job)  # travels to the work zero first, then drills
        assert ses.wait_idle(60) and ses.last_run["status"] == "finished", ses.last_run
        alone = ses.last_job_pin_log  # the job's writes alone, as the Python callers had them
        assert np.array_equal(decode_pin_log(alone, S).position_steps, want) and alone.parts[0].name == "job"
        whole = ses.last_pin_log
        assert [p.name for p in whole.parts] == ["travel", "job"] and whole.parts[0].start_steps == (300, 200, -5)
        k = whole.parts[1].first_row
        pos = machine_motion(whole)
        across = np.any(np.diff(pos[:k, :2], axis=0) != 0, axis=1)
        assert tuple(pos[k - 1]) == whole.parts[1].start_steps and np.all(pos[1:k][across, 2] == -5)  # lifted
        assert np.array_equal(decode_pin_log(whole, S, part="job").position_steps, want)
        assert ses.last_pin_log is whole  # one object per job: the page exports it once
        # the page's export (raw arrays in the server, the CSV in the worker) keeps the parts
        save_pin_log_raw(whole, tmp_path / "raw.npy")
        pin_log_csv(str(tmp_path / "raw.npy"), str(tmp_path / "page.csv"))
        back = read_pin_log(tmp_path / "page.csv")
        assert back.parts == whole.parts and np.array_equal(back.data, whole.data)
    finally:
        hold.close()
