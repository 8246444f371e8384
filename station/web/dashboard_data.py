"""What the QA dashboard shows, as plain JSON-able data read from the profile store.

One function per page, each the body of its JSON endpoint too (so the page and ``/api/...`` never
disagree): :func:`lenses_doc` (``/`` and ``/api/lenses``), :func:`lens_doc` (``/lenses/{serial}``
and ``/api/lenses/{serial}``), :func:`profile_doc` (``/api/profiles/{id}``), :func:`model_doc`
(``/model`` and ``/api/model``). They only read (:class:`station.store.ProfileStore` opened for
reading) through the store's dashboard queries (:mod:`station.store.dashboard`). A name that
is not in the store is :class:`NotFound` (404), an ambiguous serial :class:`Ambiguous` (409),
both with a one-line message.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any
from urllib.parse import quote, urlencode

from pipeline.plain import finite_or_none
from station.profile import Profile
from station.profile_choice import is_failed

ALLOW_FAILED = "allow-failed"
"""The query parameter that makes the dashboard serve an export of a profile that failed QA."""


class NotFound(LookupError):
    """Nothing of that name in the store (HTTP 404).

    Not a HarpError: the dashboard's lookups are answered as HTTP errors by :mod:`station.web.dashboard`
    (this one 404); no command raises it."""


class Ambiguous(LookupError):
    """A serial number shared by lenses of several models (HTTP 409).

    Not a HarpError: answered as HTTP 409 by :mod:`station.web.dashboard`; no command raises it."""


def lens_href(serial: str, maker: str | None = None, model: str | None = None, api: bool = False) -> str:
    q = f"?{urlencode({'maker': maker, 'model': model})}" if maker is not None and model is not None else ""
    return f"{'/api' if api else ''}/lenses/{quote(serial, safe='')}{q}"


def model_href(maker: str, model: str, api: bool = False) -> str:
    return f"{'/api' if api else ''}/model?{urlencode({'maker': maker, 'model': model})}"


# ------------------------------------------------------------ lenses page
class BadQuery(ValueError):
    """A query parameter that is not what it must be (HTTP 400); one line.

    Not a HarpError: answered as HTTP 400 by :mod:`station.web.dashboard`; no command raises it."""


FILTERS = (("from", "since"), ("to", "until"), ("station", "station"))
"""The lens list's query parameters and the :class:`station.store.dashboard.Window` fields they set."""


def window_of(query: Mapping[str, str]) -> Any:
    """The :class:`station.store.dashboard.Window` of a lens-list query: ``from`` / ``to`` (UTC days
    ``YYYY-MM-DD``, inclusive) and ``station``; empty values are absent. :class:`BadQuery` otherwise."""
    import datetime as dt

    from station.store.dashboard import Window  # defers sqlalchemy

    kw: dict[str, str | None] = {}
    for param, name in FILTERS:
        v = (query.get(param) or "").strip() or None
        if v is not None and param != "station":
            try:
                v = dt.date.fromisoformat(v).isoformat()
            except ValueError:
                raise BadQuery(f"?{param}= must be a day as YYYY-MM-DD, got {v!r}") from None
        kw[name] = v
    if kw["since"] and kw["until"] and kw["since"] > kw["until"]:
        raise BadQuery(f"?from={kw['since']} is after ?to={kw['until']}")
    return Window(**kw)


def failure_text(failures: Any) -> str:
    """The failure reason of a lens list row: each failed check's text with the focus settings it
    failed at, e.g. ``"focus 0: holdout d 0.0916 px > 0.05 px; focus 1: ..."``."""
    return "; ".join(f"focus {f.focus:g}: {f.text}" for f in failures)


def lenses_doc(store: Any, window: Any = None) -> dict[str, Any]:
    """Every lens model with its lenses and calibrations passed / failed, the counts per station
    and day, and every lens with its newest calibration's verdict and failure reason — of the
    calibrations in ``window`` (:func:`window_of`; None: all), with every station of the store."""
    from station.store.dashboard import EVERYTHING  # defers sqlalchemy

    window = EVERYTHING if window is None else window
    models = [
        {
            "maker": m.maker,
            "model": m.model,
            "lenses": m.lenses,
            "calibrations": m.calibrations,
            "passed": m.passed,
            "failed": m.failed,
            "unjudged": m.unjudged,
            "href": model_href(m.maker, m.model),
            "api": model_href(m.maker, m.model, api=True),
        }
        for m in store.lens_models(window)
    ]
    counts = [
        {
            "maker": c.maker,
            "model": c.model,
            "station": c.station,
            "day": c.day,
            "passed": c.passed,
            "failed": c.failed,
            "unjudged": c.unjudged,
        }
        for c in store.verdict_counts(window=window)
    ]
    stations = sorted({c.station for c in store.verdict_counts()})
    lenses = []
    shared = _shared_serials(store)
    for s in store.lens_summaries(window=window):
        qual = s.serial in shared
        lenses.append(
            {
                "id": s.lens_id,
                "maker": s.maker,
                "model": s.model,
                "serial": s.serial,
                "profiles": s.profiles,
                "calibrations": s.calibrations,
                "last_calibrated": s.last_at,
                "last_station": s.last_station,
                "last_verdict": s.last_verdict or "unjudged",
                "failure": failure_text(s.failures),
                "failed_checks": [{"focus": f.focus, "check": f.check, "text": f.text} for f in s.failures],
                "href": lens_href(s.serial, s.maker if qual else None, s.model if qual else None),
                "api": lens_href(s.serial, s.maker if qual else None, s.model if qual else None, api=True),
            }
        )
    return {
        "store": str(store.location),
        "filter": {param: getattr(window, name) for param, name in FILTERS},
        "stations": stations,
        "models": models,
        "counts": counts,
        "lenses": lenses,
    }


CSV_COLUMNS = (
    ("serial", "serial"),
    ("maker", "maker"),
    ("model", "model"),
    ("calibrations", "calibrations"),
    ("profiles", "profiles"),
    ("last_calibrated_utc", "last_calibrated"),
    ("station", "last_station"),
    ("verdict", "last_verdict"),
    ("failure_reason", "failure"),
)
"""The lens list's CSV: header and the :func:`lenses_doc` lens field of each column."""


def lenses_csv(doc: Mapping[str, Any]) -> str:
    """The lens list of a :func:`lenses_doc` as CSV (RFC 4180: a header row, CRLF line ends)."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([name for name, _ in CSV_COLUMNS])
    for lens in doc["lenses"]:
        w.writerow([lens[key] for _, key in CSV_COLUMNS])
    return buf.getvalue()


def _shared_serials(store: Any) -> set[str]:
    seen: dict[str, int] = {}
    for _id, _mk, _md, serial in store.lenses():
        seen[serial] = seen.get(serial, 0) + 1
    return {s for s, n in seen.items() if n > 1}


def find_lens(store: Any, serial: str, maker: str | None = None, model: str | None = None) -> tuple[int, str, str, str]:
    """The lens with this exact serial number (and maker / model, when given)."""
    hits = [
        l
        for l in store.lenses()
        if l[3] == serial and (maker is None or l[1] == maker) and (model is None or l[2] == model)
    ]
    if not hits:
        raise NotFound(f"no lens with serial {serial!r} in the store")
    if len(hits) > 1:
        names = "; ".join(f"{l[1]} {l[2]}" for l in hits)
        raise Ambiguous(f"serial {serial!r} is used by {len(hits)} lens models ({names}): add ?maker=...&model=...")
    return hits[0]


# -------------------------------------------------------------- one lens
def profile_summary(p: Profile, *, current: bool = False) -> dict[str, Any]:
    """What the lens page shows of one profile: figures, verdict with every check, plots, downloads.

    A profile that failed QA has no ``downloads``: its exports are listed in ``downloads_failed_qa``,
    each URL with ``?allow-failed=1`` (the export then says FAILED QA in the file, and the server logs it)."""
    from pipeline.exports.registry import FORMATS  # defers scipy

    m = p.merit
    unc = m.field_uncertainty
    qa = p.qa
    prov = p.provenance
    reprocess = prov.extra.get("reprocess") if isinstance(prov.extra, Mapping) else None
    assert p.id is not None
    failed = is_failed(p)  # a failed profile is not offered: only a deliberate download, stamped FAILED QA
    query = f"?{ALLOW_FAILED}=1" if failed else ""
    files = [
        {"format": name, "summary": fmt.summary, "url": f"/profiles/{p.id}/export/{name}{query}"}
        for name, fmt in FORMATS.items()
    ]
    return {
        "id": p.id,
        "focus": p.focus,
        "current": current,
        "stored_at": p.stored_at,
        "created_utc": prov.created_utc,
        "station": prov.station,
        "session_dir": prov.session_dir,
        "software": prov.software,
        "command": prov.command,
        "reprocessed": dict(reprocess) if isinstance(reprocess, Mapping) else None,
        "model": p.spec.label if p.spec is not None else p.model.name,
        "image_size": [p.width, p.height],
        "figures": {
            "before_d_px": finite_or_none(m.before.d) if m.before else None,
            "fit_d_px": finite_or_none(m.fit.d) if m.fit else None,
            "fit_d_max_px": finite_or_none(m.fit.d_max) if m.fit else None,
            "holdout_d_px": finite_or_none(m.holdout.d) if m.holdout else None,
            "holdout_d_max_px": finite_or_none(m.holdout.d_max) if m.holdout else None,
            "holdout_scheme": m.holdout.scheme if m.holdout else None,
            "field_uncertainty_rms_px": finite_or_none(unc.rms) if unc else None,
            "field_uncertainty_max_px": finite_or_none(unc.max) if unc else None,
            "distortion_max_px": finite_or_none(qa.metrics.get("distortion_max_px")) if qa else None,
            "distortion_rms_px": finite_or_none(qa.metrics.get("distortion_rms_px")) if qa else None,
        },
        "verdict": qa.verdict if qa is not None else None,
        "reasons": list(qa.reasons) if qa is not None else [],
        "checks": [c.to_dict() for c in qa.checks] if qa is not None else [],
        "thresholds": dict(qa.thresholds) if qa is not None else {},
        "plots": {"field": f"/profiles/{p.id}/field.png", "uncertainty": f"/profiles/{p.id}/uncertainty.png"},
        "downloads": [] if failed else files,
        "downloads_failed_qa": files if failed else [],
        "api": f"/api/profiles/{p.id}",
    }


def lens_doc(store: Any, serial: str, maker: str | None = None, model: str | None = None) -> dict[str, Any]:
    """One lens: every profile per focus setting (newest first; ``current`` marks the one exports
    and QA use), each with its verdict, every check, plots and downloads. Unreadable rows are
    listed in ``errors`` (one line each), the others shown."""
    lens_id, mk, md, sn = find_lens(store, serial, maker, model)
    errors: list[Any] = []
    history = store.lens_history(lens_id, errors=errors)
    current = {p.id for p in store.latest_by_focus(lens_id)} if history else set()
    focus = [
        {"focus": f, "profiles": [profile_summary(p, current=p.id in current) for p in history[f]]}
        for f in sorted(history)
    ]
    return {
        "id": lens_id,
        "maker": mk,
        "model": md,
        "serial": sn,
        "model_href": model_href(mk, md),
        "focus": focus,
        "errors": [" ".join(str(e).split()) for e in errors],
    }


def profile_doc(store: Any, profile_id: int) -> dict[str, Any]:
    """One profile in full: the summary of the lens page plus the model, merit, provenance and details."""
    p = store.profile(int(profile_id))
    if p is None:
        raise NotFound(f"no profile #{profile_id} in the store")
    mf = p.to_model_file()
    lens = p.lens
    current = store.current_profile(_lens_id(store, p), p.focus) if lens is not None and p.focus is not None else None
    return {
        **profile_summary(p, current=current is not None and current.id == p.id),
        "lens": {"maker": lens.maker, "model": lens.model, "serial": lens.serial} if lens else None,
        "lens_href": lens_href(lens.serial, lens.maker, lens.model) if lens else None,
        "camera": {"maker": p.camera.maker, "model": p.camera.model, "serial": p.camera.serial} if p.camera else None,
        "distortion_model": p.model.to_dict(),
        "spec": p.spec.to_dict() if p.spec is not None else None,
        "merit": mf.merit,
        "provenance": mf.provenance,
        "details": dict(p.details),
    }


def _lens_id(store: Any, p: Profile) -> int:
    assert p.lens is not None
    return find_lens(store, p.lens.serial, p.lens.maker, p.lens.model)[0]


# ------------------------------------------------------------ lens model
FIGURES = (
    ("distortion_max", "distortion magnitude (largest correction, modulo homography)"),
    ("holdout_d", "holdout d"),
)


def model_doc(store: Any, maker: str, model: str) -> dict[str, Any]:
    """A lens model's drift: per focus setting, each lens's newest distortion magnitude and holdout
    d in calibration order, with control limits (mean ± 3σ of the lenses that passed) and the
    spec limits (the QA limits those profiles were judged with: ``spec`` = comparison and every
    distinct limit, None when the check was not judged)."""
    from station.store.dashboard import control_limits  # defers sqlalchemy

    points = store.model_trend(maker, model)
    if not points and not any(m.maker == maker and m.model == model for m in store.lens_models()):
        raise NotFound(f"no lens model {maker!r} {model!r} in the store")
    by_focus: dict[float, list[Any]] = {}
    for t in points:
        by_focus.setdefault(t.focus, []).append(t)
    shared = _shared_serials(store)
    out = []
    for f in sorted(by_focus):
        pts = by_focus[f]
        figures = {}
        for key, label in FIGURES:
            lim = control_limits(pts, key)
            judged = [got for t in pts if (got := t.limit(key)) is not None]
            figures[key] = {
                "label": label,
                "spec": None if not judged else {"comparison": judged[0][0], "limits": sorted({v for _c, v in judged})},
                "limits": None
                if lim is None
                else {"n": lim.n, "mean": lim.mean, "sigma": lim.sigma, "lower": lim.lower, "upper": lim.upper},
                "outside": [
                    t.serial
                    for t in pts
                    if lim is not None
                    and (v := finite_or_none(getattr(t, key))) is not None
                    and not lim.lower <= v <= lim.upper
                ],
            }
        out.append(
            {
                "focus": f,
                "figures": figures,
                "points": [
                    {
                        "serial": t.serial,
                        "profile_id": t.profile_id,
                        "created_at": t.created_at,
                        "station": t.station,
                        "verdict": t.verdict,
                        "distortion_max": finite_or_none(t.distortion_max),
                        "holdout_d": finite_or_none(t.holdout_d),
                        "href": lens_href(
                            t.serial, maker if t.serial in shared else None, model if t.serial in shared else None
                        ),
                    }
                    for t in pts
                ],
            }
        )
    counts = [c for c in store.verdict_counts(maker, model)]
    days: dict[str, list[int]] = {}
    for c in counts:
        d = days.setdefault(c.day, [0, 0, 0])
        d[0] += c.passed
        d[1] += c.failed
        d[2] += c.unjudged
    return {
        "maker": maker,
        "model": model,
        "focus": out,
        "days": [{"day": d, "passed": v[0], "failed": v[1], "unjudged": v[2]} for d, v in sorted(days.items())],
        "stations": [
            {"station": c.station, "day": c.day, "passed": c.passed, "failed": c.failed, "unjudged": c.unjudged}
            for c in counts
        ],
    }
