"""``cam emulate-maximus`` and ``cam emulate-grbl``: the MAXIMUS firmware and grbl 1.1 emulators on a
pseudo-terminal (test benches, not host code)."""
from __future__ import annotations

import argparse

from ..errors import CamError
from ..sim import grbl as grbl_emulator
from ..sim import maximus as maximus_emulator

__all__ = ["cmd_emulate", "cmd_emulate_grbl"]


def cmd_emulate(args: argparse.Namespace) -> int:
    bad = maximus_emulator.travel_error(args)
    if bad:
        raise CamError(bad)
    argv = ["--speed", str(args.speed)] + (["--log", args.log] if args.log else [])
    for axis in "xyz":  # the limit switches (cam.drive.maximus.switch_options.add_maximus_switch_options)
        ends = getattr(args, f"travel_{axis}", None)
        if ends is not None:
            argv += [f"--travel-{axis}", str(ends[0]), str(ends[1])]
    argv += [f"--axis-delay={int(getattr(args, 'axis_delay', 0))}"]
    argv += [f"--trip={name}@{skip}" for name, skip in getattr(args, "trip", [])]
    return int(maximus_emulator.main(argv) or 0)


def cmd_emulate_grbl(args: argparse.Namespace) -> int:
    argv = ["--speed", str(args.speed)] + [f"--set={item}" for item in args.set]
    if args.probe_surface:
        argv.append(f"--probe-surface={args.probe_surface}")
    return int(grbl_emulator.main(argv + (["--log", args.log] if args.log else [])) or 0)
