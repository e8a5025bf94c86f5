"""Drill order: valid, short open paths from the tool's position (no timing asserted here)."""
from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest

from cam.job.drill import _machine_mm, plan_drill
from cam.job.drill_order import EXACT_MAX, drill_order, nearest_neighbour_order, tour_length_mm
from cam.errors import CamError, PlanError


def uniform(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform((0, 0), (100, 80), (n, 2))


def clustered(n: int, seed: int) -> np.ndarray:
    """Holes in tight groups (IC footprints, connectors): many near-ties and long jumps between groups."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform((0, 0), (100, 80), (max(1, n // 25), 2))
    pts = centres[rng.integers(0, len(centres), n)] + rng.normal(0, 0.8, (n, 2))
    return pts


def with_duplicates(n: int, seed: int) -> np.ndarray:
    """A board exported twice over: every hole appears two or three times."""
    pts = uniform(n // 2, seed)
    rng = np.random.default_rng(seed + 1)
    return np.vstack([pts, pts, pts[rng.integers(0, len(pts), n - 2 * len(pts))]])


def ic_grid() -> np.ndarray:
    """Rows of DIP pins at 2.54 mm pitch: exact ties everywhere."""
    xs, ys = np.meshgrid(np.arange(20) * 2.54, np.arange(6) * 7.62)
    return np.column_stack([xs.ravel() + 10, ys.ravel() + 5])


def brute_force_nn(pts: np.ndarray, start) -> list[int]:
    left = list(range(len(pts)))
    cur = np.asarray(start, float)
    out = []
    while left:
        d2 = [(pts[i, 0] - cur[0]) * (pts[i, 0] - cur[0]) + (pts[i, 1] - cur[1]) * (pts[i, 1] - cur[1]) for i in left]
        j = left[int(np.argmin(d2))]  # argmin: first of equal values = lowest index
        out.append(j)
        left.remove(j)
        cur = pts[j]
    return out


def brute_force_best(pts: np.ndarray, start) -> float:
    return min(tour_length_mm(pts, np.array(p), start) for p in itertools.permutations(range(len(pts))))


def is_permutation(order: np.ndarray, n: int) -> bool:
    return order.dtype == np.int64 and order.shape == (n,) and sorted(order.tolist()) == list(range(n))


SETS = {
    "uniform 13": (uniform(13, 1), (0.0, 0.0)),
    "uniform 60": (uniform(60, 2), (50.0, 40.0)),
    "uniform 700": (uniform(700, 3), (0.0, 0.0)),
    "clustered 400": (clustered(400, 4), (0.0, 80.0)),
    "duplicates 300": (with_duplicates(300, 5), (100.0, 0.0)),
    "IC grid": (ic_grid(), (0.0, 0.0)),
    "one line": (np.column_stack([np.random.default_rng(6).permutation(200) * 0.5, np.zeros(200)]), (30.0, 0.0)),
    "all the same point": (np.full((40, 2), 7.5), (0.0, 0.0)),
    "far start": (uniform(200, 7), (-3000.0, 5000.0)),
}


@pytest.mark.parametrize("name", list(SETS))
def test_tour_is_a_permutation_no_longer_than_nearest_neighbour(name):
    pts, start = SETS[name]
    order = drill_order(pts, start_mm=start)
    assert is_permutation(order, len(pts))
    nn = nearest_neighbour_order(pts, start_mm=start)
    assert is_permutation(nn, len(pts))
    assert tour_length_mm(pts, order, start) <= tour_length_mm(pts, nn, start) + 1e-9
    assert np.array_equal(order, drill_order(pts.copy(), start_mm=start))  # deterministic


@pytest.mark.parametrize("name", ["uniform 700", "clustered 400", "duplicates 300"])
def test_tour_is_much_shorter_than_nearest_neighbour(name):
    """Nearest neighbour is typically ~25 % above the optimum; the local search must remove most of it."""
    pts, start = SETS[name]
    ratio = tour_length_mm(pts, drill_order(pts, start), start) / tour_length_mm(
        pts, nearest_neighbour_order(pts, start), start)
    assert ratio < 0.92, ratio


def test_tour_is_2opt_optimal_on_a_random_board():
    """No pair of path edges can be exchanged (segment reversed) to shorten the path; the end is free."""
    pts, start = uniform(150, 11), (0.0, 0.0)
    order = drill_order(pts, start)
    path = np.vstack([start, pts[order]])
    n = len(path)
    edge = np.hypot(*np.diff(path, axis=0).T)  # edge i joins path[i] and path[i + 1]
    d = np.hypot(*(path[:, None, :] - path[None, :, :]).transpose(2, 0, 1))
    i, j = np.triu_indices(n, 1)  # reverse path[i+1 .. j], 0 <= i < j < n
    after = np.where(j + 1 < n, d[i + 1, np.minimum(j + 1, n - 1)], 0.0)
    before = np.where(j + 1 < n, edge[np.minimum(j, n - 2)], 0.0)
    gain = edge[i] + before - d[i, j] - after
    assert gain.max() < 1e-9


@pytest.mark.parametrize("n", [0, 1, 2, 3, 5, 7])
def test_small_sets_are_optimal(n):
    rng = np.random.default_rng(100 + n)
    pts = rng.uniform(0, 20, (n, 2))
    start = (10.0, -3.0)
    order = drill_order(pts, start)
    assert is_permutation(order, n)
    if n:
        assert tour_length_mm(pts, order, start) == pytest.approx(brute_force_best(pts, start))


def test_exact_and_heuristic_sizes_meet():
    """Just above the exact limit the heuristic still finds the optimum of an easy set: holes on a line."""
    for n in (EXACT_MAX, EXACT_MAX + 1, EXACT_MAX + 7):
        pts = np.column_stack([np.random.default_rng(n).permutation(n) * 1.0, np.zeros(n)])
        order = drill_order(pts, (-1.0, 0.0))
        assert pts[order, 0].tolist() == sorted(pts[:, 0].tolist())


def test_two_points_and_duplicates():
    pts = np.array([[10.0, 0.0], [1.0, 0.0]])
    assert drill_order(pts, (0.0, 0.0)).tolist() == [1, 0]
    assert drill_order(pts, (12.0, 0.0)).tolist() == [0, 1]
    same = np.array([[2.0, 2.0]] * 3)
    assert sorted(drill_order(same, (0.0, 0.0)).tolist()) == [0, 1, 2]
    assert tour_length_mm(same, drill_order(same, (0.0, 0.0)), (0.0, 0.0)) == pytest.approx(np.hypot(2, 2))


@pytest.mark.parametrize("start", [(0.0, 0.0), (100.0, 80.0), (50.0, 40.0), (-20.0, 30.0)])
def test_path_starts_near_the_tool(start):
    pts = uniform(500, 12)
    order = drill_order(pts, start)
    dist = np.hypot(*(pts - np.asarray(start)).T)
    rank = int((dist < dist[order[0]]).sum())  # how many holes are nearer to the tool than the first one
    assert rank < 10
    assert dist[order[0]] < dist.min() + 5.0  # mean hole spacing here is about 4 mm


def test_nearest_neighbour_is_exact():
    for pts, start in [(uniform(300, 20), (0.0, 0.0)), (with_duplicates(120, 21), (5.0, 5.0)),
                       (ic_grid(), (0.0, 0.0)), (clustered(200, 22), (100.0, 80.0))]:
        assert nearest_neighbour_order(pts, start).tolist() == brute_force_nn(pts, start)


def test_tour_length_literal():
    pts = np.array([[3.0, 4.0], [3.0, 0.0]])
    assert tour_length_mm(pts, np.array([0, 1]), (0.0, 0.0)) == pytest.approx(9.0)
    assert tour_length_mm(pts, np.array([1, 0]), (0.0, 0.0)) == pytest.approx(7.0)
    assert tour_length_mm(pts, np.zeros(0, np.int64), (1.0, 1.0)) == 0.0


@pytest.mark.parametrize("bad", [np.zeros((4, 3)), np.array([[0.0, np.nan], [1.0, 1.0]]), np.zeros(4)])
def test_bad_points_raise_plan_error(bad):
    with pytest.raises(PlanError):
        drill_order(bad)
    assert issubclass(PlanError, CamError)


def fake_holes(pts_mm: np.ndarray, tool_of_hole: np.ndarray, tools: dict[int, float]) -> SimpleNamespace:
    """The parts of an Excellon hole list that plan_drill reads (board frame, mm)."""
    return SimpleNamespace(holes_mm=pts_mm, tool_of_hole=tool_of_hole, tools=tools, source="board.drl", warnings=[])


def test_plan_drill_drills_each_tool_in_tour_order():
    rng = np.random.default_rng(30)
    pts = rng.uniform((0, 0), (100, 80), (600, 2))
    tool_of_hole = rng.choice([1, 2, 3], size=600, p=[0.6, 0.3, 0.1])
    holes = fake_holes(pts, tool_of_hole, {1: 0.8, 2: 1.0, 3: 3.2})
    plan = plan_drill(holes)
    machine_mm = _machine_mm(pts, None, False)
    assert sorted(plan.hole_index.tolist()) == list(range(600))
    cur = (0.0, 0.0)
    at = 0
    for k, (tool, _dia, count) in enumerate(plan.tool_sequence):
        idx = np.flatnonzero(tool_of_hole == tool)
        assert count == len(idx)
        got = plan.hole_index[at:at + count]
        end = (0.0, 0.0) if k == len(plan.tool_sequence) - 1 else None  # the last tool: back home after it
        assert got.tolist() == idx[drill_order(machine_mm[idx], start_mm=cur, end_mm=end)].tolist()
        # the tour is shorter than drilling in file order or in nearest-neighbour order from the same place
        tour = tour_length_mm(machine_mm, got, cur, end)
        assert tour < tour_length_mm(machine_mm, idx, cur, end)
        assert tour <= tour_length_mm(machine_mm, idx[nearest_neighbour_order(machine_mm[idx], cur)], cur, end)
        cur = tuple(machine_mm[got[-1]])
        at += count


def test_plan_drill_tour_moves_less_than_file_order():
    rng = np.random.default_rng(31)
    pts = rng.uniform((0, 0), (60, 40), (200, 2))
    holes = fake_holes(pts, np.ones(200, np.int64), {1: 0.8})

    def xy_travel_steps(plan):
        xy = plan.toolpath.points_steps[:, :2].astype(float)
        return np.hypot(*np.diff(xy, axis=0).T).sum()

    tour, file_order = plan_drill(holes), plan_drill(holes, drill_order="file")
    assert file_order.hole_index.tolist() == list(range(200))
    assert xy_travel_steps(tour) < 0.5 * xy_travel_steps(file_order)


def test_copies_of_a_hole_are_drilled_one_after_another():
    pts, start = SETS["duplicates 300"]
    order = drill_order(pts, start)
    seq = [tuple(p) for p in pts[order]]
    runs = [k for i, k in enumerate(seq) if i == 0 or seq[i - 1] != k]
    assert len(runs) == len(set(seq))  # each distinct place appears in one run


# ---------------------------------------------------------------- closed tours (back to the start)


def brute_force_closed(pts: np.ndarray, start) -> float:
    return min(tour_length_mm(pts, np.array(p), start, start) for p in itertools.permutations(range(len(pts))))


@pytest.mark.parametrize("name", list(SETS))
def test_closed_tour_no_longer_than_open_path_plus_return_nor_nearest_neighbour(name):
    pts, start = SETS[name]
    closed = drill_order(pts, start_mm=start, end_mm=start)
    assert is_permutation(closed, len(pts))
    length = tour_length_mm(pts, closed, start, start)
    open_path = drill_order(pts, start_mm=start)
    nn = nearest_neighbour_order(pts, start_mm=start)
    assert length <= tour_length_mm(pts, open_path, start, start) + 1e-9
    assert length <= tour_length_mm(pts, nn, start, start) + 1e-9


@pytest.mark.parametrize("n", [2, 3, 5, pytest.param(8, marks=pytest.mark.slow)])
def test_small_closed_tours_are_optimal(n):
    rng = np.random.default_rng(40 + n)
    pts = rng.uniform(0, 50, (n, 2))
    start = (3.0, 47.0)
    order = drill_order(pts, start_mm=start, end_mm=start)
    assert tour_length_mm(pts, order, start, start) == pytest.approx(brute_force_closed(pts, start))


def test_path_to_another_end_point():
    pts = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]] + [[x, 5.0] for x in range(20)])
    end = (0.0, 5.0)
    order = drill_order(pts, start_mm=(0.0, 0.0), end_mm=end)
    assert is_permutation(order, len(pts))
    assert tour_length_mm(pts, order, (0.0, 0.0), end) <= tour_length_mm(
        pts, drill_order(pts, start_mm=(0.0, 0.0)), (0.0, 0.0), end) + 1e-9


def test_closed_tour_length_literal():
    pts = np.array([[3.0, 4.0]])
    assert tour_length_mm(pts, np.array([0]), (0.0, 0.0), (0.0, 0.0)) == 10.0


def test_plan_drill_last_tool_tour_returns_home():
    """The job's whole travel (home, every tool, home) is no longer than with an open last path."""
    rng = np.random.default_rng(11)
    holes_mm = rng.uniform((0, 0), (60, 40), (300, 2))
    tool_of = (np.arange(300) % 2).astype(np.int64)
    holes = fake_holes(holes_mm, tool_of, {0: 0.8, 1: 1.0})
    plan = plan_drill(holes)
    xy = _machine_mm(holes_mm, None, False)
    order = plan.hole_index
    second = order[150:]
    assert set(tool_of[second].tolist()) == {1}
    open_second = second[drill_order(xy[second], start_mm=tuple(xy[order[149]]))]
    closed_len = tour_length_mm(xy[second], np.arange(150), tuple(xy[order[149]]), (0.0, 0.0))
    assert closed_len <= tour_length_mm(xy[open_second], np.arange(150), tuple(xy[order[149]]), (0.0, 0.0)) + 1e-9
