"""Make the README's pictures again: ``python docs/make_pictures.py`` (from any folder).

* docs/gear-preview.png: ``cam preview samples/gear.png --start min-distance --depth 12,4``
* docs/heart-surface.png: ``cam preview samples/heart.png --profile profiles/dome.png --surface``
* docs/web-phone.png: the web page (``cam serve``) at phone size, 390 x 844, with samples/gear.png
  loaded at depth 4 and the options folded, in Debian's Chromium through Playwright

``--out DIR`` writes them elsewhere; ``--no-browser`` skips the screenshot (which needs ``cam[web]``,
``playwright`` and /usr/bin/chromium).  The cam used is this checkout's, not an installed one.
"""
from __future__ import annotations

import argparse
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cam.cli import main as cam_main  # noqa: E402  (this checkout's cam, after the path is set)

CHROMIUM = "/usr/bin/chromium"
PHONE = {"width": 390, "height": 844}
WAIT_MS = 60_000
"""Longest wait for the page: the first job planned compiles numba kernels, seconds on a fresh clone."""

PREVIEWS = {
    "gear-preview.png": ["preview", "samples/gear.png", "--start", "min-distance", "--depth", "12,4"],
    "heart-surface.png": ["preview", "samples/heart.png", "--profile", "profiles/dome.png", "--surface"],
}
"""Picture name -> the cam command that draws it (paths from the repository root)."""
WEB_PICTURE = "web-phone.png"


def make_previews(out: Path) -> list[Path]:
    """Draw the toolpath and surface pictures into ``out``; returns their paths."""
    written = []
    for name, args in PREVIEWS.items():
        argv = [str(ROOT / a) if a.startswith(("samples/", "profiles/")) else a for a in args]
        if cam_main([*argv, "-o", str(out / name)]) != 0:
            raise SystemExit(f"make_pictures: 'cam {' '.join(args)}' failed")
        written.append(out / name)
    return written


def _start_server(jobs_dir: str) -> tuple[subprocess.Popen, str]:
    """``cam serve`` on a free localhost port: (process, page URL)."""
    server = subprocess.Popen(
        [sys.executable, "-m", "cam", "serve", "--http-port", "0", "--jobs-dir", jobs_dir],
        stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if select.select([server.stdout], [], [], 0.5)[0]:
            line = server.stdout.readline()
            if not line:
                break
            if line.startswith("cam: web page at "):
                return server, line.split(" at ", 1)[1].strip()
    server.kill()
    raise SystemExit("make_pictures: 'cam serve' did not start (see its messages above)")


def make_web_phone(out: Path) -> Path:
    """Screenshot the web page at phone size into ``out``; returns its path."""
    from playwright.sync_api import sync_playwright  # only the screenshot needs a browser

    path = out / WEB_PICTURE
    with tempfile.TemporaryDirectory(prefix="cam-jobs-") as jobs_dir:
        server, url = _start_server(jobs_dir)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox"])
                context = browser.new_context(viewport=PHONE, device_scale_factor=1, has_touch=True,
                                              bypass_csp=True)  # the page's CSP forbids eval: wait_for_function
                page = context.new_page()
                page.set_default_timeout(WAIT_MS)
                page.goto(url)
                page.wait_for_function("document.getElementById('state').dataset.state === 'idle'")
                page.fill("#opt-depth", "4")
                page.set_input_files("#file", str(ROOT / "samples" / "gear.png"))
                page.wait_for_function("!document.getElementById('start').disabled")
                page.wait_for_function("document.getElementById('preview').naturalWidth > 0")
                page.click("#options summary")  # fold the options: the preview, size and time show
                page.screenshot(path=str(path))
                browser.close()
        finally:
            server.send_signal(signal.SIGTERM)
            try:
                server.wait(10)
            except subprocess.TimeoutExpired:
                server.kill()
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="folder to write to (default: docs/)")
    parser.add_argument("--no-browser", action="store_true", help=f"skip {WEB_PICTURE} (no Chromium needed)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    written = make_previews(args.out)
    if not args.no_browser:
        written.append(make_web_phone(args.out))
    for path in written:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
