"""The web server: one machine, one job at a time, controlled from a page (Starlette on uvicorn).

The page (``static/``) talks to a small JSON API under ``/api``; live status
comes as server-sent events (``GET /api/events``).  The server is a thin
adapter: jobs are prepared by :func:`cam.job.jobs.prepare_job` and run by
:func:`cam.drive.runner.run` on the same ports as the CLI, in one background
thread.

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
import collections
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

import numpy as np

from ..verify.pinlog import PositionTracker
from ..errors import CamError, PortError
from ..fileio import atomic_write_bytes
from ..job.jobs import PROFILE_SUFFIXES, JobOptions, PreparedJob, accepted_suffixes, job_kind, prepare_job
from ..settings import DEFAULT_SETTINGS, MachineSettings, Travel

__all__ = ["ServerConfig", "MachineSession", "HttpError", "create_app", "serve", "LOCAL_HOSTS"]

STATIC_DIR = Path(__file__).resolve().parent / "static"
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
MAX_JOG_STEPS = 100_000
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


class _BoardControl:
    """Pause / stop controls of a job on a MAXIMUS board (the runner's :class:`Controller` for step/dir ports).

    The firmware has no pause.  Stop and emergency stop both go to
    :meth:`cam.drive.maximus.MaximusBoard.emergency_stop`: during a move it sends the firmware's stop
    byte, between moves it sends nothing more and the job ends before the next packet.
    """

    paused = False

    def __init__(self) -> None:
        self.halted = False
        self._board: Any = None
        self._lock = threading.Lock()

    def attach(self, board: Any) -> None:
        """The board is open; a stop asked for before this point ends the job now."""
        with self._lock:
            self._board = board
            halted = self.halted
        if halted:
            board.emergency_stop()
            raise PortError("stopped before the board started")

    def stop(self) -> None:
        with self._lock:
            self.halted = True
            board = self._board
        if board is not None:
            board.emergency_stop()

    emergency_stop = stop

    def pause(self) -> None:
        raise HttpError(409, "the MAXIMUS firmware cannot pause a job: stop it, or wait for a tool change")

    def resume(self) -> None:
        raise HttpError(409, "nothing is paused")


class MachineSession:
    """The machine as the server sees it: where the tool is, what runs, the last run's pin log.

    Thread-safe.  One activity at a time (a job, a jog or a move to the
    origin) runs in a background thread through :func:`cam.drive.runner.run`.
    """

    def __init__(self, settings: MachineSettings = DEFAULT_SETTINGS, machine_port: str = "mock",
                 realtime: bool = True) -> None:
        self.settings = settings
        self.machine_port = machine_port
        self.maximus = machine_port.startswith("maximus:")  # the PIC board: drill files and jogs only
        self.realtime = realtime
        self._lock = threading.RLock()
        self._position = np.zeros(3, np.int64)  # steps from the home, when nothing runs
        self._activity: Optional[str] = None  # "job", "jog", "origin" while one runs
        self._label = ""
        self._thread: Optional[threading.Thread] = None
        self._controller = None
        self._positions: Any = None  # a PositionTracker over the running plan's writes (None: not known)
        self._done = 0
        self._total = 0
        self._machine_ns = 0
        self._estimated_s = 0.0
        self._started_wall = 0.0
        self._finished_wall = 0.0
        self._prompt: Optional[dict[str, Any]] = None
        self._prompt_seq = 0
        self._answer = threading.Event()
        self._answer_action = "continue"
        self._estop_request_ns: Optional[int] = None
        self._log: collections.deque = collections.deque(maxlen=500)
        self._log_seq = 0
        self.last_run: dict[str, Any] = {}
        self.last_job_pin_log = None
        self.version = 0

    # -- log and state -------------------------------------------------------------
    def log(self, text: str, level: str = "info") -> None:
        """Add a line to the log the page shows."""
        with self._lock:
            self._log_seq += 1
            self._log.append({"seq": self._log_seq, "level": level, "text": text, "t": time.time()})
            self.version += 1

    @property
    def busy(self) -> bool:
        with self._lock:
            return self._activity is not None

    def position_steps(self) -> tuple[int, int, int]:
        """Where the tool is now, in steps from the home (live while something runs)."""
        with self._lock:
            pos = self._position.copy()
            if self._activity is not None and self._positions is not None and self._done > 0:
                pos = pos + np.array(self._positions.advance(self._done), np.int64)
            return tuple(int(v) for v in pos)  # type: ignore[return-value]

    def state(self, log_after: int = 0) -> dict[str, Any]:
        """JSON-able snapshot: state, position, progress, times, prompt, log lines after ``log_after``."""
        s = self.settings
        with self._lock:
            ctl = self._controller
            if self._activity is None:
                name = "idle"
            elif self._prompt is not None:
                name = "prompt"
            elif ctl is not None and ctl.halted:
                name = "stopping"
            elif ctl is not None and ctl.paused:
                name = "paused"
            else:
                name = "running" if self._activity == "job" else "moving"
            pos = self.position_steps()
            end = time.monotonic() if self._activity is not None else self._finished_wall
            elapsed = max(0.0, end - self._started_wall) if self._started_wall else 0.0
            remaining = max(0.0, self._estimated_s - self._machine_ns / 1e9) if self._activity else 0.0
            return {
                "state": name,
                "activity": self._activity,
                "label": self._label,
                "position_steps": list(pos),
                "position_mm": [round(pos[0] * s.mm_per_step_xy, 4), round(pos[1] * s.mm_per_step_xy, 4),
                                round(pos[2] * s.mm_per_step_z, 4)],
                "progress": round(100.0 * self._done / self._total, 2) if self._total else 0.0,
                "writes_done": self._done,
                "writes_total": self._total,
                "elapsed_s": round(elapsed, 2),
                "remaining_s": round(remaining, 2),
                "prompt": dict(self._prompt) if self._prompt else None,
                "last": dict(self.last_run),
                "log": [dict(e) for e in self._log if e["seq"] > log_after][-100:],
                "port": self.machine_port,
                "realtime": self.realtime or self.machine_port != "mock",
                "version": self.version,
            }

    # -- starting things ---------------------------------------------------------
    def _check_free(self) -> None:
        if self._activity is not None:
            raise HttpError(409, f"the machine is busy ({self._label}); wait for it to end or stop it")

    def _check_reach(self, extent_steps: np.ndarray, what: str) -> None:
        """Refuse a move whose extent (relative to the tool) leaves the travel from here."""
        for a, (lo, hi) in enumerate(self.settings.travel.bounds_steps()):
            p = int(self._position[a])
            if p + int(extent_steps[a, 0]) < lo or p + int(extent_steps[a, 1]) > hi:
                raise HttpError(
                    409, f"{what} would leave the {'XYZ'[a]} travel ({lo}..{hi} steps from the home): the tool "
                    f"is at {'XYZ'[a]}={p} and the move reaches {p + int(extent_steps[a, 0])}.."
                    f"{p + int(extent_steps[a, 1])}")

    def start_job(self, job: PreparedJob) -> None:
        """Run a prepared job from where the tool stands (409 if something runs or it leaves the travel)."""
        with self._lock:
            self._check_free()
            if job.settings.travel != self.settings.travel or job.settings.pins != self.settings.pins:
                raise HttpError(409, "the job was planned for other machine settings; plan it again")
            self._check_reach(job.extent_steps, "the job")
            if self.maximus:
                self._launch_maximus_job(job)
                return
            self._launch("job", job.steps, f"job {job.name or Path(job.source).name}",
                         job.estimated_time_s)

    def jog(self, axis: str, steps: int) -> None:
        """Move one axis by ``steps`` (409 while something runs; 400 for a bad axis, count or travel)."""
        a = str(axis).lower()
        if a not in ("x", "y", "z"):
            raise HttpError(400, f"axis must be x, y or z, got {axis!r}")
        if isinstance(steps, bool) or not isinstance(steps, int) or steps == 0 or abs(steps) > MAX_JOG_STEPS:
            raise HttpError(400, f"steps must be a whole number, not 0, at most {MAX_JOG_STEPS} either way, got {steps!r}")
        i = "xyz".index(a)
        with self._lock:
            self._check_free()
            lo, hi = self.settings.travel.bounds_steps()[i]
            target = int(self._position[i]) + steps
            if not lo <= target <= hi:
                raise HttpError(400, f"a jog of {steps} steps would take {a.upper()} to {target}, outside its "
                                f"travel {lo}..{hi} steps from the home")
            move = [0, 0, 0]
            move[i] = steps
            if self.maximus:
                self._launch_maximus_moves("jog", [tuple(move)], f"jog {a.upper()} {steps:+d} steps")
                return
            self._start_moves("jog", [tuple(move)], f"jog {a.upper()} {steps:+d} steps")  # type: ignore[list-item]

    def go_to_origin(self) -> None:
        """Back to the home: lift out of the material first, travel at that height, then Z to the home."""
        with self._lock:
            self._check_free()
            x, y, z = (int(v) for v in self._position)
            safe = min(z, 0)
            absolute = [(x, y, safe), (0, 0, safe), (0, 0, 0)]
            rel: list[tuple[int, int, int]] = []
            for p in absolute:
                r = (p[0] - x, p[1] - y, p[2] - z)
                if r != (0, 0, 0) and (not rel or rel[-1] != r):
                    rel.append(r)
            if not rel:
                self.log("already at the origin")
                return
            if self.maximus:
                self._launch_maximus_moves("origin", rel, "go to origin")
                return
            self._start_moves("origin", rel, "go to origin")

    def _start_moves(self, activity: str, moves: list[tuple[int, int, int]], label: str) -> None:
        from ..drive.steps import plan_steps
        from ..job.model import travel_job

        plan = plan_steps(travel_job(moves, self.settings), start_steps=tuple(int(v) for v in self._position))
        self._launch(activity, plan, label, plan.estimated_time_s)

    def _launch(self, activity: str, plan: Any, label: str, estimated_s: float) -> None:
        from ..drive.runner import Controller

        ctl = Controller()
        self._activity, self._label, self._controller = activity, label, ctl
        self._positions = PositionTracker(plan.data, plan.settings)  # live position, decoded as it goes
        self._done, self._total, self._machine_ns = 0, len(plan), 0
        self._estimated_s = estimated_s
        self._started_wall = time.monotonic()
        self._estop_request_ns = None
        self._prompt = None
        self.version += 1
        self.log(f"{label}: started")
        t = threading.Thread(target=self._worker, args=(activity, plan, ctl, label), name=f"cam-{activity}",
                             daemon=True)
        self._thread = t
        t.start()

    # -- the MAXIMUS board ----------------------------------------------------------
    def _launch_maximus_job(self, job: PreparedJob) -> None:
        from ..drive.maximus.board import drill_arguments

        dp = job.drill_plan
        if job.kind != "excellon" or dp is None:
            raise HttpError(400, f"the MAXIMUS board ({self.machine_port}) drills drill files (Excellon) only; "
                                 f"this job is {job.kind}")
        arguments = drill_arguments(dp, self.settings)
        n_holes = len(arguments["holes_steps"])

        def work(board: Any) -> None:
            def on_hole(drilled: int) -> None:
                with self._lock:
                    self._done = drilled
                    self._machine_ns = int(job.estimated_time_s * 1e9 * drilled / max(1, n_holes))
                    self.version += 1

            board.drill(**arguments, on_tool_change=lambda index, note: self._on_pause((0, 0, 0), note),
                        on_hole=on_hole)

        self._launch_board("job", work, n_holes, f"job {job.name or Path(job.source).name}",
                           job.estimated_time_s, np.zeros(3, np.int64))

    def _launch_maximus_moves(self, activity: str, moves: list[tuple[int, int, int]], label: str) -> None:
        def work(board: Any) -> None:
            for move in moves:
                for a, n in zip("xyz", move):
                    if n:
                        board.jog(a, int(n), half_step=self.settings.half_step)

        self._launch_board(activity, work, 1, label, 0.0, np.sum(np.array(moves, np.int64), axis=0))

    def _launch_board(self, activity: str, work: Callable[[Any], None], total: int, label: str,
                      estimated_s: float, moved_steps: np.ndarray) -> None:
        ctl = _BoardControl()
        self._activity, self._label, self._controller = activity, label, ctl
        self._positions = None  # the board reports no position while it moves
        self._done, self._total, self._machine_ns = 0, total, 0
        self._estimated_s = estimated_s
        self._started_wall = time.monotonic()
        self._estop_request_ns = None
        self._prompt = None
        self.version += 1
        self.log(f"{label}: started on {self.machine_port}")
        t = threading.Thread(target=self._board_worker, args=(activity, work, ctl, label, moved_steps),
                             name=f"cam-maximus-{activity}", daemon=True)
        self._thread = t
        t.start()

    def _board_worker(self, activity: str, work: Callable[[Any], None], ctl: _BoardControl, label: str,
                      moved_steps: np.ndarray) -> None:
        from ..drive.maximus.board import MaximusBoard

        error = None
        board = None
        try:
            board = MaximusBoard(self.machine_port)
            ctl.attach(board)
            work(board)
        except CamError as exc:
            error = str(exc)
        except Exception as exc:  # noqa: BLE001 - reported on the page; the host sent nothing more
            error = f"internal error: {type(exc).__name__}: {exc}"
        finally:
            if board is not None:
                board.close()
        with self._lock:
            if error is None:
                status = "finished"
                self._position = self._position + moved_steps  # a drill job ends where it started
                self._done = self._total
            else:
                status = "emergency-stopped" if ctl.halted else "error"
            self.last_run = {"activity": activity, "label": label, "status": status,
                             "messages": [error] if error else []}
            self._activity = None
            self._controller = None
            self._prompt = None
            self._finished_wall = time.monotonic()
            self.version += 1
        if error is None:
            self.log(f"{label}: finished")
        else:
            self.log(f"{label}: {error}" + ("" if status == "emergency-stopped" else
                                             " (the board's position is now unknown: jog it home)"),
                     "error")

    # -- the worker thread ---------------------------------------------------------
    def _progress(self, done: int, total: int, machine_ns: int) -> None:
        with self._lock:
            self._done, self._machine_ns = done, machine_ns
            self.version += 1

    def _on_pause(self, position_steps: tuple[int, int, int], note: str) -> None:
        ctl = self._controller
        with self._lock:
            self._prompt_seq += 1
            self._prompt = {"id": self._prompt_seq, "note": note,
                            "position_steps": [int(v) + int(p) for v, p in zip(self._position, position_steps)]}
            self._answer.clear()
            self._answer_action = "continue"
        self.log(f"{note}: waiting for an answer", "prompt")
        while not self._answer.wait(0.05):
            if ctl is None or ctl.halted:
                break
        with self._lock:
            self._prompt = None
            action = self._answer_action
            self.version += 1
        if action == "stop" and ctl is not None:
            ctl.stop()

    def _worker(self, activity: str, plan: Any, ctl: Any, label: str) -> None:
        from ..drive.ports import MockPort, open_port
        from ..drive.runner import run

        result = None
        error = None
        port = None
        try:
            port = open_port(self.machine_port)
            result = run(plan, port, realtime=self.realtime, controller=ctl, progress=self._progress,
                         on_pause=self._on_pause)
        except CamError as exc:
            error = str(exc)
        except Exception as exc:  # noqa: BLE001 - reported on the page; the runner sent nothing more
            error = f"internal error: {type(exc).__name__}: {exc}"
        finally:
            if port is not None and not isinstance(port, MockPort):
                try:
                    port.close()
                except CamError as exc:
                    error = error or str(exc)
        with self._lock:
            info: dict[str, Any] = {"activity": activity, "label": label}
            if result is not None:
                self._position = self._position + np.array(result.position_steps, np.int64)
                info.update(status=result.status, writes=result.writes, messages=list(result.messages),
                            machine_time_s=round(result.machine_time_s, 4), wall_time_s=round(result.wall_time_s, 4),
                            started_ns=result.started_ns, step_period_ns=int(max(plan.settings.delay_xy_ns,
                                                                                 plan.settings.delay_z_ns)))
                if self._estop_request_ns is not None:
                    info["estop_request_job_ns"] = int(self._estop_request_ns - result.started_ns)
                if isinstance(result.port, MockPort):
                    log = result.pin_log()
                    info["last_write_job_ns"] = int(log.t_ns[-1]) if len(log) else None
                    if activity == "job":
                        self.last_job_pin_log = log
                self._done = result.writes if result.status != "finished" else self._total
            else:
                info.update(status="error", messages=[error or "failed"])
                self._positions = None  # position unknown beyond what was confirmed
            self.last_run = info
            self._activity = None
            self._controller = None
            self._prompt = None
            self._finished_wall = time.monotonic()
            self.version += 1
        if error:
            self.log(f"{label}: {error}", "error")
        else:
            assert result is not None
            text = f"{label}: {result.status}"
            if result.messages:
                text += " (" + "; ".join(result.messages) + ")"
            self.log(text, "info" if result.status == "finished" else "warning")

    # -- control -------------------------------------------------------------------
    def pause(self) -> None:
        with self._lock:
            if self._controller is None:
                raise HttpError(409, "nothing is running")
            self._controller.pause()
            self.version += 1
        self.log("paused")

    def resume(self) -> None:
        with self._lock:
            if self._controller is None:
                raise HttpError(409, "nothing is running")
            self._controller.resume()
            self.version += 1
        self.log("resumed")

    def stop(self) -> None:
        """Stop and lift the tool to the safe plane (nothing happens when idle)."""
        ctl = self._controller  # stop first, book-keeping after (see emergency_stop)
        if ctl is not None:
            ctl.stop()
        with self._lock:
            if ctl is not None:
                self._answer_action = "stop"
                self._answer.set()
                self.version += 1
        self.log("stop requested" if ctl is not None else "stop: nothing was running")

    def emergency_stop(self, request_ns: Optional[int] = None) -> None:
        """Send nothing more at all.  ``request_ns``: ``time.monotonic_ns()`` when the request arrived."""
        now = request_ns if request_ns is not None else time.monotonic_ns()
        ctl = self._controller  # no lock before the stop: the runner may hold it for a progress update
        if ctl is not None:
            ctl.emergency_stop()
        with self._lock:
            if ctl is not None:
                if self._estop_request_ns is None:
                    self._estop_request_ns = now
                self._answer.set()
                self.version += 1
        self.log("EMERGENCY STOP" if ctl is not None else "emergency stop: nothing was moving", "error")

    def answer(self, prompt_id: Any, action: str) -> None:
        """Answer the pending prompt: ``action`` "continue" or "stop"."""
        if action not in ("continue", "stop"):
            raise HttpError(400, f"action must be 'continue' or 'stop', got {action!r}")
        with self._lock:
            if self._prompt is None:
                raise HttpError(409, "no prompt is waiting for an answer")
            if prompt_id is not None and prompt_id != self._prompt["id"]:
                raise HttpError(409, f"prompt {prompt_id!r} is no longer waiting (the current one is {self._prompt['id']})")
            self._answer_action = action
            note = self._prompt["note"]
            self._answer.set()
        self.log(f"{note}: {action}")

    def wait_idle(self, timeout_s: float = 10.0) -> bool:
        """Wait for the running activity to end; True when idle."""
        t = self._thread
        if t is not None:
            t.join(timeout_s)
        return not self.busy

    def shutdown(self) -> None:
        """Stop whatever runs (tool lifted) and wait for it."""
        if self.busy:
            self.stop()
            if not self.wait_idle(30):
                self.emergency_stop()
                self.wait_idle(5)


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
    session = session or MachineSession(config.settings, config.machine_port, config.realtime)
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
        session.start_job(job)
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

    from contextlib import asynccontextmanager

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
