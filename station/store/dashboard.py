"""Read queries for the factory QA dashboard (issue 12 item 4), over one store connection.

They read the indexed columns of ``profiles`` / ``lenses``, and decode a profile's QA record only
where a page shows what it holds (the failed checks of a lens's newest failed calibration, the
limits the newest profiles were judged with), so they stay fast on a store of many thousand
profiles. A **calibration** is one session of one lens (its
profiles share ``session_dir``); its verdict is FAIL when any of its profiles failed QA, PASS when
every one passed, and *unjudged* otherwise. Days are UTC dates (``YYYY-MM-DD``) of the calibration's
first stored profile. Call them through :class:`station.store.ProfileStore`
(``store.lens_models()``, ``store.verdict_counts()``, ``store.model_trend()``,
``store.lens_history()``); :func:`control_limits` is plain arithmetic over their results. A
:class:`Window` selects the calibrations of a date range and a station.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import sqlalchemy as sa

from station.store.schema import lenses, profiles


@dataclass(frozen=True)
class LensModel:
    """One lens model: how many lenses (serial numbers) and calibrations the store holds, and their verdicts."""

    maker: str
    model: str
    lenses: int
    calibrations: int
    passed: int
    failed: int
    unjudged: int


@dataclass(frozen=True)
class VerdictCount:
    """Calibrations of one lens model at one station on one day, by verdict."""

    maker: str
    model: str
    station: str
    day: str
    passed: int
    failed: int
    unjudged: int


@dataclass(frozen=True)
class Window:
    """Which calibrations a dashboard query counts: those whose day (UTC, ``YYYY-MM-DD``) lies in
    ``[since, until]`` (each end optional, inclusive) made at ``station`` (None: every station)."""

    since: str | None = None
    until: str | None = None
    station: str | None = None

    def holds(self, day: str, station: str) -> bool:
        return (
            (self.since is None or day >= self.since)
            and (self.until is None or day <= self.until)
            and (self.station is None or station == self.station)
        )


EVERYTHING = Window()
"""Every calibration."""


@dataclass(frozen=True)
class FailedCheck:
    """A QA check that failed: the focus setting of its profile, the check's name and its text
    (``"holdout d 0.0916 px > 0.05 px"``: value, comparison, limit)."""

    focus: float
    check: str
    text: str


@dataclass(frozen=True)
class LensSummary:
    """One lens (serial): how many profiles and calibrations the store holds, and its newest
    calibration's time (UTC), station and verdict (``"PASS"``, ``"FAIL"`` or None: not judged);
    ``failures`` the checks that failed in that calibration (by focus), empty unless it failed."""

    lens_id: int
    maker: str
    model: str
    serial: str
    profiles: int
    calibrations: int
    last_at: str
    last_station: str
    last_verdict: str | None
    failures: tuple[FailedCheck, ...] = ()


@dataclass(frozen=True)
class TrendPoint:
    """The newest profile of one lens (serial) at one focus setting: what the drift plots show (px)."""

    serial: str
    lens_id: int
    profile_id: int
    focus: float
    created_at: str
    station: str
    session_dir: str
    verdict: str | None
    distortion_max: float | None
    distortion_rms: float | None
    holdout_d: float | None
    holdout_d_max: float | None
    spec: tuple[tuple[str, str, float], ...] = ()
    """The QA limits it was judged with: ``(check, comparison, limit)`` of each judged check."""

    def limit(self, check: str) -> tuple[str, float] | None:
        """``(comparison, limit)`` of QA check ``check`` when it was judged, else None."""
        return next(((c, v) for name, c, v in self.spec if name == check), None)


@dataclass(frozen=True)
class ControlLimits:
    """Mean ± 3σ (sample standard deviation) of a figure over ``n`` passed lenses."""

    n: int
    mean: float
    sigma: float
    lower: float
    upper: float


def _calibrations(
    conn: sa.Connection, maker: str | None = None, model: str | None = None, window: Window = EVERYTHING
) -> list[sa.Row]:
    p, l = profiles, lenses
    failed = sa.func.sum(sa.case((p.c.verdict == "FAIL", 1), else_=0))
    passed = sa.func.sum(sa.case((p.c.verdict == "PASS", 1), else_=0))
    q = (
        sa.select(
            l.c.maker,
            l.c.model,
            p.c.lens_id,
            p.c.session_dir,
            p.c.station_id,
            sa.func.min(p.c.created_at).label("started"),
            sa.func.max(p.c.id).label("last_id"),
            failed.label("failed"),
            passed.label("passed"),
            sa.func.count().label("n"),
        )
        .select_from(p.join(l, l.c.id == p.c.lens_id))
        .group_by(l.c.maker, l.c.model, p.c.lens_id, p.c.session_dir, p.c.station_id)
    )
    if maker is not None:
        q = q.where(l.c.maker == maker)
    if model is not None:
        q = q.where(l.c.model == model)
    return [r for r in conn.execute(q).all() if window.holds(str(r.started)[:10], r.station_id)]


def _verdict(row: sa.Row) -> str:
    if row.failed:
        return "failed"
    return "passed" if row.passed == row.n else "unjudged"


def lens_models(conn: sa.Connection, window: Window = EVERYTHING) -> list[LensModel]:
    """Every lens model with its number of lenses and of calibrations passed / failed / unjudged
    (in ``window``), by maker and model."""
    acc: dict[tuple[str, str], dict] = {}
    for r in _calibrations(conn, window=window):
        a = acc.setdefault((r.maker, r.model), {"lenses": set(), "passed": 0, "failed": 0, "unjudged": 0})
        a["lenses"].add(r.lens_id)
        a[_verdict(r)] += 1
    return [
        LensModel(
            mk, md, len(a["lenses"]), a["passed"] + a["failed"] + a["unjudged"], a["passed"], a["failed"], a["unjudged"]
        )
        for (mk, md), a in sorted(acc.items())
    ]


def lens_summaries(
    conn: sa.Connection, maker: str | None = None, model: str | None = None, window: Window = EVERYTHING
) -> list[LensSummary]:
    """Every lens (of one model) calibrated in ``window`` with its profile and calibration counts
    there and its newest calibration there (with the checks that failed in it), by maker, model,
    serial."""
    serials = {r.id: r.serial for r in conn.execute(sa.select(lenses.c.id, lenses.c.serial)).all()}
    acc: dict[int, dict] = {}
    for r in _calibrations(conn, maker, model, window):
        a = acc.setdefault(r.lens_id, {"row": r, "profiles": 0, "calibrations": 0})
        a["profiles"] += r.n
        a["calibrations"] += 1
        if (str(r.started), r.last_id) > (str(a["row"].started), a["row"].last_id):
            a["row"] = r
    failed = _failed_checks(conn, [(lid, a["row"].session_dir) for lid, a in acc.items() if a["row"].failed])
    out = []
    for lid, a in acc.items():
        r = a["row"]
        v = _verdict(r)
        verdict = "FAIL" if v == "failed" else "PASS" if v == "passed" else None
        out.append(
            LensSummary(
                lid,
                r.maker,
                r.model,
                serials[lid],
                a["profiles"],
                a["calibrations"],
                str(r.started),
                r.station_id,
                verdict,
                failed.get((lid, r.session_dir), ()),
            )
        )
    return sorted(out, key=lambda s: (s.maker, s.model, s.serial))


def _qa_record(text: str | None) -> dict:
    """A profile's stored QA record (``qa_json``), ``{}`` when absent or unreadable (the lens page
    names an unreadable row; a summary does not fail on it)."""
    try:
        got = json.loads(text) if text else {}
    except (TypeError, ValueError):
        return {}
    return got if isinstance(got, dict) else {}


def _checks(record: dict) -> list[dict]:
    checks = record.get("checks")
    return [c for c in checks if isinstance(c, dict)] if isinstance(checks, list) else []


def _failed_checks(
    conn: sa.Connection, calibrations: Sequence[tuple[int, str]]
) -> dict[tuple[int, str], tuple[FailedCheck, ...]]:
    """The failed checks of the FAIL profiles of each ``(lens_id, session_dir)`` calibration, by focus."""
    out: dict[tuple[int, str], list[FailedCheck]] = {}
    wanted = set(calibrations)
    ids = sorted({lid for lid, _ in wanted})
    for i in range(0, len(ids), 500):
        q = (
            sa.select(profiles.c.lens_id, profiles.c.session_dir, profiles.c.focus, profiles.c.qa_json)
            .where(profiles.c.verdict == "FAIL", profiles.c.lens_id.in_(ids[i : i + 500]))
            .order_by(profiles.c.focus)
        )
        for r in conn.execute(q).all():
            key = (r.lens_id, r.session_dir)
            if key not in wanted:
                continue
            for c in _checks(_qa_record(r.qa_json)):
                if c.get("passed") is False:
                    text = str(c.get("text", "")).removesuffix(": FAIL")
                    out.setdefault(key, []).append(FailedCheck(float(r.focus), str(c.get("name", "")), text))
    return {k: tuple(v) for k, v in out.items()}


def verdict_counts(
    conn: sa.Connection, maker: str | None = None, model: str | None = None, window: Window = EVERYTHING
) -> list[VerdictCount]:
    """Calibrations passed / failed / unjudged per (maker, model, station, day), sorted so; ``maker`` /
    ``model`` select one lens model, ``window`` the days and station."""
    acc: dict[tuple[str, str, str, str], dict[str, int]] = {}
    for r in _calibrations(conn, maker, model, window):
        key = (r.maker, r.model, r.station_id, str(r.started)[:10])
        a = acc.setdefault(key, {"passed": 0, "failed": 0, "unjudged": 0})
        a[_verdict(r)] += 1
    return [VerdictCount(*k, a["passed"], a["failed"], a["unjudged"]) for k, a in sorted(acc.items())]


def model_trend(conn: sa.Connection, maker: str, model: str, focus: float | None = None) -> list[TrendPoint]:
    """For each lens (serial) of one model and each focus setting (or only ``focus``), its newest
    profile's distortion magnitude, holdout d and verdict — oldest calibration first, so that the
    points follow the serial numbers as they were calibrated (a supplier's drift)."""
    p, l = profiles, lenses
    q = (
        sa.select(
            l.c.serial,
            p.c.lens_id,
            p.c.id,
            p.c.focus,
            p.c.created_at,
            p.c.station_id,
            p.c.session_dir,
            p.c.verdict,
            p.c.distortion_max,
            p.c.distortion_rms,
            p.c.holdout_d,
            p.c.holdout_d_max,
        )
        .select_from(p.join(l, l.c.id == p.c.lens_id))
        .where(l.c.maker == maker, l.c.model == model)
        .order_by(p.c.lens_id, p.c.focus, p.c.created_at.desc(), p.c.id.desc())
    )
    if focus is not None:
        q = q.where(p.c.focus.between(focus - 1e-9, focus + 1e-9))
    newest: dict[tuple[int, float], TrendPoint] = {}
    for r in conn.execute(q).all():
        key = (r.lens_id, r.focus)
        if key not in newest:
            newest[key] = TrendPoint(
                r.serial,
                r.lens_id,
                r.id,
                r.focus,
                r.created_at,
                r.station_id,
                r.session_dir,
                r.verdict,
                r.distortion_max,
                r.distortion_rms,
                r.holdout_d,
                r.holdout_d_max,
            )
    spec = _judged_limits(conn, [t.profile_id for t in newest.values()])
    points = [dataclasses.replace(t, spec=spec.get(t.profile_id, ())) for t in newest.values()]
    return sorted(points, key=lambda t: (t.created_at, t.profile_id))


def _judged_limits(conn: sa.Connection, ids: Sequence[int]) -> dict[int, tuple[tuple[str, str, float], ...]]:
    """``(check, comparison, limit)`` of every judged check of each profile, from its QA record."""
    out: dict[int, tuple[tuple[str, str, float], ...]] = {}
    ids = sorted(ids)
    for i in range(0, len(ids), 500):
        q = sa.select(profiles.c.id, profiles.c.qa_json).where(profiles.c.id.in_(ids[i : i + 500]))
        for r in conn.execute(q).all():
            got = []
            for c in _checks(_qa_record(r.qa_json)):
                lim = c.get("limit")
                judged = isinstance(c.get("passed"), bool)
                if judged and isinstance(lim, (int, float)) and not isinstance(lim, bool) and math.isfinite(lim):
                    got.append((str(c.get("name", "")), str(c.get("comparison", "")), float(lim)))
            out[r.id] = tuple(got)
    return out


def control_limits(points: Iterable[TrendPoint], figure: str = "holdout_d") -> ControlLimits | None:
    """Mean ± 3σ of ``figure`` (``"holdout_d"``, ``"distortion_max"``, ...) over the points that
    PASSED; None with fewer than two finite values."""
    values: Sequence[float] = [
        float(v) for t in points if t.verdict == "PASS" and (v := getattr(t, figure)) is not None and math.isfinite(v)
    ]
    n = len(values)
    if n < 2:
        return None
    mean = sum(values) / n
    sigma = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    return ControlLimits(n, mean, sigma, mean - 3 * sigma, mean + 3 * sigma)
