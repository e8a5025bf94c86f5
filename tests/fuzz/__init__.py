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
SETUP_WAIT_S = 600.0
"""How long the live server's set-up (its planning worker's first start) is waited for: not a limit on an input."""

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
        "svg": [("logo.svg", (ROOT / "samples" / "logo.svg").read_bytes()), ("inkscape.svg", INKSCAPE_SVG),
                ("potrace.svg", POTRACE_SVG), ("uses.svg", USES_SVG)],
        "web": [(f"{route.strip('/').replace('/', '-')}.json", body) for route, body in WEB_BODIES],
    }


INKSCAPE_SVG = b"""<?xml version="1.0" encoding="UTF-8" standalone="no"?>
<svg xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"
   xmlns:sodipodi="http://sodipodi.sourceforge.net/DTD/sodipodi-0.dtd"
   xmlns="http://www.w3.org/2000/svg" xmlns:svg="http://www.w3.org/2000/svg"
   width="60mm" height="40mm" viewBox="0 0 60 40" version="1.1" id="svg8">
  <sodipodi:namedview id="base" inkscape:document-units="mm" />
  <g inkscape:label="Layer 1" inkscape:groupmode="layer" id="layer1" transform="translate(0,-257)">
    <path style="fill:none;stroke:#000000;stroke-width:0.26458332px" d="m 10,270 c 5,-8 15,-8 20,0 s 15,8 20,0"
       id="path10" inkscape:connector-curvature="0" />
    <rect style="fill:none;stroke:#ff0000;stroke-width:0.26" id="rect12" width="20" height="10" x="5" y="280"
       ry="2" />
    <ellipse style="fill:none;stroke:#0000ff" id="e1" cx="45" cy="285" rx="8" ry="4" transform="rotate(15,45,285)"/>
    <path d="M 30,290 A 5,5 0 1 1 40,290 Z" style="stroke:#000;fill:none" id="arc"/>
  </g>
</svg>
"""

POTRACE_SVG = b"""<?xml version="1.0" standalone="no"?>
<!DOCTYPE svg PUBLIC "-//W3C//DTD SVG 20010904//EN" "http://www.w3.org/TR/2001/REC-SVG-20010904/DTD/svg10.dtd">
<svg version="1.0" xmlns="http://www.w3.org/2000/svg" width="200.000000pt" height="100.000000pt"
 viewBox="0 0 200.000000 100.000000" preserveAspectRatio="xMidYMid meet">
<metadata>Created by potrace 1.16, written by Peter Selinger 2001-2019</metadata>
<g transform="translate(0.000000,100.000000) scale(0.100000,-0.100000)" fill="#000000" stroke="none">
<path d="M320 820 c-58 -31 -90 -86 -90 -155 0 -110 80 -185 195 -185 65 0 117 27 150 77 l22 33 3 -48 c2
-26 9 -50 17 -53 10 -4 13 21 13 123 0 141 -14 180 -80 213 -51 26 -182 23 -230 -5z M1200 500 l0 -300 100 0
100 0 0 300 0 300 -100 0 -100 0 0 -300z"/>
</g>
</svg>
"""

USES_SVG = b"""<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="80mm"
 height="80mm" viewBox="0 0 80 80">
  <defs><circle id="dot" cx="0" cy="0" r="1.5" fill="none" stroke="black"/>
    <g id="row"><use xlink:href="#dot" x="10"/><use href="#dot" x="20"/><use xlink:href="#dot" x="30"/></g></defs>
  <use xlink:href="#row" y="10"/><use xlink:href="#row" y="20" transform="scale(1.1) skewX(5)"/>
  <polyline points="5,70 20,60 35,70 50,60" fill="none" stroke="black"/>
  <line x1="60" y1="5" x2="75" y2="40" stroke="black"/>
</svg>
"""

WEB_BODIES: list[tuple[str, bytes]] = [
    ("/api/jog", b'{"axis": "x", "steps": 10, "unit": "steps"}'),
    ("/api/goto", b'{"xyz": [1, 2, 0], "unit": "mm", "machine": false}'),
    ("/api/zero", b'{"axes": "XY", "offset": "G55"}'),
    ("/api/use-offset", b'{"offset": "G54"}'),
    ("/api/plan", b'{"job": "1", "options": {}}'),
    ("/api/start", b'{"job": "1"}'),
    ("/api/answer", b'{"prompt": 1, "action": "continue"}'),
    ("/api/drill-z", b'{"which": "up"}'),
    ("/api/pause", b"{}"), ("/api/resume", b"{}"), ("/api/stop", b"{}"), ("/api/resume-job", b'{"job": "1"}'),
    ("/api/upload", b"--B\r\nContent-Disposition: form-data; name=\"role\"\r\n\r\njob\r\n--B\r\n"
                    b"Content-Disposition: form-data; name=\"file\"; filename=\"a.ngc\"\r\n"
                    b"Content-Type: application/octet-stream\r\n\r\nG0 X1\nG1 X2 F100\r\n--B--\r\n"),
]
"""A JSON (or multipart) body of each route of the page, as the page sends it."""


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


def _svg_structure(rng: np.random.Generator, data: bytes) -> bytes:
    """What breaks SVG readers: deep nesting, huge coordinates and viewBoxes, NaN transforms, broken paths,
    external entities and entity expansion, `<use>` fan-out."""
    choice = int(rng.integers(8))
    body_at = data.rfind(b"</svg>")
    body_at = len(data) if body_at < 0 else body_at
    if choice == 0:
        depth = int(rng.choice([50, 500, 5000]))
        extra = b"<g>" * depth + b'<path d="M0 0 L1 1"/>' + b"</g>" * depth
    elif choice == 1:
        extra = b'<path d="M 1e308 -1e308 L 1e30 1e30 C 9e300 0 0 9e300 1 1" stroke="black"/>'
    elif choice == 2:
        extra = b'<g transform="matrix(nan,0,0,inf,1e308,-1e308) rotate(1e309)"><rect width="5" height="5"/></g>'
    elif choice == 3:
        extra = b'<path d="M 10 10 L 20 Q 5 z z A 1 1 0 2 2 5 5 M" stroke="black"/>'
    elif choice == 4:  # entity expansion and an external entity before the root
        dtd = (b'<?xml version="1.0"?><!DOCTYPE svg [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">'
               b'<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;">'
               b'<!ENTITY x SYSTEM "file:///etc/passwd">]>')
        start = data.find(b"<svg")
        return dtd + (data[start:] if start >= 0 else data).replace(b"</svg>", b"<text>&d;&x;</text></svg>", 1)
    elif choice == 5:
        return data.replace(b"viewBox=", b'viewBox="0 0 1e300 1e-300" data-old=', 1)
    elif choice == 6:
        fan = int(rng.choice([4, 10, 30]))
        defs = b'<defs><path id="u0" d="M0 0 L1 1"/>' + b"".join(
            b'<g id="u%d">' % (i + 1) + b'<use href="#u%d"/>' % i * fan + b"</g>" for i in range(10)) + b"</defs>"
        extra = defs + b'<use href="#u10"/>'
    else:
        n = int(rng.choice([100, 1000]))  # a halftone's habit (50,000 circles: benchmarks, not the fuzzing)
        extra = b"".join(b'<circle cx="%d" cy="%d" r="0.3" stroke="black" fill="none"/>' % (i % 300, i // 300)
                         for i in range(n))
    return data[:body_at] + extra + data[body_at:]


def _json_values(rng: np.random.Generator, data: bytes) -> bytes:
    """A JSON value swapped for a wrong type, a huge or deep one, NaN, infinity or an empty string."""
    import re

    values = [b"NaN", b"Infinity", b"-Infinity", b"1e308", b"1" + b"0" * 30, b"1" + b"0" * 4000, b"[]", b"{}",
              b'""', b"null", b"true", b"[1, 2, 3]", b'{"a": {"b": {"c": 1}}}', b"[" * 5000 + b"]" * 5000,
              b'"' + b"x" * 100_000 + b'"', b"-0", b"0.0000001", b'"G59.3"', b'"XYZ"', b"[1e9, -1e9, 1e9]"]
    spans = [m.span(1) for m in re.finditer(rb':\s*("[^"]*"|[-\w.]+|\[[^\]]*\])', data)]
    if not spans:
        return data
    a, b = spans[int(rng.integers(len(spans)))]
    return data[:a] + values[int(rng.integers(len(values)))] + data[b:]


KIND_MUTATORS: dict[str, list[Callable[[np.random.Generator, bytes], bytes]]] = {
    "svg": [_svg_structure, _svg_structure, _number],
    "web": [_json_values, _json_values, _json_values],
}
"""Mutators a kind gets besides :data:`MUTATORS` (chosen as often as all of those together)."""


def mutate(rng: np.random.Generator, data: bytes, kind: str = "") -> bytes:
    """One to three mutations of ``data`` (of input kind ``kind``: its own mutators half the time)."""
    extra = KIND_MUTATORS.get(kind, [])
    for _ in range(int(rng.integers(1, 4))):
        if extra and rng.integers(2):
            data = extra[int(rng.integers(len(extra)))](rng, data)
        else:
            data = MUTATORS[int(rng.integers(len(MUTATORS)))](rng, data)
    return data[:10_000_000]


# ------------------------------------------------------------------------------------------------ targets


def _job(path: Path) -> None:
    """What ``cam drill FILE`` plans (a drawing or matrix at depth 3: a 3D one as a flat pocket)."""
    from cam.kinds.jobs import JobOptions, prepare_job

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


def _svg(path: Path) -> None:
    """What ``cam drill`` and ``cam preview`` do with an SVG file: plan it, then draw its preview."""
    from cam.kinds.jobs import JobOptions, prepare_job
    from cam.web.work import preview_of

    preview_of(prepare_job(path, JobOptions(), SETTINGS))


class _LiveServer:
    """One ``cam serve`` on the mock (simulated clock) for the whole campaign, with a planned job "1"."""

    instance: "Optional[_LiveServer]" = None

    def __init__(self) -> None:
        import socket
        import threading

        import uvicorn

        from cam.web.server import ServerConfig, create_app, uvicorn_config

        self.tmp = tempfile.mkdtemp(prefix="cam-fuzz-web-")
        self.config = ServerConfig(jobs_dir=self.tmp, port=0, realtime=False, settings=SETTINGS,
                                   state_file=str(Path(self.tmp) / "machine.json"))
        self.app = create_app(self.config)
        self.session = self.app.state.session
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{sock.getsockname()[1]}"
        self.server = uvicorn.Server(uvicorn_config(self.app, log_level="critical"))
        threading.Thread(target=self.server.run, kwargs={"sockets": [sock]}, daemon=True).start()
        while not self.server.started:
            time.sleep(0.01)
        # set-up, not an input: the first plan starts the page's planning worker (numpy, numba, the cached
        # kernels), which on a busy machine takes longer than an input may; it is waited for, not timed
        _, body, _ = self.post("/api/upload", WEB_BODIES[-1][1], "multipart/form-data; boundary=B",
                               timeout_s=SETUP_WAIT_S)
        self.post("/api/plan", b'{"job": "1", "options": {}}', timeout_s=SETUP_WAIT_S)

    @classmethod
    def get(cls) -> "_LiveServer":
        if cls.instance is None:
            cls.instance = cls()
        return cls.instance

    def post(self, route: str, body: bytes, ctype: str = "application/json", *, timeout_s: float = TIME_LIMIT_S
             ) -> tuple[int, bytes, str]:
        import urllib.error
        import urllib.request

        req = urllib.request.Request(self.url + route, data=body, method="POST", headers={
            "Content-Type": ctype, "Origin": self.url, "X-Requested-With": "cam"})
        try:
            with urllib.request.urlopen(req, timeout=timeout_s) as resp:
                return resp.status, resp.read(), resp.headers.get("content-type", "")
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read(), exc.headers.get("content-type", "")


class WebFailure(Exception):
    """The server answered a request in a way no request may get (a 5xx, not one line, the machine moving on a
    refused request)."""


def _web(path: Path) -> None:
    """POST the body to its route of a live ``cam serve`` (the route from the file name: ``api-jog.json``)."""
    import json

    srv = _LiveServer.get()
    route = "/" + path.stem.replace("-", "/", 1)
    ctype = "multipart/form-data; boundary=B" if route == "/api/upload" else "application/json"
    srv.session.wait_idle(TIME_LIMIT_S)
    before = (srv.session.position_steps(), srv.session.version)
    status, body, got_type = srv.post(route, path.read_bytes(), ctype)
    if status >= 500:
        raise WebFailure(f"{route}: HTTP {status}: {body[:200]!r}")
    if status >= 400:
        try:
            message = json.loads(body)["error"]
        except (ValueError, KeyError, TypeError):
            raise WebFailure(f"{route}: HTTP {status} without a JSON error: {body[:200]!r}") from None
        if not message or "\n" in message.strip() or "Traceback" in message:
            raise WebFailure(f"{route}: HTTP {status}, not one line: {message[:300]!r}")
        time.sleep(0.01)
        if srv.session.busy or srv.session.position_steps() != before[0]:
            raise WebFailure(f"{route}: the machine moved on a refused request ({status}: {message})")
        raise CamError(message)  # a clean refusal
    srv.session.stop()  # an accepted motion: ended, so the next input starts idle
    srv.session.wait_idle(TIME_LIMIT_S)


TARGETS: dict[str, Callable[[Path], None]] = {
    "drawing": _job, "digitized": _job, "settings": _settings, "profile": _profile_target,
    "pinlog": _pinlog, "excellon": _job, "hpgl": _job, "gcode": _job, "svg": _svg, "web": _web,
}


# ------------------------------------------------------------------------------------------------ running


def _alarm(signum, frame):  # noqa: ARG001 - a signal handler's signature
    raise Hang(f"over {TIME_LIMIT_S:g} s")


def run_one(kind: str, name: str, data: bytes, folder: Path) -> Outcome:
    """Run one input through its kind's target; never raises."""
    path = folder / name
    path.write_bytes(data)
    if kind == "web":
        _LiveServer.get()  # started once, outside the timed call
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
            data = mutate(rng, base, kind)
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
