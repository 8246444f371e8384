"""Connections to a store's database: SQLAlchemy engines per backend, write transactions with retries,
and database errors turned into one-line :class:`~station.store.errors.StoreError` messages.

SQLite: WAL journal, ``synchronous = FULL``, foreign keys on, a busy timeout; the Python driver's
own transaction handling is switched off and every transaction is begun explicitly — a write with
``BEGIN IMMEDIATE`` (the write lock is taken at the start, so two writers never deadlock on a
lock upgrade), a read with ``BEGIN``. PostgreSQL (psycopg 3): every write transaction runs at
``SERIALIZABLE`` isolation; a serialisation failure or deadlock is retried.

:func:`write` runs a function in one write transaction, retrying it while the database is locked
(SQLite) or the transaction could not be serialised (PostgreSQL), with jittered exponential back-off
up to :data:`RETRY_SECONDS`: other stations writing at the same time make a write wait, never fail.
Set ``$HARP_STORE_TIMINGS`` to a file to have every write appended to it as one JSON line
(``op``, ``seconds``, ``retries``, ``backend``, ``pid``) — what ``benchmarks/store_load.py`` reads.
"""

from __future__ import annotations

import errno
import json
import os
import random
import sqlite3
import time
from collections.abc import Callable
from typing import Any, TypeVar

import sqlalchemy as sa
from sqlalchemy import event

from station.store.errors import StoreError
from station.store.location import POSTGRESQL, SQLITE, StoreLocation

BUSY_TIMEOUT_MS = 30000
"""How long SQLite waits for another writer's lock before a write is retried."""

RETRY_SECONDS = 300.0
"""How long a write is retried (locked / not serialisable) before it gives up with a StoreError."""

_RETRY_SQLSTATES = ("40001", "40P01")  # serialization_failure, deadlock_detected

T = TypeVar("T")


def make_engine(loc: StoreLocation) -> sa.Engine:
    """The engine of a store (nothing is connected yet)."""
    if loc.backend == SQLITE:
        engine = sa.create_engine(loc.sqlalchemy_url, connect_args={"timeout": BUSY_TIMEOUT_MS / 1000})
        event.listen(engine, "connect", _sqlite_connect)
        event.listen(engine, "begin", _sqlite_begin)
        return engine
    return sa.create_engine(
        loc.sqlalchemy_url,
        connect_args={"connect_timeout": 10, "application_name": "harp-station"},
        pool_pre_ping=True,
    )


def _sqlite_connect(dbapi: sqlite3.Connection, _record: Any) -> None:
    dbapi.isolation_level = None  # transactions are begun by _sqlite_begin, not by the driver
    dbapi.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
    dbapi.execute("PRAGMA foreign_keys = ON")
    dbapi.execute("PRAGMA synchronous = FULL")
    # switching a brand-new file to WAL needs an exclusive lock the busy handler does not always
    # wait for: retry briefly
    deadline = time.monotonic() + BUSY_TIMEOUT_MS / 1000
    while True:
        try:
            dbapi.execute("PRAGMA journal_mode = WAL")
            return
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.02)


def _sqlite_begin(conn: sa.Connection) -> None:
    conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("harp_write") else "BEGIN")


def write_connection(engine: sa.Engine, loc: StoreLocation, *, serializable: bool = True) -> sa.Connection:
    """A connection whose next transaction is a write transaction (see the module docstring);
    ``serializable=False``: PostgreSQL's READ COMMITTED (each statement sees what others committed
    before it: a migration waiting on the advisory lock then sees the tables the other one made)."""
    conn = engine.connect()
    if loc.backend == SQLITE:
        return conn.execution_options(harp_write=True)
    return conn.execution_options(isolation_level="SERIALIZABLE" if serializable else "READ COMMITTED")


def retryable(exc: BaseException) -> bool:
    """A lock or serialisation conflict with another writer (the write is tried again)."""
    orig = getattr(exc, "orig", exc)
    if isinstance(orig, sqlite3.OperationalError):
        text = str(orig).lower()
        return "locked" in text or "busy" in text
    return getattr(orig, "sqlstate", None) in _RETRY_SQLSTATES


def write(
    engine: sa.Engine, loc: StoreLocation, what: str, fn: Callable[[sa.Connection], T], *, serializable: bool = True
) -> T:
    """``fn(conn)`` in one write transaction, all or nothing, retried on lock / serialisation conflicts.

    ``what`` names the write in messages (``"storing the profile"``). Raises StoreError.
    """
    start = time.monotonic()
    deadline = start + RETRY_SECONDS
    retries = 0
    delay = 0.01
    while True:
        try:
            with write_connection(engine, loc, serializable=serializable) as conn, conn.begin():
                result = fn(conn)
            _log_timing(what, time.monotonic() - start, retries, loc)
            return result
        except (sa.exc.DBAPIError, sqlite3.Error) as exc:
            if retryable(exc) and time.monotonic() < deadline:
                retries += 1
                time.sleep(delay * (0.5 + random.random()))
                delay = min(delay * 2, 1.0)
                continue
            if retryable(exc):
                raise StoreError(
                    f"{loc}: {what}: other writers held the store for {RETRY_SECONDS:.0f} s; "
                    "nothing was written: run again",
                    "busy",
                ) from None
            raise translate(exc, loc, what) from None
        except OSError as exc:
            raise translate(exc, loc, what) from None


def read(engine: sa.Engine, loc: StoreLocation, what: str, fn: Callable[[sa.Connection], T]) -> T:
    """``fn(conn)`` in one read transaction (a consistent snapshot). Raises StoreError."""
    try:
        with engine.connect() as conn, conn.begin():
            return fn(conn)
    except (sa.exc.DBAPIError, sqlite3.Error, OSError) as exc:
        raise translate(exc, loc, what) from None


def _log_timing(what: str, seconds: float, retries: int, loc: StoreLocation) -> None:
    path = os.environ.get("HARP_STORE_TIMINGS")
    if not path:
        return
    line = json.dumps({"op": what, "seconds": seconds, "retries": retries, "backend": loc.backend, "pid": os.getpid()})
    with open(path, "a", encoding="utf-8") as f:  # one short line per write: appends do not interleave
        f.write(line + "\n")


def damaged_hint(loc: StoreLocation) -> str:
    """What to do about a damaged store."""
    if loc.backend == SQLITE:
        return f"restore it from a backup, or recover what can be read with: sqlite3 {loc.path} .recover"
    return "restore the database from a backup (pg_restore) or ask its administrator"


def translate(exc: BaseException, loc: StoreLocation, what: str) -> StoreError:
    """The one-line StoreError of a database or OS error met while doing ``what``."""
    orig = getattr(exc, "orig", None) or exc
    text = " ".join(str(orig).split()) or type(orig).__name__
    low = text.lower()
    sqlstate = getattr(orig, "sqlstate", None) or ""
    if (
        "database or disk is full" in low
        or (isinstance(orig, OSError) and orig.errno == errno.ENOSPC)
        or sqlstate == "53100"
    ):
        where = loc.path.parent if loc.backend == SQLITE and loc.path else "the database server"
        return StoreError(
            f"{loc}: no space left on the disk while {what}; nothing of it was written: "
            f"free space on {where} and run again",
            "full",
        )
    if loc.backend == SQLITE and isinstance(orig, sqlite3.DatabaseError):
        if "readonly" in low or "read-only" in low:
            return StoreError(f"{loc}: cannot write the store ({text}): check its permissions", "error")
        if "unable to open" in low:
            return StoreError(f"{loc}: cannot open the store ({text})", "missing")
        if "locked" in low or "busy" in low:
            return StoreError(f"{loc}: {what}: the store is locked by another process ({text}); run again", "busy")
        if isinstance(orig, sqlite3.OperationalError) and "no such" in low:
            return StoreError(
                f"{loc}: the store's tables are damaged or missing ({text}); {damaged_hint(loc)}", "damaged"
            )
        if isinstance(orig, sqlite3.OperationalError) and "disk i/o" not in low:
            return StoreError(f"{loc}: {what}: {text}", "error")
        return StoreError(f"{loc}: the store is damaged ({text}); {damaged_hint(loc)}", "damaged")
    if loc.backend == POSTGRESQL:
        if sqlstate.startswith("XX") or sqlstate == "42P01":
            return StoreError(f"{loc}: the store is damaged ({text}); {damaged_hint(loc)}", "damaged")
        if isinstance(exc, sa.exc.OperationalError) and not sqlstate:
            first = str(orig).strip().splitlines()[0] if str(orig).strip() else type(orig).__name__
            return StoreError(f"{loc}: cannot connect to the store ({first}); is the server running?", "unreachable")
    if isinstance(orig, OSError):
        return StoreError(f"{loc}: {what}: {orig.strerror or text}", "error")
    return StoreError(f"{loc}: {what}: {text}", "error")
