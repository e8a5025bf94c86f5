"""How ``cam serve`` keeps its connections, so that the emergency stop is always served (issue #33 point 3).

The server is one asyncio event loop (uvicorn's h11 protocol, extended here);
the accept loop never waits for a client, and no client can hold a request
worker, so what a flood can take is *connections* and *request slots*.  The
rules, in the order a request meets them:

* **Safety routes** (:data:`SAFETY_ROUTES`: ``POST /api/estop``, ``/api/stop``,
  ``/api/pause`` and ``GET /api/state``) are told from their request line, before
  any body is read, and are never refused for load: they skip the request limit
  and the per-address limit, and a connection whose first bytes name one is not
  closed to make room (for :data:`SAFETY_GRACE_S`, time enough for a head that
  is being sent; a head that dawdles longer is treated like any other).  The
  token, ``Host`` and origin rules apply to them exactly as to every request.
* **Connection limits**: a connection from an address that already holds
  ``max_connections_per_client`` is *on probation*: only a safety route is
  served on it (anything else gets 503 at its head, before its body), so one
  client cannot take the request slots of the others; at most
  ``max_connections`` other requests are in progress (more get 503).  Up to
  ``max_open_connections`` connections (and at most a quarter of the process's
  file limit) are *held* rather than closed: a flood client that is left
  waiting for its deadline is not reconnecting, so the kernel's accept queue
  stays short and a new e-stop connection is accepted at once.  Over that, one
  connection with no request in progress is closed, from the address holding
  most first: a half-sent head that is no safety route (with a 503), else a
  silent or idle one, oldest first, whose unread bytes are peeked at first, so
  a just-accepted e-stop is never the one closed before it was read.  A head's
  deadline is ``header_timeout_s`` and up to half as long again at random, so
  a flood that came in one burst does not expire and come back in one.
* **Bodies**: a body announced larger than its route takes (``Content-Length``)
  is refused with 413 at once, before any of it is read; a body must come
  whole within ``body_timeout_s`` plus its length at :data:`MIN_BODY_BYTES_PER_S`
  (slow bodies are closed, one byte every 5 s cannot hold a connection), and may
  not pause longer than ``body_timeout_s``.
* **Refusals close gracefully**: after an answer given before the body came
  whole (413, 503) or a refusal for load, the connection is kept for at most
  :data:`LINGER_S` (2 to 3 s) while what comes is read and dropped (at most
  :data:`LINGER_BYTES`), so an honest client reads its answer instead of a
  reset, and a refused flood client does not reconnect at once.
"""
from __future__ import annotations

import asyncio
import random
import socket
import time
from functools import lru_cache
from typing import Any, Callable, Optional

try:
    import resource
except ImportError:  # pragma: no cover - not Unix: no file limit
    resource = None  # type: ignore[assignment]

__all__ = ["SAFETY_ROUTES", "SAFETY_GRACE_S", "MIN_BODY_BYTES_PER_S", "LINGER_S", "LINGER_BYTES",
           "is_safety_route", "safety_head", "ConnectionGuard", "guarded_h11", "plain_response"]

SAFETY_ROUTES = frozenset({("POST", "/api/estop"), ("POST", "/api/stop"), ("POST", "/api/pause"),
                           ("GET", "/api/state")})
"""(method, path) of the requests that are never refused for load: stopping the machine and seeing it."""
SAFETY_GRACE_S = 1.0
"""How long a connection whose first bytes name a safety route is kept out of the closing to make room."""
MIN_BODY_BYTES_PER_S = 16 * 1024
"""A body must come at least this fast on average (after a start of ``body_timeout_s``)."""
LINGER_S = 2.0
LINGER_BYTES = 1024 * 1024
"""After an answer given before the body came whole, or a refusal for load: read and drop what comes for at
most this long (and up to half as long again, at random) or this much, then close."""
_HEAD_PREFIX_BYTES = 64  # enough of a request line to tell its route
_SAFETY_LINES = tuple(sorted(f"{method} {path}".encode() for method, path in SAFETY_ROUTES))


def is_safety_route(method: str, path: str) -> bool:
    """Whether ``method path`` is one of :data:`SAFETY_ROUTES`.

    >>> is_safety_route("POST", "/api/estop"), is_safety_route("GET", "/api/state"), is_safety_route("POST", "/api/jog")
    (True, True, False)
    """
    return (method, path) in SAFETY_ROUTES


def safety_head(data: bytes) -> Optional[bool]:
    """Whether the first bytes of a request (``data``) ask for a safety route: True, False, or None while they
    are too few to tell.

    >>> safety_head(b"POST /api/estop HTTP/1.1\\r\\n"), safety_head(b"GET /api/state?log_after=3 HTTP/1.1")
    (True, True)
    >>> safety_head(b"POST /api/jog HTTP/1.1"), safety_head(b"POST /api/es"), safety_head(b"GET /api/stateX ")
    (False, None, False)
    """
    data = data.lstrip(b"\r\n")
    undecided = False
    for line in _SAFETY_LINES:
        if len(data) > len(line):
            if data.startswith(line) and data[len(line):len(line) + 1] in (b" ", b"?"):
                return True
        elif line.startswith(data):
            undecided = True
    return None if undecided else False


def plain_response(status: int, reason: str, text: str) -> bytes:
    """A whole HTTP/1.1 response that closes the connection (written where no request has been read)."""
    body = (text + "\n").encode()
    return (f"HTTP/1.1 {status} {reason}\r\ncontent-type: text/plain; charset=utf-8\r\nconnection: close\r\n"
            f"content-length: {len(body)}\r\n\r\n").encode() + body


def _peek(transport: Any) -> bytes:
    """The bytes a connection has sent that are not read yet (at most a request line's worth; b"" when none)."""
    sock = transport.get_extra_info("socket")
    if sock is None:
        return b""
    try:
        raw = socket.socket(sock.family, sock.type, fileno=sock.fileno())
    except OSError:
        return b""
    try:
        return raw.recv(_HEAD_PREFIX_BYTES, socket.MSG_PEEK | getattr(socket, "MSG_DONTWAIT", 0))
    except OSError:  # nothing there (EAGAIN), or the connection is gone
        return b""
    finally:
        raw.detach()  # the descriptor stays the transport's


class ConnectionGuard:
    """The server's open connections (oldest first, counted by client address) and its requests in progress.

    Shared by the HTTP protocol (:func:`guarded_h11`), which registers connections and makes room when
    there are too many, and by the server's front door, which counts the requests (``requests``: those under
    the request limit; ``safety_requests``: the safety routes, never limited) and reads ``probation``.

    ``body_cap(method, path)`` is the most body bytes the route takes (for the body's time limit).
    """

    def __init__(self, config: Any, body_cap: Callable[[str, str], int]) -> None:
        self.config = config
        self.body_cap = body_cap
        self.connections: dict[Any, None] = {}  # protocol -> None, in the order they connected
        self.per_client: dict[str, int] = {}  # client address -> connections
        self.by_peer: dict[Any, Any] = {}  # (address, port) -> protocol
        self.requests = 0
        self.safety_requests = 0
        self.closed_for_room = 0  # connections closed to make room (statistics)
        self._open_limit: Optional[int] = None

    def add(self, conn: Any) -> None:
        self.connections[conn] = None
        self.per_client[conn.client_host] = self.per_client.get(conn.client_host, 0) + 1
        self.by_peer[conn.client] = conn

    def remove(self, conn: Any) -> None:
        if self.connections.pop(conn, 0) is None:
            left = self.per_client[conn.client_host] - 1
            if left:
                self.per_client[conn.client_host] = left
            else:
                del self.per_client[conn.client_host]
            if self.by_peer.get(conn.client) is conn:
                del self.by_peer[conn.client]

    def connection_of(self, client: Any) -> Any:
        """The connection of an ASGI scope's ``client`` (address, port), or None."""
        return self.by_peer.get(tuple(client) if client else None)

    def open_limit(self) -> int:
        """The most connections held: ``max_open_connections``, and at most a quarter of this process's file
        limit (read once, at the first connection: ``serve`` raises the limit before it listens)."""
        if self._open_limit is None:
            fd_limit = resource.getrlimit(resource.RLIMIT_NOFILE)[0] if resource is not None else -1
            limit = self.config.max_open_connections
            if fd_limit > 0:
                limit = min(limit, max(16, fd_limit // 4))
            self._open_limit = limit
        return self._open_limit

    def make_room(self, newcomer: Any) -> None:
        """A new connection: on probation when its address is over ``max_connections_per_client`` (only a safety
        route is served on it); over :meth:`open_limit`, one connection with no request in progress is closed
        (never ``newcomer``), from the address holding most connections first."""
        host = newcomer.client_host
        if self.per_client.get(host, 0) > self.config.max_connections_per_client:
            newcomer.probation = True
        if len(self.connections) > self.open_limit():
            heaviest = max(self.per_client, key=self.per_client.__getitem__)
            if not (heaviest != host and self._close_one(newcomer, heaviest)):
                self._close_one(newcomer, None)

    def _close_one(self, newcomer: Any, host: Optional[str]) -> bool:
        """Close the first of: a half-sent head that is no safety route (or an answered connection being
        let go), then a silent or idle connection whose unread bytes are no safety head; oldest first, from
        ``host`` only when given.  Whether one was closed."""
        now = time.monotonic()
        silent = []
        for conn in self.connections:
            if conn is newcomer or (host is not None and conn.client_host != host):
                continue
            rank = conn.room_rank(now)
            if rank == 0:
                conn.evict()
                return True
            if rank == 1:
                silent.append(conn)
        for conn in silent:
            if safety_head(_peek(conn.transport)) is not True:
                conn.evict()
                return True
        return False


class _LingeringTransport:
    """The connection's transport as uvicorn's protocol sees it: ``close()`` after an answer given before
    the request's body came whole, or after a refusal for load, lets the connection linger (see
    :data:`LINGER_S`) instead of closing it at once."""

    def __init__(self, transport: Any, protocol: "_GuardedConnection") -> None:
        self._transport = transport
        self._protocol = protocol
        self.lingering = False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._transport, name)

    def is_closing(self) -> bool:
        return self.lingering or self._transport.is_closing()

    def close(self) -> None:
        p = self._protocol
        if (not self.lingering and not p.lost and not self._transport.is_closing()
                and (p.conn.their_state is p._h11.SEND_BODY or p.refused_for_load)):
            self.lingering = True
            p.linger()
            return
        self._transport.close()


class _GuardedConnection:
    """The rules of this module as a mixin of uvicorn's ``H11Protocol`` (whose ``conn``, ``cycle``, ``flow``,
    ``loop``, ``client``, ``headers`` and ``scope`` it uses); ``_h11`` is the h11 module uvicorn's protocol runs
    on (set by :func:`guarded_h11`, so this module imports without the web stack)."""

    _h11: Any = None

    def __init__(self, *args: Any, guard: ConnectionGuard, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.guard = guard
        self.deadline: Optional[asyncio.TimerHandle] = None
        self.head_begun = False  # bytes of the awaited request head have come
        self.head_prefix = b""  # its first bytes (to tell a safety route)
        self.head_begun_at = 0.0
        self.body_deadline_at: Optional[float] = None  # the body must be whole by then (monotonic)
        self.probation = False  # came over its address's limit: only a safety route is served
        self.refused_for_load = False  # answered 503 for load: let go slowly (see linger)
        self.lost = False  # gone, or the server is stopping: close without lingering
        self.lingered_bytes = 0
        self.raw_transport: Any = None
        self.client_host = ""

    # -- the guard's view ------------------------------------------------------------
    def idle(self) -> bool:
        """No request of this connection is in the application (waiting for a head, for the rest of a body
        already answered, or being let go)."""
        return self.cycle is None or self.cycle.response_complete

    def room_rank(self, now_s: float) -> Optional[int]:
        """0: may be closed to make room now (a half-sent head of another route, an answered connection
        being let go); 1: silent or idle, may be closed unless its unread bytes name a safety route;
        None: keep (a request in progress, or a safety head on its way)."""
        if not self.idle():
            return None
        if self.transport.lingering:
            return 0
        if self.head_begun:
            if safety_head(self.head_prefix) is True and now_s - self.head_begun_at < SAFETY_GRACE_S:
                return None
            return 0
        return 1

    def evict(self) -> None:
        self.guard.remove(self)  # closing: no longer counted, never chosen again
        self.guard.closed_for_room += 1
        if self.head_begun and self.conn.their_state is self._h11.IDLE:
            self.raw_transport.write(plain_response(
                503, "Service Unavailable", "too many connections (the limit is "
                f"{self.guard.config.max_connections}, {self.guard.config.max_connections_per_client} from one "
                "address); try again"))
        self.raw_transport.close()

    # -- deadlines -------------------------------------------------------------------
    def await_head(self) -> None:
        self.head_begun = False
        self.head_prefix = b""
        self.body_deadline_at = None
        # up to half as long again, at random: connections that came together (a flood) do not all
        # expire, and reconnect, together
        self.set_deadline(self.guard.config.header_timeout_s * (1.0 + 0.5 * random.random()))

    def set_deadline(self, delay_s: Optional[float]) -> None:
        if self.deadline is not None:
            self.deadline.cancel()
        self.deadline = None if delay_s is None else self.loop.call_later(max(0.0, delay_s), self.expire)

    def body_deadline(self) -> None:
        """The deadline while the body comes: the next byte within ``body_timeout_s``, all by its time limit."""
        config = self.guard.config
        now = time.monotonic()
        if self.body_deadline_at is None:
            scope = self.scope or {}
            expected = self.guard.body_cap(scope.get("method", ""), scope.get("path", ""))
            for name, value in self.headers or ():
                if name == b"content-length":
                    try:
                        expected = min(expected, int(value))
                    except ValueError:
                        pass
            self.body_deadline_at = now + config.body_timeout_s + expected / MIN_BODY_BYTES_PER_S
        self.set_deadline(min(config.body_timeout_s, self.body_deadline_at - now))

    def expire(self) -> None:
        self.deadline = None
        if self.raw_transport.is_closing():
            return
        if self.transport.lingering:
            self.raw_transport.close()
            return
        state = self.conn.their_state
        config = self.guard.config
        if state is self._h11.SEND_BODY and self.flow.read_paused and self.cycle is not None \
                and not self.cycle.response_complete:  # the application has not read on yet: its turn
            if self.body_deadline_at is not None:  # the client is not to blame for that time
                self.body_deadline_at += config.body_timeout_s
            self.set_deadline(config.body_timeout_s)
            return
        if state is self._h11.IDLE and self.head_begun:
            self.raw_transport.write(plain_response(
                408, "Request Timeout", f"the request head did not come whole within {config.header_timeout_s:g} s"))
        elif state is self._h11.SEND_BODY and self.cycle is not None and not self.cycle.response_started:
            self.raw_transport.write(plain_response(
                408, "Request Timeout", "the request body came too slowly (a pause over "
                f"{config.body_timeout_s:g} s, or under {MIN_BODY_BYTES_PER_S // 1024} kB/s)"))
        if state in (self._h11.IDLE, self._h11.SEND_BODY):
            self.raw_transport.close()

    def linger(self) -> None:
        """Answered before the body came whole, or refused for load: drop what comes for a while, then
        close (the client has its whole answer, told by its length, and may close first)."""
        self.raw_transport.resume_reading()
        self.set_deadline(LINGER_S * (1.0 + 0.5 * random.random()))

    # -- the protocol ----------------------------------------------------------------
    def connection_made(self, transport: Any) -> None:  # type: ignore[override]
        self.raw_transport = transport
        super().connection_made(_LingeringTransport(transport, self))  # type: ignore[misc]
        self.client_host = self.client[0] if self.client else ""
        self.guard.add(self)
        self.await_head()
        self.guard.make_room(self)

    def shutdown(self) -> None:
        """The server is stopping: nothing lingers (a connection being let go is closed now)."""
        self.lost = True
        if self.transport.lingering:
            self.raw_transport.close()
            return
        super().shutdown()

    def connection_lost(self, exc: Optional[Exception]) -> None:
        self.lost = True
        self.guard.remove(self)
        self.set_deadline(None)
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self.transport.lingering:  # answered and being let go: dropped
            self.lingered_bytes += len(data)
            if self.lingered_bytes > LINGER_BYTES:
                self.raw_transport.close()
            return
        if self.conn.their_state is self._h11.IDLE and len(self.head_prefix) < _HEAD_PREFIX_BYTES:
            if not self.head_prefix:
                self.head_begun_at = time.monotonic()
            self.head_prefix += data[:_HEAD_PREFIX_BYTES - len(self.head_prefix)]
        super().data_received(data)
        state = self.conn.their_state
        if state is self._h11.IDLE:
            self.head_begun = True  # the head's deadline stands
        elif state is self._h11.SEND_BODY:
            self.body_deadline()
        elif not self.transport.is_closing():
            self.set_deadline(None)  # the whole request is in: the application's turn

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if self.transport.is_closing():
            return
        state = self.conn.their_state
        if state is self._h11.IDLE:
            self.await_head()
        elif state is self._h11.SEND_BODY:  # answered before the body came whole: the rest must come on time
            self.body_deadline()


@lru_cache(maxsize=None)
def guarded_h11() -> type:
    """uvicorn's h11 protocol with the rules of this module over a :class:`ConnectionGuard` (passed as
    ``guard=``).

    The client must keep up whenever the server waits for it: the request head whole within
    ``header_timeout_s`` of the connection opening or the previous answer (more bytes do not extend it; a
    half-sent head gets 408), a body within its time limit (module docstring); else the connection is
    closed.  While the application is the one that is slow (an answer being made, a body not read yet)
    there is no deadline.
    """
    from uvicorn.protocols.http.h11_impl import H11Protocol, h11  # h11 as uvicorn's protocol uses it

    class GuardedH11Protocol(_GuardedConnection, H11Protocol):
        _h11 = h11

    return GuardedH11Protocol
