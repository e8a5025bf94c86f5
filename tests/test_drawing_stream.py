"""A large drawing planned as a stream (cam.job.drawing_stream, the one drawing planner) equals cam.plan (its
pieces joined) at any piece size, and cuts what the drawing asks."""
from __future__ import annotations

import tracemalloc
from pathlib import Path

import cv2
import numpy as np
import pytest

import cam
import cam.job.drawing_stream
import cam.kinds.jobs as jobs
from cam.cli import main
from cam.motion.chunks import plan_chunks
from cam.drive.ports import MockPort
from cam.drive.runner import run
from cam.job.drawing_stream import stream_drawing
from cam.kinds.jobs import JobOptions, prepare_job, resume_job
from cam.verify.pinlog import read_pin_log
from conftest import SAMPLES, assert_surface_equal

SLOW_CASES = {
    'test_stream_equals_plan[10000000-heart.png-4]',
    
    'test_stream_equals_plan[7-ring.png-3]',
    'test_stream_equals_plan[7-dumbbell.png-5]',
    'test_stream_equals_plan[7-heart.png-4]', 'test_a_stopped_streamed_drawing_resumes_and_carves_as_an_uninterrupted_run[0.2]'}
"""Cases that run in the slow tier only (tests/conftest.py): the same checks keep faster cases here."""


CASES = [
    ("ring.png", dict(profile=lambda k: 1 + k % 7, pause_at=[(30, 30), (10**6, 3)])),
    ("gear.png", dict(depth=5, passes=3, start_at=(3, 4, 2))),
    ("word.png", dict(depth=4, start_at=(-2, 0, -1))),
    ("ring.png", dict(profile=lambda k: 1 + 2 * k, tool="ball:1", start_at=(5, 5, -1))),
    ("heart.png", dict(profile=lambda k: 3 + k, tool="v:60:0.1", passes=2)),
    ("dumbbell.png", dict(profile=lambda k: 2 + k // 2, tool="flat:0.8")),
]


@pytest.mark.parametrize("name,kw", CASES, ids=[f"{n}-{i}" for i, (n, _) in enumerate(CASES)])
@pytest.mark.parametrize("piece_targets", [pytest.param(1, marks=pytest.mark.slow), 7, pytest.param(500, marks=pytest.mark.slow), 10**7])
def test_stream_equals_plan(name, kw, piece_targets):
    """The pieces, joined, are cam.plan's job row for row (points, kinds, targets, pauses), with its counts; a real
    tool's finer pass is in both (cam.plan is the stream joined)."""
    d = cam.digitize(cam.load_image(SAMPLES / name))
    kw = dict(kw)
    if d.mode == "2d":
        kw.pop("profile", None)
    if "pause_at" in kw:
        kw["pause_at"] = [tuple(int(v) for v in d.objects[0][3])] + kw["pause_at"][1:]
    whole = cam.plan(d, **kw)
    stream = stream_drawing(d, piece_targets=piece_targets, **kw)
    joined = stream.joined()
    for attr in ("points_steps", "kind", "target", "pause"):
        np.testing.assert_array_equal(getattr(joined, attr), getattr(whole, attr), err_msg=attr)
    assert (len(stream), stream.n_targets, stream.n_retracts) == (len(whole), whole.n_targets, whole.n_retracts)
    np.testing.assert_array_equal(stream.asked_depth_px(), whole.asked_depth_px())
    assert stream.deepest_px == int(whole.asked_depth_px().max())
    assert not any("left out" in w for w in stream.warnings)  # the finer pass is part of the stream
    assert stream.warnings == whole.warnings and stream.safe_z_steps == whole.safe_z_steps
    assert stream.tool == whole.tool and stream.pixels == whole.pixels
    if piece_targets == 7:
        assert sum(1 for _ in stream.pieces()) > 10


def test_stream_refuses_what_plan_refuses():
    d = cam.digitize(cam.load_image(SAMPLES / "ring.png"))
    with pytest.raises(cam.PlanError, match="profile"):
        stream_drawing(d)
    with pytest.raises(cam.PlanError, match="every depth is 0"):
        stream_drawing(d, depth=0)
    with pytest.raises(cam.PlanError, match="does not fit"):
        stream_drawing(d, profile=lambda k: 1, tool="flat:40")
    small = cam.MachineSettings().replace(travel=cam.settings.Travel(x_max_steps=50, y_max_steps=10**5))
    with pytest.raises(cam.TravelError):
        stream_drawing(d, profile=lambda k: k, settings=small)


def _big_relief(tmp_path: Path) -> Path:
    """A 3D drawing as a scanner gives it: a JPEG of a red disc with an anti-aliased black rim."""
    img = np.full((150, 170, 3), 255, np.uint8)
    cv2.circle(img, (85, 75), 60, (0, 0, 255), -1, lineType=cv2.LINE_AA)
    cv2.circle(img, (85, 75), 60, (0, 0, 0), 1, lineType=cv2.LINE_AA)
    path = tmp_path / "DISC.JPG"
    cv2.imwrite(str(path), img, [cv2.IMWRITE_JPEG_QUALITY, 92])
    return path


def _mock_run(job, settings, log: Path):
    port = MockPort(pin_log_path=log)
    cam.MachineSession(port, settings, on_prompt=lambda prompt: "continue").run(job)
    port.finish_pin_log()
    return read_pin_log(log)


def test_prepared_stream_runs_as_the_in_memory_job(tmp_path, monkeypatch):
    """Above STREAM_TARGETS a drawing is planned a piece at a time: the same report and pin log as in memory,
    and the pin log carves exactly the relief asked; resume and G-code out are refused in one line."""
    src = _big_relief(tmp_path)
    opts = JobOptions(profile_expr="1 + k // 3")
    s = cam.MachineSettings().replace(ramp="lookahead", steps_per_px_xy=2)
    whole = prepare_job(src, opts, s)
    monkeypatch.setattr("cam.job.drawing_stream.STREAM_TARGETS", 100)
    streamed = prepare_job(src, opts, s)
    assert not hasattr(streamed.toolpath, "points_steps") and streamed.toolpath.n_targets > 100
    streamed.toolpath.piece_targets = 37  # many pieces
    np.testing.assert_array_equal(streamed.extent_steps, whole.extent_steps)
    assert streamed.estimated_time_s == whole.estimated_time_s
    for key in ("objects", "rings", "points", "retracts", "depth_px", "depth_mm", "steps", "width_mm"):
        assert streamed.report[key] == whole.report[key], key
    a = _mock_run(whole, s, tmp_path / "w.csv")
    b = _mock_run(streamed, s, tmp_path / "s.csv")
    np.testing.assert_array_equal(a.t_ns, b.t_ns)
    np.testing.assert_array_equal(a.data, b.data)
    motion = cam.decode_pin_log(b, s)
    surface = cam.carve(motion, (whole.toolpath.height_px, whole.toolpath.width_px), s)
    assert_surface_equal(surface, whole.toolpath.asked_depth_px() * s.steps_per_px_z)



def stop_and_resume(job, tmp_path: Path, stop_at: float, prepare_again) -> None:
    """Run ``job`` in real time on the mock, emergency-stop it at ``stop_at`` of its writes, resume it from its
    journal (the job planned again by ``prepare_again()``): the two pin logs carve as an uninterrupted run."""
    from cam.drive.journal import read_journal
    from cam.drive.session import MachineSession
    from cam.verify.pinlog import write_pin_log
    from test_resume import _check_union, estop_run
    journal, first, second = tmp_path / "run.journal.json", tmp_path / "run1.csv", tmp_path / "run2.csv"
    estop_run(job, journal, first, stop_at)
    record = read_journal(journal)
    again = prepare_again()
    assert not hasattr(again.toolpath, "points_steps")
    resumed = resume_job(again, record)
    assert resumed.report["resumed_at_move"] > record.last_move
    session = MachineSession("mock", job.settings, on_prompt=lambda prompt: "continue")
    session.set_position(record.position_steps)
    session.run(resumed)
    write_pin_log(session.last_job_pin_log, second)
    _check_union("stream", tmp_path, again, first, second, record.position_steps)


@pytest.mark.parametrize("stop_at", [0.2, pytest.param(0.55, marks=pytest.mark.slow), pytest.param(0.9, marks=pytest.mark.slow)])
def test_a_stopped_streamed_drawing_resumes_and_carves_as_an_uninterrupted_run(tmp_path, monkeypatch, stop_at):
    src = _big_relief(tmp_path)
    opts = JobOptions(profile_expr="1 + k // 3")
    s = cam.MachineSettings().replace(ramp="constant", delay_xy_ms=0.05, delay_z_ms=0.05)
    monkeypatch.setattr("cam.job.drawing_stream.STREAM_TARGETS", 100)
    stop_and_resume(prepare_job(src, opts, s), tmp_path, stop_at, lambda: prepare_job(src, opts, s))


@pytest.mark.slow
def test_cli_streams_a_large_drawing(tmp_path, monkeypatch):
    """cam drill and cam export on a streamed relief: the same pin log and G-code as in memory, a .png preview
    of its moves; its surface picture is the in-memory job's, byte for byte."""
    src = _big_relief(tmp_path)
    args = [str(src), "--profile-expr", "1 + k // 3"]
    assert main(["drill", *args, "--yes", "--no-progress", "--pin-log", str(tmp_path / "w.csv")]) == 0
    assert main(["export", *args, "-o", str(tmp_path / "w.ngc")]) == 0
    assert main(["preview", *args, "--surface", "-o", str(tmp_path / "wc.png")]) == 0
    monkeypatch.setattr("cam.job.drawing_stream.STREAM_TARGETS", 100)
    monkeypatch.setattr(cam.job.drawing_stream, "PIECE_TARGETS", 50)
    assert main(["drill", *args, "--yes", "--no-progress", "--pin-log", str(tmp_path / "s.csv"),
                 "--preview", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "w.csv").read_bytes() == (tmp_path / "s.csv").read_bytes()
    assert main(["export", *args, "-o", str(tmp_path / "s.ngc")]) == 0
    assert (tmp_path / "w.ngc").read_text() == (tmp_path / "s.ngc").read_text()
    picture = cv2.imread(str(tmp_path / "p.png"))
    assert picture is not None and picture.shape[0] > 100
    assert main(["preview", *args, "--surface", "-o", str(tmp_path / "c.png")]) == 0
    assert (tmp_path / "c.png").read_bytes() == (tmp_path / "wc.png").read_bytes()


def _peak_of_streamed_run(d: cam.Digitized, s: cam.MachineSettings, log: Path) -> int:
    tracemalloc.start()
    try:
        stream = stream_drawing(d, profile=lambda k: 1 + k // 4, settings=s, piece_targets=2048)
        plan = plan_chunks(stream, chunk_periods=1 << 12)
        plan.motion_extent()
        run(plan, port=MockPort(pin_log_path=log), on_pause=lambda *a: None)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_streamed_memory_grows_with_the_drawing_not_the_job(small_pin_log_queue):
    """A relief of 4x the pixels takes no more memory than its larger maps of the drawing (8 bytes a pixel) beyond
    the smaller one's: nothing per move is held (the whole job of the larger would take about 6 MB more).  The pin log's writer queue is made
    small: its fill at the peak is noise (5.4 MB one CI run, 10 MB the next, for the same job)."""
    s = cam.MachineSettings().replace(travel=cam.settings.Travel(
        x_max_steps=10**6, y_max_steps=10**6, z_min_steps=-10**4, z_max_steps=10**4))
    import tempfile
    peaks = []
    with tempfile.TemporaryDirectory() as tmp:
        for size in (160, 160, 320):
            img = np.full((size, size, 3), 255, np.uint8)
            cv2.circle(img, (size // 2, size // 2), size // 2 - 4, (255, 0, 0), -1)  # RGB red
            cv2.circle(img, (size // 2, size // 2), size // 2 - 4, (0, 0, 0), 1)
            d = cam.digitize(cam.load_image(img))
            peaks.append(_peak_of_streamed_run(d, s, Path(tmp) / "log.csv"))
    small, large = peaks[1], peaks[2]
    # the maps of the drawing (asked depths, drop-cutter none, pixels 4x) and a fixed piece/chunk working set
    assert large < small + 4 * (320 * 320 * 8), (small, large)


def _streams():
    from cam.job.hpgl_stream import stream_hpgl
    d = cam.digitize(cam.load_image(SAMPLES / "ring.png"))
    drawing = stream_drawing(d, profile=lambda k: 1 + k % 5, start_at=(2, 1, 1), piece_targets=90,
                             pause_at=[tuple(int(v) for v in d.objects[1][4]), tuple(int(v) for v in d.objects[-1][2])])
    hpgl = stream_hpgl(SAMPLES / "extended.plt", piece_points=5, chunk_bytes=64)
    return {"drawing": drawing, "hpgl": hpgl}


@pytest.mark.parametrize("kind", [pytest.param("drawing", marks=pytest.mark.slow), "hpgl"])
def test_a_resumed_stream_equals_the_resumed_whole_job(kind):
    """resume_pieces of the stream, joined, is resume_toolpath of the whole job at any stop: points, kinds, pauses and their
    notes, and the move each point completes."""
    from cam.job.resume import resume_toolpath
    from cam.job.resume import resume_pieces
    stream = _streams()[kind]
    whole = stream.joined()
    n = len(whole.points_steps)
    assert whole.pause.sum() >= 2
    rng = np.random.default_rng(5)
    pauses = np.flatnonzero(whole.pause)
    stops = [-1, 0, n - 1, n - 2, *pauses.tolist(), *(pauses - 1).tolist(), *rng.integers(0, n, 12).tolist()]
    for k in stops:
        for pending in (False, True):
            pos = tuple(int(v) for v in np.maximum(whole.points_steps[max(k, 0)] + rng.integers(-3, 4, 3), 0))
            want, index, j = resume_toolpath(whole, k, pos, pause_pending=pending)
            got, move_index, j2 = resume_pieces(stream, k, pos, pause_pending=pending)
            joined = list(got.pieces())
            for attr in ("points_steps", "kind", "target", "pause"):
                np.testing.assert_array_equal(np.concatenate([getattr(p, attr) for p in joined]), getattr(want, attr),
                                              err_msg=f"{attr} k={k}")
            assert j2 == j and len(got) == len(want.points_steps) and got.safe_z_steps == want.safe_z_steps
            assert [move_index[i] for i in range(len(index))] == index.tolist()
            plan_a, plan_b = plan_chunks(want, start_steps=pos), plan_chunks(got, start_steps=pos)
            assert plan_b.pause_notes == plan_a.pause_notes, k
            np.testing.assert_array_equal(plan_b.pause_writes, plan_a.pause_writes)
