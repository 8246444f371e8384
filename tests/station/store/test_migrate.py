"""Migrations: one Alembic chain for both backends; SQLite stores written before it upgrade in place.

``data/store-schema3.sqlite`` was written by the store code of main at 0fc7b6f (schema version 3,
before this package existed) with ``data/make_schema3_fixture.py``: two lenses x three focus
settings, the session's QA recorded twice per profile (the resume duplication of issue 14), one
``harp qa LENS`` and one ``harp qa SESSION`` record, and one row taken back to what schema 2 wrote
(no typed columns, no verdict of its own).
"""

import shutil
import sqlite3
from pathlib import Path

import sqlalchemy as sa

from station.store import ProfileStore
from station.store.migrate import MIGRATIONS_DIR, check_integrity
from station.store.schema import HEAD, REVISIONS, metadata
from tests.station.store.legacy import legacy_schema
from tests.station.store.test_database import put, verdict

DATA = Path(__file__).parent / "data"


def test_revisions_are_the_migration_scripts():
    from alembic.config import Config
    from alembic.script import ScriptDirectory

    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    scripts = ScriptDirectory.from_config(cfg)
    chain = [s.revision for s in reversed(list(scripts.walk_revisions()))]
    assert tuple(chain) == REVISIONS and scripts.get_current_head() == HEAD


def test_migrations_build_the_tables_the_queries_use(store_url, raw):
    ProfileStore(store_url).close()
    insp = sa.inspect(raw)
    for table in metadata.sorted_tables:
        got = {c["name"] for c in insp.get_columns(table.name)}
        assert got == {c.name for c in table.columns}, table.name
    unique = {tuple(ix["column_names"]) for ix in insp.get_indexes("qa_results") if ix["unique"]}
    assert ("profile_id",) in unique and ("record_key",) in unique


def test_a_store_at_revision_0006_opens_and_its_qa_history_gains_keys(store_url, raw):
    """A store the previous software left (revision 0006, a ``harp qa`` row without a key) is upgraded
    when opened: its row is kept, keyless, and rows recorded again under one key are one row."""
    from alembic import command

    from station.store.engine import make_engine
    from station.store.location import parse_store
    from station.store.migrate import _alembic_config

    loc = parse_store(store_url)
    if loc.path is not None:
        loc.path.parent.mkdir(parents=True)
    engine = make_engine(loc)
    with engine.begin() as conn:
        command.upgrade(_alembic_config(conn), "0006")
        conn.execute(
            sa.text(
                "INSERT INTO qa_results (session_dir, verdict, reasons_json, metrics_json, created_at, focus, origin)"
                " VALUES ('/s', 'PASS', '[]', '{}', '2026-01-01T00:00:00+00:00', 0.5, 'command')"
            )
        )
    engine.dispose()
    with raw.connect() as conn:
        assert conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar() == "0006"

    with ProfileStore(store_url, create=False) as st:
        (old,) = st.qa_results()
        assert old["record_key"] is None and old["session_dir"] == "/s" and old["focus"] == 0.5
        check_integrity(st.engine, st.location)
        for _ in range(2):
            st.put_qa_result(verdict=verdict(0.01), session_dir="/s", focus=0.5, key="run/0")
        st.put_qa_result(verdict=verdict(0.01), session_dir="/s", focus=0.5)
        assert [r["record_key"] for r in st.qa_results()] == [None, "run/0", None]
    with raw.connect() as conn:
        assert conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar() == HEAD
        assert conn.execute(sa.text("SELECT version FROM schema_version")).scalar() == 7


def test_schema3_store_written_by_the_old_code_migrates_in_place(tmp_path):
    path = tmp_path / "old.sqlite"
    shutil.copy(DATA / "store-schema3.sqlite", path)
    db = sqlite3.connect(path)
    before = {t: db.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in ("lenses", "profiles", "qa_results")}
    db.close()
    assert before == {"lenses": 2, "profiles": 6, "qa_results": 14}

    with ProfileStore(path, create=False) as st:  # reading an old store upgrades it (it exists)
        profiles = st.profiles()
        assert len(profiles) == 6 and [l[3] for l in st.lenses()] == ["S1", "S2"]
        by = {(p.lens.serial, p.focus): p for p in profiles}
        # typed rows keep every figure; the verdict and its checks as recorded
        p = by[("S2", 0.5)]
        assert p.merit.holdout.d == 0.2 and p.merit.field_uncertainty.replicates == 12
        assert p.qa.verdict == "FAIL" and p.qa.checks[0].passed is False and p.qa.thresholds["max_holdout_d_px"] == 0.05
        # the schema-2 row: its figures from the flat columns, its verdict from its session's record
        p = by[("S1", 0.0)]
        assert p.merit.before.d == 1.5 and p.merit.holdout.per_orientation_d == (0.011, 0.013)
        assert p.qa.verdict == "PASS" and p.qa.metrics["distortion_max_px"] == 1.25
        # the session's verdicts once per profile; the two command records kept
        rows = list(st.qa_results())
        assert sum(r["origin"] == "session" for r in rows) == 6
        assert sorted(r["profile_id"] for r in rows if r["origin"] == "session") == sorted(p.id for p in profiles)
        assert sum(r["origin"] == "command" for r in rows) == 2
        assert all(r["focus"] == st.profile(r["profile_id"]).focus for r in rows if r["profile_id"])
        # failed lens S2: no current profile; S1: all three
        s1, s2 = (st.find_lens(s)[0] for s in ("S1", "S2"))
        assert [q.focus for q in st.latest_by_focus(s1)] == [0.0, 0.5, 1.0] and st.latest_by_focus(s2) == []
        # the dashboard's columns were filled from the stored verdicts
        assert {t.distortion_max for t in st.model_trend("Acme", "12mm")} == {1.25}
    with ProfileStore(path) as st:  # and it is whole, at the head revision, and writable
        check_integrity(st.engine, st.location)
        pid = put(st, session="new", qa=verdict(0.01))
        assert st.profile(pid).qa == verdict(0.01)
    db = sqlite3.connect(path)
    assert db.execute("SELECT version FROM schema_version").fetchone()[0] == 7  # old software now refuses it
    db.close()


def test_schema1_store_built_by_the_old_sql_migrates(tmp_path):
    # schema version 1 exactly as the first store code created it (tests/station/store/legacy.py)
    path = tmp_path / "v1.sqlite"
    db = sqlite3.connect(path)
    legacy_schema(db, 1)
    db.executescript(
        """
        INSERT INTO lenses (maker, model, serial) VALUES ('A', 'B', 'C');
        INSERT INTO cameras (maker, model, serial) VALUES ('K', 'L', 'M');
        INSERT INTO profiles VALUES (1, 1, 1, 0.5, 'radial',
            '{"model": "radial", "center": [1.0, 2.0], "k": [0.5], "scale": 100.0}', 640, 480,
            0.01, 0.02, 0.03, 0.04, NULL, NULL, '/s', 'st', '0.0.1', '2023-01-01T00:00:00+00:00');
        """
    )
    db.close()
    with ProfileStore(path) as st:
        (p,) = st.profiles()
        assert p.lens.serial == "C" and p.merit.holdout.d == 0.03 and p.qa is None
        assert p.provenance.software_version == "0.0.1"
        assert st.latest_by_focus(1)[0].id == 1  # not judged: current
        check_integrity(st.engine, st.location)


def test_two_processes_migrating_one_old_store_at_once(tmp_path):
    import multiprocessing as mp

    path = tmp_path / "old.sqlite"
    shutil.copy(DATA / "store-schema3.sqlite", path)
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_open_and_count, args=(str(path),)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0]
    with ProfileStore(path) as st:
        assert len(st.profiles()) == 6 and sum(r["origin"] == "session" for r in st.qa_results()) == 6


def _open_and_count(path):
    with ProfileStore(path) as st:
        assert len(st.profiles()) == 6
