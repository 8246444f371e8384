"""A ``harp qa`` run recorded again adds nothing: ``qa_results.record_key``.

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-07

* ``qa_results`` gains ``record_key`` (NULL: no key — every row written before, and every session
  verdict, which is kept once per profile by ``qa_results_session_verdict``) and a unique index on it,
  ``qa_results_record_key`` (NULLs are distinct on both backends): the row of a judged profile of a
  ``harp qa`` run carries its run's key, and ``harp qa`` run again after a commit that may or may not
  have been written reuses that key, so the row is inserted if absent, never twice.
* ``schema_version`` becomes 7, so that software older than this migration (which would write rows
  without a key, and read none) refuses the store.
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("qa_results", sa.Column("record_key", sa.Text))
    op.create_index("qa_results_record_key", "qa_results", ["record_key"], unique=True)
    op.get_bind().execute(sa.text("UPDATE schema_version SET version = 7"))
