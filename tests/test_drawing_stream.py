"""A large drawing planned as a stream (cam.job.drawing_stream) equals cam.plan, and cuts what the drawing asks."""
from __future__ import annotations

import tracemalloc
from pathlib import Path

import cv2
import numpy as np
import pytest

import cam
import cam.job.jobs as jobs
from cam.cli import main
from cam.drive.chunks import plan_chunks
from cam.drive.ports import MockPort
from cam.drive.runner import run
from cam.errors import CamError
from cam.job.drawing_stream import stream_drawing
from cam.job.jobs import JobOptions, prepare_job, resume_job
from cam.job.resume import Journal
from cam.verify.pinlog import read_pin_log
from conftest import SAMPLES, assert_surface_equal

CASES = [
    ("ring.png", dict(profile=lambda k: 1 + k % 7, pause_at=[(30, 30), (10**6, 3)])),
    ("gear.png", dict(depth=5, passes=3, start_at=(3, 4, 2))),
    ("word.png", dict(depth=4, start_at=(-2, 0, -1))),
    ("ring.png", dict(profile=lambda k: 1 + 2 * k, tool="ball:1", start_at=(5, 5, -1))),
    ("heart.png", dict(profile=lambda k: 3 + k, tool="v:60:0.1", passes=2)),
    ("dumbbell.png", dict(profile=lambda k: 2 + k // 2, tool="flat:0.8")),
]


@pytest.mark.parametrize("name,kw", CASES, ids=[f"{n}-{i}" for i, (n, _) in enumerate(CASES)])
@pytest.mark.parametrize("piece_targets", [1, 7, 500, 10**7])
def test_stream_equals_plan(name, kw, piece_targets):
    """The pieces, joined, are cam.plan's job row for row (points, kinds, targets, pauses), with its counts."""
    d = cam.digitize(cam.load_image(SAMPLES / name))
    kw = dict(kw)
    if d.mode == "2d":
        kw.pop("profile", None)
    if "pause_at" in kw:
        kw["pause_at"] = [tuple(int(v) for v in d.objects[0][3])] + kw["pause_at"][1:]
    whole = cam.plan(d, **kw)
    stream = stream_drawing(d, piece_targets=piece_targets, **kw)
    joined = stream.to_job()
    for attr in ("points_steps", "kind", "target", "pause"):
        np.testing.assert_array_equal(getattr(joined, attr), getattr(whole, attr), err_msg=attr)
    assert (len(stream), stream.n_targets, stream.n_retracts) == (len(whole), whole.n_targets, whole.n_retracts)
    np.testing.assert_array_equal(stream.asked_depth_px(), whole.asked_depth_px())
    assert stream.deepest_px == int(whole.asked_depth_px().max())
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
    monkeypatch.setattr(jobs, "STREAM_TARGETS", 100)
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
    journal = Journal(identity=streamed.identity, plan_sha256=streamed.plan_sha256, source=str(src),
                      moves=len(streamed.toolpath), last_move=3, position_steps=(0, 0, 0), state="stopped")
    with pytest.raises(CamError, match="a piece at a time"):
        resume_job(streamed, journal)


def test_cli_streams_a_large_drawing(tmp_path, monkeypatch, capsys):
    """cam drill on a streamed relief: the same pin log as in memory, a .png preview of its moves; a surface
    picture and G-code out are refused with one line and exit code 2."""
    src = _big_relief(tmp_path)
    args = [str(src), "--profile-expr", "1 + k // 3", "--yes", "--no-progress"]
    assert main(["drill", *args, "--pin-log", str(tmp_path / "w.csv")]) == 0
    monkeypatch.setattr(jobs, "STREAM_TARGETS", 100)
    assert main(["drill", *args, "--pin-log", str(tmp_path / "s.csv"), "--preview", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "w.csv").read_bytes() == (tmp_path / "s.csv").read_bytes()
    picture = cv2.imread(str(tmp_path / "p.png"))
    assert picture is not None and picture.shape[0] > 100
    capsys.readouterr()
    for extra in (["preview", str(src), "--profile-expr", "1 + k // 3", "--surface", "-o", str(tmp_path / "c.png")],
                  ["export", str(src), "--profile-expr", "1 + k // 3", "-o", str(tmp_path / "c.ngc")]):
        assert main(extra) == 2
        err = capsys.readouterr().err.strip()
        assert "a piece at a time" in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "c.png").exists() and not (tmp_path / "c.ngc").exists()


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


def test_streamed_memory_grows_with_the_drawing_not_the_job():
    """A relief of 4x the pixels takes no more memory than its larger maps of the drawing (8 bytes a pixel) beyond
    the smaller one's: nothing per move is held (the whole job of the larger would take about 6 MB more)."""
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
