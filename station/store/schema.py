"""The store's tables at the newest schema revision (SQLAlchemy Core), the same for SQLite and PostgreSQL.

* ``lenses`` / ``cameras``: one row per (maker, model, serial).
* ``profiles``: one :class:`station.profile.Profile` per row — a correction of one lens on one
  camera at one focus setting — keyed by (``session_dir``, ``focus``) so that storing it again
  (a resumed session) replaces it. The figures that lists and queries need are columns (fit and
  holdout d / d_max, field uncertainty, ``distortion_max`` / ``distortion_rms`` of the correction
  as QA measured them, ``verdict``); the whole typed record (spec, selection, merit, provenance,
  the verdict with its thresholds and every check) is kept as JSON text
  (:meth:`~station.profile.Profile.to_row`). ``verdict`` is ``PASS``, ``FAIL`` or NULL (not judged);
  ``intrinsics_json`` the camera matrix measured with the profile's distortion (NULL: none);
  ``focal`` the focal length setting of a zoom lens, mm (NULL: a fixed lens).
* ``qa_results``: QA verdicts as judged, with the checks and thresholds: ``origin = 'session'``
  is the session's own verdict of its profile (at most one per profile: a resumed session replaces
  it), ``origin = 'command'`` one per run of ``harp qa`` and judged profile. ``record_key`` (unique; NULL:
  none, every row written before revision 0007 and every session verdict) names a command's row, so that
  the same run recorded again — ``harp qa`` run again after a commit that may or may not have been
  written — adds nothing (:meth:`~station.store.database.ProfileStore.put_qa_result`).
* ``schema_version``: kept for software older than the Alembic migrations, which reads it and
  refuses a store newer than itself; ``alembic_version`` holds the revision.

The migrations that build these tables live in ``station/store/migrations/versions`` (one chain for
both backends; revisions 0001–0003 are the schema versions 1–3 of the SQLite stores written before,
so such a file is stamped at its version and upgraded in place). :data:`HEAD` is the newest revision.
"""

from __future__ import annotations

import sqlalchemy as sa

REVISIONS = ("0001", "0002", "0003", "0004", "0005", "0006", "0007")
"""Every migration revision, oldest first (a test checks them against the migration scripts)."""

HEAD = REVISIONS[-1]
"""The revision this software writes."""

LEGACY_VERSIONS = {1: "0001", 2: "0002", 3: "0003"}
"""``schema_version`` of a store written before the Alembic migrations -> the revision it equals."""

SCHEMA_VERSION = 7
"""What ``schema_version`` holds at :data:`HEAD` (greater than any version older software knows)."""

metadata = sa.MetaData()

lenses = sa.Table(
    "lenses",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("maker", sa.Text, nullable=False),
    sa.Column("model", sa.Text, nullable=False),
    sa.Column("serial", sa.Text, nullable=False),
    sa.UniqueConstraint("maker", "model", "serial"),
)

cameras = sa.Table(
    "cameras",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("maker", sa.Text, nullable=False),
    sa.Column("model", sa.Text, nullable=False),
    sa.Column("serial", sa.Text, nullable=False),
    sa.UniqueConstraint("maker", "model", "serial"),
)

profiles = sa.Table(
    "profiles",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("lens_id", sa.Integer, sa.ForeignKey("lenses.id"), nullable=False),
    sa.Column("camera_id", sa.Integer, sa.ForeignKey("cameras.id"), nullable=False),
    sa.Column("focus", sa.Float, nullable=False),
    sa.Column("model_name", sa.Text, nullable=False),
    sa.Column("model_json", sa.Text, nullable=False),
    sa.Column("width", sa.Integer, nullable=False),
    sa.Column("height", sa.Integer, nullable=False),
    sa.Column("fit_d", sa.Float),
    sa.Column("fit_d_max", sa.Float),
    sa.Column("holdout_d", sa.Float),
    sa.Column("holdout_d_max", sa.Float),
    sa.Column("field_uncertainty_rms", sa.Float),
    sa.Column("field_uncertainty_max", sa.Float),
    sa.Column("session_dir", sa.Text, nullable=False),
    sa.Column("station_id", sa.Text, nullable=False),
    sa.Column("software_version", sa.Text, nullable=False),
    sa.Column("created_at", sa.Text, nullable=False),
    sa.Column("details_json", sa.Text, nullable=False, server_default="{}"),
    sa.Column("spec_json", sa.Text),
    sa.Column("selection_json", sa.Text, nullable=False, server_default="{}"),
    sa.Column("merit_json", sa.Text),
    sa.Column("provenance_json", sa.Text, nullable=False, server_default="{}"),
    sa.Column("qa_json", sa.Text),
    sa.Column("verdict", sa.Text),
    sa.Column("distortion_max", sa.Float),
    sa.Column("distortion_rms", sa.Float),
    sa.Column("intrinsics_json", sa.Text),
    sa.Column("focal", sa.Float),
    sa.UniqueConstraint("session_dir", "focus"),
    sa.CheckConstraint("verdict IN ('PASS', 'FAIL')", name="profiles_verdict"),
)
sa.Index("profiles_lens_focus", profiles.c.lens_id, profiles.c.focus)
sa.Index("profiles_created", profiles.c.created_at)
sa.Index("profiles_lens_focal_focus", profiles.c.lens_id, profiles.c.focal, profiles.c.focus)

qa_results = sa.Table(
    "qa_results",
    metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("profile_id", sa.Integer, sa.ForeignKey("profiles.id")),
    sa.Column("session_dir", sa.Text),
    sa.Column("verdict", sa.Text, nullable=False),
    sa.Column("reasons_json", sa.Text, nullable=False),
    sa.Column("metrics_json", sa.Text, nullable=False),
    sa.Column("created_at", sa.Text, nullable=False),
    sa.Column("focus", sa.Float),
    sa.Column("checks_json", sa.Text),
    sa.Column("thresholds_json", sa.Text),
    sa.Column("origin", sa.Text, nullable=False, server_default="command"),
    sa.Column("record_key", sa.Text),
    sa.CheckConstraint("verdict IN ('PASS', 'FAIL')", name="qa_results_verdict"),
    sa.CheckConstraint("origin IN ('session', 'command')", name="qa_results_origin"),
)
sa.Index(
    "qa_results_session_verdict",
    qa_results.c.profile_id,
    unique=True,
    sqlite_where=qa_results.c.origin == "session",
    postgresql_where=qa_results.c.origin == "session",
)
sa.Index("qa_results_record_key", qa_results.c.record_key, unique=True)

schema_version = sa.Table("schema_version", metadata, sa.Column("version", sa.Integer, nullable=False))

TABLES = ("lenses", "cameras", "profiles", "qa_results", "schema_version")
"""The tables a store at :data:`HEAD` has (checked when a store is opened for writing)."""
