"""HPGL in: the reader (every command form, errors with line and column, streaming), the planner,
the carve check on the mock port, tool changes, the CLI, and flat memory on a 200 MB file."""
import io
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import cam
from cam.formats.hpgl import (
    HpglCommand,
    iter_hpgl,
    load_hpgl,
    parse_hpgl,
    scan_hpgl,
)
from cam.job.hpgl import DEFAULT_TRAVEL_HEIGHT_MM, hpgl_steps, plan_hpgl
from cam.job.model import CUT, RETRACT, TRAVEL

from conftest import ROOT, SAMPLES, run_cli

ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
S = cam.MachineSettings()
K = 0.025 / S.mm_per_step_xy  # steps per plotter unit (40 units per mm, 004 section 3.6.2)


def cmds(data: bytes, **kw):
    return [(c.name, c.params, c.line) for c in iter_hpgl(io.BytesIO(data), **kw)]


def strokes(data: bytes):
    return [(pen, pts.tolist()) for pen, pts in parse_hpgl(data).strokes()]


# ---------------------------------------------------------------- the reader


@pytest.mark.parametrize(
    "text, want",
    [
        (b"IN;DF;", [("IN", (), 1), ("DF", (), 1)]),
        (b"SP3;", [("SP", (3.0,), 1)]),
        (b"PU;PD;", [("PU", (), 1), ("PD", (), 1)]),
        (b"PA10,20;", [("PA", (10.0, 20.0), 1)]),
        (b"PR-5,5;", [("PR", (-5.0, 5.0), 1)]),
        (b"PU10,20,30,40;", [("PU", (10.0, 20.0, 30.0, 40.0), 1)]),
        (b"PD1,2,3,4,5,6", [("PD", (1.0, 2.0, 3.0, 4.0, 5.0, 6.0), 1)]),  # the last command needs no ';'
        # separators: ';', newline, nothing at all
        (b"PU1,2\nPD3,4\n", [("PU", (1.0, 2.0), 1), ("PD", (3.0, 4.0), 2)]),
        (b"PU1,2PD3,4PU", [("PU", (1.0, 2.0), 1), ("PD", (3.0, 4.0), 1), ("PU", (), 1)]),
        (b"SP1PU", [("SP", (1.0,), 1), ("PU", (), 1)]),
        # whitespace anywhere, numbers separated by ',' or whitespace, lower case
        (b"  PA 1 , 2\t3\r\n 4 ;\n\npd ;", [("PA", (1.0, 2.0, 3.0, 4.0), 1), ("PD", (), 4)]),
        # signed and decimal numbers
        (b"PA-1.5,+2.25,.5,-.75,7.,0;", [("PA", (-1.5, 2.25, 0.5, -0.75, 7.0, 0.0), 1)]),
        # unknown commands: kept as names, their parameters skipped (labels to ETX, comments quoted)
        (b'VS10;CO "a; PD1,1";LBx;y\nz\x03PU;', [("VS", (), 1), ("CO", (), 1), ("LB", (), 1), ("PU", (), 2)]),
        (b"DT#;LBab;c#PD;", [("DT", (), 1), ("LB", (), 1), ("PD", (), 1)]),  # DT sets the label terminator
    ],
)
def test_every_command_form(text, want):
    assert cmds(text) == want


def test_command_positions_and_known_flag():
    got = list(iter_hpgl(io.BytesIO(b"IN;\n  LT1;PA5,6;")))
    assert got == [
        HpglCommand("IN", (), 0, 1, 1, True),
        HpglCommand("LT", (), 6, 2, 3, False),
        HpglCommand("PA", (5.0, 6.0), 10, 2, 7, True),
    ]


def test_interpretation_absolute_relative_pen_up_down():
    # PR moves are relative to the current point; PU/PD use the current mode; DF/IN go back to absolute
    assert strokes(b"PU10,10;PR;PD5,0,0,5;PU;PA0,0;PD;PR1,1;PU;DF;PD2,2;") == [
        (0, [[10.0, 10.0], [15.0, 10.0], [15.0, 15.0]]),
        (0, [[0.0, 0.0], [1.0, 1.0]]),
        (0, [[1.0, 1.0], [2.0, 2.0]]),
    ]
    # a PD while the pen is down continues the stroke; PD then PU is a dot; SP lifts the pen
    assert strokes(b"SP2;PD;PA4,0;PD;PA4,4;PU;PA9,9;PD;PU;SP1;PA1,1;PD0,0") == [
        (2, [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]),
        (2, [[9.0, 9.0]]),
        (1, [[1.0, 1.0], [0.0, 0.0]]),
    ]


def test_unknown_commands_are_warnings_with_byte_offset_and_line():
    d = parse_hpgl(b"IN;SP1;\nVS10;PU0,0;PD10,0;\nLT;VS5;", source="w.plt")
    assert d.warnings == [
        "w.plt:2: unknown command 'VS' at byte 8 ignored (1 more like it)",
        "w.plt:3: unknown command 'LT' at byte 27 ignored",
    ]
    assert d.command_counts["VS"] == 2 and d.command_counts["PD"] == 1


@pytest.mark.parametrize(
    "text, where, fragment",
    [
        (b"PU;\nPA1.2.3,4;", "2:3", "malformed number '1.2.3'"),
        (b"PA10,12x5;", "1:6", "malformed number '12x5'"),
        (b"PA--4,3;", "1:3", "malformed number '--4'"),
        (b"SP1;\n  PA 1-2;", "2:6", "malformed number '1-2'"),
        (b"PA1e5,2;", "1:3", "malformed number '1e5'"),
        (b"PA,5;", "1:3", "empty parameter"),
        (b"PA1,,2;", "1:5", "empty parameter"),
        (b"PA1,2,;", "1:1", "a number must follow ','"),
        (b"PA1,2#;", "1:5", "malformed number '2#'"),
        (b"P1;", "1:1", "'P1' is not an HPGL command"),
        (b"PU;%", "1:4", "unexpected character"),
        (b"SP1.5;", "1:1", "'SP' takes one pen number"),
        (b"PA1,2,3;", "1:7", "odd number of coordinates (3)"),
    ],
)
def test_malformed_input_names_line_and_column(text, where, fragment):
    with pytest.raises(cam.ParseError) as info:
        parse_hpgl(text, source="bad.plt")
    msg = str(info.value)
    assert msg.startswith(f"bad.plt:{where}: ") and fragment in msg, msg
    assert "\n" not in msg


@pytest.mark.parametrize(
    "text, where, fragment",
    [
        (b"SP1;PU0,0;\nPD10,10,\n", "2:1", "unterminated command 'PD' at the end of the file"),
        (b"SP1;PU0,0;PA100,", "1:11", "unterminated command 'PA' at the end of the file"),
        (b"PU0,0;\nPA100", "2:3", "odd number of coordinates (1)"),
        (b"PU0,0;P", "1:7", "unterminated command 'P' at the end of the file"),
        (b"PU0,0;LBtext without its terminator", "1:7", "unterminated label 'LB'"),
        (b'CO "never closed', "1:1", "unterminated quoted string"),
    ],
)
def test_unterminated_command_at_the_end_of_the_file(text, where, fragment):
    with pytest.raises(cam.ParseError) as info:
        parse_hpgl(text, source="eof.plt")
    assert str(info.value).startswith(f"eof.plt:{where}: ") and fragment in str(info.value), str(info.value)


MIXED = (b"IN;DF;SP1;PU0,0;PD400,0,400,-400;PU;PA 100 , 200\nPD;PR10,10,-5,3;PU\nSP2PD1.5,2.25,+3,-.5;"
         b"LBhello; world\x03VS10;CO \"a;b PD9,9\";PA5,5;DT#;LBabc#PD;PE<=>?@AB;PU1,1;SP0;PD2,2;PU;\n")


@pytest.mark.parametrize("chunk", [1, 2, 3, 5, 8, 13, 64])
def test_chunk_boundaries_change_nothing(chunk):
    ref = load_hpgl(io.BytesIO(MIXED))
    got = load_hpgl(io.BytesIO(MIXED), chunk_bytes=chunk)
    for name in ("points_pu", "stroke_start", "stroke_pen", "point_line", "point_col"):
        assert np.array_equal(getattr(got, name), getattr(ref, name)), name
    assert got.warnings == ref.warnings and got.command_counts == ref.command_counts
    with pytest.raises(cam.ParseError, match=r"^m\.plt:3:6: malformed number '1\.5\."):
        load_hpgl(io.BytesIO(MIXED.replace(b"1.5,", b"1.5.5,")), source="m.plt", chunk_bytes=chunk)


def test_a_coordinate_command_longer_than_a_chunk_streams_pair_by_pair():
    xs = np.arange(5000)
    body = ",".join(f"{x},{(x * 7) % 300 - 150}" for x in xs.tolist())
    data = f"PU0,0;PD{body};PU;".encode()
    d = load_hpgl(io.BytesIO(data), chunk_bytes=4096)  # the PD command is ~45 kB
    assert d.n_strokes == 1
    assert np.array_equal(d.points_pu[1:, 0], xs) and np.array_equal(d.points_pu[1:, 1], (xs * 7) % 300 - 150)
    assert len(list(iter_hpgl(io.BytesIO(data)))) == 3


def test_scan_counts_extent_and_progress():
    seen = []
    s = scan_hpgl(SAMPLES / "seed_tools.plt", progress=lambda done, total: seen.append((done, total)))
    size = (SAMPLES / "seed_tools.plt").stat().st_size
    assert seen[-1] == (size, size) and s.n_bytes == size
    assert (s.n_strokes, s.n_points, s.pens) == (4, 13, [1, 2])
    assert s.extent_pu == (-4.0, -4.0, 1604.0, 1204.0)
    assert s.command_counts["SP"] == 2 and s.warnings == []


def test_missing_file_is_a_parse_error(tmp_path):
    with pytest.raises(cam.ParseError, match="not found"):
        load_hpgl(tmp_path / "nope.plt")


# ---------------------------------------------------------------- the planner


def test_units_frames_and_placement():
    d = parse_hpgl(b"SP1;PU1000,2000;PD1040,2000,1040,1960;PU;")
    xy = hpgl_steps(d)
    # 40 plotter units = 1 mm; top-left corner (smallest X, largest Y) at the home; machine y = -Y
    assert xy.tolist() == [[0, 0], [round(40 * K), 0], [round(40 * K), round(40 * K)]]
    xy_off = hpgl_steps(d, offset_mm=(5.0, 60.0))
    assert xy_off.tolist()[0] == [round((5 + 25) / S.mm_per_step_xy), round((60 - 50) / S.mm_per_step_xy)]
    # nearest step, not the seed's truncation: 3 units = 2.595 steps -> 3 (the seed's 3*250/254 gives 2)
    assert hpgl_steps(parse_hpgl(b"PD0,0,3,0"))[-1, 0] == 3


def test_plan_moves_pen_up_at_the_safe_height_and_cuts_at_depth():
    d = parse_hpgl(b"PU0,0;PD400,0;PU;PA800,0;PD800,400;PU;PA801,400;PD0,400;")
    job = plan_hpgl(d, cut_depth_mm=0.5, travel_height_mm=1.0)
    depth, safe = round(0.5 / S.mm_per_step_z), -round(1.0 / S.mm_per_step_z)
    p, kind = job.points_steps, job.kind
    prev = np.vstack([[0, 0, 0], p[:-1]])
    xy_move = np.any(p[:, :2] != prev[:, :2], axis=1)
    assert np.all((p[:, 2] == depth) == (kind == CUT))
    assert np.all(p[xy_move & (kind != CUT), 2] == safe)  # every pen-up XY move at the safe height
    assert np.all(~xy_move[kind == RETRACT])  # lifts are straight up
    assert np.all(p[xy_move, 2] == prev[xy_move, 2])  # XY moves never change Z
    assert p[-1].tolist() == [0, 0, 0] and kind[-1] == TRAVEL
    # the third stroke starts one step from where the second ended (801 vs 800 units = 1 step): no lift
    assert job.n_retracts == 3  # start, after the first stroke, at the end
    assert job.pause_notes == [] and not job.pause.any()


def test_tool_changes_pause_in_order_at_the_safe_height():
    d = load_hpgl(SAMPLES / "seed_tools.plt")
    job = plan_hpgl(d)
    assert job.pause_notes == ["tool change: pen 1", "tool change: pen 2"]
    seen = []
    result = cam.run(job, on_pause=lambda pos, note: seen.append((note, pos)))
    assert result.status == "finished"
    safe = -round(DEFAULT_TRAVEL_HEIGHT_MM / S.mm_per_step_z)
    assert [n for n, _ in seen] == ["tool change: pen 1", "tool change: pen 2"]
    assert all(pos[2] == safe for _, pos in seen)
    # pen 2 is paused for after every pen-1 stroke and before any pen-2 cut
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    steps = cam.plan_steps(job)
    second = int(steps.pause_writes[1])
    xy_before = {tuple(v) for v in motion.position_steps[:second + 1][motion.position_steps[:second + 1, 2] > 0, :2]}
    pen1 = {tuple(v) for v in hpgl_steps(d)[: d.stroke_start[2]].tolist()}
    assert pen1 <= xy_before
    # a pen that does not change (SP1 twice) and SP0 (no pen) do not pause
    again = plan_hpgl(parse_hpgl(b"SP1;PD0,0,40,0;PU;SP1;PA80,0;PD80,40;PU;SP0;PA0,80;PD40,80;"))
    assert again.pause_notes == ["tool change: pen 1"]


def test_outside_the_travel_names_line_and_column():
    """Wider than the travel (300 mm on a 289 mm X travel): refused wherever it would be placed, naming the point
    that makes it too wide.  Placed by its own zero (a machine home, ``home_steps``), a point outside the travel is
    named; without a home the job is planned in its own frame (issue #45 point 4): 5 mm left of its home fits the
    travel's span, and where it runs is checked when it is placed (from the home here: refused before a step)."""
    with pytest.raises(cam.TravelError, match=r"^far\.plt:2:9: point X12000 Y0 \(plotter units\) lies outside the "
                                              r"machine travel: X travel is 0\.\.10000 "
                                              r"steps \(0\.\.289 mm, 289 mm\) and the job spans X 0\.\.10381"):
        plan_hpgl(parse_hpgl(b"SP1;PU0,0;\nPD400,0,12000,0;", source="far.plt"))
    with pytest.raises(cam.TravelError, match=r"^o\.plt:1:3: point X0 Y0 .*beyond the X travel"):
        plan_hpgl(parse_hpgl(b"PU0,0PD40,0", source="o.plt"), offset_mm=(-5.0, 10.0), home_steps=(0, 0, 0))
    own = plan_hpgl(parse_hpgl(b"PU0,0PD40,0", source="o.plt"), offset_mm=(-5.0, 10.0))
    assert own.points_steps[:, 0].min() < 0  # left of its home
    with pytest.raises(cam.TravelError, match="leaves the machine travel"):
        cam.plan_steps(own)  # run from the home
    with pytest.raises(cam.PlanError, match="nothing to cut"):
        plan_hpgl(parse_hpgl(b"IN;PU100,100;"))


# ---------------------------------------------------------------- the carve check


def _keys(xy):
    xy = np.asarray(xy, np.int64).reshape(-1, 2)
    return xy[:, 0] * 1_000_003 + xy[:, 1]


def assert_carves_the_drawing(drawing, job, settings=S):
    """Run on the mock, decode the pin log, and compare what went below the surface with the drawing.

    Expected, computed here from the plotter coordinates: each vertex at the nearest step of its exact
    position (within half a step); each pen-down segment between them rasterised along its longer axis,
    the other axis within one step of the straight line (what a DDA of a straight move visits).
    """
    result = cam.run(job)
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    pos = motion.position_steps
    depth = int(job.points_steps[job.target][:, 2].max())
    below = pos[:, 2] > 0
    assert np.all(pos[below, 2] <= depth)
    cut = np.unique(_keys(pos[below, :2]))
    assert np.array_equal(cut, np.unique(_keys(pos[pos[:, 2] == depth, :2])))  # full depth wherever it cuts
    pu = drawing.points_pu
    exact = np.column_stack([(pu[:, 0] - pu[:, 0].min()) * K, (pu[:, 1].max() - pu[:, 1]) * K])
    vertex = np.floor(exact + 0.5).astype(np.int64)
    assert np.abs(vertex - exact).max() <= 0.5
    assert np.isin(_keys(vertex), cut).all(), "a vertex of the drawing was not cut"
    allowed = [_keys(vertex)]
    ends = np.append(drawing.stroke_start[1:], len(pu))
    for a, b in zip(drawing.stroke_start.tolist(), ends.tolist()):
        for p, q in zip(vertex[a:b - 1], vertex[a + 1:b]):
            n = int(np.abs(q - p).max())
            if n == 0:
                continue
            ideal = p + (q - p) * (np.arange(n + 1) / n)[:, None]
            lo, hi = _keys(np.floor(ideal + 1e-9)), _keys(np.ceil(ideal - 1e-9))
            covered = np.isin(lo, cut) | np.isin(hi, cut)
            assert covered.all(), f"segment {p.tolist()} -> {q.tolist()} not cut at step {int(np.argmin(covered))}"
            allowed += [lo, hi]
    extra = ~np.isin(cut, np.concatenate(allowed))
    assert not extra.any(), f"{int(extra.sum())} position(s) cut that the drawing does not ask for"
    assert motion.final_steps == (0, 0, 0)
    return result


@pytest.mark.parametrize("name", ["seed_tools", "inkscape_star", "extended"])
def test_samples_cut_exactly(name):
    d = load_hpgl(SAMPLES / f"{name}.plt")
    job = plan_hpgl(d, cut_depth_mm=0.3, travel_height_mm=0.5)
    result = assert_carves_the_drawing(d, job)
    assert result.status == "finished"


def test_random_drawings_cut_exactly():
    rng = np.random.default_rng(7)
    for trial in range(4):
        parts = ["IN;", "SP1;"]
        for _ in range(6):
            x, y = rng.integers(-800, 800, 2)
            pts = np.cumsum(rng.integers(-150, 150, (int(rng.integers(1, 6)), 2)), axis=0) + (x, y)
            parts.append(f"PU{x},{y};")
            if rng.random() < 0.5:
                parts.append("PD" + ",".join(f"{a}.{rng.integers(0, 10)},{b}" for a, b in pts.tolist()) + ";")
            else:
                parts.append("PD;" + "".join(f"PA{a},{b}" for a, b in pts.tolist()) + "\n")
        parts.append("PU0,0;")
        d = parse_hpgl("".join(parts))
        assert_carves_the_drawing(d, plan_hpgl(d, cut_depth_mm=0.2, travel_height_mm=0.3))


def test_the_carve_check_sees_a_wrong_cut():
    d = parse_hpgl(b"PU0,0;PD400,0;PU;PA0,400;PD400,400,400,800;")
    job = plan_hpgl(d)
    depth = int(job.points_steps[:, 2].max())

    def mutated(points, keep):
        return cam.Job(points_steps=points[keep], kind=job.kind[keep], target=job.target[keep],
                       pause=job.pause[keep], settings=job.settings)

    every = np.ones(len(job), bool)
    low = job.points_steps.copy()
    low[:-1][job.kind[:-1] != CUT, 2] = depth  # travel without lifting the tool
    with pytest.raises(AssertionError, match="does not ask for"):
        assert_carves_the_drawing(d, mutated(low, every))
    short = job.points_steps.copy()
    last = np.flatnonzero(job.kind == CUT)[-1]
    short[last:last + 2, :2] = short[last - 1, :2]  # the last segment left out, the lift from where it stops
    with pytest.raises(AssertionError, match="not cut"):
        assert_carves_the_drawing(d, mutated(short, every))


# ---------------------------------------------------------------- the command line


def cli(*args):
    """``cam ARGS`` in this process (conftest.run_cli)."""
    return run_cli(*args)


def assert_one_line_error(proc, *fragments):
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], lines[0]


def test_cli_runs_hpgl_with_tool_changes(tmp_path):
    proc = cli("drill", SAMPLES / "seed_tools.plt", "--yes", "--no-progress", "--cut-depth", "0.4",
               "--pin-log", tmp_path / "p.csv", "--report", tmp_path / "r.json")
    assert proc.returncode == 0, proc.stderr
    assert "job finished: 4 pen-down strokes" in proc.stdout
    notes = [line.split(":")[0] + ":" + line.split(":")[1] for line in proc.stderr.splitlines() if "tool change" in line]
    assert notes == ["tool change: pen 1", "tool change: pen 2"]
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["status"] == "finished" and report["tool_changes"] == ["tool change: pen 1", "tool change: pen 2"]
    motion = cam.decode_pin_log(tmp_path / "p.csv")
    assert motion.position_steps[:, 2].max() == round(0.4 / S.mm_per_step_z) and motion.final_steps == (0, 0, 0)
    info = cli("info", SAMPLES / "extended.plt")
    assert info.returncode == 0 and "5 pen-down strokes" in info.stdout and "'LT' at byte 1084" in info.stdout


@pytest.mark.parametrize(
    "text, fragments",
    [
        (b"SP1;PU0,0;\nPD10.5.5,3;", ("bad.plt:2:3:", "malformed number '10.5.5'")),
        (b"SP1;PU0,0;PD40,40;\nPA100,", ("bad.plt:2:1:", "unterminated command 'PA'")),
        (b"SP1;PU0,0;\nPD400,0,\n  12000,0;", ("bad.plt:3:3:", "outside the machine travel")),
    ],
)
def test_cli_bad_hpgl_is_one_line_and_nothing_moves(tmp_path, text, fragments):
    bad = tmp_path / "bad.plt"
    bad.write_bytes(text)
    log = tmp_path / "p.csv"
    assert_one_line_error(cli("drill", bad, "--yes", "--pin-log", log), *fragments)
    assert not log.exists()


# ---------------------------------------------------------------- streaming: flat memory on a 200 MB file

_CHILD = """
import json, sys
import io
import cam.formats.hpgl as h
h.scan_hpgl(io.BytesIO(b"IN;SP1;PU0,0;PD1,1;LT;"))  # load the compiled kernels first
def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset the peak to the current size
before = status("VmRSS")
s = h.scan_hpgl(sys.argv[1])
print(json.dumps({"before": before, "peak": status("VmHWM"), "points": s.n_points, "strokes": s.n_strokes,
                  "bytes": s.n_bytes, "extent": s.extent_pu, "warnings": s.warnings, "pens": s.pens}))
"""


@pytest.mark.slow
def test_scanning_200_mb_keeps_memory_flat(tmp_path):
    if not os.access("/proc/self/clear_refs", os.W_OK):
        pytest.skip("needs Linux /proc/self/clear_refs to measure the peak memory of the parse alone")
    rng = np.random.default_rng(1)
    # one block of strokes as a drawing program writes them: several pairs, decimals, signs, mixed separators
    lines = []
    n_pts = 0
    for i in range(400):
        pts = rng.integers(-20000, 20000, (12, 2))
        lines.append(f"PU{pts[0, 0]},{pts[0, 1]};PD" + ",".join(f"{a}.5,{b}" for a, b in pts[1:].tolist()) + ";")
        n_pts += 12
    block = ("\n".join(lines) + "\nVS10;").encode()
    path = tmp_path / "big.plt"
    target = 200 * 1024 * 1024
    reps = target // len(block) + 1
    with open(path, "wb") as f:
        f.write(b"IN;SP1;")
        for _ in range(reps):
            f.write(block)
        f.write(b"PU0,0;SP0;")
    size = path.stat().st_size
    assert size >= target
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True, text=True,
                          env=ENV, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    path.unlink()
    assert out["bytes"] == size and out["points"] == reps * n_pts and out["strokes"] == reps * 400
    assert out["pens"] == [1] and out["warnings"] == [f"{path}:{lines.__len__() + 1}: unknown command 'VS' at byte "
                                                      f"{7 + len(block) - 5} ignored ({reps - 1} more like it)"]
    grown_mb = (out["peak"] - out["before"]) / 2**20
    assert grown_mb < 100, f"parsing {size / 2**20:.0f} MB grew the process by {grown_mb:.0f} MB"
