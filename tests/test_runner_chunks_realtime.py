"""A chunked plan runs in real time a chunk at a time (the next made by a thread meanwhile), never as a whole plan:
the same writes as the whole plan, every interval at least the planned one, pauses and stops as a whole plan's."""
from __future__ import annotations

import numpy as np
import pytest

import cam
import cam.kinds.jobs as jobs
from cam.motion.chunks import ChunkedPlan, plan_chunks
from cam.drive.runner import FINISHED, STOPPED, Controller, Cursor, run
from cam.drive.session import MachineSession
from cam.kinds.jobs import JobOptions, prepare_job
from conftest import drawing_from_rows
from test_runner_stall import StallingPort

FAST = cam.MachineSettings().replace(delay_xy_ms=0.3, delay_z_ms=0.3, ramp="lookahead")
ROWS = ["." * 30] + ["." + "#" * 28 + "."] + ["." * 30] + ["...." + "#" * 20 + "......"] + ["." * 30]

pytestmark = pytest.mark.realtime  # every test runs a plan at real speed


_TO_PLAN = ChunkedPlan.to_plan


def _whole(job):
    """The job's writes held whole (the chunks joined), made before the runner may not join any."""
    return _TO_PLAN(plan_chunks(job))


@pytest.fixture
def no_whole_plan(monkeypatch):
    """A chunked plan made into one whole plan fails the test."""
    def refuse(self):
        raise AssertionError("the real-time runner made the whole plan")
    monkeypatch.setattr(ChunkedPlan, "to_plan", refuse)


def _job(**kw):
    return cam.plan(cam.digitize(drawing_from_rows(ROWS)), depth=3, settings=FAST, **kw)


def test_chunks_in_real_time_equal_the_whole_plan_through_a_stall(no_whole_plan):
    job = _job()
    whole = _whole(job)
    chunked = plan_chunks(job, chunk_periods=50)
    assert len(chunked) == len(whole) and len(whole) > 8 * 50
    port = StallingPort(at_write=len(whole) // 3, stall_s=0.1)
    cursor = Cursor(FAST)
    result = run(chunked, port, realtime=True, cursor=cursor)
    assert result.status == FINISHED and result.writes == len(whole)
    assert cursor.live == (len(whole), (0, 0, 0))  # the runner's cursor: every write, back at the start
    log = port.pin_log()
    np.testing.assert_array_equal(log.data, whole.data)
    assert np.all(np.diff(log.t_ns) >= np.diff(whole.t_ns)), "a write went out sooner than planned"
    assert result.lateness.stalls >= 1 and result.lateness.max_ns >= 0.08e9
    assert result.position_steps == (0, 0, 0)
    assert result.machine_time_s == pytest.approx(whole.t_ns[-1] / 1e9)


def test_chunked_pauses_and_stop_in_real_time_are_the_whole_plans(no_whole_plan):
    """Pause At points report the position the whole plan's run reports; a stop lifts from where it got to."""
    d = cam.digitize(drawing_from_rows(ROWS))
    job = cam.plan(d, depth=3, settings=FAST, pause_at=[tuple(d.objects[0][5]), tuple(d.objects[-1][7])])
    seen = {"whole": [], "chunked": []}
    run(_whole(job), cam.MockPort(), on_pause=lambda pos, note: seen["whole"].append(pos))
    run(plan_chunks(job, chunk_periods=40), cam.MockPort(), realtime=True,
        on_pause=lambda pos, note: seen["chunked"].append(pos))
    assert len(seen["whole"]) == 2 and seen["chunked"] == seen["whole"]

    whole = _whole(job)
    ctl = Controller()
    stop_at = len(whole) // 2
    port = cam.MockPort()
    calls = {"n": 0}
    real_write = port.write

    def counting(data, strobe, t_ns):
        real_write(data, strobe, t_ns)
        calls["n"] += 1
        if calls["n"] == stop_at:
            ctl.stop()
    port.write = counting
    result = run(plan_chunks(job, chunk_periods=40), port, realtime=True, controller=ctl,
                 on_pause=lambda pos, note: None)
    assert result.status == STOPPED and result.writes == stop_at
    log = port.pin_log()
    np.testing.assert_array_equal(log.data[:stop_at], whole.data[:stop_at])
    motion = cam.decode_pin_log(log, FAST)
    assert motion.final_steps == result.position_steps
    assert result.position_steps[2] <= 0  # lifted out of the material


def test_a_streamed_drawing_runs_in_the_runner_process_a_chunk_at_a_time(tmp_path, monkeypatch):
    """A session's real-time runner process takes the chunked plan of a streamed drawing and makes its writes
    itself: its pin log has the writes of the simulated run."""
    monkeypatch.setattr("cam.job.drawing_stream.STREAM_TARGETS", 10)
    src = tmp_path / "bar.png"
    import cv2
    cv2.imwrite(str(src), drawing_from_rows(ROWS))
    job = prepare_job(src, JobOptions(depth=(3,)), FAST)
    assert not hasattr(job.toolpath, "points_steps")
    job.plan.chunk_periods = 64
    simulated = MachineSession("mock", FAST)
    simulated.run(job)
    sent = []
    from cam.drive.apart import RunnerProcess
    real_run = RunnerProcess.run
    monkeypatch.setattr(RunnerProcess, "run", lambda self, plan, *a, **k: sent.append(plan) or real_run(self, plan, *a, **k))
    session = MachineSession("mock", FAST, realtime=True)
    try:
        info = session.run(job)
        assert [type(p) for p in sent] == [ChunkedPlan]  # the child makes the writes
        assert info["status"] == FINISHED, info
        a, b = simulated.last_job_pin_log, session.last_job_pin_log
    finally:
        session.runner_process().close()
    np.testing.assert_array_equal(a.data, b.data)
    assert np.all(np.diff(b.t_ns) >= np.diff(a.t_ns))
