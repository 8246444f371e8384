"""The measured camera matrix of a profile (issue 23): ``profiles.intrinsics_json``.

Revision ID: 0005
Revises: 0004
Create Date: 2024-07-01

* ``profiles`` gains ``intrinsics_json`` (NULL: no camera matrix measured): the
  :class:`pipeline.intrinsics.Intrinsics` record — fx, fy, cx, cy (and skew), their standard
  deviations and covariance, the reprojection and held-out errors, how it was measured and the
  digest of the distortion it was measured with — written by ``harp intrinsics``.
* ``schema_version`` becomes 5, so that software older than this migration refuses the store.
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("profiles", sa.Column("intrinsics_json", sa.Text))
    op.get_bind().execute(sa.text("UPDATE schema_version SET version = 5"))
