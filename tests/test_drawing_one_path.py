"""One drawing planner at every size (issue #28): a drawing's job is the same whatever the size of its pieces.

cam.plan is the piece-wise planner's pieces joined (cam.job.drawing_stream); here the plan made one target a
piece (and 2, 7) and in one piece must give the same joined job row for row, the same mock pin log byte for
byte, the same G-code and the same pictures (toolpath .png and .svg, cut surface) -- for 2D and 3D drawings
with depth lists, passes, Pause At, Start At, real tools with their finer pass and roughing.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import pytest

import cam
import cam.kinds.jobs as jobs
from cam.cli.planning import carved_surface, write_job_preview, write_preview
from cam.motion.chunks import plan_chunks
from cam.kinds.gcode_export import to_gcode
from cam.job.drawing_stream import DrawingJobStream, stream_drawing
from cam.kinds.jobs import JobOptions, prepare_job
from cam.job.model import Job
from cam.verify.pinlog import write_pin_log
from conftest import SAMPLES
from test_tools import disc

ONE_PIECE = 10**9
HEMISPHERE = "round(sqrt(n*n-(n-k)*(n-k))*4)"
_disc = disc  # a 3D drawing: a red disc with a black rim (tests/test_tools.py)


def _two_curves() -> tuple[cam.Digitized, dict]:
    d = cam.digitize(cam.load_image(SAMPLES / "two_curves.png"))
    pause = [tuple(int(v) for v in d.objects[1][10]), (10**6, 1)]
    return d, dict(depth=[3, 5], passes=3, start_at=(4, 2, 1), pause_at=pause)


def _word() -> tuple[cam.Digitized, dict]:
    return cam.digitize(cam.load_image(SAMPLES / "word.png")), dict(depth=4, tool="v:90:0", passes=2,
                                                                    start_at=(-1, 0, -1))


Z_PX_MM = cam.MachineSettings().px_to_mm_z(1)
"""One Z pixel in mm (the step-down is given in mm, as the job option stepdown_mm)."""


def _relief(size: int, radius: int, expr: str, **kw) -> tuple[cam.Digitized, dict]:
    d = cam.digitize(_disc(size, radius))
    kw = dict(kw)
    if kw.pop("pause", False):
        kw["pause_at"] = [tuple(int(v) for v in d.objects[1][2])]
    return d, dict(profile=cam.profile_from_expr(expr, d.n_layers), **kw)


CASES = {
    "2d-depth-list-passes-pause-start": _two_curves,
    "2d-v-tool-passes": _word,
    "3d-ball-finer-pause-start": lambda: _relief(21, 9, HEMISPHERE, tool="ball:1", start_at=(2, 1, 1), pause=True),
    "3d-flat-finer-start-z": lambda: _relief(21, 9, HEMISPHERE, tool="flat:0.5", start_at=(0, 3, 2)),
    "3d-v-cone-passes": lambda: _relief(21, 9, "k*3", tool="v:60:0", passes=2),
    "3d-rough-tool-change-then-ball": lambda: _relief(25, 11, HEMISPHERE, tool="ball:1", stepdown_mm=8 * Z_PX_MM,
                                                      rough_tool="flat:1", pause=True),
    "3d-rough-point-stepover": lambda: _relief(21, 9, HEMISPHERE, stepdown_mm=5 * Z_PX_MM, stepover=0.3,
                                               start_at=(1, 1, 0)),
}


def _same_job(a: Job, b: Job) -> None:
    for attr in ("points_steps", "kind", "target", "pause"):
        np.testing.assert_array_equal(getattr(a, attr), getattr(b, attr), err_msg=attr)
    for attr in ("pause_notes", "warnings", "safe_z_steps", "pixels", "tool", "settings", "source"):
        assert getattr(a, attr) == getattr(b, attr), attr


FAST_CASES = ("2d-depth-list-passes-pause-start", "2d-v-tool-passes", "3d-ball-finer-pause-start")
"""The cases of the fast tier (one 3D relief with a tool, the finer pass, a pause and a Start At offset); the
other reliefs run in the slow tier."""


SLOW_CASES = {
    'test_the_piece_size_never_changes_the_joined_job[3d-ball-finer-pause-start-1]',
    'test_the_surface_carved_a_chunk_at_a_time_is_the_simulated_surface[2d-v-tool-passes-2]',
    'test_the_surface_carved_a_chunk_at_a_time_is_the_simulated_surface[2d-v-tool-passes-3]',
    "test_pin_logs_gcode_and_pictures_are_the_same_at_any_piece_size[3d-ball-finer-pause-start]",
              "test_pin_logs_gcode_and_pictures_are_the_same_at_any_piece_size[2d-v-tool-passes]",
              "test_a_prepared_job_is_the_same_held_or_in_pieces[roughing]",
              "test_pin_logs_gcode_and_pictures_are_the_same_at_any_piece_size[2d-depth-list-passes-pause-start]",
              "test_a_prepared_job_is_the_same_held_or_in_pieces[finer-pass]"}
"""Fast-tier cases that run in the slow tier all the same (tests/conftest.py): the same checks run fast on the
2D cases and, for the relief, in the other tests of this module."""


@pytest.fixture(scope="module", params=[k if k in FAST_CASES else pytest.param(k, marks=pytest.mark.slow)
                                        for k in CASES])
def case(request):
    d, kw = CASES[request.param]()
    whole = stream_drawing(d, piece_targets=ONE_PIECE, **kw)
    return request.param, d, kw, whole, whole.joined()


@pytest.mark.parametrize("piece_targets", [1, 2, 7])
def test_the_piece_size_never_changes_the_joined_job(case, piece_targets):
    """Joined, the pieces of any size are cam.plan's job and the one-piece job, row for row and attribute for
    attribute; the stream's counts and pause notes are the joined job's."""
    name, d, kw, _, one = case
    stream = stream_drawing(d, piece_targets=piece_targets, **kw)
    joined = stream.joined()
    _same_job(joined, one)
    _same_job(cam.plan(d, **kw), one)
    assert sum(1 for _ in stream.pieces()) > 10
    assert (len(stream), stream.n_targets, stream.n_retracts) == (len(one), one.n_targets, one.n_retracts)
    assert stream.pause_notes == one.pause_notes
    np.testing.assert_array_equal(stream.asked_depth_px(), one.asked_depth_px())
    assert not any("left out" in w for w in one.warnings)
    if name.startswith("3d-rough-tool"):
        assert one.pause_notes[0].startswith("tool change") and one.pause.sum() == 2
    if "finer" in name:  # the finer pass is there: points after the pixel-centre pass that are no targets
        assert stream.finer is not None and len(stream.finer.targets) > 10
        assert len(one) > np.flatnonzero(one.target)[-1] + 10


def _pin_log_bytes(job, path: Path) -> bytes:
    write_pin_log(cam.run(job).pin_log(), path)
    return path.read_bytes()


def _pictures(job, tmp_path: Path, tag: str) -> list[bytes]:
    args = argparse.Namespace(scale=None)
    out = []
    for name, surface in (("p.png", False), ("p.svg", False), ("s.png", True)):
        path = tmp_path / f"{tag}-{name}"
        write_preview(args, job, str(path), surface=surface)
        out.append(path.read_bytes())
    return out


def test_pin_logs_gcode_and_pictures_are_the_same_at_any_piece_size(case, tmp_path):
    """The job run on the mock gives the same pin log byte for byte, the same G-code and the same toolpath and
    cut-surface pictures, given as pieces of one and of seven targets or as one Job."""
    name, d, kw, _, one = case
    want_log = _pin_log_bytes(one, tmp_path / "one.csv")
    want_gcode = to_gcode(one)
    want_pictures = _pictures(one, tmp_path, "one")
    for piece_targets in (1, 7):
        stream = stream_drawing(d, piece_targets=piece_targets, **kw)
        assert _pin_log_bytes(stream, tmp_path / f"{piece_targets}.csv") == want_log
        assert _pin_log_bytes(stream.joined(), tmp_path / f"{piece_targets}j.csv") == want_log
        assert to_gcode(stream) == want_gcode
        assert _pictures(stream, tmp_path, str(piece_targets)) == want_pictures


@pytest.mark.parametrize("spp", [8, 2, 3])
def test_the_surface_carved_a_chunk_at_a_time_is_the_simulated_surface(case, spp):
    """carved_surface (the surface picture's depths, decoded and carved a chunk of writes at a time) equals
    cam.simulate_surface of the whole job (its whole pin log at once), chunk borders inside moves and on pixel
    borders (an even number of steps per pixel) included."""
    _, d, kw, _, _ = case
    s = cam.MachineSettings().replace(steps_per_px_xy=spp)
    stream = stream_drawing(d, settings=s, piece_targets=7, **kw)
    want = cam.simulate_surface(stream.joined())
    for chunk_periods in (64, 1000):
        np.testing.assert_array_equal(carved_surface(stream, plan_chunks(stream, chunk_periods=chunk_periods)), want)


def _disc_png(tmp_path: Path) -> Path:
    path = tmp_path / "disc.png"
    cv2.imwrite(str(path), cv2.cvtColor(_disc(31, 13).to_rgb(), cv2.COLOR_RGB2BGR))
    return path


@pytest.mark.parametrize("options", [JobOptions(profile_expr=HEMISPHERE, tool="ball:1", start_at=(1, 2, 0)),
                                     JobOptions(profile_expr=HEMISPHERE, tool="ball:1", stepdown_mm=0.1,
                                                rough_tool="flat:1")],
                         ids=["finer-pass", "roughing"])
def test_a_prepared_job_is_the_same_held_or_in_pieces(tmp_path, monkeypatch, options):
    """prepare_job keeps a large drawing in pieces and joins a small one: with the threshold moved so this one is
    kept in pieces, it is the same job (fingerprint, report, warnings: the finer pass and roughing are there)
    and gives the same pictures (preview over the drawing, .svg, cut surface)."""
    src = _disc_png(tmp_path)
    s = cam.MachineSettings()
    held = prepare_job(src, options, s)
    monkeypatch.setattr("cam.job.drawing_stream.STREAM_TARGETS", 10)
    monkeypatch.setattr(cam.job.drawing_stream, "PIECE_TARGETS", 13)
    pieces = prepare_job(src, options, s)
    assert isinstance(held.toolpath, Job) and isinstance(pieces.toolpath, DrawingJobStream)
    if options.stepdown_mm is not None:
        assert pieces.toolpath.roughing is not None and held.toolpath.pause_notes[0].startswith("tool change")
    else:
        assert pieces.toolpath.finer is not None
    assert pieces.plan_sha256 == held.plan_sha256 and pieces.report == held.report
    assert pieces.warnings == held.warnings and not any("left out" in w for w in pieces.warnings)
    assert pieces.estimated_time_s == held.estimated_time_s
    args = argparse.Namespace(scale=None)
    for name, surface in (("p.png", False), ("p.svg", False), ("s.png", True)):
        write_job_preview(args, held, str(tmp_path / f"held-{name}"), surface=surface)
        write_job_preview(args, pieces, str(tmp_path / f"pieces-{name}"), surface=surface)
        assert (tmp_path / f"held-{name}").read_bytes() == (tmp_path / f"pieces-{name}").read_bytes(), name
