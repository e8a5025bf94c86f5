"""Levelling a job to a probed height map (issue #46 point 2): the map, its file, the split and offset moves, and the
proof on the mock: a warped board cut at the asked depth below its surface at every cut point, decoded from the pin
log, for an HPGL isolation drawing, a drill file and a G-code program."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import cam
from cam.errors import CamError, ParseError, PlanError
from cam.job.heightmap_level import (
    HeightMap, LevelledJob, check_map, height_at, level_job, level_points, load_height_map, save_height_map,
)
from cam.job.model import CUT, RETRACT, TRAVEL, Job
from cam.verify.pinlog import decode_pin_log, read_pin_log

from conftest import SAMPLES as ROOT_SAMPLES, run_cli

S = cam.MachineSettings()
MX, MY, MZ = S.mm_per_step_axes


def ok(proc):
    assert proc.returncode == 0, (proc.stdout, proc.stderr)
    return proc


def plane_map(a=0.2, bx=0.003, by=-0.002, cxy=0.0, x=(0, 40, 100), y=(0, 30, 80), reference_mm=0.1):
    """A map of the surface ``a + bx x + by y + cxy x y`` (bilinear: levelled exactly everywhere)."""
    xs, ys = np.asarray(x, float), np.asarray(y, float)
    gx, gy = np.meshgrid(xs, ys)
    return HeightMap(xs, ys, a + bx * gx + by * gy + cxy * gx * gy, reference_mm=reference_mm, spacing_mm=10.0)


# -- the map -----------------------------------------------------------------------------------------------------

def test_height_at_is_exact_on_a_bilinear_surface_inside_and_beyond_the_grid():
    m = plane_map(cxy=1e-5)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-20, 120, 500), rng.uniform(-20, 100, 500)
    want = 0.2 + 0.003 * x - 0.002 * y + 1e-5 * x * y
    assert np.allclose(height_at(m, x, y), want, rtol=0, atol=1e-12)
    assert height_at(m, x.reshape(20, 25), 3.0).shape == (20, 25)  # broadcast shapes in, that shape out
    assert height_at(m, 40.0, 30.0) == pytest.approx(m.height_mm[1, 1], abs=1e-15)  # the grid's own points


def test_save_and_load_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(2)
    m = HeightMap(np.array([0.0, 10.0, 20.0]), np.array([5.0, 15.0]), rng.normal(0, 0.3, (2, 3)),
                  reference_mm=0.123456789012345, spacing_mm=10.0, machine="mill.toml", time="2026-12-01T10:00:00")
    path = save_height_map(m, tmp_path / "map.json")
    back = load_height_map(path)
    assert np.array_equal(back.x_mm, m.x_mm) and np.array_equal(back.y_mm, m.y_mm)
    assert np.array_equal(back.height_mm, m.height_mm)  # every float to its last digit
    assert (back.reference_mm, back.spacing_mm, back.machine, back.time) == \
        (m.reference_mm, 10.0, "mill.toml", "2026-12-01T10:00:00")
    data = json.loads(path.read_text())
    assert (data["cam_height_map"], data["frame"], data["units"]) == (1, "machine", "mm")
    assert data["height_mm"][1] == m.height_mm[1].tolist()  # a row per y_mm
    assert not list(tmp_path.glob("*.tmp*"))  # written atomically: no temporary left


GOOD = {"cam_height_map": 1, "frame": "machine", "units": "mm", "x_mm": [0, 10, 20], "y_mm": [0, 10],
        "height_mm": [[0, 0.1, 0.2], [0.1, 0.2, 0.3]], "reference_mm": 0.0, "spacing_mm": 10, "machine": None,
        "time": "2026-12-01T10:00:00"}


def _with(**changes):
    d = dict(GOOD)
    for k, v in changes.items():
        if v is _with:
            d.pop(k)
        else:
            d[k] = v
    return json.dumps(d)


BAD_FILES = [
    ("not json", "{not json", "not a height map JSON file"),
    ("a list", "[1, 2]", "not a height map"),
    ("NaN height", _with().replace("0.3]", "NaN]"), "NaN is not a number"),
    ("infinite height", _with().replace("0.3]", "Infinity]"), "Infinity is not a number"),
    ("another format", _with(cam_height_map=2), "key 'cam_height_map' must be 1"),
    ("no version", _with(cam_height_map=_with), "key 'cam_height_map' missing"),
    ("another frame", _with(frame="work"), "key 'frame' must be \"machine\""),
    ("inches", _with(units="inch"), "key 'units' must be \"mm\""),
    ("x not ascending", _with(x_mm=[0, 20, 10]), "key 'x_mm' must be ascending: value 2 (10)"),
    ("y repeated", _with(y_mm=[5, 5]), "key 'y_mm' must be ascending"),
    ("one column", _with(x_mm=[0], height_mm=[[0], [1]]), "key 'x_mm' needs at least 2 points"),
    ("a row short", _with(height_mm=[[0, 0.1, 0.2], [0.1, 0.2]]), "key 'height_mm' row 1 has 2 values, x_mm has 3"),
    ("a row missing", _with(height_mm=[[0, 0.1, 0.2]]), "key 'height_mm' has 1 rows, y_mm has 2"),
    ("text in a row", _with(height_mm=[[0, "0.1", 0.2], [0.1, 0.2, 0.3]]), "key 'height_mm' row 0 value 1 must be "
                                                                          "a number"),
    ("true as a number", _with(x_mm=[0, True, 20]), "key 'x_mm' value 1 must be a number"),
    ("heights not a list", _with(height_mm=3), "key 'height_mm' must be a list"),
    ("no reference", _with(reference_mm=_with), "key 'reference_mm' missing"),
    ("reference text", _with(reference_mm="0"), "key 'reference_mm' must be a finite number"),
    ("no spacing", _with(spacing_mm=0), "key 'spacing_mm' must be a number > 0"),
    ("machine a number", _with(machine=3), "key 'machine' must be a file name or null"),
    ("too many points", _with(x_mm=list(range(1100)), y_mm=list(range(1000))), "points, more than 1,048,576"),
    ("a huge number", _with().replace("0.3]", "1e999]"), "key 'height_mm' row 1 value 2 is inf"),
]


@pytest.mark.parametrize("text, fragment", [b[1:] for b in BAD_FILES], ids=[b[0] for b in BAD_FILES])
def test_a_malformed_map_file_is_one_line_naming_the_file_and_the_key(tmp_path, text, fragment):
    path = tmp_path / "map.json"
    path.write_text(text)
    with pytest.raises(ParseError) as e:
        load_height_map(path)
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and msg.startswith(f"{path}: ") and fragment in msg, msg


def test_a_missing_huge_or_binary_map_file_is_one_line(tmp_path, monkeypatch):
    import cam.job.heightmap_level as hl

    with pytest.raises(ParseError, match=r"map\.json: file not found$"):
        load_height_map(tmp_path / "map.json")
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ParseError, match="not UTF-8"):
        load_height_map(tmp_path / "bin.json")
    (tmp_path / "big.json").write_text(_with())
    monkeypatch.setattr(hl, "MAX_MAP_BYTES", 100)
    with pytest.raises(ParseError, match=r"big\.json: \d+ bytes, more than a height map file may be \(100\)$"):
        load_height_map(tmp_path / "big.json")
    with pytest.raises(ParseError, match=r": is a folder, not a height map file$"):  # cam.fileio.read_bytes's lines
        load_height_map(tmp_path)


def test_a_map_made_in_python_is_checked_as_a_file_is():
    with pytest.raises(CamError, match="height map: x_mm must be ascending"):
        HeightMap([0, 0], [0, 1], np.zeros((2, 2)))
    with pytest.raises(CamError, match=r"height map: height_mm must be 2 rows .* got shape \(3, 2\)"):
        HeightMap([0, 1], [0, 1], np.zeros((3, 2)))
    with pytest.raises(CamError, match="height map: height_mm row 0 value 1 is nan"):
        HeightMap([0, 1], [0, 1], [[0, math.nan], [0, 0]])


def test_a_steep_map_is_refused_naming_the_two_points():
    m = plane_map()
    assert check_map(m) is m  # a few tenths of a mm across: fine
    h = m.height_mm.copy()
    h[2, 1] += 1.4  # a probe that touched a clamp at X 40, Y 80
    steep = HeightMap(m.x_mm, m.y_mm, h, reference_mm=0.1, spacing_mm=10)
    with pytest.raises(CamError) as e:
        check_map(steep)
    msg = str(e.value)
    assert len(msg.splitlines()) == 1
    assert "X 40, Y 80 mm" in msg and ("X 0, Y 80 mm" in msg or "X 100, Y 80 mm" in msg or "X 40, Y 30 mm" in msg)
    assert "more than 1 mm" in msg
    assert check_map(steep, max_diff_mm=2.0) is steep  # the limit is the caller's


# -- levelling points --------------------------------------------------------------------------------------------

def test_a_tilted_plane_map_levels_any_point_exactly():
    m = plane_map(cxy=2e-6)
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.integers(0, int(100 / MX), 300), rng.integers(0, int(80 / MY), 300),
                           rng.integers(-60, 200, 300)])
    lv = level_points(pts, m, S)  # no start: the points are offset, never split before point 0...
    surface = 0.2 + 0.003 * pts[:, 0] * MX - 0.002 * pts[:, 1] * MY + 2e-6 * pts[:, 0] * MX * pts[:, 1] * MY
    want = np.rint(pts[:, 2] - (surface - 0.1) / MZ)  # higher than the work zero's surface: less deep
    ends = lv.points_steps[lv.is_end]
    assert np.array_equal(ends[:, :2], pts[:, :2]) and np.array_equal(ends[:, 2], want)
    # ... and every split point's Z is its move's Z there, offset by the plane at its own XY
    p = lv.points_steps
    before = np.vstack([pts[:1], pts[:-1]])[lv.move_of]
    line_z = before[:, 2] + (pts[lv.move_of, 2] - before[:, 2]) * lv.t
    x_mm, y_mm = p[:, 0] * MX, p[:, 1] * MY
    plane = 0.2 + 0.003 * x_mm - 0.002 * y_mm + 2e-6 * x_mm * y_mm
    assert np.all(np.abs(p[:, 2] - (line_z - (plane - 0.1) / MZ)) <= 0.5 + 1e-9)


def test_moves_are_split_at_the_maps_spacing_with_z_along_the_move():
    flat = HeightMap([0, 300], [0, 300], np.zeros((2, 2)), spacing_mm=10.0)
    n100 = round(100 / MX)
    pts = np.array([[n100, 0, 64], [n100, 0, 0], [0, round(50 / MY), 0], [0, round(50 / MY), 80]])
    lv = level_points(pts, flat, S, start_steps=(0, 0, 0))
    counts = np.bincount(lv.move_of)
    assert counts.tolist() == [10, 1, 12, 1]  # 100 mm: 10 moves; a plunge: 1; the 111.8 mm diagonal: 12
    q = np.vstack([[0, 0, 0], lv.points_steps])
    lengths = np.hypot(np.diff(q[:, 0]) * MX, np.diff(q[:, 1]) * MY)
    assert lengths.max() <= 10.0 + MX  # no move longer than the spacing (a step's rounding)
    assert np.array_equal(lv.points_steps[lv.is_end], pts)  # the source's own points kept exactly
    first = lv.points_steps[:10]  # Z along the first move: 0 .. 64 steps, linear in its length
    assert np.all(np.abs(first[:, 2] - 64 * first[:, 0] / n100) <= 0.5 + 1e-9)
    assert np.allclose(lv.t[:10], np.arange(1, 11) / 10)
    # a finer grid than its spacing says: split at the grid's
    fine = HeightMap([0, 5, 300], [0, 300], np.zeros((2, 3)), spacing_mm=10.0)
    assert fine.split_mm == 5.0 and len(level_points(pts[:1], fine, S, start_steps=(0, 0, 0)).points_steps) == 20


def test_a_point_outside_the_probed_area_is_refused_naming_how_far_and_past_which_edge():
    m = HeightMap([10, 110], [20, 100], [[0.0, 0.3], [0.1, 0.4]], spacing_mm=10)
    inside = np.array([[round(50 / MX), round(50 / MY), 10]])
    level_points(inside, m, S)
    past_x = np.array([[round(113.5 / MX), round(50 / MY), 10]])
    with pytest.raises(PlanError) as e:
        level_points(past_x, m, S)
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and "mm outside the probed area, past its X max edge (X 110 mm)" in msg
    assert f"reaches {round(113.5 / MX) * MX - 110:.4g} mm outside" in msg and "--level-extrapolate" in msg
    with pytest.raises(PlanError, match=r"reaches 5\.\d+ mm outside the probed area, past its Y min edge"):
        level_points(np.array([[round(50 / MX), round(15 / MY), 0]]), m, S)
    # a move that starts inside and ends outside is refused too; its split points are checked, not only its ends
    with pytest.raises(PlanError, match="Y max edge"):
        level_points(np.array([[round(50 / MX), round(104 / MY), 0]]), m, S, start_steps=inside[0])
    # extrapolate: the edge cell's bilinear patch extended past the edge (the map is a plane here: exact)
    lv = level_points(past_x, m, S, extrapolate=True)
    x, y = past_x[0, 0] * MX, past_x[0, 1] * MY
    plane = 0.3 * (x - 10) / 100 + 0.1 * (y - 20) / 80
    assert lv.points_steps[0, 2] == round(10 - plane / MZ)


# -- levelling jobs ----------------------------------------------------------------------------------------------

def _job() -> Job:
    pts = np.array([[0, 0, -64], [1000, 0, -64], [1000, 0, 10], [3000, 500, 10], [3000, 500, 10], [3000, 500, -64],
                    [0, 0, -64]], np.int64)
    kind = np.array([TRAVEL, TRAVEL, CUT, CUT, CUT, RETRACT, TRAVEL], np.uint8)
    return Job(points_steps=pts, kind=kind, target=np.array([0, 0, 1, 1, 1, 0, 0], bool),
               pause=np.array([0, 1, 0, 0, 0, 0, 0], bool), settings=S, pause_notes=["tool change: pen 2"],
               safe_z_steps=-64, source="t", period_ns=np.array([0, 0, 9, 9, 9, 0, 0], np.int64),
               periods=np.array([0, 0, 0, 4000, 50_000, 0, 0], np.int64),
               rest=np.array([0, 0, 0, 0, 1, 0, 0], bool))


class _Pieces:
    """A job made of consecutive pieces (as a streamed planner makes them)."""

    def __init__(self, job: Job, cuts: list[int]) -> None:
        self.job, self.cuts = job, cuts
        self.settings, self.safe_z_steps, self.source = job.settings, job.safe_z_steps, job.source
        self.warnings, self.pixels, self.tool = [], None, None

    def pieces(self):
        edges = [0, *self.cuts, len(self.job)]
        for a, b in zip(edges[:-1], edges[1:]):
            j = self.job
            yield Job(points_steps=j.points_steps[a:b], kind=j.kind[a:b], target=j.target[a:b], pause=j.pause[a:b],
                      settings=j.settings, pause_notes=["tool change: pen 2"] if j.pause[a:b].any() else [],
                      safe_z_steps=j.safe_z_steps, source=j.source, period_ns=j.period_ns[a:b],
                      periods=j.periods[a:b], rest=j.rest[a:b])

    def joined(self):
        return self.job


def test_a_levelled_job_carries_every_moves_kind_pause_feed_and_time_onto_its_split_moves():
    m = plane_map(x=(-10, 200), y=(-10, 100))
    job = _job()
    home = (200, 300, -10)
    out = level_job(job, m, home)
    assert isinstance(out, Job)  # a job held in memory stays in memory
    lv = level_points(job.points_steps + np.array(home), m, S, start_steps=home)
    mv = lv.move_of
    assert np.array_equal(out.points_steps, lv.points_steps - np.array(home))  # rapids levelled too
    assert len(out) > len(job)
    assert np.array_equal(out.kind, job.kind[mv]) and np.array_equal(out.period_ns, job.period_ns[mv])
    assert np.array_equal(out.rest, job.rest[mv])
    assert np.array_equal(np.flatnonzero(out.pause), np.flatnonzero(lv.is_end)[[1]])  # at its source point only
    assert out.pause_notes == ["tool change: pen 2"] and out.n_targets == job.n_targets
    assert np.array_equal(np.bincount(mv, weights=out.periods), job.periods)  # a move's time shared among its parts
    starts = np.r_[True, mv[1:] != mv[:-1]]
    assert np.array_equal(out.move_start, starts)  # one ramp segment a source move
    # a stop lifts above the highest probed point
    rise = m.offsets_mm().max()
    assert out.safe_z_steps == -64 - math.ceil(rise / MZ)


def test_a_job_levelled_a_piece_at_a_time_is_the_job_levelled_whole():
    m = plane_map(x=(-10, 200), y=(-10, 100))
    whole = level_job(_job(), m, (200, 300, -10))
    streamed = level_job(_Pieces(_job(), [2, 3, 6]), m, (200, 300, -10))
    assert isinstance(streamed, LevelledJob)
    assert sum(1 for _ in streamed.pieces()) == 4
    got = streamed.joined()
    for name in ("points_steps", "kind", "target", "pause", "period_ns", "periods", "move_start", "rest"):
        assert np.array_equal(getattr(got, name), getattr(whole, name)), name
    assert got.safe_z_steps == whole.safe_z_steps


def test_level_options_are_declared_for_every_kind_and_extrapolate_needs_a_map():
    from cam.kinds import job_options, kind_names

    OPTIONS = {o.name: o for o in job_options()}  # with the kinds their traits give (cam.kinds)
    for name in ("level", "level_extrapolate"):
        assert OPTIONS[name].kinds == set(kind_names()) == {"drawing", "digitized", "gcode", "excellon", "hpgl",
                                                             "svg", "dxf"}
        assert not OPTIONS[name].web  # a file on the machine that runs cam
    assert OPTIONS["level"].flag == "--level" and OPTIONS["level_extrapolate"].flag == "--level-extrapolate"
    with pytest.raises(CamError, match="option 'level_extrapolate' needs a height map"):
        cam.JobOptions(level_extrapolate=True).checked()
    out = run_cli("drill", "samples/board.drl", "--level-extrapolate")
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1


def test_a_job_reaching_outside_the_map_is_refused_before_anything_is_planned(tmp_path):
    small = HeightMap([0, 20], [0, 20], np.zeros((2, 2)), spacing_mm=10)
    path = save_height_map(small, tmp_path / "small.json")
    with pytest.raises(PlanError) as e:
        cam.prepare_job("samples/board.drl", cam.JobOptions(level=str(path)))
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and msg.startswith(f"{path}: the job reaches ")
    assert "past its X max edge (X 20 mm)" in msg and "the map covers X 0..20, Y 0..20 mm" in msg
    job = cam.prepare_job("samples/board.drl", cam.JobOptions(level=str(path), level_extrapolate=True))
    assert any("levelled outside the probed area" in w for w in job.warnings)
    assert job.report["level"]["extrapolated"] is True


def test_a_maximus_board_refuses_a_levelled_job_in_one_line(tmp_path):
    path = save_height_map(plane_map(), tmp_path / "map.json")
    out = run_cli("drill", "samples/board.drl", "--level", path, "--port", "maximus:/dev/null")
    assert out.returncode == 2 and "--level" in out.stderr and len(out.stderr.strip().splitlines()) == 1


# -- the proof: a warped board on the mock ---------------------------------------------------------------------

BOARD_MM = (20.0, 20.0, 120.0, 100.0)
"""The board: 100 x 80 mm at machine X 20..120, Y 20..100 mm."""
WARP = dict(z0=0.1, ax=0.0036, ay=-0.001, b=0.2 / (50 ** 2 + 40 ** 2), cx=70.0, cy=60.0)
"""The warped surface: tilted 0.36 mm along X and 0.08 mm along Y, bowed 0.2 mm from its centre to its corners."""
SPACING_MM = 10.0


def surface_mm(x_mm, y_mm):
    """The board's surface height (mm, up positive) at machine ``(x_mm, y_mm)``."""
    w = WARP
    return w["z0"] + w["ax"] * x_mm + w["ay"] * y_mm + w["b"] * ((x_mm - w["cx"]) ** 2 + (y_mm - w["cy"]) ** 2)


BILINEAR_BOUND_MM = 3 * WARP["b"] * SPACING_MM ** 2 / 4
"""How far levelling by the map may lie from the formula besides the steps' rounding: the bilinear map is within
``b s^2 / 2`` of the bow ``b r^2`` in a cell (``b s^2 / 4`` along each axis), and a straight move at most ``s`` long
within ``b s^2 / 4`` of the bow's chord (its second derivative along any line is ``2 b``); the tilt is exact."""

HPGL = ("IN;SP1;PU0,0;PD3200,0,3200,2400,0,2400,0,0;PU400,400;PD2800,400,2800,2000,400,2000,400,400;"
        "PU400,400;PD2800,2000;PU1600,0;PD1600,2400;PU;SP0;")
"""An isolation drawing, 80 x 60 mm (40 plotter units a mm): an outline, a track round a pad, a diagonal."""

DRILL = "M48\nMETRIC\nT1C0.800\n%\nG90\nG05\nT1\n" + "".join(
    f"X{x:.3f}Y{y:.3f}\n" for y in (10.0, 30.0, 50.0, 70.0) for x in (10.0, 30.0, 50.0, 70.0, 90.0)) + "M30\n"
"""Twenty holes over 80 x 60 mm."""

CUT_STEPS = 8
"""The asked depth: 8 Z steps (0.1256 mm), a whole number of steps."""

GCODE = ("G21 G90 G17\nG0 Z2\nG0 X0 Y0\nG1 Z-{d} F100\nG1 X80 F400\nG1 Y-60\nG1 X0\nG1 Y0\nG1 X80 Y-60\nG0 Z2\n"
         "G0 X40 Y-30\nG1 Z-{d} F100\nG2 X40 Y-30 I10 J0 F300\nG0 Z2\nM2\n").format(d=CUT_STEPS * MZ)
"""The same outline and diagonal from the G54 work zero (machine Y = -Y mm), and a 20 mm circle."""


def _map_file(tmp_path, reference_mm):
    x0, y0, x1, y1 = BOARD_MM
    xs, ys = np.arange(x0, x1 + 1e-9, SPACING_MM), np.arange(y0, y1 + 1e-9, SPACING_MM)
    gx, gy = np.meshgrid(xs, ys)
    return save_height_map(HeightMap(xs, ys, surface_mm(gx, gy), reference_mm=reference_mm, spacing_mm=SPACING_MM,
                                     time="2026-12-01T10:00:00"), tmp_path / "map.json")


def _keys(pts: np.ndarray) -> np.ndarray:
    """One int64 per ``(N, 3)`` position (each axis within +-2^20 steps)."""
    p = np.asarray(pts, np.int64) + (1 << 20)
    return (p[:, 0] << 42) | (p[:, 1] << 21) | p[:, 2]


def _cut_errors(kind: str, tmp_path, level: bool, probed: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Set the work zero on the warped surface at machine (30, 30) mm, cut the job (levelled or not) on the mock and
    decode its pin log: the depth below the formula's surface minus the asked depth (mm) ``(at the job's cut points,
    at every write while cutting)``.

    The job's cut points are its points of kind CUT below the travel height (an HPGL pen-down or G-code G1 point,
    a split point of such a move, a hole's bottom), machine frame, each found among the decoded positions (the
    tool stops at every point of the job; asserted); every write while cutting is each decoded position that moves
    in XY below the travel height, and each hole's bottom.

    ``probed``: the map and the work Z zero are probed on the mock (``cam probe z``, ``cam probe grid``; the machine
    file's ``[mock] probe_surface`` is the formula), else the map is the formula sampled and the work Z zero the
    first step at or below the surface."""
    from cam.drive.state import read_state

    state, pins = tmp_path / f"{level}.state.json", tmp_path / f"{level}.pins.csv"
    machine = tmp_path / "warped.toml"
    w = WARP
    machine.write_text('[inputs]\nprobe = "!13"\n[mock]\nprobe_surface = '
                       f'"{w["z0"]},{w["ax"]},{w["ay"]},{w["b"]!r},{w["cx"]},{w["cy"]}"\n')
    m = ["--machine", machine, "--state", state]
    zx, zy = round(30.0 / MX), round(30.0 / MY)
    zz = -math.floor(float(surface_mm(zx * MX, zy * MY)) / MZ)  # the tool tip's first step at or below the surface
    if probed:  # over the point, zero X and Y there, probe Z's zero, then the board every 10 mm
        ok(run_cli("goto", f"{zx},{zy},{zz - 100}", "--unit", "steps", "--machine-coords", *m))
        ok(run_cli("zero", "XY", *m))
        ok(run_cli("probe", "z", *m))
        assert read_state(state, S).work_zero_steps() == (zx, zy, zz)  # the contact, as computed
        x0, y0, x1, y1 = BOARD_MM
        ok(run_cli("probe", "grid", "--area", f"{x0},{y0},{x1},{y1}", "--machine-coords", "--spacing",
                   str(SPACING_MM), "--out", tmp_path / "probed.json", *m))
        ok(run_cli("goto", "0,0,-1", "--unit", "mm", *m))  # back over the work zero
    else:
        ok(run_cli("goto", f"{zx},{zy},{zz}", "--unit", "steps", "--machine-coords", *m))
        ok(run_cli("zero", "XYZ", *m))
    path = tmp_path / {"hpgl": "iso.plt", "excellon": "holes.drl", "gcode": "iso.ngc"}[kind]
    path.write_text({"hpgl": HPGL, "excellon": DRILL, "gcode": GCODE}[kind])
    flags = [] if kind == "gcode" else ["--cut-depth", f"{CUT_STEPS * MZ:.6f}"]
    options = {} if kind == "gcode" else {"cut_depth_mm": float(f"{CUT_STEPS * MZ:.6f}")}
    if level:  # the reference: the height of the work Z zero's contact
        options["level"] = str(tmp_path / "probed.json") if probed else str(_map_file(tmp_path, -zz * MZ))
        flags += ["--level", options["level"]]
    settings = cam.load_settings(machine)
    planned = cam.prepare_job(path, cam.JobOptions(**options), settings, machine_state=read_state(state, settings))
    if kind == "gcode" and probed:  # a program runs from where the tool stands: over the work zero, 1 mm up
        assert tuple(read_state(state, settings).position_steps) == (zx, zy, zz - round(1 / MZ))
    ok(run_cli("drill", path, *flags, "--yes", *m, "--pin-log", pins))
    home = np.array(read_pin_log(pins).parts[-1].start_steps, np.int64)  # the job's part starts at its home
    pos = decode_pin_log(pins, settings, part="job").position_steps + home  # machine frame, after each write
    pos = pos[np.r_[True, np.any(pos[1:] != pos[:-1], axis=1)]]  # each position once (a step is two writes)
    # cutting, levelled or not: below the travel height (1 mm = 64 steps above the surface) less the warp's
    # +-0.3 mm (+-20 steps), above which the cuts never are
    low = pos[:, 2] > zz - 30
    prev, nxt = np.vstack([pos[:1], pos[:-1]]), np.vstack([pos[1:], pos[-1:]])
    bottom = low & (pos[:, 2] > prev[:, 2]) & (nxt[:, 2] < pos[:, 2])  # where a plunge turns back up
    writes = bottom | (low & np.any(pos[:, :2] != prev[:, :2], axis=1))
    toolpath = planned.toolpath.joined()
    cuts = toolpath.points_steps[(toolpath.kind == CUT) & (toolpath.points_steps[:, 2] + home[2] > zz - 30)] + home
    found = np.isin(_keys(cuts), _keys(pos))
    assert found.all(), f"{kind}: cut point {cuts[np.argmin(found)]} never reached"  # the plan drill ran
    at_cuts = np.isin(_keys(pos), _keys(cuts)) & low

    def error(at: np.ndarray) -> np.ndarray:
        x_mm, y_mm = pos[at, 0] * MX, pos[at, 1] * MY
        return surface_mm(x_mm, y_mm) + pos[at, 2] * MZ - CUT_STEPS * MZ  # the tip is at height -z MZ

    return error(at_cuts), error(writes)


@pytest.mark.parametrize("kind", ["hpgl", "excellon", "gcode"])
def test_a_levelled_job_cuts_at_the_asked_depth_below_a_warped_surface_at_every_cut_point(kind, tmp_path):
    x0, y0, x1, y1 = BOARD_MM
    gx, gy = np.meshgrid(np.linspace(x0, x1, 101), np.linspace(y0, y1, 81))
    warp = surface_mm(gx, gy)
    assert 0.45 <= warp.max() - warp.min() <= 0.55  # 0.5 mm of tilt and bow over the board
    at_cuts, writes = _cut_errors(kind, tmp_path, level=True)
    assert len(at_cuts) >= (20 if kind == "excellon" else 50) and len(writes) >= len(at_cuts)
    # at every cut point: one Z step (the point rounded to whole steps: half of one), and the map's bilinear error
    bound = MZ + BILINEAR_BOUND_MM
    worst = float(np.abs(at_cuts).max())
    assert worst <= bound, f"{kind}: depth off by {worst:.4f} mm at a cut point (bound {bound:.4f} mm)"
    # between them the step planner's DDA steps Z when floor(k dz / n) grows: up to one step behind the straight
    # line, so every write while cutting is within a step and a half
    worst_write = float(np.abs(writes).max())
    assert worst_write <= 1.5 * MZ + BILINEAR_BOUND_MM, (kind, worst_write)
    # without --level the same check fails: the error levelling removes
    plain_cuts, plain_writes = _cut_errors(kind, tmp_path, level=False)
    worst_plain = float(np.abs(plain_cuts).max())
    assert worst_plain > 10 * bound and len(plain_cuts) >= 10, (kind, worst_plain, len(plain_cuts))
    print(f"\n{kind}: levelled: {len(at_cuts)} cut points, depth error max {worst:.4f} mm, mean "
          f"{np.abs(at_cuts).mean():.4f} mm ({len(writes)} writes cutting: max {worst_write:.4f}, mean "
          f"{np.abs(writes).mean():.4f} mm); without --level: {len(plain_cuts)} cut points, max {worst_plain:.4f} mm, "
          f"mean {np.abs(plain_cuts).mean():.4f} mm ({len(plain_writes)} writes: max "
          f"{np.abs(plain_writes).max():.4f}, mean {np.abs(plain_writes).mean():.4f} mm)")


PROBE_BOUND_MM = 1.5 * MZ + BILINEAR_BOUND_MM
"""Levelled by a map probed on the mock: a contact is the first Z step at or below the surface, so every probed
height and the work Z zero lie up to one step below it (the same step a flat board's Z zero has), and the levelled
point is rounded to whole steps (half a step), besides the map's bilinear error."""


@pytest.mark.slow  # probing and three runs: over a second each (the formula's map above is the fast tier's proof)
@pytest.mark.parametrize("kind", ["hpgl", "excellon", "gcode"])
def test_a_job_levelled_by_a_map_probed_on_the_mock_cuts_at_the_asked_depth(kind, tmp_path):
    """The whole loop on the mock: cam probe z sets the work Z zero on the warped surface, cam probe grid probes
    the board every 10 mm, and cam drill --level cuts every cut point at the asked depth below the formula's
    surface within the probes' step, the rounding and the bilinear bound (PROBE_BOUND_MM)."""
    at_cuts, writes = _cut_errors(kind, tmp_path, level=True, probed=True)
    assert len(at_cuts) >= (20 if kind == "excellon" else 50)
    worst = float(np.abs(at_cuts).max())
    assert worst <= PROBE_BOUND_MM, f"{kind}: depth off by {worst:.4f} mm at a cut point (bound {PROBE_BOUND_MM:.4f})"
    assert float(np.abs(writes).max()) <= PROBE_BOUND_MM + MZ  # and between them the DDA's step
    print(f"\n{kind} (probed map): {len(at_cuts)} cut points, depth error max {worst:.4f} mm, mean "
          f"{np.abs(at_cuts).mean():.4f} mm; every write cutting: max {np.abs(writes).max():.4f} mm")


@pytest.mark.parametrize("kind", ["hpgl", "gcode", "drawing"])
def test_a_job_kept_as_pieces_is_levelled_a_piece_at_a_time_to_the_same_moves(kind, tmp_path, monkeypatch):
    """One implementation: a large job's pieces are levelled as they are made (bounded memory), a small one's joined;
    the levelled moves are the same whatever the pieces."""

    m = HeightMap([-5, 60, 140], [-5, 50, 110], [[0.0, 0.2, 0.1], [0.1, 0.4, 0.3], [0.3, 0.2, 0.5]],
                  reference_mm=0.1, spacing_mm=10)
    path = tmp_path / {"hpgl": "iso.plt", "gcode": "iso.ngc", "drawing": "d.png"}[kind]
    if kind == "drawing":
        path.write_bytes((ROOT_SAMPLES / "ellipse.png").read_bytes())
    else:
        path.write_text({"hpgl": HPGL, "gcode": GCODE}[kind])
    options = cam.JobOptions(level=str(save_height_map(m, tmp_path / "map.json")))
    held = cam.prepare_job(path, options)
    assert isinstance(held.toolpath, Job)
    monkeypatch.setattr({"hpgl": "cam.job.hpgl_stream.STREAM_POINTS", "gcode": "cam.job.gcode.STREAM_MOVES",
                         "drawing": "cam.job.drawing_stream.STREAM_TARGETS"}[kind], 0)
    streamed = cam.prepare_job(path, options)
    assert isinstance(streamed.toolpath, LevelledJob) and sum(1 for _ in streamed.toolpath.pieces()) >= 1
    a, b = held.toolpath, streamed.toolpath.joined()
    for name in ("points_steps", "kind", "target", "pause"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert held.plan_sha256 == streamed.plan_sha256 and held.report["level"] == streamed.report["level"]
    assert len(a) > held.report.get("points", 0)  # split at the spacing: more moves than the file's points


def _g1_ends_mm(lines: list[str]) -> np.ndarray:
    """``(K, 3)`` the X, Y, Z (mm) where each G1 line of a program ends (modal words carried)."""
    at, ends = {"X": 0.0, "Y": 0.0, "Z": 0.0}, []
    for line in lines:
        words = line.split()
        if not words or words[0] not in ("G0", "G1"):
            continue
        for w in words[1:]:
            if w[0] in at:
                at[w[0]] = float(w[1:])
        if words[0] == "G1":
            ends.append((at["X"], at["Y"], at["Z"]))
    return np.array(ends)


def test_export_writes_a_levelled_job_as_straight_xyz_moves_through_its_levelled_points(tmp_path):
    """``cam export --level``: a cutting move that changes X/Y and Z is one G1 X Y Z (the machine's straight move),
    not an X/Y move at the last depth and a Z step after it: every G1 in the material ends on a levelled point, and
    every levelled cut point is the end of a G1."""
    m = HeightMap([-10, 40, 100], [-10, 30, 80], [[0.0, 0.3, 0.1], [0.2, 0.5, 0.3], [0.1, 0.2, 0.4]],
                  reference_mm=0.2, spacing_mm=10)
    level = save_height_map(m, tmp_path / "map.json")
    (tmp_path / "iso.plt").write_text(HPGL)
    out = tmp_path / "iso.ngc"
    ok(run_cli("export", tmp_path / "iso.plt", "--level", level, "--arc-tolerance", "0", "-o", out))
    lines = out.read_text().splitlines()
    assert any(line.startswith("G1 X") and " Z" in line for line in lines)  # X, Y and Z together
    levelled = cam.prepare_job(tmp_path / "iso.plt", cam.JobOptions(level=str(level))).toolpath
    pts = levelled.points_steps
    want = np.column_stack([pts[:, 0] * MX, -pts[:, 1] * MY, -pts[:, 2] * MZ])  # as the program writes them
    ends = _g1_ends_mm(lines)
    ends = ends[ends[:, 2] < 0]  # in the material (below the work zero's surface)
    near = (np.abs(ends[:, None, :2] - want[None, :, :2]).max(axis=2) <= MX) & \
        (np.abs(ends[:, None, 2] - want[None, :, 2]) < 1e-4)
    assert near.any(axis=1).all(), ends[~near.any(axis=1)][:5]  # no corner at the last depth
    cuts = (levelled.kind == CUT) & (pts[:, 2] > 0)
    assert near[:, cuts].any(axis=0).all()  # every levelled cut point written


@pytest.mark.realtime
def test_a_levelled_job_stopped_and_resumed_cuts_as_its_uninterrupted_run(tmp_path):
    """A levelled job's journal names its levelled moves: stopped by the e-stop and resumed (``cam.resume_job``), the
    two runs cut what one levelled run cuts, step for step."""
    from cam.drive.journal import read_journal
    from cam.verify.pinlog import write_pin_log
    from test_resume import _check_union, estop_run

    from cam.settings import Travel

    fast = S.replace(ramp="constant", delay_xy_ms=0.05, delay_z_ms=0.05, travel=Travel(  # around the home: a resumed run starts at 0
        x_min_steps=-10**5, x_max_steps=10**5, y_min_steps=-10**5, y_max_steps=10**5, z_min_steps=-10**4,
        z_max_steps=10**4))
    m = HeightMap([-10, 40, 100], [-10, 30, 80], [[0.0, 0.3, 0.1], [0.2, 0.5, 0.3], [0.1, 0.2, 0.4]],
                  reference_mm=0.2, spacing_mm=10)
    (tmp_path / "iso.plt").write_text(HPGL)
    job = cam.prepare_job(tmp_path / "iso.plt", cam.JobOptions(level=str(save_height_map(m, tmp_path / "m.json"))),
                          fast)
    journal, first, second = tmp_path / "j.json", tmp_path / "run1.csv", tmp_path / "run2.csv"
    estop_run(job, journal, first, 0.4)
    record = read_journal(journal)
    assert record.plan_sha256 == job.plan_sha256  # the levelled moves' fingerprint
    resumed = cam.resume_job(job, record)
    write_pin_log(cam.run(resumed).pin_log(), second)
    _check_union("hpgl", tmp_path, job, first, second, record.position_steps)


@pytest.mark.realtime
def test_a_levelled_job_streams_to_grbl_through_its_levelled_points(tmp_path):
    """On a grbl board (its emulator) the levelled moves go as G-code lines: grbl executes lines whose ends are
    levelled points, and every levelled point lies on them, within the one step grbl's lines are joined by
    (PATH_TOLERANCE_STEPS)."""
    from cam.drive.grbl_machine import PATH_TOLERANCE_STEPS, close_grbl_machines, mpos_to_steps
    from cam.drive.session import MachineSession
    from cam.sim.grbl import start_emulator
    from test_grbl_session import FAST, _on_path

    m = HeightMap([-10, 40, 100], [-10, 30, 80], [[0.0, 0.3, 0.1], [0.2, 0.5, 0.3], [0.1, 0.2, 0.4]],
                  reference_mm=0.2, spacing_mm=10)
    (tmp_path / "iso.plt").write_text(HPGL)
    job = cam.prepare_job(tmp_path / "iso.plt", cam.JobOptions(level=str(save_height_map(m, tmp_path / "m.json"))))
    emu = start_emulator(speed=20.0, settings=FAST)
    try:
        session = MachineSession(f"grbl:{emu.device_path}", S, on_prompt=lambda prompt: "continue")
        session.start(job)
        assert session.wait_idle(120) and session.last_run["status"] == "finished", session.last_run
        blocks = [b for b in emu.executed() if b.kind in ("G0", "G1")]
        first = np.asarray(mpos_to_steps(blocks[0].start_mm, S), np.int64)
        ends = np.vstack([np.zeros((1, 3), np.int64),  # from the job's start, as its points
                          np.array([mpos_to_steps(b.end_mm, S) for b in blocks], np.int64) - first])
    finally:
        close_grbl_machines()
        emu.stop()
    pts = job.toolpath.points_steps
    assert _on_path(pts, ends, PATH_TOLERANCE_STEPS)
    assert np.isin(_keys(ends[1:]), _keys(np.vstack([pts, [[0, 0, 0]]]))).all()  # no point of its own


@pytest.mark.skipif(__import__("shutil").which("rs274") is None, reason="rs274 (linuxcnc-uspace) not installed")
@pytest.mark.parametrize("kind", ["hpgl", "excellon"])
def test_export_levels_every_move_rapids_included_as_the_machine_runs_it(kind, tmp_path):
    """``cam export --level`` (issue #46 point 2: every move, rapids included): the program run through LinuxCNC's
    ``rs274`` (an independent interpreter) moves, at every point of every move, G0 included, at the map's offset
    above the travel height or the cut depth within a Z step (the moves are split at the map's spacing; the map's
    twist leaves a straight move within a micrometre of the surface's offset), except where the tool's place is
    not the job's (the start, a tool change, the end): straight up or down to the clearance plane above the highest
    probed point, or across on it.  And the program passes, in order, through every point of the job ``cam drill
    --level`` runs (:func:`cam.prepare_job` with the same work zero), within a step in X/Y and exactly in Z (its
    last point, the return to its home's Z at the surface, at the travel height as every export's travels are)."""
    from cam.drive.state import read_state
    from support.lcnc import parse_canonical, run_rs274

    m = plane_map(a=0.15, bx=0.004, by=-0.003, cxy=2e-5, x=(-20, 60, 140), y=(-20, 50, 120), reference_mm=0.1)
    level = save_height_map(m, tmp_path / "map.json")
    state = tmp_path / "state.json"
    ok(run_cli("zero", "--at", "12,9,0", "--state", state))  # the work zero: machine X 12, Y 9 mm
    path = tmp_path / {"hpgl": "iso.plt", "excellon": "holes.drl"}[kind]
    path.write_text({"hpgl": HPGL, "excellon": DRILL}[kind])
    out = tmp_path / "levelled.ngc"
    ok(run_cli("export", path, "--level", level, "--state", state, "--arc-tolerance", "0", "-o", out))
    moves = parse_canonical(run_rs274(str(out)))
    assert moves and all(mv.kind in ("traverse", "feed") for mv in moves)
    prepared = cam.prepare_job(path, cam.JobOptions(level=str(level)), S, machine_state=read_state(state, S))
    home = np.asarray(prepared.levelled_home_steps, np.int64)
    assert tuple(home[:2]) != (0, 0)  # placed at the work zero: the machine frame is not the program's
    ends = np.array([(0.0, 0.0, 0.0)] + [mv.end for mv in moves])  # program mm; rs274 starts at 0, 0, 0
    rapid = np.array([False] + [mv.kind == "traverse" for mv in moves])

    def offset_mm(p: np.ndarray) -> np.ndarray:  # the map's offset under program points (X = x MX, Y = -y MY)
        return height_at(m, p[..., 0] + home[0] * MX, home[1] * MY - p[..., 1]) - m.reference_mm

    travel_mm = round(1.0 / MZ) * MZ  # the travel height (1 mm) and the depth, in whole Z steps
    depth_mm = round((0.5 if kind == "hpgl" else 2.0) / MZ) * MZ
    clear_mm = travel_mm + math.ceil(max(0.0, float(m.offsets_mm().max())) / MZ - 1e-9) * MZ
    high = np.abs(ends[:, 2] - clear_mm) < 1e-4  # on the clearance plane
    nominal = ends[:, 2] - offset_mm(ends)
    at_travel, at_depth = np.abs(nominal - travel_mm) <= MZ, np.abs(nominal + depth_mm) <= MZ
    assert np.all((at_travel | at_depth | high)[1:]), ends[1:][~(at_travel | at_depth | high)[1:]][:5]
    assert at_travel[1:][rapid[1:] & ~high[1:]].all() and rapid[1:][high[1:]].all()  # every G0: travel or clearance
    assert at_depth[~rapid].any() and (rapid & at_travel).sum() >= 10  # cuts and levelled rapids
    for i in range(1, len(ends)):  # along every move
        a, b = ends[i - 1], ends[i]
        if high[i] or high[i - 1]:  # to, from or on the clearance plane: straight up or down, or across on it
            assert np.allclose(a[:2], b[:2], atol=1e-4) or (high[i] and high[i - 1]), (i, a, b)
            continue
        if np.allclose(a[:2], b[:2], atol=1e-4):
            continue  # straight up or down over one point: a plunge, a retract
        t = np.linspace(0.0, 1.0, 41)[:, None]
        p = a + (b - a) * t
        level_along = p[:, 2] - offset_mm(p)
        want = travel_mm if at_travel[i] else -depth_mm
        assert (at_travel[i] == at_travel[i - 1]) and np.abs(level_along - want).max() <= MZ, (i, a, b)
    # the program and the job the machine runs: the same points in the same order
    toolpath = prepared.toolpath.joined() if hasattr(prepared.toolpath, "joined") else prepared.toolpath
    pts = toolpath.points_steps
    job_mm = np.column_stack([pts[:, 0] * MX, -pts[:, 1] * MY, -pts[:, 2] * MZ])
    # a travel at or above the surface (the job's return to its home's Z at the end) is written at the travel
    # height, as every export writes its travels (the job's own travels are at it already)
    off_steps = -offset_mm(job_mm) / MZ
    up = np.isin(toolpath.kind, (RETRACT, TRAVEL)) & (pts[:, 2] - off_steps <= 0.5)
    assert (np.abs(job_mm[up, 2] + np.rint(-round(1.0 / MZ) + off_steps[up]) * MZ) < 1e-9).sum() >= up.sum() - 1
    job_mm[up, 2] = -np.rint(-round(1.0 / MZ) + off_steps[up]) * MZ
    job_mm = job_mm[np.r_[True, np.any(np.abs(np.diff(job_mm, axis=0)) > 1e-9, axis=1)]]
    written = ends[1:][~high[1:]]
    written = written[np.r_[True, np.any(np.abs(np.diff(written, axis=0)) > 1e-9, axis=1)]]
    assert len(written) == len(job_mm), (len(written), len(job_mm))
    assert np.abs(written[:, :2] - job_mm[:, :2]).max() <= MX + 1e-4  # the source's exact X/Y: within a step
    assert np.abs(written[:, 2] - job_mm[:, 2]).max() < 1e-4  # Z: the machine's levelled steps
    print(f"\n{kind}: {len(moves)} moves ({int(rapid.sum())} G0, {int((rapid & at_travel & ~high).sum())} of them "
          f"levelled travels), every one at the map's offset within a step; {len(job_mm)} job points matched")
