"""The command line (``python -m cam``, the ``cam`` script): a thin adapter over the library.

:func:`main` parses the arguments first (:mod:`cam.cli.parser` imports no
numpy, numba, OpenCV or web stack, so ``cam --help`` starts at once), then
loads only the module of the chosen command, which imports the library it
needs.  Any :class:`~cam.errors.CamError` becomes one line on stderr and exit
code 2.
"""
from __future__ import annotations

import gc
import importlib
import os
import sys
from typing import Optional, Sequence

from ..errors import CamError
from .checks import check_args
from .parser import EXIT_BAD_INPUT, EXIT_INTERRUPTED, build_parser

__all__ = ["main", "build_parser", "COMMANDS"]

COMMANDS = {
    "drill": ("cam.cli.drill", "cmd_drill"),
    "export": ("cam.cli.files", "cmd_export"),
    "preview": ("cam.cli.files", "cmd_preview"),
    "digitize": ("cam.cli.files", "cmd_digitize"),
    "info": ("cam.cli.files", "cmd_info"),
    "profile": ("cam.cli.files", "cmd_profile"),
    "trace": ("cam.cli.trace", "cmd_trace"),
    "jog": ("cam.cli.machine", "cmd_jog"),
    "goto": ("cam.cli.machine", "cmd_goto"),
    "where": ("cam.cli.machine_state", "cmd_where"),
    "zero": ("cam.cli.machine_state", "cmd_zero"),
    "home": ("cam.cli.home", "cmd_home"),
    "probe": ("cam.cli.probe", "cmd_probe"),
    "tools": ("cam.cli.tools", "cmd_tools"),
    "serve": ("cam.cli.serve", "cmd_serve"),
    "emulate-maximus": ("cam.cli.emulate", "cmd_emulate"),
    "emulate-grbl": ("cam.cli.emulate", "cmd_emulate_grbl"),
}
"""Command name -> (module, function).  The module is imported only when its command runs: lazy by design."""


FIRST_COMPILE_NOTE = ("cam: compiling kernels for this machine into {where}, first run only "
                      "(up to a minute or two; later runs load them from there)")
"""The line said once on stderr when a run compiles a kernel (:func:`_note_first_compile`)."""


def _note_first_compile() -> None:
    """Say once on stderr when a compiled kernel is not in numba's cache (the first run on a machine, or with an
    empty ``NUMBA_CACHE_DIR``): compiling takes a minute, and the run should not sit silent.  numba reports each
    real compilation (not a load from its cache) as a ``numba:compile`` event."""
    from .._compiled import cache_dir  # points numba's cache at cam's folder, before numba is imported

    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - another numba layout: say nothing
        return
    where = cache_dir()
    note = FIRST_COMPILE_NOTE.format(where=where if where is not None else "numba's cache")

    class _Note(event.Listener):
        said = False

        def on_start(self, ev) -> None:
            if not _Note.said:
                _Note.said = True
                print(note, file=sys.stderr, flush=True)

        def on_end(self, ev) -> None:
            pass

    event.register("numba:compile", _Note())


def main_process() -> int:
    """Entry point of the ``cam`` script and ``python -m cam``: :func:`main` in a process of its own."""
    return main(own_process=True)


def main(argv: Optional[Sequence[str]] = None, *, own_process: bool = False) -> int:
    """Run one command (``argv``: the command line without the program name; None: ``sys.argv[1:]``); returns
    the exit code.  :func:`main_process` is the entry point of ``python -m cam`` and the ``cam`` script.

    ``own_process``: this process runs only this command (``python -m cam``): once the command's modules are
    imported, the garbage collector is told to leave everything that exists then alone (:func:`gc.freeze`: a
    long job's send loop then does not pay for walking numba's objects over and over)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.command:
        sys.stderr.write(parser.format_usage())
        return EXIT_BAD_INPUT
    module_name, function_name = COMMANDS[args.command]
    try:
        check_args(args)
        _note_first_compile()  # every output path and flag, before anything is planned, written or sent
        command = getattr(importlib.import_module(module_name), function_name)
        if own_process:
            gc.freeze()
        return int(command(args))
    except CamError as exc:
        print(f"cam: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("cam: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # e.g. `cam info board.drl | head`: the reader left; that is not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:  # a path the system refuses (a name too long, no permission): one line, not a traceback
        name = str(exc.filename)[:80] + ("..." if len(str(exc.filename)) > 80 else "") if exc.filename else ""
        print(f"cam: error: {name + ': ' if name else ''}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
