"""A write that meets another writer is retried, not failed: SQLite "database is locked" past the
busy timeout, PostgreSQL "could not serialize access" — each provoked for real with a second
connection holding the lock / updating the same row."""

import json
import sqlite3
import threading
import time

import sqlalchemy as sa

from station.store import ProfileStore
from station.store.location import parse_store
from tests.station.store.test_database import put, verdict


def test_sqlite_locked_past_the_busy_timeout_is_retried(tmp_path, monkeypatch):
    import station.store.engine as engine

    monkeypatch.setattr(engine, "WRITE_TRY_MS", 50)  # give up waiting quickly: the retry loop takes over
    timings = tmp_path / "timings.jsonl"
    monkeypatch.setenv("HARP_STORE_TIMINGS", str(timings))
    path = tmp_path / "p.sqlite"
    with ProfileStore(path) as st:
        put(st, session="first")
        other = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
        other.execute("BEGIN IMMEDIATE")  # another station holds the write lock for 0.6 s
        release = threading.Timer(0.6, lambda: other.execute("COMMIT"))
        release.start()
        t0 = time.monotonic()
        pid = put(st, session="second")
        waited = time.monotonic() - t0
        release.join()
        other.close()
        assert st.profile(pid).provenance.session_dir == "second"
    last = json.loads(timings.read_text().splitlines()[-1])
    assert last["op"] == "storing the profile" and last["retries"] >= 1 and waited >= 0.5


def test_postgresql_serialisation_failure_is_retried(postgres, tmp_path, monkeypatch):
    timings = tmp_path / "timings.jsonl"
    monkeypatch.setenv("HARP_STORE_TIMINGS", str(timings))
    url = postgres.create_database("retries")
    with ProfileStore(url) as st:
        pid = put(st, qa=verdict(0.01))
        raw = sa.create_engine(parse_store(url).sqlalchemy_url)
        conn = raw.connect().execution_options(isolation_level="SERIALIZABLE")
        tx = conn.begin()
        # another station updates the same profile row in a transaction still open ...
        conn.execute(sa.text("UPDATE profiles SET verdict = 'PASS' WHERE id = :i"), {"i": pid})
        done = []
        writer = threading.Thread(target=lambda: done.append(st.record_verdict(pid, verdict(0.3))))
        writer.start()  # ... our write waits on its row lock, then cannot be serialised after it commits
        time.sleep(0.5)
        tx.commit()
        writer.join(30)
        conn.close()
        raw.dispose()
        assert done == [None]
        assert st.profile(pid).qa.verdict == "FAIL"  # our write, retried, is the last word
    ops = [json.loads(line) for line in timings.read_text().splitlines()]
    assert [o["retries"] for o in ops if o["op"] == "recording the verdict"][-1] >= 1
