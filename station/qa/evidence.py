"""What a session kept, read back for QA and its report: each accepted shot's measured
edges and each focus setting's bootstrap uncertainty map (written by the executor,
:mod:`station.session.evidence` says how). A file that is missing, damaged (checksum
against the manifest) or written by an incompatible version reads as None: the caller
says so or measures again. Light: no plotting library is imported here.
"""

from __future__ import annotations


def _last_record(session, kind: str, **match) -> dict | None:
    found = None
    for r in session.of_kind(kind):
        if all(r.get(k) == v for k, v in match.items()):
            found = r
    return found


def stored_measurement(session, focus_idx: int, orientation_idx: int):
    """The ``ImageMeasurement`` the executor kept for the shot's current attempt, or None
    (no ``measurements/*.npz`` for it, or written by an incompatible version)."""
    from station.session.directory import SessionError
    from station.session.evidence import measurement_from_arrays

    rec = _last_record(session, "measure", focus_idx=focus_idx, orientation_idx=orientation_idx)
    if rec is None or "file" not in rec or rec.get("attempt") != session.attempt(focus_idx, orientation_idx):
        return None
    try:
        return measurement_from_arrays(session.read_arrays(rec["file"], rec.get("sha256")))
    except (OSError, ValueError, KeyError, SessionError):
        return None


def stored_uncertainty(session, focus_idx: int, model):
    """The bootstrap uncertainty map the executor kept for a focus setting, or None."""
    from station.session.directory import SessionError
    from station.session.evidence import uncertainty_from_arrays

    rec = _last_record(session, "fit", focus_idx=focus_idx)
    if rec is None or not rec.get("uncertainty_file"):
        return None
    try:
        return uncertainty_from_arrays(
            session.read_arrays(rec["uncertainty_file"], rec.get("uncertainty_sha256")), model
        )
    except (OSError, ValueError, SessionError):
        return None
