"""Profile store: a real SQLite file, WAL, migrations, concurrent writers."""

import multiprocessing as mp
import sqlite3

import pytest

from pipeline.models import model_from_dict
from station.config import Identity
from station.profile import Figures, Holdout, Merit, Profile, Provenance
from station.store import MIGRATIONS, SCHEMA_VERSION, ProfileStore, StoreError

LENS = ("Acme", "50mm", "S1")
CAM = ("Cam", "Body", "C1")
MODEL = {"model": "radial", "center": [1.0, 2.0], "k": [1.0, 0.01], "scale": 100.0}


def put(store, session="sess", focus=0.5, lens=LENS, holdout_d=0.012, details=None):
    return store.put_profile(
        Profile(
            model_from_dict(MODEL),
            640,
            480,
            merit=Merit(fit=Figures(0.01, 0.02), holdout=Holdout(holdout_d, 0.03)),
            lens=Identity(*lens),
            camera=Identity(*CAM),
            focus=focus,
            provenance=Provenance(software="harp-station 0.1.0", station="st", session_dir=session),
            details=details or {},
        )
    )


def test_roundtrip_and_wal(tmp_path):
    path = tmp_path / "p.sqlite"
    with ProfileStore(path) as st:
        pid = put(st)
        assert st.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert st.schema_version() == SCHEMA_VERSION
    with ProfileStore(path) as st:
        p = st.profile(pid)
        assert p.lens == Identity(*LENS) and p.camera == Identity(*CAM) and p.model.to_dict() == MODEL
        assert p.focus == 0.5
        assert p.merit.holdout.d == 0.012 and p.merit.field_uncertainty is None
        assert st.find_lens("S1")[0] == st.find_lens("acme 50")[0] == st.find_lens(f"#{p.id}")[0]


def test_same_session_focus_updates(tmp_path):
    with ProfileStore(tmp_path / "p.sqlite") as st:
        a = put(st, holdout_d=0.5)
        b = put(st, holdout_d=0.1)
        put(st, session="other")
        assert a == b
        assert len(st.profiles()) == 2
        assert st.profile(a).merit.holdout.d == 0.1
        lens_id = st.find_lens("S1")[0]
        assert len(st.latest_by_focus(lens_id)) == 1


def test_ambiguous_and_missing_lens(tmp_path):
    with ProfileStore(tmp_path / "p.sqlite") as st:
        put(st)
        put(st, lens=("Acme", "35mm", "S2"), session="b")
        with pytest.raises(StoreError, match="matches 2 lenses"):
            st.find_lens("acme")
        with pytest.raises(StoreError, match="no lens matching"):
            st.find_lens("zeiss")


def test_migrates_v1_file(tmp_path):
    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    db.execute("INSERT INTO schema_version VALUES (1)")
    MIGRATIONS[0](db)
    db.execute("INSERT INTO lenses (maker, model, serial) VALUES ('A','B','C')")
    db.commit()
    db.close()
    with ProfileStore(path) as st:
        assert st.schema_version() == SCHEMA_VERSION == 3
        assert st.lenses() == [(1, "A", "B", "C")]
        pid = put(st, details={"cv": [0.1]})
        assert st.profile(pid).details == {"cv": [0.1]}


def test_newer_schema_refused(tmp_path):
    path = tmp_path / "new.sqlite"
    with ProfileStore(path) as st:
        st.db.execute("UPDATE schema_version SET version = 99")
    with pytest.raises(StoreError, match="newer than this software"):
        ProfileStore(path)


def test_not_a_database(tmp_path):
    path = tmp_path / "junk.sqlite"
    path.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(StoreError, match="not a usable profile store"):
        ProfileStore(path)


def _writer(path, session, n, barrier):
    barrier.wait()
    with ProfileStore(path) as st:
        for i in range(n):
            put(st, session=session, focus=float(i))
            st.put_qa_result(verdict="PASS", reasons=[], metrics={"i": i}, session_dir=session)


def test_two_processes_write_concurrently(tmp_path):
    path = tmp_path / "shared.sqlite"  # brand-new file: both also race to create the schema
    ctx = mp.get_context("spawn")
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_writer, args=(str(path), f"session-{k}", 20, barrier)) for k in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0, 0]
    with ProfileStore(path) as st:
        profiles = st.profiles()
        assert len(profiles) == 40
        assert {p.provenance.session_dir for p in profiles} == {"session-0", "session-1"}
        assert len(list(st.qa_results())) == 40
        assert st.db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert len(st.lenses()) == 1


def test_store_under_a_file_names_the_file(tmp_path):
    blocker = tmp_path / "profiles"
    blocker.write_text("a file where a directory should be")
    with pytest.raises(StoreError) as exc:
        ProfileStore(blocker / "harp.sqlite")
    assert str(exc.value) == (
        f"{blocker / 'harp.sqlite'}: cannot open profile store: {blocker} is a file, not a directory"
    )
