"""Bring a store's schema to :data:`~station.store.schema.HEAD`: Alembic, run by the station itself.

:func:`ensure_schema` is called when a store is opened. A store at the head revision costs
one small query. Otherwise, under the store's write lock (``BEGIN IMMEDIATE`` on SQLite, a
transaction-scoped advisory lock on PostgreSQL, so that processes opening a new store at the
same time migrate it once), it

* creates the tables of a new store (every revision from 0001),
* stamps a SQLite store written before the Alembic migrations (a ``schema_version`` table,
  versions 1–3, no ``alembic_version``) at the revision equal to its version and upgrades it
  in place,
* upgrades an older revision,

all in one transaction: a migration that fails leaves the store as it was. A store written by
newer software (an unknown revision, or a ``schema_version`` above what this software knows)
is refused with a one-line message. The migration scripts ship inside the package
(``station/store/migrations``), so an installed ``harp`` migrates its stores.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import sqlalchemy as sa

from station.store.engine import damaged_hint, read, write
from station.store.errors import StoreError
from station.store.location import POSTGRESQL, StoreLocation
from station.store.schema import HEAD, LEGACY_VERSIONS, REVISIONS, TABLES

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"
_LOCK_KEY = 0x48415250  # "HARP": the advisory lock that serialises migrations on PostgreSQL


def state(conn: sa.Connection) -> tuple[str | None, int | None, set[str]]:
    """(Alembic revision or None, legacy ``schema_version`` or None, table names) of a store."""
    tables = set(sa.inspect(conn).get_table_names())
    rev = None
    if "alembic_version" in tables:
        rev = conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar()
    legacy = None
    if "schema_version" in tables:
        legacy = conn.execute(sa.text("SELECT version FROM schema_version")).scalar()
    return rev, (int(legacy) if legacy is not None else None), tables


def _alembic_config(conn: sa.Connection):
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.attributes["connection"] = conn
    return cfg


def _newer(loc: StoreLocation, what: str) -> StoreError:
    return StoreError(
        f"{loc}: the store was written by newer software ({what}; this one knows revisions up to {HEAD}): "
        "upgrade harp station",
        "schema",
    )


def ensure_schema(
    engine: sa.Engine,
    loc: StoreLocation,
    *,
    create: bool,
    on_wait: Callable[[str], None] | None = None,
    upgrade: bool = True,
) -> None:
    """Migrate the store to :data:`HEAD` if it is not there (see the module docstring); ``on_wait``: as
    :func:`station.store.engine.write`'s (another process migrating, or writing, makes it wait).

    ``create=False`` (opening for reading) never creates tables in a store that has none:
    it raises StoreError (``kind="missing"``) instead. An existing older store is upgraded either way,
    unless ``upgrade=False`` (what only looks, writing nothing: ``harp reprocess --dry-run``): then it
    raises StoreError (``kind="older"``; a newer store: ``kind="schema"``) and writes nothing.
    """
    rev, legacy, tables = read(engine, loc, "reading the schema", state)
    if rev == HEAD:
        return
    if rev is None and legacy is None and not (tables & set(TABLES)) and not create:
        raise StoreError(
            f"{loc}: not a profile store (no harp tables); name another with --store or --config", "missing"
        )
    if not upgrade:
        if rev is not None and rev not in REVISIONS:
            raise _newer(loc, f"revision {rev}")
        if rev is None and legacy is not None and legacy not in LEGACY_VERSIONS:
            raise _newer(loc, f"schema version {legacy}")
        which = f"revision {rev}" if rev is not None else f"schema version {legacy}"
        raise StoreError(
            f"{loc}: written by older software ({which}; this one writes {HEAD}); not upgraded here: "
            "any command that writes the store upgrades it",
            "older",
        )

    def migrate(conn: sa.Connection) -> None:
        from alembic import command

        if loc.backend == POSTGRESQL:
            conn.execute(sa.text("SELECT pg_advisory_xact_lock(:k)"), {"k": _LOCK_KEY})
        rev, legacy, tables = state(conn)  # again, under the lock: another process may have migrated
        if rev == HEAD:
            return
        if rev is not None and rev not in REVISIONS:
            raise _newer(loc, f"revision {rev}")
        cfg = _alembic_config(conn)
        if rev is None and legacy is not None:
            if legacy not in LEGACY_VERSIONS:
                raise _newer(loc, f"schema version {legacy}")
            command.stamp(cfg, LEGACY_VERSIONS[legacy])
        elif rev is None and tables & {"profiles", "lenses"}:
            raise StoreError(
                f"{loc}: has profile tables but no schema version: not a store this software wrote; "
                "name another with --store or --config",
                "damaged",
            )
        command.upgrade(cfg, "head")

    write(engine, loc, "upgrading the store's schema", migrate, serializable=False, on_wait=on_wait)


def check_integrity(engine: sa.Engine, loc: StoreLocation) -> None:
    """Before writing: the store is whole. SQLite: ``PRAGMA quick_check`` (every page and index
    readable and consistent, in O(N)); both backends: the revision is :data:`HEAD` and every table
    of :data:`~station.store.schema.TABLES` is there and can be read. Raises StoreError
    (``kind="damaged"``) naming the store and what to do."""

    def check(conn: sa.Connection) -> list[str]:
        problems: list[str] = []
        if engine.dialect.name == "sqlite":
            rows = [r[0] for r in conn.exec_driver_sql("PRAGMA quick_check(5)").all()]
            if rows != ["ok"]:
                problems.append("quick_check: " + "; ".join(str(r) for r in rows))
        rev, _legacy, tables = state(conn)
        if rev != HEAD:
            problems.append(f"schema revision {rev}, expected {HEAD}")
        missing = [t for t in TABLES if t not in tables]
        if missing:
            problems.append(f"missing tables: {', '.join(missing)}")
        for t in TABLES:
            if t in tables:
                conn.execute(sa.text(f"SELECT * FROM {t} LIMIT 1")).all()
        return problems

    problems = read(engine, loc, "checking the store", check)
    if problems:
        raise StoreError(f"{loc}: the store is damaged ({'; '.join(problems)}); {damaged_hint(loc)}", "damaged")
