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

__all__ = ["claim_machine", "as_background", "FIFO_PRIORITY"]

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


def claim_machine(nice_fallback: int = -10) -> str:
    """Ask for SCHED_FIFO (else the ``nice_fallback`` niceness step), lock the process's memory and keep the calling
    thread on the last core; returns one line saying what was got."""
    return f"{_real_time(nice_fallback)}, {_lock_memory()}, {_own_core()}"


def as_background() -> None:
    """The calling thread back in the ordinary scheduling class, on every core the process had (a helper thread
    of the runner: it inherited the runner's class and core)."""
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass
    if _EVERY_CPU is not None:
        try:
            os.sched_setaffinity(0, _EVERY_CPU)
        except OSError:
            pass
