"""One HPGL planner (issue #28): however the points are batched into pieces (from the file's chunks or an
in-memory drawing's arrays), the joined job, its mock pin log and its G-code are the same, and ``plan_hpgl`` is
the stream's pieces joined."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cam
from cam.drive.ports import MockPort
from cam.drive.runner import run
from cam.kinds.gcode_export import gcode_pieces, to_gcode
from cam.formats.hpgl import load_hpgl, parse_hpgl
from cam.job.hpgl import plan_hpgl
from cam.job.hpgl_stream import HpglJobStream, stream_hpgl
from cam.job.model import Job, JobLike, pause_points
from test_hpgl_stream import _random_hpgl as random_hpgl
from support.pinlogs import pin_log_bytes as _pin_log_bytes

SLOW_CASES = {'test_gcode_is_identical', 'test_pin_logs_are_byte_identical', 'test_any_piece_size_joins_to_the_same_job[3]'}
"""Cases that run in the slow tier only (tests/conftest.py): the same checks keep faster cases here."""


SAMPLES = Path(__file__).resolve().parent.parent / "samples"
PER_MOVE = ("points_steps", "kind", "target", "pause", "period_ns", "periods", "move_start", "rest")
ONE_PIECE = 10**9
SETTINGS = cam.MachineSettings().replace(ramp="lookahead", delay_xy_ms=0.05, delay_z_ms=0.05)

HANDWRITTEN = {
    # pens 1 and 2 (tool-change pauses), SP0 keeps the tool, the same pen again is no change, an unknown command
    "pens.plt": b"IN;SP1;PU0,0;PD400,0,400,400;PU;SP2;PA800,0;PD800,400;PU;SP0;PU0,800;PD400,800;SP2;PD400,1200;"
                b"SP1;PU100,100;PD200,200;LT;PU0,0;",
    # PU/PD/PA/PR, relative moves with several pairs, a dot, separators of every kind
    "moves.plt": b"IN;SP3;PU40,40;PR;PD40,0,0,40,-40,0;PA;PU200,200\nPD;PU;PR10,-10;PD 5 5;PA300,300 PD310,300;"
                 b"PU;DF;PA0,0;",
    # duplicates: repeated points, a stroke starting where the last ended (cut on without lifting), one step away,
    # zero-length strokes, repeated pens
    "dups.plt": b"SP1;PD0,0,0,0,0,0,40,40,40,40;PU40,40;PD40,40,40,40;PU41,40;PD80,40;SP1;PD80,40;SP2;PD80,40;"
                b"PU80,40;PD80,40,120,40,120,40;PU0,0;",
}


def _random_hpgl(seed: int) -> bytes:
    """test_hpgl_stream's random files, 150 commands, points within +-4000 plotter units."""
    return random_hpgl(seed, 150, clip_pu=4000)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> list[Path]:
    tmp = tmp_path_factory.mktemp("hpgl")
    out = sorted(SAMPLES.glob("*.plt"))
    for name, data in HANDWRITTEN.items():
        (tmp / name).write_bytes(data)
        out.append(tmp / name)
    for seed in range(3):
        p = tmp / f"random{seed}.plt"
        p.write_bytes(_random_hpgl(seed))
        out.append(p)
    zigzag = "PU0,0;PD" + ",".join(f"{30 * i},{30 * (i % 2)}" for i in range(1, 40)) + ";"
    big = tmp / "zigzag.plt"  # more than one piece of 1000 points, more than one chunk of the file
    big.write_text("IN;SP1;" + zigzag * 40 + "SP2;" + zigzag * 40 + "PU0,0;")
    out.append(big)
    return out


def _assert_same_job(got: Job, want: Job, what: str) -> None:
    for name in PER_MOVE:
        a, b = getattr(got, name), getattr(want, name)
        if b is None:
            assert a is None, f"{what}: {name}"
            continue
        assert a.dtype == b.dtype, f"{what}: {name}"
        np.testing.assert_array_equal(a, b, err_msg=f"{what}: {name}")
    for name in ("pause_notes", "warnings", "source", "safe_z_steps", "settings", "pixels", "tool"):
        assert getattr(got, name) == getattr(want, name), f"{what}: {name}"


def _stream(src, piece_points: int, chunk_bytes: int = 64) -> HpglJobStream:
    return stream_hpgl(src, settings=SETTINGS, piece_points=piece_points, chunk_bytes=chunk_bytes)


def _tool_changes(job: Job) -> dict[int, tuple[int, str]]:
    """As ``cam export`` gives them: the pen of each "tool change: pen N" pause, before the point after it."""
    at = pause_points(job) + 1
    return {int(i): (int(note.split()[-1]), note) for i, note in zip(at, job.pause_notes or [])}


@pytest.mark.parametrize("sizes", [(3,), pytest.param((1, 2, 4, 5, 6, 7), marks=pytest.mark.slow)],
                         ids=["3", "1-2-4-5-6-7"])
def test_any_piece_size_joins_to_the_same_job(files, sizes):
    """From the file (its chunks) and from the drawing in memory (its arrays sliced), pieces of 1..7 points join
    to the one-piece job: every per-move array, the pause notes, the warnings."""
    for path in files:
        one = _stream(path, ONE_PIECE, chunk_bytes=1 << 19)
        assert sum(1 for _ in one.pieces()) == 1, path
        want = one.joined()
        assert want.pause_notes is not None and len(want.pause_notes) == int(want.pause.sum())
        drawing = load_hpgl(path)
        assert _stream(drawing, ONE_PIECE).joined().points_steps.shape == want.points_steps.shape
        _assert_same_job(_stream(drawing, ONE_PIECE).joined(), want, f"{path.name} drawing, one piece")
        for k in sizes:
            for src, how in ((path, "file"), (drawing, "drawing")):
                stream = _stream(src, k, chunk_bytes=16 + 9 * k)
                pieces = list(stream.pieces())
                assert len(pieces) > 1, (path, how, k)
                assert isinstance(stream, JobLike) and len(stream) == len(want)
                _assert_same_job(stream.joined(), want, f"{path.name} {how} piece_points={k}")


def test_tool_changes_and_warnings_come_through(files):
    """The inputs exercise what the pieces carry over: pen changes (pauses and their notes) and warnings."""
    by_name = {p.name: p for p in files}
    pens = _stream(by_name["pens.plt"], 2).joined()
    assert pens.pause_notes == ["tool change: pen 1", "tool change: pen 2", "tool change: pen 1"]  # SP0, SP2 again
    assert any("'LT'" in w for w in pens.warnings)
    assert _stream(by_name["extended.plt"], 3).joined().warnings == load_hpgl(by_name["extended.plt"]).warnings
    assert sum(1 for _ in _stream(by_name["zigzag.plt"], 1000, chunk_bytes=1 << 12).pieces()) > 2


def test_plan_hpgl_is_the_stream_joined(files):
    """``plan_hpgl`` of a path, of the drawing, and ``stream_hpgl(path).joined()`` are one job."""
    for path in files:
        want = stream_hpgl(path, settings=SETTINGS).joined()
        _assert_same_job(plan_hpgl(path, settings=SETTINGS), want, f"{path.name} plan_hpgl(path)")
        drawing = load_hpgl(path)
        assert drawing.source == want.source
        _assert_same_job(plan_hpgl(drawing, settings=SETTINGS), want, f"{path.name} plan_hpgl(drawing)")
        for offset in ((150.0, 150.0), (120.0, 160.0)):
            _assert_same_job(plan_hpgl(drawing, settings=SETTINGS, offset_mm=offset, cut_depth_mm=0.3),
                             stream_hpgl(path, settings=SETTINGS, offset_mm=offset, cut_depth_mm=0.3, piece_points=5,
                                         chunk_bytes=64).joined(), f"{path.name} offset {offset}")


def test_pin_logs_are_byte_identical(files, tmp_path):
    """The mock runs of the one-piece job, of the tiny-piece job joined and of the tiny-piece stream itself."""
    for path in files:
        if path.name.startswith("random") and path.name != "random0.plt":
            continue
        want = _pin_log_bytes(_stream(path, ONE_PIECE).joined(), tmp_path, "one.csv")
        assert len(want) > 0
        for k in (1, 4, 7):
            stream = _stream(path, k)
            assert _pin_log_bytes(stream.joined(), tmp_path, f"joined{k}.csv") == want, (path, k)
            assert _pin_log_bytes(stream, tmp_path, f"stream{k}.csv") == want, (path, k)


def test_gcode_is_identical(files):
    """G-code out of the one-piece job, the tiny-piece job joined, the tiny-piece stream a piece at a time."""
    for path in files:
        whole = plan_hpgl(path, settings=SETTINGS)
        changes = _tool_changes(whole)
        want = to_gcode(whole, tool_changes=changes, title=path.name)
        assert ("M6" in want) == bool(whole.pause.any())
        for k in (1, 2, 3, 5, 7):
            stream = _stream(path, k)
            assert to_gcode(stream.joined(), tool_changes=changes, title=path.name) == want, (path, k)
            assert "".join(gcode_pieces(stream, tool_changes=changes, title=path.name)) == want, (path, k)


def test_an_in_memory_drawing_needs_no_file():
    """A notebook's drawing (parsed from text, never a file) plans in pieces as a file does."""
    text = HANDWRITTEN["pens.plt"] + HANDWRITTEN["dups.plt"]
    drawing = parse_hpgl(text, source="notebook")
    want = plan_hpgl(drawing, settings=SETTINGS)
    assert want.source == "notebook" and len(want.pause_notes) >= 4
    for k in range(1, 8):
        _assert_same_job(_stream(drawing, k).joined(), want, f"piece_points={k}")
