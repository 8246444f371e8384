"""The SQL of the SQLite store schemas 1-3 exactly as the store code before the Alembic migrations
ran it (station/store.py at 0fc7b6f), to build old store files in tests."""

import sqlite3

V1 = """
    CREATE TABLE lenses (
        id INTEGER PRIMARY KEY,
        maker TEXT NOT NULL, model TEXT NOT NULL, serial TEXT NOT NULL,
        UNIQUE (maker, model, serial));
    CREATE TABLE cameras (
        id INTEGER PRIMARY KEY,
        maker TEXT NOT NULL, model TEXT NOT NULL, serial TEXT NOT NULL,
        UNIQUE (maker, model, serial));
    CREATE TABLE profiles (
        id INTEGER PRIMARY KEY,
        lens_id INTEGER NOT NULL REFERENCES lenses(id),
        camera_id INTEGER NOT NULL REFERENCES cameras(id),
        focus REAL NOT NULL,
        model_name TEXT NOT NULL,
        model_json TEXT NOT NULL,
        width INTEGER NOT NULL, height INTEGER NOT NULL,
        fit_d REAL, fit_d_max REAL,
        holdout_d REAL, holdout_d_max REAL,
        field_uncertainty_rms REAL, field_uncertainty_max REAL,
        session_dir TEXT NOT NULL,
        station_id TEXT NOT NULL,
        software_version TEXT NOT NULL,
        created_at TEXT NOT NULL,
        UNIQUE (session_dir, focus));
    CREATE INDEX profiles_lens_focus ON profiles (lens_id, focus);
    CREATE TABLE qa_results (
        id INTEGER PRIMARY KEY,
        profile_id INTEGER REFERENCES profiles(id),
        session_dir TEXT,
        verdict TEXT NOT NULL CHECK (verdict IN ('PASS', 'FAIL')),
        reasons_json TEXT NOT NULL,
        metrics_json TEXT NOT NULL,
        created_at TEXT NOT NULL);
"""

V2 = "ALTER TABLE profiles ADD COLUMN details_json TEXT NOT NULL DEFAULT '{}'"

V3 = [
    f"ALTER TABLE profiles ADD COLUMN {column}"
    for column in (
        "spec_json TEXT",
        "selection_json TEXT NOT NULL DEFAULT '{}'",
        "merit_json TEXT",
        "provenance_json TEXT NOT NULL DEFAULT '{}'",
        "qa_json TEXT",
        "verdict TEXT CHECK (verdict IN ('PASS', 'FAIL'))",
    )
]


def legacy_schema(db: sqlite3.Connection, version: int) -> None:
    """Create the tables of schema ``version`` (1-3) and its ``schema_version`` row in ``db``."""
    db.execute("CREATE TABLE schema_version (version INTEGER NOT NULL)")
    db.execute("INSERT INTO schema_version VALUES (?)", (version,))
    for stmt in V1.split(";"):
        if stmt.strip():
            db.execute(stmt)
    if version >= 2:
        db.execute(V2)
    if version >= 3:
        for stmt in V3:
            db.execute(stmt)
    db.commit()
