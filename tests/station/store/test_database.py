"""Profile store on both backends (a real SQLite file, a real PostgreSQL server): round trip, one
transaction per write, verdicts stored with their checks, current profiles, unreadable rows,
integrity on open, reading never creates, concurrent writers."""

import multiprocessing as mp

import pytest
import sqlalchemy as sa

from pipeline.models import model_from_dict
from station.config import Identity
from station.profile import Check, Figures, Holdout, Merit, Profile, Provenance, UncertaintySummary, Verdict
from station.store import ProfileStore, StoreError
from station.store.location import parse_store
from station.store.migrate import check_integrity
from station.store.schema import HEAD
from tests.station.store.conftest import tamper

LENS = ("Acme", "50mm", "S1")
CAM = ("Cam", "Body", "C1")
MODEL = {"model": "radial", "center": [1.0, 2.0], "k": [1.0, 0.01], "scale": 100.0}
THRESHOLDS = {"max_holdout_d_px": 0.05, "max_distortion_px": 5.0, "max_reference_deviation_px": None}


def verdict(holdout_d: float, limit: float = 0.05, distortion: float = 1.5) -> Verdict:
    """A verdict as QA writes one, with its checks (the truth the store must keep as given)."""
    ok = holdout_d <= limit
    return Verdict(
        "PASS" if ok else "FAIL",
        () if ok else (f"holdout d {holdout_d:.4f} px > {limit:g} px",),
        {"holdout_d_px": holdout_d, "distortion_max_px": distortion, "distortion_rms_px": distortion / 3},
        (
            Check("holdout_d", holdout_d, "<=", limit, ok, f"holdout d {holdout_d:.4f} px <= {limit:g} px"),
            Check("distortion_max", distortion, "<=", 5.0, True, f"distortion max {distortion:.3f} px <= 5 px"),
        ),
        {**THRESHOLDS, "max_holdout_d_px": limit},
    )


def profile(session="sess", focus=0.5, lens=LENS, holdout_d=0.012, qa=None, details=None, station="st") -> Profile:
    return Profile(
        model_from_dict(MODEL),
        640,
        480,
        merit=Merit(
            fit=Figures(0.01, 0.02),
            holdout=Holdout(holdout_d, 0.03, "leave one orientation out", (0.011, 0.013)),
            field_uncertainty=UncertaintySummary(0.001, 0.004, 12),
        ),
        qa=qa,
        lens=Identity(*lens),
        camera=Identity(*CAM),
        focus=focus,
        provenance=Provenance(software="harp-station 0.1.0", station=station, session_dir=session),
        details=details or {},
    )


def put(store, **kw):
    return store.put_profile(profile(**kw))


def counts(engine) -> dict[str, int]:
    with engine.connect() as conn:
        return {
            t: conn.execute(sa.text(f"SELECT count(*) FROM {t}")).scalar_one()
            for t in ("lenses", "cameras", "profiles", "qa_results")
        }


# ------------------------------------------------------------------ round trip
def test_roundtrip(store_url):
    with ProfileStore(store_url) as st:
        pid = put(st, qa=verdict(0.012))
    with ProfileStore(store_url, create=False) as st:
        p = st.profile(pid)
        assert p.id == pid and p.lens == Identity(*LENS) and p.camera == Identity(*CAM)
        assert p.model.to_dict() == MODEL and (p.width, p.height, p.focus) == (640, 480, 0.5)
        assert p.merit == profile().merit
        assert p.qa == verdict(0.012)  # verdict, reasons, figures, thresholds and every check
        assert p.provenance.station == "st" and p.provenance.session_dir == "sess"
        assert st.find_lens("S1")[0] == st.find_lens("acme 50")[0] == st.find_lens(f"#{p.id}")[0]
        assert st.profile(pid + 1000) is None


def test_sqlite_store_is_wal(tmp_path):
    with ProfileStore(tmp_path / "p.sqlite") as st:
        put(st)
        with st.engine.connect() as conn:
            assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"


def test_same_session_focus_replaces_the_row(store_url):
    with ProfileStore(store_url) as st:
        a = put(st, holdout_d=0.5)
        b = put(st, holdout_d=0.1)
        put(st, session="other")
        assert a == b
        assert len(st.profiles()) == 2
        assert st.profile(a).merit.holdout.d == 0.1


def test_ambiguous_and_missing_lens(store_url):
    with ProfileStore(store_url) as st:
        put(st)
        put(st, lens=("Acme", "35mm", "S2"), session="b")
        with pytest.raises(StoreError, match="matches 2 lenses"):
            st.find_lens("acme")
        with pytest.raises(StoreError, match="no lens matching"):
            st.find_lens("zeiss")


# ------------------------------------------------------------------ transactions
def test_profile_verdict_and_lens_are_written_together(store_url, raw):
    with ProfileStore(store_url) as st:
        pid = put(st, qa=verdict(0.2))
        (row,) = list(st.qa_results())
        assert row["origin"] == "session" and row["profile_id"] == pid and row["verdict"] == "FAIL"
        assert row["checks"] == [c.to_dict() for c in verdict(0.2).checks] and row["focus"] == 0.5
        assert row["thresholds"]["max_holdout_d_px"] == 0.05
        # a verdict the database refuses (its CHECK constraint) fails after the lens row was
        # inserted in the same transaction: nothing of it stays
        before = counts(raw)
        bad = Verdict("MAYBE", (), {}, (), {})
        with pytest.raises(StoreError):
            put(st, lens=("Other", "lens", "X9"), session="s2", qa=bad)
        assert counts(raw) == before
        assert [l[3] for l in st.lenses()] == ["S1"]


def test_session_verdict_is_kept_once_per_profile(store_url):
    with ProfileStore(store_url) as st:
        pid = put(st, qa=verdict(0.012))
        for _ in range(3):  # a resumed session judging and storing again
            put(st, qa=verdict(0.013))
            st.record_verdict(pid, verdict(0.014))
        rows = list(st.qa_results())
        assert len(rows) == 1 and rows[0]["metrics"]["holdout_d_px"] == 0.014
        assert st.profile(pid).qa == verdict(0.014)
        # runs of `harp qa` are history: one row each, and they do not change the profile's verdict
        st.put_qa_result(verdict=verdict(0.2), profile_id=pid, focus=0.5)
        st.put_qa_result(verdict="PASS", reasons=[], metrics={"focus": 0.5, "holdout_d_px": 0.01}, profile_id=pid)
        rows = list(st.qa_results(profile_id=pid))
        assert [r["origin"] for r in rows] == ["session", "command", "command"]
        assert rows[1]["checks"][0]["passed"] is False and rows[2]["focus"] == 0.5
        assert st.profile(pid).qa.verdict == "PASS"
        # re-stored without a verdict (re-fitted, not judged yet): the old fit's verdict goes
        put(st, holdout_d=0.02)
        assert st.profile(pid).qa is None
        assert [r["origin"] for r in st.qa_results(profile_id=pid)] == ["command", "command"]


def test_a_qa_result_recorded_again_under_its_key_is_one_row(store_url):
    """``harp qa`` run again after a commit that may or may not have been written records the same rows
    under the same keys: a row already there is not added again; other keys, and no key, add rows."""
    with ProfileStore(store_url) as st:
        pid = put(st)
        first = st.put_qa_result(verdict=verdict(0.2), profile_id=pid, focus=0.5, key="run-a/0")
        again = st.put_qa_result(verdict=verdict(0.2), profile_id=pid, focus=0.5, key="run-a/0")
        assert again == first
        assert [r["record_key"] for r in st.qa_results(profile_id=pid)] == ["run-a/0"]
        st.put_qa_result(verdict=verdict(0.2), profile_id=pid, focus=0.5, key="run-b/0")  # a later run
        st.put_qa_result(verdict=verdict(0.2), profile_id=pid, focus=0.5)  # no key: a row each time
        st.put_qa_result(verdict=verdict(0.2), profile_id=pid, focus=0.5)
        assert [r["record_key"] for r in st.qa_results(profile_id=pid)] == ["run-a/0", "run-b/0", None, None]


def test_record_verdict_of_no_profile_is_an_error(store_url):
    with ProfileStore(store_url) as st, pytest.raises(StoreError, match="no profile #42"):
        st.record_verdict(42, verdict(0.01))


# ------------------------------------------------------------------ current profiles
def test_a_failed_profile_is_never_current(store_url):
    with ProfileStore(store_url) as st:
        old = put(st, session="2024-a", focus=0.5, qa=verdict(0.01))
        put(st, session="2024-a", focus=1.0, qa=verdict(0.01))
        new = put(st, session="2024-b", focus=0.5, qa=verdict(0.3))  # newer, FAILED
        unjudged = put(st, session="2024-b", focus=0.0)  # stored, not judged yet
        lens = st.find_lens("S1")[0]
        cur = st.latest_by_focus(lens)
        # focus 0.5: the newest failed, so none — the older passing profile does not stand in
        assert [(p.focus, p.id) for p in cur] == [(0.0, unjudged), (1.0, cur[1].id)]
        assert st.current_profile(lens, 0.5) is None
        assert st.current_profile(lens, 0.5, allow_failed=True).id == new
        every = st.latest_by_focus(lens, allow_failed=True)
        assert [p.focus for p in every] == [0.0, 0.5, 1.0] and not every[1].qa.passed
        assert old in {p.id for p in st.profiles(lens)}  # listings keep every profile
        # judged again as PASS (e.g. a corrected session QA), it is current again
        st.record_verdict(new, verdict(0.01))
        assert st.current_profile(lens, 0.5).id == new


# ------------------------------------------------------------------ unreadable rows
@pytest.mark.parametrize(
    "damage, says",
    [
        ("UPDATE profiles SET model_json = '{not json' WHERE id = {pid}", "cannot be read"),
        (
            """UPDATE profiles SET model_json = '{"model": "radial", "k": [1.0], "scale": 100.0}' WHERE id = {pid}""",
            "center",
        ),
        ("UPDATE profiles SET merit_json = '[1, 2' WHERE id = {pid}", "cannot be read"),
        ("DELETE FROM lenses", "refers to lens"),
    ],
    ids=["bad-json", "no-centre", "bad-merit", "lens-missing"],
)
def test_a_row_that_cannot_be_read_is_reported(store_url, raw, damage, says):
    with ProfileStore(store_url) as st:
        pid = put(st)
        put(st, session="good", lens=("B", "b", "S2"))
    if damage.startswith("DELETE"):
        tamper(raw, f"DELETE FROM lenses WHERE serial = '{LENS[2]}'")
    else:
        tamper(raw, damage.replace("{pid}", str(pid)))
    with ProfileStore(store_url, create=False) as st:
        with pytest.raises(StoreError) as exc:
            st.profiles()
        msg = str(exc.value)
        assert "\n" not in msg and f"profile #{pid}" in msg and says in msg and str(st.location) in msg
        assert exc.value.kind == "damaged" and ("restore" in msg)
        errors = []
        assert [p.provenance.session_dir for p in st.profiles(errors=errors)] == ["good"]  # the others, and
        assert len(errors) == 1 and f"profile #{pid}" in str(errors[0])  # the damaged one reported


# ------------------------------------------------------------------ opening
def test_opening_for_reading_never_creates(store_url, raw):
    with pytest.raises(StoreError) as exc:
        ProfileStore(store_url, create=False)
    assert exc.value.kind == "missing" and "\n" not in str(exc.value)
    loc = parse_store(store_url)
    if loc.backend == "sqlite":
        assert not loc.path.parent.exists()  # not even its directory
    else:
        assert sa.inspect(raw).get_table_names() == []


def test_open_for_writing_creates_at_head(store_url, raw):
    ProfileStore(store_url).close()
    with raw.connect() as conn:
        assert conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar() == HEAD
        assert conn.execute(sa.text("SELECT version FROM schema_version")).scalar() == 7
    with ProfileStore(store_url, create=False) as st:
        assert st.profiles() == []


def test_newer_store_is_refused(store_url, raw):
    ProfileStore(store_url).close()
    tamper(raw, "UPDATE alembic_version SET version_num = 'ffff'")
    for create in (True, False):
        with pytest.raises(StoreError, match="newer software") as exc:
            ProfileStore(store_url, create=create)
        assert exc.value.kind == "schema"


def test_integrity_is_checked_before_writing(store_url, raw):
    with ProfileStore(store_url) as st:
        put(st)
    tamper(raw, "DROP TABLE qa_results")
    with pytest.raises(StoreError) as exc:
        ProfileStore(store_url)
    msg = str(exc.value)
    assert exc.value.kind == "damaged" and "qa_results" in msg and "restore" in msg and "\n" not in msg


def test_sqlite_damaged_page_is_found_on_open_for_writing(tmp_path):
    path = tmp_path / "p.sqlite"
    with ProfileStore(path) as st:
        for i in range(60):  # a few pages of profiles and index entries
            put(st, session=f"s{i}", details={"pad": "x" * 500})
    data = bytearray(path.read_bytes())
    page = 4096
    assert len(data) > 8 * page
    data[5 * page : 5 * page + 200] = b"\xa5" * 200  # garble the start of a page (not the header)
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError) as exc:
        ProfileStore(path)
    msg = str(exc.value)
    assert exc.value.kind == "damaged" and str(path) in msg and "sqlite3" in msg and ".recover" in msg
    assert "\n" not in msg


def test_not_a_database(tmp_path):
    path = tmp_path / "junk.sqlite"
    path.write_bytes(b"this is not sqlite" * 100)
    for create in (True, False):
        with pytest.raises(StoreError) as exc:
            ProfileStore(path, create=create)
        assert exc.value.kind == "damaged" and str(path) in str(exc.value)
    assert path.read_bytes() == b"this is not sqlite" * 100  # left as it was


def test_store_under_a_file_names_the_file(tmp_path):
    blocker = tmp_path / "profiles"
    blocker.write_text("a file where a directory should be")
    with pytest.raises(StoreError) as exc:
        ProfileStore(blocker / "harp.sqlite")
    assert str(exc.value) == (
        f"{blocker / 'harp.sqlite'}: cannot open profile store: {blocker} is a file, not a directory"
    )


def test_unreachable_postgresql_is_one_line():
    import socket

    with socket.socket() as s:  # a loopback port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(StoreError) as exc:
        ProfileStore(f"postgresql://harp@127.0.0.1:{port}/harp")
    assert exc.value.kind == "unreachable" and "\n" not in str(exc.value) and str(port) in str(exc.value)


# ------------------------------------------------------------------ concurrency
def _writer(url, session, n, barrier):
    barrier.wait()
    with ProfileStore(url) as st:  # a brand-new store: all writers also race to create the schema
        for i in range(n):
            pid = put(st, session=session, focus=float(i), qa=verdict(0.01 * (i % 7)))
            st.record_verdict(pid, verdict(0.01 * (i % 7)))  # again: still once
            st.put_qa_result(verdict="PASS", reasons=[], metrics={"i": i}, session_dir=session)


def test_concurrent_writers_all_succeed_once(store_url):
    ctx = mp.get_context("spawn")
    n_proc, n = 2, 12
    barrier = ctx.Barrier(n_proc)
    procs = [ctx.Process(target=_writer, args=(store_url, f"session-{k}", n, barrier)) for k in range(n_proc)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0] * n_proc
    with ProfileStore(store_url) as st:
        profiles = st.profiles()
        assert len(profiles) == n_proc * n
        assert {(p.provenance.session_dir, p.focus) for p in profiles} == {
            (f"session-{k}", float(i)) for k in range(n_proc) for i in range(n)
        }
        rows = list(st.qa_results())
        assert sum(r["origin"] == "session" for r in rows) == n_proc * n
        assert sum(r["origin"] == "command" for r in rows) == n_proc * n
        assert len(st.lenses()) == 1
        check_integrity(st.engine, st.location)
