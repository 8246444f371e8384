"""The PostgreSQL server goes away and comes back while stations use it (a database restart, a network
blip on the factory floor): a real server of this module's own (tests/pg_server.py), stopped and started
again by the tests — never the session's shared one. Every store URL carries a password (the test server
trusts any) that no message may print.

What is promised (README, fault matrix): one line naming the store and what to do, exit 2, bounded time;
nothing captured or stored lost; a session stopped at its store step resumes storing each profile once;
a store kept open (``harp serve``, a station) reads and writes again once the server is back; a write
whose connection is lost before its commit is tried again on a new connection, one lost at its commit
says it may or may not have been written."""

from __future__ import annotations

import threading
import time
import urllib.error
import urllib.request
import uuid

import pytest
import sqlalchemy as sa

from station.cli import main
from station.session.directory import SessionDir
from station.session.executor import EXIT_ABORTED, EXIT_OK
from station.session.records import Aborted, FrameSaved
from station.session_run import run_session
from station.store import ProfileStore, StoreError
from station.store import engine as store_engine
from station.store.location import parse_store
from tests.station.fakes import FakeCamera, FakeStage
from tests.station.session.test_executor import make_config
from tests.station.store.test_database import counts, put

PASSWORD = "s3cret-pw"
BOUND_S = 60.0  # a command against a stopped server ends well within this (connect_timeout is 10 s)


@pytest.fixture(scope="module")
def own_server():
    from tests.pg_server import postgres_server

    with postgres_server() as server:
        yield server


@pytest.fixture
def pg(own_server):
    """The module's server, running; started again after a test that left it stopped."""
    yield own_server
    if not own_server.running():
        own_server.start()


@pytest.fixture
def url(pg):
    """A new, empty database on the module's server, as a URL with a password."""
    plain = pg.create_database(f"restart_{uuid.uuid4().hex[:12]}")
    return plain.replace("postgresql://harp@", f"postgresql://harp:{PASSWORD}@")


@pytest.fixture
def admin(url):
    """A plain engine on the test's database (outside the store's code), to hold locks and end backends."""
    engine = sa.create_engine(parse_store(url).sqlalchemy_url, isolation_level="AUTOCOMMIT")
    yield engine
    engine.dispose()


def _one_line(text: str) -> None:
    assert text.count("\n") <= 1 and "Traceback" not in text and PASSWORD not in text, text


def _store_backend(admin, *, waiting: str, timeout: float = 30.0) -> int:
    """The pid of the store's backend (``application_name`` harp-station) waiting on ``waiting``
    (a ``wait_event_type`` or ``wait_event``); fails the test after ``timeout``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with admin.connect() as c:
            pid = c.execute(
                sa.text(
                    "SELECT pid FROM pg_stat_activity WHERE application_name = 'harp-station' "
                    "AND (wait_event_type = :w OR wait_event = :w)"
                ),
                {"w": waiting},
            ).scalar()
        if pid is not None:
            return int(pid)
        time.sleep(0.05)
    pytest.fail(f"no store backend waited on {waiting} within {timeout} s")


def _in_thread(fn):
    """Run ``fn`` on a thread; returns (thread, outcome dict with ``result`` or ``error``)."""
    out: dict = {}

    def run():
        try:
            out["result"] = fn()
        except BaseException as exc:  # the test looks at it
            out["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t, out


# ----------------------------------------------------------- a session, and the commands, while it is down
def test_a_session_whose_server_stops_at_its_store_step_keeps_its_frames_and_resumes_storing_each_once(
    pg, url, admin, tmp_path, capsys
):
    import yaml

    from station.config import load_config

    cfg = make_config(tmp_path, focus=(0.0, 1.0))
    d = yaml.safe_load(cfg.path.read_text())
    d["store"] = {"url": url, "sessions_dir": "sessions"}
    cfg.path.write_text(yaml.safe_dump(d))
    cfg = load_config(cfg.path)
    loc = parse_store(url)
    stage = FakeStage(offset_deg=5.0)
    with ProfileStore(url) as store, SessionDir.create(tmp_path / "sessions", cfg, name="s") as s:
        pg.stop()  # the server goes away after the session opened its store, before the first store step
        t0 = time.monotonic()
        result = run_session(s, FakeCamera(stage), stage, store=store, sleep=lambda _s: None, report=False)
        assert time.monotonic() - t0 < BOUND_S
        assert result.exit_code == EXIT_ABORTED
        msg = result.message
        _one_line(msg)
        assert str(loc) in msg and "cannot connect to the store" in msg and f"harp session resume {s.path}" in msg
        assert len(list(s.of_type(Aborted))) == 1
        assert len(list(s.of_type(FrameSaved))) == 4  # every frame of focus 0 kept (stopped at its store step)
    session = tmp_path / "sessions" / "s"

    # the commands against the stopped server: one line naming the store (not its password), exit 2, bounded
    for argv in (
        ["profile", "list", "--store", url],
        ["profile", "show", "DEMO-0001", "--store", url],
        ["qa", "DEMO-0001", "--store", url],
        ["session", "resume", str(session), "--quiet", "--no-report"],
    ):
        capsys.readouterr()
        t0 = time.monotonic()
        assert main(argv) == 2, argv
        assert time.monotonic() - t0 < BOUND_S, argv
        out, err = capsys.readouterr()
        _one_line(err)
        assert PASSWORD not in out and str(loc) in err and "is the server running?" in err, (argv, err)

    pg.start()
    capsys.readouterr()
    assert main(["session", "resume", str(session), "--quiet", "--no-report"]) == EXIT_OK
    with ProfileStore(url, create=False) as store:
        profiles = store.profiles()
        assert sorted(p.focus for p in profiles) == [0.0, 1.0]
        rows = list(store.qa_results())
        assert sorted(r["profile_id"] for r in rows) == sorted(p.id for p in profiles)  # once each

    pg.stop()  # and re-processing the archived session while it is down
    capsys.readouterr()
    t0 = time.monotonic()
    assert main(["reprocess", str(session), "--store", url, "--workers", "1"]) == 2
    assert time.monotonic() - t0 < BOUND_S
    out, err = capsys.readouterr()
    _one_line(err)
    assert PASSWORD not in out and str(loc) in err and "is the server running?" in err, err

    # harp qa of the session judges it from its files: the verdict stands, its history row is said to be missing
    capsys.readouterr()
    code = main(["qa", str(session)])
    assert code in (0, 1)  # PASS / FAIL, as judged
    out, err = capsys.readouterr()
    warned = [line for line in err.splitlines() if "result not recorded" in line]
    assert len(warned) == 1 and PASSWORD not in out + err and "Traceback" not in err, err
    assert str(loc) in warned[0] and f"run harp qa {session} again to record it" in warned[0], warned
    pg.start()
    assert main(["qa", str(session)]) == code  # run again: recorded
    with admin.connect() as c:
        assert c.exec_driver_sql("SELECT count(*) FROM qa_results WHERE origin = 'command'").scalar_one() == 2


# ------------------------------------------------------------------- a process that keeps its store open
@pytest.mark.parametrize("mode", ["immediate", "fast"])
def test_a_store_kept_open_across_a_restart_reads_and_writes_again(pg, url, mode):
    with ProfileStore(url) as st:
        put(st, session="before")
        assert len(st.profiles()) == 1  # its connection now idle in the pool
        pg.stop(mode)
        for call in (st.profiles, lambda: put(st, session="while-down")):
            with pytest.raises(StoreError) as exc:
                call()
            assert exc.value.kind == "unreachable" and str(st.location) in str(exc.value)
            _one_line(str(exc.value))
        pg.start()
        put(st, session="after")  # a write first: the pool's dead connections are found and replaced
        assert len(st.profiles()) == 2


def _get(url: str) -> tuple[int, str, float]:
    t0 = time.monotonic()
    try:
        with urllib.request.urlopen(url, timeout=BOUND_S) as r:
            return r.status, r.read().decode(), time.monotonic() - t0
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode(), time.monotonic() - t0


def test_the_dashboard_says_the_store_is_down_and_serves_again_once_it_is_back(pg, url):
    from station.web import start
    from station.web.dashboard import dashboard_app

    with ProfileStore(url) as st:
        put(st, session="a")
    with ProfileStore(url, create=False) as st, start(dashboard_app(st)) as srv:
        base = srv.base.rstrip("/")
        status, body, _ = _get(base + "/api/lenses")
        assert status == 200 and len(__import__("json").loads(body)["lenses"]) == 1
        pg.stop()
        for path in ("/api/lenses", "/"):
            status, body, took = _get(base + path)
            assert status == 503 and took < BOUND_S, (path, status, body[:300])
            assert str(st.location) in body and "cannot connect to the store" in body and PASSWORD not in body
            assert "Traceback" not in body
        pg.start()
        status, body, _ = _get(base + "/api/lenses")
        assert status == 200 and len(__import__("json").loads(body)["lenses"]) == 1


def test_the_dashboard_says_a_store_that_stopped_answering_does_not_answer_and_serves_again_after(pg, url, monkeypatch):
    """A server that stops answering without closing its connections (frozen; a machine cut off by the network
    looks the same to the dashboard): each page says so (503) within the dashboard's bound instead of hanging,
    and the dashboard serves again once the server answers."""
    import json

    from station.web import dashboard, start
    from station.web.dashboard import dashboard_app

    monkeypatch.setattr(dashboard, "STORE_ANSWER_S", 2.0)
    with ProfileStore(url) as st:
        put(st, session="a")
    with ProfileStore(url, create=False) as st, start(dashboard_app(st)) as srv:
        base = srv.base.rstrip("/")
        status, body, _ = _get(base + "/api/lenses")
        assert status == 200 and len(json.loads(body)["lenses"]) == 1
        pid = st.profiles()[0].id
        with pg.frozen():
            for path in ("/api/lenses", "/", f"/api/profiles/{pid}", f"/profiles/{pid}/export/opencv"):
                status, body, took = _get(base + path)
                assert status == 503 and took < 10.0, (path, status, took, body[:300])
                assert str(st.location) in body and "did not answer within 2 s" in body and PASSWORD not in body
                assert "Traceback" not in body
        status, body, _ = _get(base + "/api/lenses")
        assert status == 200 and len(json.loads(body)["lenses"]) == 1


# -------------------------------------------------- a server that stops answering while a command waits for it
def test_a_write_or_read_that_the_server_stops_answering_is_given_up_after_the_bound_then_done_once(
    pg, url, admin, monkeypatch
):
    """A server that stops answering without closing its connections (frozen: a hung or paused machine looks the
    same; a network cut too, where not even TCP answers): the write and the read on a connection kept from
    before (the pool's) end with one line after the store's bound of silence (engine.STORE_ANSWER_S), naming the
    store (not its password) and saying that nothing of the write was written; before, they waited for the
    server for ever. Once the server answers again, the write run again is stored, once."""
    monkeypatch.setattr(store_engine, "STORE_ANSWER_S", 2.0)
    with ProfileStore(url) as st:
        put(st, session="before")
        for call, what in (
            (lambda: put(st, session="x"), "storing the profile"),
            (st.profiles, "reading the profiles"),
        ):
            assert len(st.profiles()) == 1  # a connection answered, now idle in the pool: the one the call takes
            with pg.frozen():
                t0 = time.monotonic()
                with pytest.raises(StoreError) as exc:
                    call()
                took = time.monotonic() - t0
            text = str(exc.value)
            _one_line(text)
            assert 2.0 <= took < 2.0 + 5.0, (what, took)
            assert exc.value.kind == "unreachable" and PASSWORD not in text
            assert text.startswith(f"{st.location}: {what}: the store did not answer for 2 s "), text
            if what == "storing the profile":
                assert "nothing of it was written" in text
        put(st, session="x")  # run again once it answers
        assert len(st.profiles()) == 2
    with admin.connect() as c:
        assert c.exec_driver_sql("SELECT count(*) FROM profiles").scalar_one() == 2


def test_a_session_whose_server_stops_answering_at_its_store_step_stops_in_bounded_time_and_resumes(
    pg, url, tmp_path, monkeypatch
):
    """The server stops answering (frozen) just as a session stores its first profile: the session stops within
    the bound of silence with its one line (the store, what to do, the resume command), every frame kept; resumed
    once the server answers, each profile is stored once. Before, the session waited for the server for ever."""
    import yaml

    from station.config import load_config

    monkeypatch.setattr(store_engine, "STORE_ANSWER_S", 2.0)
    cfg = make_config(tmp_path, focus=(0.0, 1.0))
    d = yaml.safe_load(cfg.path.read_text())
    d["store"] = {"url": url, "sessions_dir": "sessions"}
    cfg.path.write_text(yaml.safe_dump(d))
    cfg = load_config(cfg.path)
    stage = FakeStage(offset_deg=5.0)
    with ProfileStore(url) as store, SessionDir.create(tmp_path / "sessions", cfg, name="s") as s:
        assert store.profiles() == []  # the session's store has a connection from before, idle in its pool
        put_profile = store.put_profile
        freezing = pg.frozen()

        def freeze_then_store(*args, **kwargs):  # the moment: the first store step
            freezing.__enter__()
            return put_profile(*args, **kwargs)

        monkeypatch.setattr(store, "put_profile", freeze_then_store)
        t0 = time.monotonic()
        try:
            result = run_session(s, FakeCamera(stage), stage, store=store, sleep=lambda _s: None, report=False)
        finally:
            freezing.__exit__(None, None, None)
        assert time.monotonic() - t0 < BOUND_S
        assert result.exit_code == EXIT_ABORTED
        _one_line(result.message)
        assert str(store.location) in result.message and "did not answer for 2 s" in result.message
        assert f"harp session resume {s.path}" in result.message and PASSWORD not in result.message
        assert len(list(s.of_type(FrameSaved))) == 4  # every frame of focus 0 kept
    session = tmp_path / "sessions" / "s"
    assert main(["session", "resume", str(session), "--quiet", "--no-report"]) == EXIT_OK
    with ProfileStore(url, create=False) as store:
        assert sorted(p.focus for p in store.profiles()) == [0.0, 1.0]  # once each


# -------------------------------------------------------------- the connection lost during a write
def test_a_write_whose_connection_is_ended_while_it_waits_is_tried_again_and_stored_once(url, admin, monkeypatch):
    monkeypatch.setattr(store_engine, "WRITE_TRY_MS", 60000)  # one long lock wait: the backend ended in it
    with ProfileStore(url) as st:
        with admin.connect() as holder:
            holder.exec_driver_sql("BEGIN")
            holder.exec_driver_sql("LOCK TABLE lenses IN EXCLUSIVE MODE")  # the write waits on it
            thread, out = _in_thread(lambda: put(st, session="x"))
            pid = _store_backend(admin, waiting="Lock")
            with admin.connect() as c:  # an administrator (or a restart) ends the waiting connection
                assert c.execute(sa.text("SELECT pg_terminate_backend(:p)"), {"p": pid}).scalar()
            _store_backend(admin, waiting="Lock")  # the write waits again, on a new connection
            holder.exec_driver_sql("COMMIT")
        thread.join(BOUND_S)
        assert not thread.is_alive()
        assert "error" not in out, out
        assert counts(admin)["profiles"] == 1 and [p.id for p in st.profiles()] == [out["result"]]


def test_a_write_whose_connection_is_lost_at_its_commit_says_it_may_not_be_written(url, admin):
    with ProfileStore(url) as st:
        with admin.connect() as c:  # COMMIT of a profile row sleeps (a deferred trigger): the moment to end it
            c.exec_driver_sql(
                "CREATE FUNCTION slow_commit() RETURNS trigger LANGUAGE plpgsql AS "
                "$$BEGIN PERFORM pg_sleep(120); RETURN NULL; END$$"
            )
            c.exec_driver_sql(
                "CREATE CONSTRAINT TRIGGER slow_commit AFTER INSERT ON profiles "
                "DEFERRABLE INITIALLY DEFERRED FOR EACH ROW EXECUTE FUNCTION slow_commit()"
            )
        thread, out = _in_thread(lambda: put(st, session="x"))
        pid = _store_backend(admin, waiting="PgSleep")
        with admin.connect() as c:
            assert c.execute(sa.text("SELECT pg_terminate_backend(:p)"), {"p": pid}).scalar()
        thread.join(BOUND_S)
        assert not thread.is_alive()
        exc = out.get("error")
        assert isinstance(exc, StoreError), out
        msg = str(exc)
        _one_line(msg)
        assert exc.kind == "unreachable" and str(st.location) in msg and "storing the profile" in msg
        assert "may or may not have been written" in msg and "run again" in msg
        assert counts(admin) == {"lenses": 0, "cameras": 0, "profiles": 0, "qa_results": 0}  # none of it
        with admin.connect() as c:
            c.exec_driver_sql("DROP TRIGGER slow_commit ON profiles")
        put(st, session="x")  # run again: stored, once
        assert counts(admin)["profiles"] == 1


def test_a_write_waiting_when_the_server_is_stopped_fast_is_one_line_and_written_once_run_again(
    pg, url, admin, monkeypatch
):
    monkeypatch.setattr(store_engine, "WRITE_TRY_MS", 60000)
    with ProfileStore(url) as st:
        holder = admin.connect()
        try:
            holder.exec_driver_sql("BEGIN")
            holder.exec_driver_sql("LOCK TABLE lenses IN EXCLUSIVE MODE")
            thread, out = _in_thread(lambda: put(st, session="x"))
            _store_backend(admin, waiting="Lock")
            pg.stop("fast")  # an administrator's restart: every backend told "terminating connection"
        finally:
            holder.invalidate()
            holder.close()
        thread.join(BOUND_S)
        assert not thread.is_alive()
        exc = out.get("error")
        assert isinstance(exc, StoreError), out
        _one_line(str(exc))
        assert exc.kind == "unreachable" and str(st.location) in str(exc)
        pg.start()
        admin.dispose()
        assert counts(admin)["profiles"] == 0  # nothing half-written
        put(st, session="x")  # run again, on the same open store
        assert counts(admin)["profiles"] == 1
