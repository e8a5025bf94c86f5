"""Heavy work in a process of its own, with a time and a memory limit.

The machine comes first: while a job runs, the step runner must get the CPU
(and Python's interpreter lock) the moment a write is due.  Planning a file,
drawing a preview and exporting a pin log can take seconds and gigabytes, so
front ends that share a process with a running machine (the web server) hand
them to a :class:`Worker`: one child process, a new Python interpreter (never
a fork of a process whose threads drive a machine), that runs one call at a time.  A call that runs over its time limit is ended by
ending the process; one that needs more memory than its limit gets a
``MemoryError`` inside the child.  Either way the caller gets a one-line
:class:`~cam.errors.CamError` and the next call gets a new process.

    worker = Worker(time_limit_s=60, memory_limit_bytes=2 << 30)
    job = worker.call(prepare_job, path, options, settings, what="planning part.png")
    worker.close()

Functions and arguments travel by pickle: module-level functions only.
"""
from __future__ import annotations

import importlib
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
from multiprocessing.connection import Connection
from typing import Any, Callable, Optional

try:
    import resource
except ImportError:  # pragma: no cover - not Unix: no memory limit to set
    resource = None  # type: ignore[assignment]

from .errors import CamError

__all__ = ["Worker", "WorkerLimitError", "DEFAULT_TIME_LIMIT_S", "default_memory_limit_bytes"]

DEFAULT_TIME_LIMIT_S = 120.0
"""How long one call may take by default (a large drawing plans in well under a minute)."""

_END_GRACE_S = 1.0  # after SIGTERM, wait this long before SIGKILL
_START_LIMIT_S = 300.0
"""The longest a child may take to start (its imports and cached kernels) before a call gives up on it: a start is
waited for, not counted against the call's time limit (on a busy machine it takes seconds)."""
_NICE = 10  # the worker's niceness step: heavy work yields the CPU to the machine


class WorkerLimitError(CamError):
    """A call ran over the worker's time or memory limit (the work was ended; nothing changed)."""


def default_memory_limit_bytes() -> int:
    """Half the machine's memory, at most 8 GiB and at least 2 GiB (an address-space limit: the worker's
    libraries take about 650 MB of it, and compiling a kernel the first time a few hundred MB more)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not Unix
        total = 4 << 30
    return int(min(8 << 30, max(2 << 30, total // 2)))


def _limit_memory(limit_bytes: int) -> None:
    if resource is None:  # pragma: no cover - not Unix
        return
    try:
        resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))
    except (ValueError, OSError):  # pragma: no cover - a hard limit below ours: keep it
        pass


_CV_NO_MEMORY = -4
"""OpenCV's error code for a failed allocation (``cv::Error::StsNoMem``): its own MemoryError."""


def _out_of_memory(exc: BaseException) -> bool:
    """An exception that means an allocation failed, though not a MemoryError (OpenCV raises its own)."""
    return type(exc).__module__.startswith("cv2") and getattr(exc, "code", None) == _CV_NO_MEMORY


def _load_cached_kernels() -> None:
    """Load the compiled kernels numba's cache holds (the table of cam._kernel_signatures; none is compiled here)
    before the memory limit: numba links a cached kernel into the process with LLVM on its first call, and under an
    address-space limit that first call took about two minutes, mostly system time, so a job over the memory
    limit ran into the 120 s time limit instead (test_planning_over_the_work_memory_limit_is_a_clean_error)."""
    from ._compiled import is_cached, signatures

    for _name, dispatcher, arg_types in signatures():
        if is_cached(dispatcher, arg_types):
            dispatcher.compile(arg_types)  # from the cache: milliseconds


def _serve(fd: int, memory_limit_bytes: int, warm_up: tuple[str, ...]) -> None:
    """The child: set the memory limit, import what calls need, then answer calls until the socket closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    os.nice(_NICE)  # the machine's runner and the server come first
    conn = Connection(fd)
    for name in warm_up:
        importlib.import_module(name)
    _load_cached_kernels()
    _limit_memory(memory_limit_bytes)
    conn.send(("ready", None))  # the calls' time limits count from here
    while True:
        try:
            message = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            fn, args, kwargs = pickle.loads(message)
            reply: tuple[str, Any] = ("ok", fn(*args, **kwargs))
        except MemoryError:
            reply = ("memory", None)
        except CamError as exc:
            reply = ("cam", exc)
        except Exception as exc:  # noqa: BLE001 - a bug: the parent raises it as such
            reply = ("memory", None) if _out_of_memory(exc) else ("bug", f"{type(exc).__name__}: {exc}")
        try:
            conn.send(reply)
        except MemoryError:
            conn.send(("memory", None))
        except Exception as exc:  # noqa: BLE001 - e.g. an exception that does not pickle
            conn.send(("bug", f"the answer could not be sent back: {type(exc).__name__}: {exc}"))


class Worker:
    """One child process that runs calls one at a time, each within a time and a memory limit (thread-safe).

    Args:
        time_limit_s: the longest one call may run; then the process is ended and the call raises
            :class:`WorkerLimitError`.
        memory_limit_bytes: the child's address-space limit (``RLIMIT_AS``); a call that needs more
            raises :class:`WorkerLimitError`.  None: :func:`default_memory_limit_bytes`.
        warm_up: modules the child imports as it starts, so the first call does not pay for them.
    """

    def __init__(self, *, time_limit_s: float = DEFAULT_TIME_LIMIT_S, memory_limit_bytes: Optional[int] = None,
                 warm_up: tuple[str, ...] = ()) -> None:
        if not time_limit_s > 0:
            raise CamError(f"the worker's time limit must be > 0 s, got {time_limit_s}")
        self.time_limit_s = float(time_limit_s)
        self.memory_limit_bytes = int(memory_limit_bytes or default_memory_limit_bytes())
        if self.memory_limit_bytes < 256 << 20:
            raise CamError(f"the worker's memory limit must be at least 256 MB, got {self.memory_limit_bytes} bytes")
        self.warm_up = tuple(warm_up)
        self._lock = threading.Lock()
        self._process: Any = None
        self._conn: Any = None
        self._ready = False
        self._closed = False
        self.restarts = 0

    def start(self) -> None:
        """Start the child now (else at the first call)."""
        with self._lock:
            self._ensure()

    def _ensure(self) -> None:
        if self._process is not None and self._process.poll() is None:
            return
        self._end()
        ours, theirs = socket.socketpair()
        code = (f"from cam.worker import _serve; _serve({theirs.fileno()}, {self.memory_limit_bytes}, "
                f"{self.warm_up!r})")
        env = dict(os.environ)
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in [env.get("PYTHONPATH")] if p])  # this cam
        try:
            process = subprocess.Popen([sys.executable, "-c", code], pass_fds=(theirs.fileno(),), env=env,
                                       stdin=subprocess.DEVNULL)
        finally:
            theirs.close()
        self._process, self._conn = process, Connection(ours.detach())
        self._ready = False

    def _end(self) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if conn is not None:
            conn.close()
        if process is not None:
            if process.poll() is None:
                process.terminate()
                try:
                    process.wait(_END_GRACE_S)
                except subprocess.TimeoutExpired:
                    process.kill()
            process.wait()

    def call(self, fn: Callable[..., Any], *args: Any, what: str = "the work", **kwargs: Any) -> Any:
        """``fn(*args, **kwargs)`` in the child; its result, or its CamError raised here.

        ``what`` names the work in the messages ("planning part.png").  Calls from several threads queue.

        Raises:
            WorkerLimitError: over the time or memory limit, or the child died (it is restarted).
            CamError: what ``fn`` raised.
            RuntimeError: any other exception of ``fn`` (a bug), with its type and message.
        """
        with self._lock:
            if self._closed:
                raise CamError(f"{what}: the worker is closed")
            self._ensure()
            self._await_ready(what)
            try:
                self._conn.send((fn, args, kwargs))
                ready = self._conn.poll(self.time_limit_s)
                kind, value = self._conn.recv() if ready else ("time", None)
            except (EOFError, OSError, BrokenPipeError):
                try:
                    code = self._process.wait(_END_GRACE_S) if self._process is not None else None
                except subprocess.TimeoutExpired:
                    code = None
                self._restart()
                raise WorkerLimitError(f"{what} ended the worker process (exit code {code}); "
                                       "it was too large for this machine") from None
            if kind == "time":
                self._restart()
                raise WorkerLimitError(f"{what} took over {self.time_limit_s:g} s and was stopped "
                                       "(the server's work time limit)")
            if kind == "memory":
                self._restart()  # a fresh child: nothing half-allocated stays
                raise WorkerLimitError(f"{what} needs more than {self.memory_limit_bytes >> 20} MB "
                                       "(the server's work memory limit)")
            if kind == "cam":
                raise value
            if kind == "bug":
                raise RuntimeError(f"{what} failed: {value}")
            return value

    def _await_ready(self, what: str) -> None:
        """Wait until the child has started (imported its warm-up modules, loaded the cached kernels, set its
        memory limit): a start is not work, and the call's time limit counts from its end.

        Raises:
            WorkerLimitError: the child died while starting, or took over :data:`_START_LIMIT_S`.
        """
        if self._ready:
            return
        try:
            said = self._conn.recv() if self._conn.poll(_START_LIMIT_S) else ("time", None)
        except (EOFError, OSError):
            said = ("died", None)
        if said[0] != "ready":
            code = self._process.poll() if self._process is not None else None
            self._restart()
            raise WorkerLimitError(f"{what}: the worker process did not start "
                                   + (f"within {_START_LIMIT_S:g} s" if said[0] == "time" else f"(exit code {code})"))
        self._ready = True

    def _restart(self) -> None:
        self._end()
        self.restarts += 1

    def close(self) -> None:
        """End the child at once (a running call raises :class:`WorkerLimitError`); later calls are refused."""
        self._closed = True
        process = self._process
        if process is not None and process.poll() is None:
            process.terminate()  # the running call sees the pipe close
        with self._lock:
            self._end()

    def __enter__(self) -> "Worker":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
