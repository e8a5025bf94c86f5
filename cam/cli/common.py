"""Helpers every command shares: machine settings from the options, the state file, durations, progress bars."""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
from pathlib import Path
from typing import Any

from tqdm import tqdm

from ..drive.maximus.board import with_delays
from ..values import format_duration
from ..drive.machines import DEFAULT_PORT, backend_of
from ..motion.ramps import check_delay_speeds, top_speeds_mm_s
from ..drive.state import default_state_path, recorded_machine
from ..errors import CamError
from ..settings import MachineSettings, load_settings

__all__ = ["speeds_line", "machine_settings", "port_settings", "format_duration", "progress_wanted", "reading_bar",
           "state_path_of", "use_recorded_machine"]


def state_path_of(args: argparse.Namespace) -> Path:
    """The state file of a command: ``--state``, else the default one of ``--port`` (and ``--machine`` on the
    mock; :func:`cam.drive.state.default_state_path`)."""
    given = getattr(args, "state", None)
    if given:
        return Path(given)
    return default_state_path(getattr(args, "machine", None), getattr(args, "port", None) or DEFAULT_PORT)


def use_recorded_machine(args: argparse.Namespace) -> None:
    """A command that holds the machine without ``--machine`` (nor ``--machine-changed``) runs with the machine
    file its state file records (issue #43 point 5): ``args.machine`` is set to it.

    Raises:
        CamError: the recorded machine file is gone (one line naming it and the state file).
    """
    if getattr(args, "machine", None) or getattr(args, "machine_changed", False) or not hasattr(args, "state"):
        return
    path = state_path_of(args)
    record = recorded_machine(path)
    if record is None or record.path is None:
        return
    if not Path(record.path).is_file():
        raise CamError(f"the state file {path} records machine file {record.path}, which is not there any more: "
                       f"give --machine FILE (with --machine-changed if the machine changed)")
    args.machine = record.path


def machine_settings(args: argparse.Namespace) -> MachineSettings:
    """The settings of --machine (or the built-in ones) with --steps-per-pixel, --delay and --ramp applied."""
    s = load_settings(args.machine)
    changes: dict[str, Any] = {}
    if args.steps_per_pixel:
        changes["steps_per_px_xy"], changes["steps_per_px_z"] = args.steps_per_pixel
    if args.delay:
        changes["delay_xy_ms"], changes["delay_z_ms"] = args.delay
    if getattr(args, "ramp", None):
        changes["ramp"] = args.ramp
    s = s.replace(**changes) if changes else s
    if args.delay:
        check_delay_speeds(s)  # a delay the ramps would not honour is refused, naming what limits it
    return s


def port_settings(args: argparse.Namespace, port: str) -> MachineSettings:
    """The machine settings for ``port``.

    A MAXIMUS board starts from its own settings (resolution, step modes, 16-bit travel, the PC program's
    Machine Settings form); --machine changes the keys it gives, --delay sets its Delay bytes and --spindle
    whether the spindle runs while it drills.  Without --machine, a command that holds the machine uses the
    machine file its state file records (:func:`use_recorded_machine`).
    """
    use_recorded_machine(args)
    backend = backend_of(port)
    base = backend.base_settings()
    if base is None:
        return machine_settings(args)
    s = backend.adapt_settings(load_settings(args.machine, base=base))
    if getattr(args, "delay", None):
        s = with_delays(s, *args.delay)
    if getattr(args, "spindle", None):
        s = s.replace(maximus=dataclasses.replace(s.maximus, spindle=args.spindle == "on"))
    return s


def speeds_line(settings: MachineSettings, port: str = DEFAULT_PORT) -> str:
    """One line: the top speed of each axis with the settings' ramps and delays (what ``cam info`` shows); on a
    MAXIMUS board its Delay bytes' feeds (:func:`~cam.drive.maximus.board.board_speeds_line`)."""
    own = backend_of(port).speeds_line(settings)
    if own is not None:
        return own
    x, y, z = top_speeds_mm_s(settings)
    return (f"top speeds: X {x:.3g}, Y {y:.3g}, Z {z:.3g} mm/s ({settings.ramp} ramps, delays "
            f"{settings.delay_xy_ms:g}/{settings.delay_z_ms:g} ms)")


def progress_wanted(args: argparse.Namespace) -> bool:
    """Whether to draw a progress bar: --progress forces it, --no-progress forbids it, and otherwise only
    when stderr is a terminal (so a log or a pipe gets no bar, and an error stays one line)."""
    if getattr(args, "progress", False):
        return True
    if getattr(args, "no_progress", False):
        return False
    return sys.stderr is not None and sys.stderr.isatty()


def reading_bar(args: argparse.Namespace):
    """A progress bar by bytes read (large HPGL files), as :func:`progress_wanted` says; yields its callback or None."""
    if not progress_wanted(args):
        return contextlib.nullcontext(None)

    @contextlib.contextmanager
    def bar_callback():
        total = Path(args.image).stat().st_size if Path(args.image).is_file() else None
        with tqdm(total=total, unit="B", unit_scale=True, desc="reading", file=sys.stderr, mininterval=0.2,
                  leave=False) as bar:
            yield lambda done, total_bytes: bar.update(done - bar.n)

    return bar_callback()
