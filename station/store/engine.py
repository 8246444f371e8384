"""Connections to a store's database: SQLAlchemy engines per backend, write transactions with retries,
and database errors turned into one-line :class:`~station.store.errors.StoreError` messages.

SQLite: WAL journal, ``synchronous = FULL``, foreign keys on, a busy timeout; the Python driver's
own transaction handling is switched off and every transaction is begun explicitly — a write with
``BEGIN IMMEDIATE`` (the write lock is taken at the start, so two writers never deadlock on a
lock upgrade) and a busy timeout of :data:`WRITE_TRY_MS` per try, a read with ``BEGIN`` and
:data:`BUSY_TIMEOUT_MS` (in WAL a reader does not wait for a writer). PostgreSQL (psycopg 3): every
write transaction runs at ``SERIALIZABLE`` isolation with a ``lock_timeout`` of :data:`WRITE_TRY_MS`;
a serialisation failure, a deadlock or a lock not granted in that time is retried.

:func:`write` runs a function in one write transaction, retrying it while the database is locked
(SQLite), a lock is held by another writer or the transaction could not be serialised
(PostgreSQL), with jittered exponential back-off up to :data:`RETRY_SECONDS`: other stations
writing at the same time make a write wait, never fail. A transaction whose connection is lost
before its commit (the server restarted or ended the connection; the server rolled it back) is
tried again once on a new connection (:data:`LOST_TRIES`; a connection that died idle in the pool is
found so, at its try's first statement); one lost at its commit may have been committed, and says
so. A PostgreSQL server that stops answering while a read or write waits for it (its machine hung or
paused, the network to it cut: nothing comes back, nothing closes the connection) is given up after
:data:`STORE_ANSWER_S` of silence (:class:`_AnswerWatch`), with one line, instead of waiting for TCP to give
up (a quarter of an hour) or for ever. A write still waiting after
:data:`WAIT_NOTICE_S` says so, once, through its ``on_wait`` callback (the command prints the line:
the store itself prints nothing).
Set ``$HARP_STORE_TIMINGS`` to a file to have every write appended to it as one JSON line
(``op``, ``seconds``, ``retries``, ``backend``, ``pid``) — what ``benchmarks/store_load.py`` reads.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import random
import socket
import sqlite3
import struct
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

import sqlalchemy as sa
from sqlalchemy import event

from station.store.errors import StoreError
from station.store.location import POSTGRESQL, SQLITE, StoreLocation

BUSY_TIMEOUT_MS = 30000
"""How long a SQLite read (and the opening of a new file) waits for a lock (in WAL a reader waits
only in rare moments: a checkpoint restarting the log, a crashed writer's log recovered)."""

WRITE_TRY_MS = 1000
"""How long one try of a write waits for another writer's lock (SQLite's busy timeout, PostgreSQL's
``lock_timeout``) before :func:`write` tries again: the retry loop does the waiting, so that it can
say it is waiting (:data:`WAIT_NOTICE_S`) and give up after :data:`RETRY_SECONDS`."""

RETRY_SECONDS = 300.0
"""How long a write is retried (locked / not serialisable) before it gives up with a StoreError."""

WAIT_NOTICE_S = 2.0
"""A write still waiting for other writers this long after it began says so (``on_wait``), once."""

_RETRY_SQLSTATES = ("40001", "40P01", "55P03")  # serialization_failure, deadlock_detected, lock_not_available

_NOT_SERVING = (
    "57P01",
    "57P02",
    "57P03",
)  # admin_shutdown, crash_shutdown, cannot_connect_now (starting up / shutting down)

LOST_TRIES = 1
"""How often a transaction whose connection was lost before its commit (the server restarted, an
administrator ended the connection, a network blip) is tried again on a new connection: once —
a server that is down then fails to connect at once, with its one line."""

STORE_ANSWER_S = 30.0
"""How long a PostgreSQL server may send nothing while a read or write waits for it before the command gives up
on it (:class:`_AnswerWatch`): every statement of the station's is answered in milliseconds, a lock wait ends
after :data:`WRITE_TRY_MS`, and a large answer keeps arriving; silence this long is a server that stopped
answering (a hung or paused machine, a network cut) and would otherwise hang the command until TCP gives up
(``tcp_retries2``: about 15 minutes) or, a frozen server whose machine still acknowledges, for ever."""

_TCP_INFO_LAST_DATA_RECV = 52
"""Byte offset of ``tcpi_last_data_recv`` (ms since data last arrived) in Linux's ``struct tcp_info``: eight
one-byte fields, then ``tcpi_rto`` ... (``include/uapi/linux/tcp.h``; the layout is the kernel's ABI)."""

T = TypeVar("T")


class _AnswerWatch:
    """Whether a try of :func:`read` or :func:`write` was cut for silence (:attr:`fired`). While the try runs on a
    PostgreSQL connection over TCP (:meth:`on`), a thread cuts the connection (``shutdown`` of its socket, which
    wakes the driver's wait with the connection lost) once the try has lasted :data:`STORE_ANSWER_S` and the
    server has sent nothing for as long (``TCP_INFO``'s ``tcpi_last_data_recv``). SQLite, a Unix-socket connection
    (a server on this machine) and a platform without ``TCP_INFO`` are not watched."""

    def __init__(self) -> None:
        self.fired = False

    @contextlib.contextmanager
    def on(self, conn: sa.Connection, loc: StoreLocation) -> Iterator[None]:
        """Watch ``conn`` inside the block (see the class)."""
        sock = _tcp_socket(conn) if loc.backend == POSTGRESQL else None
        if sock is None:
            yield
            return
        done = threading.Event()
        threading.Thread(
            target=self._run, args=(sock, done, time.monotonic()), name="harp-store-answer-watch", daemon=True
        ).start()
        try:
            yield
        finally:
            done.set()

    def _run(self, sock: socket.socket, done: threading.Event, started: float) -> None:
        try:
            while not done.wait(min(1.0, STORE_ANSWER_S / 4)):
                if time.monotonic() - started < STORE_ANSWER_S:
                    continue
                with contextlib.suppress(OSError):  # the driver closed it meanwhile
                    info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 104)
                    if struct.unpack_from("I", info, _TCP_INFO_LAST_DATA_RECV)[0] / 1000.0 < STORE_ANSWER_S:
                        continue
                    self.fired = True  # before the cut: the try's error is read as this
                    sock.shutdown(socket.SHUT_RDWR)
                return
        finally:
            sock.close()


def _tcp_socket(conn: sa.Connection) -> socket.socket | None:
    """A socket object on ``conn``'s own TCP socket (a duplicate descriptor: shut down, it ends the driver's wait
    too), or None: not psycopg's, already bad (its try fails by itself), not TCP, or no ``TCP_INFO`` here."""
    if not hasattr(socket, "TCP_INFO"):
        return None
    try:
        fd = conn.connection.dbapi_connection.pgconn.socket  # type: ignore[union-attr]
        sock = socket.socket(fileno=os.dup(fd))
    except Exception:
        return None
    if sock.family not in (socket.AF_INET, socket.AF_INET6):
        sock.close()
        return None
    return sock


def _silent(what: str, loc: StoreLocation, written: str) -> StoreError:
    """The StoreError of a try cut by :class:`_AnswerWatch`; ``written``: what became of the write, or ""."""
    return StoreError(
        f"{loc}: {what}: the store did not answer for {STORE_ANSWER_S:g} s (its server stopped answering, or the "
        f"network to it is cut){written}: check the server and the network, then run again",
        "unreachable",
    )


def make_engine(loc: StoreLocation) -> sa.Engine:
    """The engine of a store (nothing is connected yet)."""
    if loc.backend == SQLITE:
        engine = sa.create_engine(loc.sqlalchemy_url, connect_args={"timeout": BUSY_TIMEOUT_MS / 1000})
        event.listen(engine, "connect", _sqlite_connect)
        event.listen(engine, "begin", _sqlite_begin)
        return engine
    # no pool_pre_ping: its ping at checkout, before any try is watched (_AnswerWatch), would wait for a server
    # that stopped answering for ever; a connection that died idle in the pool fails at its try's first statement
    # instead, and the try runs again on a new connection (LOST_TRIES; SQLAlchemy then drops the pool's others)
    return sa.create_engine(
        loc.sqlalchemy_url,
        connect_args={"connect_timeout": 10, "application_name": "harp-station"},
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
    if conn.get_execution_options().get("harp_write"):  # one try: the retry loop of write() waits
        conn.exec_driver_sql(f"PRAGMA busy_timeout = {WRITE_TRY_MS}")
        conn.exec_driver_sql("BEGIN IMMEDIATE")
    else:
        conn.exec_driver_sql(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        conn.exec_driver_sql("BEGIN")


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


def waiting_text(loc: StoreLocation) -> str:
    """What a write that waits for other writers says (:data:`WAIT_NOTICE_S`), once."""
    return (
        f"waiting for the store {loc}: another program is writing to it "
        f"(up to {RETRY_SECONDS:.0f} s; Ctrl-C to stop, nothing is lost)"
    )


def write(
    engine: sa.Engine,
    loc: StoreLocation,
    what: str,
    fn: Callable[[sa.Connection], T],
    *,
    serializable: bool = True,
    on_wait: Callable[[str], None] | None = None,
) -> T:
    """``fn(conn)`` in one write transaction, all or nothing, retried on lock / serialisation conflicts.

    ``what`` names the write in messages (``"storing the profile"``). ``on_wait`` is told
    :func:`waiting_text`, once, when the write has waited :data:`WAIT_NOTICE_S` for other writers.
    Raises StoreError.
    """
    start = time.monotonic()
    deadline = start + RETRY_SECONDS
    retries = 0
    delay = 0.01
    max_delay = 0.1 if loc.backend == SQLITE else 1.0  # SQLite's busy timeout already waited WRITE_TRY_MS
    told = False
    lost = 0
    while True:
        committing = False
        watch = _AnswerWatch()
        try:
            with write_connection(engine, loc, serializable=serializable) as conn, watch.on(conn, loc), conn.begin():
                if loc.backend == POSTGRESQL:  # a lock wait ends after one try, and is retried
                    conn.exec_driver_sql(f"SET LOCAL lock_timeout = {WRITE_TRY_MS}")
                result = fn(conn)
                committing = True
            _log_timing(what, time.monotonic() - start, retries, loc)
            return result
        except (sa.exc.DBAPIError, sqlite3.Error) as exc:
            if watch.fired:
                written = "; it may or may not have been written" if committing else "; nothing of it was written"
                raise _silent(what, loc, written) from None
            if connection_lost(exc):
                if committing:  # the server may have committed before the connection went: not tried again
                    raise StoreError(
                        f"{loc}: {what}: the connection to the store was lost while committing "
                        f"({_first_line(exc)}), so it may or may not have been written; "
                        "check that the server is running, then run again",
                        "unreachable",
                    ) from None
                if lost < LOST_TRIES:  # rolled back by the server: nothing of it was written; again
                    lost += 1
                    continue
                raise StoreError(
                    f"{loc}: {what}: the connection to the store was lost ({_first_line(exc)}); nothing of it "
                    "was written: check that the server is running, then run again",
                    "unreachable",
                ) from None
            now = time.monotonic()
            if retryable(exc) and now < deadline:
                retries += 1
                if on_wait is not None and not told and now - start >= WAIT_NOTICE_S:
                    told = True
                    on_wait(waiting_text(loc))
                time.sleep(delay * (0.5 + random.random()))
                delay = min(delay * 2, max_delay)
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
    """``fn(conn)`` in one read transaction (a consistent snapshot), tried again on a new connection when
    its connection is lost (:data:`LOST_TRIES`). Raises StoreError."""
    lost = 0
    while True:
        watch = _AnswerWatch()
        try:
            with engine.connect() as conn, watch.on(conn, loc), conn.begin():
                return fn(conn)
        except (sa.exc.DBAPIError, sqlite3.Error, OSError) as exc:
            if watch.fired:
                raise _silent(what, loc, "") from None
            if connection_lost(exc) and lost < LOST_TRIES:
                lost += 1
                continue
            raise translate(exc, loc, what) from None


def connection_lost(exc: BaseException) -> bool:
    """An open connection to the server went away (SQLAlchemy found it broken and dropped it from the
    pool: the server restarted or ended it, the network failed); not a connection that could not be made."""
    return isinstance(exc, sa.exc.DBAPIError) and exc.connection_invalidated


def _first_line(exc: BaseException) -> str:
    orig = getattr(exc, "orig", None) or exc
    text = str(orig).strip()
    return text.splitlines()[0].strip() if text else type(orig).__name__


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
        if connection_lost(exc):
            return StoreError(
                f"{loc}: {what}: the connection to the store was lost ({_first_line(exc)}); "
                "check that the server is running, then run again",
                "unreachable",
            )
        if isinstance(exc, sa.exc.OperationalError) and (not sqlstate or sqlstate in _NOT_SERVING):
            return StoreError(
                f"{loc}: cannot connect to the store ({_first_line(exc)}); is the server running?", "unreachable"
            )
    if isinstance(orig, OSError):
        return StoreError(f"{loc}: {what}: {orig.strerror or text}", "error")
    return StoreError(f"{loc}: {what}: {text}", "error")
