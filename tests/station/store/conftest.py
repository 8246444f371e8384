"""The store tests run against both backends: a real SQLite file and a real PostgreSQL server."""

import uuid

import pytest
import sqlalchemy as sa


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request, tmp_path):
    """A store location that does not exist yet: a file path in ``tmp_path``, or a new, empty
    database on the session's PostgreSQL server (tests/pg_server.py)."""
    if request.param == "sqlite":
        return str(tmp_path / "store" / "profiles.sqlite")
    server = request.getfixturevalue("postgres")
    return server.create_database(f"store_{uuid.uuid4().hex[:12]}")


@pytest.fixture
def raw(store_url):
    """A plain SQLAlchemy engine on the store's database, to tamper with it as a damaged file or a
    careless administrator would (foreign keys not enforced)."""
    from station.store.location import parse_store

    loc = parse_store(store_url)
    engine = sa.create_engine(loc.sqlalchemy_url)
    yield engine
    engine.dispose()


def tamper(engine, *statements):
    """Run SQL on the store's database with foreign keys off (SQLite pragma / PostgreSQL replica role)."""
    with engine.connect() as conn:
        if engine.dialect.name == "sqlite":
            conn.exec_driver_sql("PRAGMA foreign_keys = OFF")
        else:
            conn.exec_driver_sql("SET session_replication_role = replica")
        for s in statements:
            conn.execute(sa.text(s))
        conn.commit()
