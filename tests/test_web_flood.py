"""The emergency stop is always served (issue #33 point 3): slow bodies, connection floods and clients over
their address's limit never get e-stop, stop, pause or state refused, while the token and origin rules hold.

Real servers (``test_web.Server``) on 127.0.0.1 with small limits, so a handful of sockets is a flood; every
wait is bounded.  The timings under a real 1,000-client flood are a benchmark (benchmarks/estop_flood.py).
"""
from __future__ import annotations

import json
import socket
import time

import pytest

from test_web import FAST, TOKEN, Server

from cam.web.connections import ConnectionGuard, safety_head

LIMITS = dict(max_connections=4, max_event_streams=2, max_connections_per_client=3, max_open_connections=6,
              header_timeout_s=3.0, body_timeout_s=1.0)


@pytest.fixture(scope="module")
def tmp(tmp_path_factory):
    return tmp_path_factory.mktemp("flood")


@pytest.fixture(scope="module")
def small(tmp):
    """A server with room for 4 requests, 3 connections from one address, 6 connections held."""
    s = Server(tmp, settings=FAST, **LIMITS)
    yield s
    s.close()


@pytest.fixture(scope="module")
def small_token(tmp):
    s = Server(tmp, settings=FAST, token=TOKEN, **LIMITS)
    yield s
    s.close()


@pytest.fixture
def server(small):
    yield small
    _wait_all_closed(small)


def _port(s) -> int:
    return int(s.url.rsplit(":", 1)[1])


def _connect(s, source: str = "127.0.0.1") -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", _port(s)), timeout=5, source_address=(source, 0))
    return sock


def _head(s, method: str, path: str, *, length: int | None = None, token: str | None = None) -> bytes:
    lines = [f"{method} {path} HTTP/1.1", f"Host: 127.0.0.1:{_port(s)}"]
    if method == "POST":
        lines += [f"Origin: {s.url}", "Content-Type: application/json", f"Content-Length: {length or 0}"]
    if token:
        lines.append(f"X-Cam-Token: {token}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def _answer(sock: socket.socket, timeout_s: float = 5.0) -> tuple[int, dict, bytes]:
    """(status, lower-case headers, body) of the one answer on ``sock`` (status 0: closed with none)."""
    sock.settimeout(timeout_s)
    got = b""
    try:
        while b"\r\n\r\n" not in got:
            chunk = sock.recv(65536)
            if not chunk:
                return 0, {}, got
            got += chunk
        head, _, body = got.partition(b"\r\n\r\n")
        lines = head.decode().split("\r\n")
        headers = {k.lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
        while len(body) < int(headers.get("content-length", 0)):
            chunk = sock.recv(65536)
            if not chunk:
                break
            body += chunk
    except (ConnectionResetError, socket.timeout):
        return 0, {}, got
    return int(lines[0].split()[1]), headers, body


def _ask(s, method: str, path: str, *, token: str | None = None, source: str = "127.0.0.1") -> tuple[int, dict]:
    """(status, JSON) of one request on a new connection."""
    body = b"{}" if method == "POST" else b""
    with _connect(s, source) as sock:
        sock.sendall(_head(s, method, path, length=len(body), token=token) + body)
        status, _, payload = _answer(sock)
    return status, (json.loads(payload) if payload.startswith(b"{") else {})


def _slow_bodies(s, n: int, path: str = "/api/jog") -> list[socket.socket]:
    """``n`` requests whose head came whole and whose body (26 bytes announced) has only begun, each from an
    address of its own (127.0.0.10, 127.0.0.11, ...: no address over its limit)."""
    socks = []
    for i in range(n):
        sock = _connect(s, f"127.0.0.{10 + i}")
        sock.sendall(_head(s, "POST", path, length=26) + b'{"axis": "y", ')
        socks.append(sock)
    return socks


def _wait(predicate, what: str, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


def _wait_all_closed(s) -> None:
    guard = s.app.state.guard
    _wait(lambda: not guard.connections and guard.requests == 0, f"connections left: {len(guard.connections)}")


def _close(socks) -> None:
    for sock in socks:
        sock.close()


SAFETY = [("POST", "/api/estop"), ("POST", "/api/stop"), ("POST", "/api/pause"), ("GET", "/api/state")]
ANSWER = {"/api/estop": 200, "/api/stop": 200, "/api/pause": 409, "/api/state": 200}
"""Each safety route's own answer on an idle machine (pause: "nothing is running"), not a refusal for load."""


def test_safety_routes_are_answered_while_slow_bodies_hold_every_request_slot(server):
    """Issue #33's finding: slow JSON bodies made Stop, Pause and State answer 503.  Here slow bodies fill the
    request slots; every safety route is still answered, anything else is
    refused for load, and nothing moved."""
    guard = server.app.state.guard
    socks = _slow_bodies(server, LIMITS["max_connections"])
    try:
        _wait(lambda: guard.requests == LIMITS["max_connections"], "the slow bodies are in progress")
        status, r = _ask(server, "GET", "/api/config")
        assert status == 503 and ("busy" in r["error"] or "too many connections" in r["error"]), r
        for method, path in SAFETY:
            status, r = _ask(server, method, path)
            assert status == ANSWER[path], (path, r)
        assert list(server.session.position_steps()) == [0, 0, 0]
    finally:
        _close(socks)


def test_an_oversized_content_length_is_refused_before_its_body(server):
    """A body announced over the route's limit gets 413 at its head (no byte of it sent), whatever the route."""
    for path, limit in (("/api/jog", "8 kB"), ("/api/estop", "8 kB"), ("/api/upload", "too large")):
        with _connect(server) as sock:
            sock.sendall(_head(server, "POST", path, length=10 ** 9))
            status, headers, body = _answer(sock)
            assert status == 413 and limit in json.loads(body)["error"], (path, body)
            assert headers["connection"] == "close"
    # the usual client, which sends its whole oversized body before reading, still gets the answer
    status, r = server.call("POST", "/api/jog", raw=b'{"pad": "' + b"x" * 200_000 + b'"}',
                            headers={"Content-Type": "application/json"})
    assert status == 413 and "8 kB" in r["error"]


def test_a_body_that_dribbles_in_is_closed_at_its_time_limit(server):
    """A body may not pause longer than body_timeout_s, and must come whole within body_timeout_s (+1 s per
    16 kB): one byte every 0.15 s never pauses too long, and is closed anyway."""
    with _connect(server) as sock:
        sock.sendall(_head(server, "POST", "/api/jog", length=26))
        sent, status = 0, None
        for byte in b'{"axis": "y", "steps": 7}'[:20]:
            try:
                sock.sendall(bytes([byte]))
                sent += 1
            except OSError:
                break
            time.sleep(0.15)
        status, _, body = _answer(sock, 2.0)
    assert sent < 20 and status in (408, 0), (sent, status, body)
    assert list(server.session.position_steps()) == [0, 0, 0]


def test_a_client_over_its_address_limit_gets_only_safety_routes_and_others_are_served(server):
    """Three connections from 127.0.0.1 (the limit): a fourth from there may stop the machine and read its
    state but nothing else; a client at another address is served as usual."""
    held = [_connect(server) for _ in range(LIMITS["max_connections_per_client"])]
    try:
        guard = server.app.state.guard
        _wait(lambda: guard.per_client.get("127.0.0.1") == len(held), "the held connections are counted")
        status, r = _ask(server, "GET", "/api/config")
        assert status == 503 and "too many connections" in r["error"], r
        for method, path in SAFETY:
            assert _ask(server, method, path)[0] == ANSWER[path], path
        status, r = _ask(server, "GET", "/api/config", source="127.0.0.2")
        assert status == 200 and "max_upload_bytes" in r
    finally:
        _close(held)


def test_connections_over_the_held_limit_close_half_sent_heads_first(server):
    """Over max_open_connections a half-sent head of another route is closed (503) to make room; the e-stop
    that came last is answered."""
    half = []
    try:
        for _ in range(LIMITS["max_open_connections"] + 2):
            sock = _connect(server, "127.0.0.3")  # another address: no probation, only the held limit
            sock.sendall(b"POST /api/jog HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            half.append(sock)
            time.sleep(0.02)
        closed = [_answer(sock, 0.5) for sock in half[:2]]
        assert all(status in (503, 0) for status, _, _ in closed), closed
        assert any(status == 503 and b"too many connections" in body for status, _, body in closed), closed
        assert _ask(server, "POST", "/api/estop", source="127.0.0.4")[0] == 200
    finally:
        _close(half)


def test_an_estop_under_flood_on_a_token_server_still_needs_the_token(small_token):
    s = small_token
    before = (s.session.version, s.session.last_run)
    socks = _slow_bodies(s, LIMITS["max_connections"])  # every request slot taken
    flood = []
    try:
        for _ in range(LIMITS["max_open_connections"]):
            flood.append(_connect(s))
            flood[-1].sendall(b"POST /api/jog HTTP/1.1\r\n")
        for method, path in SAFETY:
            status, r = _ask(s, method, path)
            assert status == 401 and "token" in r["error"], (path, r)
        assert (s.session.version, s.session.last_run) == before  # not even a log line
        for method, path in SAFETY:
            assert _ask(s, method, path, token=TOKEN)[0] == ANSWER[path], path
        assert _ask(s, "POST", "/api/estop", token="wrong-token-0123456789")[0] == 401
    finally:
        _close(socks + flood)
        _wait_all_closed(s)


# ------------------------------------------------------------------------------------
# the rules on their own
# ------------------------------------------------------------------------------------


class _Conn:
    """A stand-in for the guarded protocol: a real socket's server end, silent unless ``prefix`` came."""

    def __init__(self, transport_sock: socket.socket, host: str = "127.0.0.1") -> None:
        self.sock = transport_sock
        self.client_host, self.client = host, (host, transport_sock.fileno())
        self.evicted = False
        self.probation = False
        self.transport = self

    def get_extra_info(self, name: str):
        return self.sock if name == "socket" else None

    def room_rank(self, now_s: float):
        return None if self.evicted else 1  # silent: closed only when its unread bytes are no safety head

    def evict(self) -> None:
        self.evicted = True


def test_closing_to_make_room_never_takes_an_unread_estop():
    """A connection whose e-stop is in its socket but not read yet is passed over; the oldest silent one
    without is closed instead."""
    class Config:
        max_connections, max_connections_per_client, max_open_connections = 100, 100, 2

    guard = ConnectionGuard(Config(), lambda method, path: 8192)
    pairs = [socket.socketpair() for _ in range(3)]
    try:
        conns = [_Conn(server_end) for server_end, _ in pairs]
        pairs[0][1].sendall(b"POST /api/estop HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")  # the oldest: an e-stop
        pairs[2][1].sendall(b"GET /api/state?log_after=0 HTTP/1.1\r\n")
        for conn in conns:
            guard.add(conn)
        guard.make_room(conns[2])  # three held, two allowed
        assert [c.evicted for c in conns] == [False, True, False]
        assert pairs[0][0].recv(5, socket.MSG_PEEK) == b"POST "  # left unread for the server
    finally:
        for a, b in pairs:
            a.close()
            b.close()


@pytest.mark.parametrize("head, safety", [
    (b"POST /api/estop HTTP/1.1\r\n", True), (b"POST /api/stop?x=1 HTTP/1.1", True), (b"POST /api/pause ", True),
    (b"GET /api/state HTTP/1.1", True), (b"\r\nGET /api/state ", True),
    (b"GET /api/estop HTTP/1.1", False), (b"POST /api/stopper ", False), (b"POST /api/jog ", False),
    (b"POST /api/resume ", False), (b"", None), (b"POS", None), (b"POST /api/e", None),
])
def test_safety_heads_are_told_from_the_request_line(head, safety):
    assert safety_head(head) is safety
