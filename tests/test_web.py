"""The web page: the API over HTTP, and the page driven in a real (headless) Chromium through Playwright.

Every server here is the real one (Starlette on uvicorn) on a free localhost
port, in a thread of this process, so the tests can read the machine session
(pin log, timings) directly.  Jobs run on the mock port; the pin log is
decoded and carve-checked against the same job planned in the library.
"""
from __future__ import annotations

import json
import os
import threading
import time
import urllib.error
import urllib.request
import uuid
from pathlib import Path

import numpy as np
import pytest
import uvicorn

import cam
from cam.drive.runner import EMERGENCY_STOPPED, FINISHED
from cam.kinds.jobs import JobOptions, prepare_job

from conftest import SAMPLES, assert_surface_equal

from cam.web.server import ServerConfig, bind_socket, create_app, safe_name, uvicorn_config  # noqa: E402

# over 1.3 s each: the slow tier (the fast tier stays under 3 minutes, docs/tests.md)
SLOW_CASES = {'test_api_bad_requests_are_4xx_json_and_nothing_moves'}

CHROMIUM = "/usr/bin/chromium"
ROOT = Path(__file__).resolve().parent.parent

# fast machines so jobs take a fraction of a second in real time
# (constant step delay, no speed ramp: the step period is the delay)
FAST = cam.MachineSettings().replace(delay_xy_ms=0.02, delay_z_ms=0.02, ramp="constant")
SLOW = cam.MachineSettings().replace(ramp="constant")  # e-stop timing: the thesis's own 5 ms step period
MEDIUM = cam.MachineSettings().replace(delay_xy_ms=0.2, delay_z_ms=0.2, ramp="constant")  # ~1.5 s jobs

TOKEN = "s3cret-token-of-the-tests"  # at least 16 characters (cam.web.server.TOKEN_MIN_CHARS)

GCODE = """%
(square with a tool change)
G21 G90
G0 Z1
G0 X1 Y-1
G1 Z-0.3 F200
G1 X4 F600
G1 Y-4
M6 T2
G1 X1
G1 Y-1
G0 Z1
G0 X0 Y0
G0 Z0
M2
%
"""

EXCELLON = """M48
METRIC,LZ
T1C0.8
T2C1.0
%
T1
X5.0Y5.0
X10.0Y5.0
T2
X10.0Y10.0
M30
"""

HTTP_HANG_S = 600.0
"""How long a test's request may wait for its answer before the server counts as hung."""


class Server:
    """A real server on a free localhost port, in a thread.

    ``seen`` records (method, path, status) of every HTTP request it answered.
    """

    def __init__(self, tmp: Path, **config) -> None:
        self.config = ServerConfig(jobs_dir=str(tmp / f"jobs-{uuid.uuid4().hex[:6]}"), port=0, **config)
        self.app = create_app(self.config)
        self.session = self.app.state.session
        self.seen: list[tuple[str, str, int]] = []
        sock = bind_socket("127.0.0.1", 0)
        self.url = f"http://127.0.0.1:{sock.getsockname()[1]}"
        ucfg = uvicorn_config(self._recording(self.app), log_level="warning", timeout_graceful_shutdown=1)
        self.server = uvicorn.Server(ucfg)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [sock]}, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started:
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.02)

    def _recording(self, app):
        async def recorder(scope, receive, send):
            async def send_seen(message):
                if message["type"] == "http.response.start":
                    self.seen.append((scope["method"], scope["path"], message["status"]))
                await send(message)

            await app(scope, receive, send_seen if scope["type"] == "http" else send)

        recorder.state = app.state
        return recorder

    def close(self) -> None:
        self.session.shutdown()
        self.server.should_exit = True
        self.thread.join(10)

    def page_headers(self, method: str) -> dict[str, str]:
        """What the page's own fetch() adds: the browser its Origin to a POST, app.js X-Requested-With."""
        return {} if method in ("GET", "HEAD") else {"Origin": self.url, "X-Requested-With": "cam"}

    # -- plain HTTP (urllib) -----------------------------------------------------
    def call(self, method: str, path: str, body=None, *, token=None, headers=None, raw: bytes | None = None):
        """(status, decoded JSON or text) of one request, sent as the page sends it; a header given as None
        in ``headers`` is left out."""
        h = self.page_headers(method)
        data = raw
        if body is not None:
            data = json.dumps(body).encode()
            h["Content-Type"] = "application/json"
        if token:
            h["X-Cam-Token"] = token
        h.update(headers or {})
        h = {k: v for k, v in h.items() if v is not None}
        req = urllib.request.Request(self.url + path, data=data, method=method, headers=h)
        try:
            # the answer is the condition waited for; the socket's timeout only keeps a dead server from
            # hanging the suite (30 s was too short for a relief planned on a 2-core machine under load)
            with urllib.request.urlopen(req, timeout=HTTP_HANG_S) as resp:
                status, payload, ctype = resp.status, resp.read(), resp.headers.get("content-type", "")
        except urllib.error.HTTPError as exc:
            status, payload, ctype = exc.code, exc.read(), exc.headers.get("content-type", "")
        if "json" in ctype:
            return status, json.loads(payload)
        return status, payload

    def upload(self, name: str, data: bytes, role: str = "job", token=None, headers=None):
        boundary = uuid.uuid4().hex
        parts = [
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"role\"\r\n\r\n{role}\r\n".encode(),
            f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{name}\"\r\n"
            f"Content-Type: application/octet-stream\r\n\r\n".encode() + data + b"\r\n",
            f"--{boundary}--\r\n".encode(),
        ]
        return self.call("POST", "/api/upload", raw=b"".join(parts), token=token,
                         headers={"Content-Type": f"multipart/form-data; boundary={boundary}", **(headers or {})})

    def wait_idle(self, timeout_s: float = 20.0) -> dict:
        deadline = time.monotonic() + timeout_s
        while self.session.busy:
            assert time.monotonic() < deadline, "job did not end"
            time.sleep(0.02)
        return self.session.state()


@pytest.fixture(scope="module", autouse=True)
def compiled_kernels(tmp_path_factory):
    """Plan one job of each kind first: numba compiles its kernels on first use (seconds on a fresh
    clone), which must not eat into the browser tests' waiting times."""
    tmp = tmp_path_factory.mktemp("warm")
    (tmp / "w.drl").write_text(EXCELLON)
    (tmp / "w.ngc").write_text(GCODE)
    for path in (SAMPLES / "ellipse.png", tmp / "w.drl", tmp / "w.ngc", ROOT / "samples" / "seed_tools.plt"):
        for settings in (FAST, SLOW, cam.MachineSettings()):
            prepare_job(path, JobOptions(), settings)


@pytest.fixture(scope="module")
def servers(tmp_path_factory):
    made: dict[str, Server] = {}
    tmp = tmp_path_factory.mktemp("web")

    def get(name: str, **config) -> Server:
        if name not in made:
            made[name] = Server(tmp, **config)
        return made[name]

    yield get
    for s in made.values():
        s.close()


@pytest.fixture
def fast(servers):
    s = servers("fast", settings=FAST, realtime=True)
    s.session.wait_idle()
    return s


# ------------------------------------------------------------------------------------
# library: jobs.py
# ------------------------------------------------------------------------------------


def _carve_check_drawing(log: cam.PinLog, path: Path, depth: int, settings) -> None:
    """The pin log carves exactly what the same job planned in the library carves (and the drawing asks)."""
    d = cam.digitize(cam.load_image(path))
    job = cam.plan(d, depth=depth, settings=settings)
    want = cam.simulate_surface(job)
    motion = cam.decode_pin_log(log, settings)
    got = cam.carve(motion, (job.height_px, job.width_px), settings, origin_px=job.origin_px)
    assert_surface_equal(got, want)
    assert int(want.max()) == depth * settings.steps_per_px_z
    assert motion.final_steps == (0, 0, 0)


# ------------------------------------------------------------------------------------
# API over HTTP
# ------------------------------------------------------------------------------------


def test_safe_name_keeps_uploads_in_the_jobs_folder(fast):
    assert safe_name("../../x/../evil.png") == "evil.png"
    assert safe_name("..\\..\\win.ngc") == "win.ngc"
    status, r = fast.upload("../../../escape.png", (SAMPLES / "ellipse.png").read_bytes())
    assert status == 200 and r["name"] == "escape.png", r
    jobs_dir = Path(fast.config.jobs_dir)
    assert [p.name for p in jobs_dir.iterdir() if p.name.endswith("escape.png")] == [f"{int(r['job']):04d}-escape.png"]
    assert not (jobs_dir.parent / "escape.png").exists()


def test_api_bad_requests_are_4xx_json_and_nothing_moves(fast):
    before = fast.session.last_run
    status, r = fast.upload("notes.exe", b"MZ....")
    assert status == 400 and "unknown file type" in r["error"] and "notes.exe" in r["error"]
    status, r = fast.call("POST", "/api/jog", raw=b"{not json", headers={"Content-Type": "application/json"})
    assert status == 400 and "malformed JSON" in r["error"]
    status, r = fast.call("POST", "/api/jog", {"axis": "w", "steps": 5})
    assert status == 400 and "axis" in r["error"]
    status, r = fast.call("POST", "/api/jog", {"axis": "x", "steps": "lots"})
    assert status == 400
    status, r = fast.call("POST", "/api/start", {"job": "999"})
    assert status == 404
    status, r = fast.upload("e.png", (SAMPLES / "ellipse.png").read_bytes())
    status, r = fast.call("POST", "/api/plan", {"job": r["job"], "options": {"depth": "deep"}})
    assert status == 400 and "depth" in r["error"]
    status, r = fast.call("POST", "/api/plan", {"job": "1", "options": {"no_such": 1}})
    assert status in (400, 404)
    status, r = fast.call("GET", "/api/nothing")
    assert status == 404 and "error" in r
    # a bad G-code file: 400 naming file:line, nothing runs
    status, r = fast.upload("bad.ngc", b"G21\nG1 X1 Q5\n")
    status, r = fast.call("POST", "/api/plan", {"job": r["job"]})
    assert status == 400 and "bad.ngc:2" in r["error"]
    assert fast.session.last_run is before and not fast.session.busy
    assert fast.session.position_steps() == (0, 0, 0)


@pytest.mark.realtime
def test_second_start_is_409_and_jog_is_refused_while_running(servers):
    s = servers("medium", settings=MEDIUM, realtime=True)
    status, r = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
    status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": {"depth": 2}})
    assert status == 200, plan
    status, r = s.call("POST", "/api/start", {"job": plan["job"]})
    assert status == 200 and r["state"] in ("running", "idle")
    status, r = s.call("POST", "/api/start", {"job": plan["job"]})
    assert status == 409 and "busy" in r["error"]
    status, r = s.call("POST", "/api/jog", {"axis": "x", "steps": 10})
    assert status == 409
    status, r = s.call("POST", "/api/stop", {})
    assert status == 200
    st = s.wait_idle()
    assert st["last"]["status"] == "stopped"
    assert st["position_steps"][2] == 0  # tool lifted to the surface
    status, r = s.call("POST", "/api/origin", {})
    assert status == 200
    assert s.wait_idle()["position_steps"] == [0, 0, 0]


def test_oversized_upload_is_413_and_the_server_keeps_serving(servers):
    s = servers("small-uploads", settings=FAST, max_upload_bytes=100_000)
    status, r = s.upload("big.png", b"\x00" * 400_000)
    assert status == 413 and "too large" in r["error"]
    status, r = s.call("GET", "/api/state")
    assert status == 200 and r["state"] == "idle"
    status, r = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
    assert status == 200
    assert not any(p.name.endswith("big.png") for p in Path(s.config.jobs_dir).iterdir())


def test_token_required_on_every_machine_request(servers):
    token = TOKEN
    s = servers("token", settings=FAST, token=token)
    for method, path, body in [("GET", "/api/state", None), ("POST", "/api/jog", {"axis": "x", "steps": 5}),
                               ("POST", "/api/estop", {}), ("POST", "/api/start", {"job": "1"}),
                               ("GET", "/api/events", None), ("GET", "/api/pinlog", None)]:
        status, r = s.call(method, path, body)
        assert status == 401, (path, r)
        status, r = s.call(method, path, body, token="wrong")
        assert status == 401, (path, r)
    status, r = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
    assert status == 401
    assert s.session.position_steps() == (0, 0, 0) and s.session.last_run == {}
    status, r = s.call("POST", "/api/jog", {"axis": "x", "steps": 5}, token=token)
    assert status == 200
    assert s.wait_idle()["position_steps"] == [5, 0, 0]
    status, r = s.call("GET", f"/api/state?token={token}")
    assert status == 200
    status, _ = s.call("GET", "/")  # the page itself loads; it carries the token from its URL
    assert status == 200


def test_localhost_server_refuses_other_hosts_and_cross_site_origins(fast):
    status, r = fast.call("POST", "/api/jog", {"axis": "x", "steps": 5}, headers={"Host": "evil.example:80"})
    assert status == 403
    status, r = fast.call("POST", "/api/jog", {"axis": "x", "steps": 5}, headers={"Origin": "http://evil.example"})
    assert status == 403
    assert fast.session.position_steps() == (0, 0, 0)


def test_non_local_host_needs_a_token():
    with pytest.raises(cam.CamError, match="token"):
        ServerConfig(host="0.0.0.0").checked()


def test_jog_travel_limits_and_origin(fast):
    status, r = fast.call("POST", "/api/jog", {"axis": "x", "steps": -5})
    assert status == 400 and "travel" in r["error"]
    for axis, n in [("x", 40), ("y", 24), ("z", 7)]:
        status, r = fast.call("POST", "/api/jog", {"axis": axis, "steps": n})
        assert status == 200, r
        fast.wait_idle()
    assert fast.session.position_steps() == (40, 24, 7)
    log = fast.session.last_run
    assert log["status"] == FINISHED
    status, r = fast.call("POST", "/api/origin", {})
    st = fast.wait_idle()
    assert st["position_steps"] == [0, 0, 0] and st["position_mm"] == [0.0, 0.0, 0.0]


# ------------------------------------------------------------------------------------
# the page in Chromium
# ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser():
    from playwright import sync_api

    if not os.path.exists(CHROMIUM) and not os.environ.get("CI"):
        pytest.skip("Debian chromium not installed")
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        yield b
        b.close()


@pytest.fixture
def page(browser):
    ctx = browser.new_context(viewport={"width": 390, "height": 844}, device_scale_factor=1, has_touch=True,
                              bypass_csp=True)  # the page's CSP forbids eval, which wait_for_function needs
    p = ctx.new_page()
    p.set_default_timeout(20_000)
    yield p
    ctx.close()


def _open(page, server, token=None) -> None:
    page.goto(server.url + "/" + (f"?token={token}" if token else ""))
    page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")


def _load(page, path: Path, depth: str | None = None) -> None:
    if depth is not None:
        page.fill("#opt-depth", depth)
    page.set_input_files("#file", str(path))
    page.wait_for_function("!document.getElementById('start').disabled")
    page.wait_for_function("document.getElementById('preview').naturalWidth > 0")


def _wait_done(page, server) -> dict:
    page.wait_for_function("document.getElementById('percent').textContent === '100'")
    page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
    return server.wait_idle()


@pytest.mark.browser
def test_page_runs_a_drawing_and_the_pin_log_carves_exactly(page, fast, tmp_path):
    _open(page, fast)
    _load(page, SAMPLES / "ellipse.png", depth="3")
    assert "66.12 × 33.29 mm" in page.text_content("#job-size")
    job = prepare_job(SAMPLES / "ellipse.png", JobOptions(depth=(3,)), FAST)
    assert f"{job.estimated_time_s:.1f} s" in page.text_content("#job-time")
    page.click("#start")
    st = _wait_done(page, fast)
    assert st["last"]["status"] == FINISHED and st["last"]["activity"] == "job"
    # the pin log over HTTP, as CSV, decoded and carve-checked against the library's own plan
    status, csv = fast.call("GET", "/api/pinlog")
    assert status == 200
    (tmp_path / "log.csv").write_bytes(csv)
    log = cam.read_pin_log(tmp_path / "log.csv")
    assert np.array_equal(log.data, job.steps.data)  # every write the library planned, in order
    _carve_check_drawing(log, SAMPLES / "ellipse.png", 3, FAST)
    assert page.text_content("#pos-steps") == "0, 0, 0"
    assert "job ellipse.png: finished" in page.text_content("#log")


@pytest.mark.browser
def test_page_emergency_stop_is_sent_again_until_the_server_answers(page, servers):
    """The page's e-stop retries (issue #33 point 3): the first three tries are lost (503, a dropped
    connection), the fourth reaches the server and stops the job."""
    s = servers("slow-retried", settings=SLOW, realtime=True)  # its own: it ends e-stopped
    s.session.wait_idle()
    _open(page, s)
    _load(page, SAMPLES / "ellipse.png", depth="2")
    tries = []

    def flaky(route):
        tries.append(1)
        if len(tries) == 1:
            route.fulfill(status=503, content_type="application/json", body='{"error": "busy"}')
        elif len(tries) <= 3:
            route.abort("connectionreset")
        else:
            route.continue_()

    page.route("**/api/estop", flaky)
    page.click("#start")
    page.wait_for_function("parseFloat(document.getElementById('percent').textContent) > 2")
    page.click("#estop")
    deadline = time.monotonic() + 10
    while s.session.busy and time.monotonic() < deadline:
        page.wait_for_timeout(50)  # the page's retries run while this waits (Playwright's routes need it)
    assert len(tries) >= 4 and s.session.state()["last"]["status"] == EMERGENCY_STOPPED, len(tries)


@pytest.mark.browser
def test_page_emergency_stop_halts_within_one_step_period(page, servers):
    s = servers("slow", settings=SLOW, realtime=True)
    s.session.wait_idle()
    _open(page, s)
    _load(page, SAMPLES / "ellipse.png", depth="2")
    page.click("#start")
    page.wait_for_function("parseFloat(document.getElementById('percent').textContent) > 2")
    page.click("#estop")
    st = s.wait_idle(10)
    last = st["last"]
    assert last["status"] == EMERGENCY_STOPPED
    log = s.session.last_job_pin_log
    # the last write sent is no later than one step period after the request reached the server
    assert int(log.t_ns[-1]) <= last["estop_request_job_ns"] + SLOW.delay_xy_ns
    assert last["last_write_job_ns"] == int(log.t_ns[-1])
    total = len(prepare_job(SAMPLES / "ellipse.png", JobOptions(depth=(2,)), SLOW).steps)
    assert 0 < len(log) < total
    page.wait_for_function("document.getElementById('log').textContent.includes('EMERGENCY STOP')")
    # the tool stays where it stopped (nothing more sent); the page shows it
    motion = cam.decode_pin_log(log, SLOW)
    assert tuple(st["position_steps"]) == motion.final_steps
    page.wait_for_function(f"document.getElementById('pos-steps').textContent === '{', '.join(map(str, motion.final_steps))}'")
    page.click("#origin")
    page.wait_for_function("document.getElementById('pos-steps').textContent === '0, 0, 0'", timeout=30_000)
    s.wait_idle()


def _medium_at_origin(servers) -> "Server":
    """The medium-speed real-time server, idle, its tool back at the origin (an earlier test may have left it)."""
    s = servers("medium", settings=MEDIUM, realtime=True)
    s.session.wait_idle()
    if s.session.position_steps() != (0, 0, 0):
        s.session.go_to_origin()
        s.wait_idle()
    return s


@pytest.mark.browser
def test_page_pause_resume_keeps_the_carve_exact(page, servers):
    s = _medium_at_origin(servers)
    _open(page, s)
    _load(page, SAMPLES / "two_curves.png", depth="2")
    page.click("#start")
    page.wait_for_function("parseFloat(document.getElementById('percent').textContent) > 5")
    page.click("#pause")
    page.wait_for_function("document.getElementById('state').dataset.state === 'paused'")
    held = s.session.position_steps()
    time.sleep(0.3)
    assert s.session.position_steps() == held  # nothing moves while paused
    assert not page.is_disabled("#resume")
    page.click("#resume")
    st = _wait_done(page, s)
    assert st["last"]["status"] == FINISHED
    _carve_check_drawing(s.session.last_job_pin_log, SAMPLES / "two_curves.png", 2, MEDIUM)


@pytest.mark.browser
def test_page_runs_gcode_with_a_tool_change_prompt(page, fast, tmp_path):
    path = tmp_path / "square.ngc"
    path.write_text(GCODE)
    _open(page, fast)
    _load(page, path)
    assert "tool change" in page.text_content("#job-tools")
    page.click("#start")
    page.wait_for_selector("#prompt-dialog[open]")
    assert "tool change" in page.text_content("#prompt-text")
    assert fast.session.busy  # the job waits for the answer
    page.click("#prompt-continue")
    st = _wait_done(page, fast)
    assert st["last"]["status"] == FINISHED
    from cam.motion.steps import plan_steps
    from cam.formats.gcode import load_gcode
    from cam.job.gcode import plan_gcode

    want = plan_steps(plan_gcode(load_gcode(path), FAST))
    log = fast.session.last_job_pin_log
    assert np.array_equal(log.data, want.data) and np.array_equal(log.strobe, want.strobe)


@pytest.mark.browser
def test_page_runs_an_excellon_file(page, fast, tmp_path):
    path = tmp_path / "board.drl"
    path.write_text(EXCELLON)
    _open(page, fast)
    page.set_input_files("#file", str(path))
    page.wait_for_function("!document.getElementById('start').disabled")
    assert "3 holes" in page.text_content("#job-summary")
    page.fill("#opt-cut-depth", "1.5")
    page.click("#plan")
    page.wait_for_function("document.getElementById('job-size').textContent.includes('depth 1.50')")
    page.click("#start")
    for tool in ("T1 0.800 mm", "T2 1.000 mm"):  # one prompt per tool, smallest first
        page.wait_for_function("document.getElementById('prompt-dialog').open && "
                               f"document.getElementById('prompt-text').textContent.includes('{tool}')")
        page.click("#prompt-continue")
    st = _wait_done(page, fast)
    assert st["last"]["status"] == FINISHED
    want = prepare_job(path, JobOptions(cut_depth_mm=1.5), FAST).steps
    log = fast.session.last_job_pin_log
    assert np.array_equal(log.data, want.data)
    # every hole drilled to 1.5 mm: decoded plunges
    motion = cam.decode_pin_log(log, FAST)
    z = motion.position_steps[:, 2]
    assert z.max() == round(1.5 / FAST.mm_per_step_z)


@pytest.mark.browser
def test_page_fields_and_ranges_come_from_the_options_schema(page, fast, tmp_path):
    """GET /api/options decides which fields a kind shows and what range each takes (cam/options.py); a value out
    of range is refused by the server, in one line in the error banner (issue #47 point 6)."""
    path = tmp_path / "board.drl"
    path.write_text(EXCELLON)
    _open(page, fast)
    page.set_input_files("#file", str(path))
    page.wait_for_function("!document.getElementById('start').disabled")
    assert page.is_visible("#opt-cut-depth") and page.is_visible("#opt-mirror-x")
    assert not page.is_visible("#opt-depth") and not page.is_visible("#opt-flip-y")  # drawing and G-code only
    assert not page.is_visible("#opt-tool-spec")  # the cutter applies to drawings, SVG and HPGL, not drill files
    page.fill("#opt-cut-depth", "0")
    seen_before = len(fast.seen)  # the server is shared by the module's tests: only this test's requests count
    page.click("#plan")
    page.wait_for_function("!document.getElementById('error').hidden")
    assert "option 'cut_depth_mm' must be > 0 and at most 10000 mm" in page.text_content("#error-text")
    assert ("POST", "/api/plan", 400) in fast.seen[seen_before:]  # refused by the server, by the schema's range


@pytest.mark.browser
def test_page_shows_4xx_errors_and_nothing_moves(page, fast, tmp_path):
    bad = tmp_path / "notes.docx"
    bad.write_bytes(b"PK\x03\x04 not a job")
    _open(page, fast)
    page.set_input_files("#file", str(bad))
    page.wait_for_selector("#error:not([hidden])")
    assert "unknown file type" in page.text_content("#error-text")
    assert page.is_disabled("#start")
    # a bad option value: the message is shown, the old plan is not run
    _load(page, SAMPLES / "ellipse.png", depth="2")
    page.fill("#opt-depth", "-4")
    page.click("#plan")
    page.wait_for_function("document.getElementById('error-text').textContent.includes('depth')")
    assert page.is_disabled("#start")
    assert not fast.session.busy


@pytest.mark.browser
def test_page_with_a_token(page, servers):
    token = TOKEN
    s = servers("token", settings=FAST, token=token)
    page.goto(s.url + "/")  # without the token: the page says so
    page.wait_for_selector("#error:not([hidden])")
    assert "token" in page.text_content("#error-text")
    _open(page, s, token=token)
    page.select_option("#jog-steps", "100")
    page.click("button.jog[data-axis='x'][data-dir='1']")
    page.wait_for_function("document.getElementById('pos-steps').textContent.startsWith('1')")
    s.wait_idle()
    page.click("#origin")
    page.wait_for_function("document.getElementById('pos-steps').textContent === '0, 0, 0'")


@pytest.mark.browser
def test_phone_screenshot(page, servers, tmp_path):
    """Phone size: the emergency stop stays on screen, nothing overflows sideways; the README picture."""
    thesis = servers("thesis")  # the thesis machine's settings: the time shown is the real one
    _open(page, thesis)
    _load(page, SAMPLES / "gear.png", depth="4")
    box = page.locator("#estop").bounding_box()
    assert box["y"] + box["height"] <= 844 and box["width"] > 300 and box["height"] >= 64
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    page.mouse.wheel(0, 600)
    box = page.locator("#estop").bounding_box()
    assert box["y"] + box["height"] <= 844  # still visible after scrolling
    page.evaluate("window.scrollTo(0, 0)")
    page.click("#options summary")  # fold the options: the preview and its size and time show
    out = tmp_path / "web-phone.png"
    page.screenshot(path=str(out))  # docs/make_pictures.py takes the README's copy the same way
    assert out.stat().st_size > 10_000


# ------------------------------------------------------------------------------------
# the MAXIMUS board behind the server (emulated on a pty)
# ------------------------------------------------------------------------------------


@pytest.mark.slow
def test_api_drives_the_maximus_board(tmp_path):
    """A drill file on the emulated MAXIMUS board from the web API: prompts answered from the page's
    endpoint, every hole drilled once, no pause; jog and origin move the board; a drawing is refused."""
    from cam.drive.maximus.board import MAXIMUS_SETTINGS
    from cam.sim.maximus import start_emulator
    from support.maximus_log import decode_port_log, hole_strokes

    emu = start_emulator(speed=None)
    s = Server(tmp_path, settings=MAXIMUS_SETTINGS, machine_port=f"maximus:{emu.device_path}", realtime=True)
    try:
        status, r = s.upload("ellipse.png", (SAMPLES / "ellipse.png").read_bytes())
        status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": {"depth": 2}})
        assert status == 200
        status, r = s.call("POST", "/api/start", {"job": plan["job"]})
        assert status == 409 and "Excellon" in r["error"]  # the board drills drill files only

        status, r = s.upload("board.drl", (SAMPLES / "board.drl").read_bytes())
        status, plan = s.call("POST", "/api/plan", {"job": r["job"], "options": {"cut_depth_mm": 1.0}})
        assert status == 200, plan
        assert s.call("POST", "/api/start", {"job": plan["job"]})[0] == 200
        answered, ids = [], set()
        deadline = time.monotonic() + 60
        while s.session.busy:
            assert time.monotonic() < deadline, "the drill job did not end"
            st = s.session.state()
            if st["prompt"] and st["prompt"]["id"] not in ids:  # a prompt answered stays shown until the board goes on
                if not answered:
                    assert s.call("POST", "/api/pause", {})[0] == 409  # the firmware cannot pause
                answered.append(st["prompt"]["note"])
                ids.add(st["prompt"]["id"])
                assert s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})[0] == 200
            time.sleep(0.01)
        st = s.session.state()
        assert st["last"]["status"] == "finished", st["last"]
        assert [n.split(":")[1].split()[0] for n in answered] == ["T1", "T2", "T3"]  # 0.8, 1.0, 3.2 mm
        log = emu.port_log()
        strokes = hole_strokes(log)
        assert len(strokes) == 44 and len({(int(x), int(y)) for x, y, *_ in strokes}) == 44
        # from the start height (the travel height, 1.0 mm above the board) down 1.0 mm more into it
        depth = 2 * round(1.0 / MAXIMUS_SETTINGS.mm_per_step_z)
        assert (strokes[:, 2] - strokes[:, 3] == depth).all()
        start = decode_port_log(log)[0]
        assert decode_port_log(log)[-1].tolist() == start.tolist()  # back where it started

        assert s.call("POST", "/api/jog", {"axis": "x", "steps": 120})[0] == 200
        s.wait_idle(20)
        assert decode_port_log(emu.port_log())[-1][0] == start[0] + 120
        assert s.session.state()["position_steps"][0] == 120
        assert s.call("POST", "/api/origin", {})[0] == 200
        s.wait_idle(20)
        assert decode_port_log(emu.port_log())[-1].tolist() == start.tolist()
        assert s.session.state()["position_steps"] == [0, 0, 0]
    finally:
        s.close()
        emu.stop()
    assert emu.error is None


@pytest.mark.realtime
def test_api_emergency_stop_on_the_maximus_board(tmp_path):
    """The page's emergency stop during a move reaches the firmware's stop byte; the job ends naming the hole."""
    from cam.drive.maximus.board import MAXIMUS_SETTINGS
    from cam.sim.maximus import start_emulator

    emu = start_emulator(speed=1.0)  # the firmware's own timing: a move between holes takes seconds
    s = Server(tmp_path, settings=MAXIMUS_SETTINGS, machine_port=f"maximus:{emu.device_path}", realtime=True)
    try:
        status, r = s.upload("board.drl", (SAMPLES / "board.drl").read_bytes())
        status, plan = s.call("POST", "/api/plan", {"job": r["job"]})
        assert s.call("POST", "/api/start", {"job": plan["job"]})[0] == 200
        deadline = time.monotonic() + 30
        while not s.session.state()["prompt"]:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        st = s.session.state()
        assert s.call("POST", "/api/answer", {"prompt": st["prompt"]["id"], "action": "continue"})[0] == 200
        deadline = time.monotonic() + 30  # the offset and first hole moves are under way: the head moved
        while s.session.state()["activity"] and s.session.state()["position_steps"] == st["position_steps"]:
            assert time.monotonic() < deadline, "the board never moved"
            time.sleep(0.01)
        assert s.call("POST", "/api/estop", {})[0] == 200
        st = s.wait_idle(20)
        assert st["last"]["status"] == "emergency-stopped", st["last"]
        assert "hole" in st["last"]["messages"][0] and "stop" in st["last"]["messages"][0].lower(), st["last"]
        assert any("EMERGENCY STOP" in e["text"] for e in st["log"])
    finally:
        s.close()
        emu.stop()
    assert emu.error is None


def test_the_page_takes_svg_with_its_options(fast):
    """Issue 16: an SVG upload is an "svg" job; scale and fit come from the page's form fields."""
    svg = (b'<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="20mm" viewBox="0 0 40 20">'
           b'<circle cx="10" cy="10" r="8" stroke="black" fill="none"/></svg>')
    status, up = fast.upload("logo.svg", svg)
    assert status == 200 and up["kind"] == "svg"
    status, planned = fast.call("POST", "/api/plan", {"job": up["job"], "options": {"fit_mm": "32x32",
                                                                                      "cut_depth_mm": "0.3"}})
    assert status == 200 and planned["kind"] == "svg", planned
    assert abs(planned["size_mm"][0] - 32) < 0.1 and abs(planned["size_mm"][1] - 32) < 0.1
    status, bad = fast.call("POST", "/api/plan", {"job": up["job"], "options": {"depth": "3"}})
    assert status == 400 and "does not apply" in str(bad)
    status, info = fast.call("GET", "/api/config")
    assert status == 200 and ".svg" in info["accepted"]["svg"]


@pytest.mark.browser
def test_the_page_traces_a_sketch_and_cuts_what_the_library_traces(page, fast, tmp_path):
    """Issue 16 point 7: a photo of a sketch, traced on the server from the page's "Sketch or photo" box,
    plans the very job the library makes from ``cam.trace``."""
    from cam.digitize.sketch import load_sketch, trace

    sketch = ROOT / "samples" / "sketch.jpg"
    _open(page, fast)
    page.fill("#opt-depth", "2")
    page.check("#opt-trace")
    _load(page, sketch)
    page.wait_for_function("document.getElementById('log').textContent.includes('traced:')")  # live view: soon
    drawing = trace(load_sketch(sketch), source=str(sketch))
    expected = cam.plan_steps(cam.plan(cam.digitize(drawing), depth=2, settings=FAST))
    page.click("#start")
    _wait_done(page, fast)
    assert np.array_equal(fast.session.last_job_pin_log.data, expected.data)  # every write, in order


@pytest.mark.browser
def test_page_resume_job_button_finishes_a_stopped_job_exactly(page, servers):
    """Stop a job from the page, then press Resume job: the two pin logs together carve the drawing exactly
    (issue #15: the page's Resume button after a stop)."""
    s = _medium_at_origin(servers)
    _open(page, s)
    _load(page, SAMPLES / "two_curves.png", depth="2")
    assert page.is_disabled("#resume-job")
    page.click("#start")
    page.wait_for_function("parseFloat(document.getElementById('percent').textContent) > 20")
    page.click("#stop")
    st = s.wait_idle(10)
    assert st["last"]["status"] == "stopped"
    first, stopped_at = s.session.last_job_pin_log, np.array(st["position_steps"], np.int64)
    page.wait_for_function("!document.getElementById('resume-job').disabled")
    page.click("#resume-job")
    page.wait_for_function("document.getElementById('log').textContent.includes('resumed at move')")
    st = s.wait_idle(30)
    assert st["last"]["status"] == FINISHED
    second = s.session.last_job_pin_log
    m1, m2 = cam.decode_pin_log(first, MEDIUM), cam.decode_pin_log(second, MEDIUM)
    both = cam.Motion(np.r_[m1.t_ns, m2.t_ns], np.vstack([m1.position_steps, m2.position_steps + stopped_at]),
                      m1.step_counts + m2.step_counts)
    d = cam.digitize(cam.load_image(SAMPLES / "two_curves.png"))
    surface = cam.carve(both, (d.height_px, d.width_px), MEDIUM)
    want = np.zeros_like(surface)
    for obj in d.objects:
        want[obj[:, 1], obj[:, 0]] = 2 * MEDIUM.steps_per_px_z
    assert np.array_equal(surface, want)
