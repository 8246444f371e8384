"""A command whose write waits on a busy store says so on stderr after a moment, then stores once the
store is free: a real second process holds SQLite's write lock on a real file (``BEGIN IMMEDIATE``)
while the real command runs as a process of its own; PostgreSQL: a real second connection holds the
row the write needs. Reading does not wait for a writer (WAL)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import sqlalchemy as sa

from station.store import ProfileStore
from station.store.engine import waiting_text
from station.store.location import parse_store
from tests.station.store.test_database import THRESHOLDS, profile, put, verdict

REPO = Path(__file__).resolve().parents[3]

HOLDER = """
import sqlite3, sys
con = sqlite3.connect(sys.argv[1], isolation_level=None)
con.execute("BEGIN IMMEDIATE")  # the write lock, as another station storing its profile holds it
con.execute("INSERT INTO lenses (maker, model, serial) VALUES ('other', 'station', 'HOLDER')")
print("holding", flush=True)
sys.stdin.readline()  # released when the test says so (or killed with its group)
con.execute("COMMIT")
print("released", flush=True)
"""


def _kill(proc: subprocess.Popen) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


@contextlib.contextmanager
def write_lock_held(store: Path) -> Iterator[subprocess.Popen]:
    """Another process holding the store's write lock until a line is written to its stdin; killed with
    its process group on every way out."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(store)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline() == "holding\n", proc.stderr.read() if proc.stderr else ""
        yield proc
    finally:
        _kill(proc)


def _release(holder: subprocess.Popen) -> None:
    assert holder.stdin is not None and holder.stdout is not None
    holder.stdin.write("\n")
    holder.stdin.flush()
    assert holder.stdout.readline() == "released\n"


class Harp:
    """``harp ARGV`` running as a process of its own (its own group), its stdout and stderr read by two
    threads as they come: ``err`` the stderr lines so far, ``waiting`` set once a line says it waits."""

    def __init__(self, argv: tuple[str, ...]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "station.cli", *argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
            env={**os.environ, "PYTHONPATH": str(REPO)},
        )
        self.out: list[str] = []
        self.err: list[str] = []
        self.waiting = threading.Event()
        self.readers = [
            threading.Thread(target=self._read, args=(self.proc.stdout, self.out), daemon=True),
            threading.Thread(target=self._read, args=(self.proc.stderr, self.err), daemon=True),
        ]
        for r in self.readers:
            r.start()

    def _read(self, stream, lines: list[str]) -> None:
        for line in stream:
            lines.append(line)
            if "waiting for the store" in line:
                self.waiting.set()

    def finish(self, timeout: float) -> tuple[int, str, list[str]]:
        """Wait for the command to end: ``(exit code, stdout, stderr lines)``."""
        code = self.proc.wait(timeout)
        for r in self.readers:
            r.join(timeout)
        return code, "".join(self.out), self.err

    def kill(self) -> None:
        _kill(self.proc)
        for r in self.readers:
            r.join(10)


@contextlib.contextmanager
def harp(*argv: str) -> Iterator[Harp]:
    """:class:`Harp` ``ARGV``, killed with its process group on every way out."""
    h = Harp(argv)
    try:
        yield h
    finally:
        h.kill()


def _store_with_a_lens(path: Path) -> None:
    from station.qa.verdicts import qa_verdict

    with ProfileStore(path) as st:
        for focus in (0.0, 1.0):
            p = profile(focus=focus)
            st.put_profile(p.with_(qa=qa_verdict(p, {**THRESHOLDS, "max_distortion_px": 10.0})))


def _command_rows(path: Path) -> int:
    with ProfileStore(path, create=False) as st:
        return sum(r["origin"] == "command" for r in st.qa_results())


def test_qa_waiting_on_another_writer_says_so_and_records_once_the_store_is_free(tmp_path):
    store = tmp_path / "store.sqlite"
    _store_with_a_lens(store)
    with write_lock_held(store) as holder, harp("qa", "S1", "--store", str(store), "--json") as qa:
        # generous: the command imports numpy, OpenCV and SQLAlchemy and judges first; the line comes
        # ~2 s after its write began waiting (SQLite's busy timeout per try is 30 s: the first retry
        # would have come after 30 s)
        assert qa.waiting.wait(90), f"no waiting line; stderr so far: {qa.err}"
        assert qa.proc.poll() is None  # still waiting: the lock is held
        assert _command_rows(store) == 0  # reading the store does not wait for the writer
        _release(holder)
        code, out, err = qa.finish(120)
        assert code == 0, err
    assert err == [f"harp qa: {waiting_text(parse_store(store))}\n"]
    assert err[0] == (
        f"harp qa: waiting for the store {store}: another program is writing to it "
        "(up to 300 s; Ctrl-C to stop, nothing is lost)\n"
    )
    doc = json.loads(out)  # stdout holds the JSON only
    assert doc["verdict"] == "PASS" and len(doc["profiles"]) == 2
    assert _command_rows(store) == 2  # both of this run's QA rows, stored after the wait
    with ProfileStore(store, create=False) as st:  # and the other writer's row too
        assert ("other", "station", "HOLDER") in [tuple(l[1:]) for l in st.lenses()]


def test_ctrl_c_while_waiting_is_exit_130_and_writes_nothing(tmp_path):
    """Ctrl-C (SIGINT to the command's process group) while it waits: one more line, exit 130, nothing of
    it in the store. A try waits 1 s in SQLite's busy handler, where Python cannot act on the signal: it
    is acted on within about that (before: up to the 30 s busy timeout)."""
    store = tmp_path / "store.sqlite"
    _store_with_a_lens(store)
    with write_lock_held(store), harp("qa", "S1", "--store", str(store), "--json") as qa:
        assert qa.waiting.wait(90), f"no waiting line; stderr so far: {qa.err}"
        os.killpg(qa.proc.pid, signal.SIGINT)
        code, out, err = qa.finish(60)
        assert code == 130, err
    assert out == "" and len(err) == 2 and err[1] == "harp: interrupted\n", err
    assert _command_rows(store) == 0


def test_reading_commands_do_not_wait_for_a_writer(tmp_path):
    store = tmp_path / "store.sqlite"
    _store_with_a_lens(store)
    with write_lock_held(store), harp("profile", "list", "--store", str(store)) as listing:
        code, out, err = listing.finish(25)  # a read waiting on the lock would wait 30 s and more
        assert code == 0, err
    assert "S1" in out and not any("waiting" in line for line in err)


def test_sqlite_write_says_it_waits_after_a_moment_not_after_the_busy_timeout(tmp_path):
    """The line comes WAIT_NOTICE_S (2 s) after the write began waiting: before, a write waited in
    SQLite's busy handler 30 s per try, and could not have said anything before then. The other writer
    lets go when told, so nothing depends on a delay; the one bound (15 s) is generous both ways."""
    import station.store.engine as engine

    path = tmp_path / "p.sqlite"
    told: list[tuple[str, float]] = []
    with ProfileStore(path) as st:
        put(st, session="first")
        with write_lock_held(path) as holder:

            def on_wait(text: str) -> None:
                told.append((text, time.monotonic() - t0))
                _release(holder)  # the other station commits: the write goes on

            st.on_wait = on_wait
            t0 = time.monotonic()
            pid = put(st, session="second")
        assert st.profile(pid).provenance.session_dir == "second"
        put(st, session="third")  # a write that does not wait says nothing
    assert [text for text, _ in told] == [waiting_text(st.location)]
    assert engine.WAIT_NOTICE_S <= told[0][1] < 15.0 < engine.BUSY_TIMEOUT_MS / 1000


def test_postgresql_write_waiting_on_a_row_lock_says_so_and_is_retried(postgres, monkeypatch):
    import station.store.engine as engine

    monkeypatch.setattr(engine, "WAIT_NOTICE_S", 0.5)
    monkeypatch.setattr(engine, "WRITE_TRY_MS", 200)
    url = postgres.create_database("store_wait")
    told = threading.Event()
    texts: list[str] = []

    def on_wait(text: str) -> None:
        texts.append(text)
        told.set()

    with ProfileStore(url, on_wait=on_wait) as st:
        pid = put(st, qa=verdict(0.01))
        raw = sa.create_engine(parse_store(url).sqlalchemy_url)
        try:
            with raw.connect() as conn:
                tx = conn.begin()  # another station holds the profile's row (an update not yet committed)
                conn.execute(sa.text("UPDATE profiles SET verdict = 'PASS' WHERE id = :i"), {"i": pid})
                done: list[object] = []
                writer = threading.Thread(target=lambda: done.append(st.record_verdict(pid, verdict(0.3))))
                writer.start()
                # without a lock timeout the write waits inside its statement, unseen, for as long as the row is held
                assert told.wait(60), "the waiting write said nothing"
                tx.commit()
                writer.join(60)
        finally:
            raw.dispose()
        assert done == [None]
        assert st.profile(pid).qa.verdict == "FAIL"  # our write, retried, is the last word
    assert texts == [waiting_text(parse_store(url))]
