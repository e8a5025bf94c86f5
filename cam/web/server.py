"""The web server: one machine, one job at a time, controlled from a page (Starlette on uvicorn).

The page (``static/``) talks to a small JSON API under ``/api``; live status
comes as server-sent events (``GET /api/events``).  The server is a thin
adapter: jobs are prepared by :func:`cam.job.jobs.prepare_job` and run by
the :class:`~cam.drive.session.MachineSession` that the CLI and the Python API
use too, on the same ports.

Frames: positions are machine steps ``(x, y, z)`` from the *home*, where the
tool stood when the server started (+Z deeper); a job starts where the tool
stands and is checked against the machine travel from there.

Security:

* it listens on 127.0.0.1 unless told otherwise; any other address needs a
  token (``serve`` makes one), and with a token every ``/api`` request must
  carry it (header ``X-Cam-Token``, ``Authorization: Bearer``, or ``?token=``
  for the event stream and pictures), else 401;
* without a token, requests must name a localhost ``Host`` (no DNS
  rebinding) and a cross-site ``Origin`` is refused (403), so another web
  site open in the same browser cannot drive the machine;
* uploads over the size limit get 413; stored names are reduced to safe
  characters and always land inside the jobs folder;
* a job or jog while another runs gets 409; bad requests get 4xx JSON
  ``{"error": "..."}`` before anything moves.
"""
from __future__ import annotations

import asyncio
import json
import re
import secrets
import socket
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Awaitable, Callable, Optional
from urllib.parse import urlsplit

from ..drive.session import MachineSession
from ..errors import BusyError, CamError, CapabilityError
from ..fileio import atomic_write_bytes
from ..job.jobs import PROFILE_SUFFIXES, JobOptions, PreparedJob, accepted_suffixes, job_kind, prepare_job
from ..settings import DEFAULT_SETTINGS, MachineSettings
from contextlib import asynccontextmanager

__all__ = ["ServerConfig", "HttpError", "create_app", "serve", "LOCAL_HOSTS"]

STATIC_DIR = Path(__file__).resolve().parent / "static"
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
_DRAIN_LIMIT_BYTES = 64 * 1024 * 1024  # read and drop at most this much of a refused upload
_MULTIPART_SLACK_BYTES = 64 * 1024  # form boundaries and headers around the file


@dataclass
class ServerConfig:
    """How the server runs.

    Attributes:
        host, port: where it listens (default 127.0.0.1:8000).
        token: required on every ``/api`` request when set (None = none needed; only for localhost).
        jobs_dir: the folder uploads are stored in (None = a new temporary folder).
        max_upload_bytes: larger uploads get 413.
        settings: the machine settings; machine_port: "mock" or a device such as /dev/parport0.
        realtime: run the mock on the real clock (real ports always are).
    """

    host: str = "127.0.0.1"
    port: int = 8000
    token: Optional[str] = None
    jobs_dir: Optional[str] = None
    max_upload_bytes: int = 50 * 1024 * 1024
    settings: MachineSettings = DEFAULT_SETTINGS
    machine_port: str = "mock"
    realtime: bool = True

    def checked(self) -> "ServerConfig":
        """Refuse a non-local address without a token; returns self."""
        if self.host not in LOCAL_HOSTS and not self.token:
            raise CamError(f"listening on {self.host} needs a token (--token, or let 'cam serve' make one)")
        if self.max_upload_bytes < 1:
            raise CamError(f"the upload limit must be > 0 bytes, got {self.max_upload_bytes}")
        return self


class HttpError(Exception):
    """A request that cannot be served: HTTP ``status`` and a one-line message for the page."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


def safe_name(filename: str) -> str:
    """An uploaded file name reduced to ``[A-Za-z0-9._-]``, no folders, no leading dots, at most 80 chars.

    >>> safe_name("../../etc/pass wd.png"), safe_name("C:\\\\x\\\\..\\\\a b.NGC"), safe_name("...")
    ('pass_wd.png', 'a_b.NGC', 'upload')
    """
    base = re.split(r"[\\/]", filename or "")[-1]
    base = re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip("._")
    if len(base) > 80:
        stem, dot, suffix = base.rpartition(".")
        base = (stem[: 79 - len(suffix)] + dot + suffix) if dot and len(suffix) < 16 else base[:80]
    return base or "upload"


# ----------------------------------------------------------------------------------
# HTTP
# ----------------------------------------------------------------------------------


def _json_error(status: int, message: str):
    from starlette.responses import JSONResponse

    return JSONResponse({"error": message}, status_code=status, headers={"Cache-Control": "no-store"})


def create_app(config: ServerConfig, session: Optional[MachineSession] = None):
    """The Starlette application.  ``app.state.session`` is the :class:`MachineSession`."""
    from starlette.applications import Starlette
    from starlette.formparsers import MultiPartException, MultiPartParser
    from starlette.requests import Request
    from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles
    from starlette.concurrency import run_in_threadpool

    config.checked()
    jobs_dir = Path(config.jobs_dir or tempfile.mkdtemp(prefix="cam-jobs-")).resolve()
    jobs_dir.mkdir(parents=True, exist_ok=True)
    config.jobs_dir = str(jobs_dir)
    session = session or MachineSession(config.machine_port, config.settings, realtime=config.realtime)
    uploads: dict[str, dict[str, Any]] = {}
    prepared: dict[str, PreparedJob] = {}
    previews: dict[str, bytes] = {}
    counter = {"n": 0}
    closing = threading.Event()

    def authorised(request: Request) -> None:
        if config.token:
            given = (request.headers.get("x-cam-token") or request.query_params.get("token") or "")
            auth = request.headers.get("authorization", "")
            if auth.lower().startswith("bearer "):
                given = given or auth[7:].strip()
            if not secrets.compare_digest(given.encode(), config.token.encode()):
                raise HttpError(401, "this server needs its token: open the URL it printed (with ?token=...)")
            return
        host = (request.headers.get("host") or "").rsplit(":", 1)[0].strip("[]").lower()
        if host not in LOCAL_HOSTS:
            raise HttpError(403, f"requests must be addressed to localhost, not {host!r}")
        origin = request.headers.get("origin")
        if origin and origin != "null" and urlsplit(origin).netloc.lower() != (request.headers.get("host") or "").lower():
            raise HttpError(403, f"cross-site request from {origin} refused")

    def api(handler: Callable[[Request], Awaitable[Any]]):
        async def endpoint(request: Request):
            try:
                authorised(request)
                out = await handler(request)
            except HttpError as exc:
                return _json_error(exc.status, exc.message)
            except (BusyError, CapabilityError) as exc:  # the machine cannot do it now, or at all
                return _json_error(409, str(exc))
            except CamError as exc:
                return _json_error(400, str(exc))
            if isinstance(out, Response):
                return out
            return JSONResponse(out, headers={"Cache-Control": "no-store"})

        return endpoint

    async def body_json(request: Request) -> dict[str, Any]:
        raw = await request.body()
        if not raw.strip():
            return {}
        try:
            value = json.loads(raw)
        except (ValueError, UnicodeDecodeError) as exc:
            raise HttpError(400, f"malformed JSON: {exc}") from None
        if not isinstance(value, dict):
            raise HttpError(400, "the request body must be a JSON object")
        return value

    def job_summary(job_id: str, job: PreparedJob) -> dict[str, Any]:
        return {
            "job": job_id, "name": uploads[job_id]["name"], "kind": job.kind, "summary": job.summary,
            "size_mm": list(job.size_mm), "depth_mm": job.depth_mm,
            "estimated_time_s": round(job.estimated_time_s, 3), "warnings": list(job.warnings),
            "tool_changes": list(job.tool_changes), "writes": len(job.steps),
            "preview": f"/api/preview/{job_id}.png?v={counter['n']}",
        }

    # -- routes ----------------------------------------------------------------
    async def index(request: Request):
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    async def get_config(request: Request):
        s = config.settings
        return {
            "port": config.machine_port, "realtime": session.realtime or config.machine_port != "mock",
            "max_upload_bytes": config.max_upload_bytes,
            "accepted": {k: list(v) for k, v in accepted_suffixes().items()},
            "profile_suffixes": list(PROFILE_SUFFIXES),
            "mm_per_step": [s.mm_per_step_xy, s.mm_per_step_xy, s.mm_per_step_z],
            "travel_steps": [list(b) for b in s.travel.bounds_steps()],
            "options": JobOptions().__dict__,
        }

    async def upload(request: Request):
        limit = config.max_upload_bytes
        cap = limit + _MULTIPART_SLACK_BYTES
        length = request.headers.get("content-length")
        too_big = False
        if length is not None:
            try:
                too_big = int(length) > cap
            except ValueError:
                raise HttpError(400, "bad Content-Length") from None
        body = bytearray()
        seen = 0
        async for chunk in request.stream():
            seen += len(chunk)
            if too_big or seen > cap:
                too_big = True
                if seen > cap + _DRAIN_LIMIT_BYTES:
                    break
                continue
            body += chunk
        if too_big:
            return JSONResponse({"error": f"upload too large: the limit is {limit / 1048576:g} MB"}, status_code=413,
                                headers={"Connection": "close"})
        ctype = request.headers.get("content-type", "")
        if not ctype.startswith("multipart/form-data"):
            raise HttpError(400, "upload the file as multipart/form-data (field 'file')")

        async def stream():
            yield bytes(body)

        try:
            form = await MultiPartParser(request.headers, stream(), max_files=1, max_fields=8,
                                         max_part_size=64 * 1024).parse()
        except MultiPartException as exc:
            raise HttpError(400, f"malformed upload: {exc.message}") from None
        item = form.get("file")
        if item is None or isinstance(item, str):
            raise HttpError(400, "no file in the upload (field 'file')")
        role = str(form.get("role") or "job")
        if role not in ("job", "profile"):
            raise HttpError(400, f"role must be 'job' or 'profile', got {role!r}")
        data = await item.read()
        if len(data) > limit:
            return JSONResponse({"error": f"upload too large: the limit is {limit / 1048576:g} MB"}, status_code=413)
        name = safe_name(item.filename or "")
        if role == "job":
            kind = job_kind(name)
        else:
            kind = "profile"
            if Path(name).suffix.lower() not in PROFILE_SUFFIXES:
                raise HttpError(400, f"{name}: a profile is a drawing or a CSV ({' '.join(PROFILE_SUFFIXES)})")
        if not data:
            raise HttpError(400, f"{name}: the file is empty")
        counter["n"] += 1
        job_id = str(counter["n"])
        path = (jobs_dir / f"{int(job_id):04d}-{name}").resolve()
        if path.parent != jobs_dir:  # pragma: no cover - safe_name makes this impossible
            raise HttpError(400, "bad file name")
        await run_in_threadpool(atomic_write_bytes, path, data)
        uploads[job_id] = {"path": str(path), "name": name, "kind": kind, "role": role}
        session.log(f"uploaded {name} ({kind}, {len(data)} bytes)")
        return {"job": job_id, "name": name, "kind": kind, "bytes": len(data)}

    async def plan_job(request: Request):
        body = await body_json(request)
        job_id = str(body.get("job", ""))
        if job_id not in uploads or uploads[job_id]["role"] != "job":
            raise HttpError(404, f"no uploaded job {job_id!r}; upload a file first")
        raw = body.get("options") or {}
        if not isinstance(raw, dict):
            raise HttpError(400, "options must be a JSON object")
        raw = dict(raw)
        profile_id = raw.pop("profile", None)
        if profile_id not in (None, ""):
            ref = uploads.get(str(profile_id))
            if ref is None or ref["role"] != "profile":
                raise HttpError(400, f"no uploaded profile {profile_id!r}")
            raw["profile"] = ref["path"]
        options = JobOptions.from_mapping(raw)
        if session.busy and session.realtime:
            raise HttpError(409, "a job is running: planning now would disturb its step timing; wait for it to end")
        job = await run_in_threadpool(lambda: prepare_job(uploads[job_id]["path"], options, config.settings,
                                                             name=uploads[job_id]["name"]))
        counter["n"] += 1
        prepared.pop(job_id, None)  # re-planned: the newest again, so the last eight planned stay
        prepared[job_id] = job
        previews.pop(job_id, None)
        for old in list(prepared)[:-8]:
            prepared.pop(old, None)
            previews.pop(old, None)
        for w in job.warnings:
            session.log(f"{uploads[job_id]['name']}: {w}", "warning")
        session.log(f"planned {job.summary}; {job.estimated_time_s:.1f} s")
        return job_summary(job_id, job)

    async def preview(request: Request):
        job_id = request.path_params["job"]
        job = prepared.get(job_id)
        if job is None:
            raise HttpError(404, f"job {job_id!r} is not planned")
        if job_id not in previews:
            previews[job_id] = await run_in_threadpool(job.preview_png)
        return Response(previews[job_id], media_type="image/png", headers={"Cache-Control": "no-store"})

    async def start(request: Request):
        body = await body_json(request)
        job_id = str(body.get("job", ""))
        job = prepared.get(job_id)
        if job is None:
            raise HttpError(404 if job_id not in uploads else 409,
                            f"job {job_id!r} is not planned; upload it and set its options first")
        session.start(job, label=f"job {job.name or Path(job.source).name}")
        return session.state()

    def control(fn: Callable[[], None]):
        async def handler(request: Request):
            await body_json(request)
            fn()
            return session.state()

        return handler

    async def emergency_stop(request: Request):
        t = time.monotonic_ns()
        session.emergency_stop(t)
        return {"ok": True}

    async def jog(request: Request):
        body = await body_json(request)
        session.jog(body.get("axis", ""), body.get("steps", 0))
        return session.state()

    async def answer(request: Request):
        body = await body_json(request)
        session.answer(body.get("prompt"), body.get("action", "continue"))
        return session.state()

    async def state(request: Request):
        try:
            after = int(request.query_params.get("log_after", "0"))
        except ValueError:
            raise HttpError(400, "log_after must be a whole number") from None
        return session.state(after)

    async def events(request: Request):
        async def stream():
            last_version = -1
            last_sent = 0.0
            log_after = 0
            while not closing.is_set():
                v = session.version
                now = time.monotonic()
                if v != last_version or now - last_sent > 1.0:
                    snap = session.state(log_after)
                    if snap["log"]:
                        log_after = snap["log"][-1]["seq"]
                    last_version, last_sent = v, now
                    yield f"data: {json.dumps(snap)}\n\n"
                if await request.is_disconnected():
                    break
                await asyncio.sleep(0.1)

        return StreamingResponse(stream(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    async def pinlog(request: Request):
        log = session.last_job_pin_log
        if log is None:
            raise HttpError(404, "no job has run on the mock port yet")
        lines = ["t_ns,data,strobe"]
        lines += [f"{t},{d},{s}" for t, d, s in zip(log.t_ns.tolist(), log.data.tolist(), log.strobe.tolist())]
        return Response("\n".join(lines) + "\n", media_type="text/csv")

    async def not_found(request: Request):
        raise HttpError(404, f"no such API endpoint: {request.method} {request.url.path}")

    def on_shutdown() -> None:
        closing.set()
        session.shutdown()

    routes = [
        Route("/", index),
        Route("/api/config", api(get_config)),
        Route("/api/upload", api(upload), methods=["POST"]),
        Route("/api/plan", api(plan_job), methods=["POST"]),
        Route("/api/preview/{job}.png", api(preview)),
        Route("/api/start", api(start), methods=["POST"]),
        Route("/api/pause", api(control(session.pause)), methods=["POST"]),
        Route("/api/resume", api(control(session.resume)), methods=["POST"]),
        Route("/api/stop", api(control(session.stop)), methods=["POST"]),
        Route("/api/estop", api(emergency_stop), methods=["POST"]),
        Route("/api/jog", api(jog), methods=["POST"]),
        Route("/api/origin", api(control(session.go_to_origin)), methods=["POST"]),
        Route("/api/answer", api(answer), methods=["POST"]),
        Route("/api/state", api(state)),
        Route("/api/events", api(events)),
        Route("/api/pinlog", api(pinlog)),
        Route("/api/{rest:path}", api(not_found), methods=["GET", "POST", "PUT", "DELETE", "PATCH"]),
        Mount("/static", StaticFiles(directory=STATIC_DIR), name="static"),
    ]

    async def security_headers(scope, receive, send):
        async def send_wrapped(message):
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers += [
                    (b"x-content-type-options", b"nosniff"),
                    (b"x-frame-options", b"DENY"),
                    (b"referrer-policy", b"no-referrer"),
                    (b"content-security-policy",
                     b"default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
                     b"connect-src 'self'; frame-ancestors 'none'"),
                ]
                message = {**message, "headers": headers}
            await send(message)

        await inner(scope, receive, send_wrapped)


    @asynccontextmanager
    async def lifespan(app):
        yield
        await run_in_threadpool(on_shutdown)

    inner = Starlette(routes=routes, lifespan=lifespan)
    inner.state.session = session
    inner.state.config = config
    inner.state.closing = closing

    async def app(scope, receive, send):
        if scope["type"] == "http":
            await security_headers(scope, receive, send)
        else:
            await inner(scope, receive, send)

    app.state = inner.state  # type: ignore[attr-defined]
    return app


def lan_address() -> str:
    """This computer's address on the local network (best guess; nothing is sent)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.1", 9))  # TEST-NET-1: routing lookup only, no packet leaves
            return s.getsockname()[0]
    except OSError:
        return socket.gethostname()


def page_url(config: ServerConfig, port: Optional[int] = None) -> str:
    """The URL to open (with the token when there is one)."""
    host = config.host
    if host in ("0.0.0.0", "::", ""):
        host = lan_address()
    if ":" in host:
        host = f"[{host}]"
    url = f"http://{host}:{port or config.port}/"
    return url + (f"?token={config.token}" if config.token else "")


def bind_socket(host: str, port: int) -> socket.socket:
    """A listening TCP socket (CamError naming host:port when it cannot be had)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise CamError(f"cannot listen on {host}:{port} ({exc.strerror or exc})") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


def serve(config: ServerConfig, announce: Callable[[str], None] = print) -> int:
    """Run the server until Ctrl-C; a running job is stopped (tool lifted) on the way out.  Returns 0."""
    import uvicorn

    if config.host not in LOCAL_HOSTS and not config.token:
        config.token = secrets.token_urlsafe(24)
    sock = bind_socket(config.host, config.port)
    try:
        app = create_app(config)
    except BaseException:
        sock.close()
        raise
    port = sock.getsockname()[1]
    ucfg = uvicorn.Config(app, host=config.host, port=port, log_level="warning", access_log=False,
                          timeout_graceful_shutdown=2, lifespan="on")
    server = uvicorn.Server(ucfg)
    mode = "real time" if (config.realtime or config.machine_port != "mock") else "simulated clock"
    announce(f"cam: web page at {page_url(config, port)}")
    announce(f"cam: machine port {config.machine_port} ({mode}); uploads in {config.jobs_dir}; Ctrl-C stops")
    server.run(sockets=[sock])
    return 0
