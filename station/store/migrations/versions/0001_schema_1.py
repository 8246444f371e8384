"""Schema 1: lenses, cameras, profiles (flat figures), qa_results, schema_version.

Revision ID: 0001
Revises:
Create Date: 2024-05-01

The tables as SQLite stores of schema version 1 hold them; a store of that version is stamped
at this revision and upgraded from here.
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def _identity_table(name: str) -> None:
    op.create_table(
        name,
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("maker", sa.Text, nullable=False),
        sa.Column("model", sa.Text, nullable=False),
        sa.Column("serial", sa.Text, nullable=False),
        sa.UniqueConstraint("maker", "model", "serial"),
    )


def upgrade() -> None:
    op.create_table("schema_version", sa.Column("version", sa.Integer, nullable=False))
    op.execute("INSERT INTO schema_version (version) VALUES (1)")
    _identity_table("lenses")
    _identity_table("cameras")
    op.create_table(
        "profiles",
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
        sa.UniqueConstraint("session_dir", "focus"),
    )
    op.create_index("profiles_lens_focus", "profiles", ["lens_id", "focus"])
    op.create_table(
        "qa_results",
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("profile_id", sa.Integer, sa.ForeignKey("profiles.id")),
        sa.Column("session_dir", sa.Text),
        sa.Column("verdict", sa.Text, nullable=False),
        sa.Column("reasons_json", sa.Text, nullable=False),
        sa.Column("metrics_json", sa.Text, nullable=False),
        sa.Column("created_at", sa.Text, nullable=False),
        sa.CheckConstraint("verdict IN ('PASS', 'FAIL')", name="qa_results_verdict"),
    )
