"""The profile store: :class:`ProfileStore`, one connection to a SQLite file or a PostgreSQL database.

Opening
    ``ProfileStore(where, create=True)`` opens for **writing**: creates the file (and its
    directory) or the tables if missing, migrates an older store in place
    (:mod:`station.store.migrate`) and checks its integrity
    (:func:`~station.store.migrate.check_integrity`: ``PRAGMA quick_check`` on SQLite) before
    anything is written. ``create=False`` opens for **reading**: a store that is not there is an
    error (``StoreError``, ``kind="missing"``), never an empty store created as a side effect.
    ``where`` is a path, a URL or a :class:`~station.store.location.StoreLocation`.
    ``on_wait`` is told one line when a write (a migration on opening included) has waited a moment
    for other writers (:func:`station.store.engine.write`): the command says it; the store prints nothing.
    ``upgrade=False`` (with ``create=False``: what must write nothing, ``harp reprocess --dry-run``)
    refuses an older store (``kind="older"``) instead of upgrading it.

Writing — each call is one transaction, all or nothing, retried while other writers hold the
store (:func:`station.store.engine.write`)
    :meth:`put_profile` stores a profile with its lens and camera rows and, when the profile
    carries its QA verdict (``profile.qa``), the verdict with its thresholds and every check, and
    the session's ``qa_results`` row — together or not at all. :meth:`record_verdict` keeps the
    verdict of a profile already stored (and replaces the session's ``qa_results`` row: once per
    profile, however often a session is resumed). :meth:`put_qa_result` adds one row of QA
    history (a run of ``harp qa``), once per ``key``: the same run recorded again adds nothing.

Reading (for the commands)
    :meth:`profile` (by id), :meth:`profiles` (every profile, failed ones included: listings),
    :meth:`lenses`, :meth:`find_lens`, and the **current** profiles: :meth:`latest_by_focus` /
    :meth:`current_profile` — the newest profile of each focus setting, where a focus whose newest
    profile FAILED QA has no current profile (an older passing profile does not stand in for it)
    unless ``allow_failed=True``; :meth:`qa_results`.

Reading (for the factory dashboard, :mod:`station.store.dashboard`)
    :meth:`lens_models`, :meth:`verdict_counts`, :meth:`lens_summaries`, :meth:`lens_history`,
    :meth:`model_trend`.

A row that cannot be read (bad JSON, a model without a centre, a profile whose lens row is
missing) raises a one-line StoreError (``kind="damaged"``) naming the store, the profile and what
to do; listings pass ``errors=[]`` to get the readable rows and the errors of the others.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import sqlalchemy as sa

from pipeline.plain import finite_or_none, plain
from station.store import dashboard
from station.store.engine import damaged_hint, make_engine, read, translate, write
from station.store.errors import StoreError
from station.store.location import POSTGRESQL, SQLITE, StoreLocation, parse_store
from station.store.migrate import check_integrity, ensure_schema
from station.store.schema import cameras, lenses, profiles, qa_results

if TYPE_CHECKING:
    from pipeline.intrinsics import Intrinsics
    from station.profile import Profile, Verdict

#: the columns a profile row is written with (:meth:`station.profile.Profile.to_row`, ids resolved)
PROFILE_COLUMNS = (
    "lens_id",
    "camera_id",
    "focus",
    "model_name",
    "model_json",
    "width",
    "height",
    "fit_d",
    "fit_d_max",
    "holdout_d",
    "holdout_d_max",
    "field_uncertainty_rms",
    "field_uncertainty_max",
    "session_dir",
    "station_id",
    "software_version",
    "created_at",
    "details_json",
    "spec_json",
    "selection_json",
    "merit_json",
    "provenance_json",
    "qa_json",
    "verdict",
    "distortion_max",
    "distortion_rms",
    "intrinsics_json",
    "focal",
)

FOCUS_TOL = 1e-9
"""Two focus settings closer than this are the same setting."""


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _iso_utc(text: str) -> str:
    """``text`` (ISO 8601; naive means UTC) as the store writes times: UTC, to the second."""
    try:
        t = _dt.datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError:
        raise StoreError(f"cannot store the profile: stored_at {text!r} is not an ISO 8601 time") from None
    t = t.replace(tzinfo=_dt.UTC) if t.tzinfo is None else t.astimezone(_dt.UTC)
    return t.isoformat(timespec="seconds")


_OTHER_STORE = (
    " (the session stored its profiles in another store: give that one with --store, or leave --store out for "
    "its configuration's)"
)
"""What to do when a session's recorded profile id is not its profile in this store (:meth:`ProfileStore.record_verdict`)."""

_ID_LIMIT = {SQLITE: 2**63, POSTGRESQL: 2**31}
"""The ids a row can have are within ``[-limit, limit)``: SQLite's 64-bit integers, PostgreSQL's ``integer``
(``sa.Integer``, :mod:`station.store.schema`)."""


def _insert(backend: str):
    if backend == POSTGRESQL:
        from sqlalchemy.dialects.postgresql import insert
    else:
        from sqlalchemy.dialects.sqlite import insert
    return insert


class ProfileStore:
    """A connection to the profile store at ``where`` (see the module docstring)."""

    def __init__(
        self,
        where: str | os.PathLike[str] | StoreLocation,
        *,
        create: bool = True,
        on_wait: Callable[[str], None] | None = None,
        upgrade: bool = True,
    ):
        self.location = where if isinstance(where, StoreLocation) else parse_store(where)
        self.on_wait = on_wait
        """Told when a write waits for other writers (the module docstring)."""
        loc = self.location
        self.path: Path | str = loc.path if loc.backend == SQLITE and loc.path is not None else str(loc)
        """The file of a SQLite store; the URL (without password) of a PostgreSQL one."""
        if loc.backend == SQLITE:
            assert loc.path is not None
            if not create:
                if not loc.path.is_file():
                    raise StoreError(f"{loc.path}: no profile store here; name one with --store or --config", "missing")
                if loc.path.stat().st_size == 0:
                    raise StoreError(f"{loc.path}: empty file, not a profile store", "missing")
            else:
                blocker = next((p for p in loc.path.parents if p.exists() and not p.is_dir()), None)
                if blocker is not None:
                    raise StoreError(f"{loc.path}: cannot open profile store: {blocker} is a file, not a directory")
                if loc.path.is_dir():
                    raise StoreError(f"{loc.path}: cannot open profile store: is a directory")
                try:
                    loc.path.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise StoreError(f"{loc.path}: cannot open profile store: {exc.strerror or exc}") from None
        self.engine = make_engine(loc)
        try:
            ensure_schema(self.engine, loc, create=create, on_wait=on_wait, upgrade=upgrade)
            if create:
                check_integrity(self.engine, loc)
        except StoreError:
            self.engine.dispose()
            raise
        except Exception as exc:  # a driver error outside a transaction (connecting): one line
            self.engine.dispose()
            raise translate(exc, loc, "opening the store") from None

    @property
    def backend(self) -> str:
        """``"sqlite"`` or ``"postgresql"``."""
        return self.location.backend

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> ProfileStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _read(self, what: str, fn: Callable[[sa.Connection], Any]) -> Any:
        return read(self.engine, self.location, what, fn)

    def _write(self, what: str, fn: Callable[[sa.Connection], Any]) -> Any:
        return write(self.engine, self.location, what, fn, on_wait=self.on_wait)

    # ============================================================ writes
    def _ident(self, conn: sa.Connection, table: sa.Table, ident: tuple[str, str, str]) -> int:
        values = dict(zip(("maker", "model", "serial"), (str(x) for x in ident)))
        conn.execute(_insert(self.backend)(table).values(values).on_conflict_do_nothing())
        return int(
            conn.execute(sa.select(table.c.id).where(*(table.c[k] == v for k, v in values.items()))).scalar_one()
        )

    def put_profile(self, profile: Profile, *, stored_at: str | None = None) -> int:
        """Store a profile — its lens and camera rows, the profile, and (when ``profile.qa`` is set)
        its verdict with thresholds and checks and the session's ``qa_results`` row — in one
        transaction; returns its id. The same session and focus again (a resumed session)
        replaces the row, keeping its id. ``stored_at`` (ISO 8601 UTC, default now) is the time
        the row records, which dates the calibration on the dashboard: a copy of another store
        passes the original's ``profile.stored_at`` to keep its history.

        Raises StoreError when the profile lacks what a row needs (lens, camera, focus, session
        directory, station) or the store cannot be written (nothing is then written)."""
        try:
            row = profile.to_row()
        except ValueError as exc:
            raise StoreError(f"{self.location}: cannot store the profile: {exc}") from None
        qa = profile.qa
        dist = (qa.metrics if qa is not None else {}) or {}
        values_base = {
            **{k: row[k] for k in PROFILE_COLUMNS if k in row},
            "distortion_max": finite_or_none(dist.get("distortion_max_px")),
            "distortion_rms": finite_or_none(dist.get("distortion_rms_px")),
        }

        when = _now() if stored_at is None else _iso_utc(stored_at)

        def tx(conn: sa.Connection) -> int:
            values = {
                **values_base,
                "lens_id": self._ident(conn, lenses, tuple(row["lens"])),
                "camera_id": self._ident(conn, cameras, tuple(row["camera"])),
                "created_at": when,
            }
            stmt = _insert(self.backend)(profiles).values(values)
            stmt = stmt.on_conflict_do_update(
                index_elements=["session_dir", "focus"],
                set_={c: stmt.excluded[c] for c in PROFILE_COLUMNS if c not in ("session_dir", "focus")},
            ).returning(profiles.c.id)
            pid = int(conn.execute(stmt).scalar_one())
            if qa is not None:
                self._session_verdict(conn, pid, qa, row["session_dir"], row["focus"])
            else:  # a re-stored, not yet judged profile: the verdict of the fit it replaces goes
                conn.execute(
                    sa.delete(qa_results).where(qa_results.c.profile_id == pid, qa_results.c.origin == "session")
                )
            return pid

        return int(self._write("storing the profile", tx))

    def _session_verdict(
        self, conn: sa.Connection, pid: int, v: Verdict, session_dir: str | None, focus: float
    ) -> None:
        values = {
            "profile_id": pid,
            "session_dir": session_dir,
            "origin": "session",
            "created_at": _now(),
            **_qa_values(v, focus),
        }
        stmt = _insert(self.backend)(qa_results).values(values)
        stmt = stmt.on_conflict_do_update(
            index_elements=["profile_id"],
            index_where=sa.text("origin = 'session'"),
            set_={c: stmt.excluded[c] for c in values if c not in ("profile_id", "origin")},
        )
        conn.execute(stmt)

    def record_verdict(
        self,
        profile_id: int,
        verdict: Verdict,
        *,
        session_dir: str | None = None,
        stored_as: tuple[str | None, float] | None = None,
    ) -> None:
        """Keep ``verdict`` (thresholds and every check) as the verdict of a stored profile — the
        one that decides whether it can be current — and as its session's ``qa_results`` row
        (replaced, not added: once per profile). One transaction. ``session_dir`` defaults to the
        profile's own. ``stored_as``: the session directory (None: not known) and focus the profile was
        stored with, checked against the row, so that an id a session recorded in another store is never
        taken for another profile of this one. Raises StoreError when there is no such profile, or it is not
        the one ``stored_as`` names (nothing written)."""

        def tx(conn: sa.Connection) -> None:
            got = conn.execute(
                sa.select(profiles.c.session_dir, profiles.c.focus).where(profiles.c.id == int(profile_id))
            ).first()
            if got is None:
                raise StoreError(
                    f"{self.location}: no profile #{profile_id} to record a verdict for"
                    + (_OTHER_STORE if stored_as is not None else "")
                )
            if stored_as is not None:
                problem = self._not_stored_as(profile_id, stored_as, got, "nothing was written")
                if problem is not None:
                    raise StoreError(problem)
            conn.execute(
                sa.update(profiles)
                .where(profiles.c.id == int(profile_id))
                .values(
                    qa_json=json.dumps(plain(verdict.to_record())),
                    verdict=verdict.verdict,
                    distortion_max=finite_or_none(verdict.metrics.get("distortion_max_px")),
                    distortion_rms=finite_or_none(verdict.metrics.get("distortion_rms_px")),
                )
            )
            self._session_verdict(conn, int(profile_id), verdict, session_dir or got[0], float(got[1]))

        self._write("recording the verdict", tx)

    def _id_possible(self, profile_id: int) -> bool:
        """Whether a row can have this id (:data:`_ID_LIMIT`): the driver raises for one beyond the id column's
        integer instead of finding nothing."""
        return -_ID_LIMIT[self.backend] <= int(profile_id) < _ID_LIMIT[self.backend]

    def stored_as_problem(self, profile_id: int, stored_as: tuple[str | None, float], then: str) -> str | None:
        """Why profile ``profile_id`` of this store is not the one a session stored as ``stored_as`` (its session
        directory, None: not known, and focus), as one line ending with ``then`` and what to do; None when it is.
        What :meth:`record_verdict` checks, asked before a session resumed or repaired into this store captures,
        fits or stores anything."""
        q = sa.select(profiles.c.session_dir, profiles.c.focus).where(profiles.c.id == int(profile_id))
        got = (
            self._read("reading the profile", lambda conn: conn.execute(q).first())
            if self._id_possible(profile_id)
            else None
        )
        if got is None:
            return f"{self.location}: no profile #{profile_id}, which the session stored; {then}" + _OTHER_STORE
        return self._not_stored_as(profile_id, stored_as, got, then)

    def _not_stored_as(self, profile_id: int, stored_as: tuple[str | None, float], got: Any, then: str) -> str | None:
        """The line of :meth:`stored_as_problem` for the row ``got`` (its session directory and focus)."""
        if (stored_as[0] is None or got[0] == stored_as[0]) and math.isclose(got[1], stored_as[1]):
            return None
        return (
            f"{self.location}: profile #{profile_id} is the profile of session {got[0]} at focus {got[1]:g}, "
            f"not of {stored_as[0] or 'this session'} at focus {stored_as[1]:g}; {then}" + _OTHER_STORE
        )

    def set_intrinsics(self, profile_id: int, intrinsics: Intrinsics) -> None:
        """Keep the camera matrix measured with a stored profile's distortion (``harp intrinsics --id``),
        replacing any earlier one. One transaction; StoreError when there is no such profile."""

        def tx(conn: sa.Connection) -> None:
            done = conn.execute(
                sa.update(profiles)
                .where(profiles.c.id == int(profile_id))
                .values(intrinsics_json=json.dumps(plain(intrinsics.to_dict())))
            )
            if done.rowcount != 1:
                raise StoreError(f"{self.location}: no profile #{profile_id} to keep a camera matrix for", "missing")

        self._write("storing the camera matrix", tx)

    def put_qa_result(
        self,
        *,
        verdict: str | Verdict,
        reasons: list[str] | None = None,
        metrics: Mapping[str, Any] | None = None,
        profile_id: int | None = None,
        session_dir: str | None = None,
        focus: float | None = None,
        key: str | None = None,
    ) -> int:
        """Add one row of QA history (``origin = 'command'``: a run of ``harp qa``); returns its id.
        ``verdict`` is a :class:`~station.profile.Verdict` (its checks and thresholds are kept) or
        ``"PASS"`` / ``"FAIL"`` with ``reasons`` and ``metrics``. Does not change which profile is
        current: that is :meth:`record_verdict`'s.

        ``key`` (``record_key``, unique) names the row: when a row with that key is there already — the
        same result recorded again, after a commit that may or may not have been written — nothing is
        added and that row's id is returned. Without a key every call adds a row."""
        from station.profile import Verdict  # defers cv2, numpy, yaml

        v = (
            verdict
            if isinstance(verdict, Verdict)
            else Verdict(str(verdict), tuple(reasons or ()), dict(metrics or {}))
        )
        if focus is None:
            focus = finite_or_none((metrics or v.metrics).get("focus"))
        values = {
            "profile_id": profile_id,
            "session_dir": session_dir,
            "origin": "command",
            "created_at": _now(),
            "record_key": key,
            **_qa_values(v, focus),
        }
        if reasons is not None:
            values["reasons_json"] = json.dumps(list(reasons))
        if metrics is not None:
            values["metrics_json"] = json.dumps(plain(dict(metrics)))

        def tx(conn: sa.Connection) -> int:
            if key is None:
                return int(conn.execute(sa.insert(qa_results).values(values).returning(qa_results.c.id)).scalar_one())
            stmt = _insert(self.backend)(qa_results).values(values)
            stmt = stmt.on_conflict_do_nothing(index_elements=["record_key"]).returning(qa_results.c.id)
            got = conn.execute(stmt).scalar()
            if got is None:  # recorded before: that row
                got = conn.execute(sa.select(qa_results.c.id).where(qa_results.c.record_key == key)).scalar_one()
            return int(got)

        return int(self._write("recording the QA result", tx))

    # ============================================================= reads
    def _select(self) -> sa.Select:
        l, c = lenses.alias("l"), cameras.alias("c")
        return (
            sa.select(
                profiles,
                l.c.maker.label("l_maker"),
                l.c.model.label("l_model"),
                l.c.serial.label("l_serial"),
                c.c.maker.label("c_maker"),
                c.c.model.label("c_model"),
                c.c.serial.label("c_serial"),
            )
            .select_from(
                profiles.outerjoin(l, l.c.id == profiles.c.lens_id).outerjoin(c, c.c.id == profiles.c.camera_id)
            )
            .order_by(
                l.c.maker, l.c.model, l.c.serial, profiles.c.focus, profiles.c.created_at.desc(), profiles.c.id.desc()
            )
        )

    def _profile(self, row: sa.Row) -> Profile:
        from station.profile import Profile  # defers cv2, numpy, yaml

        values = dict(row._mapping)
        pid = values.get("id")
        for who, prefix in (("lens", "l_"), ("camera", "c_")):
            if values.get(prefix + "serial") is None:
                raise StoreError(
                    f"{self.location}: profile #{pid} refers to {who} #{values.get(who + '_id')}, which is not in "
                    f"the store (damaged store); {damaged_hint(self.location)}",
                    "damaged",
                )
            values[who] = (values[prefix + "maker"], values[prefix + "model"], values[prefix + "serial"])
        try:
            return Profile.from_row(values)
        except (ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
            what = f"{type(exc).__name__}: {exc}" if isinstance(exc, KeyError) else str(exc)
            raise StoreError(
                f"{self.location}: profile #{pid} (lens {values['lens'][2]}, focus {values.get('focus')}) "
                f"cannot be read ({what}); {damaged_hint(self.location)}, or calibrate the lens again",
                "damaged",
            ) from None

    def _profiles(self, rows: list[sa.Row], errors: list[StoreError] | None) -> list[Profile]:
        out = []
        for r in rows:
            try:
                out.append(self._profile(r))
            except StoreError as exc:
                if errors is None:
                    raise
                errors.append(exc)
        return out

    def profiles(self, lens_id: int | None = None, *, errors: list[StoreError] | None = None) -> list[Profile]:
        """Every profile (of one lens), failed ones included, ordered by lens, focus, then newest first.

        A row that cannot be read raises StoreError; with ``errors=[]`` it is appended there instead
        and the readable rows are returned (a listing shows them and reports the others)."""
        q = self._select()
        if lens_id is not None:
            q = q.where(profiles.c.lens_id == int(lens_id))
        rows = self._read("reading the profiles", lambda conn: conn.execute(q).all())
        return self._profiles(rows, errors)

    def profile(self, profile_id: int) -> Profile | None:
        """The profile with this id (whatever its verdict), or None (also for an id no row can have: beyond
        the id column's integer, whose driver would raise instead of finding nothing)."""
        if not self._id_possible(profile_id):
            return None
        q = self._select().where(profiles.c.id == int(profile_id))
        row = self._read("reading the profile", lambda conn: conn.execute(q).first())
        return self._profile(row) if row is not None else None

    def lenses(self) -> list[tuple[int, str, str, str]]:
        """``(id, maker, model, serial)`` of every lens, by maker, model, serial."""
        q = sa.select(lenses.c.id, lenses.c.maker, lenses.c.model, lenses.c.serial).order_by(
            lenses.c.maker, lenses.c.model, lenses.c.serial
        )
        return [tuple(r) for r in self._read("reading the lenses", lambda conn: conn.execute(q).all())]

    def find_lens(self, query: str) -> tuple[int, str, str, str]:
        """Resolve a user's LENS argument: a serial, ``maker/model/serial``, an id
        (``#3``), or any unambiguous substring of "maker model serial"."""
        all_lenses = self.lenses()
        q = query.strip()
        if q.startswith("#") and q[1:].isdigit():
            hits = [l for l in all_lenses if l[0] == int(q[1:])]
        else:
            hits = [l for l in all_lenses if l[3] == q or "/".join(l[1:]) == q]
            if not hits:
                hits = [l for l in all_lenses if q.lower() in " ".join(l[1:]).lower()]
        if not hits:
            raise StoreError(f"no lens matching {query!r} in {self.location}", "missing")
        if len(hits) > 1:
            names = "; ".join(f"#{l[0]} {l[1]} {l[2]} {l[3]}" for l in hits[:5])
            raise StoreError(f"{query!r} matches {len(hits)} lenses ({names}); be more specific")
        return hits[0]

    def latest_by_focus(self, lens_id: int, *, allow_failed: bool = False) -> list[Profile]:
        """The **current** profiles of a lens, by focus: the newest profile of each focus setting
        (of a zoom lens: of each (focal, focus) setting, ordered by focal then focus).

        A focus setting whose newest profile failed QA has no current profile — it is left out,
        and an older passing profile does not stand in for it — unless ``allow_failed=True``
        (then the newest is returned whatever its verdict; ``p.qa.passed`` tells). A profile not
        judged yet (``p.qa is None``) is current. Callers that must say *why* a focus is missing
        (``profile export`` naming the failed check) ask again with ``allow_failed=True``."""
        newest: dict[tuple[float, float], Profile] = {}  # by (focal, focus): a zoom lens's settings
        for p in self.profiles(lens_id):  # newest first within a focus
            assert p.focus is not None
            key = (-1.0 if p.focal is None else p.focal, p.focus)
            if not any(
                math.isclose(key[0], z, rel_tol=0, abs_tol=FOCUS_TOL)
                and math.isclose(key[1], f, rel_tol=0, abs_tol=FOCUS_TOL)
                for z, f in newest
            ):
                newest[key] = p
        return [newest[k] for k in sorted(newest) if allow_failed or newest[k].qa is None or newest[k].qa.passed]

    def current_profile(self, lens_id: int, focus: float, *, allow_failed: bool = False) -> Profile | None:
        """The current profile of a lens at one calibrated focus setting (see :meth:`latest_by_focus`), or None."""
        for p in self.latest_by_focus(lens_id, allow_failed=allow_failed):
            assert p.focus is not None
            if math.isclose(p.focus, focus, rel_tol=0, abs_tol=FOCUS_TOL):
                return p
        return None

    def qa_results(self, *, profile_id: int | None = None, session_dir: str | None = None) -> Iterator[dict]:
        """Rows of ``qa_results`` (oldest first) as dicts, JSON decoded: ``verdict``, ``reasons``,
        ``metrics``, ``checks`` (list of :meth:`~station.profile.Check.to_dict`), ``thresholds``,
        ``focus``, ``origin`` (``'session'`` / ``'command'``), ``profile_id``, ``session_dir``, ``created_at``."""
        q = sa.select(qa_results).order_by(qa_results.c.id)
        if profile_id is not None:
            q = q.where(qa_results.c.profile_id == int(profile_id))
        if session_dir is not None:
            q = q.where(qa_results.c.session_dir == session_dir)
        rows = self._read("reading the QA results", lambda conn: conn.execute(q).all())
        for r in rows:
            d = dict(r._mapping)
            try:
                d["reasons"] = json.loads(d["reasons_json"])
                d["metrics"] = json.loads(d["metrics_json"])
                d["checks"] = json.loads(d["checks_json"]) if d.get("checks_json") else []
                d["thresholds"] = json.loads(d["thresholds_json"]) if d.get("thresholds_json") else {}
            except (TypeError, ValueError) as exc:
                raise StoreError(
                    f"{self.location}: QA result #{d['id']} cannot be read ({exc}); {damaged_hint(self.location)}",
                    "damaged",
                ) from None
            yield d

    # ========================================================= dashboard
    def lens_models(self, window: dashboard.Window = dashboard.EVERYTHING) -> list[dashboard.LensModel]:
        """Every lens model (maker, model): lenses, calibrations, how many passed / failed (in
        ``window``). See :func:`station.store.dashboard.lens_models`."""
        return self._read("reading the lens models", lambda conn: dashboard.lens_models(conn, window))

    def verdict_counts(
        self, maker: str | None = None, model: str | None = None, window: dashboard.Window = dashboard.EVERYTHING
    ) -> list[dashboard.VerdictCount]:
        """Pass / fail counts of calibrations per lens model, station and day (UTC). See
        :func:`station.store.dashboard.verdict_counts`."""
        return self._read(
            "reading the verdict counts", lambda conn: dashboard.verdict_counts(conn, maker, model, window)
        )

    def lens_summaries(
        self, maker: str | None = None, model: str | None = None, window: dashboard.Window = dashboard.EVERYTHING
    ) -> list[dashboard.LensSummary]:
        """Every lens with its profiles, calibrations and newest calibration's verdict and failed
        checks. See :func:`station.store.dashboard.lens_summaries`."""
        return self._read("reading the lenses", lambda conn: dashboard.lens_summaries(conn, maker, model, window))

    def lens_history(self, lens_id: int, *, errors: list[StoreError] | None = None) -> dict[float, list[Profile]]:
        """Every profile of a lens by focus setting, newest first, each with its verdict and checks (``p.qa``)."""
        out: dict[float, list[Profile]] = {}
        for p in self.profiles(lens_id, errors=errors):
            assert p.focus is not None
            out.setdefault(p.focus, []).append(p)
        return out

    def model_trend(self, maker: str, model: str, *, focus: float | None = None) -> list[dashboard.TrendPoint]:
        """Distortion magnitude and holdout d of a lens model over its serial numbers. See
        :func:`station.store.dashboard.model_trend`; control limits: :func:`station.store.dashboard.control_limits`."""
        return self._read("reading the model trend", lambda conn: dashboard.model_trend(conn, maker, model, focus))


def _qa_values(v: Verdict, focus: float | None) -> dict[str, Any]:
    rec = v.to_record()
    return {
        "verdict": v.verdict,
        "reasons_json": json.dumps(plain(rec["reasons"])),
        "metrics_json": json.dumps(plain(rec["metrics"])),
        "checks_json": json.dumps(plain(rec["checks"])),
        "thresholds_json": json.dumps(plain(rec["thresholds"])),
        "focus": focus,
    }
