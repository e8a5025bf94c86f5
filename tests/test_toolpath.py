import numpy as np
import pytest

import cam
from cam.job.model import CUT, RETRACT, TRAVEL
from cam.digitize.profile import as_profile

from conftest import drawing_from_rows

TWO = drawing_from_rows(["......", ".##...", "......", "...##.", "......"])


def test_literal_path_depth_sorted_with_retracts():
    d = cam.digitize(TWO)
    job = cam.plan(d, depth=[2, 1])
    assert job.points_px().tolist() == [
        [3, 3, 0], [3, 3, 1], [4, 3, 1], [4, 3, 0], [1, 1, 0], [1, 1, 2], [2, 1, 2], [2, 1, 0], [0, 0, 0],
    ]
    assert job.kind.tolist() == [TRAVEL, CUT, CUT, RETRACT, TRAVEL, CUT, CUT, RETRACT, TRAVEL]
    assert job.target.tolist() == [False, True, True, False, False, True, True, False, False]
    assert job.n_retracts == 2


def test_every_move_is_xy_or_z_and_non_adjacent_moves_happen_at_the_surface():
    d = cam.digitize(TWO)
    job = cam.plan(d, depth=3, passes=3)
    pts = np.vstack([[0, 0, 0], job.points_px()])
    delta = np.diff(pts, axis=0)
    assert not np.any(np.any(delta[:, :2] != 0, axis=1) & (delta[:, 2] != 0))
    far = np.abs(delta[:, :2]).max(axis=1) > 1
    assert np.all(pts[1:][far, 2] == 0) and np.all(pts[:-1][far, 2] == 0)


def test_depth_list_too_short_states_both_counts():
    d = cam.digitize(TWO)
    with pytest.raises(cam.PlanError, match="1 depth value.*2 objects"):
        cam.plan(d, depth=[3])


def test_depth_sort_is_stable_and_shallowest_first():
    img = drawing_from_rows(["........", ".##.##..", "........", ".##.....", "........"])
    d = cam.digitize(img)
    job = cam.plan(d, depth=[5, 2, 5])
    cuts = job.points_px()[job.target]
    assert cuts[:, 2].tolist() == [2, 2, 5, 5, 5, 5]
    assert cuts[:, :2].tolist() == [[4, 1], [5, 1], [1, 1], [2, 1], [1, 3], [2, 3]]


def test_repeat_drill_passes_go_deeper():
    d = cam.digitize(drawing_from_rows([".....", ".###.", "....."]))
    job = cam.plan(d, depth=5, passes=3)
    cuts = job.points_px()[job.target]
    assert cuts[:, 2].tolist() == [2] * 3 + [4] * 3 + [5] * 3


def test_no_twenty_object_limit():
    img = np.full((5, 100), 255, np.uint8)
    img[2, 2:98:3] = 0  # 32 single dots
    d = cam.digitize(img)
    assert len(d.objects) == 32
    job = cam.plan(d, depth=list(range(1, 33)))
    assert job.n_targets == 32


def test_start_at_offsets_everything():
    d = cam.digitize(TWO)
    base = cam.plan(d, depth=2)
    moved = cam.plan(d, depth=2, start_at=(10, 20, 3))
    assert np.array_equal(moved.points_px()[moved.target], base.points_px()[base.target] + [10, 20, 3])
    assert moved.points_px()[-1].tolist() == [0, 0, 0]


def test_pause_at_marks_the_point_and_warns_for_unknown():
    d = cam.digitize(TWO)
    job = cam.plan(d, depth=2, pause_at=[(2, 1), (5, 4)])
    assert job.points_px()[job.pause].tolist() == [[2, 1, 2]]
    assert any("(5, 4)" in w for w in job.warnings)


def test_travel_limit_refused_naming_first_point():
    d = cam.digitize(TWO)
    small = cam.MachineSettings().replace(travel=cam.settings.Travel(x_max_steps=20))
    with pytest.raises(cam.TravelError, match=r"point 4 \(x=3, y=3, z=0 px = 24, 24, 0 steps\): X travel is 0..20"):
        cam.plan(d, depth=2, settings=small)
    with pytest.raises(cam.TravelError, match="Z travel"):
        cam.plan(d, depth=5000)


def test_goto_moves_xy_first_then_z():
    job = cam.goto((4, 5, 2))
    assert job.points_steps.tolist() == [[32, 40, 0], [32, 40, 2]]  # pixels x 8 steps X/Y, x 1 step Z
    result = cam.run(job)
    assert result.position_steps == (32, 40, 2)


@pytest.mark.parametrize("name", ["gear.png", "word.png", "heart.png", "dumbbell.png", "ring.png"])
def test_fast_assembly_equals_the_reference_loop(name):
    from cam.job.drawing import _assemble
    from support.references import assemble_reference as _assemble_reference
    from conftest import SAMPLES

    d = cam.digitize(cam.load_image(SAMPLES / name))
    kw = dict(profile=lambda k: 1 + k % 7) if d.mode == "3d" else dict(depth=[3 + i for i in range(len(d.objects))])
    job = cam.plan(d, passes=2, start_at=(2, 3, 1), pause_at=[tuple(d.objects[0][3])], **kw)
    targets = job.points_px()[job.target]
    assert job.pause.sum() >= 1
    asked = np.zeros((d.height_px + 5, d.width_px + 4), np.int64)
    np.maximum.at(asked, (targets[:, 1], targets[:, 0]), targets[:, 2] - 1)
    pause_px = np.zeros(asked.shape, bool)
    pause_px[job.points_px()[job.pause][:, 1], job.points_px()[job.pause][:, 0]] = True
    # rebuild the depth-sorted target list the planner used (with duplicates) from the digitized matrix
    from cam.job.drawing import _pass_targets
    depth = as_profile(kw["profile"], d.n_layers).depth_of(d.levels) if d.mode == "3d" else np.array(kw["depth"])
    t = _pass_targets(d, np.asarray(depth, np.int64), 2)
    t = t + [2, 3, 1]
    a = _assemble(t, pause_px, asked, job.settings, 1, 0, 1)
    b = _assemble_reference(t, pause_px, asked, job.settings, 1, 0, 1)
    for u, v in zip(a, b):
        assert np.array_equal(u, v)
    # the same targets assembled in pieces (each going on after the one before) give the same rows
    cuts = [0, 1, 2, 57, 58, len(t) // 2, len(t) - 1, len(t)]
    parts = [_assemble(t[i:j], pause_px, asked, job.settings, 1, 0, 1, after=t[i - 1] if i else None,
                       last=j == len(t)) for i, j in zip(cuts, cuts[1:])]
    for k, whole in enumerate(a):
        assert np.array_equal(np.concatenate([part[k] for part in parts]), whole)


@pytest.mark.parametrize("start_at", [(-67, -6, 0), (-200, -100, 0), (0, 0, 0), (37, 5, 0), (500, 300, 2)])
def test_every_start_at_inside_the_travel_cuts_exactly_the_moved_drawing(start_at):
    """Start At works in machine coordinates: negative, zero and large offsets cut the drawing moved by them."""
    from conftest import SAMPLES, assert_surface_equal, carve_job, expected_surface_2d

    s = cam.MachineSettings().replace(
        travel=cam.settings.Travel(x_min_steps=-20000, x_max_steps=20000, y_min_steps=-20000, y_max_steps=20000))
    d = cam.digitize(cam.load_image(SAMPLES / "two_curves.png"))
    job = cam.plan(d, depth=3, settings=s, start_at=start_at)
    surface, _, _ = carve_job(job)
    assert_surface_equal(surface, expected_surface_2d(d, [3] * len(d.objects), s))


@pytest.mark.parametrize("start_at", [(0, -1000, 0), (100_000_000, 0, 0), (-5, 0, 0)])
def test_a_start_at_outside_the_travel_is_refused(start_at):
    """A drawing job is planned in its own frame (issue #45 point 4): a Start At that makes it wider than the travel
    (its home included) is refused when it is planned; one that fits the travel's span is planned, and refused
    before a step where it runs (from the home here)."""
    d = cam.digitize(drawing_from_rows(["....", ".##.", "...."]))
    if start_at[0] > 10_000:
        with pytest.raises(cam.TravelError, match="travel .*wherever it is placed"):
            cam.plan(d, depth=2, start_at=start_at)
        return
    job = cam.plan(d, depth=2, start_at=start_at)
    with pytest.raises(cam.TravelError, match="leaves the machine travel"):
        cam.plan_steps(job)
    with pytest.raises(cam.TravelError, match="travel"):
        cam.run(job)
