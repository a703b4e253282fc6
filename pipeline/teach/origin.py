"""The teach page's websocket Origin check: only the page itself may drive the server.

A websocket whose ``Origin`` header is not the server's own address (a page on another
site, which the user's browser would let connect to 127.0.0.1) is refused with 403 before
its first message (:func:`own_origin`). viser builds its websocket server itself, so
:func:`origin_checked_serve` puts the check into it while it is built.
"""

from __future__ import annotations

import contextlib
import http
import ipaddress
import socket
import threading
from collections.abc import Iterator
from typing import Any
from urllib.parse import urlsplit

_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
_WILDCARD_HOSTS = frozenset({"", "0.0.0.0", "::"})


def own_origin(origin: str, *, host: str, port: int) -> bool:
    """Whether a websocket's ``Origin`` is the teach page's own: ``http(s)://`` the
    server's host (or a loopback name; when it listens on all interfaces, an IP address
    of one of this machine's interfaces, see :func:`is_own_address`) and its port. A host
    *name* other than ``localhost`` is refused even when it resolves here: that is how DNS
    rebinding reaches 127.0.0.1.
    """
    try:
        parts = urlsplit(origin)
        origin_port = parts.port or {"http": 80, "https": 443}.get(parts.scheme)
    except ValueError:
        return False
    name = (parts.hostname or "").lower()
    if parts.scheme not in ("http", "https") or origin_port != port or not name:
        return False
    if name in _LOOPBACK_NAMES:
        return True
    if host in _WILDCARD_HOSTS:  # (an Origin of 0.0.0.0 is no page's address)
        return is_own_address(name)
    return name == host.lower().strip("[]")


def is_own_address(name: str) -> bool:
    """Whether ``name`` is an IP literal of one of this machine's interfaces (a socket can
    bind to it); not an unspecified, multicast or broadcast address, never a host name."""
    try:
        ip = ipaddress.ip_address(name)
    except ValueError:
        return False
    if ip.is_unspecified or ip.is_multicast or str(ip) == "255.255.255.255":
        return False
    family = socket.AF_INET6 if ip.version == 6 else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as probe:
            probe.bind((str(ip), 0))
    except OSError:
        return False  # EADDRNOTAVAIL: not an address of this machine
    return True


# viser builds its websocket server inside a thread it starts; the Origin check is put
# into that server by wrapping ``websockets.asyncio.server.serve`` while it is built
_SERVE_LOCK = threading.Lock()


@contextlib.contextmanager
def origin_checked_serve(host: str) -> Iterator[list[bool]]:
    """While active, websocket servers built in this process refuse foreign Origins.

    Yields a list that gains an entry when a server was built with the check (the
    caller fails closed when viser built none)."""
    import websockets.asyncio.server as ws_server

    real = ws_server.serve
    built: list[bool] = []

    def serve(*args: Any, **kwargs: Any) -> Any:
        inner = kwargs.get("process_request")

        def process_request(connection: Any, request: Any) -> Any:
            origin = request.headers.get("Origin")
            if (
                request.headers.get("Upgrade", "").lower() == "websocket"
                and origin is not None
                and not own_origin(origin, host=host, port=int(connection.local_address[1]))
            ):
                return connection.respond(
                    http.HTTPStatus.FORBIDDEN,
                    f"armlab teach: a websocket from {origin} is refused; open the page itself\n",
                )
            return inner(connection, request) if inner is not None else None

        kwargs["process_request"] = process_request
        built.append(True)
        return real(*args, **kwargs)

    with _SERVE_LOCK:
        setattr(ws_server, "serve", serve)  # noqa: B010 - mypy: serve is a class there
        try:
            yield built
        finally:
            setattr(ws_server, "serve", real)  # noqa: B010


def guard_incoming_messages() -> None:
    """Make viser's per-connection message loop survive a malformed message.

    A message that does not decode (random bytes, an unknown type, missing fields, a
    100k-deep value) or that viser's handler cannot apply is dropped with one line on
    stderr (``armlab teach: ignored a malformed message from a client: ...``), never a
    traceback, and the connection keeps going. Idempotent.
    """
    import viser.infra._infra as infra

    if getattr(infra._message_consumer, "_armlab_guarded", False):
        return

    async def _message_consumer(websocket: Any, handle_message: Any, message_class: Any) -> None:
        while True:
            raw = await websocket.recv()
            try:
                if not isinstance(raw, bytes):
                    raise TypeError(f"a text frame of {len(raw)} characters")
                message = message_class.deserialize(raw)
                handle_message(message)
            except RecursionError:
                _ignored("nested too deeply")
            except Exception as err:  # a client's bytes: never a traceback here
                _ignored(f"{type(err).__name__}: {err}")

    _message_consumer._armlab_guarded = True  # type: ignore[attr-defined]
    infra._message_consumer = _message_consumer


def _ignored(reason: str) -> None:
    import sys

    line = " ".join(reason.split())[:200]
    print(f"armlab teach: ignored a malformed message from a client: {line}", file=sys.stderr)
