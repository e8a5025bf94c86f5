"""Benchmark rows of issue #33 point 3: the emergency stop is served under connection floods.

    python benchmarks/estop_flood.py            # 50 e-stops a load
    python benchmarks/estop_flood.py --quick    # 10 e-stops a load

A real ``cam serve`` (a separate process, default connection limits, the mock
port on the simulated clock) is loaded by another process with one of:

* a reconnect flood: 1,000 clients, each opening a connection, sending half a
  request head and opening another as soon as the server closes it;
* 300 slow bodies: 300 clients, each sending a whole ``POST /api/jog`` head
  announcing ``Content-Length: 100000`` and then one body byte every 5 s
  (under the 10 s pause limit), opening another when the server closes it.

Meanwhile this process sends the page's requests one after another, each on
a new connection as a page opened afresh would: ``POST /api/estop`` (the count
a load), with a ``POST /api/stop`` and a ``GET /api/state`` after each.  An
e-stop is *answered* when a 200 comes back within 5 s; a reset, a close
without an answer or a timeout is not.  Stop and State are *refused* when they
get a 503 (or no answer at all).

Each row compares the e-stop's median answer time under the load with the
reference, the same measurement on the idle server in the same run, as a
ratio of medians; the goal is every e-stop answered within 50 ms and no Stop
or State refused for load.
"""
from __future__ import annotations

import argparse
import asyncio
import http.client
import os
import re
import resource
import select
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

N_FLOOD = 1000
N_SLOW = 300
SLOW_LENGTH = 100_000
SLOW_PERIOD_S = 5.0
ANSWER_TIMEOUT_S = 5.0
GOAL_MS = 50.0


def start_server(jobs_dir: Path, token: str | None) -> tuple[subprocess.Popen, str]:
    """``cam serve`` on a free port of 127.0.0.1 (default limits); (process, URL without the token)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "cam", "serve", "--http-port", "0", "--simulated", "--jobs-dir", str(jobs_dir)]
    if token:
        cmd += ["--token", token]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    ready, _, _ = select.select([proc.stdout], [], [], 60)
    line = proc.stdout.readline() if ready else ""
    m = re.search(r"(http://127\.0\.0\.1:\d+)", line)
    if not m:
        proc.kill()
        raise RuntimeError(f"cam serve did not start: {line!r}")
    return proc, m.group(1)


# ---------------------------------------------------------------- the loads (run in a process of their own)


async def _flood(host: str, port: int, n: int) -> None:
    head = f"POST /api/jog HTTP/1.1\r\nHost: {host}:{port}\r\nContent-Ty".encode()

    async def one() -> None:
        while True:
            try:
                reader, writer = await asyncio.open_connection(host, port)
            except OSError:
                await asyncio.sleep(0.01)
                continue
            try:
                writer.write(head)
                while await reader.read(65536):
                    pass  # until the server closes it: then at once another
            except OSError:
                pass
            finally:
                writer.close()

    await asyncio.gather(*(one() for _ in range(n)))


async def _slow_bodies(host: str, port: int, n: int) -> None:
    head = (f"POST /api/jog HTTP/1.1\r\nHost: {host}:{port}\r\nOrigin: http://{host}:{port}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {SLOW_LENGTH}\r\n\r\n").encode()

    async def one(i: int) -> None:
        await asyncio.sleep(i * 0.005)
        while True:
            try:
                reader, writer = await asyncio.open_connection(host, port)
            except OSError:
                await asyncio.sleep(0.1)
                continue
            try:
                writer.write(head)
                while True:
                    try:
                        if not await asyncio.wait_for(reader.read(65536), SLOW_PERIOD_S):
                            break  # closed by the server
                    except asyncio.TimeoutError:
                        writer.write(b" ")  # one byte every 5 s
            except OSError:
                pass
            finally:
                writer.close()

    await asyncio.gather(*(one(i) for i in range(n)))


def run_load(kind: str, url: str) -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 8192), hard))
    host, port = url.split("//")[1].split(":")
    asyncio.run(_flood(host, int(port), N_FLOOD) if kind == "flood" else _slow_bodies(host, int(port), N_SLOW))


# ---------------------------------------------------------------- the page's requests


def request(url: str, method: str, path: str, token: str | None) -> tuple[int | None, float]:
    """(status or None when not answered, round trip in ms) of one request as the page sends it, on a new
    connection."""
    host, port = url.split("//")[1].split(":")
    headers = {"Origin": url, "X-Requested-With": "cam"} if method == "POST" else {}
    if token:
        headers["X-Cam-Token"] = token
    body = b"{}" if method == "POST" else None
    if body is not None:
        headers["Content-Type"] = "application/json"
    t0 = time.perf_counter()
    conn = http.client.HTTPConnection(host, int(port), timeout=ANSWER_TIMEOUT_S)
    try:
        conn.request(method, path, body=body, headers=headers)
        resp = conn.getresponse()
        resp.read()
        status: int | None = resp.status
    except (OSError, http.client.HTTPException):
        status = None
    finally:
        conn.close()
    return status, (time.perf_counter() - t0) * 1e3


def measure(url: str, n: int, token: str | None) -> dict:
    """``n`` rounds of e-stop, stop, state: answered e-stops, their times, Stop/State refusals."""
    estop_ms, answered, refused, other = [], 0, 0, 0
    for _ in range(n):
        status, ms = request(url, "POST", "/api/estop", token)
        estop_ms.append(ms)
        answered += status == 200
        for method, path in (("POST", "/api/stop"), ("GET", "/api/state")):
            status, _ = request(url, method, path, token)
            refused += status in (None, 503)
            other += status not in (None, 200, 503)
        time.sleep(0.02)
    ok = sorted(ms for ms in estop_ms)
    return {"answered": answered, "n": n, "median_ms": statistics.median(ok),
            "p99_ms": ok[min(len(ok) - 1, int(round(0.99 * (len(ok) - 1))))], "max_ms": ok[-1],
            "within_goal": sum(ms <= GOAL_MS for ms in estop_ms), "refused": refused, "other": other}


def with_load(kind: str | None, url: str, n: int, token: str | None) -> dict:
    load = None
    if kind:
        load = subprocess.Popen([sys.executable, __file__, "--load", kind, url], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        time.sleep(3.0)  # the load is up (the slow bodies are all sent heads)
    try:
        return measure(url, n, token)
    finally:
        if load is not None:
            load.terminate()
            load.wait(30)
            time.sleep(1.0)  # the server lets the load's connections go


def bench_rows(quick: bool, token: str | None = None) -> list[dict]:
    n = 10 if quick else 50
    with tempfile.TemporaryDirectory(prefix="cam-bench-") as tmp:
        proc, url = start_server(Path(tmp) / "jobs", token)
        try:
            request(url, "GET", "/api/state", token)  # the server's first answer (imports) is not measured
            idle = with_load(None, url, n, token)
            loaded = {kind: with_load(kind, url, n, token) for kind in ("flood", "slow")}
        finally:
            proc.terminate()
            proc.wait(30)
    names = {"flood": f"e-stop under {N_FLOOD:,}-client reconnect flood",
             "slow": f"e-stop under {N_SLOW} slow bodies"}
    rows = []
    for kind, r in loaded.items():
        ratio = r["median_ms"] / idle["median_ms"]
        met = r["answered"] == n and r["within_goal"] == n and r["refused"] == 0
        rows.append(dict(
            name=names[kind], cam=r["median_ms"], ref=idle["median_ms"],
            ratio=(f"{ratio:.2f}x idle median; answered {r['answered']}/{n}, {r['within_goal']}/{n} within "
                   f"{GOAL_MS:g} ms; p99 {r['p99_ms']:.1f} ms, max {r['max_ms']:.1f} ms (idle: {idle['within_goal']}/{n} "
                   f"within {GOAL_MS:g} ms, p99 {idle['p99_ms']:.1f} ms); Stop/State refused {r['refused']}/{2 * n}"),
            target=f"{n}/{n} answered within {GOAL_MS:g} ms; Stop/State never refused", met=met))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 e-stops a load instead of 50")
    ap.add_argument("--token", help="run the server with this token (at least 16 characters)")
    ap.add_argument("--load", nargs=2, metavar=("KIND", "URL"), help=argparse.SUPPRESS)  # the load's process
    args = ap.parse_args(argv)
    if args.load:
        run_load(*args.load)
        return 0
    rows = bench_rows(args.quick, args.token)
    print("| workload | cam (median ms) | reference: idle server (median ms) | result | target | met |")
    print("| --- | ---: | ---: | --- | --- | --- |")
    for r in rows:
        met = {True: "yes", False: "**no**"}[r["met"]]
        print(f"| {r['name']} | {r['cam']:.2f} | {r['ref']:.2f} | {r['ratio']} | {r['target']} | {met} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
