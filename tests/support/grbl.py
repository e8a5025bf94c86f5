"""Fixtures of the tests that drive the grbl emulator (cam.sim.grbl) on a pty."""
from __future__ import annotations

import sys

import pytest

from cam.drive.grbl_machine import close_grbl_machines


@pytest.fixture(autouse=True)
def quick_thread_switches():
    """The emulator, the link's reader and the test share the GIL: switch threads every 0.5 ms, not 5 ms; the
    grbl links the test's sessions opened are closed after it."""
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)
    yield
    sys.setswitchinterval(before)
    close_grbl_machines()
