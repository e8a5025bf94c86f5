import numpy as np
import pytest

import cam
from cam.motion.steps import plan_steps
from cam.settings import DEFAULT_SETTINGS

from conftest import SAMPLES

# the thesis's timing (Eq. 4.4): constant delays, no speed ramps (ramps: tests/test_ramps.py)
CONSTANT = DEFAULT_SETTINGS.replace(ramp="constant")


def job_px(points_px, settings=DEFAULT_SETTINGS):
    """A job through drawing-pixel points (scaled to machine steps by the settings)."""
    pts = np.asarray(points_px, np.int64).reshape(-1, 3)
    scale = np.array([settings.steps_per_px_xy, settings.steps_per_px_xy, settings.steps_per_px_z])
    n = len(pts)
    return cam.Job(points_steps=pts * scale, kind=np.zeros(n, np.uint8), target=np.zeros(n, bool),
                   pause=np.zeros(n, bool), settings=settings)


def one_move(x, y, z=0, settings=CONSTANT):
    return plan_steps(job_px([[x, y, z]], settings))


def test_diagonal_pixel_move_steps_x_and_y_together():
    p = one_move(1, 1)
    # pins: X clock 6 / dir 7 -> bits 4/5 (16/32); Y clock 4 / dir 5 -> bits 2/3 (4/8)
    assert p.data[:5].tolist() == [40, 60, 40, 60, 40]
    assert p.t_ns[:5].tolist() == [0, 2_500_000, 5_000_000, 7_500_000, 10_000_000]
    assert len(p) == 1 + 2 * 8
    assert p.t_ns[-1] == 8 * 5_000_000  # Eq 4.4: max(dx, dy) * steps/pixel * delay
    assert p.steps_total.tolist() == [8, 8, 0]
    assert set(p.strobe.tolist()) == {0}  # Half/Full* held low: full steps


def test_eq_4_4_time_is_max_of_axes():
    p = one_move(3, 1)
    assert p.estimated_time_s == 3 * 8 * 0.005
    motion = cam.decode_pin_log(cam.PinLog(p.t_ns, p.data, p.strobe))
    assert motion.final_steps == (24, 8, 0)
    # Y steps are spread over the move, never two Y steps in one period
    y = motion.position_steps[:, 1]
    assert np.all(np.diff(y) >= 0) and np.all(np.diff(y) <= 1)


def test_z_only_move_uses_z_delay_and_direction():
    s = CONSTANT.replace(delay_z_ms=2.0)
    p = one_move(0, 0, 3, settings=s)
    assert p.t_ns[-1] == 3 * 2_000_000
    # Z clock pin 2 -> bit 0, Z dir pin 3 -> bit 1 (+Z = deeper = set)
    assert p.data[:3].tolist() == [2, 3, 2]


def test_negative_direction_clears_dir_bit():
    job = job_px([[2, 0, 0], [1, 0, 0]])
    p = plan_steps(job)
    motion = cam.decode_pin_log(cam.PinLog(p.t_ns, p.data, p.strobe))
    assert motion.final_steps == (8, 0, 0)
    i = 2 * 16  # write that ends the first move: direction already set for the next, -X
    assert p.data[i] & 32 == 0 and p.data[i - 1] & 32 == 32


def test_custom_pin_map_is_used_by_plan_and_decoder():
    from cam.settings import Pins
    s = DEFAULT_SETTINGS.replace(pins=Pins(clock_x=9, dir_x=8, clock_y=7, dir_y=6, clock_z=5, dir_z=4))
    p = one_move(1, 0, settings=s)
    assert p.data[1] == (1 << 7) | (1 << 6)  # clock X on pin 9, dir X on pin 8
    assert cam.decode_pin_log(cam.PinLog(p.t_ns, p.data, p.strobe), s).final_steps == (8, 0, 0)


def test_compiled_step_kernel_equals_the_vectorised_reference():
    from support.references import port_writes

    rng = np.random.default_rng(3)
    pts = np.abs(np.cumsum(rng.integers(-3, 4, size=(300, 3)), axis=0)) + 5
    job = job_px(pts)
    plan = plan_steps(job)
    # reference: DDA per move in numpy, then port_writes
    s = job.settings
    steps = np.vstack([[0, 0, 0], job.points_steps])
    signed, periods = [], []
    for a, b in zip(steps[:-1], steps[1:]):
        d = b - a
        n = int(np.abs(d).max())
        if n == 0:
            continue
        k = np.arange(1, n + 1)[:, None]
        stepped = (k * np.abs(d)) // n - ((k - 1) * np.abs(d)) // n
        signed.append(stepped * np.sign(d))
        xy, z = bool(np.any(d[:2])), bool(d[2])
        per = max(s.delay_xy_ns, s.delay_z_ns) if xy and z else (s.delay_xy_ns if xy else s.delay_z_ns)
        periods.append(np.full(n, per))
    t, data, strobe = port_writes(np.vstack(signed), np.concatenate(periods), s)
    assert np.array_equal(t, plan.t_ns) and np.array_equal(data, plan.data)


def test_run_cursor_and_chunked_extent_equal_the_full_decode(monkeypatch):
    """The web page's live position (the runner's cursor, moved on batch by batch) and a job's extent come from
    bounded-memory decoders: same answers."""
    import cam.verify.pinlog as pinlog
    from cam.drive.runner import Cursor
    from cam.verify.pinlog import PinLog, decode_pin_log, motion_extent

    d = cam.digitize(cam.load_image(SAMPLES / "gear.png"))
    job = cam.plan(d, depth=[12, 4])
    plan = cam.plan_steps(job)
    full = decode_pin_log(PinLog(plan.t_ns, plan.data, plan.strobe), job.settings).position_steps
    monkeypatch.setattr(pinlog, "_CHUNK", 1000)  # many chunk borders
    cursor = Cursor(job.settings)
    for n in (0, 1, 5, 999, 1000, 1001, 5000, len(plan)):
        cursor.note(plan.t_ns[cursor.sent:n], plan.data[cursor.sent:n])
        assert cursor.live == (n, tuple(int(v) for v in full[n - 1]) if n else (0, 0, 0))
    extent, cut = motion_extent(plan.data, job.settings)
    with_start = np.vstack([np.zeros((1, 3), np.int64), full])
    assert extent[:, 0].tolist() == with_start.min(axis=0).tolist()
    assert extent[:, 1].tolist() == with_start.max(axis=0).tolist()
    below = full[full[:, 2] > 0]
    assert cut[:, 0].tolist() == below.min(axis=0).tolist() and cut[:, 1].tolist() == below.max(axis=0).tolist()



@pytest.mark.parametrize("batch", [16384, 7])
def test_the_position_at_each_pause_is_the_decoded_one(monkeypatch, tmp_path, batch):
    """The send loop counts a chunk's steps once up to each pause in it (not batch by batch): the position each
    pause is told, and the run's end, are those decoded from the pin log, with pauses at chunk borders and inside
    chunks, and with batches that end between pauses (a small ``_BATCH``)."""
    from cam.drive import runner
    from cam.motion.chunks import plan_chunks
    from cam.formats.hpgl import load_hpgl
    from cam.job.hpgl import plan_hpgl

    monkeypatch.setattr(runner, "_BATCH", batch)
    (tmp_path / "pens.plt").write_text("IN;" + "".join(f"SP{1 + i % 2};PU{40 * i},0;PD{40 * i},{200 + 40 * i};"
                                                       for i in range(12)) + "PU0,0;")
    job = plan_hpgl(load_hpgl(tmp_path / "pens.plt"))
    assert len(job.pause_notes) == 12
    plan = plan_chunks(job, chunk_periods=50)
    seen = []
    counted = []
    counts = runner.Cursor.counts
    monkeypatch.setattr(runner.Cursor, "counts", lambda self, data, ends: counted.append(len(ends)) or
                        counts(self, data, ends))
    result = runner.run(plan, cam.MockPort(), on_pause=lambda pos, note: seen.append(pos))
    if batch > 2 * 50 + 1:  # longer than a chunk: every batch ends at a pause or a chunk's end, one count a chunk
        assert len(counted) == sum(1 for _ in plan.chunks()) and sum(counted) == len(counted) + 12
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    pause_writes = np.asarray(plan.pause_writes, np.int64)
    assert len(seen) == len(pause_writes) == 12
    assert seen == [tuple(int(v) for v in motion.position_steps[w]) for w in pause_writes]
    assert result.position_steps == motion.final_steps
