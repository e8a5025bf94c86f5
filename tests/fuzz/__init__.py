"""Fuzzing every reader through the Python API: no input may find a traceback, a hang or a crash.

Each input kind has seeds (small valid files in the habits of the programs that
make them) and a target: the API call a user makes with such a file.  A
mutator (bit flips, truncation, duplicated and deleted spans, extreme numbers,
NaN and infinities, unicode, long lines, huge image dimensions) makes each
input from a seed; the target runs it in this process and the outcome is one of

* ``accepted``: the call returned;
* ``clean``: it raised a :class:`cam.errors.CamError` with a one-line message;
* ``failure``: anything else (another exception, a message over one line, or a
  call over the time limit).

    python -m tests.fuzz --count 100000          # the long mode: a table per input kind
    python -m tests.fuzz --count 300 --seed 1    # what the test suite runs (tests/test_fuzz.py)

Failing inputs are written to ``--save DIR`` (default ``fuzz-failures/``) with
what they raised; the ones worth keeping go to ``tests/fuzz/regressions/``,
which the test suite replays.
"""
from __future__ import annotations

import dataclasses
import os
import signal
import struct
import tempfile
import time
import traceback
import zlib
from pathlib import Path
from typing import Callable, Optional

import cv2
import numpy as np

import cam
from cam.errors import CamError

ROOT = Path(__file__).resolve().parents[2]
REGRESSIONS = Path(__file__).resolve().parent / "regressions"
TIME_LIMIT_S = 10.0
"""An input whose call takes longer than this is a failure (a hang)."""

SETTINGS = cam.MachineSettings()


class Hang(Exception):
    """Raised by the alarm when a call runs over :data:`TIME_LIMIT_S`."""


@dataclasses.dataclass
class Outcome:
    kind: str
    status: str  # "accepted", "clean", "failure"
    detail: str = ""
    seconds: float = 0.0


# ------------------------------------------------------------------------------------------------ seeds


def _png(img: np.ndarray, ext: str = ".png", params: Optional[list[int]] = None) -> bytes:
    ok, data = cv2.imencode(ext, img, params or [])
    assert ok
    return data.tobytes()


def _drawing_2d() -> np.ndarray:
    img = np.full((40, 60, 3), 255, np.uint8)
    cv2.line(img, (5, 5), (50, 30), (0, 0, 0), 1)
    cv2.circle(img, (30, 20), 10, (0, 0, 0), 1)
    return img


def _drawing_3d() -> np.ndarray:
    img = np.full((40, 40, 3), 255, np.uint8)
    cv2.circle(img, (20, 20), 12, (0, 0, 255), -1)  # red interior (BGR)
    cv2.circle(img, (20, 20), 12, (0, 0, 0), 1)
    return img


def _profile() -> np.ndarray:
    img = np.full((30, 40, 3), 255, np.uint8)
    img[5, 5:35] = 0  # layer axis
    img[5:25, 5] = 0  # depth axis
    img[5, 5] = (0, 0, 255)  # origin, red
    for k in range(1, 25):
        img[5 + min(18, k // 2 + 1), 5 + k] = (255, 0, 0)  # blue curve
    return img


def seeds() -> dict[str, list[tuple[str, bytes]]]:
    """Input kind -> ``(file name, bytes)`` seeds."""
    drill = sorted((ROOT / "samples" / "drill").glob("*.drl"))
    return {
        "drawing": [("two.png", _png(_drawing_2d())), ("disc.png", _png(_drawing_3d())),
                    ("two.jpg", _png(_drawing_2d(), ".jpg", [cv2.IMWRITE_JPEG_QUALITY, 85])),
                    ("two.bmp", _png(_drawing_2d(), ".bmp"))],
        "digitized": [("two.dig", _digitized_text(_drawing_2d())), ("disc.dig", _digitized_text(_drawing_3d()))],
        "settings": [("machine.toml", (ROOT / "profiles" / p).read_bytes()) for p in
                     sorted(os.listdir(ROOT / "profiles")) if p.endswith(".toml")][:3],
        "profile": [("profile.png", _png(_profile())), ("depths.csv", b"layer,depth\n1,1\n2,3\n3,4\n4,4\n")],
        "pinlog": [("pins.csv", _pin_log_text())],
        "excellon": [(p.name, p.read_bytes()) for p in drill[:4]],
        "hpgl": [("seed_tools.plt", (ROOT / "samples" / "seed_tools.plt").read_bytes()[:4000]),
                 ("star.plt", (ROOT / "samples" / "inkscape_star.plt").read_bytes()[:4000])],
        "gcode": [("job.ngc", b"%\n(square)\nG21 G90\nG0 Z1\nG0 X1 Y-1\nG1 Z-0.3 F200\nG1 X4 F600\nG2 X4 Y-4 I0 J-1.5\n"
                              b"G1 X1\nG4 P0.5\nM6 T2\nG1 Y-1\nG0 Z1\nM2\n%\n")],
    }


def _digitized_text(img: np.ndarray) -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "d.dig"
        cam.save_digitized(cam.digitize(img[:, :, ::-1].copy()), path)
        return path.read_bytes()


def _pin_log_text() -> bytes:
    job = cam.plan(cam.digitize(_drawing_2d()[:, :, ::-1].copy()), depth=2, settings=SETTINGS)
    plan = cam.plan_steps(job)
    n = min(len(plan), 400)
    rows = "".join(f"{t},{d},{s}\n" for t, d, s in zip(plan.t_ns[:n], plan.data[:n], plan.strobe[:n]))
    return ("t_ns,data,strobe\n" + rows).encode()


# ------------------------------------------------------------------------------------------------ mutators

EXTREMES = [b"1e309", b"-1e309", b"nan", b"NaN", b"inf", b"-inf", b"9" * 400, b"-9" * 30, b"0", b"-0",
            b"1e-320", b"4611686018427387905", b"0.0000000001", b"99999999999999999999", b"1e6", b"-1e6", b""]


def _flip(rng: np.random.Generator, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 9))):
        if b:
            i = int(rng.integers(len(b)))
            b[i] ^= 1 << int(rng.integers(8))
    return bytes(b)


def _truncate(rng: np.random.Generator, data: bytes) -> bytes:
    return data[: int(rng.integers(0, len(data) + 1))]


def _duplicate(rng: np.random.Generator, data: bytes) -> bytes:
    if not data:
        return data
    i = int(rng.integers(len(data)))
    j = min(len(data), i + int(rng.integers(1, 200)))
    k = int(rng.integers(len(data) + 1))
    return data[:k] + data[i:j] * int(rng.integers(1, 50)) + data[k:]


def _delete(rng: np.random.Generator, data: bytes) -> bytes:
    if not data:
        return data
    i = int(rng.integers(len(data)))
    return data[:i] + data[i + int(rng.integers(1, 100)):]


def _number(rng: np.random.Generator, data: bytes) -> bytes:
    import re

    spans = [m.span() for m in re.finditer(rb"-?\d+(?:\.\d*)?", data)]
    if not spans:
        return data + EXTREMES[int(rng.integers(len(EXTREMES)))]
    out = data
    for _ in range(int(rng.integers(1, 4))):
        a, b = spans[int(rng.integers(len(spans)))]
        if b <= len(out):
            out = out[:a] + EXTREMES[int(rng.integers(len(EXTREMES)))] + out[b:]
    return out


def _unicode(rng: np.random.Generator, data: bytes) -> bytes:
    junk = ["\u00e9", "\u2212", "\ufeff", "\x00", "\u202e", "\U0001f600", "\r", "\t", "\x1a"]
    i = int(rng.integers(len(data) + 1))
    return data[:i] + junk[int(rng.integers(len(junk)))].encode("utf-8") + data[i:]


def _long_line(rng: np.random.Generator, data: bytes) -> bytes:
    i = int(rng.integers(len(data) + 1))
    return data[:i] + b"X" * int(rng.integers(1000, 200_000)) + data[i:]


def _huge_dimensions(rng: np.random.Generator, data: bytes) -> bytes:
    """A PNG whose header claims another (often huge or zero) size, with a valid header checksum."""
    if not data.startswith(b"\x89PNG") or len(data) < 33:
        return _flip(rng, data)
    w, h = (int(v) for v in rng.choice([0, 1, 2, 70000, 16000, 2**31 - 1, 100000], size=2))
    ihdr = data[12:16] + struct.pack(">II", w, h) + data[24:29]
    crc = struct.pack(">I", zlib.crc32(ihdr) & 0xFFFFFFFF)
    return data[:12] + ihdr + crc + data[33:]


MUTATORS: list[Callable[[np.random.Generator, bytes], bytes]] = [
    _flip, _truncate, _duplicate, _delete, _number, _unicode, _long_line, _huge_dimensions,
]


def mutate(rng: np.random.Generator, data: bytes) -> bytes:
    """One to three mutations of ``data``."""
    for _ in range(int(rng.integers(1, 4))):
        data = MUTATORS[int(rng.integers(len(MUTATORS)))](rng, data)
    return data[:10_000_000]


# ------------------------------------------------------------------------------------------------ targets


def _job(path: Path) -> None:
    """What ``cam drill FILE`` plans (a drawing or matrix at depth 3: a 3D one as a flat pocket)."""
    from cam.job.jobs import JobOptions, prepare_job

    prepare_job(path, JobOptions(depth=(3,)) if path.suffix in (".png", ".jpg", ".bmp", ".dig") else JobOptions(),
                SETTINGS)


def _settings(path: Path) -> None:
    cam.load_settings(path)


def _profile_target(path: Path) -> None:
    cam.load_profile(path)


def _pinlog(path: Path) -> None:
    cam.decode_pin_log(cam.read_pin_log(path), SETTINGS)
    from cam.verify.pinlog import iter_pin_log
    from cam.verify.ramps import check_ramps
    check_ramps(path, SETTINGS)  # the file read a piece at a time
    for _ in iter_pin_log(path, 7):  # in small pieces: every piece boundary
        pass


TARGETS: dict[str, Callable[[Path], None]] = {
    "drawing": _job, "digitized": _job, "settings": _settings, "profile": _profile_target,
    "pinlog": _pinlog, "excellon": _job, "hpgl": _job, "gcode": _job,
}


# ------------------------------------------------------------------------------------------------ running


def _alarm(signum, frame):  # noqa: ARG001 - a signal handler's signature
    raise Hang(f"over {TIME_LIMIT_S:g} s")


def run_one(kind: str, name: str, data: bytes, folder: Path) -> Outcome:
    """Run one input through its kind's target; never raises."""
    path = folder / name
    path.write_bytes(data)
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, TIME_LIMIT_S)
    t0 = time.perf_counter()
    try:
        TARGETS[kind](path)
        status, detail = "accepted", ""
    except CamError as exc:
        text = str(exc)
        status, detail = ("clean", text) if text and "\n" not in text.strip() else ("failure", f"multi-line: {text!r}")
    except Hang as exc:
        status, detail = "failure", f"hang: {exc}"
    except BaseException as exc:  # noqa: BLE001 - the point: anything else is a finding
        if isinstance(exc, KeyboardInterrupt):
            raise
        tb = traceback.extract_tb(exc.__traceback__)
        where = f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else "?"
        status, detail = "failure", f"{type(exc).__name__} at {where}: {str(exc)[:200]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    seconds = time.perf_counter() - t0
    if status != "failure" and seconds > TIME_LIMIT_S:
        status, detail = "failure", f"slow: {seconds:.1f} s"
    return Outcome(kind, status, detail, seconds)


def campaign(count: int, seed: int = 0, kinds: Optional[list[str]] = None, save: Optional[Path] = None,
             report: Callable[[int, Outcome], None] = lambda i, o: None) -> list[Outcome]:
    """Run ``count`` mutated inputs spread over the kinds; failing inputs saved to ``save`` when given."""
    rng = np.random.default_rng(seed)
    all_seeds = seeds()
    names = kinds or list(TARGETS)
    outcomes = []
    with tempfile.TemporaryDirectory(prefix="cam-fuzz-") as tmp:
        folder = Path(tmp)
        for i in range(count):
            kind = names[i % len(names)]
            name, base = all_seeds[kind][int(rng.integers(len(all_seeds[kind])))]
            data = mutate(rng, base)
            o = run_one(kind, name, data, folder)
            outcomes.append(o)
            if o.status == "failure" and save is not None:
                save.mkdir(parents=True, exist_ok=True)
                stem = f"{kind}-{seed}-{i}"
                (save / f"{stem}{Path(name).suffix}").write_bytes(data)
                (save / f"{stem}.txt").write_text(o.detail + "\n")
            report(i, o)
            for p in folder.iterdir():
                p.unlink()
    return outcomes


def table(outcomes: list[Outcome]) -> str:
    """A Markdown table: inputs, clean errors, accepted and failures per kind."""
    lines = ["| input kind | inputs | clean errors | accepted | failures |", "| --- | ---: | ---: | ---: | ---: |"]
    for kind in sorted({o.kind for o in outcomes}):
        mine = [o for o in outcomes if o.kind == kind]
        n = {s: sum(o.status == s for o in mine) for s in ("clean", "accepted", "failure")}
        lines.append(f"| {kind} | {len(mine)} | {n['clean']} | {n['accepted']} | {n['failure']} |")
    total = {s: sum(o.status == s for o in outcomes) for s in ("clean", "accepted", "failure")}
    lines.append(f"| all | {len(outcomes)} | {total['clean']} | {total['accepted']} | {total['failure']} |")
    return "\n".join(lines)


def regression_inputs() -> list[tuple[str, Path]]:
    """The committed failing inputs: ``(kind, path)``, the kind from the file name (``KIND-...``)."""
    if not REGRESSIONS.is_dir():
        return []
    return [(p.name.split("-")[0], p) for p in sorted(REGRESSIONS.iterdir()) if p.suffix != ".txt"]


__all__ = ["campaign", "table", "run_one", "seeds", "mutate", "regression_inputs", "TARGETS", "Outcome"]
