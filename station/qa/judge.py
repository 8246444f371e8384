"""QA of a finished session: every profile judged, recorded and stored, after the executor.

:func:`judge_session` reads the profiles the session directory holds
(:func:`station.qa.verdicts.session_profiles`), judges each against the
configuration's ``qa`` thresholds (:func:`station.qa.verdicts.qa_verdict`), records each
verdict in the manifest (``qa``) and the store (``qa_results``, and with its profile),
measures the focus-interpolation error (leave one calibrated focus out,
``interpolation``) and records the session's verdict (``qa_session``). What it finds
is also said, one line each, through ``note`` (the console of ``harp session run``).

Judging again — a session resumed after a kill during QA or the report — records nothing
twice: a record equal to one written since the last profile was stored is not appended
again, and the store keeps a profile's verdict once per profile and session
(``record_verdict`` replaces it).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import station.qa.verdicts
from pipeline.model_file import read_model_file
from pipeline.plain import json_default
from station.profile import Profile, Verdict
from station.qa.verdicts import combine, interpolation_error, qa_verdict, session_measurements
from station.session import layout
from station.session.records import InterpolationError, QARecorded, Reopened, SessionVerdict, Stored


@dataclass(frozen=True)
class SessionQA:
    """The verdicts of a session: per profile (by focus index), overall, and the interpolation error."""

    profiles: Sequence[tuple[int, Profile]]
    verdicts: Sequence[Verdict]
    overall: str
    interpolation: Sequence[Any]


def _append_once(session: Any, record: Any) -> None:
    """Append ``record`` unless the same record was written since the last profile was stored
    (``stored`` / ``reopened``: a new round of QA)."""
    same = _normal(record.to_json())
    for r in reversed(session.typed):
        if isinstance(r, (Stored, Reopened)):
            break
        if r.kind == record.kind and _normal(r.to_json()) == same:
            return
    session.append(record)


def _normal(d: dict) -> Any:
    """``d`` as it reads back from the manifest (JSON types)."""
    return json.loads(json.dumps(d, default=json_default))


def _in_store(store: Any, session_dir: str, focus: float) -> bool:
    """Whether the store holds this session's verdict for a focus setting without a stored profile."""
    return any(
        r.get("profile_id") is None and r.get("focus") == focus for r in store.qa_results(session_dir=session_dir)
    )


def foreign_store_problem(session: Any, store: Any) -> str | None:
    """Why ``store`` is not the store a session stored its profiles in, before it is resumed or repaired into it:
    the first focus setting whose recorded store id is not its profile there (another store's ids are another
    lens's rows here, whose verdicts :func:`judge_session` would otherwise take), as one line with what to do;
    None when every stored profile the session holds is its own row there. A profile file that cannot be read
    (damaged: a repair re-derives it) is not asked."""
    stored = session.stored_ids()
    for f, path in layout.profile_files(session.path):
        pid = stored.get(f)
        if pid is None:
            continue
        try:
            p = Profile.from_model_file(read_model_file(path))
        except (OSError, ValueError, KeyError, TypeError):
            continue
        focus = p.focus if p.focus is not None else session.config.focus_settings[f]
        problem = store.stored_as_problem(
            pid, (p.provenance.session_dir, focus), "nothing was captured, fitted or stored"
        )
        if problem is not None:
            return problem
    return None


def judge_session(
    session: Any, *, store: Any = None, note: Callable[[str], None] = lambda _t: None
) -> SessionQA | None:
    """Judge, record and say the QA of every profile of an open session directory (None: no profile yet)."""
    config = session.config
    profiles = station.qa.verdicts.session_profiles(session.path)  # looked up now: tests replace it
    if not profiles:
        return None
    stored = session.stored_ids()
    verdicts = []
    for f, p in profiles:
        focus = p.focus if p.focus is not None else config.focus_settings[f]
        # the stored model judged on the edges it was fitted on (kept in measurements/)
        v = qa_verdict(p, config.qa, measurements=session_measurements(session, f))
        verdicts.append(v)
        pid = stored.get(f)
        _append_once(
            session,
            QARecorded(
                f, v.verdict, list(v.reasons), dict(v.metrics), [c.to_dict() for c in v.checks], dict(v.thresholds)
            ),
        )
        if store is not None:
            session_dir = str(session.path.resolve())
            if pid is not None:  # the profile's own verdict, once per profile however often resumed
                # checked to be this profile's row: an id recorded in another store is another lens's in this one
                store.record_verdict(pid, v, session_dir=session_dir, stored_as=(p.provenance.session_dir, focus))
            elif not _in_store(store, session_dir, focus):  # no stored profile: one history row, once
                store.put_qa_result(verdict=v, session_dir=session_dir, focus=focus)
        note(
            f"QA focus {focus:g}: [{'green' if v.passed else 'red'}]{v.verdict}[/] "
            + "; ".join(c.text for c in v.checks if c.passed is (False if not v.passed else True))
        )
    w, h = profiles[0][1].width, profiles[0][1].height
    try:
        loo = interpolation_error(
            {(p.focus if p.focus is not None else config.focus_settings[f]): p.model for f, p in profiles}, w, h
        )
    except ValueError as exc:
        loo = []
        note(f"focus interpolation: not available ({exc})")
    for e in loo:
        _append_once(session, InterpolationError(e.focus, e.rms_px, e.max_px))
        note(
            f"focus interpolation error at {e.focus:g} (left out, interpolated from the "
            f"others): RMS {e.rms_px:.4f} px, max {e.max_px:.4f} px"
        )
    overall = combine(verdicts)
    _append_once(session, SessionVerdict(overall))
    note(f"QA verdict: [{'bold green' if overall == 'PASS' else 'bold red'}]{overall}")
    return SessionQA(profiles, verdicts, overall, loo)
