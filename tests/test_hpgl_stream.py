"""A large HPGL file planned as a stream (cam.job.hpgl_stream) equals plan_hpgl, and its memory does not grow."""
from __future__ import annotations

from typing import Optional

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import cam
import cam.kinds.jobs as jobs
from cam.motion.chunks import plan_chunks
from cam.drive.ports import MockPort
from cam.drive.runner import run
from cam.motion.steps import plan_steps
from cam.errors import CamError
from cam.formats.hpgl import load_hpgl
from cam.job.hpgl import plan_hpgl
from cam.job.hpgl_stream import stream_hpgl
from cam.kinds.jobs import JobOptions, prepare_job
from cam.verify.pinlog import read_pin_log

SLOW_CASES = {'test_streamed_plan_equals_whole_plan[lookahead]',
              'test_a_stopped_streamed_hpgl_job_resumes_and_carves_as_an_uninterrupted_run[0.3]'}
"""Cases that run in the slow tier only (tests/conftest.py): the same checks keep faster cases here."""


SAMPLES = Path(__file__).resolve().parent.parent / "samples"


def _random_hpgl(seed: int, n_cmds: int = 300, clip_pu: Optional[int] = None) -> bytes:
    """Pens that change, SP0, dots, repeated points, strokes that join the last one, relative moves;
    ``clip_pu``: pen-down points kept within +-clip_pu plotter units (None: wherever the walk goes)."""
    rng = np.random.default_rng(seed)
    out = ["IN;"]
    x = y = 0
    for _ in range(n_cmds):
        r = rng.random()
        if r < 0.08:
            out.append(f"SP{int(rng.integers(0, 4))};")
        elif r < 0.3:
            x, y = x + int(rng.integers(-2, 3)), y + int(rng.integers(-2, 3))
            out.append(f"PU{x},{y};")
        elif r < 0.35:
            out.append("PD;PU;")
        elif r < 0.45:
            out.append(f"PR{int(rng.integers(-50, 51))},{int(rng.integers(-50, 51))};PA;")
        else:
            pts = []
            for _ in range(int(rng.integers(1, 8))):
                if rng.random() > 0.2:
                    x, y = x + int(rng.integers(-300, 301)), y + int(rng.integers(-300, 301))
                    if clip_pu is not None:
                        x, y = int(np.clip(x, -clip_pu, clip_pu)), int(np.clip(y, -clip_pu, clip_pu))
                pts += [str(x), str(y)]
            out.append("PD" + ",".join(pts) + ";")
    out.append("PU0,0;")
    return "".join(out).encode()


def _files(tmp_path: Path) -> list[Path]:
    files = sorted(SAMPLES.glob("*.plt"))
    for seed in range(6):
        p = tmp_path / f"r{seed}.plt"
        p.write_bytes(_random_hpgl(seed))
        files.append(p)
    return files


@pytest.mark.parametrize("piece_points,chunk_bytes", [pytest.param(1, 64, marks=pytest.mark.slow), (5, 333), (4096, 1 << 19)])
def test_stream_equals_plan_hpgl(tmp_path, piece_points, chunk_bytes):
    s = cam.MachineSettings()
    for path in _files(tmp_path):
        for offset in (None, (40.0, 120.0), (0.0, 0.0)):
            stream = stream_hpgl(path, settings=s, offset_mm=offset, piece_points=piece_points,
                                 chunk_bytes=chunk_bytes)
            try:
                whole = plan_hpgl(load_hpgl(path), settings=s, offset_mm=offset)
            except CamError as exc:  # outside the travel: the same message, naming the same point
                with pytest.raises(type(exc)) as got:
                    stream.joined()
                assert str(got.value) == str(exc)
                continue
            job = stream.joined()
            for name in ("points_steps", "kind", "target", "pause"):
                np.testing.assert_array_equal(getattr(job, name), getattr(whole, name), err_msg=f"{path} {name}")
            assert job.pause_notes == whole.pause_notes
            assert len(stream) == len(whole)


@pytest.mark.parametrize("ramp", ["lookahead", pytest.param("constant", marks=pytest.mark.slow), pytest.param("linear40", marks=pytest.mark.slow)])
def test_streamed_plan_equals_whole_plan(tmp_path, ramp):
    s = cam.MachineSettings().replace(ramp=ramp)
    for path in _files(tmp_path)[:5]:
        whole = plan_steps(plan_hpgl(load_hpgl(path), settings=s))
        chunked = plan_chunks(stream_hpgl(path, settings=s, piece_points=3, chunk_bytes=100), chunk_periods=211)
        got = chunked.to_plan()
        for name in ("t_ns", "data", "strobe", "point_write", "pause_writes"):
            np.testing.assert_array_equal(getattr(got, name), getattr(whole, name), err_msg=f"{path} {name}")
        assert chunked.pause_notes == whole.pause_notes
        np.testing.assert_array_equal(chunked.steps_total, whole.steps_total)
        assert chunked.end_steps == whole.end_steps


def test_prepared_stream_runs_as_the_in_memory_job(tmp_path, monkeypatch):
    """Above STREAM_POINTS the file is streamed: the same pin log and report."""
    src = SAMPLES / "extended.plt"
    opts = JobOptions()
    s = cam.MachineSettings().replace(ramp="lookahead")
    whole = prepare_job(src, opts, s)
    monkeypatch.setattr("cam.job.hpgl_stream.STREAM_POINTS", 2)
    streamed = prepare_job(src, opts, s)
    assert not hasattr(streamed.toolpath, "points_steps")
    np.testing.assert_array_equal(streamed.extent_steps, whole.extent_steps)
    assert streamed.estimated_time_s == whole.estimated_time_s
    assert streamed.tool_changes == whole.tool_changes
    for key in ("strokes", "points", "pens", "steps", "size_mm", "depth_mm"):
        assert streamed.report[key] == whole.report[key], key
    logs = []
    for job, name in ((whole, "w.csv"), (streamed, "s.csv")):
        port = MockPort(pin_log_path=tmp_path / name)
        session = cam.MachineSession(port, s, on_prompt=lambda prompt: "continue")
        session.run(job)
        port.finish_pin_log()
        logs.append(read_pin_log(tmp_path / name))
    np.testing.assert_array_equal(logs[0].t_ns, logs[1].t_ns)
    np.testing.assert_array_equal(logs[0].data, logs[1].data)


@pytest.mark.parametrize("stop_at", [0.3, pytest.param(0.8, marks=pytest.mark.slow)])
def test_a_stopped_streamed_hpgl_job_resumes_and_carves_as_an_uninterrupted_run(tmp_path, monkeypatch, stop_at):
    """A streamed HPGL job with pen changes (tool-change pauses), stopped anywhere, resumes from its journal."""
    from test_drawing_stream import stop_and_resume
    src = SAMPLES / "extended.plt"
    s = cam.MachineSettings().replace(ramp="constant", delay_xy_ms=0.02, delay_z_ms=0.02)
    monkeypatch.setattr("cam.job.hpgl_stream.STREAM_POINTS", 2)
    stop_and_resume(prepare_job(src, JobOptions(), s), tmp_path, stop_at, lambda: prepare_job(src, JobOptions(), s))


def test_streamed_journal_counts_moves_as_the_whole_plan(monkeypatch):
    """The journal of a streamed run finds the last completed move from the blocks made lately."""
    s = cam.MachineSettings()
    src = SAMPLES / "inkscape_star.plt"
    chunked = plan_chunks(stream_hpgl(src, settings=s, piece_points=2, chunk_bytes=64), chunk_periods=50)
    point_write = chunked.full_point_write()
    recent = chunked.point_write
    from cam.job.resume import last_completed
    for chunk in chunked.chunks():
        for w in (chunk.first_write, chunk.first_write + len(chunk) // 2, chunk.first_write + len(chunk)):
            assert recent.last_completed(w) <= last_completed(point_write, w)
            assert recent.last_completed(w) == last_completed(point_write, w) or w < int(recent.blocks[0][1][0])
        chunked.live = (chunk.first_write + len(chunk), (0, 0, 0))


def _zigzag_hpgl(path: Path, n_blocks: int) -> None:
    zigzag = "PU0,0;PD" + ",".join(f"{3 * i},{3 * (i % 2)}" for i in range(1, 12)) + ";"
    path.write_text("IN;SP1;" + zigzag * (256 * n_blocks) + "PU0,0;")


def _peak_of_streamed_run(path: Path, s) -> int:
    stream = stream_hpgl(path, settings=s, piece_points=4096, chunk_bytes=1 << 14)
    tracemalloc.start()
    try:
        plan = plan_chunks(stream, chunk_periods=1 << 12)
        plan.motion_extent()
        run(plan, port=MockPort(pin_log_path=path.with_suffix(".csv")), on_pause=lambda *a: None)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_streamed_memory_does_not_grow_with_the_file(tmp_path, small_pin_log_queue):
    """Planning, the extent and a run with its pin log of a file 4x longer take about the same peak memory. (What
    a plan keeps for the journal, the last ~4 chunks of moves, is full at the smaller file already.)"""
    s = cam.MachineSettings().replace(ramp="lookahead", travel=cam.settings.Travel(
        x_max_steps=10**6, y_max_steps=10**6, z_min_steps=-10**4, z_max_steps=10**4))
    small, large = tmp_path / "small.plt", tmp_path / "large.plt"
    _zigzag_hpgl(small, 16)
    _zigzag_hpgl(large, 64)
    _peak_of_streamed_run(large, s)  # warm up: numba's lazy imports are not the job's memory
    a = _peak_of_streamed_run(small, s)
    b = _peak_of_streamed_run(large, s)
    assert b < 1.1 * a + (256 << 10), (a, b)


def test_streamed_preview_equals_the_in_memory_one(monkeypatch):
    """The preview of a streamed job is drawn a piece at a time and is the in-memory job's picture."""
    src = SAMPLES / "extended.plt"
    whole = prepare_job(src)
    monkeypatch.setattr("cam.job.hpgl_stream.STREAM_POINTS", 2)
    streamed = prepare_job(src)
    streamed.toolpath.piece_points, streamed.toolpath.chunk_bytes = 3, 64
    assert sum(1 for _ in streamed.toolpath.pieces()) > 5
    np.testing.assert_array_equal(streamed.preview_picture(), whole.preview_picture())


def test_streamed_gcode_out_equals_the_in_memory_one(tmp_path, monkeypatch):
    """cam export of a streamed HPGL file (pen changes and all) writes the in-memory job's G-code."""
    from cam.cli import main
    src = SAMPLES / "extended.plt"
    assert main(["export", str(src), "-o", str(tmp_path / "w.ngc")]) == 0
    monkeypatch.setattr("cam.job.hpgl_stream.STREAM_POINTS", 2)
    assert main(["export", str(src), "-o", str(tmp_path / "s.ngc")]) == 0
    text = (tmp_path / "s.ngc").read_text()
    assert text == (tmp_path / "w.ngc").read_text() and "M6" in text
