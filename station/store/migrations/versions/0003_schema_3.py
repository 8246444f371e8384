"""Schema 3: the typed profile record (fit spec, selection, merit, provenance, QA verdict) as JSON columns.

Revision ID: 0003
Revises: 0002
Create Date: 2024-05-01

Rows of schema 2 keep NULL / '{}' here and are read from their flat figures and details.
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("profiles", sa.Column("spec_json", sa.Text))
    op.add_column("profiles", sa.Column("selection_json", sa.Text, nullable=False, server_default="{}"))
    op.add_column("profiles", sa.Column("merit_json", sa.Text))
    op.add_column("profiles", sa.Column("provenance_json", sa.Text, nullable=False, server_default="{}"))
    op.add_column("profiles", sa.Column("qa_json", sa.Text))
    # the same SQL on both backends (Alembic's add_column does not render a column CHECK)
    op.execute("ALTER TABLE profiles ADD COLUMN verdict TEXT CHECK (verdict IN ('PASS', 'FAIL'))")
    op.execute("UPDATE schema_version SET version = 3")
