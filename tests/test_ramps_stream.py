"""The ramp checker a piece of the pin log at a time (a log of any length) gives the whole log's report."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import cam
from cam.motion.chunks import plan_chunks
from cam.verify.pinlog import PinLog, write_pin_log
from cam.verify.ramps import check_ramps
from conftest import SAMPLES

S = cam.MachineSettings()  # look-ahead ramps


def _pieces(log: PinLog, cuts: list[int]):
    bounds = [0, *sorted(set(c for c in cuts if 0 < c < len(log))), len(log)]
    for a, b in zip(bounds, bounds[1:]):
        yield PinLog(log.t_ns[a:b], log.data[a:b], log.strobe[a:b])


def _same(a, b):
    assert (a.ok, a.counts, a.steps, a.pairs) == (b.ok, b.counts, b.steps, b.pairs)
    assert a.max_speed_mm_s == pytest.approx(b.max_speed_mm_s, rel=1e-12)
    assert [(v.rule, v.axis, v.t_s, v.excess_mm_s) for v in a.worst] == \
        [(v.rule, v.axis, v.t_s, v.excess_mm_s) for v in b.worst]


def _logs():
    """A drawing job with Pause At points (look-ahead ramps: passes) and the same job with constant periods too
    fast to start at (breaks R1..R3), and one whose step times were jittered (breaks R2 here and there)."""
    d = cam.digitize(cam.load_image(SAMPLES / "gear.png"))
    job = cam.plan(d, depth=4, settings=S, pause_at=[tuple(d.objects[0][9]), tuple(d.objects[0][40])])
    plan = cam.plan_steps(job)
    good = cam.run(plan).pin_log()
    fast = S.replace(ramp="constant", delay_xy_ms=0.05, delay_z_ms=0.05)
    bad = cam.run(cam.plan_steps(dataclasses.replace(job, settings=fast))).pin_log()
    rng = np.random.default_rng(3)
    gap = int(np.diff(good.t_ns).min())
    jitter = good.t_ns + rng.integers(0, max(1, gap // 2), len(good))  # still increasing
    return [("good", good, plan.pause_writes), ("too fast", bad, plan.pause_writes),
            ("jittered", PinLog(jitter, good.data, good.strobe), plan.pause_writes)]


@pytest.mark.parametrize("case", range(3))
def test_pieces_give_the_whole_logs_report(case):
    name, log, pauses = _logs()[case]
    whole = check_ramps(log, S, pause_writes=pauses)
    assert whole.ok == (name == "good") and sum(whole.steps) > 1000
    rng = np.random.default_rng(case)
    for cuts in ([1], [2, 3, 4, 5, 6, 7], list(range(0, len(log), 997)), rng.integers(0, len(log), 60).tolist(),
                 list(range(0, 400, 1)) + [len(log) - 1]):
        _same(check_ramps(_pieces(log, cuts), S, pause_writes=pauses), whole)


def test_a_pin_log_file_is_checked_a_piece_at_a_time(tmp_path, monkeypatch):
    """check_ramps(path) reads the file in pieces (here of 500 writes) and reports as for the whole log."""
    import cam.verify.pinlog as pinlog
    name, log, pauses = _logs()[2]
    write_pin_log(log, tmp_path / "log.csv")
    read = []
    real = pinlog.iter_pin_log
    monkeypatch.setattr(cam.verify.ramps, "iter_pin_log", lambda p: (read.append(len(x)) or x for x in real(p, 500)))
    _same(check_ramps(tmp_path / "log.csv", S, pause_writes=pauses), check_ramps(log, S, pause_writes=pauses))
    assert max(read) == 500 and sum(read) == len(log)


def test_a_chunked_plans_chunks_pass_the_checker():
    """The chunks of a ChunkedPlan, checked as they are made (nothing whole), pass: look-ahead across chunk
    boundaries keeps every ramp (a job with boundaries inside ramps)."""
    d = cam.digitize(cam.load_image(SAMPLES / "ellipse.png"))
    job = cam.plan(d, depth=5, settings=S)
    chunked = plan_chunks(job, chunk_periods=300)
    report = check_ramps((PinLog(c.t_ns, c.data, c.strobe) for c in chunked.chunks()), S,
                         pause_writes=chunked.pause_writes)
    assert report.ok, report.summary()
    assert sum(report.steps) == int(np.sum(chunked.steps_total))


def test_broken_logs_are_reported_or_refused_in_one_line():
    """Two steps of one axis at one time break R1 (not a division by zero); time going back is refused."""
    from cam.errors import CamError
    clock = int(cam.pins.axis_bits(S)[0][0])
    t = np.array([0, 10_000_000, 10_000_000, 10_000_000, 20_000_000, 30_000_000, 40_000_000], np.int64)
    data = np.array([0, clock, 0, clock, 0, clock, 0], np.uint8)
    report = check_ramps(PinLog(t, data, np.zeros(len(t), np.uint8)), S)
    assert not report.ok and report.counts["R1 top speed"] >= 1
    back = PinLog(np.array([0, 5, 3], np.int64), np.zeros(3, np.uint8), np.zeros(3, np.uint8))
    with pytest.raises(CamError, match="write 2 at 3 ns is earlier"):
        check_ramps(_pieces(back, [1]), S)
