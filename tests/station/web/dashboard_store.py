"""A store for the dashboard tests: the real session's lens and a few more of its model (test helper).

The real lens (DEMO-0001) comes from the shared archive (one real session, tests/station/archive.py):
its two profiles, with the session directory they name (frames, bootstrap maps; no report). The
other lenses of the model are that lens's profiles with their distortion scaled (the radial and
tangential terms times a factor) and their holdout d changed, judged afresh by the station's QA
(:func:`station.qa.verdicts.qa_verdict` with the session's thresholds) and stored under their own
serials and sessions (which do not exist on disk), dated :data:`DAYS_AGO` days before the real one
(``put_profile(stored_at=...)``) so that the dashboard has days to filter. :data:`LENSES` is the
plan, from which the tests compute what the pages must show.
"""

from __future__ import annotations

import datetime as dt
import shutil
from dataclasses import replace
from pathlib import Path

from station.config import load_config
from station.store import ProfileStore

# serial, station, distortion factor, holdout d factor
LENSES = (
    ("DEMO-0002", "line-1", 0.97, 1.10),
    ("DEMO-0003", "line-2", 1.02, 0.95),
    ("DEMO-0004", "line-2", 1.05, 1.20),
    ("DEMO-0005", "line-1", 0.99, 1.05),
    ("DEMO-0006", "line-2", 1.60, 30.0),  # a lens that fails QA (holdout d 0.09 px > 0.05) and drifts
)
DAYS_AGO = {"DEMO-0002": 3, "DEMO-0003": 3, "DEMO-0004": 2, "DEMO-0005": 1, "DEMO-0006": 1}
"""How many days before the real session each added lens is dated (at 09:00 UTC)."""


def _scaled(model, factor: float):
    d = model.to_dict()
    d["k"] = [d["k"][0], *(factor * k for k in d["k"][1:])]
    d["tangential"] = [factor * t for t in d.get("tangential", [])]
    return type(model).from_dict(d)


def build_store(archive, dst: Path) -> tuple[Path, dict]:
    """A copy of the archive's store with :data:`LENSES` added; returns it and ``{serial: [profiles]}``
    as stored (with their ids)."""
    from station.qa.verdicts import qa_verdict

    dst.mkdir(parents=True, exist_ok=True)
    path = dst / "profiles.sqlite"
    shutil.copy(archive.store, path)
    cfg = load_config(archive.config)
    out: dict[str, list] = {}
    with ProfileStore(path) as st:
        real = sorted(st.profiles(), key=lambda p: p.focus)
        out[archive.serial] = real
        today = dt.datetime.fromisoformat(min(p.stored_at for p in real)).date()
        for serial, station, dist, hold in LENSES:
            out[serial] = []
            day = today - dt.timedelta(days=DAYS_AGO[serial])
            when = dt.datetime.combine(day, dt.time(9, 0), dt.UTC).isoformat()
            for p in real:
                h = p.merit.holdout
                merit = replace(p.merit, holdout=replace(h, d=h.d * hold, d_max=h.d_max * hold))
                q = p.with_(
                    id=None,
                    qa=None,  # another lens: judged afresh below, not against the real lens's recorded verdict
                    lens=replace(p.lens, serial=serial),
                    model=_scaled(p.model, dist),
                    merit=merit,
                    provenance=replace(
                        p.provenance, station=station, session_dir=str(dst / "sessions" / f"{serial}-s1")
                    ),
                )
                q = q.with_(qa=qa_verdict(q, cfg.qa))
                pid = st.put_profile(q, stored_at=when)
                out[serial].append(st.profile(pid))
    return path, out


def copy_into(src: Path, url: str) -> None:
    """Every profile of the SQLite store ``src`` stored again in the store at ``url`` (oldest first)."""
    with ProfileStore(src, create=False) as a, ProfileStore(url) as b:
        for p in sorted(a.profiles(), key=lambda p: p.id):
            b.put_profile(p.with_(id=None), stored_at=p.stored_at)
