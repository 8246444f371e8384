"""Verdicts that bind (issues 9, 12, 14): QA results typed and once per profile, distortion as columns.

Revision ID: 0004
Revises: 0003
Create Date: 2024-06-01

* ``qa_results`` gains ``focus``, ``checks_json``, ``thresholds_json`` and ``origin``
  (``'session'``: the session's own verdict of its profile; ``'command'``: a run of ``harp qa``).
  Rows written before are ``'session'`` when they name both a profile and a session (the
  executor's records), else ``'command'``; the focus is taken from the metrics or the profile.
  A session's verdict is kept once per profile: of the duplicates a killed-and-resumed session
  left (issue 14), the newest is kept, and a unique index keeps it so.
* ``profiles`` gains ``distortion_max`` / ``distortion_rms`` (the correction's displacement over
  the image, modulo homography, as QA measured it), filled from the stored verdicts. A profile
  of schema 2 with no verdict of its own takes its session's newest verdict from ``qa_results``
  (reasons and figures; its checks were never stored).
* ``schema_version`` becomes 4, so that software older than these migrations refuses the store
  instead of writing rows it does not understand.

A row whose JSON cannot be read is left as it is (it is reported when read, not here).
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def _json(text):
    try:
        v = json.loads(text) if text else None
    except (TypeError, ValueError):
        return None
    return v if isinstance(v, dict) else None


def _num(v):
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and v == v else None


def upgrade() -> None:
    op.add_column("qa_results", sa.Column("focus", sa.Float))
    op.add_column("qa_results", sa.Column("checks_json", sa.Text))
    op.add_column("qa_results", sa.Column("thresholds_json", sa.Text))
    op.execute(
        "ALTER TABLE qa_results ADD COLUMN origin TEXT NOT NULL DEFAULT 'command'"
        " CHECK (origin IN ('session', 'command'))"
    )
    op.add_column("profiles", sa.Column("distortion_max", sa.Float))
    op.add_column("profiles", sa.Column("distortion_rms", sa.Float))
    conn = op.get_bind()

    # qa_results: origin, focus; one session verdict per profile (the newest)
    conn.execute(
        sa.text("UPDATE qa_results SET origin = 'session' WHERE profile_id IS NOT NULL AND session_dir IS NOT NULL")
    )
    conn.execute(
        sa.text(
            "DELETE FROM qa_results WHERE origin = 'session' AND id NOT IN "
            "(SELECT max(id) FROM qa_results WHERE origin = 'session' GROUP BY profile_id)"
        )
    )
    focus_of = dict(conn.execute(sa.text("SELECT id, focus FROM profiles")).all())
    for qid, pid, metrics in conn.execute(sa.text("SELECT id, profile_id, metrics_json FROM qa_results")).all():
        focus = _num((_json(metrics) or {}).get("focus"))
        if focus is None:
            focus = focus_of.get(pid)
        if focus is not None:
            conn.execute(sa.text("UPDATE qa_results SET focus = :f WHERE id = :i"), {"f": focus, "i": qid})
    op.create_index(
        "qa_results_session_verdict",
        "qa_results",
        ["profile_id"],
        unique=True,
        sqlite_where=sa.text("origin = 'session'"),
        postgresql_where=sa.text("origin = 'session'"),
    )
    op.create_index("profiles_created", "profiles", ["created_at"])

    # profiles: the verdict of a schema-2 row from its session's record; distortion columns
    session_qa = {
        pid: (verdict, reasons, metrics)
        for pid, verdict, reasons, metrics in conn.execute(
            sa.text("SELECT profile_id, verdict, reasons_json, metrics_json FROM qa_results WHERE origin = 'session'")
        ).all()
    }
    rows = conn.execute(sa.text("SELECT id, qa_json, verdict FROM profiles")).all()
    for pid, qa_json, verdict in rows:
        qa = _json(qa_json)
        if qa is None and verdict is None and pid in session_qa:
            v, reasons, metrics = session_qa[pid]
            try:
                reasons = json.loads(reasons)
            except (TypeError, ValueError):
                reasons = []
            qa = {"verdict": v, "reasons": reasons, "metrics": _json(metrics) or {}, "checks": [], "thresholds": {}}
            conn.execute(
                sa.text("UPDATE profiles SET qa_json = :q, verdict = :v WHERE id = :i"),
                {"q": json.dumps(qa), "v": v, "i": pid},
            )
        elif qa is not None and verdict is None and qa.get("verdict") in ("PASS", "FAIL"):
            conn.execute(sa.text("UPDATE profiles SET verdict = :v WHERE id = :i"), {"v": qa["verdict"], "i": pid})
        metrics = (qa or {}).get("metrics") or {}
        dmax, drms = _num(metrics.get("distortion_max_px")), _num(metrics.get("distortion_rms_px"))
        if dmax is not None or drms is not None:
            conn.execute(
                sa.text("UPDATE profiles SET distortion_max = :m, distortion_rms = :r WHERE id = :i"),
                {"m": dmax, "r": drms, "i": pid},
            )
    conn.execute(sa.text("UPDATE schema_version SET version = 4"))
