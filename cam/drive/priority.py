"""The real-time runner's claim on the machine (issue #32 point 2): a real-time scheduling class, memory that is
never paged out, and a core of its own, as LinuxCNC's and Klipper's hosts take them.

:func:`claim_machine` is called once by the runner process (:mod:`cam.drive.apart`) before it runs anything;
:func:`as_background` puts a helper thread of that process (the one that makes the next chunks) back in the
ordinary class on every core, so it never holds up the thread that writes.  Each step falls back quietly where the
system does not allow it (not root, no ``CAP_SYS_NICE``, a small ``RLIMIT_MEMLOCK``, one core) and the line
:func:`claim_machine` returns says what was got.
"""
from __future__ import annotations

import ctypes
import errno
import os
import resource
from typing import Optional

__all__ = ["claim_machine", "as_background", "real_time_class", "FIFO_PRIORITY", "CLAIM_ENV"]

FIFO_PRIORITY = 20
"""SCHED_FIFO priority of the runner: above every ordinary process, below the kernel's own real-time threads
(interrupt threads run at 50 on a PREEMPT_RT kernel)."""
_MCL_CURRENT, _MCL_FUTURE = 1, 2
_EVERY_CPU: Optional[set[int]] = None  # the process's cores before it kept one for itself


def _real_time(nice_fallback: int) -> str:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
        return f"SCHED_FIFO priority {FIFO_PRIORITY}"
    except (OSError, AttributeError):
        pass
    try:
        os.nice(nice_fallback)
        return f"nice {os.nice(0)} (a real-time class is not permitted here)"
    except OSError:
        return "the ordinary priority (neither a real-time class nor a higher one is permitted)"


def _lock_memory() -> str:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    except (OSError, AttributeError, ValueError):
        return "memory not locked (no mlockall here)"
    # future pages too only when the limit cannot be reached: past it every later allocation would fail
    flags = _MCL_CURRENT | (_MCL_FUTURE if soft == resource.RLIM_INFINITY else 0)
    if libc.mlockall(flags) != 0:
        return f"memory not locked ({os.strerror(ctypes.get_errno() or errno.EPERM)})"
    return "memory locked" if flags & _MCL_FUTURE else "memory locked as it is now"


def _own_core() -> str:
    global _EVERY_CPU
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (OSError, AttributeError):
        return "on any core"
    if len(cpus) < 2:
        return "on the only core"
    _EVERY_CPU = set(cpus)
    try:
        os.sched_setaffinity(0, {cpus[-1]})
    except OSError:
        return "on any core"
    return f"on core {cpus[-1]} of {len(cpus)}"


CLAIM_ENV = "CAM_RUNNER_CLAIM"
"""``nice``: the runner only takes the niceness step, as before issue #32 point 2 (benchmarks/busy_pc.py compares the
two); anything else, or unset: the full claim."""


def claim_machine(nice_fallback: int = -10) -> str:
    """Ask for SCHED_FIFO (else the ``nice_fallback`` niceness step), lock the process's memory and keep the calling
    thread on the last core; returns one line saying what was got (with ``CAM_RUNNER_CLAIM=nice`` in the
    environment: the niceness step only)."""
    if os.environ.get(CLAIM_ENV) == "nice":
        try:
            os.nice(nice_fallback)
            return f"nice {os.nice(0)} only ({CLAIM_ENV}=nice)"
        except OSError:
            return f"the ordinary priority ({CLAIM_ENV}=nice)"
    return f"{_real_time(nice_fallback)}, {_lock_memory()}, {_own_core()}"


HELPER_PRIORITY = 10
"""SCHED_FIFO priority of the runner's helper threads (the chunk maker, the journal): below the writer, above every
ordinary process.  They share the interpreter with the writer, so one that an ordinary process preempted while it
held the interpreter's lock held the writer up until it ran again: 50 ms stalls with both cores busy
(benchmarks/busy_pc.py)."""


def real_time_class() -> bool:
    """Whether the calling thread runs in a real-time scheduling class (SCHED_FIFO or SCHED_RR)."""
    try:
        return os.sched_getscheduler(0) in (os.SCHED_FIFO, os.SCHED_RR)
    except (OSError, AttributeError):
        return False


def as_background() -> None:
    """The calling thread (a helper thread of the runner: it inherited the runner's class and core) below the
    writer: SCHED_FIFO at :data:`HELPER_PRIORITY` when the writer has a real-time class (so no ordinary process
    preempts it while it holds the interpreter's lock the writer needs), else the ordinary class; on every core the
    process had."""
    try:
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(HELPER_PRIORITY))
    except (OSError, AttributeError):
        pass
    if _EVERY_CPU is not None:
        try:
            os.sched_setaffinity(0, _EVERY_CPU)
        except OSError:
            pass
