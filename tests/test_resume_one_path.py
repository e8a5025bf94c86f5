"""One resume path for every job size (issue #28): :func:`cam.job.resume.resume_toolpath` is the joined pieces of
:func:`cam.job.resume.resume_pieces`, and a job resumed in memory or given as pieces of any size resumes the same.

For a drawing, an HPGL, a drill and a G-code job (feeds, dwells, ramp segments, program pauses and tool
changes), stopped at several moves (at and before its pauses, left pending or not): the resumed job, the move
each of its points completes, its fingerprint and its mock pin log are the same whether the job is a
:class:`~cam.job.model.Job` in memory or a :class:`~cam.job.model.JobLike` of pieces of 1 or 3 moves (empty
pieces between them too) or one piece.  The plan fingerprint the journals keep is the same in pieces of any
size and, for a job in memory, what it has always been.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Iterator, Optional

import numpy as np
import pytest

import cam
from cam.errors import CamError
from cam.job.drawing_stream import stream_drawing
from cam.job.hpgl_stream import stream_hpgl
from cam.kinds.jobs import JobOptions, prepare_job
from cam.job.model import Job, JobLike, PixelFrame, join_pieces
from cam.job.resume import MoveIndex, PlanFingerprint, ResumedJob, plan_fingerprint, resume_pieces, resume_toolpath
from cam.settings import MachineSettings, Travel
from conftest import SAMPLES

SLOW_CASES = {'test_resumed_in_memory_or_in_pieces_is_the_same[drawing]'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

SETTINGS = cam.MachineSettings().replace(ramp="constant", delay_xy_ms=0.05, delay_z_ms=0.05, travel=Travel(
    x_min_steps=-10**5, x_max_steps=10**5, y_min_steps=-10**5, y_max_steps=10**5, z_min_steps=-10**4,
    z_max_steps=10**4))
"""A travel around the home on every side: a resumed job (relative to where the tool stands) runs from (0, 0, 0)."""

GCODE = """G21 G90
G0 Z1
G0 X1 Y-1
G1 Z-0.5 F300
G1 X4 Y-1 F900
G4 P0.2
G1 X4 Y-4
M0
G1 X1 Y-4
G1 X1 Y-1
G0 Z1
T2 M6
G0 X6 Y-2
G1 Z-0.3 F300
G2 X8 Y-2 I1 J0 F900
G2 X6 Y-2 I-1 J0
G0 Z1
G0 X0 Y0
M2
"""

_COLUMNS = ("period_ns", "periods", "move_start", "rest")
SIZES = {"1": (1, False), "3": (3, False), "3+empty": (3, True), "one piece": (0, False)}
"""Pieces of the sliced jobs: ``(moves a piece, empty pieces between)``; 0: the whole job as one piece."""


@dataclass
class Sliced:
    """A :class:`Job` given as a :class:`JobLike` of consecutive pieces of ``size`` moves (0: one piece),
    an empty piece after each one if ``empty_between``: the frame and every row of ``job``, cut up."""

    job: Job
    size: int
    empty_between: bool = False

    @property
    def settings(self) -> MachineSettings:
        return self.job.settings

    @property
    def safe_z_steps(self) -> int:
        return self.job.safe_z_steps

    @property
    def source(self) -> str:
        return self.job.source

    @property
    def warnings(self) -> list[str]:
        return list(self.job.warnings)

    @property
    def pixels(self) -> Optional[PixelFrame]:
        return self.job.pixels

    @property
    def tool(self) -> Any:
        return self.job.tool

    def pieces(self) -> Iterator[Job]:
        job, n = self.job, len(self.job)
        size = self.size or max(n, 1)
        before = np.concatenate([[0], np.cumsum(np.asarray(job.pause, bool))])  # pauses before each row
        for a in range(0, n, size):
            b = min(n, a + size)
            notes = None if job.pause_notes is None else list(job.pause_notes[before[a]:before[b]])
            yield Job(points_steps=job.points_steps[a:b], kind=job.kind[a:b], target=job.target[a:b],
                      pause=job.pause[a:b], settings=job.settings, warnings=[], safe_z_steps=job.safe_z_steps,
                      pixels=job.pixels, tool=job.tool, pause_notes=notes,
                      **{c: None if getattr(job, c) is None else getattr(job, c)[a:b] for c in _COLUMNS})
            if self.empty_between:
                yield Job(points_steps=np.zeros((0, 3), np.int64), kind=np.zeros(0, np.uint8),
                          target=np.zeros(0, bool), pause=np.zeros(0, bool), settings=job.settings,
                          safe_z_steps=job.safe_z_steps, pixels=job.pixels)

    def joined(self) -> Job:
        return join_pieces(self.pieces(), self)


def _gcode_job(tmp_path: Path) -> Job:
    path = tmp_path / "part.ngc"
    path.write_text(GCODE)
    return prepare_job(path, JobOptions(), SETTINGS).toolpath


def _drawing_job() -> Job:
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    pause_at = [tuple(int(v) for v in d.objects[0][4]), tuple(int(v) for v in d.objects[-1][2])]
    return cam.plan(d, depth=2, settings=SETTINGS, start_at=(2, 1, 1), pause_at=pause_at)


@pytest.fixture(scope="module")
def jobs(tmp_path_factory) -> dict[str, Job]:
    """Every kind of job, in memory: a drawing (Start At below the home, two Pause Ats), HPGL (pen changes),
    a drill file (tool changes), G-code (feeds, a dwell, M0 and a tool change)."""
    out = {
        "drawing": _drawing_job(),
        "hpgl": prepare_job(SAMPLES / "extended.plt", JobOptions(), SETTINGS).toolpath.joined(),
        "drill": prepare_job(SAMPLES / "board.drl", JobOptions(), SETTINGS).toolpath.joined(),
        "gcode": _gcode_job(tmp_path_factory.mktemp("gcode")).joined(),
    }
    for name, job in out.items():
        assert isinstance(job, Job) and job.pause.sum() >= 2, name
    assert all(getattr(out["gcode"], c) is not None for c in _COLUMNS)
    assert out["gcode"].rest.any() and out["gcode"].pixels is None and out["drawing"].pixels is not None
    return out


def _stops(job: Job) -> list[tuple[int, bool]]:
    """``(last completed move, pause pending)``: before the start, at the start and end, at and before each
    pause (pending at it, or answered), in the middle."""
    n = len(job)
    pauses = np.flatnonzero(job.pause).tolist()
    out = [(-1, False), (0, False), (n // 3, False), (n // 2, True), (n - 2, False), (n - 1, False)]
    out += [(p, pending) for p in pauses for pending in (False, True)] + [(p - 1, False) for p in pauses]
    return sorted(set(out))


def _position(job: Job, k: int) -> tuple[int, int, int]:
    """Where a stop after move ``k`` may leave the tool: near the point, lifted a little."""
    p = np.asarray(job.points_steps[max(k, 0)], np.int64) + (k % 3 - 1, 1 - k % 2, -(k % 4))
    return tuple(int(v) for v in p)  # type: ignore[return-value]


def assert_same_job(got: Job, want: Job, what: str) -> None:
    """Every field of two jobs equal: the per-move arrays row for row (values, dtype, shape), the rest ==."""
    for f in fields(Job):
        a, b = getattr(got, f.name), getattr(want, f.name)
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            assert (a is None) == (b is None), f"{what}: {f.name} {a!r} {b!r}"
            if a is not None:
                assert a.dtype == b.dtype and a.shape == b.shape, f"{what}: {f.name}"
                np.testing.assert_array_equal(a, b, err_msg=f"{what}: {f.name}")
        else:
            assert a == b, f"{what}: {f.name} {a!r} != {b!r}"


def _pin_log_bytes(job: Job) -> bytes:
    log = cam.run(job).pin_log()
    return b"|".join(np.ascontiguousarray(a).tobytes() for a in (log.t_ns, log.data, log.strobe))


@pytest.mark.parametrize("size", list(SIZES))
def test_sliced_is_the_job(jobs, size):
    """The test's JobLike holds the job: its pieces joined are the job row for row (every column, notes)."""
    for name, job in jobs.items():
        sliced = Sliced(job, *SIZES[size])
        assert isinstance(sliced, JobLike)
        assert_same_job(sliced.joined(), job, f"{name} in pieces of {size}")


@pytest.mark.parametrize("kind", ["drawing", "hpgl", "drill", "gcode"])
def test_resumed_in_memory_or_in_pieces_is_the_same(jobs, kind):
    """At every stop: the same resumed job, move index, first move and fingerprint in memory and in pieces."""
    job = jobs[kind]
    for k, pending in _stops(job):
        pos = _position(job, k)
        want, want_index, want_j = resume_toolpath(job, k, pos, pause_pending=pending)
        assert want_index.dtype == np.int64 and len(want_index) == len(want)
        want_sha = plan_fingerprint(want)
        for size, (rows, empty) in SIZES.items():
            what = f"{kind} k={k} pending={pending} pieces of {size}"
            sliced = Sliced(job, rows, empty)
            got, index, j = resume_toolpath(sliced, k, pos, pause_pending=pending)
            assert_same_job(got, want, what)
            np.testing.assert_array_equal(index, want_index, err_msg=what)
            assert j == want_j, what
            lazy, move_index, j2 = resume_pieces(sliced, k, pos, pause_pending=pending)
            assert isinstance(lazy, ResumedJob) and isinstance(move_index, MoveIndex) and j2 == want_j, what
            assert len(lazy) == len(want) == len(move_index) and lazy.job_moves == len(job), what
            assert [move_index[i] for i in range(len(move_index))] == want_index.tolist(), what
            assert plan_fingerprint(lazy) == want_sha, what
            assert lazy.safe_z_steps == want.safe_z_steps and lazy.pause_notes == want.pause_notes, what


@pytest.mark.parametrize("kind", ["drawing", "hpgl", "drill", "gcode"])
def test_resumed_pin_logs_are_byte_identical(jobs, kind):
    """The mock pin log of the resumed run is the same, byte for byte, in memory and in pieces of 1, 3 and one."""
    job = jobs[kind]
    pauses = np.flatnonzero(job.pause)
    for k, pending in [(len(job) // 3, False), (int(pauses[0]), True), (int(pauses[-1]) - 1, False)]:
        pos = _position(job, k)
        want = _pin_log_bytes(resume_toolpath(job, k, pos, pause_pending=pending)[0])
        assert len(want) > 100
        for size in ("1", "3", "one piece"):
            got = _pin_log_bytes(resume_toolpath(Sliced(job, *SIZES[size]), k, pos, pause_pending=pending)[0])
            assert got == want, f"{kind} k={k} pending={pending} pieces of {size}"


def test_a_stop_outside_the_job_is_refused_in_memory_and_in_pieces(jobs):
    job = jobs["drill"]
    for given in (job, Sliced(job, 3)):
        for k in (-2, len(job)):
            with pytest.raises(CamError, match="outside the job's"):
                resume_pieces(given, k, (0, 0, 0))


def test_fingerprint_is_the_same_in_pieces_of_any_size(jobs):
    """plan_fingerprint of a job is that of its moves given in pieces of any size, empty ones between too."""
    for name, job in jobs.items():
        want = plan_fingerprint(job)
        for rows, empty in [(1, False), (2, True), (3, False), (7, False), (len(job) - 1, False), (0, False)]:
            assert plan_fingerprint(Sliced(job, rows, empty)) == want, (name, rows, empty)


def test_fingerprint_of_a_job_in_memory_is_the_journals_format(jobs):
    """The journals written before keep their fingerprint: sha256 of the points, kinds and pauses arrays, each
    followed by a zero byte (so a job stopped by an earlier version still resumes)."""
    for name, job in jobs.items():
        h = hashlib.sha256()
        for arr, dtype in ((job.points_steps, np.int64), (job.kind, np.uint8), (job.pause, np.bool_)):
            h.update(np.ascontiguousarray(np.asarray(arr, dtype)).tobytes())
            h.update(b"\0")
        assert plan_fingerprint(job) == h.hexdigest(), name


def test_fingerprint_spooled_to_disk_is_the_same(jobs, monkeypatch):
    """Kinds and pauses past the spool's size go to a temporary file: the same fingerprint; and more pieces
    may be added after a digest."""
    job = jobs["drawing"]
    want = plan_fingerprint(job)
    monkeypatch.setattr(PlanFingerprint, "SPOOL_BYTES", 16)
    h = PlanFingerprint()
    pieces = list(Sliced(job, 5).pieces())
    for piece in pieces[:3]:
        h.add(piece)
    assert h.hexdigest() == plan_fingerprint(Sliced(Job(*(getattr(job, c)[:15] for c in
                                                          ("points_steps", "kind", "target", "pause"))), 5))
    for piece in pieces[3:]:
        h.add(piece)
    assert h.hexdigest() == want and plan_fingerprint(Sliced(job, 5)) == want


def test_streams_fingerprint_as_their_jobs_joined():
    """The real streams (a drawing a few targets a piece, an HPGL file a few points a piece): the fingerprint
    of the stream is that of its job in memory, and it resumes as that job does."""
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    kw = dict(depth=2, settings=SETTINGS, start_at=(2, 1, 1), pause_at=[tuple(int(v) for v in d.objects[0][4])])
    streams = {"drawing": stream_drawing(d, piece_targets=7, **kw),
               "hpgl": stream_hpgl(SAMPLES / "extended.plt", settings=SETTINGS, piece_points=3, chunk_bytes=64)}
    for name, stream in streams.items():
        whole = stream.joined()
        assert sum(1 for _ in stream.pieces()) > 3, name
        assert plan_fingerprint(stream) == plan_fingerprint(whole), name
        k = len(whole) // 2
        pos = _position(whole, k)
        got, index, j = resume_toolpath(stream, k, pos)
        want, want_index, want_j = resume_toolpath(whole, k, pos)
        assert_same_job(got, want, name)
        np.testing.assert_array_equal(index, want_index)
        assert j == want_j
