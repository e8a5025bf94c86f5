"""The machine comes first: planning, previews and pin-log exports run in the server's worker process, within
its limits, and a job running meanwhile keeps every step interval.

The servers are the real ones (see ``test_web.Server``).
"""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

import cam
from conftest import SAMPLES
from test_web import MEDIUM, Server, compiled_kernels, servers  # noqa: F401 (fixtures)

SLOW_CASES = {'test_planning_over_the_work_memory_limit_is_a_clean_error'}
"""Cases run in the slow tier only (tests/conftest.py): the fast tier stays under 3 minutes."""

HALF_MS = MEDIUM.replace(delay_xy_ms=0.5, delay_z_ms=0.5)
PNG = (SAMPLES / "ellipse.png").read_bytes()
DRILLS = "M48\nMETRIC\nT1C0.8\n%\nT1\n" + "".join(f"X{x * 0.5:.1f}Y{y * 0.5:.1f}\n" for y in range(5)
                                                   for x in range(10)) + "M30\n"


def _plan(s, name: str, data: bytes, options: dict):
    status, r = s.upload(name, data)
    assert status == 200, r
    return s.call("POST", "/api/plan", {"job": r["job"], "options": options})


@pytest.mark.realtime
def test_planning_and_previews_during_a_job_leave_its_step_timing_alone(servers):
    s = servers("half-ms", settings=HALF_MS, realtime=True)
    status, first = _plan(s, "ellipse.png", PNG, {"depth": 2})
    assert status == 200, first
    assert s.call("POST", "/api/start", {"job": first["job"]})[0] == 200
    # while it runs (about 4 s): plan a 50-hole drill file and fetch its preview, then the first job's preview
    status, second = _plan(s, "board.drl", DRILLS.encode(), {})
    assert status == 200, second
    assert s.session.busy, "the job ended before the planning: make it longer"
    status, png = s.call("GET", second["preview"])
    assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n"
    st = s.wait_idle(60)
    assert st["last"]["status"] == "finished"
    log = s.session.last_job_pin_log
    planned = cam.kinds.jobs.prepare_job(SAMPLES / "ellipse.png", cam.kinds.jobs.JobOptions(depth=(2,)), HALF_MS).steps
    assert np.array_equal(log.data, planned.data)
    assert np.all(np.diff(log.t_ns) >= np.diff(planned.t_ns)), "a step came sooner than planned"
    # the pin log export is a file made by the worker: the same writes, as CSV
    status, csv = s.call("GET", "/api/pinlog")
    assert status == 200
    rows = np.loadtxt(csv.decode().splitlines()[1:], delimiter=",", dtype=np.int64)
    assert np.array_equal(rows[:, 0], log.t_ns) and np.array_equal(rows[:, 1], log.data)
    s.call("POST", "/api/origin", {})
    s.wait_idle()


def test_planning_over_the_work_time_limit_is_a_clean_error_and_the_server_goes_on(tmp_path):
    s = Server(tmp_path, settings=MEDIUM, work_time_limit_s=0.001)
    try:
        worker = s.app.state.config  # the limit is the server's, from its configuration
        assert worker.work_time_limit_s == 0.001
        status, r = _plan(s, "ellipse.png", PNG, {"depth": 1})
        assert status == 400 and "planning ellipse.png took over 0.001 s and was stopped" in r["error"], r
        assert s.call("POST", "/api/estop", {})[0] == 200
        status, r = _plan(s, "ellipse.png", PNG, {"depth": 1})  # a new worker process, the same clean answer
        assert status == 400 and "took over" in r["error"], r
        assert s.call("GET", "/api/state")[0] == 200
    finally:
        s.close()


def test_planning_over_the_work_memory_limit_is_a_clean_error(tmp_path):
    big_travel = MEDIUM.replace(travel=cam.settings.Travel(x_max_steps=40_000, y_max_steps=40_000))
    s = Server(tmp_path, settings=big_travel, work_memory_limit_bytes=800 << 20)
    try:
        # a 4000 x 4000 drawing (inside the travel and the image size limit): its planning needs more than
        # what is left of 800 MB once the worker has loaded its libraries
        import cv2
        image = np.full((4000, 4000, 3), 255, np.uint8)
        for r in range(100, 1990, 6):
            cv2.circle(image, (2000, 2000), r, (0, 0, 0), 1)
        ok, data = cv2.imencode(".png", image)
        status, r = _plan(s, "huge.png", data.tobytes(), {"depth": 1})
        assert status == 400 and "planning huge.png needs more than 800 MB" in r["error"], r
        assert s.app.state.config.work_memory_limit_bytes == 800 << 20
        assert s.call("GET", "/api/state")[0] == 200 and s.call("POST", "/api/estop", {})[0] == 200
        # (that the next call gets a fresh worker is tests/test_worker.py's: 800 MB is too tight here for a
        # worker that must compile numba kernels on a fresh clone)
    finally:
        s.close()


def test_serve_bad_limits_are_one_line():
    from conftest import run_cli

    bad = run_cli("serve", "--max-connections", "5", "--max-event-streams", "9")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "max_event_streams (9) must be below max_connections (5)" in bad.stderr
    bad = run_cli("serve", "--work-time-limit", "0")
    assert bad.returncode == 2 and "--work-time-limit" in bad.stderr


@pytest.mark.slow
def test_serve_limits_options_reach_the_server(tmp_path):
    """``cam serve`` as a process: its work time limit reaches the page's planning."""
    import json
    import re
    import subprocess
    import sys
    import urllib.request
    import uuid

    from conftest import ROOT

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "cam", "serve", "--http-port", "0", "--simulated",
                             "--jobs-dir", str(tmp_path / "jobs"), "--work-time-limit", "0.001"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = re.search(r"(http://127\.0\.0\.1:\d+)", proc.stdout.readline()).group(1)
        boundary = uuid.uuid4().hex
        body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"role\"\r\n\r\njob\r\n"
                f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"e.png\"\r\n\r\n").encode()
        body += PNG + f"\r\n--{boundary}--\r\n".encode()
        headers = {"Origin": url, "X-Requested-With": "cam"}
        req = urllib.request.Request(url + "/api/upload", data=body, method="POST",
                                     headers={**headers, "Content-Type": f"multipart/form-data; boundary={boundary}"})
        job = json.loads(urllib.request.urlopen(req, timeout=600).read())["job"]
        req = urllib.request.Request(url + "/api/plan", data=json.dumps({"job": job}).encode(), method="POST",
                                     headers={**headers, "Content-Type": "application/json"})
        try:
            urllib.request.urlopen(req, timeout=600)
            raise AssertionError("planning within 1 ms?")
        except urllib.error.HTTPError as exc:
            assert exc.code == 400 and "took over 0.001 s" in json.loads(exc.read())["error"]
    finally:
        proc.terminate()
        proc.wait(20)


@pytest.mark.realtime
def test_a_planning_that_takes_minutes_leaves_the_machine_answering(tmp_path):
    """The issue's case: a 1000^2 noise drawing with min-distance starts took the server for about a minute."""
    import threading

    import cv2
    rng = np.random.default_rng(1)
    image = np.full((1000, 1000, 3), 255, np.uint8)
    noise = rng.random((1000, 1000)) < 0.3
    noise[0, :] = noise[-1, :] = noise[:, 0] = noise[:, -1] = False
    image[noise] = 0
    ok, data = cv2.imencode(".png", image)
    s = Server(tmp_path, settings=MEDIUM, realtime=True, work_time_limit_s=5)
    try:
        status, up = s.upload("noise.png", data.tobytes())
        assert status == 200, up
        box = {}
        planning = threading.Thread(target=lambda: box.update(
            r=s.call("POST", "/api/plan", {"job": up["job"], "options": {"depth": 1, "start": "min-distance"}})))
        planning.start()
        time.sleep(1.0)
        assert s.call("POST", "/api/jog", {"axis": "x", "steps": 200})[0] == 200
        assert s.wait_idle(10)["last"]["status"] == "finished"  # the machine moved while the planning ran
        assert s.call("POST", "/api/estop", {})[0] == 200
        assert s.call("GET", "/api/state")[0] == 200
        assert planning.is_alive(), "the planning ended first: the test proves nothing"
        planning.join(60)
        status, r = box["r"]
        assert status == 400 and "planning noise.png took over 5 s and was stopped" in r["error"], r
    finally:
        s.close()
