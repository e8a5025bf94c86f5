"""Running an emulator from the command line until Ctrl-C or its own fault (``cam emulate-maximus``,
``cam emulate-grbl``)."""
from __future__ import annotations

import sys
import time
from typing import Any

__all__ = ["serve_until_stopped"]


def serve_until_stopped(emulator: Any) -> int:
    """Wait while ``emulator`` (a started emulator: ``error``, ``stop()``) runs; stop it on Ctrl-C or its own fault.

    Returns the exit code: 0 after Ctrl-C, 1 when the emulator stopped on a fault (said on stderr).
    """
    try:
        while emulator.error is None:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        emulator.stop()
    if emulator.error is not None:
        print(f"emulator stopped: {emulator.error}", file=sys.stderr)
        return 1
    return 0
