"""One G-code planner (issue #28): a program is planned a piece of moves at a time, from the program held in memory
or from its file interpreted again a line at a time on each pass, and ``plan_gcode`` is those pieces joined.
However the moves are cut into pieces, the joined job, its step plan and mock pin log and its G-code out are the
same; the file is read a line at a time (jumps seek), and a big file runs through ``cam drill`` in bounded
memory (slow tier)."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import cam
from cam.motion.chunks import plan_chunks
from cam.drive.ports import MockPort
from cam.drive.runner import run
from cam.formats import _gcode_lines
from cam.formats.gcode import GcodeFile, load_gcode, open_gcode, parse_gcode
from cam.kinds.gcode_export import gcode_pieces, to_gcode
from cam.job import gcode as gcode_job
from cam.job.gcode import GcodeJobStream, plan_gcode, stream_gcode
from cam.kinds.jobs import JobOptions, prepare_job
from cam.job.model import Job, JobLike
from cam.job.resume import plan_fingerprint
from conftest import SAMPLES
from test_gcode_lang import CONSTRUCTS, HOME_G28_IN, HOME_G30_IN, SUBROUTINE, TOOLS_IN
from support.pinlogs import pin_log_bytes as _pin_log_bytes

PER_MOVE = ("points_steps", "kind", "target", "pause", "period_ns", "periods", "move_start", "rest")
ONE_PIECE = 10**9
SETTINGS = cam.MachineSettings().replace(ramp="lookahead", delay_xy_ms=0.05, delay_z_ms=0.05)

HANDWRITTEN = {
    # tool changes and program pauses, a dwell, coolant (one warning), arcs, a G93 move
    "pauses.ngc": "G21 G90 G17\nT1 M6\nG0 Z2 M8\nG0 X5 Y-5\nG1 Z-0.5 F100\nG2 X15 Y-5 I5 J0\nG4 P0.5\nM0\n"
                  "T2 M6\nG93 G1 X20 Y-8 F2\nG94\nG3 X20 Y-8 I-2 J0 F300\nM1\nG0 Z2\nM30\n",
    # a loop, a subroutine called before it is defined, a branch, splines
    "flow.ngc": "G21 G90\n#1 = 0\no10 while [#1 LT 4]\n  o<step> call [#1]\n  #1 = [#1 + 1]\no10 endwhile\n"
                "o20 if [#1 EQ 4]\n  G5.1 X30 Y-10 I5 J-5 F200\no20 elseif [#1 EQ 5]\n  G0 X0\no20 else\n  G0 X1\n"
                "o20 endif\nG5 X40 Y-12 I3 J-2 P-2 Q1\nM2\n"
                "o<step> sub\n  G1 X[#1 * 3] Y[-#1] Z[-0.2 * #1] F400\n  G0 Z1\no<step> endsub\n",
    "cycles.ngc": "G21 G90 G17\nG0 Z3\nG99 G81 X5 Y-5 Z-1 R1 F100\nX10\nG91 X2 L3\nG90 G98 G83 X20 Y-10 Z-2 R1 Q0.5\n"
                  "G80\nM2\n",
}


def _options(tmp: Path) -> dict:
    subs = tmp / "subs"
    subs.mkdir(exist_ok=True)
    (subs / "square.ngc").write_text(SUBROUTINE)
    return dict(tool_lengths_mm={t: z * 25.4 for t, z in TOOLS_IN.items()},
                home_g28_mm=tuple(v * 25.4 for v in HOME_G28_IN), home_g30_mm=tuple(v * 25.4 for v in HOME_G30_IN),
                subroutine_path=[subs], max_lines=100_000)


@pytest.fixture(scope="module")
def programs(tmp_path_factory) -> list[tuple[Path, dict]]:
    """(file, interpreter options): the sample, the handwritten programs and test_gcode_lang's constructs."""
    tmp = tmp_path_factory.mktemp("gcode")
    out = [(SAMPLES / "bolt_plate.ngc", {})]
    for name, text in HANDWRITTEN.items():
        (tmp / name).write_text(text)
        out.append((tmp / name, {}))
    options = _options(tmp)
    for name, text in CONSTRUCTS.items():
        (tmp / f"{name}.ngc").write_text(text)
        out.append((tmp / f"{name}.ngc", options))
    return out


def _settings_for(path: Path) -> cam.MachineSettings:
    if path.parent == SAMPLES or path.name in HANDWRITTEN:
        return SETTINGS
    wide = cam.settings.Travel(-10**7, 10**7, -10**7, 10**7, -10**7, 10**7)
    return SETTINGS.replace(travel=wide)


def _assert_same_job(got: Job, want: Job, what: str) -> None:
    for name in PER_MOVE:
        a, b = getattr(got, name), getattr(want, name)
        assert (a is None) == (b is None), f"{what}: {name}"
        if b is not None:
            assert a.dtype == b.dtype, f"{what}: {name}"
            np.testing.assert_array_equal(a, b, err_msg=f"{what}: {name}")
    for name in ("pause_notes", "warnings", "source", "safe_z_steps", "settings", "pixels", "tool"):
        assert getattr(got, name) == getattr(want, name), f"{what}: {name}"


def test_a_file_is_read_as_its_text_is(tmp_path, monkeypatch):
    """``load_gcode`` reads the file a line at a time (seeking back for loops, marks every few lines, a tiny
    cache) and gives what ``parse_gcode`` of its text gives: every line ending, loops, branches, subroutines."""
    monkeypatch.setattr(_gcode_lines, "MARK_EVERY", 3)
    monkeypatch.setattr("cam.formats._gcode_flow.CACHE_LINES", 2)
    for name, text in HANDWRITTEN.items():
        for ending in ("\n", "\r\n", "\r"):
            path = tmp_path / f"{ending == chr(10)}{len(ending)}{name}"
            path.write_bytes(text.replace("\n", ending).encode())
            want = parse_gcode(text, source=str(path))
            got = load_gcode(path)
            assert got.moves == want.moves and got.warnings == want.warnings, (name, repr(ending))
    odd = tmp_path / "odd.ngc"  # a form feed ends a line too, as str.splitlines has it; no line end at the end
    odd.write_bytes(b"G21 G90\x0cG0 X1\n\nG1 Y-2 F100\r\nG1 X3")
    assert load_gcode(odd).moves == parse_gcode(odd.read_text(), source=str(odd)).moves
    assert [m.line for m in load_gcode(odd).moves] == [2, 4, 5]


def test_a_bad_file_names_its_line(tmp_path):
    bad = tmp_path / "bad.ngc"
    bad.write_bytes(b"G21\nG0 X1\nG0 X\xff\n")
    with pytest.raises(cam.CamError, match="bad.ngc:1: not a G-code text file"):
        load_gcode(bad)
    bad.write_text("G21\n" + "G0 X1\n" * 500 + "G7\n")
    with pytest.raises(cam.CamError, match="bad.ngc:502: "):
        list(stream_gcode(open_gcode(bad), SETTINGS).pieces())
    with pytest.raises(cam.CamError, match="file not found"):
        open_gcode(tmp_path / "none.ngc")


NAMES = ["bolt_plate.ngc", *HANDWRITTEN, *(f"{n}.ngc" for n in CONSTRUCTS)]


@pytest.mark.parametrize("name,sizes", [pytest.param(n, (1,), id=f"1-{n}") for n in NAMES]
                         + [pytest.param(n, (2, 3, 5, 7), id=f"2-3-5-7-{n}", marks=pytest.mark.slow) for n in NAMES])
def test_any_piece_size_joins_to_the_same_job(programs, name, sizes):
    """From the program in memory (its moves sliced) and from the file (interpreted again on each pass), pieces of
    1..7 moves join to ``plan_gcode``'s job: every per-move array, the pause notes, the warnings."""
    path, options = {p.name: (p, o) for p, o in programs}[name]
    s = _settings_for(path)
    program = load_gcode(path, **options)
    want = plan_gcode(program, s)
    assert len(want) > 0
    assert want.pause_notes is not None and len(want.pause_notes) == int(want.pause.sum())
    one = stream_gcode(open_gcode(path, **options), s, piece_moves=ONE_PIECE)
    assert sum(1 for _ in one.pieces()) == 1
    _assert_same_job(one.joined(), want, f"{path.name} file, one piece")
    _assert_same_job(plan_gcode(open_gcode(path, **options), s), want, f"{path.name} plan_gcode(file)")
    for k in sizes:
        for src, how in ((program, "program"), (open_gcode(path, **options), "file")):
            stream = stream_gcode(src, s, piece_moves=k)
            assert isinstance(stream, JobLike) and len(stream) == len(want)
            assert stream.n_program_moves == len(program.moves)
            if len(program.moves) > 2 * k:
                assert sum(1 for _ in stream.pieces()) > 1, (path.name, how, k)
            _assert_same_job(stream.joined(), want, f"{path.name} {how} piece_moves={k}")


def _random_lines(seed: int, n: int) -> str:
    """Straight moves of every sort: rapids, feeds at F (some slower than the step delays allow) and in G93,
    moves of no length, short and long moves, in X/Y, in Z and in all three, in inches too."""
    rng = np.random.default_rng(seed)
    out = ["G21 G90 G94 F300"]
    for _ in range(n):
        r = rng.random()
        if r < 0.05:
            out.append("G20" if rng.random() < 0.5 else "G21")
        elif r < 0.08:
            out.append(f"G93 G1 X{rng.uniform(0, 2):.4f} F{rng.uniform(1, 50):.3f}\nG94 F300")
        elif r < 0.1:
            out.append("G1 X[#<_x>] Y[#<_y>]")
        else:
            scale = 10 ** rng.uniform(-3, 1)
            x, y, z = rng.uniform(0, 1, 3) * (scale, scale, min(scale, 0.3))
            words = " ".join(f"{a}{v:.4f}" for a, v, keep in zip("XYZ", (x, -y, -z), rng.random(3) < 0.7) if keep)
            code = "G0" if rng.random() < 0.3 else f"G1 F{rng.choice([30, 300, 3000, 90000])}"
            out.append(f"{code} {words or 'X0'}")
    return "\n".join(out + ["M2", ""])


@pytest.mark.parametrize("seed", range(3))
def test_straight_moves_at_once_are_the_moves_one_by_one(monkeypatch, seed):
    """Consecutive straight moves are planned at once (:func:`cam.job.gcode._straight_run`); the rows are exactly
    those of planning each move alone."""
    program = parse_gcode(_random_lines(seed, 250), source="lines.ngc")
    want_fast = plan_gcode(program, SETTINGS)
    monkeypatch.setattr(gcode_job, "_straight_run", lambda *a: None)
    _assert_same_job(want_fast, plan_gcode(program, SETTINGS), f"seed {seed}")
    assert len(want_fast) > 250


def test_pauses_warnings_and_counts_come_through(programs):
    by_name = {p.name: (p, o) for p, o in programs}
    path, _ = by_name["pauses.ngc"]
    stream = stream_gcode(open_gcode(path), SETTINGS, piece_moves=1)
    assert stream.warnings == []  # known after a pass
    job = stream.joined()
    assert job.pause_notes == ["tool change: T1 (line 2)", "program pause M0 (line 8)", "tool change: T2 (line 9)",
                               "program pause M1 (line 13)"]
    assert stream.pause_notes == job.pause_notes and len(job.warnings) == 1 and "coolant" in job.warnings[0]
    assert stream.warnings == job.warnings and bool(job.rest.any())
    plan = plan_chunks(stream)
    assert plan.pause_notes == job.pause_notes and plan.warnings == job.warnings


@pytest.mark.parametrize("name", ["pauses.ngc", "flow.ngc", pytest.param("bolt_plate.ngc", marks=pytest.mark.slow)])
def test_step_plans_and_pin_logs_are_byte_identical(programs, tmp_path, name):
    """The mock runs of the one-piece job, of the one-move-piece job joined and of the file's stream itself."""
    path, options = {p.name: (p, o) for p, o in programs}[name]
    whole = plan_gcode(load_gcode(path, **options), SETTINGS)
    want = _pin_log_bytes(whole, tmp_path, "one.csv")
    want_plan = plan_chunks(whole)
    for k in (1, 3):
        stream = stream_gcode(open_gcode(path, **options), SETTINGS, piece_moves=k)
        plan = plan_chunks(stream)
        np.testing.assert_array_equal(plan.pause_writes, want_plan.pause_writes)
        np.testing.assert_array_equal(plan.full_point_write(), want_plan.full_point_write())
        assert plan.n_periods == want_plan.n_periods and plan.estimated_time_s == want_plan.estimated_time_s
        assert plan_fingerprint(stream) == plan_fingerprint(whole)
        assert _pin_log_bytes(stream.joined(), tmp_path, f"joined{k}.csv") == want, k
        assert _pin_log_bytes(stream, tmp_path, f"stream{k}.csv") == want, k


def test_gcode_out_is_identical(programs):
    """G-code out of the one-piece job, the tiny-piece job joined and the tiny-piece stream a piece at a time."""
    for path, options in programs[:4]:
        want = to_gcode(plan_gcode(load_gcode(path, **options), SETTINGS), title=path.name)
        for k in (1, 4):
            stream = stream_gcode(open_gcode(path, **options), SETTINGS, piece_moves=k)
            assert to_gcode(stream.joined(), title=path.name) == want, (path.name, k)
            assert "".join(gcode_pieces(stream, title=path.name)) == want, (path.name, k)


def test_checks_over_the_whole_program_are_made_piece_by_piece(tmp_path):
    """The travel is checked as the pieces are made, naming the line, whatever the piece size (and the program's
    time so far, carried from piece to piece, below)."""
    far = tmp_path / "far.ngc"
    far.write_text("G21 G90\n" + "G1 X1 F100\nG1 X0\n" * 50 + "G0 X100000\nM2\n")
    for k in (1, ONE_PIECE):
        with pytest.raises(cam.TravelError, match="far.ngc:102: "):
            stream_gcode(open_gcode(far), SETTINGS, piece_moves=k).joined()


def test_the_programs_time_is_carried_from_piece_to_piece(tmp_path):
    """8761 one-hour dwells in pieces of 50: the program passes a year at line 8762 (the G21 is line 1)."""
    year = tmp_path / "year.ngc"
    year.write_text("G21\n" + "G4 P3600\n" * 8761)
    with pytest.raises(cam.PlanError, match="year.ngc:8762: the program takes more than 365 days"):
        list(stream_gcode(open_gcode(year, max_lines=10**5), SETTINGS, piece_moves=50).pieces())


def test_a_spilled_stream_reads_back_the_same_pieces(programs, monkeypatch):
    """With ``spill`` the first whole pass keeps its pieces in a temporary file and later passes read them: the
    same pieces, the program not interpreted again; an unfinished pass spills nothing."""
    path, options = {p.name: (p, o) for p, o in programs}["pauses.ngc"]
    want = list(stream_gcode(open_gcode(path, **options), SETTINGS, piece_moves=2).pieces())
    stream = stream_gcode(open_gcode(path, **options), SETTINGS, piece_moves=2, spill=True)
    next(stream.pieces())  # abandoned
    assert stream._spilled is None and not stream._spilling
    first = list(stream.pieces())
    def again(*args):
        raise AssertionError("the program was interpreted again")
    monkeypatch.setattr(stream.src, "move_batches", again)
    for got in (first, list(stream.pieces()), list(stream.pieces())):
        assert len(got) == len(want) > 2
        for a, b in zip(got, want):
            _assert_same_job(a, b, "spilled piece")
    assert stream.held(10**9) is not None and stream.held(3) is None
    monkeypatch.undo()
    copy = pickle.loads(pickle.dumps(stream))  # to the page's worker and back: without the spill file
    assert copy._spilled is None and stream._spilled is not None
    for a, b in zip(list(copy.pieces()), want):
        _assert_same_job(a, b, "pickled stream")


def test_prepare_job_keeps_a_large_job_as_its_pieces(tmp_path, monkeypatch):
    """Over STREAM_MOVES moves ``prepare_job`` keeps the file's stream (interpreted again on each pass) instead of
    the joined job: the same plan, report and pin log."""
    path = SAMPLES / "bolt_plate.ngc"
    held = prepare_job(path, JobOptions(), SETTINGS)
    assert isinstance(held.toolpath, Job)
    monkeypatch.setattr("cam.job.gcode.STREAM_MOVES", 100)
    streamed = prepare_job(path, JobOptions(), SETTINGS)
    assert isinstance(streamed.toolpath, GcodeJobStream) and isinstance(streamed.toolpath.src, GcodeFile)
    assert streamed.summary == held.summary and streamed.report == held.report
    assert streamed.warnings == held.warnings and streamed.tool_changes == held.tool_changes
    assert streamed.plan_sha256 == held.plan_sha256
    assert _pin_log_bytes(streamed.toolpath, tmp_path, "s.csv") == _pin_log_bytes(held.toolpath, tmp_path, "h.csv")


def _big_program(path: Path, n_lines: int) -> None:
    """A zigzag of short feed moves (0.1 mm apart, 10 mm rows) with a tool change every 100,000 lines."""
    with open(path, "w") as f:
        f.write("G21 G90 G17\nT1 M6\nG0 Z1\nG0 X0 Y0\nG1 Z-0.2 F600\n")
        rows = 100
        for i in range(n_lines):
            if i and i % 100_000 == 0:
                f.write(f"G0 Z1\nT{2 + i // 100_000 % 2} M6\nG1 Z-0.2\n")
            r, c = divmod(i, rows)
            x = c if r % 2 == 0 else rows - c
            f.write(f"G1 X{x * 0.1:.1f} Y{-(r % 300) * 0.1:.1f}\n")
        f.write("G0 Z1\nM2\n")


@pytest.mark.slow
def test_a_big_file_runs_through_cam_drill_in_bounded_memory(tmp_path):
    """Two million lines (29 MB) planned, checked and run on the mock by ``cam drill --yes``: the peak RSS of the
    process stays under 500 MB (the file's moves are never all held).  The thesis machine's step delays: with much
    shorter ones (0.05 ms) the look-ahead ramps plan windows of a million periods on each side of a chunk, which
    alone take some 350 MB (cam/motion/chunks.py, whatever the job)."""
    n = 2_000_000
    path = tmp_path / "big.ngc"
    _big_program(path, n)
    assert path.stat().st_size > 25 * 2**20
    # the process's own peak, from a small launcher's wait4: the test process's RUSAGE_CHILDREN is the largest of
    # every child it ever had (a benchmark run earlier in the suite passes 500 MB by itself)
    launcher = ("import os, subprocess, sys\np = subprocess.Popen(sys.argv[1:])\n_, status, usage = os.wait4(p.pid, 0)\n"
                "print('exit', os.waitstatus_to_exitcode(status), usage.ru_maxrss)\n")
    t0 = time.time()
    out = subprocess.run([sys.executable, "-c", launcher, sys.executable, "-m", "cam", "drill", str(path), "--yes",
                          "--max-lines", str(n + 100)],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(SAMPLES.parent)})
    took = time.time() - t0
    _, code, maxrss_kb = out.stdout.strip().splitlines()[-1].split()
    peak_mb = int(maxrss_kb) / 1024
    assert int(code) == 0, out.stderr[-2000:]
    print(f"\n{n} lines: peak RSS {peak_mb:.0f} MB, {took:.0f} s")
    assert peak_mb < 500, f"peak RSS {peak_mb:.0f} MB"
    assert "finished" in out.stdout + out.stderr
