"""Schema 2: free-form details kept with a profile (``details_json``).

Revision ID: 0002
Revises: 0001
Create Date: 2024-05-01
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("profiles", sa.Column("details_json", sa.Text, nullable=False, server_default="{}"))
    op.execute("UPDATE schema_version SET version = 2")
