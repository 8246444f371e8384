"""Read queries for the factory QA dashboard (issue 12 item 4), over one store connection.

They read only the indexed columns of ``profiles`` / ``lenses`` (no JSON is decoded), so they stay
fast on a store of many thousand profiles. A **calibration** is one session of one lens (its
profiles share ``session_dir``); its verdict is FAIL when any of its profiles failed QA, PASS when
every one passed, and *unjudged* otherwise. Days are UTC dates (``YYYY-MM-DD``) of the calibration's
first stored profile. Call them through :class:`station.store.ProfileStore`
(``store.lens_models()``, ``store.verdict_counts()``, ``store.model_trend()``,
``store.lens_history()``); :func:`control_limits` is plain arithmetic over their results.
"""

from __future__ import annotations

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
class LensSummary:
    """One lens (serial): how many profiles and calibrations the store holds, and its newest
    calibration's time (UTC), station and verdict (``"PASS"``, ``"FAIL"`` or None: not judged)."""

    lens_id: int
    maker: str
    model: str
    serial: str
    profiles: int
    calibrations: int
    last_at: str
    last_station: str
    last_verdict: str | None


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


@dataclass(frozen=True)
class ControlLimits:
    """Mean ± 3σ (sample standard deviation) of a figure over ``n`` passed lenses."""

    n: int
    mean: float
    sigma: float
    lower: float
    upper: float


def _calibrations(conn: sa.Connection, maker: str | None = None, model: str | None = None) -> list[sa.Row]:
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
    return list(conn.execute(q).all())


def _verdict(row: sa.Row) -> str:
    if row.failed:
        return "failed"
    return "passed" if row.passed == row.n else "unjudged"


def lens_models(conn: sa.Connection) -> list[LensModel]:
    """Every lens model with its number of lenses and of calibrations passed / failed / unjudged,
    by maker and model."""
    acc: dict[tuple[str, str], dict] = {}
    for r in _calibrations(conn):
        a = acc.setdefault((r.maker, r.model), {"lenses": set(), "passed": 0, "failed": 0, "unjudged": 0})
        a["lenses"].add(r.lens_id)
        a[_verdict(r)] += 1
    return [
        LensModel(
            mk, md, len(a["lenses"]), a["passed"] + a["failed"] + a["unjudged"], a["passed"], a["failed"], a["unjudged"]
        )
        for (mk, md), a in sorted(acc.items())
    ]


def lens_summaries(conn: sa.Connection, maker: str | None = None, model: str | None = None) -> list[LensSummary]:
    """Every lens (of one model) with its profile and calibration counts and its newest calibration,
    by maker, model, serial."""
    serials = {r.id: r.serial for r in conn.execute(sa.select(lenses.c.id, lenses.c.serial)).all()}
    acc: dict[int, dict] = {}
    for r in _calibrations(conn, maker, model):
        a = acc.setdefault(r.lens_id, {"row": r, "profiles": 0, "calibrations": 0})
        a["profiles"] += r.n
        a["calibrations"] += 1
        if (str(r.started), r.last_id) > (str(a["row"].started), a["row"].last_id):
            a["row"] = r
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
            )
        )
    return sorted(out, key=lambda s: (s.maker, s.model, s.serial))


def verdict_counts(conn: sa.Connection, maker: str | None = None, model: str | None = None) -> list[VerdictCount]:
    """Calibrations passed / failed / unjudged per (maker, model, station, day), sorted so; ``maker`` /
    ``model`` select one lens model."""
    acc: dict[tuple[str, str, str, str], dict[str, int]] = {}
    for r in _calibrations(conn, maker, model):
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
    return sorted(newest.values(), key=lambda t: (t.created_at, t.profile_id))


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
