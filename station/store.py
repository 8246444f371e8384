"""The profile store: one SQLite database file (WAL mode) of lens profiles.

Tables: ``lenses`` (maker, model, serial), ``cameras`` (maker, model,
serial), ``profiles`` (one :class:`station.profile.Profile` per row: a fitted
correction of one lens on one camera at one focus setting, with its fit and
holdout straightness and field uncertainty as columns for listing and queries,
and the whole typed record — fit spec, merit, provenance, QA verdict with its
checks — as JSON columns; :meth:`Profile.to_row` / :meth:`Profile.from_row`
convert), ``qa_results`` and ``schema_version``. :data:`MIGRATIONS` brings any older file up to
:data:`SCHEMA_VERSION` inside one ``BEGIN IMMEDIATE`` transaction, so two
processes opening a new file at once do not race.

Concurrency: every connection uses WAL and a ``busy_timeout``; every write is
one ``BEGIN IMMEDIATE`` transaction, so concurrent writers from several
processes are serialised by SQLite and all succeed. A profile is keyed by
(session directory, focus setting): storing it again (a resumed session)
updates the row instead of duplicating it.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import sqlite3
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # imported where used: listing the commands must not load the models
    from station.profile import Profile, Verdict

BUSY_TIMEOUT_MS = 30000

DEFAULT_STORE = Path("profiles") / "harp-profiles.sqlite"
"""Where the commands look for the store when none is named (what ``configs/demo.yaml`` uses)."""


def default_store_path() -> Path:
    """``$HARP_STORE``, else :data:`DEFAULT_STORE` (relative to the working directory)."""
    return Path(os.environ.get("HARP_STORE", DEFAULT_STORE))


class StoreError(RuntimeError):
    """A profile store problem; message is one line."""


def _script(db: sqlite3.Connection, sql: str) -> None:
    # one statement at a time: executescript() would COMMIT the migration transaction
    for stmt in sql.split(";"):
        if stmt.strip():
            db.execute(stmt)


def _v1(db: sqlite3.Connection) -> None:
    _script(
        db,
        """
    CREATE TABLE lenses (
        id INTEGER PRIMARY KEY,
        maker TEXT NOT NULL, model TEXT NOT NULL, serial TEXT NOT NULL,
        UNIQUE (maker, model, serial));
    CREATE TABLE cameras (
        id INTEGER PRIMARY KEY,
        maker TEXT NOT NULL, model TEXT NOT NULL, serial TEXT NOT NULL,
        UNIQUE (maker, model, serial));
    CREATE TABLE profiles (
        id INTEGER PRIMARY KEY,
        lens_id INTEGER NOT NULL REFERENCES lenses(id),
        camera_id INTEGER NOT NULL REFERENCES cameras(id),
        focus REAL NOT NULL,
        model_name TEXT NOT NULL,
        model_json TEXT NOT NULL,
        width INTEGER NOT NULL, height INTEGER NOT NULL,
        fit_d REAL, fit_d_max REAL,
        holdout_d REAL, holdout_d_max REAL,
        field_uncertainty_rms REAL, field_uncertainty_max REAL,
        session_dir TEXT NOT NULL,
        station_id TEXT NOT NULL,
        software_version TEXT NOT NULL,
        created_at TEXT NOT NULL,
        UNIQUE (session_dir, focus));
    CREATE INDEX profiles_lens_focus ON profiles (lens_id, focus);
    CREATE TABLE qa_results (
        id INTEGER PRIMARY KEY,
        profile_id INTEGER REFERENCES profiles(id),
        session_dir TEXT,
        verdict TEXT NOT NULL CHECK (verdict IN ('PASS', 'FAIL')),
        reasons_json TEXT NOT NULL,
        metrics_json TEXT NOT NULL,
        created_at TEXT NOT NULL);
    """,
    )


def _v2(db: sqlite3.Connection) -> None:
    # free-form details kept with a profile (per-orientation holdout, model
    # selection table, focus-interpolation / bootstrap results added later)
    db.execute("ALTER TABLE profiles ADD COLUMN details_json TEXT NOT NULL DEFAULT '{}'")


def _v3(db: sqlite3.Connection) -> None:
    # the typed profile record (station.profile.Profile): what was fitted, every figure of
    # merit, the provenance and the QA verdict with its checks; rows of schema 2 keep NULL /
    # '{}' and are read from their flat figures and details
    for column in (
        "spec_json TEXT",
        "selection_json TEXT NOT NULL DEFAULT '{}'",
        "merit_json TEXT",
        "provenance_json TEXT NOT NULL DEFAULT '{}'",
        "qa_json TEXT",
        "verdict TEXT CHECK (verdict IN ('PASS', 'FAIL'))",
    ):
        db.execute(f"ALTER TABLE profiles ADD COLUMN {column}")


#: migration i (1-based) brings a database from version i-1 to version i
MIGRATIONS: list[Callable[[sqlite3.Connection], None]] = [_v1, _v2, _v3]
SCHEMA_VERSION = len(MIGRATIONS)

#: the columns a profile row is written with (:meth:`station.profile.Profile.to_row`)
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
)


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


class ProfileStore:
    """A connection to the profile database at ``path`` (created if missing)."""

    def __init__(self, path: str | os.PathLike, *, create: bool = True):
        self.path = Path(path)
        if not create and not self.path.is_file():
            raise StoreError(f"{self.path}: no profile store here")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
        except (OSError, sqlite3.Error) as exc:
            blocker = next((p for p in self.path.parents if p.exists() and not p.is_dir()), None)
            reason = (
                f"{blocker} is a file, not a directory"
                if blocker is not None
                else (getattr(exc, "strerror", None) or exc)
            )
            raise StoreError(f"{self.path}: cannot open profile store: {reason}") from None
        self.db.row_factory = sqlite3.Row
        self.db.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        try:
            self._retry_locked(lambda: self.db.execute("PRAGMA journal_mode = WAL"))
            self.db.execute("PRAGMA foreign_keys = ON")
            self.db.execute("PRAGMA synchronous = FULL")
            self._migrate()
        except sqlite3.DatabaseError as exc:
            self.db.close()
            raise StoreError(f"{self.path}: not a usable profile store: {exc}") from None

    def _retry_locked(self, fn, seconds: float = BUSY_TIMEOUT_MS / 1000):
        # switching a brand-new file to WAL needs an exclusive lock that the
        # busy handler does not always wait for; retry briefly.
        deadline = time.monotonic() + seconds
        while True:
            try:
                return fn()
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) or time.monotonic() > deadline:
                    raise
                time.sleep(0.02)

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> ProfileStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ----------------------------------------------------------- schema
    def _transaction(self):
        store = self

        class _Tx:
            def __enter__(self_inner):
                store._retry_locked(lambda: store.db.execute("BEGIN IMMEDIATE"))
                return store.db

            def __exit__(self_inner, exc_type, *_):
                store.db.execute("COMMIT" if exc_type is None else "ROLLBACK")

        return _Tx()

    def schema_version(self) -> int:
        row = self.db.execute("SELECT name FROM sqlite_master WHERE name='schema_version'").fetchone()
        if row is None:
            return 0
        return int(self.db.execute("SELECT version FROM schema_version").fetchone()[0])

    def _migrate(self) -> None:
        if self.schema_version() == SCHEMA_VERSION:
            return
        with self._transaction() as db:
            v = self.schema_version()  # re-read under the write lock
            if v > SCHEMA_VERSION:
                raise StoreError(
                    f"{self.path}: schema version {v} is newer than this software "
                    f"({SCHEMA_VERSION}); upgrade harp station"
                )
            if v == 0:
                db.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
                db.execute("INSERT INTO schema_version VALUES (0)")
            for i in range(v, SCHEMA_VERSION):
                MIGRATIONS[i](db)
                db.execute("UPDATE schema_version SET version = ?", (i + 1,))

    # ------------------------------------------------------------ writes
    def _ident(self, db, table: str, ident: tuple[str, str, str]) -> int:
        db.execute(f"INSERT OR IGNORE INTO {table} (maker, model, serial) VALUES (?, ?, ?)", ident)
        return db.execute(f"SELECT id FROM {table} WHERE maker=? AND model=? AND serial=?", ident).fetchone()[0]

    def put_profile(self, profile: Profile) -> int:
        """Insert (or, for the same session and focus, replace) a profile; returns its id.

        Raises StoreError when the profile lacks what a row needs (lens, camera,
        focus, session directory, station)."""
        try:
            row = profile.to_row()
        except ValueError as exc:
            raise StoreError(f"{self.path}: cannot store the profile: {exc}") from None
        with self._transaction() as db:
            values = {
                **row,
                "lens_id": self._ident(db, "lenses", tuple(row["lens"])),
                "camera_id": self._ident(db, "cameras", tuple(row["camera"])),
                "created_at": _now(),
            }
            cols = ", ".join(PROFILE_COLUMNS)
            marks = ", ".join("?" for _ in PROFILE_COLUMNS)
            update = ", ".join(f"{c}=excluded.{c}" for c in PROFILE_COLUMNS if c not in ("session_dir", "focus"))
            db.execute(
                f"INSERT INTO profiles ({cols}) VALUES ({marks}) ON CONFLICT (session_dir, focus) DO UPDATE SET {update}",
                tuple(values[c] for c in PROFILE_COLUMNS),
            )
            return db.execute(
                "SELECT id FROM profiles WHERE session_dir=? AND focus=?", (row["session_dir"], row["focus"])
            ).fetchone()[0]

    def record_verdict(self, profile_id: int, verdict: Verdict) -> None:
        """Keep a QA verdict, with its checks, with the profile it judged."""
        with self._transaction() as db:
            db.execute(
                "UPDATE profiles SET qa_json = ?, verdict = ? WHERE id = ?",
                (json.dumps(verdict.to_record()), verdict.verdict, int(profile_id)),
            )

    def put_qa_result(
        self,
        *,
        verdict: str,
        reasons: list[str],
        metrics: dict,
        profile_id: int | None = None,
        session_dir: str | None = None,
    ) -> int:
        with self._transaction() as db:
            cur = db.execute(
                "INSERT INTO qa_results (profile_id, session_dir, verdict, reasons_json,"
                " metrics_json, created_at) VALUES (?, ?, ?, ?, ?, ?)",
                (profile_id, session_dir, verdict, json.dumps(reasons), json.dumps(metrics), _now()),
            )
            return cur.lastrowid

    # ------------------------------------------------------------- reads
    _SELECT = """
        SELECT p.*, l.maker AS l_maker, l.model AS l_model, l.serial AS l_serial,
               c.maker AS c_maker, c.model AS c_model, c.serial AS c_serial
        FROM profiles p JOIN lenses l ON l.id = p.lens_id JOIN cameras c ON c.id = p.camera_id"""

    def _profile(self, row: sqlite3.Row) -> Profile:
        from station.profile import Profile

        values = {k: row[k] for k in row.keys()}
        values["lens"] = (row["l_maker"], row["l_model"], row["l_serial"])
        values["camera"] = (row["c_maker"], row["c_model"], row["c_serial"])
        try:
            return Profile.from_row(values)
        except (ValueError, KeyError, TypeError) as exc:
            raise StoreError(f"{self.path}: profile #{row['id']} cannot be read: {exc}") from None

    def profiles(self, lens_id: int | None = None) -> list[Profile]:
        """All profiles (of one lens), ordered by lens, focus, then newest first."""
        where, args = ("WHERE p.lens_id = ?", (lens_id,)) if lens_id is not None else ("", ())
        rows = self.db.execute(
            f"{self._SELECT} {where} ORDER BY l.maker, l.model, l.serial, p.focus, p.created_at DESC, p.id DESC", args
        ).fetchall()
        return [self._profile(r) for r in rows]

    def profile(self, profile_id: int) -> Profile | None:
        row = self.db.execute(f"{self._SELECT} WHERE p.id = ?", (profile_id,)).fetchone()
        return self._profile(row) if row else None

    def lenses(self) -> list[tuple[int, str, str, str]]:
        return [
            tuple(r)
            for r in self.db.execute("SELECT id, maker, model, serial FROM lenses ORDER BY maker, model, serial")
        ]

    def find_lens(self, query: str) -> tuple[int, str, str, str]:
        """Resolve a user's LENS argument: a serial, ``maker/model/serial``, an id
        (``#3``), or any unambiguous substring of "maker model serial"."""
        lenses = self.lenses()
        q = query.strip()
        if q.startswith("#") and q[1:].isdigit():
            hits = [l for l in lenses if l[0] == int(q[1:])]
        else:
            hits = [l for l in lenses if l[3] == q or "/".join(l[1:]) == q]
            if not hits:
                hits = [l for l in lenses if q.lower() in " ".join(l[1:]).lower()]
        if not hits:
            raise StoreError(f"no lens matching {query!r} in {self.path}")
        if len(hits) > 1:
            names = "; ".join(f"#{l[0]} {l[1]} {l[2]} {l[3]}" for l in hits[:5])
            raise StoreError(f"{query!r} matches {len(hits)} lenses ({names}); be more specific")
        return hits[0]

    def latest_by_focus(self, lens_id: int) -> list[Profile]:
        """The newest profile of each focus setting of a lens, by focus."""
        seen: dict[float, Profile] = {}
        for p in self.profiles(lens_id):
            seen.setdefault(p.focus, p)
        return [seen[f] for f in sorted(seen)]

    def qa_results(self) -> Iterator[dict]:
        for r in self.db.execute("SELECT * FROM qa_results ORDER BY id"):
            yield {**dict(r), "reasons": json.loads(r["reasons_json"]), "metrics": json.loads(r["metrics_json"])}
