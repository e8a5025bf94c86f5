"""The machine first on a busy PC (issue #32 point 2): the real-time runner process asks for SCHED_FIFO, locks its
memory and keeps a core of its own where there are two or more, and says in one line what it got."""
import os

import numpy as np
import pytest

from cam.drive.priority import FIFO_PRIORITY
from cam.drive.session import MachineSession
from cam.job.model import travel_job
from cam.settings import DEFAULT_SETTINGS


@pytest.mark.realtime
def test_the_runner_process_claims_the_machine_and_says_what_it_got():
    session = MachineSession("mock", DEFAULT_SETTINGS, realtime=True)
    try:
        session.start(travel_job(np.array([[20, 0, 0]]), DEFAULT_SETTINGS))
        session.wait_idle(None)
        runner = session.runner_process()
        pid = runner.pid
        said = [e["text"] for e in session.state(log_after=0)["log"] if e["text"].startswith("step runner: ")]
        assert said == [f"step runner: {runner.claimed}"]
        cpus = os.sched_getaffinity(0)
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))  # may this system give one at all?
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            permitted = True
        except OSError:
            permitted = False
        if permitted:
            assert os.sched_getscheduler(pid) == os.SCHED_FIFO
            assert os.sched_getparam(pid).sched_priority == FIFO_PRIORITY
            assert runner.claimed.startswith(f"SCHED_FIFO priority {FIFO_PRIORITY}")
        else:
            assert "not permitted" in runner.claimed
        if len(cpus) >= 2:
            assert os.sched_getaffinity(pid) == {max(cpus)}
            assert runner.claimed.endswith(f"on core {max(cpus)} of {len(cpus)}")
        assert session.last_run["status"] == "finished"
    finally:
        session.shutdown()
