"""Compiled kernels, ahead of time when the install built them, else numba's JIT.

Every numba kernel that Python code calls is marked with :func:`entry`.  The
install (``pip install``, see ``setup.py``) compiles those kernels ahead of
time with ``numba.pycc`` into one extension module, ``cam._aot_kernels``, for
the argument types listed in :mod:`cam._aot_signatures`; a first run then
compiles nothing and starts as fast as a warm one.  Why ahead of time: numba
compiles the kernels of one job in 10 to 16 s, against 1.5 s for the whole
warm run, and that cannot be made small enough by trimming kernels; a
background compile would still make the first run wait; vectorised numpy is
5 to 50 times slower on the tracing, ramp and tour kernels.

The extension module is used only when it was built from exactly the kernel
sources on disk (a digest of them is written next to it), and only for calls
whose argument types it was built for: any other call goes to numba's JIT,
which gives the same result (the kernels are the same Python functions).  A
call with other types must never reach the ahead-of-time code, which does not
check types.

``python -m cam._aot collect`` lists the argument types the sample jobs use;
``python -m cam._aot build`` compiles the module in place.
"""
from __future__ import annotations

import hashlib
import importlib
import json
import os
from pathlib import Path
from typing import Any, Callable, Optional

import llvmlite.binding as llvm
import numpy as np

__all__ = ["entry", "KERNEL_MODULES", "HOLDS_GIL", "source_digest", "aot_status", "ENTRIES", "type_key", "resolved"]

KERNEL_MODULES = (
    "cam.digitize._classify",
    "cam.digitize._kernels",
    "cam.drive._kernels",
    "cam.drive.ramps",
    "cam.job.drill_order",
    "cam.job._route",
    "cam.job._svg_kernels",
    "cam.formats.hpgl",
    "cam.verify.ramps",
)
"""Modules holding numba kernels; the ahead-of-time build is valid only for their exact sources."""

HOLDS_GIL = frozenset({"cam.drive._kernels.net_steps_kernel"})
"""Kernels whose ahead-of-time build keeps the GIL: called in the send loop once a batch of a few hundred writes
(microseconds each), where letting go of the GIL hands it to the thread making the next chunks and the send loop
then waits to take it back."""

EXTENSION = "cam._aot_kernels"
MANIFEST = "_aot_kernels.json"

ENTRIES: dict[str, Any] = {}
"""Qualified name -> numba dispatcher of every kernel marked with :func:`entry` (filled on import)."""

_ROOT = Path(__file__).resolve().parent
_TABLE: Optional[dict[str, dict[tuple[str, ...], Callable]]] = None
_STATUS = "not loaded"


def source_digest() -> str:
    """sha256 of the sources of :data:`KERNEL_MODULES`, in that order (hex)."""
    h = hashlib.sha256()
    for name in KERNEL_MODULES:
        path = _ROOT.joinpath(*name.split(".")[1:]).with_suffix(".py")
        h.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def host_cpu() -> str:
    """This machine's CPU model and instruction-set features, as LLVM names them."""
    return f"{llvm.get_host_cpu_name()} {llvm.get_host_cpu_features().flatten()}"


def symbol_of(qualname: str, index: int) -> str:
    """Name of the ahead-of-time function for signature ``index`` of kernel ``qualname``."""
    return qualname.replace(".", "__") + f"__{index}"


def _load() -> dict[str, dict[tuple[str, ...], Callable]]:
    """Kernel -> {argument type names -> ahead-of-time function}; empty when there is no valid build."""
    global _TABLE, _STATUS
    if _TABLE is not None:
        return _TABLE
    _TABLE = {}
    if os.environ.get("CAM_NO_AOT"):
        _STATUS = "turned off by CAM_NO_AOT (numba compiles on first use)"
        return _TABLE
    manifest_path = _ROOT / MANIFEST
    try:
        manifest = json.loads(manifest_path.read_text())
    except (OSError, ValueError):
        _STATUS = "not built (numba compiles on first use)"
        return _TABLE
    if manifest.get("digest") != source_digest():
        _STATUS = "stale: built from other kernel sources (numba compiles on first use)"
        return _TABLE
    if manifest.get("cpu") != host_cpu():
        _STATUS = "built for another CPU (numba compiles on first use)"
        return _TABLE
    try:
        module = importlib.import_module(EXTENSION)
    except ImportError as exc:
        _STATUS = f"not loadable ({exc}); numba compiles on first use"
        return _TABLE
    for qualname, variants in manifest.get("kernels", {}).items():
        table = _TABLE.setdefault(qualname, {})
        for symbol, arg_types in variants:
            function = getattr(module, symbol, None)
            if function is not None:
                table[tuple(arg_types)] = function
    _STATUS = f"built ahead of time ({sum(len(t) for t in _TABLE.values())} kernel variants)"
    return _TABLE


def aot_status() -> str:
    """One line: whether the ahead-of-time kernels are in use, and why not."""
    _load()
    return _STATUS


_SCALARS = {bool: "bool", int: "int64", float: "float64"}
_ARRAY_NAMES: dict[tuple, str] = {}
_SCALAR_NAMES: dict[type, str] = {}


def type_key(value: Any) -> Optional[str]:
    """The name numba gives ``value``'s type (``str(numba.typeof(value))``) for the kinds of values the
    kernels take: arrays, Python and numpy scalars; None for anything else.  Computed here without numba's
    ``typeof``, which interns a type object on every call."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        if not flags.aligned:
            return None
        shape = (value.dtype, value.ndim, flags.c_contiguous, flags.f_contiguous, flags.writeable)
        name = _ARRAY_NAMES.get(shape)
        if name is None:  # numpy builds a dtype's name on every ask: each kind of array is named once
            layout = "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"
            readonly = "" if flags.writeable else "readonly "
            name = _ARRAY_NAMES[shape] = f"{readonly}array({value.dtype.name}, {value.ndim}d, {layout})"
        return name
    kind = _SCALARS.get(type(value))
    if kind is not None:
        return kind
    if isinstance(value, (np.integer, np.floating, np.bool_)):
        return _SCALAR_NAMES.get(type(value)) or _SCALAR_NAMES.setdefault(type(value), value.dtype.name)
    return None


class _Kernel:
    """A kernel marked with :func:`entry`: calls its ahead-of-time build for the argument types it was built
    for, and numba's dispatcher otherwise."""

    def __init__(self, dispatcher: Any, table: dict[tuple[str, ...], Callable]) -> None:
        self.dispatcher = dispatcher
        self.py_func = dispatcher.py_func
        self.__name__ = dispatcher.__name__
        self.__doc__ = dispatcher.__doc__
        self.__wrapped__ = dispatcher.py_func
        self._table = table

    def __call__(self, *args: Any) -> Any:
        return self.resolve(*args)(*args)

    def resolve(self, *args: Any) -> Callable:
        """What serves arguments of the types of ``args``: the ahead-of-time build, else numba's dispatcher (a
        caller that makes many small calls with the same types resolves once)."""
        return self._table.get(tuple(type_key(a) for a in args)) or self.dispatcher


def entry(dispatcher: Any) -> Any:
    """Mark a numba kernel that Python code calls (not other kernels: those call the dispatcher).

    Returns the dispatcher itself when no ahead-of-time build of it is available, else a callable that
    uses the build for the argument types it has and the dispatcher for any other.
    """
    qualname = f"{dispatcher.py_func.__module__}.{dispatcher.__name__}"
    ENTRIES[qualname] = dispatcher
    table = _load().get(qualname)
    return _Kernel(dispatcher, table) if table else dispatcher


def resolved(kernel: Any, *args: Any) -> Callable:
    """What serves ``kernel`` for arguments of the types of ``args`` (:meth:`_Kernel.resolve`; a plain numba
    dispatcher serves itself)."""
    return kernel.resolve(*args) if isinstance(kernel, _Kernel) else kernel
