"""Factory QA: a PASS / FAIL verdict for a lens profile against thresholds.

Checks (each enabled by its threshold, from the configuration's ``qa``
section or the command line):

* ``max_holdout_d_px``: the cross-validated straightness after correction
  (leave-one-orientation-out ``holdout d``) must not exceed it — the
  correction must generalise to shots it was not fitted on;
* ``max_distortion_px``: the largest displacement of the correction over the
  image, modulo the best homography (a lens out of its specification);
* ``max_reference_deviation_px``: the largest field difference, modulo the
  best homography, from a golden reference profile of the same lens model
  (:func:`pipeline.compare.compare_models`).

A profile with no holdout figure, or a correction that is not finite over
the image, FAILs with that reason. Figures that are not judged (e.g. the
field uncertainty, or a distortion with no threshold) are still reported.

:func:`qa_verdict` is the entry point for one :class:`station.profile.Profile`;
:func:`evaluate` is the same on a model. Each judged figure is a typed
:class:`station.profile.Check` (value, comparison, limit, passed) of the
:class:`station.profile.Verdict`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from station.config import QAConfig
from station.profile import Check, Profile, Verdict

THRESHOLD_FIELDS = ("max_holdout_d_px", "max_distortion_px", "max_reference_deviation_px")


def thresholds_from(obj: Any = None, **overrides) -> QAConfig:
    """A :class:`~station.config.QAConfig` from a QAConfig, a mapping or None (defaults),
    with ``overrides`` (``None`` values ignored). ValueError for an unknown or bad field."""
    if obj is None:
        base = QAConfig()
    elif isinstance(obj, QAConfig):
        base = obj
    elif isinstance(obj, Mapping):
        unknown = set(obj) - set(THRESHOLD_FIELDS)
        if unknown:
            raise ValueError(
                f"unknown QA threshold(s) {', '.join(sorted(unknown))}; known: {', '.join(THRESHOLD_FIELDS)}"
            )
        base = QAConfig(**{**QAConfig().__dict__, **obj})
    else:
        raise ValueError(f"thresholds must be a QAConfig or a mapping, got {type(obj).__name__}")
    values = {**base.__dict__, **{k: v for k, v in overrides.items() if v is not None}}
    for k in THRESHOLD_FIELDS:
        v = values.get(k)
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"QA threshold {k} must be a positive number, got {v!r}")
    if values.get("max_holdout_d_px") is None:
        raise ValueError("QA threshold max_holdout_d_px must be set")
    return QAConfig(**values)


def grid_step(width: int, height: int) -> float:
    """Spacing (px) of the grid on which QA compares corrections (:func:`distortion_magnitude`)."""
    return max(8.0, max(width, height) / 80)


def distortion_magnitude(model, width: int, height: int) -> tuple[float, float]:
    """(RMS, max) displacement of the correction modulo the best homography, px."""
    from pipeline.compare import compare_models
    from pipeline.models.base import IdentityModel

    c = compare_models(model, IdentityModel(), width, height, step=grid_step(width, height))
    return c.rms, c.max


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def evaluate(
    model,
    width: int,
    height: int,
    holdout_d: float | None,
    thresholds: QAConfig,
    reference=None,
    extra: Mapping[str, Any] | None = None,
) -> Verdict:
    """Judge one correction (a :class:`~pipeline.models.base.DistortionModel`).

    ``reference`` is the golden correction of the same lens model for this
    image size (or ``None``: that check is skipped, and reported as such when
    a threshold is set). ``extra`` figures (e.g. the field uncertainty) are
    reported with the verdict, not judged.
    """
    from pipeline.compare import compare_models

    reasons: list[str] = []
    checks: list[Check] = []
    metrics: dict = {"holdout_d_px": holdout_d}
    metrics.update({k: v for k, v in (extra or {}).items() if v is not None})

    t = thresholds.max_holdout_d_px
    if not _finite(holdout_d):
        reasons.append("no cross-validated (holdout) straightness for this profile")
    else:
        ok = holdout_d <= t
        checks.append(Check("holdout_d", holdout_d, "<=", t, ok, f"holdout d {holdout_d:.4f} px <= {t:g} px"))
        if not ok:
            reasons.append(
                f"holdout d {holdout_d:.4f} px > {t:g} px: the correction does not "
                "straighten shots it was not fitted on well enough"
            )

    try:
        rms, mx = distortion_magnitude(model, width, height)
    except (ValueError, FloatingPointError):
        rms = mx = math.nan
    metrics.update(distortion_rms_px=rms, distortion_max_px=mx)
    if not (math.isfinite(rms) and math.isfinite(mx)):
        reasons.append("the correction is not finite over the whole image")
    elif thresholds.max_distortion_px is not None:
        lim = thresholds.max_distortion_px
        ok = mx <= lim
        checks.append(Check("distortion_max", mx, "<=", lim, ok, f"distortion max {mx:.3f} px <= {lim:g} px"))
        if not ok:
            reasons.append(f"distortion {mx:.3f} px (max over the image, modulo homography) > {lim:g} px")

    lim = thresholds.max_reference_deviation_px
    if reference is not None:
        c = compare_models(model, reference, width, height, step=grid_step(width, height))
        metrics.update(reference_rms_px=c.rms, reference_max_px=c.max)
        if lim is not None:
            ok = c.max <= lim
            checks.append(
                Check(
                    "reference_deviation_max",
                    c.max,
                    "<=",
                    lim,
                    ok,
                    f"deviation from reference max {c.max:.4f} px <= {lim:g} px",
                )
            )
            if not ok:
                reasons.append(f"deviates from the reference by {c.max:.4f} px max ({c.rms:.4f} px RMS) > {lim:g} px")
        else:
            checks.append(
                Check(
                    "reference_deviation_max",
                    c.max,
                    "<=",
                    None,
                    None,
                    f"deviation from reference max {c.max:.4f} px: reported only (no threshold)",
                )
            )
    elif lim is not None:
        checks.append(
            Check(
                "reference_deviation_max",
                None,
                "<=",
                lim,
                None,
                "deviation from reference: not checked (no reference given)",
            )
        )

    return Verdict(
        "FAIL" if reasons else "PASS",
        tuple(reasons),
        metrics,
        tuple(checks),
        {k: getattr(thresholds, k) for k in THRESHOLD_FIELDS},
    )


def _num(v) -> float | None:
    return float(v) if _finite(v) else None


def reported_figures(profile: Profile) -> dict[str, float | None]:
    """The figures of a profile QA reports without judging them (px)."""
    m = profile.merit
    unc = m.field_uncertainty
    return {
        "holdout_d_max_px": _num(m.holdout.d_max) if m.holdout else None,
        "fit_d_px": _num(m.fit.d) if m.fit else None,
        "field_uncertainty_rms_px": _num(unc.rms) if unc else None,
        "field_uncertainty_max_px": _num(unc.max) if unc else None,
    }


def qa_verdict(profile: Profile, thresholds=None, reference=None) -> Verdict:
    """The QA verdict of one profile.

    Parameters
    ----------
    profile : Profile
        The correction and its figures.
    thresholds : QAConfig or mapping, optional
        ``max_holdout_d_px`` (default 0.05), ``max_distortion_px``,
        ``max_reference_deviation_px`` (``None``: not judged).
    reference : DistortionModel or Profile, optional
        The golden reference correction of the same lens model; a profile must be
        for the same image size (ValueError otherwise).

    Returns
    -------
    Verdict
        ``passed``, ``reasons`` (one per failed check), ``figures`` (px), ``checks``.
    """
    if isinstance(reference, Profile):
        if (reference.width, reference.height) != (profile.width, profile.height):
            raise ValueError(
                f"the reference is for {reference.width}x{reference.height} images, the profile for "
                f"{profile.width}x{profile.height}: they cannot be compared"
            )
        reference = reference.model
    return evaluate(
        profile.model,
        profile.width,
        profile.height,
        _num(profile.merit.holdout_d),
        thresholds_from(thresholds),
        reference=reference,
        extra=reported_figures(profile),
    )


def combine(verdicts) -> str:
    """PASS only if every verdict passed (and there is at least one)."""
    verdicts = list(verdicts)
    return "PASS" if verdicts and all(v.passed for v in verdicts) else "FAIL"


def session_profiles(session_path) -> list[tuple[int, Profile]]:
    """``(focus_idx, profile)`` of every profile a session directory holds, by focus index
    (a profile file that does not record its focus gets the session's focus setting later)."""
    from pipeline.model_file import read_model_file
    from station.session import layout

    return [(f, Profile.from_model_file(read_model_file(p))) for f, p in layout.profile_files(session_path)]


def interpolation_error(models_by_focus: dict, width: int, height: int):
    """Leave-one-out focus-interpolation error (list of ``(focus, rms_px, max_px)``),
    empty with fewer than 3 calibrated settings."""
    from pipeline.interpolate import leave_one_out_error

    if len(models_by_focus) < 3:
        return []
    return leave_one_out_error(models_by_focus, width, height)
