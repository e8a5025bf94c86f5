"""Fill numba's cache with cam's kernels, and list the argument types they are called with (see
:mod:`cam._compiled`).

``python -m cam._kernel_cache compile`` compiles every kernel marked with
:func:`cam._compiled.entry` for the argument types in
:mod:`cam._kernel_signatures` into numba's on-disk cache (``--cache-dir`` or
:func:`cam._compiled.cache_dir`): after it no run on this machine compiles.
Nothing needs it (a run compiles what it uses, once); it prepares a machine,
or an image, ahead of the first job.  ``status`` says how many of those kernels
are cached.

``python -m cam._kernel_cache collect`` runs the sample jobs and rewrites
:mod:`cam._kernel_signatures` with the argument types they used (run it after
changing a kernel's arguments; a test checks the list is complete).
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ._compiled import ENTRIES, KERNEL_MODULES, cache_dir

ROOT = Path(__file__).resolve().parent
SAMPLES = ROOT.parent / "samples"


def type_expr(t: Any) -> str:
    """A Python expression over ``numba.types`` that evaluates to the numba type ``t``."""
    from numba.core import types

    if isinstance(t, types.Array):
        readonly = "" if t.mutable else ", readonly=True"
        return f"Array({type_expr(t.dtype)}, {t.ndim}, {t.layout!r}{readonly})"
    if isinstance(t, types.UniTuple):
        return f"UniTuple({type_expr(t.dtype)}, {t.count})"
    if isinstance(t, types.Tuple):
        return "Tuple((" + "".join(type_expr(x) + ", " for x in t.types) + "))"
    if isinstance(t, types.Boolean):
        return "boolean"
    if isinstance(t, (types.Integer, types.Float, types.NoneType)):
        return str(t)
    raise TypeError(f"no written form for argument type {t}")


def load_kernels() -> None:
    """Import every module of :data:`cam._compiled.KERNEL_MODULES` (fills :data:`cam._compiled.ENTRIES`)."""
    for name in KERNEL_MODULES:
        importlib.import_module(name)


def signatures() -> list[tuple[str, Any, tuple]]:
    """(kernel name, dispatcher, argument types) for every line of :mod:`cam._kernel_signatures`."""
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


def compile_all(progress: bool = True) -> tuple[int, int]:
    """Compile every kernel of :mod:`cam._kernel_signatures` into numba's cache (those not cached yet);
    returns (compiled, already cached)."""
    todo = signatures()
    compiled = cached = 0
    for index, (qualname, dispatcher, arg_types) in enumerate(todo, 1):
        if is_cached(dispatcher, arg_types):
            cached += 1
            continue
        start_s = time.monotonic()
        dispatcher.compile(arg_types)
        compiled += 1
        if progress:
            print(f"cam: [{index}/{len(todo)}] {qualname} ({time.monotonic() - start_s:.1f} s)", file=sys.stderr,
                  flush=True)
    return compiled, cached


def sample_commands(tmp: Path) -> list[list[str]]:
    """The CLI runs whose kernel argument types the table covers: every sample kind, each ramp mode."""
    s = SAMPLES
    out = lambda name: str(tmp / name)  # noqa: E731
    return [
        ["drill", str(s / "ellipse.png"), "--depth", "5", "--pin-log", out("a.csv")],
        ["drill", str(s / "two_curves.png"), "--depth", "3", "--ramp", "constant"],
        ["drill", str(s / "disc.png"), "--depth", "4", "--ramp", "linear40"],
        ["drill", str(s / "pyramid.png"), "--depth", "6"],
        ["drill", str(s / "board.drl"), "--yes", "--pin-log", out("b.csv")],
        ["drill", str(s / "inkscape_star.plt"), "--yes"],
        ["drill", str(s / "seed_tools.plt"), "--yes", "--ramp", "constant"],
        ["drill", str(s / "bolt_plate.ngc"), "--yes"],
        ["drill", str(s / "logo.svg")],
        ["drill", str(s / "sketch.jpg"), "--trace", "--depth", "2"],
        ["drill", str(s / "heart.png"), "--profile", str(ROOT.parent / "profiles" / "dome.png")],
        ["drill", str(s / "disc.png"), "--profile-expr", "k // 2", "--yes"],
        ["info", str(s / "extended.plt")],
        ["preview", str(s / "heart.png"), "--depth", "3", "-o", out("p.png")],
    ]


def collect() -> dict[str, list[str]]:
    """Run :func:`sample_commands` in this process; return kernel -> argument type lists."""
    from .cli import main

    with tempfile.TemporaryDirectory() as tmp:
        for argv in sample_commands(Path(tmp)):
            code = main(argv)
            if code != 0:
                raise SystemExit(f"sample run failed ({code}): cam {' '.join(argv)}")
    load_kernels()
    found: dict[str, list[str]] = {}
    for qualname, dispatcher in sorted(ENTRIES.items()):
        found[qualname] = sorted("(" + "".join(type_expr(t) + ", " for t in sig) + ")"
                                 for sig in dispatcher.signatures)
    return found


def write_signatures(found: dict[str, list[str]]) -> Path:
    """Rewrite :mod:`cam._kernel_signatures` with ``found``; return its path."""
    path = ROOT / "_kernel_signatures.py"
    lines = ['"""Argument types of each kernel Python calls, as the sample jobs use them (generated by',
             '``python -m cam._kernel_cache collect``; ``python -m cam._kernel_cache compile`` compiles exactly '
             'these)."""', "",
             "SIGNATURES = {"]
    for qualname, sigs in found.items():
        lines.append(f"    {qualname!r}: [")
        lines += [f"        {sig!r}," for sig in sigs]
        lines.append("    ],")
    lines.append("}")
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m cam._kernel_cache", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cache-dir", type=Path, help="numba's cache folder (default: NUMBA_CACHE_DIR, else "
                                                       "~/.cache/cam/numba)")
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("compile", help="compile every kernel of cam/_kernel_signatures.py into the cache")
    sub.add_parser("status", help="how many of those kernels the cache holds")
    sub.add_parser("collect", help="rewrite cam/_kernel_signatures.py from the sample jobs")
    args = parser.parse_args(argv)
    if args.cache_dir is not None:
        if "numba" in sys.modules:  # pragma: no cover - run as a script, numba is not imported yet
            raise SystemExit("--cache-dir must be given before numba is imported")
        os.environ["NUMBA_CACHE_DIR"] = str(args.cache_dir)
    start_s = time.monotonic()
    where = cache_dir() or "numba's default"
    if args.what == "collect":
        print(f"{write_signatures(collect())} ({time.monotonic() - start_s:.1f} s)", file=sys.stderr)
    elif args.what == "status":
        todo = signatures()
        held = sum(is_cached(d, t) for _, d, t in todo)
        print(f"{held} of {len(todo)} kernels cached in {where}")
    else:
        compiled, cached = compile_all()
        print(f"cam: {compiled} kernels compiled, {cached} already cached, in {where} "
              f"({time.monotonic() - start_s:.1f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
