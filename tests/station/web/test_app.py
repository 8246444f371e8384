"""station.web, the base of every station page, over real HTTP (uvicorn on 127.0.0.1)."""

from __future__ import annotations

import http.client
import json
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route

from station.web import ServeError, check_bind, create_app, render, start


def _page_app(tmp_path: Path):
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "page.html").write_text(
        '{% extends "base.html" %}{% block content %}<p id="who">{{ who }}</p>{% endblock %}'
    )
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "page.js").write_text("window.page = 1;\n")

    async def index(request: Request) -> Response:
        return render(request, "page.html", who=request.app.state.who)

    async def boom(request: Request) -> Response:
        raise RuntimeError("the store is gone\nsecond line")

    return create_app(
        "a test page",
        [Route("/", index), Route("/boom", boom)],
        templates=[tmp_path / "t"],
        static={"page": tmp_path / "s"},
        nav=[("/", "Home")],
        state={"who": "dashboard <b>"},
    )


def _get(url: str, headers: dict | None = None):
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()


def test_app_factory_pages_static_and_errors(tmp_path):
    with start(_page_app(tmp_path)) as srv:
        status, headers, body = _get(srv.base)
        html = body.decode()
        assert status == 200 and '<p id="who">dashboard &lt;b&gt;</p>' in html  # autoescaped
        assert "<title>a test page</title>" in html and '<a href="/">Home</a>' in html
        assert "default-src 'self'" in headers["content-security-policy"]  # nothing from the internet
        assert "http://" not in html.replace(srv.base, "") and "https://" not in html
        assert _get(srv.base + "static/base/harp.js")[0] == 200
        assert _get(srv.base + "static/page/page.js")[2] == b"window.page = 1;\n"
        assert json.loads(_get(srv.base + "healthz")[2]) == {"ok": True, "title": "a test page"}
        status, _, body = _get(srv.base + "boom")
        assert status == 500 and json.loads(body) == {"error": "RuntimeError: the store is gone second line"}


def test_token_gate(tmp_path):
    with start(_page_app(tmp_path), token="s3cret-token") as srv:
        assert srv.url.endswith("/?token=s3cret-token")
        status, _, body = _get(srv.base)
        assert status == 401 and body.startswith(b"401: this page needs its token")
        assert _get(srv.base + "healthz", {"Authorization": "Bearer wrong"})[0] == 401
        assert _get(srv.base + "healthz", {"Authorization": "Bearer s3cret-token"})[0] == 200
        conn = http.client.HTTPConnection(srv.host, srv.port, timeout=10)
        conn.request("GET", "/?x=1&token=s3cret-token")
        r = conn.getresponse()
        r.read()
        assert r.status == 303 and r.getheader("location") == "/?x=1"
        cookie = r.getheader("set-cookie")
        assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
        assert _get(srv.base + "?x=1", {"Cookie": cookie.split(";")[0]})[0] == 200
        assert _get(srv.base, {"Cookie": "harp_token=nope"})[0] == 401


def test_binding_rules():
    check_bind("127.0.0.1", None)
    check_bind("::1", None)
    check_bind("0.0.0.0", "long-random-token")
    with pytest.raises(ServeError, match="give a token"):
        check_bind("0.0.0.0", None)
    with pytest.raises(ServeError, match="empty"):
        check_bind("127.0.0.1", "  ")
    with pytest.raises(ServeError, match="give a token"):
        start(create_app("x", []), host="0.0.0.0")


def test_a_port_in_use_is_one_line(tmp_path):
    with start(create_app("x", [])) as srv:
        with pytest.raises(ServeError) as err:
            start(create_app("y", []), port=srv.port)
        assert f"cannot listen on 127.0.0.1:{srv.port}" in str(err.value) and "\n" not in str(err.value)


def test_importing_the_cli_does_not_import_the_web_stack():
    import subprocess
    import sys

    code = "import sys, station.cli.live, station.live.checks; print(any(m.split('.')[0] in ('starlette', 'uvicorn', 'jinja2') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
