"""The factory QA dashboard (``harp serve``): a read-only web app over the profile store.

Pages (HTML, Jinja templates extending ``base.html``) and the JSON endpoints that hold the same
data (:mod:`station.web.dashboard_data`):

=========================================  ==================================================
``/``, ``/api/lenses``                     lens models with lenses and calibrations passed /
                                           failed; pass/fail counts per station and day; lenses
                                           with their failure reason; ``?from=&to=&station=``
                                           show the calibrations of those days and station
``/lenses.csv``                            the lens list (same filters) as CSV
``/lenses/{serial}``, ``/api/lenses/...``  one lens: profiles per focus (newest first), verdict
                                           with every check, plots, downloads
``/api/profiles/{id}``                     one profile in full (model, merit, provenance, QA)
``/model?maker=&model=``, ``/api/model``   a lens model's distortion magnitude and holdout d
                                           over its serial numbers, control limits (mean ± 3σ
                                           of the passed lenses), spec limits (QA's)
``/profiles/{id}/field.png``               the field plot (session report's, else rendered)
``/profiles/{id}/uncertainty.png``         the field-uncertainty plot
``/profiles/{id}/export/{format}``         the profile in an export format (download); a
                                           profile that failed QA is refused (409) unless
                                           ``?allow-failed=1``: then logged, stamped FAILED QA
=========================================  ==================================================

A serial shared by several lens models takes ``?maker=...&model=...``. Files are found from what
the store holds for a profile, never from a path in the request (:mod:`station.web.profile_files`).
Only GET: nothing is written. Serve it with :func:`station.web.serve` (127.0.0.1 by default, a
token for any other address).
"""

from __future__ import annotations

from typing import Any
from urllib.parse import urlencode

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Route

from station.profile_choice import export_refusal, failed_line, lens_row
from station.store import StoreError
from station.store.engine import STORE_ANSWER_S
from station.web import create_app, render
from station.web import dashboard_data as data
from station.web.app import log
from station.web.charts import ChartPoint, SpecLimit, control_chart, verdict_bars
from station.web.profile_files import ProfileFiles, Served, Unavailable


def _store(request: Request) -> Any:
    return request.app.state.store


def _err(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": " ".join(message.split())}, status_code=status)


def _page_error(request: Request, status: int, message: str) -> Response:
    return render(request, "dashboard_error.html", status_code=status, message=" ".join(message.split()))


async def _call(fn: Any, *args: Any) -> Any:
    """Run ``fn(*args)`` on a worker thread (a plot or an export)."""
    return await run_in_threadpool(fn, *args)


async def _read(request: Request, fn: Any, *args: Any) -> Any:
    """``fn(store, *args)``, a read of the request's store, on a worker thread (the store's calls block); a
    :class:`~station.store.StoreError` (503) when it does not answer within the store's own bound of silence
    (:data:`station.store.engine.STORE_ANSWER_S`; the read under it then gives up and frees its thread and
    connection, the page does not wait for that: a read waiting for a new connection adds its connect timeout)."""
    import anyio.to_thread

    store = _store(request)
    with anyio.move_on_after(STORE_ANSWER_S):
        return await anyio.to_thread.run_sync(fn, store, *args, abandon_on_cancel=True)
    raise StoreError(
        f"{store.location}: the store did not answer within {STORE_ANSWER_S:g} s (its server stopped answering, "
        "or the network to it is down?); the dashboard serves again once it answers",
        kind="unreachable",
    )


def _profile(store: Any, profile_id: int) -> Any:
    return store.profile(profile_id)


def _lens_args(request: Request) -> tuple[str, str | None, str | None]:
    q = request.query_params
    return request.path_params["serial"], q.get("maker"), q.get("model")


def _lookup_status(exc: LookupError) -> int:
    return 409 if isinstance(exc, data.Ambiguous) else 404


def _store_error(exc: Exception) -> str | None:
    return " ".join(str(exc).split()) if isinstance(exc, StoreError) else None


# ------------------------------------------------------------------- JSON
async def _lenses(request: Request) -> dict[str, Any]:
    """The lens list of the request's filters (``?from=&to=&station=``); BadQuery for a bad one."""
    return dict(await _read(request, data.lenses_doc, data.window_of(request.query_params)))


async def api_lenses(request: Request) -> Response:
    try:
        return JSONResponse(await _lenses(request))
    except data.BadQuery as exc:
        return _err(400, str(exc))


async def lenses_csv(request: Request) -> Response:
    try:
        doc = await _lenses(request)
    except data.BadQuery as exc:
        return _err(400, str(exc))
    name = "-".join(["harp-lenses", *(str(v) for v in doc["filter"].values() if v)])
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    return Response(
        data.lenses_csv(doc),
        media_type="text/csv; charset=utf-8",
        headers={"content-disposition": f'attachment; filename="{safe}.csv"'},
    )


async def api_lens(request: Request) -> Response:
    try:
        return JSONResponse(await _read(request, data.lens_doc, *_lens_args(request)))
    except LookupError as exc:
        return _err(_lookup_status(exc), str(exc))


async def api_profile(request: Request) -> Response:
    try:
        return JSONResponse(await _read(request, data.profile_doc, request.path_params["profile_id"]))
    except LookupError as exc:
        return _err(_lookup_status(exc), str(exc))


async def api_model(request: Request) -> Response:
    q = request.query_params
    if not q.get("maker") or not q.get("model"):
        return _err(400, "give the lens model as ?maker=...&model=...")
    try:
        return JSONResponse(await _read(request, data.model_doc, q["maker"], q["model"]))
    except LookupError as exc:
        return _err(404, str(exc))


# ------------------------------------------------------------------ pages
async def index(request: Request) -> Response:
    try:
        doc = await _lenses(request)
    except data.BadQuery as exc:
        return _page_error(request, 400, str(exc))
    days: dict[str, list[int]] = {}
    for c in doc["counts"]:
        d = days.setdefault(c["day"], [0, 0, 0])
        d[0] += c["passed"]
        d[1] += c["failed"]
        d[2] += c["unjudged"]
    bars = verdict_bars([(d, *v) for d, v in sorted(days.items())])
    query = urlencode({k: v for k, v in doc["filter"].items() if v})
    return render(
        request, "dashboard_index.html", doc=doc, bars=bars, csv_href="/lenses.csv" + (f"?{query}" if query else "")
    )


async def lens_page(request: Request) -> Response:
    try:
        doc = await _read(request, data.lens_doc, *_lens_args(request))
    except LookupError as exc:
        return _page_error(request, _lookup_status(exc), str(exc))
    return render(request, "dashboard_lens.html", doc=doc)


def _charts(doc: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for f in doc["focus"]:
        charts = []
        for key, fig in f["figures"].items():
            lim = fig["limits"] or {}
            spec = fig["spec"]
            pts = [ChartPoint(p["serial"], p[key], p["verdict"], p["href"]) for p in f["points"]]
            charts.append(
                {
                    "key": key,
                    "label": fig["label"],
                    "limits": fig["limits"],
                    "spec": spec,
                    "outside": fig["outside"],
                    "svg": control_chart(
                        pts,
                        mean=lim.get("mean"),
                        lower=lim.get("lower"),
                        upper=lim.get("upper"),
                        spec=SpecLimit(spec["comparison"], tuple(spec["limits"])) if spec else None,
                        title=f"{fig['label']} at focus {f['focus']:g}",
                        css_id=f"chart-{key}-{len(out)}",
                    ),
                }
            )
        out.append({"focus": f["focus"], "charts": charts, "points": f["points"]})
    return out


async def model_page(request: Request) -> Response:
    q = request.query_params
    if not q.get("maker") or not q.get("model"):
        return _page_error(request, 400, "give the lens model as ?maker=...&model=...")
    try:
        doc = await _read(request, data.model_doc, q["maker"], q["model"])
    except LookupError as exc:
        return _page_error(request, 404, str(exc))
    bars = verdict_bars([(d["day"], d["passed"], d["failed"], d["unjudged"]) for d in doc["days"]])
    return render(request, "dashboard_model.html", doc=doc, focus=_charts(doc), bars=bars)


# ------------------------------------------------------------------ files
def _served(s: Served) -> Response:
    headers = {"cache-control": "private, max-age=60", "x-harp-source": s.source}
    if s.filename:
        headers["content-disposition"] = f'attachment; filename="{s.filename}"'
    if s.path is not None:
        return FileResponse(s.path, media_type=s.media_type, headers=headers)
    assert s.data is not None
    return Response(s.data, media_type=s.media_type, headers=headers)


def _export_refused(request: Request, profile: Any) -> Response | None:
    """409 for an export of a profile that failed QA (the rule of :func:`station.profile_choice.export_refusal`),
    unless ``?allow-failed=1``: then None, and a log line names the profile and the client."""
    lens = lens_row(profile)
    refusal = export_refusal(lens, profile, f"?{data.ALLOW_FAILED}=1")
    if refusal is None:
        return None
    if request.query_params.get(data.ALLOW_FAILED) != "1":
        return _err(409, refusal)
    client = f"{request.client.host}:{request.client.port}" if request.client else "unknown client"
    log.warning(
        "harp serve: %s: exported as %s to client %s because of ?%s=1 (the file is stamped FAILED QA)",
        failed_line(lens, profile),
        request.path_params["fmt"],
        client,
        data.ALLOW_FAILED,
    )
    return None


def _file_endpoint(what: str) -> Any:
    async def endpoint(request: Request) -> Response:
        files: ProfileFiles = request.app.state.files
        pid = request.path_params["profile_id"]
        profile = await _read(request, _profile, pid)
        if profile is None:
            return _err(404, f"no profile #{pid} in the store")
        try:
            if what == "field":
                s = await _call(files.field_plot, profile)
            elif what == "uncertainty":
                s = await _call(files.uncertainty_plot, profile)
            else:
                refused = _export_refused(request, profile)
                if refused is not None:
                    return refused
                s = await _call(files.export, profile, request.path_params["fmt"])
        except Unavailable as exc:
            return _err(404, str(exc))
        return _served(s)

    return endpoint


def dashboard_app(store: Any, *, title: str = "harp QA dashboard") -> Starlette:
    """The dashboard's app over an open :class:`station.store.ProfileStore` (read only)."""

    async def store_errors(request: Request, exc: Exception) -> Response:
        msg = _store_error(exc) or f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        if request.url.path.startswith("/api/") or "/profiles/" in request.url.path:
            return _err(503 if _store_error(exc) else 500, msg)
        return _page_error(request, 503 if _store_error(exc) else 500, msg)

    app = create_app(
        title,
        [
            Route("/", index),
            Route("/lenses.csv", lenses_csv),
            Route("/lenses/{serial:path}", lens_page),  # a serial may hold a '/' (sent as %2F)
            Route("/model", model_page),
            Route("/api/lenses", api_lenses),
            Route("/api/lenses/{serial:path}", api_lens),
            Route("/api/profiles/{profile_id:int}", api_profile),
            Route("/api/model", api_model),
            Route("/profiles/{profile_id:int}/field.png", _file_endpoint("field")),
            Route("/profiles/{profile_id:int}/uncertainty.png", _file_endpoint("uncertainty")),
            Route("/profiles/{profile_id:int}/export/{fmt}", _file_endpoint("export")),
        ],
        nav=[("/", "Lenses"), ("/api/lenses", "JSON")],
        state={"store": store, "files": ProfileFiles()},
    )
    app.add_exception_handler(StoreError, store_errors)
    return app
