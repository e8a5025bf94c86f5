"""``cam emulate-maximus``: the MAXIMUS firmware emulator on a pseudo-terminal (a test bench, not host code)."""
from __future__ import annotations

import argparse

from ..sim import maximus as maximus_emulator

__all__ = ["cmd_emulate"]


def cmd_emulate(args: argparse.Namespace) -> int:
    argv = ["--speed", str(args.speed)] + (["--log", args.log] if args.log else [])
    return int(maximus_emulator.main(argv) or 0)
