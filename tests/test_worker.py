"""The worker process: heavy work apart from the machine, within a time and a memory limit."""
import os
import time

import numpy as np
import pytest

from cam.errors import CamError, ParseError
from cam.verify.pinlog import read_pin_log
from cam.worker import Worker, WorkerLimitError


@pytest.fixture(scope="module")
def worker():
    w = Worker(time_limit_s=3, memory_limit_bytes=1 << 30, warm_up=("numpy",))
    yield w
    w.close()


def test_a_call_runs_in_another_process_and_returns_its_value(worker):
    assert worker.call(os.getpid) != os.getpid()
    assert worker.call(np.arange, 5).tolist() == [0, 1, 2, 3, 4]


def test_its_cam_errors_come_back_as_they_were(worker):
    with pytest.raises(ParseError, match="nowhere.csv: file not found"):
        worker.call(read_pin_log, "/nowhere.csv")


def test_over_the_memory_limit_is_a_clean_error_and_the_next_call_works(worker):
    restarts = worker.restarts
    with pytest.raises(WorkerLimitError, match=r"building a big array needs more than 1024 MB"):
        worker.call(np.ones, 2 << 30, np.uint8, what="building a big array")
    assert worker.restarts == restarts + 1
    assert worker.call(np.add, 2, 3) == 5


@pytest.mark.slow
def test_over_the_time_limit_the_work_is_ended(worker):
    pid = worker.call(os.getpid)
    with pytest.raises(WorkerLimitError, match=r"sleeping took over 3 s and was stopped"):
        worker.call(time.sleep, 60, what="sleeping")
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # that process is gone, not left running in the background
    assert worker.call(os.getpid) != pid


def test_a_crash_of_the_child_is_a_clean_error(worker):
    with pytest.raises(WorkerLimitError, match="exit code 7"):
        worker.call(os._exit, 7, what="exiting")
    assert worker.call(np.add, 1, 1) == 2


def test_a_bug_is_not_dressed_as_bad_input(worker):
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):
        worker.call(divmod, 1, 0)


def test_close_ends_a_running_call_at_once():
    import threading

    w = Worker(time_limit_s=60, warm_up=())
    w.start()
    box = {}

    def run():
        try:
            w.call(time.sleep, 30, what="a long planning")
        except CamError as exc:
            box["error"] = exc

    t = threading.Thread(target=run)
    t.start()
    time.sleep(0.5)
    w.close()
    t.join(5)
    assert not t.is_alive() and isinstance(box["error"], WorkerLimitError)
    with pytest.raises(CamError, match="closed"):
        w.call(os.getpid)


def test_limits_are_checked():
    with pytest.raises(CamError, match="time limit"):
        Worker(time_limit_s=0)
    with pytest.raises(CamError, match="at least 256 MB"):
        Worker(memory_limit_bytes=1000)
