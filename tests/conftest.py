"""Shared test helpers: tiny drawings and the carve check."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cam

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"


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
