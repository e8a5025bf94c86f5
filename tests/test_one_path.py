"""One code path for the Python API, the command line and the page (issue #28 points 2 and 5).

``cam.run(job)`` (a notebook), ``cam.run(prepared)`` and ``cam drill FILE`` all run the job's step plan a chunk at
a time through the machine session and the runner's one send loop: the same writes, byte for byte, and the same
report.  The step plan held whole (``plan_steps``) is those chunks joined, whatever the chunk size.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import cam
from cam.motion.chunks import plan_chunks
from cam.drive.runner import Controller, Cursor, run
from cam.kinds.jobs import JobOptions, prepare_job
from cam.verify.pinlog import read_pin_log, write_pin_log
from conftest import SAMPLES, run_cli

SETTINGS = cam.MachineSettings()

# one file of every kind a step/dir job is made from, with the options the CLI takes for it
CASES = [
    ("ellipse.png", ["--depth", "5"], JobOptions(depth=(5,))),
    ("pyramid.png", ["--depth", "4"], JobOptions(depth=(4,))),
    ("board.drl", [], JobOptions()),
    ("extended.plt", [], JobOptions()),
    ("logo.svg", [], JobOptions()),
    ("bolt_plate.ngc", [], JobOptions()),
]


def _bytes(path) -> bytes:
    return path.read_bytes()


def assert_same_job_writes(api_log, cli_log) -> None:
    """The command's pin log holds the job as its one part (no travel: the job starts at the work zero where the
    tool stands), and that part's writes are the API's, time for time (issue #44 point 4 marks the parts)."""
    cli = read_pin_log(cli_log)
    assert [p.name for p in cli.parts] == ["job"], cli.parts
    job, api = read_pin_log(cli_log, part="job"), read_pin_log(api_log)
    assert np.array_equal(job.t_ns, api.t_ns) and np.array_equal(job.data, api.data)
    assert np.array_equal(job.strobe, api.strobe)
    rows = [line for line in _bytes(cli_log).splitlines() if not line.startswith(b"#")]
    assert b"\n".join(rows) + b"\n" == _bytes(api_log)  # the same text, but for the part line


@pytest.mark.parametrize("name,flags,options", CASES, ids=[c[0] for c in CASES])
def test_api_and_cli_give_the_same_pin_log_and_report(tmp_path, name, flags, options):
    """``cam.run(prepare_job(...))`` and ``cam drill FILE --pin-log --report`` write the same job."""
    src = SAMPLES / name
    cli_log, cli_report = tmp_path / "cli.csv", tmp_path / "cli.json"
    r = run_cli("drill", src, *flags, "--yes", "--pin-log", cli_log, "--report", cli_report)
    assert r.returncode == 0, r.stderr

    job = prepare_job(src, options, SETTINGS)
    result = cam.run(job)
    api_log = tmp_path / "api.csv"
    write_pin_log(result.pin_log(), api_log)
    assert_same_job_writes(api_log, cli_log)

    report = json.loads(cli_report.read_text())
    assert report.pop("status") == result.status == "finished"
    ours = json.loads(json.dumps(job.full_report()))
    assert {k: v for k, v in report.items() if k in ours} == ours


@pytest.mark.parametrize("ramp", ["lookahead", "linear40", "constant"])
def test_a_notebook_job_runs_the_chunked_plan_of_the_cli(tmp_path, ramp):
    """``cam.run(cam.plan(...))`` sends the writes ``cam drill`` sends for the same drawing and settings."""
    s = SETTINGS.replace(ramp=ramp)
    machine = tmp_path / "machine.toml"
    machine.write_text(f'ramp = "{ramp}"\n')
    job = cam.plan(cam.digitize(cam.load_image(SAMPLES / "ellipse.png")), depth=5, settings=s)
    api_log = tmp_path / "api.csv"
    write_pin_log(cam.run(job).pin_log(), api_log)
    cli_log = tmp_path / "cli.csv"
    r = run_cli("drill", SAMPLES / "ellipse.png", "--depth", "5", "--ramp", ramp, "--yes", "--pin-log", cli_log)
    assert r.returncode == 0, r.stderr
    assert_same_job_writes(api_log, cli_log)


@pytest.mark.parametrize("ramp,chunk_periods", [(r, c) if c > 1 else pytest.param(r, c, marks=pytest.mark.slow)
                                                for r in ("linear40", "constant") for c in (1, 7, 1000, 1 << 18)]
                         + [("lookahead", c) if c > 7 else pytest.param("lookahead", c, marks=pytest.mark.slow)
                            for c in (7, 1000, 1 << 18)])
def test_any_chunk_size_makes_the_same_writes(ramp, chunk_periods):
    """The writes do not depend on the chunk size (one period to the whole job) on a G-code job whose source
    moves (linear40's ramp segments) span many points: the same data always; the same times for the constant
    and linear40 ramps.  The look-ahead ramps are planned in windows of ``margin_periods`` around a chunk, and a
    window's ends are rests to it, so a chunk boundary can move a write's time (this job: 0.3 % of its machine
    time); such plans keep the acceleration rules (checked).  A chunk of one period breaks them at two seams of
    this job: filed as an issue, the runner's chunks are 2^18 periods.)"""
    from cam.verify.ramps import check_ramps

    from cam.formats.gcode import load_gcode
    from cam.job.gcode import plan_gcode

    s = SETTINGS.replace(ramp=ramp)
    job = plan_gcode(load_gcode(SAMPLES / "bolt_plate.ngc"), settings=s)
    whole = plan_chunks(job, chunk_periods=1 << 30).to_plan()
    got = plan_chunks(job, chunk_periods=chunk_periods, margin_periods=None).to_plan()
    np.testing.assert_array_equal(got.data, whole.data)
    if ramp == "lookahead":
        assert check_ramps(cam.PinLog(got.t_ns, got.data, got.strobe), s).ok
    else:
        np.testing.assert_array_equal(got.t_ns, whole.t_ns)


def test_linear40_in_chunks_equals_the_whole_job_ramp():
    """The streamed linear40 ramp is the seed's ramp over the whole job's periods (cam.motion.ramps)."""
    from cam.motion.ramps import ramp_periods
    from cam.formats.gcode import load_gcode
    from cam.job.gcode import plan_gcode

    s = SETTINGS.replace(ramp="linear40")
    job = plan_gcode(load_gcode(SAMPLES / "bolt_plate.ngc"), settings=s)
    nominal = plan_chunks(_with_settings(job, SETTINGS.replace(ramp="constant")), chunk_periods=64).to_plan()
    ramped = plan_chunks(job, chunk_periods=64).to_plan()
    per_nominal = np.diff(nominal.t_ns[0::2])
    per_ramped = np.diff(ramped.t_ns[0::2])
    pts = np.vstack([np.zeros((1, 3), np.int64), job.points_steps])
    n_per_move = np.maximum(np.abs(np.diff(pts, axis=0)).max(axis=1),
                            0 if job.periods is None else np.asarray(job.periods))
    first = np.cumsum(n_per_move) - n_per_move
    move_first = first if job.move_start is None else first[np.asarray(job.move_start, bool)]
    high = nominal.data[1::2]
    want = ramp_periods(high, per_nominal, s, move_first=move_first)
    np.testing.assert_array_equal(per_ramped, want)


def _with_settings(job, settings):
    from dataclasses import replace

    return replace(job, settings=settings)


def test_the_cursor_is_the_runs_live_position():
    """The runner's cursor says how many writes went out and where the tool is after them, at every pause."""
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    job = cam.plan(d, depth=5, pause_at=[tuple(d.objects[0][10])], settings=SETTINGS)
    whole = cam.plan_steps(job)
    cursor = Cursor(SETTINGS)
    seen = []
    result = run(job, cam.MockPort(), controller=Controller(),
                 on_pause=lambda pos, note: seen.append((cursor.sent, pos)), cursor=cursor)
    assert result.status == "finished" and cursor.sent == len(whole) == result.writes
    (sent, pos), = seen
    assert sent == int(whole.pause_writes[0]) + 1
    motion = cam.decode_pin_log(cam.PinLog(whole.t_ns[:sent], whole.data[:sent], whole.strobe[:sent]), SETTINGS)
    assert pos == motion.final_steps
