"""The station's web stack: one small ASGI base that every page of harp station builds on.

Starlette + Jinja2 templates, served by uvicorn, with no resource from the internet at run
time (hand-written CSS and JS in ``static/``; a page may add its own static folder). Import
this package only in a command that serves a page: it pulls in Starlette, Jinja2 and uvicorn.

How a page (the live view, the factory QA dashboard) uses it::

    from starlette.routing import Route
    from station.web import create_app, render, serve

    HERE = Path(__file__).parent

    async def index(request):
        return render(request, "dashboard.html", stations=...)   # extends "base.html"

    app = create_app(
        "harp dashboard",
        [Route("/", index)],
        templates=[HERE / "templates"],          # searched before station/web/templates
        static={"dashboard": HERE / "static"},   # served at /static/dashboard/...
        nav=[("/", "Stations")],
        state={"store": store},                  # request.app.state.store
    )
    serve(app, host="127.0.0.1", port=8000, token=None)   # blocks until Ctrl-C

* :func:`create_app` -- the app factory: the base template and static files, ``/healthz``,
  one-line JSON errors (never a traceback), strict security headers (same-origin
  resources only), and the page's routes, templates, static folders and state.
* :func:`render` -- a template response with the app's title and navigation.
* :func:`serve` / :func:`start` -- run an app in the foreground or on a background thread
  (tests, a live page next to a running session). Both bind 127.0.0.1 by default and refuse
  any other address unless a token is given (:mod:`station.web.serve`).
* ``templates/base.html`` -- the page frame: ``{% block head %}``, ``{% block content %}``,
  ``{% block scripts %}``; a ``#device-errors`` list for one-line device errors.
* ``static/harp.css``, ``static/harp.js`` -- the look, and ``harp.poll``, ``harp.post``,
  ``harp.fmt``, ``harp.errors``, ``harp.chart.line`` / ``harp.chart.bars`` (canvas charts).
"""

from station.web.app import create_app, render
from station.web.serve import LOOPBACK_HOSTS, RunningServer, ServeError, check_bind, serve, start

__all__ = ["LOOPBACK_HOSTS", "RunningServer", "ServeError", "check_bind", "create_app", "render", "serve", "start"]
