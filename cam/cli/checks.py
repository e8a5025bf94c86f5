"""Every option checked before anything is planned, written or sent.

:func:`check_args` runs in :func:`cam.cli.main` right after parsing, for
every command: each output path must be writable where it points, and each
flag must apply to the file's kind (a flag that does not apply is an error,
never ignored), and the flags must keep the rules between options
(:data:`cam.options.RULES`: one depth, ...).  A bad one is one line on stderr
and exit code 2, and nothing has moved.  It then fills in the defaults of options left out.  (Options that
need a port's capability are checked by the commands that open a port, before
they plan: :func:`cam.cli.execute.check_port_options`.)

Standard library and light modules only (it runs before the command's module
loads the library).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Optional

from ..choices import is_height_map
from ..errors import CamError
from ..kinds import forced_kind, job_kind, job_options, kind, kind_names, kinds
from ..options import OPTION_OF_DEST, OPTIONS, broken_rule, degenerate

__all__ = ["check_args", "job_kind_of", "OUTPUTS", "applies_to", "check_output_path"]



def applies_to() -> dict[str, frozenset[str]]:
    """Which file kinds each option applies to (drill, export, preview and info): the job options' kinds
    (:func:`cam.kinds.job_options`, from the kinds' traits) and the command line's own flags for drawings in
    pixels; ``cam export`` widens some (:func:`_check_applies`)."""
    pixels = frozenset(k.name for k in kinds() if "pixels" in k.all_traits)
    return {**{o.dest: o.kinds for o in job_options()},
            "load_digitized": pixels, "steps_per_pixel": pixels, "save_digitized": frozenset({"drawing"}),
            "surface": pixels}


_EXPORT_WIDENS = ("travel_height", "flip_y")
"""export writes every kind's travel at --travel-height, and --flip-y mirrors Y of every kind."""

OUTPUTS = {
    # option dest: (flag, accepted suffixes or None for any)
    "pin_log": ("--pin-log", (".csv",)),
    "report": ("--report", (".json",)),
    "journal": ("--journal", (".json",)),
    "preview": ("--preview", (".png", ".svg")),
    "save_digitized": ("--save-digitized", None),  # a digitized matrix's suffixes (cam.kinds.digitized)
    "output": ("--output", None),
    "log": ("--log", (".csv",)),
    "out": ("--out", (".json",)),
}
"""Files a command writes, checked before it starts."""

_OUTPUT_SUFFIXES = {"preview": (".png", ".svg"), "digitize": None, "export": None,
                    "trace": (".png", ".bmp", ".tif", ".tiff")}
"""What ``-o`` of each command writes."""

_DEFAULTS = {OPTIONS[name].dest: (list(OPTIONS[name].default) if isinstance(OPTIONS[name].default, tuple)
                                   else OPTIONS[name].default)
             for name in ("start", "passes", "start_at", "pause_at", "drill_order")}
"""Defaults of options that are None when not given (so that a given one can be told apart).  --depth stays
None when left out: 10 Z pixels on a 2D drawing, and a 3D drawing then needs a profile."""


def job_kind_of(args: argparse.Namespace, warnings: Optional[list[str]] = None) -> Optional[str]:
    """The kind of the command's input file ("drawing", "excellon", ...) by its suffix and, where the suffix is
    generic, unknown or contradicted, its first few kB (:func:`cam.kinds.job_kind`), or None."""
    image = getattr(args, "image", None)
    if image and getattr(args, "kind", None):  # --kind: what the user says, whatever the name and content
        return forced_kind(args.kind)
    if image:
        return job_kind(image, warnings)
    if getattr(args, "load_digitized", None):
        return "digitized"
    return None


def check_output_path(path: str, flag: str, suffixes: Optional[tuple[str, ...]] = None) -> None:
    """Refuse an output path that cannot be written: a missing folder, a folder, a read-only place, a wrong suffix."""
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise CamError(f"{flag} {path}: the file must end in {' or '.join(suffixes)}")
    if not folder.is_dir():
        raise CamError(f"{flag} {path}: folder {folder} does not exist")
    if p.is_dir():
        raise CamError(f"{flag} {path}: is a folder, not a file")
    if not os.access(folder, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise CamError(f"{flag} {path}: cannot write there (permission denied)")


def _given(args: argparse.Namespace, dest: str) -> bool:
    value = getattr(args, dest, None)
    return value is not None and value is not False and value != []


def _check_applies(args: argparse.Namespace, kind: str) -> None:
    table = applies_to()
    every = frozenset(kind_names())
    if args.command == "export":
        table.update({dest: every for dest in _EXPORT_WIDENS})
    if args.command == "preview":
        table["scale"] = every  # picture pixels per drawing pixel, or an SVG's scale
    for dest, applies in table.items():
        if hasattr(args, dest) and _given(args, dest) and kind not in applies:
            flag = OPTION_OF_DEST[dest].flag if dest in OPTION_OF_DEST else "--" + dest.replace("_", "-")
            names = " and ".join(sorted(applies))
            raise CamError(f"{flag} does not apply to {getattr(args, 'image', None) or 'this job'} "
                           f"(a {kind} file); it applies to {names} files")


def _check_rules(args: argparse.Namespace) -> None:
    """The rules between the job options (:data:`cam.options.RULES`: one depth, ...), named by their flags."""
    broken = broken_rule(lambda name: getattr(args, OPTIONS[name].dest, None), lambda name: OPTIONS[name].flag)
    if broken is not None:
        raise CamError(f"{OPTIONS[broken[0]].flag} {broken[1]}")


def _check_outputs(args: argparse.Namespace) -> None:
    for dest, (flag, suffixes) in OUTPUTS.items():
        path = getattr(args, dest, None)
        if not path:
            continue
        if dest == "output":
            suffixes = _OUTPUT_SUFFIXES.get(args.command)
        if dest == "save_digitized" or (dest == "output" and args.command == "digitize"):
            suffixes = kind("digitized").suffixes  # a saved digitized matrix
        check_output_path(path, flag, suffixes)


def check_args(args: argparse.Namespace) -> None:
    """Check every option of ``args`` before the command runs, then fill kind-dependent defaults.

    Raises:
        CamError: an unwritable output, a flag that does not apply to the file's kind, or flags that break a rule
        between options (:func:`cam.options.broken_rule`); the message names the flags.  Options against the
        port are checked by :func:`cam.cli.execute.check_port_options`.
    """
    _check_outputs(args)
    warnings: list[str] = []
    image = getattr(args, "image", None)
    if args.command in ("drill", "export", "preview", "info") and image and is_height_map(image):
        if args.command in ("drill", "export"):  # a map is no job: it levels one
            raise CamError(f"{image} is a height map, not a job: level a job by it with --level {image}, or show it "
                           f"with cam info / cam preview")
        over = getattr(args, "over", None)  # cam preview MAP.json --over FILE: the job's options are FILE's
        kind = job_kind(over, warnings) if over and Path(over).is_file() else None
    else:
        kind = job_kind_of(args, warnings) if args.command in ("drill", "export", "preview", "info") else None
    args.kind_warnings = warnings
    for w in warnings:  # a suffix the content contradicts: said before anything is read
        print(f"warning: {w}", file=sys.stderr)
    if kind is not None:
        _check_applies(args, kind)
    if args.command in ("drill", "export", "preview", "info"):  # (cam trace's own --trace-min-length needs no --trace)
        _check_rules(args)
    odd = degenerate(lambda name: getattr(args, OPTIONS[name].dest, None))  # zero where zero is unsafe
    if odd is not None:
        raise CamError(f"{OPTIONS[odd[0]].flag} {odd[1]}")
    for dest, value in _DEFAULTS.items():
        if hasattr(args, dest) and getattr(args, dest) is None:
            setattr(args, dest, value)
