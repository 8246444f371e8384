"""What a session kept, read back for QA and its report: each accepted shot's measured
edges and each focus setting's bootstrap uncertainty map (written by the executor,
:mod:`station.session.evidence` says how). A file that is missing, damaged (checksum
against the manifest) or written by an incompatible version reads as None: the caller
says so or measures again. Light: no plotting library is imported here.
"""

from __future__ import annotations

from station.session.records import FitFailed, Fitted, ShotMeasured

_MEASUREMENTS: dict[tuple[str, str], tuple[tuple[int, int], object]] = {}
"""Measurements read, by (file, SHA-256), with the file's (size, mtime) when read: the store step,
QA and the report of one session read the same files. A file changed since (damaged, rewritten) is
read, and its checksum checked, again."""
_MEASUREMENTS_MAX = 512


def _stamp(path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


def stored_measurement(session, focus_idx: int, orientation_idx: int):
    """The ``ImageMeasurement`` the executor kept for the shot's current attempt, or None
    (no ``measurements/*.npz`` for it, or written by an incompatible version)."""
    from station.session.directory import SessionError  # defers cv2, numpy, yaml
    from station.session.evidence import measurement_from_arrays  # defers numpy

    rec = session.last(ShotMeasured, focus_idx=focus_idx, orientation_idx=orientation_idx)
    if rec is None or not rec.file or rec.attempt != session.attempt(focus_idx, orientation_idx):
        return None
    sha = rec.sha256
    path = session.path / rec.file
    key = (str(path), str(sha))
    stamp = _stamp(path)
    hit = _MEASUREMENTS.get(key)
    if sha and stamp is not None and hit is not None and hit[0] == stamp:
        return hit[1]
    try:
        m = measurement_from_arrays(session.read_arrays(rec.file, sha))
    except (OSError, ValueError, KeyError, SessionError):
        return None
    if sha and stamp is not None:
        if len(_MEASUREMENTS) >= _MEASUREMENTS_MAX:
            _MEASUREMENTS.clear()
        _MEASUREMENTS[key] = (stamp, m)
    return m


def measurement_problem(session, focus_idx: int, orientations) -> str | None:
    """Why a kept measurement of one of ``orientations`` (indices) at ``focus_idx`` cannot be read, as one
    line naming the file (``DIR/measurements/f0_o1_a0.npz: checksum does not match the manifest``), or None
    when none was recorded as kept that cannot be read (the session kept none, or they all read back)."""
    from station.session.directory import SessionError  # defers cv2, numpy, yaml
    from station.session.evidence import measurement_from_arrays  # defers numpy

    for o in orientations:
        rec = session.last(ShotMeasured, focus_idx=focus_idx, orientation_idx=o)
        if rec is None or not rec.file or rec.attempt != session.attempt(focus_idx, o):
            continue
        path = session.path / rec.file
        try:
            measurement_from_arrays(session.read_arrays(rec.file, rec.sha256))
        except SessionError as exc:
            return str(exc)
        except OSError as exc:
            return f"{path}: {exc.strerror or type(exc).__name__}"
        except (ValueError, KeyError) as exc:
            return f"{path}: cannot be read ({' '.join(str(exc).split()) or type(exc).__name__})"
    return None


def stored_uncertainty(session, focus_idx: int, model):
    """The bootstrap uncertainty map the executor kept for a focus setting, or None."""
    from station.session.directory import SessionError  # defers cv2, numpy, yaml
    from station.session.evidence import uncertainty_from_arrays  # defers numpy

    rec = session.last((Fitted, FitFailed), focus_idx=focus_idx)  # the last fit: a failed one has no map
    if not isinstance(rec, Fitted) or not rec.uncertainty_file:
        return None
    try:
        return uncertainty_from_arrays(session.read_arrays(rec.uncertainty_file, rec.uncertainty_sha256), model)
    except (OSError, ValueError, SessionError):
        return None
