"""The web server: one machine, one job at a time, controlled from a page (Starlette on uvicorn).

The page (``static/``) talks to a small JSON API under ``/api``; live status
comes as server-sent events (``GET /api/events``).  The server is a thin
adapter: jobs are prepared by :func:`cam.kinds.jobs.prepare_job` and run by
the :class:`~cam.drive.session.MachineSession` that the CLI and the Python API
use too, on the same ports.

The machine comes first: the session's step runner has a thread of its own,
and planning, previews and pin-log exports run in a :class:`~cam.worker.Worker`
process with a time and a memory limit (``--work-time-limit``,
``--work-memory-limit``), so no request and no number of clients holds up a
step write or the emergency stop.  Planning while a job runs is allowed.

Frames: positions are machine steps ``(x, y, z)`` from the *home*, where the
tool stood when the server started (+Z deeper); a job starts where the tool
stands and is checked against the machine travel from there.

Security:

* it listens on 127.0.0.1 unless told otherwise; any other address needs a
  token (``serve`` makes a random one of 128 bits, :func:`new_token`; one
  given must be at least :data:`TOKEN_MIN_CHARS` characters), and with a
  token every ``/api`` request must carry it (header ``X-Cam-Token``,
  ``Authorization: Bearer``, or ``?token=`` for the event stream and
  pictures), else 401;
* requests must name this computer in their ``Host`` (no DNS rebinding):
  without a token a localhost name; with one also an IP address, this
  computer's own name (``NAME``, ``NAME.local``) or a name given by
  ``allowed_hosts`` (``--allow-host``), as a rebinding page would name its
  own site;
* only the page itself may ask (with or without a token): an ``Origin`` header
  must be the server's own origin, ``scheme://host:port`` as the page was
  served (``null``, another port, another site: 403), and so must a browser's
  ``Sec-Fetch-Site`` (``cross-site`` / ``same-site``: 403); a request that
  changes anything (every non-GET under ``/api``) with no ``Origin`` must carry
  a header a cross-site page cannot send without a CORS preflight
  (``X-Requested-With``, ``X-Cam-Token`` or ``Authorization``), else 403; and
  JSON requests must say ``Content-Type: application/json``, uploads
  ``multipart/form-data`` (else 415).  The server never answers a preflight
  (``OPTIONS`` gets 405 and no ``Access-Control-Allow-*``), so another web page
  in the same browser, a sandboxed frame included, cannot drive the machine.
  The emergency stop follows the same rules: a cross-site page could otherwise
  spoil a running job, and the page's own button always qualifies;
* uploads over the size limit get 413; stored names are reduced to safe
  characters and always land inside the jobs folder;
* a job or jog while another runs gets 409; bad requests get 4xx JSON
  ``{"error": "..."}`` before anything moves;
* JSON bodies are limited to 8 kB (413) and 16 levels of nesting (400);
* slow clients and floods cannot keep the emergency stop out (run through :func:`uvicorn_config`, as
  ``serve`` does; the rules are in :mod:`cam.web.connections`): ``POST /api/estop``, ``/api/stop``,
  ``/api/pause`` and ``GET /api/state`` are told from their request line and never refused for load; a
  connection beyond ``max_connections_per_client`` (50) from one address may only ask for those; at most
  ``max_connections`` (100) other requests are in progress (more get 503 JSON); up to
  ``max_open_connections`` (2000) connections are held, and beyond that an idle or half-sent one is closed
  (never one whose unread bytes are an e-stop); a request head must arrive whole within ``header_timeout_s`` (5 s; else
  408 and closed), a body announced over its route's limit gets 413 before any of it is read, and a body
  must come whole within ``body_timeout_s`` (10 s) plus 1 s per 16 kB, pausing at most ``body_timeout_s``;
  an idle connection is closed after 5 s; at most ``max_event_streams`` (16) live event streams at once,
  more get 503.
"""
from __future__ import annotations

import asyncio
import gc
import ipaddress
import json
import math
import re
import secrets
import socket
import tempfile
import threading
import time
from contextlib import asynccontextmanager
from dataclasses import dataclass, field, replace
from functools import lru_cache, partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Awaitable, Callable, Optional

import numpy as np

try:
    import resource
except ImportError:  # pragma: no cover - not Unix: no file limit to raise
    resource = None  # type: ignore[assignment]

from ..drive.journal import read_journal
from ..drive.machines import DEFAULT_PORT, can
from ..drive.probing import job_area_mm
from ..drive.placement import placed_kinds, placed_home
from ..drive.session import MachineSession
from ..drive.track import (TABLE_UNITS, drill_holes, hole_states, hole_writes, job_track, job_units,
                           remaining_time_s, start_at_hole, to_job_units)
from ..drive.state import MachineState, StateHold, machine_record
from ..errors import BusyError, CamError, CapabilityError, StalePlanError
from ..fileio import atomic_write_bytes
from ..sniff import HEAD_BYTES
from ..kinds import kinds_json, schema_json
from ..kinds.jobs import PROFILE_SUFFIXES, JobOptions, PreparedJob, accepted_suffixes, job_kind
from ..machine_file import backup_path, list_settings, machine_file_of, save_settings
from ..settings import DEFAULT_SETTINGS, MachineSettings
from ..tool_table import (TABLE_SHAPES, job_tool_warnings, read_tool_table, tool_from_mapping, tool_table_path,
                          write_tool_table)
from ..worker import DEFAULT_TIME_LIMIT_S, Worker, default_memory_limit_bytes
from .connections import ConnectionGuard, guarded_h11, is_safety_route
from .work import (
    WARM_UP, height_map_png, pin_log_csv, plan_with_preview, preview_of, resumed_from_journal, save_pin_log_raw,
)

if TYPE_CHECKING:
    from starlette.requests import Request

__all__ = ["ServerConfig", "HttpError", "create_app", "uvicorn_config", "serve", "new_token", "is_loopback",
           "LOCAL_HOSTS", "TOKEN_MIN_CHARS"]

STATIC_DIR = Path(__file__).resolve().parent / "static"
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
TOKEN_MIN_CHARS = 16
"""A token given to the server must be at least this long (a short one can be guessed)."""
_DRAIN_LIMIT_BYTES = 64 * 1024 * 1024  # read and drop at most this much of a refused upload
_MAX_JSON_BYTES = 8 * 1024  # a JSON request body (the largest, planning options, is well under 1 kB)
_MAX_JSON_DEPTH = 16  # arrays and objects inside each other (the requests use 3)
_MULTIPART_SLACK_BYTES = 64 * 1024  # form boundaries and headers around the file
_BACKLOG = 2048  # connections the kernel holds for accept (a reconnect flood must not crowd the e-stop out)
_EVENT_PERIOD_S = 0.15  # live views get a snapshot about 6 times a second while something runs (issue #47 point 1:
# the live track at least 5 times a second), at most that often


@dataclass
class ServerConfig:
    """How the server runs.

    Attributes:
        host, port: where it listens (default 127.0.0.1:8000).
        token: required on every ``/api`` request when set (None = none needed; only for localhost); at least
            :data:`TOKEN_MIN_CHARS` characters (:func:`new_token` makes one).
        allowed_hosts: ``Host`` names accepted besides localhost, IP addresses and this computer's own name
            (with a token only; a reverse proxy's or a DNS name for this computer).
        jobs_dir: the folder uploads are stored in (None = a new temporary folder).
        max_upload_bytes: larger uploads get 413.
        settings: the machine settings; machine_port: a port name (:mod:`cam.drive.machines`; the mock by default).
        realtime: run the mock on the real clock (real ports always are).
        max_connections: requests in progress at once (safety routes aside); max_connections_per_client:
            connections from one client address beyond which a new one may only ask for a safety route;
            max_open_connections: connections held at once (beyond, idle and half-sent ones are closed); see
            :mod:`cam.web.connections`.  max_event_streams: live event streams at once (more get 503).
        header_timeout_s: a request head must arrive whole within this time of the connection opening or
            the previous answer (else 408, closed); body_timeout_s: the longest pause inside a request body.
        work_time_limit_s, work_memory_limit_bytes: the limits of one planning, preview or pin-log export,
            which run in a worker process apart from the machine (None: half the memory, at most 8 GiB).
        state_file: the machine state file (:mod:`cam.drive.state`), locked while the server runs: the page
            works in the machine and work frames, jobs are placed at the work zero, every end is recorded
            (``cam serve`` passes the machine's default one).  None: no file; the home is where the tool stands
            when the server starts.
        machine_file, machine_changed: the machine file the settings came from ("": the built-in settings;
            None: not said, nothing checked) and whether the user says the machine on the port changed: the
            state file records it, and on a real port refuses another one than it records unless changed
            (:class:`~cam.drive.state.StateHold`).  On a real port the device itself is locked too.
    """

    host: str = "127.0.0.1"
    port: int = 8000
    token: Optional[str] = None
    allowed_hosts: tuple[str, ...] = ()
    jobs_dir: Optional[str] = None
    max_upload_bytes: int = 50 * 1024 * 1024
    settings: MachineSettings = DEFAULT_SETTINGS
    machine_port: str = DEFAULT_PORT
    realtime: bool = True
    max_connections: int = 100
    max_connections_per_client: int = 50
    max_open_connections: int = 2000
    max_event_streams: int = 16
    header_timeout_s: float = 5.0
    body_timeout_s: float = 10.0
    work_time_limit_s: float = DEFAULT_TIME_LIMIT_S
    work_memory_limit_bytes: Optional[int] = None
    state_file: Optional[str] = None
    machine_file: Optional[str] = None
    machine_changed: bool = False

    def checked(self) -> "ServerConfig":
        """Refuse a non-local address without a token, and a short token; returns self."""
        if not is_loopback(self.host) and not self.token:
            raise CamError(f"listening on {self.host} needs a token (--token, or let 'cam serve' make one)")
        if self.token is not None and len(self.token) < TOKEN_MIN_CHARS:
            raise CamError(f"--token must be at least {TOKEN_MIN_CHARS} characters, got {len(self.token)} (a short "
                           "one can be guessed); leave it out and 'cam serve' makes a random one")
        if self.allowed_hosts and not self.token:
            raise CamError("--allow-host needs a token: without one only localhost names are served")
        if self.max_upload_bytes < 1:
            raise CamError(f"the upload limit must be > 0 bytes, got {self.max_upload_bytes}")
        for name in ("max_connections", "max_connections_per_client", "max_open_connections", "max_event_streams", "header_timeout_s", "body_timeout_s",
                     "work_time_limit_s"):
            if not getattr(self, name) > 0:
                raise CamError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.max_event_streams >= self.max_connections:
            raise CamError(f"max_event_streams ({self.max_event_streams}) must be below max_connections "
                           f"({self.max_connections}), or the live views could take every connection")
        return self


class HttpError(Exception):
    """A request that cannot be served: HTTP ``status``, a one-line message for the page, extra headers."""

    def __init__(self, status: int, message: str, headers: Optional[dict[str, str]] = None) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
        self.headers = headers


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
# HTTP: the routes are module-level functions over one _AppState
# ----------------------------------------------------------------------------------


@dataclass
class _AppState:
    """What the routes share: the configuration, the machine session, and the uploaded and planned jobs.

    Job ids are the upload counter's values as strings; the counter also moves on at every planning,
    so a preview URL changes when its job is planned again.
    """

    config: ServerConfig
    session: MachineSession
    jobs_dir: Path
    worker: Worker  # planning, previews and pin-log exports: never in the machine's process
    uploads: dict[str, dict[str, Any]] = field(default_factory=dict)  # id -> path, name, kind, role
    prepared: dict[str, PreparedJob] = field(default_factory=dict)  # the last eight planned, oldest first
    plan_options: dict[str, JobOptions] = field(default_factory=dict)  # id -> the options it was planned with
    plan_maps: dict[str, Any] = field(default_factory=dict)  # id -> the page's height map it was planned after
    previews: dict[str, bytes] = field(default_factory=dict)  # id -> PNG
    counter: int = 0
    last_job: Optional[str] = None  # the id of the job started last (the Resume job button resumes it)
    streams: int = 0  # live event streams now
    pin_log_csv: Optional[tuple[Any, Path]] = None  # (the pin log, its exported CSV)
    broadcast: Any = None  # the _Broadcast of the live views (made with the state)
    track: dict[str, Any] = field(default_factory=dict)  # the live track's (issue #47): see _track_extra

    def __post_init__(self) -> None:
        self.broadcast = _Broadcast(self.session, self.closing, partial(_track_extra, self))
    closing: threading.Event = field(default_factory=threading.Event)

    def shut_down(self) -> None:
        """End the event streams and the worker, stop whatever runs (tool lifted) and wait for it."""
        self.closing.set()
        self.worker.close()
        self.session.shutdown()
        if self.session.state_hold is not None:
            self.session.state_hold.close()


Handler = Callable[[_AppState, "Request"], Awaitable[Any]]
"""A route: (app state, request) -> a JSON-able value or a Starlette response."""

_SECURITY_HEADERS = [
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"same-origin"),  # the page's own POSTs carry its Origin, never null
    (b"content-security-policy",
     b"default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
     b"connect-src 'self'; frame-ancestors 'none'"),
]
"""Added to every HTTP response."""


def _json_error(status: int, message: str, headers: Optional[dict[str, str]] = None):
    from starlette.responses import JSONResponse

    return JSONResponse({"error": message}, status_code=status,
                        headers={"Cache-Control": "no-store", **(headers or {})})


def _too_large(limit_bytes: int, headers: Optional[dict[str, str]] = None):
    from starlette.responses import JSONResponse

    return JSONResponse({"error": f"upload too large: the limit is {limit_bytes / 1048576:g} MB"}, status_code=413,
                        headers=headers)


_SAFE_METHODS = ("GET", "HEAD")
"""Methods that change nothing; every other method under ``/api`` changes the machine or the jobs."""
_CUSTOM_HEADERS = ("x-requested-with", "x-cam-token", "authorization")
"""A request with one of these was not sent by a cross-site page: the browser would ask first (preflight)."""


def _own_origin(request: Request) -> str:
    """``scheme://host[:port]`` of the page, as the browser addressed it (its ``Host`` header)."""
    return f"{request.url.scheme}://{(request.headers.get('host') or '').lower()}"


def new_token() -> str:
    """A random token of 128 bits (22 URL-safe characters), as ``cam serve`` makes for a non-local address."""
    return secrets.token_urlsafe(16)


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a listening address) reaches this computer only: localhost or a loopback address."""
    if host.lower() in LOCAL_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@lru_cache(maxsize=1)
def _own_names() -> frozenset[str]:
    """This computer's own names, as a browser on the network may address it (no DNS lookup)."""
    name = socket.gethostname().lower()
    short = name.split(".", 1)[0]
    return frozenset(n for n in (name, short, f"{short}.local") if n)


def _check_host(config: ServerConfig, host_header: str) -> None:
    """HttpError 403 unless the ``Host`` names this computer (no DNS rebinding, with or without a token).

    Without a token: localhost or a loopback address.  With one also an IP address (a page served from an address is this
    server's own page, a rebinding page names its own site), this computer's own name, or one of
    ``config.allowed_hosts``."""
    host = host_header.lower()
    host = host[1:].split("]", 1)[0] if host.startswith("[") else host.rsplit(":", 1)[0]
    if host and is_loopback(host):  # localhost, 127.x.y.z, ::1
        return
    if config.token:
        try:
            ipaddress.ip_address(host)
            return
        except ValueError:
            pass
        if host in _own_names() or host in (h.lower() for h in config.allowed_hosts):
            return
        raise HttpError(403, f"requests must be addressed to this computer (an IP address, localhost or "
                             f"{sorted(_own_names())[0] if _own_names() else 'its name'}), not {host!r}; "
                             "another name needs --allow-host")
    raise HttpError(403, f"requests must be addressed to localhost, not {host!r}")


def _authorise(config: ServerConfig, request: Request) -> None:
    """A ``Host`` naming this computer (:func:`_check_host`), the token when the server has one; then only the
    page itself (HttpError).

    The page itself: an ``Origin`` equal to :func:`_own_origin`, no ``Sec-Fetch-Site`` naming another
    site, and for a request that changes anything with no ``Origin``, one of :data:`_CUSTOM_HEADERS`.
    """
    headers = request.headers
    _check_host(config, headers.get("host") or "")
    if config.token:
        given = (headers.get("x-cam-token") or request.query_params.get("token") or "")
        auth = headers.get("authorization", "")
        if auth.lower().startswith("bearer "):
            given = given or auth[7:].strip()
        if not secrets.compare_digest(given.encode(), config.token.encode()):
            raise HttpError(401, "this server needs its token: open the URL it printed (with ?token=...)")
    origin = headers.get("origin")
    if origin is not None and origin.lower() != _own_origin(request):
        raise HttpError(403, f"cross-site request from {origin} refused: only the page at "
                             f"{_own_origin(request)}/ may use this server")
    site = headers.get("sec-fetch-site", "").lower()
    if site in ("cross-site", "same-site"):
        raise HttpError(403, f"{site} request refused: only the page at {_own_origin(request)}/ may use this server")
    if request.method not in _SAFE_METHODS and origin is None and not any(h in headers for h in _CUSTOM_HEADERS):
        raise HttpError(403, "a request that changes anything needs the page's Origin or the header "
                             "X-Requested-With (e.g. curl -H 'X-Requested-With: cam')")


def _check_content_type(request: Request, wanted: str) -> None:
    """HttpError 415 unless the request's media type is ``wanted`` (parameters such as charset allowed)."""
    given = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if given != wanted:
        raise HttpError(415, f"send {wanted} (Content-Type: {wanted}), not {given or 'no content type'}")


def _api(st: _AppState, handler: Handler, *, body: Optional[str] = None) -> Callable[[Request], Awaitable[Any]]:
    """A Starlette endpoint: authorise, check the body's content type (``body``, e.g. "application/json";
    None: no body expected), run ``handler``, turn errors into JSON (401/403/415/4xx, 409 busy)."""
    from starlette.requests import ClientDisconnect
    from starlette.responses import JSONResponse, Response

    async def endpoint(request: Request):
        try:
            _authorise(st.config, request)
            if body is not None:
                _check_content_type(request, body)
            out = await handler(st, request)
        except HttpError as exc:
            return _json_error(exc.status, exc.message, exc.headers)
        except (BusyError, CapabilityError) as exc:  # the machine cannot do it now, or at all
            return _json_error(409, str(exc))
        except CamError as exc:
            return _json_error(400, str(exc))
        except ClientDisconnect:  # gone (or cut off by a deadline) before its body came whole: no one to answer
            return Response(status_code=400)
        if isinstance(out, Response):
            return out
        return JSONResponse(out, headers={"Cache-Control": "no-store"})

    return endpoint


def _json_depth(text: str) -> int:
    """How deep arrays and objects nest in the JSON ``text`` (brackets inside strings do not count).

    >>> _json_depth('{"a": [1, {"b": "[[["}]}'), _json_depth('3'), _json_depth('[[[]]]')
    (3, 0, 3)
    """
    depth = deepest = 0
    for bracket in re.findall(r"[\[\]{}]", re.sub(r'"(?:[^"\\]|\\.)*"', '""', text)):
        depth += 1 if bracket in "[{" else -1
        deepest = max(deepest, depth)
    return deepest


async def _body_json(request: Request) -> dict[str, Any]:
    """The request's JSON object ({} for an empty body); HttpError 413 when over :data:`_MAX_JSON_BYTES`,
    400 when nested deeper than :data:`_MAX_JSON_DEPTH` or not a JSON object."""
    raw = await _read_capped(request, _MAX_JSON_BYTES, drain_bytes=1024 * 1024)
    if raw is None:
        raise HttpError(413, f"request body too large: JSON requests are limited to {_MAX_JSON_BYTES // 1024} kB",
                        {"Connection": "close"})
    if not raw.strip():
        return {}
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise HttpError(400, f"malformed JSON: not UTF-8 ({exc.reason} at byte {exc.start})") from None
    if _json_depth(text) > _MAX_JSON_DEPTH:
        raise HttpError(400, f"JSON nested too deep: at most {_MAX_JSON_DEPTH} levels of arrays and objects")
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise HttpError(400, f"malformed JSON: {exc}") from None
    if not isinstance(value, dict):
        raise HttpError(400, "the request body must be a JSON object")
    return value


def _job_summary(st: _AppState, job_id: str, job: PreparedJob) -> dict[str, Any]:
    return {
        "job": job_id, "name": st.uploads[job_id]["name"], "kind": job.kind, "summary": job.summary,
        "size_mm": list(job.size_mm), "depth_mm": job.depth_mm,
        "estimated_time_s": round(job.estimated_time_s, 3), "warnings": list(job.warnings),
        "tool_changes": list(job.tool_changes), "writes": len(job.plan),
        "tool": job.report.get("tool"), "line_width_mm": job.report.get("line_width_mm"),
        "preview": f"/api/preview/{job_id}.png?v={st.counter}",
    }


# -- routes ------------------------------------------------------------------------


async def _index(request: Request):
    from starlette.responses import FileResponse

    return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})


async def _get_config(st: _AppState, request: Request) -> dict[str, Any]:
    config = st.config
    s = config.settings
    return {
        "port": config.machine_port, "realtime": st.session.realtime,
        "max_upload_bytes": config.max_upload_bytes,
        "accepted": {k: list(v) for k, v in accepted_suffixes().items()},
        "profile_suffixes": list(PROFILE_SUFFIXES),
        "mm_per_step": list(s.mm_per_step_axes),
        "travel_steps": [list(b) for b in s.travel.bounds_steps()],
        "options": JobOptions().__dict__,
    }


async def _get_options(st: _AppState, request: Request) -> list[dict[str, Any]]:
    """``GET /api/options``: the job options' schema (:func:`cam.kinds.schema_json`): each option's name, label,
    group, flag, type, unit, range, choices, the file kinds it applies to, its default on each of them
    (:func:`cam.kinds.kind_defaults`) and help; the page makes its job-options form from it (issue #47
    point 6)."""
    return schema_json()


async def _get_kinds(st: _AppState, request: Request) -> list[dict[str, Any]]:
    """``GET /api/kinds``: the file kinds (:func:`cam.kinds.kinds_json`): the page's "Read as" list and the
    names it shows come from it, so a new kind (one module of :mod:`cam.kinds`) is on the page with no page code."""
    return kinds_json()


async def _read_capped(request: Request, cap_bytes: int, *, drain_bytes: int = _DRAIN_LIMIT_BYTES) -> Optional[bytes]:
    """The request body, or None when it is longer than ``cap_bytes``.

    A body announced or found too long is read on (up to ``drain_bytes`` past the cap) and dropped, so the
    client gets to read the answer.
    """
    length = request.headers.get("content-length")
    too_big = False
    if length is not None:
        try:
            too_big = int(length) > cap_bytes
        except ValueError:
            raise HttpError(400, "bad Content-Length") from None
    body = bytearray()
    seen = 0
    async for chunk in request.stream():
        seen += len(chunk)
        if too_big or seen > cap_bytes:
            too_big = True
            if seen > cap_bytes + drain_bytes:
                break
            continue
        body += chunk
    return None if too_big else bytes(body)


async def _parse_upload(request: Request, body: bytes) -> tuple[Any, str]:
    """The uploaded file of a multipart ``body`` and its role ("job" or "profile"); HttpError 400 otherwise."""
    from starlette.formparsers import MultiPartException, MultiPartParser

    async def stream():
        yield body

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
    return item, role


def _upload_kind(name: str, role: str, data: bytes = b"", warnings: Optional[list[str]] = None) -> str:
    """The job kind of an uploaded file by its name and first bytes (a drill file named ``.TXT`` too), or
    "profile"; HttpError 400 for a profile of another suffix."""
    if role == "job":
        return job_kind(name, warnings, head=data[:HEAD_BYTES])
    if Path(name).suffix.lower() not in PROFILE_SUFFIXES:
        raise HttpError(400, f"{name}: a profile is a drawing or a CSV ({' '.join(PROFILE_SUFFIXES)})")
    return "profile"


async def _upload(st: _AppState, request: Request):
    from starlette.concurrency import run_in_threadpool

    limit = st.config.max_upload_bytes
    body = await _read_capped(request, limit + _MULTIPART_SLACK_BYTES)
    if body is None:
        return _too_large(limit, {"Connection": "close"})
    item, role = await _parse_upload(request, body)
    data = await item.read()
    if len(data) > limit:
        return _too_large(limit)
    name = safe_name(item.filename or "")
    if not data:
        _upload_kind(name, role)  # a bad name first
        raise HttpError(400, f"{name}: the file is empty")
    kind_warnings: list[str] = []
    kind = _upload_kind(name, role, data, kind_warnings)
    st.counter += 1
    job_id = str(st.counter)
    path = (st.jobs_dir / f"{int(job_id):04d}-{name}").resolve()
    if path.parent != st.jobs_dir:  # pragma: no cover - safe_name makes this impossible
        raise HttpError(400, "bad file name")
    await run_in_threadpool(atomic_write_bytes, path, data)
    st.uploads[job_id] = {"path": str(path), "name": name, "kind": kind, "role": role}
    st.session.log(f"uploaded {name} ({kind}, {len(data)} bytes)")
    for w in kind_warnings:
        st.session.log(w, "warning")
    return {"job": job_id, "name": name, "kind": kind, "bytes": len(data)}


def _job_options(st: _AppState, raw: Any) -> JobOptions:
    """The planning options of a request (a profile named by its upload id becomes its path)."""
    if not isinstance(raw, dict):
        raise HttpError(400, "options must be a JSON object")
    raw = dict(raw)
    profile_id = raw.pop("profile", None)
    if profile_id not in (None, ""):
        ref = st.uploads.get(str(profile_id))
        if ref is None or ref["role"] != "profile":
            raise HttpError(400, f"no uploaded profile {profile_id!r}")
        raw["profile"] = ref["path"]
    return JobOptions.from_mapping(raw)


async def _plan_job(st: _AppState, request: Request) -> dict[str, Any]:
    body = await _body_json(request)
    job_id = str(body.get("job", ""))
    if job_id not in st.uploads or st.uploads[job_id]["role"] != "job":
        raise HttpError(404, f"no uploaded job {job_id!r}; upload a file first")
    options = _job_options(st, body.get("options") or {})
    job = await _plan(st, job_id, options)
    job.warnings += job_tool_warnings(job, read_tool_table(_tools_path(st)))  # the machine's tool table (#47)
    for w in job.warnings:
        st.session.log(f"{st.uploads[job_id]['name']}: {w}", "warning")
    st.session.log(f"planned {job.summary}; {job.estimated_time_s:.1f} s")
    return _job_summary(st, job_id, job)


def _planning_state(session: MachineSession) -> MachineState:
    """The machine state a job is planned in (issue #43 point 6): the state file's work offsets, or without one
    the session's frame (offsets at its home), with the tool where the session has it now (a G-code program runs
    from there, as ``cam drill`` plans it)."""
    here = tuple(int(v) for v in session.position_steps())
    st = session.state_hold.state if session.state_hold is not None else MachineState()
    return replace(st, position_steps=here)


async def _plan(st: _AppState, job_id: str, options: JobOptions) -> PreparedJob:
    """Plan upload ``job_id`` with ``options`` in the worker, in the machine state now (:func:`_planning_state`),
    and keep it (with its options and preview) as the job's plan."""
    from starlette.concurrency import run_in_threadpool

    upload = st.uploads[job_id]
    options = _levelled(st, options)
    job, png = await run_in_threadpool(st.worker.call, plan_with_preview, upload["path"], options,
                                       st.config.settings, upload["name"], _planning_state(st.session),
                                       what=f"planning {upload['name']}")
    st.counter += 1
    st.prepared.pop(job_id, None)  # re-planned: the newest again, so the last eight planned stay
    st.prepared[job_id] = job
    st.plan_options[job_id] = options
    st.plan_maps[job_id] = st.session.last_map
    st.previews[job_id] = png
    for old in list(st.prepared)[:-8]:
        st.prepared.pop(old, None)
        st.previews.pop(old, None)
        st.plan_options.pop(old, None)
        st.plan_maps.pop(old, None)
    return job


# -- probing (issue #46 point 5): thin adapters over the session's probe methods ------------------------------

def _height_map_path(st: _AppState) -> Path:
    """Where the page's Probe the job's area writes its height map (with the uploads)."""
    return st.jobs_dir / "height-map.json"


def _levelled(st: _AppState, options: JobOptions) -> JobOptions:
    """``options`` levelled to the map the page probed last (:meth:`MachineSession.probe_map` wrote it), when it
    did; a job planned after Probe the job's area is levelled to it."""
    path = str(_height_map_path(st))
    if options.level == path and st.session.last_map_path != path:  # planned with the map the page forgot since
        return replace(options, level=None)
    if st.session.last_map_path != path or options.level:
        return options
    return replace(options, level=path)


def _mm_field(body: dict[str, Any], key: str, default: Optional[float]) -> Optional[float]:
    value = body.get(key, default)
    if value is None or value == "":
        return default
    try:
        number = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan
    except OverflowError:
        number = math.nan
    if not math.isfinite(number):
        raise HttpError(400, f"{key} must be a number of mm, got {str(json.dumps(value))[:40]}")
    return number


async def _probe_z(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"plate_mm": 0}``: Probe Z (``cam probe z``): the work Z zero on the surface, the plate below the
    contact, set when the probe finishes."""
    body = await _body_json(request)
    st.session.probe_work_z(_mm_field(body, "plate_mm", 0.0), wait=False)
    return st.session.state()


async def _probe_tool(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"plate_mm": null}``: Probe tool (``cam probe tool``) after a tool change."""
    body = await _body_json(request)
    st.session.probe_tool(_mm_field(body, "plate_mm", None), wait=False)
    return st.session.state()


async def _probe_area(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"job": id, "spacing_mm": 10, "margin_mm": 0}``: Probe the job's area (``cam probe grid --over``): a
    height map over where the planned job cuts, which the jobs planned after it are levelled to."""
    body = await _body_json(request)
    job_id = str(body.get("job", ""))
    job = st.prepared.get(job_id)
    if job is None:
        raise HttpError(409, "no planned job to probe the area of: load a file first")
    session = st.session
    session.backend.require(session.port, "probes", "probing")
    area = job_area_mm(job, _planning_state(session), st.config.settings)
    out = _height_map_path(st)
    session.probe_map(area, out, spacing_mm=_mm_field(body, "spacing_mm", 10.0),
                      margin_mm=_mm_field(body, "margin_mm", 0.0),
                      machine=str(Path(st.config.machine_file).resolve()) if st.config.machine_file else None,
                      wait=False)
    return session.state()


async def _forget_height_map(st: _AppState, request: Request) -> dict[str, Any]:
    """``{}``: Forget the height map (:meth:`MachineSession.forget_map`): the jobs started from now on are not
    levelled (a planned job is planned again without it when started); its picture is gone (404)."""
    await _body_json(request)
    st.session.forget_map()
    return st.session.state()


async def _height_map(st: _AppState, request: Request):
    """The PNG of the page's height map with the job (``?job=ID``, planned) over it where it would run."""
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import Response

    path = _height_map_path(st)
    if st.session.last_map_path != str(path) or not path.is_file():
        raise HttpError(404, "no height map yet: Probe the job's area first")
    job = st.prepared.get(request.query_params.get("job", ""))
    png = await run_in_threadpool(st.worker.call, height_map_png, str(path), job, _planning_state(st.session),
                                  st.config.settings, what="the height map's picture")
    return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})


async def _preview(st: _AppState, request: Request):
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import Response

    job_id = request.path_params["job"]
    job = st.prepared.get(job_id)
    if job is None:
        raise HttpError(404, f"job {job_id!r} is not planned")
    if job_id not in st.previews:
        st.previews[job_id] = await run_in_threadpool(st.worker.call, preview_of, job,
                                                      what=f"the preview of {job.name or job_id}")
    return Response(st.previews[job_id], media_type="image/png", headers={"Cache-Control": "no-store"})


async def _start(st: _AppState, request: Request) -> dict[str, Any]:
    """Start a planned job.  A plan holds for the machine state it was made in (issue #43 point 6): planned before a
    jog, a Go To or a new work zero, the job is planned again from where the tool stands now (with the same options,
    as ``cam drill`` would plan it) and that plan runs; the answer then carries it as ``planned``."""
    body = await _body_json(request)
    job_id = str(body.get("job", ""))
    job = st.prepared.get(job_id)
    if job is None:
        raise HttpError(404 if job_id not in st.uploads else 409,
                        f"job {job_id!r} is not planned; upload it and set its options first")
    replanned = None
    page_map = str(_height_map_path(st))
    if st.session.last_map is not st.plan_maps.get(job_id) and page_map in (st.session.last_map_path,
                                                                            st.plan_options[job_id].level):
        st.session.log(f"{job.name or job_id}: planned again, " + ("levelled to the height map probed since"
                       if st.session.last_map_path == page_map else "not levelled: the height map was forgotten"))
        job = await _plan(st, job_id, st.plan_options[job_id])  # levelled to it, or no more (_levelled)
        replanned = _job_summary(st, job_id, job)
    try:
        _start_planned(st, job_id, job)
    except StalePlanError as exc:
        st.session.log(f"{exc.args[0].split(':')[0]}: planned again from where the tool stands now")
        job = await _plan(st, job_id, st.plan_options[job_id])
        try:
            _start_planned(st, job_id, job)
        except StalePlanError as again:  # the machine moved again meanwhile
            raise HttpError(409, str(again)) from None
        replanned = _job_summary(st, job_id, job)
    out = st.session.state()
    if replanned is not None:
        out["planned"] = replanned
    return out


def _start_planned(st: _AppState, job_id: str, job: PreparedJob) -> None:
    home = _job_home(st, job)  # the live track's (issue #47): where the job runs, before anything moves
    st.session.start(job, label=f"job {job.name or Path(job.source).name}", journal=str(_journal_path(st, job_id)))
    st.last_job = job_id
    _track_started(st, job_id, job, home)


def _journal_path(st: _AppState, job_id: str) -> Path:
    """Where the page's runs of a planned job keep their journal (with the uploads)."""
    return st.jobs_dir / f"job-{job_id}.journal.json"


async def _resume_job(st: _AppState, request: Request) -> dict[str, Any]:
    """Resume the last job started after its stop (the page's Resume job button), from where the tool stands:
    the same library call as ``cam drill --resume`` (:func:`cam.kinds.jobs.resume_job`), in the worker."""
    from starlette.concurrency import run_in_threadpool

    body = await _body_json(request)
    job_id = str(body.get("job") or st.last_job or "")
    job = st.prepared.get(job_id)
    path = _journal_path(st, job_id)
    if job is None or not path.is_file():
        raise HttpError(409, "no stopped job to resume: start a job first")
    journal = read_journal(path)
    where = tuple(int(v) - int(h) for v, h in zip(st.session.position_steps(), journal.home_steps))
    resumed = await run_in_threadpool(st.worker.call, resumed_from_journal, job, str(path), where,
                                      what=f"resuming {job.name or job_id}")
    st.session.start(resumed, label=f"job {job.name or Path(job.source).name} (resumed at move "
                     f"{resumed.report['resumed_at_move']})", journal=str(path))
    return st.session.state()


async def _control(st: _AppState, request: Request, *, action: Callable[[], None]) -> dict[str, Any]:
    """Pause, resume, stop or go to the origin (``action``, a session method); the new state."""
    await _body_json(request)
    action()
    return st.session.state()


async def _emergency_stop(st: _AppState, request: Request) -> dict[str, Any]:
    t = time.monotonic_ns()
    st.session.emergency_stop(t)
    return {"ok": True}


async def _jog(st: _AppState, request: Request) -> dict[str, Any]:
    body = await _body_json(request)
    st.session.jog(body.get("axis", ""), body.get("steps", 0), body.get("unit", "steps"))
    return st.session.state()


async def _zero(st: _AppState, request: Request) -> dict[str, Any]:
    body = await _body_json(request)
    st.session.zero(body.get("axes", "XYZ"), body.get("offset") or None)
    return st.session.state()


async def _goto(st: _AppState, request: Request) -> dict[str, Any]:
    body = await _body_json(request)
    st.session.go_to(body.get("xyz"), body.get("unit", "mm"), machine_coords=body.get("machine", False))
    return st.session.state()


async def _set_position(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"xyz": [x, y, z], "unit": "mm" | "steps"}``: where the tool stands, machine frame (the page's Set
    position, ``cam where --set``): after an emergency stop or a limit stop the position is known again, no restart
    (issue #45 point 3).  The session checks the numbers."""
    body = await _body_json(request)
    st.session.set_position(body.get("xyz"), body.get("unit", "mm"), name="xyz")
    return st.session.state()


async def _use_offset(st: _AppState, request: Request) -> dict[str, Any]:
    body = await _body_json(request)
    st.session.use_offset(body.get("offset", ""))
    return st.session.state()


async def _feed_override(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"percent": 10..200}``: the feed override of a grbl board (its real-time override bytes); the session
    checks the number."""
    body = await _body_json(request)
    st.session.feed_override(body.get("percent"))
    return st.session.state()


async def _drill_z(st: _AppState, request: Request) -> dict[str, Any]:
    """Z Drill Up / Down (``which``) of a MAXIMUS board from where the head stands."""
    body = await _body_json(request)
    st.session.set_drill_z(body.get("which", ""))
    _keep_drill_z(st)
    return st.session.state()


async def _answer(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"prompt": id, "action": "continue" | "stop" | "probe-tool", "plate_mm": null}``: answer the prompt; at a
    tool change that offers it, "probe-tool" probes the new tool while the job waits (the dialog's Probe tool:
    :meth:`MachineSession.probe_tool_at_prompt`, ``plate_mm`` null the recorded plate), then the prompt asks
    again."""
    body = await _body_json(request)
    action = body.get("action", "continue")
    if action == "probe-tool":
        st.session.probe_tool_at_prompt(body.get("prompt"), _mm_field(body, "plate_mm", None))
    else:
        st.session.answer(body.get("prompt"), action)
    return st.session.state()


async def _state(st: _AppState, request: Request) -> dict[str, Any]:
    try:
        after = int(request.query_params.get("log_after", "0"))
    except ValueError:
        raise HttpError(400, "log_after must be a whole number") from None
    return _track_extra(st, st.session.state(after))


class _Broadcast:
    """One snapshot of the machine for every live view: made once per change (at most every
    :data:`_EVENT_PERIOD_S`, at least every second) and sent to all, so the cost of a snapshot does not grow
    with the number of pages."""

    def __init__(self, session: MachineSession, closing: threading.Event,
                 extra: Optional[Callable[[dict[str, Any]], dict[str, Any]]] = None) -> None:
        self.session, self.closing = session, closing
        self.extra = extra or (lambda snap: snap)  # what the server adds to a snapshot (the job's own units)
        self.seq = 0
        self.message = ""
        self._log_after = 0
        self._changed: Optional[asyncio.Event] = None
        self._task: Optional[asyncio.Task] = None

    def ensure_running(self) -> None:
        """Start the snapshot task in the running event loop (once)."""
        if self._task is None or self._task.done():
            self._changed = asyncio.Event()
            self._task = asyncio.get_running_loop().create_task(self._run())

    async def _run(self) -> None:
        last_version, last_sent = -1, 0.0
        while not self.closing.is_set():
            version, now = self.session.version, time.monotonic()
            # while something runs, a snapshot every period even when the session's version stands still (a MAXIMUS
            # board reports after each hole): the page's live track is never older than a period
            if version != last_version or now - last_sent > (_EVENT_PERIOD_S if self.session.busy else 1.0):
                snap = self.extra(self.session.state(self._log_after))
                if snap["log"]:
                    self._log_after = snap["log"][-1]["seq"]
                self.message = f"data: {json.dumps(snap)}\n\n"
                self.seq += 1
                last_version, last_sent = version, now
                changed, self._changed = self._changed, asyncio.Event()
                changed.set()
            await asyncio.sleep(_EVENT_PERIOD_S)
        self.seq += 1  # the end: every stream wakes and sees the server closing
        if self._changed is not None:
            self._changed.set()

    async def after(self, seq: int) -> tuple[int, str]:
        """The next snapshot after number ``seq`` (there is one at least every second, and at the end)."""
        changed = self._changed
        if self.seq == seq and changed is not None:
            await changed.wait()
        return self.seq, self.message


async def _events(st: _AppState, request: Request):
    """Server-sent events: the whole state first, then the shared snapshot at each change (new log lines only;
    the page skips lines it has)."""
    from starlette.responses import StreamingResponse

    class CountedStream(StreamingResponse):
        async def __call__(self, scope, receive, send) -> None:
            try:
                await super().__call__(scope, receive, send)
            finally:
                st.streams -= 1

    limit = st.config.max_event_streams
    if st.streams >= limit:
        raise HttpError(503, f"too many live views: {limit} pages already follow this machine; close one and "
                             "reload", {"Retry-After": "5"})
    broadcast = st.broadcast
    broadcast.ensure_running()

    async def stream():
        seq = broadcast.seq
        yield f"data: {json.dumps(_track_extra(st, st.session.state(0)))}\n\n"
        while not st.closing.is_set():
            new_seq, message = await broadcast.after(seq)
            if new_seq != seq:
                seq = new_seq
                yield message
            # a page that went away is noticed when a write to it fails (or by Starlette's disconnect watch)

    st.streams += 1  # until CountedStream ends
    return CountedStream(stream(), media_type="text/event-stream",
                         headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})


async def _pinlog(st: _AppState, request: Request):
    """The last job's pin log as CSV, exported once per job by the worker and sent from its file."""
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import FileResponse

    log = st.session.last_pin_log  # every write: the travel to the work zero too, each part marked
    if log is None:
        raise HttpError(404, "no job has run on the mock port yet")
    if st.pin_log_csv is None or st.pin_log_csv[0] is not log:
        st.counter += 1
        raw = st.jobs_dir / f".pinlog-{st.counter}.npy"
        csv = st.jobs_dir / f"pinlog-{st.counter}.csv"
        await run_in_threadpool(save_pin_log_raw, log, raw)
        try:
            await run_in_threadpool(st.worker.call, pin_log_csv, str(raw), str(csv), what="the pin-log export")
        finally:
            raw.unlink(missing_ok=True)
        if st.pin_log_csv is not None:
            st.pin_log_csv[1].unlink(missing_ok=True)
        st.pin_log_csv = (log, csv)
    return FileResponse(st.pin_log_csv[1], media_type="text/csv", filename="pinlog.csv",
                        headers={"Cache-Control": "no-store"})


async def _not_found(st: _AppState, request: Request):
    raise HttpError(404, f"no such API endpoint: {request.method} {request.url.path}")


# -- machine settings and the tool table (issue #47 points 4 and 5): thin adapters over cam.machine_file and
# cam.tool_table --------------------------------------------------------------------------------------------

def _machine_path(st: _AppState) -> Path:
    """The machine file the page's Settings save to (:func:`cam.machine_file.machine_file_of`)."""
    return machine_file_of(st.config.machine_file or None)


def _tools_path(st: _AppState) -> Path:
    """The machine's tool table (:func:`cam.tool_table.tool_table_path`)."""
    return tool_table_path(st.config.machine_file or None)


def _settings_answer(st: _AppState) -> dict[str, Any]:
    path = _machine_path(st)
    return {"file": str(path), "backup": str(backup_path(path)), "exists": path.is_file(),
            "settings": [info.to_json() for info in list_settings(st.session.settings)]}


async def _get_settings(st: _AppState, request: Request) -> dict[str, Any]:
    """``GET /api/settings``: every key of the machine file (:func:`cam.machine_file.list_settings`): name, value,
    kind, unit, range and help, with the file they are saved to."""
    return _settings_answer(st)


def _save_machine(st: _AppState, values: Any, what: str) -> None:
    """Save ``values`` (key -> value) to the machine file (:func:`cam.machine_file.save_settings`, a backup kept)
    and run the next job with the file as saved: the session's and the planner's settings, the machine file the
    state file records (so the next ``cam serve`` on this machine reads it) and its tool table."""
    session = st.session
    if session.busy:
        raise BusyError("the machine is busy: settings are saved while it is idle")
    path = _machine_path(st)
    backend = session.backend
    old = session.settings
    new = save_settings(path, values, base=backend.base_settings(), adapt=backend.adapt_settings)
    st.config.settings = session.settings = new
    st.config.machine_file = str(path)
    session.tool_table_path = str(_tools_path(st))
    hold = session.state_hold
    if hold is not None:  # the file as saved is the machine's now: recorded, no "changed since" at the next start
        hold.machine = machine_record(str(path))
        hold.settings = new
        hold.save(hold.state)
    session.log(f"{what} saved to {path} (the old file kept as {backup_path(path).name})")
    if new.mm_per_step_axes != old.mm_per_step_axes or new.travel != old.travel:
        session.log("the steps per mm or the travel changed: home the machine or Set position before the next job",
                    "warning")


async def _post_settings(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"values": {key: value}}``: change machine-file keys (numbers, true/false, or their text), saved with a
    backup and used from the next job on; a value out of range is one 400 line naming the key, unit and range."""
    from starlette.concurrency import run_in_threadpool

    body = await _body_json(request)
    values = body.get("values")
    if not isinstance(values, dict) or not values:
        raise HttpError(400, "values must be an object of machine-file keys and their new values")
    await run_in_threadpool(_save_machine, st, values, f"machine settings ({', '.join(sorted(values))[:200]})")
    return _settings_answer(st)


def _keep_drill_z(st: _AppState) -> None:
    """Z Drill Up / Down set on the page are kept in the machine file (its ``[maximus]`` keys): the next server
    starts with them.  A file that cannot be written is a warning in the log; the stroke holds until then."""
    m = st.session.settings.maximus
    try:
        _save_machine(st, {"maximus.drill_z_up_steps": m.drill_z_up_steps,
                           "maximus.drill_z_down_steps": m.drill_z_down_steps}, "Z Drill Up / Down")
    except CamError as exc:
        st.session.log(f"Z Drill Up / Down not kept in the machine file: {exc}", "warning")


def _tools_answer(st: _AppState) -> dict[str, Any]:
    path = _tools_path(st)
    return {"file": str(path), "shapes": list(TABLE_SHAPES),
            "tools": [t.to_json() for t in read_tool_table(path).sorted()]}


async def _get_tools(st: _AppState, request: Request) -> dict[str, Any]:
    """``GET /api/tools``: the machine's tool table, by number."""
    return _tools_answer(st)


async def _set_tool(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"number", "shape", "diameter_mm", "angle_deg", "length_mm"}``: add or replace a tool (written atomically;
    :func:`cam.tool_table.tool_from_mapping` checks every field)."""
    body = await _body_json(request)
    tool = tool_from_mapping(body)
    path = _tools_path(st)
    write_tool_table(path, read_tool_table(path).with_tool(tool), st.config.machine_file or "")
    st.session.log(f"tool table: {tool.describe()}")
    return _tools_answer(st)


async def _remove_tool(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"number": N}``: remove tool N from the table."""
    body = await _body_json(request)
    number = body.get("number")
    if isinstance(number, str) and number.strip().isdigit():
        number = int(number)
    if isinstance(number, bool) or not isinstance(number, int):
        raise HttpError(400, f"number must be a whole number, got {json.dumps(number)[:40]}")
    path = _tools_path(st)
    write_tool_table(path, read_tool_table(path).without(number), st.config.machine_file or "")
    st.session.log(f"tool table: T{number} removed")
    return _tools_answer(st)


def _routes(st: _AppState) -> list:
    """Every URL of the server (all of ``/api`` behind :func:`_api`)."""
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    session = st.session
    post = ["POST"]

    def json_api(handler: Handler):
        return _api(st, handler, body="application/json")

    return [
        Route("/", _index),
        Route("/api/config", _api(st, _get_config)),
        Route("/api/options", _api(st, _get_options)),
        Route("/api/kinds", _api(st, _get_kinds)),
        Route("/api/upload", _api(st, _upload, body="multipart/form-data"), methods=post),
        Route("/api/plan", json_api(_plan_job), methods=post),
        Route("/api/preview/{job}.png", _api(st, _preview)),
        Route("/api/start", json_api(_start), methods=post),
        Route("/api/pause", json_api(partial(_control, action=session.pause)), methods=post),
        Route("/api/resume", json_api(partial(_control, action=session.resume)), methods=post),
        Route("/api/stop", json_api(partial(_control, action=session.stop)), methods=post),
        Route("/api/resume-job", json_api(_resume_job), methods=post),
        Route("/api/estop", json_api(_emergency_stop), methods=post),
        Route("/api/jog", json_api(_jog), methods=post),
        Route("/api/origin", json_api(partial(_control, action=session.go_to_origin)), methods=post),
        Route("/api/offset", json_api(partial(_control, action=session.set_offset)), methods=post),
        Route("/api/drill-z", json_api(_drill_z), methods=post),
        Route("/api/feed-override", json_api(_feed_override), methods=post),
        Route("/api/home", json_api(partial(_control, action=session.home)), methods=post),
        Route("/api/set-position", json_api(_set_position), methods=post),
        Route("/api/zero", json_api(_zero), methods=post),
        Route("/api/goto", json_api(_goto), methods=post),
        Route("/api/use-offset", json_api(_use_offset), methods=post),
        Route("/api/answer", json_api(_answer), methods=post),
        Route("/api/probe-z", json_api(_probe_z), methods=post),
        Route("/api/probe-tool", json_api(_probe_tool), methods=post),
        Route("/api/probe-area", json_api(_probe_area), methods=post),
        Route("/api/height-map.png", _api(st, _height_map)),
        Route("/api/forget-height-map", json_api(_forget_height_map), methods=post),
        Route("/api/settings", _api(st, _get_settings)),
        Route("/api/settings", json_api(_post_settings), methods=post),
        Route("/api/tools", _api(st, _get_tools)),
        Route("/api/tools", json_api(_set_tool), methods=post),
        Route("/api/tools/remove", json_api(_remove_tool), methods=post),
        Route("/api/track", _api(st, _get_track)),
        Route("/api/holes", _api(st, _get_holes)),
        Route("/api/goto-hole", json_api(_goto_hole), methods=post),
        Route("/api/start-at-hole", json_api(_start_at_hole), methods=post),
        Route("/api/spindle", json_api(_spindle), methods=post),
        Route("/api/state", _api(st, _state)),
        Route("/api/events", _api(st, _events)),
        Route("/api/pinlog", _api(st, _pinlog)),
        Route("/api/{rest:path}", _api(st, _not_found), methods=["GET", "POST", "PUT", "DELETE", "PATCH"]),
        Mount("/static", StaticFiles(directory=STATIC_DIR), name="static"),
    ]


def _body_cap(method: str, path: str, config: ServerConfig) -> int:
    """The most body bytes the route takes: an upload's limit and its form around it, else a JSON body's."""
    if (method, path) == ("POST", "/api/upload"):
        return config.max_upload_bytes + _MULTIPART_SLACK_BYTES
    return _MAX_JSON_BYTES


def _front_door(inner: Callable[..., Awaitable[None]], guard: ConnectionGuard) -> Callable[..., Awaitable[None]]:
    """The ASGI app ``inner`` behind the load rules of :mod:`cam.web.connections`, with :data:`_SECURITY_HEADERS`
    on every HTTP response.

    Before any body is read: a ``Content-Length`` over the route's limit gets 413 at once (closed); then a
    safety route (:data:`~cam.web.connections.SAFETY_ROUTES`: e-stop, stop, pause, state) goes in whatever the
    load.  Any other request gets 503 (closed) when its connection came over a connection limit and none could
    be closed for it (probation), or when ``max_connections`` requests are already in progress.
    """
    limit = guard.config.max_connections
    close = {"Connection": "close", "Retry-After": "1"}

    async def app(scope, receive, send):
        if scope["type"] != "http":
            await inner(scope, receive, send)
            return

        async def send_wrapped(message):
            if message["type"] == "http.response.start":
                message = {**message, "headers": list(message.get("headers", [])) + _SECURITY_HEADERS}
            await send(message)

        method, path = scope["method"], scope["path"]
        refusal = None
        length = next((v for k, v in scope["headers"] if k == b"content-length"), None)
        cap = _body_cap(method, path, guard.config)
        if length is not None and length.isdigit() and int(length) > cap:
            refusal = (_too_large(guard.config.max_upload_bytes, {"Connection": "close"})
                       if cap > _MAX_JSON_BYTES else
                       _json_error(413, f"request body too large: JSON requests are limited to "
                                        f"{_MAX_JSON_BYTES // 1024} kB", {"Connection": "close"}))
        safety = is_safety_route(method, path)
        if refusal is None and not safety:
            conn = guard.connection_of(scope.get("client"))
            if conn is not None and conn.probation:
                conn.refused_for_load = True
                refusal = _json_error(503, f"too many connections (at most {guard.config.max_connections}, "
                                           f"{guard.config.max_connections_per_client} from one address); close a "
                                           "page or try again", close)
            elif guard.requests >= limit:
                if conn is not None:
                    conn.refused_for_load = True
                refusal = _json_error(503, f"the server is busy: {limit} requests at once is its limit; close a "
                                           "page or try again", close)
        if refusal is not None:
            await refusal(scope, receive, send_wrapped)
            return
        counter = "safety_requests" if safety else "requests"
        setattr(guard, counter, getattr(guard, counter) + 1)
        try:
            await inner(scope, receive, send_wrapped)
        finally:
            setattr(guard, counter, getattr(guard, counter) - 1)

    return app


def create_app(config: ServerConfig, session: Optional[MachineSession] = None):
    """The Starlette application.  ``app.state.session`` is the :class:`MachineSession`."""
    from starlette.applications import Starlette
    from starlette.concurrency import run_in_threadpool

    config.checked()
    jobs_dir = Path(config.jobs_dir or tempfile.mkdtemp(prefix="cam-jobs-")).resolve()
    jobs_dir.mkdir(parents=True, exist_ok=True)
    config.jobs_dir = str(jobs_dir)
    if session is None:
        machine = None if config.machine_file is None else machine_record(config.machine_file or None)
        hold = StateHold(config.state_file, config.settings, "cam serve", port=config.machine_port, machine=machine,
                         machine_changed=config.machine_changed) if config.state_file else None
        try:
            session = MachineSession(config.machine_port, config.settings, realtime=config.realtime, state=hold)
            for warning in hold.warnings if hold is not None else ():
                session.log(warning, "warning")
        except BaseException:
            if hold is not None:
                hold.close()
            raise
    if session.tool_table_path is None:  # the prompt names the machine's tool (issue #47 point 4)
        session.tool_table_path = str(tool_table_path(config.machine_file or None))
    worker = Worker(time_limit_s=config.work_time_limit_s,
                    memory_limit_bytes=config.work_memory_limit_bytes or default_memory_limit_bytes(),
                    warm_up=WARM_UP)
    st = _AppState(config, session, jobs_dir, worker)

    @asynccontextmanager
    async def lifespan(app):
        await run_in_threadpool(worker.start)
        yield
        await run_in_threadpool(st.shut_down)

    inner = Starlette(routes=_routes(st), lifespan=lifespan)
    inner.state.session = session
    inner.state.config = config
    inner.state.closing = st.closing
    inner.state.guard = ConnectionGuard(config, partial(_body_cap, config=config))
    app = _front_door(inner, inner.state.guard)
    app.state = inner.state  # type: ignore[attr-defined]
    return app


def uvicorn_config(app: Any, **options: Any) -> Any:
    """The ``uvicorn.Config`` that runs ``app`` (from :func:`create_app`) with its connection limits.

    The HTTP protocol is h11 with the deadlines and the connection limit of ``app.state.config`` (see
    :func:`cam.web.connections.guarded_h11`); proxy headers are ignored (nothing proxies this server) and there are no
    websockets.  uvicorn's own ``limit_concurrency`` is not used: it counts half-sent connections too, so
    a flood of them would get the emergency stop refused.  ``options`` go to ``uvicorn.Config`` (the listen
    backlog is 2048 unless given).
    """
    import uvicorn

    http = partial(guarded_h11(), guard=app.state.guard)
    options.setdefault("backlog", _BACKLOG)
    return uvicorn.Config(app, http=http, ws="none", proxy_headers=False, lifespan="on", **options)


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
    sock.listen(_BACKLOG)
    sock.set_inheritable(True)
    return sock


def _raise_file_limit(wanted: int = 8192) -> None:
    """Let this process have up to ``wanted`` open files (sockets), as far as its hard limit allows.

    A burst of connections is accepted before any is trimmed to ``max_connections``; with the usual
    limit of 1024, about a thousand at once would run out of descriptors, and asyncio then stops
    accepting anyone (the emergency stop too) for a second.  Nothing happens where there is no such limit.
    """
    if resource is None:  # pragma: no cover - not Unix
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        except (ValueError, OSError):  # pragma: no cover - a sandbox that forbids it: keep the limit
            pass


def _freeze_startup_objects() -> None:
    """Leave the objects made so far (the library, numpy, the web stack: about 100,000) out of the garbage
    collector's full passes from now on (:func:`gc.freeze`).

    A full pass over them takes tens to hundreds of milliseconds, during which the event loop answers no
    one; connection churn (a flood) makes such passes come every few seconds, and each one held up an
    emergency stop that came during it.  The web stack's own first-use imports are made first; ``serve``
    unfreezes when the server has stopped.
    """
    import uvicorn.protocols.http.h11_impl  # noqa: F401 (imported by the server at its start otherwise)
    from starlette.responses import FileResponse, JSONResponse, StreamingResponse  # noqa: F401

    gc.collect()
    gc.freeze()


def serve(config: ServerConfig, announce: Callable[[str], None] = print) -> int:
    """Run the server until Ctrl-C; a running job is stopped (tool lifted) on the way out.  Returns 0."""
    import uvicorn

    if not is_loopback(config.host) and not config.token:
        config.token = new_token()
    sock = bind_socket(config.host, config.port)
    try:
        app = create_app(config)
    except BaseException:
        sock.close()
        raise
    port = sock.getsockname()[1]
    _raise_file_limit()
    ucfg = uvicorn_config(app, host=config.host, port=port, log_level="warning", access_log=False,
                          timeout_graceful_shutdown=2)
    server = uvicorn.Server(ucfg)
    mode = "real time" if (config.realtime or not can(config.machine_port, "simulated")) else "simulated clock"
    _freeze_startup_objects()
    announce(f"cam: web page at {page_url(config, port)}")
    announce(f"cam: machine port {config.machine_port} ({mode}); uploads in {config.jobs_dir}; Ctrl-C stops")
    try:
        server.run(sockets=[sock])
    finally:
        gc.unfreeze()  # what the server held may be let go again
        hold = app.state.session.state_hold
        if hold is not None:  # the machine's lock goes with the server, however it ended (again: no harm)
            hold.close()
    return 0


# -- the live track, the job's own units and the hole table (issue #47 points 1-3): thin adapters over
# cam.drive.track ---------------------------------------------------------------------------------------------

_NO_LOG = 1 << 62  # a snapshot's log_after that leaves every log line out


def _job_home(st: _AppState, job: PreparedJob) -> tuple[int, int, int]:
    """Where (machine steps) ``job``'s home stands if it started now: a file placed at the active work zero with a
    state file (:func:`cam.drive.placement.placed_home`), else where the tool stands (a job without a state file,
    a G-code program); a job started at a hole: where the tool stands minus where it starts in the job."""
    session = st.session
    here = tuple(int(v) for v in session.position_steps())
    resumed = getattr(job, "resumed", None)
    if resumed is not None:
        return tuple(h - int(s) for h, s in zip(here, resumed.start_position_steps))  # type: ignore[return-value]
    if session.state_hold is not None and job.kind in placed_kinds():
        return tuple(int(v) for v in placed_home(job, session.state_hold.state, None))  # type: ignore[return-value]
    return here  # type: ignore[return-value]


def _track_started(st: _AppState, job_id: str, job: PreparedJob, home: tuple[int, int, int], first: int = 0) -> None:
    """A job of the page started from ``home`` (machine steps, :func:`_job_home` before it started; ``first`` holes
    skipped): its run is what the track and the hole states follow from now on."""
    original = st.prepared.get(job_id, job)
    plan = getattr(original, "drill_plan", None)
    writes = None
    if plan is not None and not _board_drills(st):  # a pass over a drill job's moves (bounded by MAX_HOLES)
        writes = hole_writes(job)
    st.track["run"] = {"job": job_id, "prepared": job, "first": first, "home": home, "writes": writes,
                       "n_holes": 0 if plan is None else len(plan.holes_steps), "states": None}


def _board_drills(st: _AppState) -> bool:
    """The machine drills a drill job by itself (a MAXIMUS board): its progress counts holes, not writes."""
    return not st.session.backend.can("step_dir", st.session.port)


def _hole_states_now(st: _AppState, snap: dict[str, Any], n_holes: int) -> Optional[list[str]]:
    """The states of the started run's holes from the snapshot's progress (None: no run of a drill job)."""
    run = st.track.get("run")
    if run is None:
        return None
    job = run["prepared"]
    ours = snap["activity"] == "job" or (snap["activity"] is None and (snap.get("last") or {}).get("activity") == "job")
    if not ours:
        return run["states"]  # a jog since: the run's last states stay shown
    running = snap["activity"] == "job"
    done = int(snap["writes_done"])
    if _board_drills(st):
        states = hole_states(n_holes, first=run["first"], done=done, drilling=running and done < n_holes - run["first"])
    else:
        writes = run["writes"]
        if writes is None:
            return run["states"]
        holes_done = int(np.count_nonzero(writes[:, 1] <= done))
        drilling = running and holes_done < len(writes) and int(writes[holes_done, 0]) <= done
        states = hole_states(n_holes, first=run["first"], done=holes_done, drilling=drilling)
    run["states"] = states
    return states


def _track_extra(st: _AppState, snap: dict[str, Any]) -> dict[str, Any]:
    """A snapshot with the tool in the job's own units (``job_position``, :func:`cam.drive.track.to_job_units`, for
    the job whose track the page asked last) and the started drill job's hole states (``holes``: ``{"job", "states"}``)."""
    if snap["activity"] is not None and st.session.backend.can("overrides", st.session.port):
        # the time left follows the feed override (issue #47 point 7): the machine's own part of the snapshot says it
        pct = next((part["feed_override_pct"] for part in snap.values()
                    if isinstance(part, dict) and "feed_override_pct" in part), None)
        snap["remaining_s"] = remaining_time_s(snap["remaining_s"], pct)
    units = st.track.get("units")
    if units is not None:
        snap["job_position"] = dict(to_job_units(snap["position_steps"], units[1]), job=units[0])
    run = st.track.get("run")
    if run is not None and run["n_holes"]:
        states = _hole_states_now(st, snap, run["n_holes"])
        if states is not None:
            snap["holes"] = {"job": run["job"], "states": states}
    return snap


def _track_job(st: _AppState, request: Request) -> tuple[str, PreparedJob]:
    job_id = request.query_params.get("job", "")
    job = st.prepared.get(job_id)
    if job is None:
        raise HttpError(404, f"job {job_id!r} is not planned")
    return job_id, job


async def _drill_holes_of(st: _AppState, job_id: str, job: PreparedJob) -> Optional[dict[str, Any]]:
    """:func:`cam.drive.track.drill_holes` of a planned job (in the worker; kept per plan)."""
    from starlette.concurrency import run_in_threadpool

    kept = st.track.setdefault("holes", {}).get(job_id)
    if kept is None or kept[0] is not job:
        holes = await run_in_threadpool(st.worker.call, drill_holes, job, st.plan_options.get(job_id),
                                        what=f"the holes of {job.name or job_id}")
        kept = st.track["holes"][job_id] = (job, holes)
    return kept[1]


async def _get_track(st: _AppState, request: Request) -> dict[str, Any]:
    """``GET /api/track?job=ID``: the job's path and holes in machine mm where it runs (the started run's home
    while it runs or after it, else where it would run now) and its own units (:func:`cam.drive.track.job_track`);
    from now on the snapshots carry the tool in those units (``job_position``)."""
    from starlette.concurrency import run_in_threadpool

    job_id, job = _track_job(st, request)
    run = st.track.get("run")
    ours = run is not None and run["job"] == job_id
    home = run["home"] if ours else _job_home(st, job)
    holes = await _drill_holes_of(st, job_id, job)
    track = await run_in_threadpool(st.worker.call, job_track, job, home, st.config.settings, holes,
                                    what=f"the track of {job.name or job_id}")
    st.track["units"] = (job_id, job_units(job, home, st.config.settings, holes))
    return dict(track, job=job_id)


async def _get_holes(st: _AppState, request: Request) -> dict[str, Any]:
    """``GET /api/holes?job=ID&unit=mm|inch|mil``: a drill job's hole table: each hole in drilling order with its
    number, tool, diameter, X and Y in the file's own frame in ``unit``, and its state (to do, drilling, done,
    skipped) in the started run; ``{"holes": []}`` for a job that is not one of holes only."""
    job_id, job = _track_job(st, request)
    unit = request.query_params.get("unit", "mm")
    if unit not in TABLE_UNITS:
        raise HttpError(400, f"unit must be one of {', '.join(TABLE_UNITS)}, got {unit[:20]!r}")
    holes = await _drill_holes_of(st, job_id, job)
    if holes is None:
        return {"job": job_id, "unit": unit, "file_units": None, "holes": []}
    run = st.track.get("run")
    states = None
    if run is not None and run["job"] == job_id:
        states = (_track_extra(st, st.session.state(_NO_LOG)).get("holes") or {}).get("states")
    per = TABLE_UNITS[unit]
    rows = [{"number": i + 1, "tool": int(t), "diameter_mm": round(float(d), 4),
             "x": round(float(xy[0]) * per, 4), "y": round(float(xy[1]) * per, 4),
             "state": states[i] if states else "to do"}
            for i, (xy, t, d) in enumerate(zip(holes["board_mm"], holes["tools"], holes["diameters_mm"]))]
    return {"job": job_id, "unit": unit, "file_units": holes["units"], "holes": rows}


def _hole_number(body: dict[str, Any], job: PreparedJob) -> int:
    hole = body.get("hole")
    n = 0 if job.drill_plan is None else len(job.drill_plan.holes_steps)
    if isinstance(hole, bool) or not isinstance(hole, int) or not 1 <= hole <= n:
        raise HttpError(400, f"hole must be a whole number 1..{n}, got {json.dumps(hole)[:40]}" if n else
                        f"{job.name}: no hole table (a drill job of holes only has one)")
    return hole


def _planned_body(st: _AppState, body: dict[str, Any]) -> tuple[str, PreparedJob]:
    job_id = str(body.get("job", ""))
    job = st.prepared.get(job_id)
    if job is None:
        raise HttpError(404, f"job {job_id!r} is not planned; upload it and set its options first")
    return job_id, job


async def _goto_hole(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"job": ID, "hole": N}``: Go To above hole N (drilling order) at the job's travel height, where the job
    would drill it now: the session's Go To in the machine frame (lifted, across, down; refused while a job runs)."""
    body = await _body_json(request)
    job_id, job = _planned_body(st, body)
    k = _hole_number(body, job) - 1
    home = _job_home(st, job)
    x, y = (int(v) for v in job.drill_plan.holes_steps[k])
    target = [home[0] + x, home[1] + y, home[2] + int(job.drill_plan.safe_z_steps)]
    st.session.go_to(target, "steps", machine_coords=True)
    return st.session.state()


async def _start_at_hole(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"job": ID, "hole": N}``: Start At: run the drill job from hole N (the holes before it skipped), from
    where the tool stands: :func:`cam.drive.track.start_at_hole`, the library's resume of a stop after hole N - 1
    (lift, travel to the hole, its tool asked for); the job's journal is kept as a page's run keeps it."""
    from starlette.concurrency import run_in_threadpool

    body = await _body_json(request)
    job_id, job = _planned_body(st, body)
    hole = _hole_number(body, job)
    session = st.session
    if session.busy:
        raise BusyError("the machine is busy: Start At waits for the running activity to end")
    home = _job_home(st, job)
    where = tuple(int(p) - h for p, h in zip(session.position_steps(), home))
    started = await run_in_threadpool(st.worker.call, start_at_hole, job, hole, where, board=_board_drills(st),
                                      what=f"starting {job.name or job_id} at hole {hole}")
    session.start(started, label=f"job {job.name or Path(job.source).name} (from hole {hole})",
                  journal=str(_journal_path(st, job_id)))
    st.last_job = job_id
    _track_started(st, job_id, started, home, first=hole - 1)
    return session.state()


async def _spindle(st: _AppState, request: Request) -> dict[str, Any]:
    """``{"on": true | false}``: the spindle switch (issue #47 point 7; :meth:`MachineSession.spindle`: a machine with
    one, refused while anything runs)."""
    body = await _body_json(request)
    st.session.spindle(body.get("on"))
    return st.session.state()
