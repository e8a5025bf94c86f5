"""Resume (#15 point 3) and nothing lost (point 5): a job stopped anywhere goes on from its journal.

Every kind of job (a 2D drawing, a 3D relief, an Excellon drill file, HPGL, G-code) is stopped at a random
point on the mock -- by SIGINT to a real-time ``cam drill`` process, by an emergency stop through the API,
or by SIGKILL of the ``cam drill`` process (its runner process stops the job, lifts the tool and keeps the
journal and the pin log) -- and resumed with ``cam drill --resume``.  The two pin logs together (the second
one's motion starting where its report says, ``start_position_steps``) must carve exactly what an
uninterrupted run carves (a point tool), never deeper, and drill every hole exactly once.
"""
from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.cli.checks import check_args
from cam.cli.common import port_settings
from cam.cli.parser import build_parser
from cam.cli.planning import prepare
from cam.drive.journal import read_journal
from cam.drive.session import MachineSession
from cam.job.model import CUT, RETRACT, TRAVEL, travel_job
from cam.job.resume import resume_toolpath
from cam.verify.pinlog import Motion, carve, decode_pin_log, read_pin_log, write_pin_log
from conftest import ROOT, SAMPLES, run_cli

ENV = dict(os.environ, PYTHONPATH=str(ROOT))

GCODE = """G21 G90
G0 Z1
G0 X1 Y-1
G1 Z-0.5 F300
G1 X4 Y-1 F900
G1 X4 Y-4
G1 X1 Y-4
G1 X1 Y-1
G0 Z1
G0 X6 Y-2
G1 Z-0.3 F300
G2 X8 Y-2 I1 J0 F900
G2 X6 Y-2 I-1 J0
G0 Z1
G0 X0 Y0
M2
"""

_FAST = ["--delay", "0.2,0.2", "--ramp", "constant"]
JOBS = {
    # kind: (input file, options): each runs 2..4 s in real time
    "2d": ("ellipse.png", ["--depth", "2", "--steps-per-pixel", "2,1", "--delay", "1,1", "--ramp", "constant"]),
    "3d": ("disc.png", ["--profile", str(ROOT / "profiles" / "dome.png"), "--steps-per-pixel", "2,1", *_FAST]),
    "drill": ("board.drl", ["--delay", "0.1,0.1", "--ramp", "constant", "--yes"]),
    "hpgl": ("inkscape_star.plt", [*_FAST, "--yes"]),
    "gcode": ("part.ngc", _FAST),
}


def _input(kind: str, tmp_path: Path) -> Path:
    name = JOBS[kind][0]
    if kind == "gcode":
        path = tmp_path / name
        path.write_text(GCODE)
        return path
    return SAMPLES / name


def _drill_args(kind: str, tmp_path: Path, *more: str) -> list[str]:
    return ["drill", str(_input(kind, tmp_path)), *JOBS[kind][1], *more]


def _cam(args: list[str], timeout_s: float = 120):
    """``cam ARGS`` in this process (conftest.run_cli)."""
    return run_cli(*args)


def _one_line(stderr: str) -> bool:
    """An error is one line (a note that numba compiles, on a fresh cache, aside)."""
    lines = [line for line in stderr.splitlines() if line.strip() and "first run only" not in line]
    return len(lines) == 1 and lines[0].startswith("cam: error: ")


def _prepared(args: list[str]):
    """The job exactly as ``cam drill`` plans it from these arguments (same options, same settings)."""
    ns = build_parser().parse_args(args)
    check_args(ns)
    return prepare(ns, port_settings(ns, "mock")), ns


def _wait_closed(journal: Path, timeout_s: float = 30.0) -> dict:
    """The journal once its run ended (the runner process of a killed ``cam drill`` closes it on its own)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if journal.exists():
            values = json.loads(journal.read_text())
            if values["state"] != "running":
                return values
        time.sleep(0.05)
    raise AssertionError(f"{journal} was not closed: {journal.read_text() if journal.exists() else 'missing'}")


def _wait_cutting(proc: subprocess.Popen, percent: int, timeout_s: float = 60.0) -> threading.Thread:
    """Read a ``cam drill --progress`` process's stderr until its cutting bar (not the reading bar of a large
    file) shows ``percent`` %; returns the thread that goes on reading it."""
    chunks: list[bytes] = []
    reader = threading.Thread(target=lambda: chunks.extend(iter(lambda: os.read(proc.stderr.fileno(), 4096), b"")),
                              daemon=True)
    reader.start()
    deadline = time.monotonic() + timeout_s
    while max([int(v) for v in re.findall(rb"cutting:\s*(\d+)%", b"".join(chunks))] or [0]) < percent:
        assert time.monotonic() < deadline and proc.poll() is None, b"".join(chunks)
        time.sleep(0.02)
    return reader


def _interrupt(kind: str, how: str, seed: int, tmp_path: Path) -> tuple[Path, Path]:
    """Run the job and stop it at a random point: returns (journal, pin log of the interrupted run)."""
    rng = random.Random(f"{kind}-{how}-{seed}")
    pins, report, journal = tmp_path / "run1.csv", tmp_path / "run1.json", tmp_path / "run1.journal.json"
    if how == "estop":  # through the API, in this process: a machine session, as the web page uses it
        job, ns = _prepared(_drill_args(kind, tmp_path))
        estop_run(job, journal, pins, rng.uniform(0.1, 0.9))
        return journal, pins
    proc = subprocess.Popen([sys.executable, "-m", "cam", *_drill_args(kind, tmp_path), "--realtime", "--progress",
                             "--pin-log", str(pins), "--report", str(report)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    try:
        reader = _wait_cutting(proc, rng.randint(5, 80))
        if how == "sigint":
            proc.send_signal(signal.SIGINT)
            assert proc.wait(60) == 130
        else:  # SIGKILL of the cam process; its runner process stops the job and keeps the outputs
            proc.kill()
            proc.wait(60)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    reader.join(5)
    values = _wait_closed(journal)
    assert values["state"] == "stopped", values
    assert pins.exists()
    return journal, pins


def estop_run(job, journal: Path, pins: Path, stop_at: float, port: str = "mock", as_steps=None) -> None:
    """Run a prepared job in real time on the mock (or ``port``) through a machine session, emergency-stop it after
    ``stop_at`` of its writes, and keep its journal and pin log (read back into step/dir writes by ``as_steps``,
    for a port that writes something else)."""
    session = MachineSession(port, job.settings, realtime=True, on_prompt=lambda prompt: "continue")
    session.on_progress = lambda done, total, t_ns: session.emergency_stop() if done >= stop_at * total else None
    try:
        session.start(job, journal=str(journal))
        session.wait_idle(None)
    finally:
        session.shutdown()
    assert session.last_run["status"] == "emergency-stopped", session.last_run
    log = session.last_result.pin_log()
    write_pin_log(log if as_steps is None else as_steps(log), pins)
    assert read_journal(journal).state == "emergency-stopped"


def _motion(log_path: Path, settings: cam.MachineSettings, start_steps=(0, 0, 0)) -> Motion:
    m = decode_pin_log(read_pin_log(log_path), settings)
    return Motion(m.t_ns, m.position_steps + np.asarray(start_steps, np.int64), m.step_counts)


def _joined(a: Motion, b: Motion) -> Motion:
    return Motion(np.r_[a.t_ns, b.t_ns], np.vstack([a.position_steps, b.position_steps]), a.step_counts + b.step_counts)


def _step_surface(motion: Motion, lo: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The deepest cut (z > 0) at every (x, y) step: a point tool on the finest grid there is."""
    p = motion.position_steps
    below = p[p[:, 2] > 0]
    out = np.zeros(shape, np.int64)
    np.maximum.at(out, (below[:, 1] - lo[1], below[:, 0] - lo[0]), below[:, 2])
    return out


def _check_union(kind: str, tmp_path: Path, job, first: Path, second: Path, start_steps) -> None:
    s = job.settings
    whole = decode_pin_log(cam.run(job.steps).pin_log(), s)
    both = _joined(_motion(first, s), _motion(second, s, start_steps))
    lo = np.minimum(whole.position_steps.min(axis=0), both.position_steps.min(axis=0))
    hi = np.maximum(whole.position_steps.max(axis=0), both.position_steps.max(axis=0))
    shape = (int(hi[1] - lo[1] + 1), int(hi[0] - lo[0] + 1))
    want, got = _step_surface(whole, lo, shape), _step_surface(both, lo, shape)
    bad = np.argwhere(got != want)
    assert not len(bad), f"{len(bad)} steps differ; first at {bad[0]}: cut {got[tuple(bad[0])]}, asked {want[tuple(bad[0])]}"
    assert both.position_steps[:, 2].max() == whole.position_steps[:, 2].max()  # never deeper than asked
    if job.toolpath.pixels is not None:  # drawings: the carve check, pixel by pixel
        tp = job.toolpath
        shape_px = (tp.height_px, tp.width_px)
        assert np.array_equal(carve(both, shape_px, s, origin_px=tp.origin_px),
                              carve(whole, shape_px, s, origin_px=tp.origin_px))
    if kind == "drill":  # every hole drilled to its depth exactly once
        z = both.position_steps[:, 2]
        bottom = int(whole.position_steps[:, 2].max())
        arrivals = np.flatnonzero((z[1:] == bottom) & (z[:-1] < bottom)) + 1
        drilled = Counter(tuple(int(v) for v in both.position_steps[i, :2]) for i in arrivals)
        holes = Counter(tuple(int(v) for v in h) for h in np.asarray(job.drill_plan.holes_steps).reshape(-1, 2))
        assert drilled == holes


@pytest.mark.realtime
@pytest.mark.parametrize("kind", list(JOBS))
@pytest.mark.parametrize("how", ["sigint", "estop", "sigkill"])
def test_a_stopped_job_resumes_and_carves_as_an_uninterrupted_run(kind, how, tmp_path):
    journal, first = _interrupt(kind, how, 1, tmp_path)
    job, _ = _prepared(_drill_args(kind, tmp_path))
    record = read_journal(journal)
    assert record.identity == job.identity
    second, report = tmp_path / "run2.csv", tmp_path / "run2.json"
    done = _cam(_drill_args(kind, tmp_path, "--resume", str(journal), "--pin-log", str(second),
                            "--report", str(report)))
    assert done.returncode == 0, done.stderr
    rep = json.loads(report.read_text())
    assert rep["status"] == "finished"
    assert rep["start_position_steps"] == list(record.position_steps)
    assert rep["resumed_at_move"] > record.last_move
    assert read_journal(journal).state == "finished"
    _check_union(kind, tmp_path, job, first, second, rep["start_position_steps"])


@pytest.mark.realtime
def test_a_resumed_run_can_be_stopped_and_resumed_again(tmp_path):
    """A journal of a resumed run resumes too: three runs carve as one."""
    kind = "3d"
    job, _ = _prepared(_drill_args(kind, tmp_path))
    journal, first = _interrupt(kind, "estop", 2, tmp_path)
    start1 = read_journal(journal).position_steps
    resumed = cam.kinds.jobs.resume_job(job, read_journal(journal))
    session = MachineSession("mock", job.settings, realtime=True)
    session.set_position(start1)
    session.on_progress = lambda done, total, t_ns: session.stop() if done >= total // 2 else None
    try:
        session.start(resumed, journal=str(journal))
        session.wait_idle(None)
    finally:
        session.shutdown()
    assert session.last_run["status"] == "stopped"
    second = tmp_path / "run2.csv"
    write_pin_log(session.last_result.pin_log(), second)
    mid = read_journal(journal)
    assert mid.state == "stopped" and mid.resumed_at_move == resumed.report["resumed_at_move"]
    third, report = tmp_path / "run3.csv", tmp_path / "run3.json"
    done = _cam(_drill_args(kind, tmp_path, "--resume", str(journal), "--pin-log", str(third), "--report", str(report)))
    assert done.returncode == 0, done.stderr
    start3 = json.loads(report.read_text())["start_position_steps"]
    assert start3 == list(mid.position_steps)
    s = job.settings
    both = _joined(_joined(_motion(first, s), _motion(second, s, start1)), _motion(third, s, start3))
    whole = decode_pin_log(cam.run(job.steps).pin_log(), s)
    tp = job.toolpath
    shape_px = (tp.height_px, tp.width_px)
    assert np.array_equal(carve(both, shape_px, s, origin_px=tp.origin_px), carve(whole, shape_px, s, origin_px=tp.origin_px))


@pytest.mark.realtime
def test_a_journal_of_another_input_or_options_is_refused_and_nothing_is_lost(tmp_path):
    journal, first = _interrupt("2d", "estop", 3, tmp_path)
    before = journal.read_bytes(), first.read_bytes()
    out = tmp_path / "run2.csv"
    for args in (["drill", str(SAMPLES / "ellipse.png"), "--depth", "3", *JOBS["2d"][1][2:]],  # other options
                 ["drill", str(SAMPLES / "two_curves.png"), *JOBS["2d"][1]],  # another input
                 _drill_args("2d", tmp_path, "--delay", "2,2")):  # other machine settings
        done = _cam([*args, "--resume", str(journal), "--pin-log", str(out)])
        assert done.returncode == 2 and _one_line(done.stderr), done.stderr
        assert f"journal {journal} was written for another input or options" in done.stderr
    assert not out.exists()
    assert (journal.read_bytes(), first.read_bytes()) == before


@pytest.mark.realtime
def test_a_resumed_run_that_fails_leaves_the_journal_and_earlier_outputs_intact(tmp_path):
    journal, first = _interrupt("2d", "estop", 4, tmp_path)
    report = tmp_path / "run1.json"
    report.write_text('{"status": "emergency-stopped"}\n')
    before = journal.read_bytes(), first.read_bytes(), report.read_bytes()
    for more in (["--port", str(tmp_path / "no-such-parport")],  # the port cannot be opened
                 ["--start-at", "99999,0,0"]):  # another job: refused before anything runs
        done = _cam(_drill_args("2d", tmp_path, "--resume", str(journal), "--report", str(report), *more))
        assert done.returncode == 2 and _one_line(done.stderr), done.stderr
    assert (journal.read_bytes(), first.read_bytes(), report.read_bytes()) == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "no temporary file left behind"


def test_a_finished_or_broken_journal_is_one_line(tmp_path):
    journal = tmp_path / "j.journal.json"
    done = _cam(_drill_args("2d", tmp_path, "--report", str(tmp_path / "r.json")))
    assert done.returncode == 0, done.stderr
    auto = tmp_path / "r.journal.json"  # next to the report by default
    assert read_journal(auto).state == "finished"
    for text, message in ((auto.read_text(), "the job finished; there is nothing to resume"),
                          ("{not json", "not a cam journal"), ('{"cam_journal": 1}', "the journal has no")):
        journal.write_text(text)
        done = _cam(_drill_args("2d", tmp_path, "--resume", str(journal)))
        assert done.returncode == 2 and message in done.stderr and _one_line(done.stderr), done.stderr


def _line_job() -> cam.Job:
    """Travel to (10, 0), plunge 3 deep, cut to (20, 0), (30, 0), lift, travel home."""
    pts = np.array([[10, 0, 0], [10, 0, 3], [20, 0, 3], [30, 0, 3], [30, 0, -4], [0, 0, -4]])
    job = travel_job(pts, cam.MachineSettings())
    job.kind[:] = [TRAVEL, CUT, CUT, CUT, RETRACT, TRAVEL]
    return job


def test_resume_starts_at_the_interrupted_move_and_skips_what_does_not_cut():
    job = _line_job()
    # stopped (lifted to 0) during move 2: travel height is the job's highest travel (-4); move 2 again
    r, index, j = resume_toolpath(job, 1, (14, 0, 0))
    assert j == 2
    assert (r.points_steps + (14, 0, 0)).tolist() == [[14, 0, -4], [10, 0, -4], [10, 0, 3], [20, 0, 3], [30, 0, 3],
                                                      [30, 0, -4], [0, 0, -4]]
    assert index.tolist() == [1, 1, 1, 2, 3, 4, 5]
    # all cuts done (move 3 reached): nothing more cuts, the job ends where it would
    r, index, j = resume_toolpath(job, 3, (30, 0, 3))
    assert j == 6 and (r.points_steps + (30, 0, 3)).tolist() == [[30, 0, -4], [0, 0, -4]]
    # a pause the stop skipped (a tool change on the lift) is made above its point
    job.pause[4] = True
    job.pause_notes = ["tool change: T2"]
    r, index, j = resume_toolpath(job, 3, (30, 0, 3))
    assert r.pause.tolist() == [False, True, False] and r.pause_notes == ["tool change: T2"]


@pytest.mark.realtime
def test_the_page_resumes_a_stopped_job_from_where_the_tool_stands(tmp_path):
    """The web page's Resume job button (POST /api/resume-job) calls the same library function as the CLI."""
    from test_web import MEDIUM, Server

    s = Server(tmp_path, settings=MEDIUM, realtime=True)
    try:
        status, r = s.call("POST", "/api/resume-job", {})
        assert status == 409 and "no stopped job" in r["error"]
        status, r = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
        status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": {"depth": 2}})
        assert status == 200, plan
        s.call("POST", "/api/jog", {"axis": "x", "steps": 40})  # the job's home is not the session's
        home = np.array(s.wait_idle()["position_steps"], np.int64)
        s.session.on_progress = lambda done, total, t_ns: s.session.stop() if done >= total // 3 else None
        assert s.call("POST", "/api/start", {"job": plan["job"]})[0] == 200
        st = s.wait_idle()
        s.session.on_progress = None
        assert st["last"]["status"] == "stopped" and st["last"]["journal"]
        first, stopped_at = s.session.last_job_pin_log, np.array(st["position_steps"], np.int64)
        status, r = s.call("POST", "/api/resume-job", {})
        assert status == 200, r
        st = s.wait_idle()
        assert st["last"]["status"] == "finished" and "resumed at move" in st["last"]["label"]
        second = s.session.last_job_pin_log
        job = prepare_job_like_the_page(SAMPLES / "ellipse.png")
    finally:
        s.close()
    settings = job.settings
    m1, m2 = decode_pin_log(first, settings), decode_pin_log(second, settings)
    both = Motion(np.r_[m1.t_ns, m2.t_ns], np.vstack([m1.position_steps, m2.position_steps + (stopped_at - home)]),
                  m1.step_counts + m2.step_counts)
    whole = decode_pin_log(cam.run(job.steps).pin_log(), settings)
    tp = job.toolpath
    shape_px = (tp.height_px, tp.width_px)
    assert np.array_equal(carve(both, shape_px, settings, origin_px=tp.origin_px),
                          carve(whole, shape_px, settings, origin_px=tp.origin_px))


def prepare_job_like_the_page(path: Path):
    from test_web import MEDIUM

    from cam.kinds.jobs import JobOptions, prepare_job

    return prepare_job(path, JobOptions(depth=(2,)), MEDIUM)


@pytest.mark.realtime
def test_the_journal_is_never_ahead_of_the_machine(tmp_path):
    """Every journal written while a job runs names a move and a position the writes already sent reached."""
    job, _ = _prepared(_drill_args("hpgl", tmp_path))
    journal = tmp_path / "j.journal.json"
    seen = []
    session = MachineSession("mock", job.settings, realtime=True, on_prompt=lambda prompt: "continue")
    try:
        session.start(job, journal=str(journal))
        while session.busy:
            if journal.exists():
                seen.append(read_journal(journal))
            time.sleep(0.05)
    finally:
        session.shutdown()
    running = [j for j in seen if j.state == "running" and j.writes_done > 0]
    assert len({j.writes_done for j in running}) >= 3  # updated as it ran
    positions = decode_pin_log(cam.PinLog(job.steps.t_ns, job.steps.data, job.steps.strobe), job.settings)
    for j in running:
        assert tuple(positions.position_steps[j.writes_done - 1]) == j.position_steps
        assert j.last_move == -1 or job.steps.point_write[j.last_move] < j.writes_done  # -1: no move done yet
        assert j.last_move + 1 == len(job.toolpath) or job.steps.point_write[j.last_move + 1] >= j.writes_done
    assert read_journal(journal).state == "finished"


def test_a_tampered_journal_is_refused_in_one_line_before_anything_is_planned(tmp_path):
    """Positions no run on this machine could have written (issue #33 point 4): refused from the numbers, at once
    (a position of 10^18 steps used to be walked a write at a time by the way in)."""
    done = _cam(_drill_args("2d", tmp_path, "--report", str(tmp_path / "r.json")))
    assert done.returncode == 0, done.stderr
    good = json.loads((tmp_path / "r.journal.json").read_text())
    good["state"] = "stopped"
    journal = tmp_path / "j.journal.json"
    for key, value, message in (
            ("position_steps", [10 ** 18, 0, 0], "'position_steps' puts the tool at X=1000000000000000000"),
            ("position_steps", [0, -5, 0], "'position_steps' puts the tool at Y=-5"),
            ("home_steps", [0, 0, 10 ** 9], "'home_steps' puts the tool at Z=1000000000"),
            ("writes_done", good["writes_total"] + 1, "is outside 0..writes_total")):
        journal.write_text(json.dumps(dict(good, **{key: value})))
        done = _cam(_drill_args("2d", tmp_path, "--resume", str(journal)))
        assert done.returncode == 2 and message in done.stderr and _one_line(done.stderr), (key, done.stderr)
