"""The app factory of the station's web pages (see :mod:`station.web`)."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jinja2
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import BaseRoute, Mount, Route
from starlette.staticfiles import StaticFiles
from starlette.templating import Jinja2Templates
from starlette.types import ASGIApp, Message, Receive, Scope, Send

HERE = Path(__file__).resolve().parent
BASE_TEMPLATES = HERE / "templates"
BASE_STATIC = HERE / "static"

#: every resource from this origin only: nothing is fetched from the internet
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'"
)

log = logging.getLogger("station.web")


class _SecurityHeaders:
    """Adds the security headers to every response; ``no-store`` on ``/api/`` responses."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        api = str(scope.get("path", "")).startswith("/api/")

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers += [
                    (b"content-security-policy", CONTENT_SECURITY_POLICY.encode()),
                    (b"x-content-type-options", b"nosniff"),
                    (b"referrer-policy", b"no-referrer"),
                ]
                if api:
                    headers.append((b"cache-control", b"no-store"))
                message["headers"] = headers
            await send(message)

        await self.app(scope, receive, send_with_headers)


async def _healthz(request: Request) -> Response:
    return JSONResponse({"ok": True, "title": request.app.state.title})


async def _server_error(request: Request, exc: Exception) -> Response:
    text = " ".join(str(exc).split()) or type(exc).__name__
    log.error("%s %s: %s", request.method, request.url.path, text)
    return JSONResponse({"error": f"{type(exc).__name__}: {text}"}, status_code=500)


def create_app(
    title: str,
    routes: Sequence[BaseRoute],
    *,
    templates: Sequence[Path] = (),
    static: Mapping[str, Path] | None = None,
    nav: Sequence[tuple[str, str]] = (),
    state: Mapping[str, Any] | None = None,
    middleware: Sequence[Middleware] = (),
    lifespan: Any = None,
) -> Starlette:
    """A Starlette app with the station's base template, static files and conventions.

    Parameters
    ----------
    title : shown in the page header and the ``<title>``.
    routes : the page's routes (``/healthz`` and ``/static/...`` are added).
    templates : folders searched for templates before :data:`BASE_TEMPLATES`
        (``base.html``); a page template ``{% extends "base.html" %}``.
    static : extra static folders, ``{name: folder}``, served at ``/static/<name>/``
        (``base`` is :data:`BASE_STATIC`).
    nav : ``(href, label)`` links in the header.
    state : set as attributes of ``app.state`` (reach them as ``request.app.state.X``).
    middleware, lifespan : passed to Starlette.
    """
    static = dict(static or {})
    if "base" in static:
        raise ValueError("static folder name 'base' is the station's own")
    env = jinja2.Environment(
        loader=jinja2.ChoiceLoader([jinja2.FileSystemLoader([str(p) for p in templates] + [str(BASE_TEMPLATES)])]),
        autoescape=jinja2.select_autoescape(default=True),
        undefined=jinja2.StrictUndefined,
    )
    mounts: list[BaseRoute] = [Mount("/static/base", StaticFiles(directory=BASE_STATIC), name="static-base")]
    mounts += [
        Mount(f"/static/{name}", StaticFiles(directory=folder), name=f"static-{name}")
        for name, folder in static.items()
    ]
    app = Starlette(
        routes=[*routes, Route("/healthz", _healthz), *mounts],
        middleware=[Middleware(_SecurityHeaders), *middleware],
        exception_handlers={Exception: _server_error},
        lifespan=lifespan,
    )
    app.state.title = title
    app.state.nav = list(nav)
    app.state.templates = Jinja2Templates(env=env)
    app.state.static_names = ["base", *static]
    for key, value in (state or {}).items():
        setattr(app.state, key, value)
    return app


def render(request: Request, name: str, status_code: int = 200, **context: Any) -> Response:
    """The template ``name`` rendered with ``title``, ``nav`` and ``context``."""
    app_state = request.app.state
    ctx = {"title": app_state.title, "nav": app_state.nav, **context}
    response: Response = app_state.templates.TemplateResponse(request, name, ctx, status_code=status_code)
    return response
