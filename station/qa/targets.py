"""What ``harp qa`` judges, and with what (:mod:`station.cli.qa` parses and prints).

* :func:`session_targets` — every fitted profile of a session directory, each with the
  measurements the session kept for its focus setting;
* :func:`unfinished` — the focus settings of a session's plan that have no profile (why each, and what to
  do): ``harp qa`` gives no verdict for such a session unless asked for the profiles it has;
* :func:`lens_targets` — the newest profile of each focus setting of a stored lens, failed ones
  included (QA judges them all);
* :func:`attach_session_measurements` — for a stored profile, the measurements of the session
  it names, when that directory is at hand;
* :func:`thresholds_for` — the thresholds a target is judged with: the command line's over
  ``--config``'s over those it was calibrated under (the session's configuration, the stored
  verdict's) over the defaults;
* :func:`reference_model` — the golden reference's correction at a target's focus: a model
  file, a stored profile ``#id``, or a lens in the store (interpolated between its calibrated
  focus settings when needed);
* :func:`judge_targets` — every target judged (:func:`station.qa.verdicts.qa_verdict`), the
  overall verdict and the focus-interpolation error (:class:`Judgement`);
* :func:`write_qa_report` — the report of a judgement (:mod:`station.qa.report`): a session's
  evidence from its directory, a stored lens's from its profiles (:func:`lens_context`).

Every problem the user can fix is a :class:`QAInputError` (one line, exit 2).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.model_file import read_model_file
from station.config import ConfigError
from station.errors import HarpError
from station.profile import Profile, Verdict
from station.qa.evidence import measurement_problem
from station.qa.verdicts import (
    calibrated_thresholds,
    combine,
    interpolation_error,
    qa_verdict,
    session_measurements,
    session_profiles,
    thresholds_from,
)
from station.session import layout
from station.session.directory import SessionDir, SessionError
from station.session.records import FitFailed, Fitted

REPORT_BOOTSTRAP = 20
"""Bootstrap replicates of the report's uncertainty map when the configuration sets none."""

StoreOpener = Callable[[], AbstractContextManager[Any]]
"""Opens the profile store for reading (``with open_store() as store``)."""


class QAInputError(HarpError):
    """A one-line error for the user (exit 2)."""


@dataclass
class Target:
    """One profile to judge: its focus, where it comes from, and what it is judged with."""

    focus: float
    profile: Profile
    profile_id: int | None
    source: str
    focus_idx: int | None = None  # in the session the measurements come from
    measurements: Any = None  # station.qa.verdicts.Measurements, or None
    thresholds_from: str = "defaults"
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------- targets
def session_targets(session: Any) -> list[Target]:
    """Every profile of an open session (:class:`~station.session.directory.SessionDir`)."""
    profiles = session_profiles(session.path)
    if not profiles:
        raise QAInputError(f"{session.path}: session has no fitted profile yet")
    targets = []
    for f, p in profiles:
        target = Target(
            p.focus if p.focus is not None else session.config.focus_settings[f],
            p,
            p.id,
            str(session.path / layout.profile_file(f)),
            focus_idx=f,
            measurements=session_measurements(session, f),
        )
        if target.measurements is None:
            target.notes.append(_no_measurements(session, f))
        targets.append(target)
    return targets


def unfinished(session: Any) -> list[str]:
    """One phrase per focus setting of the session's plan (``focus_settings``) that has no profile file: why
    (its last fit failed, with the reason; else the session stopped before fitting or storing it). Empty for a
    session whose every focus setting has its profile."""
    have = {f for f, _path in layout.profile_files(session.path)}
    out = []
    for f, focus in enumerate(session.config.focus_settings):
        if f in have:
            continue
        fit = session.last((Fitted, FitFailed), focus_idx=f)
        why = f"its fit failed ({fit.failure})" if isinstance(fit, FitFailed) else "not fitted and stored yet"
        out.append(f"focus {focus:g} has no profile: {why}")
    return out


def unfinished_error(session: Any, missing: list[str]) -> QAInputError:
    """The one line ``harp qa`` gives for a session that is not finished (:func:`unfinished`): no verdict, since a
    PASS of the focus settings fitted so far would pass a lens calibrated at fewer than its plan's."""
    return QAInputError(
        f"{session.path}: the session is not finished ({'; '.join(missing)}): run harp session resume "
        f"{session.path} to finish it, then harp qa again (--partial judges the profiles it has)"
    )


def lens_targets(store: Any, lens_text: str) -> list[Target]:
    """The newest profile of each focus setting of the lens ``lens_text`` names, whatever its verdict."""
    lens = store.find_lens(lens_text)
    profiles = store.latest_by_focus(lens[0], allow_failed=True)
    if not profiles:
        raise QAInputError(f"lens {lens_text!r} has no profile")
    return [Target(p.focus, p, p.id, f"profile #{p.id}") for p in profiles]


def attach_session_measurements(target: Target, opened: dict[str, Any]) -> None:
    """The measurements of the session a stored profile names, when its directory is at hand
    (``opened``: the sessions opened so far, by directory, ``None`` for one that cannot be read;
    the caller closes them). What could not be had is said in ``target.notes``."""
    where = target.profile.provenance.session_dir
    if not where or not (Path(where) / layout.SESSION_FILE).is_file():
        target.notes.append(
            f"its session directory {where or '(none recorded)'} is not at hand: the model is judged without "
            "the measurements it was fitted on"
        )
        return
    if where not in opened:
        try:
            opened[where] = SessionDir.open(Path(where), read_only=True)
        except (SessionError, ConfigError, OSError, ValueError) as exc:
            opened[where] = None
            target.notes.append(f"its session {where} cannot be read ({exc}): judged without its measurements")
            return
    session = opened[where]
    if session is None:
        return
    hits = [f for f, v in enumerate(session.config.focus_settings) if math.isclose(v, target.focus, abs_tol=1e-9)]
    if not hits:
        target.notes.append(f"its session {where} has no focus setting {target.focus:g}: judged without measurements")
        return
    target.focus_idx = hits[0]
    target.measurements = session_measurements(session, hits[0])
    if target.measurements is None:
        problem = measurement_problem(session, hits[0], session.config.capture.fitted)
        target.notes.append(
            f"its session {where} kept no measurements at focus {target.focus:g}"
            if problem is None
            else f"{problem}: the model is judged without its session's measurements; run: harp session repair {where}"
        )


def _no_measurements(session: Any, focus_idx: int) -> str:
    """The note of a session's focus setting judged without its measurements: which kept file cannot be read
    and what to do, or that the session kept none."""
    problem = measurement_problem(session, focus_idx, session.config.capture.fitted)
    if problem is None:
        return "the session kept no measurements for this focus setting: stored figures judged"
    return (
        f"{problem}: stored figures judged, the holdout d not recomputed; run: harp session repair {session.path} "
        "(it fits the focus setting again from its frames)"
    )


# ------------------------------------------------------------- thresholds
def thresholds_for(
    target: Target, overrides: Mapping[str, float | None], *, config: Any = None, session: Any = None
) -> Any:
    """The thresholds (:class:`~station.config.QAConfig`) to judge ``target`` with: ``overrides``
    (the command line: ``max_holdout_d_px``, ``max_distortion_px``, ``max_reference_deviation_px``,
    ``None`` where not given) over ``config``'s (``--config``) over those it was calibrated under
    (``session``'s configuration, else the stored verdict's) over the defaults. Where they come
    from is set in ``target.thresholds_from``."""
    base: Any
    if config is not None:
        base, origin = config.qa, f"--config {config.path}"
    elif session is not None:
        base, origin = session.config.qa, "the session's configuration"
    elif (cal := calibrated_thresholds(target.profile)) is not None:
        base, origin = cal, "calibration"
    else:
        base, origin = None, "defaults (the profile records none)"
    if any(v is not None for v in overrides.values()):
        origin += " and the command line"
    target.thresholds_from = origin
    return thresholds_from(base, **overrides)


# -------------------------------------------------------------- reference
def reference_model(ref: str, open_store: StoreOpener, focus: float, width: int, height: int) -> Any:
    """The correction of the golden reference ``ref`` for a ``width`` x ``height`` profile at ``focus``:
    a harp model file, a stored profile ``#id``, or a lens in the store (its current profile at
    ``focus``, interpolated between its calibrated focus settings when needed)."""
    if Path(ref).is_file():
        try:
            mf = read_model_file(ref)
        except ValueError as exc:
            raise QAInputError(f"reference {exc}") from None  # the message starts with the file name
        if (mf.width, mf.height) != (width, height):
            raise QAInputError(f"reference {ref} is for {mf.width}x{mf.height} images, not {width}x{height}")
        return mf.model
    if "/" in ref or Path(ref).suffix.lower() in (".yaml", ".yml", ".json"):
        raise QAInputError(f"reference {ref}: no such model file")
    with open_store() as store:
        if ref.startswith("#") and ref[1:].isdigit():
            p = store.profile(int(ref[1:]))
            if p is None:
                raise QAInputError(f"no profile {ref} in {store.path}")
            profiles = [p]
        else:
            lens = store.find_lens(ref)
            profiles = store.latest_by_focus(lens[0])
    sizes = {(p.width, p.height) for p in profiles}
    if sizes != {(width, height)}:
        raise QAInputError(
            f"reference {ref!r} is for {', '.join(f'{w}x{h}' for w, h in sorted(sizes))} images, not {width}x{height}"
        )
    if len(profiles) == 1 and ref.startswith("#"):
        return profiles[0].model
    same = [p for p in profiles if math.isclose(p.focus, focus, abs_tol=1e-9)]
    if same:
        return same[0].model
    from pipeline.interpolate import interpolate_correction  # defers scipy

    try:
        return interpolate_correction({p.focus: p.model for p in profiles}, focus, width, height)
    except ValueError as exc:
        raise QAInputError(f"reference lens {ref!r} at focus {focus:g}: {exc}") from None


# -------------------------------------------------------------- judgement
@dataclass(frozen=True)
class Judgement:
    """The verdict of every target (in order), the thresholds each was judged with, the overall
    verdict and the leave-one-focus-out interpolation error (empty unless the targets share one
    image size and have distinct focus settings, three or more)."""

    verdicts: list[Verdict]
    thresholds: list[Any]
    overall: str
    interpolation: list[Any]


def judge_targets(
    targets: list[Target],
    overrides: Mapping[str, float | None],
    *,
    config: Any = None,
    session: Any = None,
    reference: str | None = None,
    open_store: StoreOpener | None = None,
    recompute: bool = True,
    opened: dict[str, Any] | None = None,
) -> Judgement:
    """Judge every target: of a stored lens (no ``session``) with the measurements of the session
    each profile names (:func:`attach_session_measurements`, sessions kept open in ``opened``),
    with the thresholds of :func:`thresholds_for`, against the ``reference`` (needs
    ``open_store`` for a stored one, and a reference threshold), recomputing the holdout d from
    the measurements unless ``recompute`` is false."""
    verdicts, used = [], []
    for t in targets:
        if session is None:
            attach_session_measurements(t, opened if opened is not None else {})
        thresholds = thresholds_for(t, overrides, config=config, session=session)
        used.append(thresholds)
        ref = None
        if reference is not None:
            if thresholds.max_reference_deviation_px is None:
                raise QAInputError(
                    "--reference needs a threshold: set qa.max_reference_deviation_px in the "
                    "configuration or give --max-reference-deviation PX"
                )
            if open_store is None:
                raise ValueError("a reference needs open_store")
            ref = reference_model(reference, open_store, t.focus, t.profile.width, t.profile.height)
        v = qa_verdict(t.profile, thresholds, reference=ref, measurements=t.measurements, recompute=recompute)
        note = v.metrics.get("holdout_note")
        if note:
            t.notes.append(f"holdout d {note}")
        verdicts.append(v)
    profiles = [t.profile for t in targets]
    interpolation: list[Any] = []
    if len({(p.width, p.height) for p in profiles}) == 1 and len({t.focus for t in targets}) == len(targets):
        interpolation = interpolation_error(
            {t.focus: t.profile.model for t in targets}, profiles[0].width, profiles[0].height
        )
    return Judgement(verdicts, used, combine(verdicts), interpolation)


# ----------------------------------------------------------------- report
def write_qa_report(
    directory: Path, title: str, targets: list[Target], judged: Judgement, session: Any, overlays: str | None = None
) -> Path:
    """Write the report of ``judged`` into ``directory`` (:func:`station.qa.report.write_report`):
    for a session, each focus setting's evidence from its directory (the uncertainty map
    bootstrapped if it kept none); for a stored lens, the stored model and figures.
    ``overlays``: which focus settings keep their overlays (None: a session's ``report.overlays``,
    else all)."""
    # defers matplotlib, PIL, jinja2
    from station.qa.report import focus_evidence, session_context, session_evidence, write_report

    evidence = []
    for t, v in zip(targets, judged.verdicts):
        if session is not None and t.focus_idx is not None:
            e = session_evidence(
                session,
                t.focus_idx,
                t.focus,
                t.profile,
                v,
                source=t.source,
                bootstrap_if_missing=session.config.pipeline.bootstrap or REPORT_BOOTSTRAP,
            )
        else:
            prof = t.profile
            e = focus_evidence(prof, t.focus, v, t.source)
            unc = prof.merit.field_uncertainty
            e.uncertainty_note = (
                "stored: RMS {} px, max {} px (no per-pixel map without the session's "
                "frames: run `harp qa SESSION_DIR --report`)"
            ).format(*(f"{x:.4f}" if x is not None else "-" for x in ((unc.rms, unc.max) if unc else (None, None))))
        evidence.append(e)
    if session is not None:
        context, warnings = session_context(session)
    else:
        context, warnings = lens_context(targets), []
    notes = [f"focus {t.focus:g}: {n}" for t in targets for n in t.notes]
    return write_report(
        directory,
        title,
        evidence,
        judged.overall,
        thresholds=judged.thresholds[0],
        interpolation=judged.interpolation,
        notes=notes,
        context=context,
        warnings=warnings,
        workers=session.config.pipeline.workers if session is not None else 1,
        overlays=overlays or (session.config.report.overlays if session is not None else "all"),
    )


def lens_context(targets: list[Target]) -> list[tuple[str, str]]:
    """Report rows of a stored lens: each profile's calibration date, station, software and session."""
    from station import __version__  # defers importlib.metadata

    rows = [("software (this report)", f"harp station {__version__}")]
    for t in targets:
        p = t.profile.provenance
        rows.append(
            (
                f"focus {t.focus:g}",
                f"{t.source}, calibrated {p.created_utc or t.profile.stored_at or '-'} on station "
                f"{p.station or '-'} with {p.software or '-'}, session `{p.session_dir or '-'}`; "
                f"thresholds from {t.thresholds_from}",
            )
        )
    return rows
