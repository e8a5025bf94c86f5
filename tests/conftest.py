"""Shared test helpers: tiny drawings, the carve check, the command line in this process, and the test tiers.

Test tiers (markers, declared in pyproject.toml; ``--strict-markers`` refuses any other):

``browser``
    drives the web page in Chromium through Playwright.
``realtime``
    runs an emulator, a machine session or ``cam drill --realtime`` at real speed (waits on the clock).
``packaging``
    ``pip install`` or ``pip wheel``, a virtual environment, a fresh kernel cache, or a check of what an
    install ships.
``slow``
    anything else that would make the fast tier too slow (large inputs, many planned jobs, fuzzing, memory
    bounds on 200 MB files, benchmarks, real ``python -m cam`` processes kept for what only a process shows).

A test marked ``browser``, ``realtime`` or ``packaging`` is marked ``slow`` too: this file adds the ``slow``
marker to it (``pytest_collection_modifyitems``), so mark it with its kind only.

``python -m pytest tests`` runs every test (nothing is deselected by default; the README's and .ci/run's
command).  ``python -m pytest -m "not slow"`` is the fast tier, for every commit: it still runs every module's
behaviour, with at least one end-to-end test per input kind (2D and 3D drawings, profiles, digitized matrices,
Excellon, HPGL, SVG, G-code) and the mock port's pin-log carve check.  ``-m slow`` runs the rest.

The measured time of each tier is in docs/tests.md (the fast tier: 1,729 tests in 2 min 52 s on the idle 2-core
machine, 2026-11-26).  Keep a new test in the fast tier only if it takes well under a second; give its costly
cases ``pytest.param(..., marks=pytest.mark.slow)``, or name them in the module's ``SLOW_CASES``.

The command line is tested in this process (:func:`run_cli`: ``cam.cli.main`` with its own stdout, stderr and
stdin, exit code from its return value or ``SystemExit``), which saves the 2.6 s of imports every
``python -m cam`` process pays; a few tests still start a real process: ``python -m cam --help``, a bad input's
exit code, one real run, and what needs a process (signals, a terminal, a killed run, a missing package).
"""
from __future__ import annotations

import ast
import functools
import gc
import io
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

ROOT = Path(__file__).resolve().parent.parent

# Compiled bytecode, kept outside the tree (<root>/.pytest_cache/pycache): where PYTHONDONTWRITEBYTECODE is set
# (this development machine sets it) every run would otherwise compile cam and re-write the asserts of every
# test module again (9 s of the fast tier's collection), and every `python -m cam` a test starts would compile
# cam (0.4 s each).  Set before cam or a test module is imported; the environment carries it to those processes.
if sys.dont_write_bytecode and not os.environ.get("CAM_TESTS_NO_BYTECODE"):
    sys.pycache_prefix = sys.pycache_prefix or str(ROOT / ".pytest_cache" / "pycache")
    sys.dont_write_bytecode = False
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    os.environ["PYTHONPYCACHEPREFIX"] = sys.pycache_prefix

import numpy as np  # noqa: E402 (after the bytecode setting above)
import pytest  # noqa: E402

import cam  # noqa: E402

SAMPLES = ROOT / "samples"

# The machine state files (cam.drive.state) of the commands the tests run, in this process and in the
# `python -m cam` processes they start (whose environment is copied from this one): a folder of this test
# session's own, emptied before each test, never the user's ~/.local/state/cam (see state_home below).
STATE_HOME = Path(tempfile.mkdtemp(prefix="cam-tests-state-"))
os.environ["XDG_STATE_HOME"] = str(STATE_HOME)


@functools.lru_cache(maxsize=None)
def parsed_source(path: Path) -> ast.Module:
    """The syntax tree of a source file, parsed once for every test that reads cam's sources (do not change it)."""
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


_ACTIVITY_THREAD = re.compile(r"cam-(job|jog|origin|home|probe)$")
"""The names of a machine session's activity threads (cam.drive.session: ``cam-{activity}``)."""


@pytest.fixture(autouse=True)
def state_home():
    """Each test starts with no machine state: every machine at its home, position known, nothing running.

    A test ends when the machine activities it started have ended (at most 10 s each): an activity still running
    when its emulator was stopped ends in a link fault a moment later, and the fault's marker (keyed by the
    device, /dev/pts/N) must land in this test's state folder, not in the next test's, whose emulator may get the
    same pty."""
    shutil.rmtree(STATE_HOME / "cam", ignore_errors=True)
    yield STATE_HOME / "cam"
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and _ACTIVITY_THREAD.match(thread.name):
            thread.join(10)


def pytest_sessionstart(session):
    """Fill numba's kernel cache before the first test (a no-op once it is filled: about 2 s to check).

    ``cam`` compiles its kernels on a machine's first run (cam/_compiled.py); a test whose subprocess must answer
    within a limit would otherwise count a minute of compiling on a fresh machine.  Done here, the README's test
    command is the whole of what a fresh machine needs, as ``.ci/run`` runs it."""
    from cam._kernel_cache import compile_all

    compile_all(progress=True)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """Each test starts with this process's garbage collected and what is left frozen out of later collections.

    The emulators (MAXIMUS, grbl) run their firmware in a thread of this process, so a pause of the process is
    a pause of the board's firmware, which a real board never has.  A full collection of the process's objects
    (the parsed sources :func:`parsed_source` keeps, every module loaded) took up to 1.55 s late in the suite on
    a loaded machine, longer than the MAXIMUS host's 1.0 s reply margin.  Frozen objects are never scanned again
    (:func:`gc.freeze`), so a collection during a test scans only what that test made: at most 0.37 s in the
    same run with this."""
    gc.collect()
    gc.freeze()


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(STATE_HOME, ignore_errors=True)


def drawing_from_rows(rows: list[str]) -> np.ndarray:
    """A grey image from text rows: '#' = black, anything else white."""
    h, w = len(rows), max(len(r) for r in rows)
    img = np.full((h, w), 255, np.uint8)
    for r, line in enumerate(rows):
        for c, ch in enumerate(line):
            if ch == "#":
                img[r, c] = 0
    return img


def expected_surface_2d(digitized: cam.Digitized, depths_px: list[int], settings: cam.MachineSettings) -> np.ndarray:
    """What the drawing asks for: each traced pixel at its object's depth (Z steps), 0 elsewhere."""
    out = np.zeros((digitized.height_px, digitized.width_px), np.int64)
    for obj, d in zip(digitized.objects, depths_px):
        out[obj[:, 1], obj[:, 0]] = d * settings.steps_per_px_z
    return out


def carve_job(job: cam.Job, **run_kwargs) -> tuple[np.ndarray, cam.RunResult, cam.Motion]:
    """Run a toolpath on the mock, decode the pin log, carve with a point tool."""
    result = cam.run(job, **run_kwargs)
    motion = cam.decode_pin_log(result.pin_log(), job.settings)
    surface = cam.carve(motion, (job.height_px, job.width_px), job.settings, origin_px=job.origin_px)
    return surface, result, motion


def assert_surface_equal(got: np.ndarray, want: np.ndarray) -> None:
    diff = np.argwhere(got != want)
    if len(diff):
        r, c = diff[0]
        raise AssertionError(
            f"{len(diff)} pixel(s) differ; first at (x={c}, y={r}): cut {got[r, c]} Z steps, asked {want[r, c]}"
        )


@pytest.fixture
def small_pin_log_queue(monkeypatch):
    """Makes a streamed pin log's writer queue small (one group of 4096 writes).  How full its default queue (up to
    about 13 MB) is when a peak of memory is taken depends on the disk and the scheduler, not on the job, so
    memory tests that compare two jobs' peaks use this to compare what the jobs hold."""
    import cam.drive.ports as ports
    monkeypatch.setattr(ports, "_LOG_QUEUE", 1)
    monkeypatch.setattr(ports, "_LOG_ROWS", 1 << 12)


@pytest.fixture
def tiny_settings() -> cam.MachineSettings:
    """Fast settings for real-time tests: 2 steps/pixel, 1 ms periods."""
    return cam.MachineSettings().replace(steps_per_px_xy=2, delay_xy_ms=1.0, delay_z_ms=1.0)


@pytest.fixture
def emu():
    """A MAXIMUS emulator on a pseudo-terminal, sped up (no waiting for the firmware's delays)."""
    from cam.sim.maximus import start_emulator

    e = start_emulator(speed=None)
    yield e
    e.stop()
    assert e.error is None, repr(e.error)


def wait_for_progress(proc, percent: int, timeout_s: float = 60.0) -> list:
    """Read a command's stderr (its ``--progress`` bar) until it shows ``percent`` %; returns the chunks read so
    far, which a thread keeps filling (join ``chunks.reader`` after the process ends)."""
    import os
    import re
    import threading
    import time

    chunks: list = []
    reader = threading.Thread(target=lambda: chunks.extend(iter(lambda: os.read(proc.stderr.fileno(), 4096), b"")),
                              daemon=True)
    reader.start()
    deadline = time.monotonic() + timeout_s
    while max([int(v) for v in re.findall(rb"(\d+)%", b"".join(chunks))] or [0]) < percent:
        assert time.monotonic() < deadline and proc.poll() is None, b"".join(chunks)
        time.sleep(0.02)
    wait_for_progress.reader = reader
    return chunks


# -- test tiers ---------------------------------------------------------------------------------------------

_SLOW_KINDS = ("browser", "realtime", "packaging")


@pytest.hookimpl(tryfirst=True)  # before -m selects: a realtime test is slow when "not slow" is applied
def pytest_collection_modifyitems(config, items):
    """Every browser, realtime and packaging test is slow too (see the module docstring); so is every test whose
    name is in its module's ``SLOW_CASES`` (a case of a test parametrized through a fixture, which
    ``pytest.param`` marks cannot single out)."""
    for item in items:
        slow_cases = getattr(item.module, "SLOW_CASES", ())
        if (any(item.get_closest_marker(kind) is not None for kind in _SLOW_KINDS) or item.name in slow_cases) \
                and item.get_closest_marker("slow") is None:
            item.add_marker(pytest.mark.slow)


# -- the command line in this process -----------------------------------------------------------------------

@dataclass
class CliRun:
    """What ``python -m cam ARGS`` gives back, as :class:`subprocess.CompletedProcess` names it."""
    args: list
    returncode: int
    stdout: str
    stderr: str


_STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))

# Python's default warning filters (python -W default is not given): what a ``python -m cam`` process shows
_DEFAULT_FILTERS = (("ignore", DeprecationWarning), ("ignore", PendingDeprecationWarning),
                    ("ignore", ImportWarning), ("ignore", ResourceWarning))


def _numba_listeners() -> tuple:
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover
        return None, []
    return event, list(event._registered.get("numba:compile", []))


def one_line_error(proc, *fragments: str) -> str:
    """Exit 2 and one error line on stderr (no traceback; the first-run notice and grbl's settings warning
    aside) naming every fragment; returns the line."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = [line for line in proc.stderr.splitlines()
             if line.strip() and "first run only" not in line and not line.startswith("warning: grbl's settings")]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def ok(proc):
    """Exit 0 (else the command's output in the failure); returns ``proc``."""
    assert proc.returncode == 0, (proc.stdout, proc.stderr)
    return proc


def run_cli(*args, cwd: Optional[os.PathLike] = None, env: Optional[dict] = None, stdin: str = "",
            timeout: Optional[float] = None) -> CliRun:
    """``python -m cam ARGS`` in this process: ``cam.cli.main`` with its own stdout and stderr (pipes to it:
    not terminals, so no progress bar unless asked), an empty stdin that cannot be selected on (a prompt
    reads no answer, as with ``stdin=DEVNULL``), ``cwd`` and ``env`` (entries set for the call) applied and
    restored.  The exit code comes from main's return value or a ``SystemExit`` (``--help``, argparse's
    errors); any other exception is a traceback on stderr and exit code 1, as the interpreter would make it.
    Warnings go to stderr as a process shows them (Python's default filters).  Signal handlers and numba's
    compile listeners that main installs are removed afterwards.  ``timeout`` is accepted for the
    subprocess-shaped call sites and not enforced."""
    from cam.cli import main

    argv = [str(a) for a in args]
    out_buf, err_buf = io.BytesIO(), io.BytesIO()
    out = io.TextIOWrapper(out_buf, encoding="utf-8", errors="replace", write_through=True)
    err = io.TextIOWrapper(err_buf, encoding="utf-8", errors="replace", write_through=True)
    inp = io.TextIOWrapper(io.BytesIO(stdin.encode()), encoding="utf-8")
    saved_streams = sys.stdin, sys.stdout, sys.stderr
    saved_handlers = {s: signal.getsignal(s) for s in _STOP_SIGNALS}
    saved_cwd = os.getcwd()
    saved_env = {k: os.environ.get(k) for k in (env or {})}
    event, listeners = _numba_listeners()
    code = 0
    try:
        if cwd is not None:
            os.chdir(cwd)
        for k, v in (env or {}).items():
            os.environ[k] = str(v)
        sys.stdin, sys.stdout, sys.stderr = inp, out, err
        with warnings.catch_warnings(record=True) as caught:
            warnings.resetwarnings()
            warnings.simplefilter("default")
            for action, category in _DEFAULT_FILTERS:
                warnings.filterwarnings(action, category=category)
            try:
                code = main(argv)
            except SystemExit as exc:
                if exc.code is None:
                    code = 0
                elif isinstance(exc.code, int):
                    code = exc.code
                else:
                    print(exc.code, file=err)
                    code = 1
            except Exception:  # noqa: BLE001 - as the interpreter: the traceback, exit code 1
                err.write(traceback.format_exc())
                code = 1
        for w in caught:
            err.write(warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line))
    finally:
        sys.stdin, sys.stdout, sys.stderr = saved_streams
        for s, handler in saved_handlers.items():
            if signal.getsignal(s) is not handler and handler is not None:
                signal.signal(s, handler)
        os.chdir(saved_cwd)
        for k, v in saved_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        if event is not None:
            for listener in event._registered.get("numba:compile", [])[len(listeners):]:
                event.unregister("numba:compile", listener)
        for stream in (out, err, inp):
            stream.flush()

    def text(buf: io.BytesIO) -> str:  # as subprocess.run(text=True) reads a pipe: universal newlines
        return buf.getvalue().decode("utf-8", errors="replace").replace("\r\n", "\n").replace("\r", "\n")

    return CliRun(argv, int(code), text(out_buf), text(err_buf))


@pytest.fixture
def cli_run():
    """:func:`run_cli`, as a fixture."""
    return run_cli
