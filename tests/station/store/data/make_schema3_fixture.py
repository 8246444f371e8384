"""Write store-schema3.sqlite with the store code before the Alembic migrations (schema version 3).

Run from a checkout of commit 0fc7b6f (the last with station/store.py as one module), e.g.
``git worktree add /tmp/old 0fc7b6f && cd /tmp/old && python PATH/TO/make_schema3_fixture.py OUT.sqlite``.
Kept with the file it wrote so the fixture can be rebuilt and read; not run by the tests.
"""

# ruff: noqa
import sys, json, sqlite3
from pathlib import Path
from pipeline.models import model_from_dict
from station.config import Identity
from station.profile import Figures, Holdout, Merit, Profile, Provenance, UncertaintySummary, Verdict, Check
from station.store import ProfileStore, SCHEMA_VERSION

assert SCHEMA_VERSION == 3
out = Path(sys.argv[1])
out.unlink(missing_ok=True)
MODEL = {"model": "radial", "center": [320.0, 240.0], "k": [1.0, 0.01], "scale": 400.0}
with ProfileStore(out) as st:
    ids = []
    for serial, session, verdict in (("S1", "/sessions/a", "PASS"), ("S2", "/sessions/b", "FAIL")):
        for focus in (0.0, 0.5, 1.0):
            p = Profile(
                model_from_dict(MODEL),
                640,
                480,
                merit=Merit(
                    fit=Figures(0.01, 0.02),
                    holdout=Holdout(
                        0.012 if verdict == "PASS" else 0.2, 0.03, "leave one orientation out", (0.011, 0.013)
                    ),
                    field_uncertainty=UncertaintySummary(0.001, 0.004, 12),
                ),
                lens=Identity("Acme", "12mm", serial),
                camera=Identity("Cam", "Body", "C1"),
                focus=focus,
                provenance=Provenance(
                    created_utc="2024-05-01T10:00:00Z",
                    software="harp-station 0.1.0",
                    station="line-1",
                    session_dir=session,
                ),
            )
            pid = st.put_profile(p)
            ids.append(pid)
            hd = p.merit.holdout.d
            v = Verdict(
                verdict,
                () if verdict == "PASS" else (f"holdout d {hd:.4f} px > 0.05 px",),
                {"holdout_d_px": hd, "distortion_max_px": 1.25, "distortion_rms_px": 0.5},
                (Check("holdout_d", hd, "<=", 0.05, verdict == "PASS", f"holdout d {hd:.4f} px <= 0.05 px"),),
                {"max_holdout_d_px": 0.05, "max_distortion_px": None, "max_reference_deviation_px": None},
            )
            # the session's QA, recorded twice for the same profile (the resume duplication of issue 14)
            for _ in range(2):
                st.put_qa_result(
                    verdict=v.verdict,
                    reasons=list(v.reasons),
                    metrics=dict(v.metrics),
                    profile_id=pid,
                    session_dir=session,
                )
            st.record_verdict(pid, v)
    # a `harp qa LENS` record (no session) and a `harp qa SESSION` record (no profile id)
    st.put_qa_result(verdict="PASS", reasons=[], metrics={"holdout_d_px": 0.012, "focus": 0.5}, profile_id=ids[1])
    st.put_qa_result(
        verdict="PASS", reasons=[], metrics={"holdout_d_px": 0.012, "focus": 0.5}, session_dir="/sessions/a"
    )
# a schema-2 style row: no typed columns (as written before schema 3), verdict unknown
db = sqlite3.connect(out)
db.execute(
    "UPDATE profiles SET spec_json=NULL, merit_json=NULL, qa_json=NULL, verdict=NULL, provenance_json='{}', details_json=? WHERE id=?",
    (
        json.dumps(
            {
                "holdout_per_orientation": [0.011, 0.013],
                "d_before": 1.5,
                "d_max_before": 4.0,
                "bootstrap_replicates": 12,
            }
        ),
        ids[0],
    ),
)
db.commit()
db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
db.execute("PRAGMA journal_mode=DELETE")
db.execute("VACUUM")
db.close()
print(out, out.stat().st_size)
