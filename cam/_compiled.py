"""Compiled kernels: numba's JIT with its on-disk cache, in a folder of cam's own.

Every numba kernel of cam is ``@njit(cache=True)``: the first run on a machine
compiles each kernel it uses (for this machine's CPU, as numba's JIT does) and
writes it to numba's cache; every later run loads it from there, in a few
milliseconds a kernel.  Nothing is compiled at install, so the package is pure
Python (one ``py3-none-any`` wheel for every machine).

Where the cache lives (see :func:`cache_dir`): ``$NUMBA_CACHE_DIR`` when it is
set, else ``$XDG_CACHE_HOME/cam/numba`` (``~/.cache/cam/numba``), a folder of
the user's that works for a read-only or system-wide install too.  Importing
this module (every kernel module does, before its kernels are defined) points
numba there.  When that folder cannot be written, numba's own choice stands
(``__pycache__`` next to the sources, else ``~/.cache/numba``).  numba keys each
cached kernel by a hash of its source file, the argument types and the CPU, so
an edited kernel, another CPU or another numba is compiled afresh; deleting the
folder is always safe.

The command line says once on stderr when it compiles (see
:func:`cam.cli._note_first_compile`).  ``python -m cam._kernel_cache compile``
fills the cache with every kernel for the argument types the sample jobs use
(:mod:`cam._kernel_signatures`), so that no later run compiles; :func:`signatures` and
:func:`is_cached` read that table here, below every layer (the planning worker loads the cached kernels
with them, tests/test_layers.py).
"""
from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from typing import Any, Callable, Optional

__all__ = ["entry", "resolved", "KERNEL_MODULES", "ENTRIES", "cache_dir", "default_cache_dir", "use_cache_dir",
           "load_kernels", "signatures", "is_cached"]

KERNEL_MODULES = (
    "cam.digitize._classify",
    "cam.digitize._kernels",
    "cam.motion.kernels",
    "cam.motion.ramps",
    "cam.job.drill_order",
    "cam.job._route",
    "cam.job._svg_kernels",
    "cam.job._gcode_kernels",
    "cam.formats.hpgl",
    "cam.verify.ramps",
)
"""Modules holding numba kernels (``python -m cam._kernel_cache`` imports them all)."""

ENTRIES: dict[str, Any] = {}
"""Qualified name -> numba dispatcher of every kernel marked with :func:`entry` (filled on import)."""

CACHE_ENV = "NUMBA_CACHE_DIR"


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/cam/numba``, or ``~/.cache/cam/numba`` when ``XDG_CACHE_HOME`` is not set."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "cam" / "numba"


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(folder, os.W_OK | os.X_OK)


def use_cache_dir() -> Optional[Path]:
    """Point numba's on-disk cache at :func:`default_cache_dir` unless ``NUMBA_CACHE_DIR`` is already set;
    return the folder in use (None: numba's own choice, when cam's folder cannot be written).

    Sets ``NUMBA_CACHE_DIR`` in the environment (so worker processes share the folder, and numba's reload of
    its settings from the environment keeps it) and in numba's settings when numba is already imported.  Must
    run before a kernel is defined: numba picks a kernel's cache folder when it is decorated."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given)
    folder = default_cache_dir()
    if not _writable(folder):
        return None
    os.environ[CACHE_ENV] = str(folder)
    config = sys.modules.get("numba.core.config")
    if config is not None and not getattr(config, "CACHE_DIR", ""):
        config.CACHE_DIR = str(folder)
    return folder


def cache_dir() -> Optional[Path]:
    """The folder numba caches cam's kernels in (None: numba's own choice next to the sources)."""
    given = os.environ.get(CACHE_ENV)
    return Path(given) if given else None


use_cache_dir()


def entry(dispatcher: Any) -> Any:
    """Mark a numba kernel that Python code calls (not other kernels: those call the dispatcher); returns the
    dispatcher itself.  The marked kernels are those ``python -m cam._kernel_cache`` lists and compiles."""
    qualname = f"{dispatcher.py_func.__module__}.{dispatcher.__name__}"
    ENTRIES[qualname] = dispatcher
    return dispatcher


def resolved(kernel: Any, *args: Any) -> Callable:
    """What serves ``kernel`` for arguments of the types of ``args`` (a caller making many small calls with the
    same types asks once): numba's dispatcher itself."""
    return kernel


def load_kernels() -> None:
    """Import every module of :data:`KERNEL_MODULES` (fills :data:`ENTRIES`)."""
    for name in KERNEL_MODULES:
        importlib.import_module(name)


def signatures() -> list[tuple[str, Any, tuple]]:
    """(kernel name, dispatcher, argument types) for every line of :mod:`cam._kernel_signatures` (the kernel
    modules imported first); numba's types are loaded here, only when the table is read."""
    import numba.core.types as nbtypes

    from ._kernel_signatures import SIGNATURES

    load_kernels()
    names = dict(vars(nbtypes))
    out = []
    for qualname, sigs in SIGNATURES.items():
        dispatcher = ENTRIES.get(qualname)
        if dispatcher is None:
            raise SystemExit(f"{qualname}: no such kernel (run python -m cam._kernel_cache collect)")
        for expr in sigs:
            out.append((qualname, dispatcher, tuple(eval(expr, names))))  # noqa: S307 - our own generated table
    return out


def is_cached(dispatcher: Any, arg_types: tuple) -> bool:
    """Whether numba's cache holds ``dispatcher`` for ``arg_types`` on this machine (loads it if so)."""
    if tuple(arg_types) in dispatcher.overloads:
        return True
    return dispatcher._cache.load_overload(arg_types, dispatcher.targetctx) is not None
