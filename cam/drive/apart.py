"""The real-time step runner in a process of its own: nothing else shares its interpreter.

Python runs one thread at a time per process.  A machine session's real-time
runner thread, sharing a process with a web server, waits for the
interpreter whenever a request, an event stream or a preview holds it --
milliseconds late, then every later write shifted by that.  So a session
runs real-time step plans in a :class:`RunnerProcess`: a child interpreter
started once per session (a new interpreter, never a fork of a process with
threads) that runs :func:`cam.drive.runner.run` on the port named by the
session, and nothing else.

Between the two:

* a socket carries the plan to the child, the pauses' prompts to the parent
  and their answers back, and the result (with the mock's pin log) at the end;
* a page of shared memory (a file both map) carries the controls, written by
  the parent the moment they are asked for (pause, stop, emergency stop: see
  :attr:`Controller.listeners`), and the progress, written by the child and
  read by the parent every few milliseconds.  The child reads the controls
  before every write and at least every :data:`_POLL_S` while it waits, so a
  stop or an emergency stop still halts within one step period.

The child ignores Ctrl-C, SIGTERM and SIGHUP (a terminal sends them to the
whole process group): the parent decides, and stops the job as it always
does.  If the parent dies, the child stops the job (tool lifted) and ends.
"""
from __future__ import annotations

import gc
import mmap
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from multiprocessing.connection import Connection
from typing import Optional

import numpy as np

from ..errors import CamError, PortError
from ..verify.pinlog import PinLog, write_pin_log
from .journal import JournalSpec, JournalWriter, journal_state_of
from .machines import open_port
from .pause_probe import PauseProbe, probe_at_pause
from .ports import MockPort, Port
from .priority import claim_machine
from .runner import Controller, Cursor, PauseFn, ProgressFn, RunResult, run
from ..motion.chunks import ChunkedPlan
from ..motion.steps import StepPlan

__all__ = ["RunnerProcess"]

# slots of the shared page (int64 each)
_FLAGS, _DONE, _MACHINE_NS, _ALIVE, _SEQ, _X, _Y, _Z = 0, 1, 2, 3, 4, 5, 6, 7
"""Slots of the shared page; _SEQ is odd while the child writes (_DONE, _X, _Y, _Z): the parent reads an even,
unchanged _SEQ around them, so the live position and the writes sent are never torn."""
_PAUSE, _STOP, _ESTOP = 1, 2, 4
_PAGE_BYTES = 4096
_POLL_S = 0.0005  # the child's longest sleep between looks at the controls
_PARENT_POLL_S = 0.005  # the parent's look at the progress
_START_S = 30.0  # the longest wait for a new runner process to say what it got
_NICE = -10
"""The runner's niceness step where a real-time class is not permitted (:func:`cam.drive.priority.claim_machine`:
with SCHED_FIFO the runner keeps one core, the one it busy-waits on before each write, and the others serve the
rest)."""


def _flags_of(ctl: Controller) -> int:
    return (_PAUSE if ctl.paused else 0) | (_STOP if ctl.stop_requested else 0) | \
        (_ESTOP if ctl.estop_requested else 0)


# ---------------------------------------------------------------------------------------- the child's side


class _SharedWake:
    """The child's stand-in for the controller's wake event: sleeps in short slices, watching the controls."""

    def __init__(self, slots: np.ndarray, parent_pid: int) -> None:
        self.slots, self.parent_pid = slots, parent_pid
        self._next_parent_check = 0.0
        self.orphaned = False

    def wait(self, timeout_s: Optional[float] = None) -> bool:
        flags = int(self.slots[_FLAGS])
        end = time.monotonic() + (timeout_s if timeout_s is not None else 3600.0)
        while True:
            self.check_parent()
            if int(self.slots[_FLAGS]) != flags:
                return True
            left = end - time.monotonic()
            if left <= 0:
                return False
            time.sleep(min(_POLL_S, left))

    def clear(self) -> None:
        pass

    def set(self) -> None:
        pass

    def check_parent(self) -> None:
        """The parent gone (killed): stop the job, as the parent would have."""
        now = time.monotonic()
        if now >= self._next_parent_check:
            self._next_parent_check = now + 0.05
            if os.getppid() != self.parent_pid:
                self.orphaned = True
                self.slots[_FLAGS] = int(self.slots[_FLAGS]) | _STOP


class _SharedController(Controller):
    """A :class:`Controller` whose requests live in the shared page (the child's side)."""

    def __init__(self, slots: np.ndarray, parent_pid: int) -> None:  # noqa: D107 - no Controller.__init__
        self.slots = slots
        self.listeners = []
        self._wake = _SharedWake(slots, parent_pid)

    def _bit(self, bit: int) -> bool:
        return bool(int(self.slots[_FLAGS]) & bit)

    def _set(self, bit: int, on: bool) -> None:
        flags = int(self.slots[_FLAGS])
        self.slots[_FLAGS] = (flags | bit) if on else (flags & ~bit)

    paused = property(lambda self: self._bit(_PAUSE), lambda self, on: self._set(_PAUSE, on))
    stop_requested = property(lambda self: self._bit(_STOP), lambda self, on: self._set(_STOP, on))
    estop_requested = property(lambda self: self._bit(_ESTOP), lambda self, on: self._set(_ESTOP, on))


def _child(sock_fd: int, page_fd: int, parent_pid: int) -> None:
    """The runner process: run each plan it is sent, on the port it names, until the socket closes."""
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_IGN)
    # the objects of the imports (numba, numpy: hundreds of thousands) out of the collector's full passes: such a
    # pass held the interpreter for 50 ms every 2 s of a run, and the writer with it (benchmarks/busy_pc.py)
    gc.collect()
    gc.freeze()
    claimed = claim_machine(_NICE)  # the machine first: a real-time class, locked memory, a core of its own
    conn = Connection(sock_fd)
    conn.send(("claimed", claimed))
    page = mmap.mmap(page_fd, _PAGE_BYTES)
    slots = np.frombuffer(page, np.int64)
    slots[_ALIVE] = os.getpid()
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        _, plan, port_name, journal = message
        ctl = _SharedController(slots, parent_pid)
        cursor = Cursor(plan.settings)
        writer = JournalWriter(journal, plan, cursor, on_error=ctl.stop) if journal is not None else None

        def progress(done: int, total: int, machine_ns: int) -> None:
            sent, position = cursor.live
            slots[_SEQ] += 1
            slots[_DONE], slots[_X], slots[_Y], slots[_Z] = sent, *position
            slots[_SEQ] += 1
            slots[_MACHINE_NS] = machine_ns
            ctl._wake.check_parent()

        def on_pause(position_steps: tuple[int, int, int], note: str) -> None:
            conn.send(("prompt", position_steps, note))
            while True:
                while not conn.poll(0.01):  # the answer; an emergency stop or a lost parent meanwhile ends the wait
                    ctl._wake.check_parent()
                    if ctl.halted:
                        return
                message = conn.recv()
                if message[0] != "pause-probe":
                    return
                # the new tool probed on this process's open port while the job waits (cam.drive.pause_probe)
                conn.send(("pause-probed", probe_at_pause(port, plan.settings, True, ctl, message[1], writer)))

        port: Optional[Port] = None
        try:
            port = open_port(port_name, plan.settings)
            result = run(plan, port, realtime=True, controller=ctl, progress=progress, on_pause=on_pause,
                         cursor=cursor)
            log = result.pin_log() if isinstance(port, MockPort) else None
            if ctl._wake.orphaned:  # nobody will take the result: this process keeps the outputs it can
                _orphan_outputs(journal, log)
            if writer is not None:
                journal_error = writer.close(journal_state_of(result.status), result.writes, result.position_steps)
                writer = None
                if journal_error:
                    result.messages.append(journal_error)
            fields = {k: v for k, v in vars(result).items() if k != "port"}
            reply: tuple = ("result", fields, None if log is None else (log.t_ns, log.data, log.strobe))
        except CamError as exc:
            reply = ("error", str(exc))
        except Exception as exc:  # noqa: BLE001 - reported to the parent, which books the activity as failed
            reply = ("error", f"internal error in the step runner: {type(exc).__name__}: {exc}")
        finally:
            if writer is not None:  # the run failed: the journal says where it got to
                writer.close("failed")
            if port is not None and not isinstance(port, MockPort):
                try:
                    port.close()
                except CamError:
                    pass
        try:
            conn.send(reply)
        except OSError:  # the parent is gone
            return


def _orphan_outputs(journal: Optional[JournalSpec], log: Optional[PinLog]) -> None:
    """The parent died during the run: write the mock's pin log where the job asked for it (the journal comes
    next), so the run can be resumed and checked."""
    if journal is None or log is None or not journal.pin_log_path:
        return
    try:
        write_pin_log(log, journal.pin_log_path)
    except CamError:
        pass


# ---------------------------------------------------------------------------------------- the parent's side


class _RemotePort(Port):
    """What a result names when its port lived in the runner process (a real port, now closed there)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def write(self, data: int, strobe: int, t_ns: int) -> None:
        raise PortError(f"{self.name} was driven by the runner process and is closed")


class RunnerProcess:
    """One child interpreter that runs real-time step plans for a machine session, one at a time.

    Started at the first :meth:`run` (or :meth:`start`), ended by :meth:`close`.  Not thread-safe: the session
    runs one activity at a time.
    """

    def __init__(self) -> None:
        self._process: Optional[subprocess.Popen] = None
        self._conn: Optional[Connection] = None
        self._page: Optional[mmap.mmap] = None
        self._slots: Optional[np.ndarray] = None
        self._lock = threading.Lock()
        self.claimed = ""
        """What the runner process got: its scheduling class, locked memory, its core (one line)."""

    @property
    def pid(self) -> Optional[int]:
        """The runner process's id (None before it starts)."""
        return self._process.pid if self._process is not None else None

    def start(self) -> None:
        """Start the child now (it imports numpy and the runner: a fraction of a second)."""
        if self._process is not None and self._process.poll() is None:
            return
        self.close()
        page_file = tempfile.TemporaryFile(prefix="cam-runner-")
        page_file.truncate(_PAGE_BYTES)
        ours, theirs = socket.socketpair()
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in [env.get("PYTHONPATH")] if p])  # this cam
        code = (f"from cam.drive.apart import _child; _child({theirs.fileno()}, {page_file.fileno()}, "
                f"{os.getpid()})")
        try:
            self._process = subprocess.Popen([sys.executable, "-c", code], env=env, stdin=subprocess.DEVNULL,
                                             pass_fds=(theirs.fileno(), page_file.fileno()))
        except OSError as exc:
            ours.close()
            raise PortError(f"cannot start the step runner process ({exc.strerror or exc})") from None
        finally:
            theirs.close()
        self._page = mmap.mmap(page_file.fileno(), _PAGE_BYTES)
        page_file.close()
        self._slots = np.frombuffer(self._page, np.int64)
        self._conn = Connection(ours.detach())
        if self._conn.poll(_START_S):  # what the runner got from the system, said once (the session logs it)
            message = self._conn.recv()
            if message[0] == "claimed":
                self.claimed = str(message[1])

    def run(self, plan: "StepPlan | ChunkedPlan", port_name: str, controller: Controller,
            progress: Optional[ProgressFn] = None, on_pause: Optional[PauseFn] = None,
            journal: Optional[JournalSpec] = None, cursor: Optional[Cursor] = None) -> RunResult:
        """Run ``plan`` in real time on the port ``port_name``, in the child; as :func:`cam.drive.runner.run`.

        A :class:`~cam.motion.chunks.ChunkedPlan` goes to the child as its job and settings; the child makes its
        writes a chunk at a time, so neither process holds every write.

        ``journal``: the child keeps the job's journal (:class:`~cam.drive.journal.JournalWriter`); if this
        process dies during the run, the child stops the job, writes the journal's last record and the mock's
        pin log (``journal.pin_log_path``) itself.

        ``controller``'s requests reach the child the moment they are made; ``progress`` is called from this
        thread every few milliseconds while the job runs; ``on_pause`` is called here at each pause and the
        job goes on when it returns.  ``cursor`` follows the child's: the writes sent and the live position.

        Raises:
            PortError: the runner process could not start or ended during the job (the machine stopped
                where it was: nothing more was sent).
            CamError: what the run raised in the child (e.g. the port could not be opened).
        """
        with self._lock:
            self.start()
            assert self._slots is not None and self._conn is not None
            slots, conn = self._slots, self._conn
            slots[_DONE] = slots[_MACHINE_NS] = slots[_X] = slots[_Y] = slots[_Z] = slots[_SEQ] = 0

            def mirror() -> None:
                slots[_FLAGS] = _flags_of(controller)

            mirror()
            controller.listeners.append(mirror)
            try:
                conn.send(("run", plan, port_name, journal))
                return self._follow(plan, controller, progress, on_pause, cursor or Cursor(plan.settings))
            finally:
                controller.listeners.remove(mirror)
                slots[_FLAGS] = 0

    def pause_work(self, request: PauseProbe) -> dict:
        """While the job runs here waits at a pause (in ``on_pause``): probe the new tool on the child's open port
        (:func:`cam.drive.pause_probe.probe_at_pause`); its reply.

        Raises:
            PortError: the runner process ended meanwhile."""
        conn = self._conn
        assert conn is not None
        conn.send(("pause-probe", request))
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):
                raise PortError("the step runner process ended while probing the new tool; the machine stopped "
                                "where it was") from None
            if message[0] == "pause-probed":
                return message[1]

    def _follow(self, plan: "StepPlan | ChunkedPlan", ctl: Controller, progress: Optional[ProgressFn],
                on_pause: Optional[PauseFn], cursor: Cursor) -> RunResult:
        assert self._slots is not None and self._conn is not None and self._process is not None
        slots, conn, total = self._slots, self._conn, len(plan)
        last_done = -1
        while True:
            try:
                ready = conn.poll(_PARENT_POLL_S)
                message = conn.recv() if ready else None
            except (EOFError, OSError):
                code = self._process.poll()
                self.close()
                raise PortError(f"the step runner process ended during the job (exit code {code}); the machine "
                                "stopped where it was") from None
            seq = int(slots[_SEQ])
            done, x, y, z = int(slots[_DONE]), int(slots[_X]), int(slots[_Y]), int(slots[_Z])
            if seq % 2 == 0 and seq == int(slots[_SEQ]):
                cursor.set(done, (x, y, z))
            if progress is not None and done != last_done:
                last_done = done
                progress(done, total, int(slots[_MACHINE_NS]))
            if message is None:
                continue
            if message[0] == "prompt":
                _, position_steps, note = message
                if on_pause is not None:
                    on_pause(tuple(position_steps), note)
                conn.send(("answer",))
            elif message[0] == "error":
                raise CamError(message[1])
            else:
                _, fields, log = message
                port: Port = _RemotePort(str(fields.get("port", "")))
                if log is not None:
                    port = MockPort()
                    port.write_many(*log)
                if progress is not None:
                    progress(int(fields["writes"]), total, int(round(float(fields["machine_time_s"]) * 1e9)))
                return RunResult(port=port, **fields)

    def close(self) -> None:
        """End the child; a job still running there is stopped first (tool lifted)."""
        process, conn, page, slots = self._process, self._conn, self._page, self._slots
        self._process = self._conn = self._page = None
        self._slots = None
        if slots is not None:
            slots[_FLAGS] = int(slots[_FLAGS]) | _STOP  # a job still running there stops (tool lifted)
        del slots
        if conn is not None:
            conn.close()
        if process is not None and process.poll() is None:
            try:
                process.wait(5)  # it ends at the socket's close, after the stop's lift
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if page is not None:
            try:
                page.close()
            except BufferError:  # a view of it is still alive somewhere: the OS frees it with the process
                pass

