"""Zoom lenses (issue 23): a profile's focal length setting, ``profiles.focal``.

Revision ID: 0006
Revises: 0005
Create Date: 2024-07-02

* ``profiles`` gains ``focal`` (mm; NULL: a fixed lens, every profile written before): a zoom
  lens is profiled per (focal length, focus). The current profile of a lens is then the newest of
  each (focal, focus) setting; a zoom session stores each focal length from its own session
  directory, so the key (``session_dir``, ``focus``) stays unique.
* an index on (``lens_id``, ``focal``, ``focus``) for the lookups by setting.
* ``schema_version`` becomes 6.
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("profiles", sa.Column("focal", sa.Float))
    op.create_index("profiles_lens_focal_focus", "profiles", ["lens_id", "focal", "focus"])
    op.get_bind().execute(sa.text("UPDATE schema_version SET version = 6"))
