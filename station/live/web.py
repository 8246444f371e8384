"""The live page, built on :mod:`station.web` like every station page.

Routes: ``/`` (the page), ``/api/state`` (JSON, :meth:`LiveStation.state`), ``/api/frame.jpg``
(the last frame, downscaled; ``?id=N`` only makes the address change with the frame),
``/api/command`` (POST ``{"action": ..., "value": ...}``, :meth:`LiveStation.command`).
"""

from __future__ import annotations

import asyncio
from pathlib import Path

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from station.live.runner import LiveStation
from station.web import create_app, render

HERE = Path(__file__).resolve().parent
COMMAND_WAIT_S = 2.0
"""How long a command's answer is awaited (a move answers at once; its end shows in the state)."""


def _live(request: Request) -> LiveStation:
    station: LiveStation = request.app.state.live
    return station


async def index(request: Request) -> Response:
    return render(request, "live.html", station=_live(request))


async def state(request: Request) -> Response:
    return JSONResponse(_live(request).state())


async def frame(request: Request) -> Response:
    _, jpeg = _live(request).frame_jpeg()
    if jpeg is None:
        return JSONResponse({"error": "no frame yet"}, status_code=404)
    return Response(jpeg, media_type="image/jpeg", headers={"cache-control": "no-store"})


async def command(request: Request) -> Response:
    try:
        body = await request.json()
    except ValueError:
        return JSONResponse({"error": 'expected a JSON object {"action": ..., "value": ...}'}, status_code=400)
    if not isinstance(body, dict) or not isinstance(body.get("action"), str):
        return JSONResponse({"error": 'expected a JSON object {"action": ..., "value": ...}'}, status_code=400)
    fut = _live(request).command(body["action"], body.get("value"))
    if fut.done() and fut.exception() is not None:
        return JSONResponse({"error": str(fut.exception())}, status_code=400)
    if body["action"] in ("next", "previous", "goto", "home"):
        return JSONResponse({"ok": True, "queued": body["action"]}, status_code=202)
    try:
        result = await asyncio.wait_for(asyncio.wrap_future(fut), COMMAND_WAIT_S)
    except TimeoutError:
        return JSONResponse({"ok": True, "queued": body["action"]}, status_code=202)
    except ValueError as exc:
        return JSONResponse({"error": str(exc)}, status_code=400)
    return JSONResponse(result)


def live_app(station: LiveStation) -> Starlette:
    """The live page's app for ``station`` (serve it with :func:`station.web.serve`)."""
    return create_app(
        f"harp live — {station.title}",
        [
            Route("/", index),
            Route("/api/state", state),
            Route("/api/frame.jpg", frame),
            Route("/api/command", command, methods=["POST"]),
        ],
        templates=[HERE / "templates"],
        static={"live": HERE / "static"},
        state={"live": station},
    )
