"""``cam emulate-maximus`` and ``cam emulate-grbl``: the MAXIMUS firmware and grbl 1.1 emulators on a
pseudo-terminal (test benches, not host code)."""
from __future__ import annotations

import argparse

from ..sim import grbl as grbl_emulator
from ..sim import maximus as maximus_emulator

__all__ = ["cmd_emulate", "cmd_emulate_grbl"]


def cmd_emulate(args: argparse.Namespace) -> int:
    argv = ["--speed", str(args.speed)] + (["--log", args.log] if args.log else [])
    return int(maximus_emulator.main(argv) or 0)


def cmd_emulate_grbl(args: argparse.Namespace) -> int:
    argv = ["--speed", str(args.speed)] + [f"--set={item}" for item in args.set]
    return int(grbl_emulator.main(argv + (["--log", args.log] if args.log else [])) or 0)
