"""Run a station web app: on 127.0.0.1 by default, behind a token when reachable from elsewhere.

:func:`serve` runs an app in the foreground until Ctrl-C; :func:`start` runs it on a background
thread and returns a :class:`RunningServer` (its ``url``; ``stop()``), for tests and for a live
page next to a running session. Both refuse to bind an address other than the loopback one
unless a token is given (:func:`check_bind`): the live view moves a turntable and changes the
camera's settings, the dashboard shows a factory's results.

With a token every request needs it, as ``Authorization: Bearer TOKEN``, or once as
``?token=TOKEN`` in the address (the browser then keeps it in a same-site, HTTP-only
cookie and is redirected to the address without it). Without it: 401 and one line.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import socket
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.cookies import SimpleCookie
from urllib.parse import parse_qsl, urlencode

from starlette.types import ASGIApp, Receive, Scope, Send

from station.errors import HarpError

LOOPBACK_HOSTS = ("127.0.0.1", "::1", "localhost")
COOKIE = "harp_token"


class ServeError(HarpError, ValueError):
    """The app cannot be served as asked; ``str()`` is one line."""


def check_bind(host: str, token: str | None) -> None:
    """Refuse (:class:`ServeError`) a non-loopback ``host`` without a ``token``, or an empty token."""
    if token is not None and not token.strip():
        raise ServeError("the token is empty: give a long random string (e.g. from `openssl rand -hex 16`)")
    if host not in LOOPBACK_HOSTS and token is None:
        raise ServeError(
            f"host {host!r} makes the page reachable from other machines: give a token (--token) or serve on 127.0.0.1"
        )


class TokenGate:
    """ASGI middleware: every request must carry ``token`` (module docstring)."""

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app, self.token = app, token

    def _ok(self, value: str | None) -> bool:
        return value is not None and hmac.compare_digest(value.encode(), self.token.encode())

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        auth = headers.get("authorization", "")
        if auth.lower().startswith("bearer ") and self._ok(auth[7:].strip()):
            await self.app(scope, receive, send)
            return
        cookie = SimpleCookie()
        with contextlib.suppress(Exception):
            cookie.load(headers.get("cookie", ""))
        if COOKIE in cookie and self._ok(cookie[COOKIE].value):
            await self.app(scope, receive, send)
            return
        query = parse_qsl(scope.get("query_string", b"").decode("latin-1"), keep_blank_values=True)
        given = [v for k, v in query if k == "token"]
        if scope["type"] == "http" and given and self._ok(given[-1]):
            rest = urlencode([(k, v) for k, v in query if k != "token"])
            location = scope.get("root_path", "") + scope["path"] + (f"?{rest}" if rest else "")
            await send(
                {
                    "type": "http.response.start",
                    "status": 303,
                    "headers": [
                        (b"location", location.encode("latin-1")),
                        (b"set-cookie", f"{COOKIE}={self.token}; HttpOnly; SameSite=Strict; Path=/".encode()),
                        (b"content-length", b"0"),
                    ],
                }
            )
            await send({"type": "http.response.body", "body": b""})
            return
        body = b"401: this page needs its token (open the address printed by the command, with ?token=...)\n"
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 4401})
            return
        await send(
            {
                "type": "http.response.start",
                "status": 401,
                "headers": [
                    (b"content-type", b"text/plain; charset=utf-8"),
                    (b"content-length", str(len(body)).encode()),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})


def _bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ServeError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


def _server(app: ASGIApp, token: str | None):  # -> uvicorn.Server
    import uvicorn

    wrapped = TokenGate(app, token) if token is not None else app
    config = uvicorn.Config(wrapped, log_level="warning", access_log=False, lifespan="on", timeout_graceful_shutdown=2)
    return uvicorn.Server(config)


def _url(host: str, port: int, token: str | None) -> str:
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/" + (f"?token={token}" if token is not None else "")


@dataclass
class RunningServer:
    """An app served on a background thread (:func:`start`)."""

    host: str
    port: int
    token: str | None
    _server: object = field(repr=False)
    _thread: threading.Thread = field(repr=False)

    @property
    def url(self) -> str:
        """The page's address (with ``?token=`` when there is one)."""
        return _url(self.host, self.port, self.token)

    @property
    def base(self) -> str:
        """The address without the token."""
        return _url(self.host, self.port, None)

    def stop(self, timeout: float = 5.0) -> None:
        self._server.should_exit = True  # type: ignore[attr-defined]
        self._thread.join(timeout)

    def __enter__(self) -> RunningServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def start(app: ASGIApp, host: str = "127.0.0.1", port: int = 0, token: str | None = None) -> RunningServer:
    """Serve ``app`` on a background thread; return once it accepts connections.

    ``port`` 0 picks a free port (``RunningServer.port``). Raises
    :class:`ServeError` (one line) when the address cannot be used.
    """
    check_bind(host, token)
    sock = _bind(host, port)
    server = _server(app, token)
    failed: list[BaseException] = []

    def run() -> None:
        try:
            asyncio.run(server.serve(sockets=[sock]))
        except BaseException as exc:  # reported by start()
            failed.append(exc)
        finally:
            sock.close()

    thread = threading.Thread(target=run, name=f"harp-web-{sock.getsockname()[1]}", daemon=True)
    thread.start()
    while not server.started and thread.is_alive():
        thread.join(0.01)
    if not server.started:
        raise ServeError(f"the web server on {host} did not start: {failed[0] if failed else 'unknown reason'}")
    return RunningServer(host, int(sock.getsockname()[1]), token, server, thread)


def serve(app: ASGIApp, host: str = "127.0.0.1", port: int = 8000, token: str | None = None) -> None:
    """Serve ``app`` in the foreground until Ctrl-C (then KeyboardInterrupt, after a clean shutdown).

    Prints the address to stderr. Raises :class:`ServeError` (one line) for
    a refused or unusable address.
    """
    check_bind(host, token)
    sock = _bind(host, port)
    # not through say: the address line of harp serve and harp live, read by scripts from the line's start
    print(f"serving on {_url(host, int(sock.getsockname()[1]), token)} (Ctrl-C to stop)", file=sys.stderr, flush=True)
    server = _server(app, token)
    try:  # uvicorn re-raises the Ctrl-C it captured (KeyboardInterrupt) once it has shut down
        asyncio.run(server.serve(sockets=[sock]))
    finally:
        sock.close()


@contextlib.contextmanager
def started(app: ASGIApp, host: str = "127.0.0.1", port: int = 0, token: str | None = None) -> Iterator[RunningServer]:
    """:func:`start` as a context manager (stopped on exit)."""
    srv = start(app, host, port, token)
    try:
        yield srv
    finally:
        srv.stop()
