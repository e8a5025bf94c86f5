"""Benchmark rows 10-13: the machine comes first while the web server is under load.

    python benchmarks/machine_first.py            # 3 repeats a load, the 4 s job
    python benchmarks/machine_first.py --quick    # 1 repeat a load

A real ``cam serve`` (a separate process, the mock port in real time, 0.5 ms
step periods, no speed ramp) runs ``samples/ellipse.png`` at depth 2 (about
4 s, 14,000 writes) while this process loads it with one of:

* a large preview: planning a 20,000-hole drill file and fetching its preview,
  over and over (both run in the server's worker process);
* 200 event-stream clients following the machine live;
* 1,000 half-open connections (request heads that never end, opened again as
  the server closes them).

The run's pin log (``/api/pinlog``) is compared write by write with the plan
of the same job made here: each write's lateness is how much longer its
interval was than planned (the runner moves the rest of the run later by it),
and the shortest ratio of measured to planned interval must never fall below
1.  A second run under the same load is emergency-stopped after 1 s: the
answer time of ``POST /api/estop`` is measured here, and the server's last
write after the request is read from its state.

Each row compares the load with the reference, the same job on the idle
server measured in the same run, as a ratio of medians (p99 lateness).
"""
from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
import uuid
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cam  # noqa: E402
from cam.kinds.jobs import JobOptions, prepare_job  # noqa: E402

SETTINGS = cam.MachineSettings().replace(delay_xy_ms=0.5, delay_z_ms=0.5, ramp="constant")
JOB_FILE = ROOT / "samples" / "ellipse.png"
JOB_OPTIONS = {"depth": 2}
N_STREAMS = 200
N_HALF_OPEN = 1000
N_HOLES = 20_000


class Client:
    """The page's requests to a ``cam serve`` at ``url`` (its Origin and header on every POST)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.headers = {"Origin": url, "X-Requested-With": "cam"}

    def call(self, method: str, path: str, body=None, raw: bytes | None = None, content_type: str | None = None):
        h = dict(self.headers) if method == "POST" else {}
        data = raw
        if body is not None:
            data, content_type = json.dumps(body).encode(), "application/json"
        if content_type:
            h["Content-Type"] = content_type
        req = urllib.request.Request(self.url + path, data=data, method=method, headers=h)
        try:
            with urllib.request.urlopen(req, timeout=120) as resp:
                payload, ctype = resp.read(), resp.headers.get("content-type", "")
        except urllib.error.HTTPError as exc:
            raise RuntimeError(f"{method} {path}: {exc.code} {exc.read()[:200]!r}") from None
        return json.loads(payload) if "json" in ctype else payload

    def plan(self, name: str, data: bytes, options: dict) -> dict:
        boundary = uuid.uuid4().hex
        body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"role\"\r\n\r\njob\r\n"
                f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{name}\"\r\n\r\n"
                ).encode() + data + f"\r\n--{boundary}--\r\n".encode()
        up = self.call("POST", "/api/upload", raw=body, content_type=f"multipart/form-data; boundary={boundary}")
        return self.call("POST", "/api/plan", {"job": up["job"], "options": options})

    def wait_idle(self) -> dict:
        while True:
            st = self.call("GET", "/api/state")
            if st["activity"] is None:
                return st
            time.sleep(0.05)


def start_server(jobs_dir: Path) -> tuple[subprocess.Popen, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "cam", "serve", "--http-port", "0", "--jobs-dir", str(jobs_dir),
         "--delay", "0.5,0.5", "--ramp", "constant", "--max-connections", str(N_HALF_OPEN + N_STREAMS + 300),
         "--max-event-streams", str(N_STREAMS + 50)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    m = re.search(r"(http://127\.0\.0\.1:\d+)", line)
    if not m:
        proc.kill()
        raise RuntimeError(f"cam serve did not start: {line}{proc.stderr.read()}")
    return proc, m.group(1)


# ---------------------------------------------------------------- loads (asyncio, in a thread of their own)


class Load:
    """Runs one load against the server until :meth:`stop`."""

    def __init__(self, kind: str, client: Client, drill_file: bytes) -> None:
        self.kind, self.client, self.drill_file = kind, client, drill_file
        self.host, self.port = client.url.split("//")[1].split(":")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.count = 0  # previews made, streams or half-open connections opened

    def start(self) -> "Load":
        self._thread.start()
        time.sleep(1.0 if self.kind != "idle" else 0.0)  # the load is up before the job starts
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(30)

    def _run(self) -> None:
        if self.kind == "preview":
            while not self._stop.is_set():
                planned = self.client.plan("board.drl", self.drill_file, {})
                self.client.call("GET", planned["preview"])
                self.count += 1
        elif self.kind in ("streams", "half-open"):
            asyncio.run(self._sockets())

    async def _sockets(self) -> None:
        n = N_STREAMS if self.kind == "streams" else N_HALF_OPEN
        head = (f"GET /api/events HTTP/1.1\r\nHost: {self.host}:{self.port}\r\n\r\n" if self.kind == "streams"
                else f"POST /api/jog HTTP/1.1\r\nHost: {self.host}:{self.port}\r\nContent-Ty").encode()

        async def one() -> None:
            while not self._stop.is_set():
                try:
                    reader, writer = await asyncio.open_connection(self.host, int(self.port))
                except OSError:
                    await asyncio.sleep(0.1)
                    continue
                self.count += 1
                writer.write(head)
                try:
                    while not self._stop.is_set():
                        try:
                            data = await asyncio.wait_for(reader.read(65536), 0.2)
                        except asyncio.TimeoutError:
                            continue
                        if not data:
                            break  # closed by the server (a half-open head's deadline): open another
                finally:
                    writer.close()

        await asyncio.gather(*(one() for _ in range(n)))


# ---------------------------------------------------------------- one measured run


def interval_lateness(measured_t_ns: np.ndarray, planned_t_ns: np.ndarray) -> dict:
    """Each write's lateness (how much longer its interval was than planned: the runner then moves the rest
    of the run later by it): p50, p99 and max in us, and the shortest measured/planned interval ratio."""
    measured, planned = np.diff(measured_t_ns), np.diff(planned_t_ns)
    late = measured - planned
    ok = planned > 0
    p50, p99, mx = (float(np.percentile(late, q)) / 1e3 for q in (50, 99, 100))
    return {"p50_us": p50, "p99_us": p99, "max_us": mx, "min_ratio": float((measured[ok] / planned[ok]).min())}


def lateness(log_csv: bytes, plan) -> dict:
    rows = np.loadtxt(log_csv.decode().splitlines()[1:], delimiter=",", dtype=np.int64)
    if not np.array_equal(rows[:, 1], plan.data):
        raise RuntimeError("the pin log is not the planned job")
    return interval_lateness(rows[:, 0], plan.t_ns)


def measure(client: Client, kind: str, job_id: str, plan, drill_file: bytes) -> dict:
    load = Load(kind, client, drill_file).start()
    try:
        client.call("POST", "/api/start", {"job": job_id})
        st = client.wait_idle()
        assert st["last"]["status"] == "finished", st["last"]
        out = lateness(client.call("GET", "/api/pinlog"), plan)
        client.call("POST", "/api/origin", {})
        client.wait_idle()
        # the same job again, emergency-stopped after 1 s
        client.call("POST", "/api/start", {"job": job_id})
        time.sleep(1.0)
        t0 = time.perf_counter()
        client.call("POST", "/api/estop", {})
        out["estop_ms"] = (time.perf_counter() - t0) * 1e3
        last = client.wait_idle()["last"]
        out["halt_ms"] = max(0, last["last_write_job_ns"] - last["estop_request_job_ns"]) / 1e6
        client.call("POST", "/api/origin", {})
        client.wait_idle()
    finally:
        load.stop()
    out["load_count"] = load.count
    return out


def bench_rows(quick: bool, loads: tuple[str, ...] = ("idle", "preview", "streams", "half-open")) -> list[dict]:
    repeats = 1 if quick else 3
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 8192), hard))
    rng = np.random.default_rng(3)
    holes = rng.uniform((1, 1), (99, 79), size=(N_HOLES, 2))
    drill_file = ("M48\nMETRIC\nT1C0.8\n%\nT1\n" + "".join(f"X{x:.3f}Y{y:.3f}\n" for x, y in holes) + "M30\n").encode()
    plan = prepare_job(JOB_FILE, JobOptions.from_mapping(JOB_OPTIONS), SETTINGS).steps
    with tempfile.TemporaryDirectory(prefix="cam-bench-") as tmp:
        proc, url = start_server(Path(tmp) / "jobs")
        try:
            client = Client(url)
            job_id = client.plan(JOB_FILE.name, JOB_FILE.read_bytes(), JOB_OPTIONS)["job"]
            runs: dict[str, list[dict]] = {k: [] for k in loads}
            for _ in range(repeats):  # interleaved, so drift on a shared machine hits every load alike
                for kind in runs:
                    runs[kind].append(measure(client, kind, job_id, plan, drill_file))
                    print(f"  ... {kind}: {runs[kind][-1]}", file=sys.stderr, flush=True)
        finally:
            proc.terminate()
            proc.wait(30)
    idle_p99 = statistics.median(r["p99_us"] for r in runs["idle"]) if runs.get("idle") else float("nan")
    names = {"idle": "idle server (the reference)",
             "preview": f"planning + preview of {N_HOLES} holes, over and over",
             "streams": f"{N_STREAMS} event-stream clients", "half-open": f"{N_HALF_OPEN} half-open connections"}
    rows = []
    for kind, rs in runs.items():
        p99 = statistics.median(r["p99_us"] for r in rs)
        worst = max(r["max_us"] for r in rs)
        min_ratio = min(r["min_ratio"] for r in rs)
        estop = max(r["estop_ms"] for r in rs)
        halt = max(r["halt_ms"] for r in rs)
        ratio = p99 / idle_p99 if idle_p99 > 0 else float("inf")
        rows.append(dict(
            name=f"machine first: {len(plan)} writes at 0.5 ms, {names[kind]}", cam=p99 / 1e6, ref=idle_p99 / 1e6,
            ratio=(f"{ratio:.2f}x idle p99 lateness; p99 {p99:.0f} us, max {worst:.0f} us; shortest interval "
                   f"{min_ratio:.3f}x planned; e-stop answered in {estop:.1f} ms, last write {halt:.2f} ms after it"),
            target="no interval under the planned one; e-stop answered <= 50 ms",
            met=min_ratio >= 1.0 and estop <= 50.0, note=""))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one repeat a load")
    ap.add_argument("--loads", default="idle,preview,streams,half-open", help="which loads (idle is the reference)")
    args = ap.parse_args(argv)
    print_table(bench_rows(args.quick, tuple(args.loads.split(","))))
    return 0


def print_table(rows) -> None:
    """The rows (dicts: name, cam, ref, ratio, target, met) as the benchmarks' Markdown table, times in s."""
    print("| workload | cam (median s) | reference (median s) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in rows:
        met = {True: "yes", False: "**no**", None: "n/a"}[r["met"]]
        print(f"| {r['name']} | {r['cam']:.6f} | {r['ref']:.6f} | {r['ratio']} | {r['target']} | {met} |")


if __name__ == "__main__":
    sys.exit(main())
