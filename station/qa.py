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

:func:`qa_verdict` is the entry point for one profile in any of its forms (a
stored :class:`station.store.Profile`, a :class:`pipeline.model_file.ModelFile`
or a plain mapping); :func:`evaluate` is the same on a model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from station.config import QAConfig

THRESHOLD_FIELDS = ("max_holdout_d_px", "max_distortion_px", "max_reference_deviation_px")


@dataclass(frozen=True)
class Verdict:
    """The QA verdict of one profile.

    ``verdict`` is ``"PASS"`` or ``"FAIL"``; ``reasons`` say why it failed
    (empty for PASS); ``metrics`` (alias ``figures``) holds every figure
    computed, in pixels; ``checks`` lists what was judged, one line each.
    """

    verdict: str
    reasons: tuple[str, ...]
    metrics: dict = field(default_factory=dict)
    checks: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return self.verdict == "PASS"

    @property
    def figures(self) -> dict:
        return self.metrics

    def to_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "passed": self.passed,
            "reasons": list(self.reasons),
            "checks": list(self.checks),
            "figures": dict(self.metrics),
        }


QAVerdict = Verdict


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
    checks: list[str] = []
    metrics: dict = {"holdout_d_px": holdout_d}
    metrics.update({k: v for k, v in (extra or {}).items() if v is not None})

    t = thresholds.max_holdout_d_px
    if not _finite(holdout_d):
        reasons.append("no cross-validated (holdout) straightness for this profile")
    else:
        checks.append(f"holdout d {holdout_d:.4f} px <= {t:g} px")
        if holdout_d > t:
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
        checks.append(f"distortion max {mx:.3f} px <= {thresholds.max_distortion_px:g} px")
        if mx > thresholds.max_distortion_px:
            reasons.append(
                f"distortion {mx:.3f} px (max over the image, modulo homography) > {thresholds.max_distortion_px:g} px"
            )

    if reference is not None:
        c = compare_models(model, reference, width, height, step=grid_step(width, height))
        metrics.update(reference_rms_px=c.rms, reference_max_px=c.max)
        lim = thresholds.max_reference_deviation_px
        if lim is not None:
            checks.append(f"deviation from reference max {c.max:.4f} px <= {lim:g} px")
            if not c.max <= lim:
                reasons.append(f"deviates from the reference by {c.max:.4f} px max ({c.rms:.4f} px RMS) > {lim:g} px")
        else:
            checks.append(f"deviation from reference max {c.max:.4f} px: reported only (no threshold)")
    elif thresholds.max_reference_deviation_px is not None:
        checks.append("deviation from reference: not checked (no reference given)")

    return Verdict("FAIL" if reasons else "PASS", tuple(reasons), metrics, tuple(checks))


@dataclass(frozen=True)
class ProfileData:
    """What QA needs of a profile, whatever it was read from."""

    model: Any  # DistortionModel
    width: int
    height: int
    holdout_d: float | None = None
    holdout_d_max: float | None = None
    fit_d: float | None = None
    field_uncertainty_rms: float | None = None
    field_uncertainty_max: float | None = None
    focus: float | None = None

    def extra(self) -> dict:
        return {
            "holdout_d_max_px": self.holdout_d_max,
            "fit_d_px": self.fit_d,
            "field_uncertainty_rms_px": self.field_uncertainty_rms,
            "field_uncertainty_max_px": self.field_uncertainty_max,
        }


def _num(v) -> float | None:
    return float(v) if _finite(v) else None


def profile_data(obj) -> ProfileData:
    """Normalise a stored ``Profile``, a ``ModelFile``, a mapping or a ``ProfileData``.

    A mapping needs ``model`` (a DistortionModel or its dict), ``width``,
    ``height``; optional ``holdout_d``, ``holdout_d_max``, ``fit_d``,
    ``field_uncertainty_rms``, ``field_uncertainty_max``, ``focus``.
    """
    from pipeline.models import model_from_dict
    from pipeline.models.base import DistortionModel

    if isinstance(obj, ProfileData):
        return obj
    if hasattr(obj, "merit") and hasattr(obj, "provenance"):  # pipeline.model_file.ModelFile
        merit = obj.merit or {}
        fu = merit.get("field_uncertainty") or {}
        return ProfileData(
            obj.model,
            int(obj.width),
            int(obj.height),
            holdout_d=_num((merit.get("holdout") or {}).get("d")),
            holdout_d_max=_num((merit.get("holdout") or {}).get("d_max")),
            fit_d=_num((merit.get("fit") or {}).get("d")),
            field_uncertainty_rms=_num(fu.get("rms")),
            field_uncertainty_max=_num(fu.get("max")),
            focus=_num((obj.provenance or {}).get("focus")),
        )
    if isinstance(obj, Mapping):
        get = obj.get
    elif hasattr(obj, "model") and hasattr(obj, "width"):  # station.store.Profile

        def get(k, default=None):
            return getattr(obj, k, default)
    else:
        raise ValueError(f"not a profile: {type(obj).__name__}")
    model = get("model")
    if isinstance(model, Mapping):
        model = model_from_dict(dict(model))
    if not isinstance(model, DistortionModel):
        raise ValueError("a profile needs a 'model' (a distortion model or its dict)")
    if get("width") is None or get("height") is None:
        raise ValueError("a profile needs its image 'width' and 'height'")
    return ProfileData(
        model,
        int(get("width")),
        int(get("height")),
        holdout_d=_num(get("holdout_d")),
        holdout_d_max=_num(get("holdout_d_max")),
        fit_d=_num(get("fit_d")),
        field_uncertainty_rms=_num(get("field_uncertainty_rms")),
        field_uncertainty_max=_num(get("field_uncertainty_max")),
        focus=_num(get("focus")),
    )


def qa_verdict(profile, thresholds=None, reference=None) -> Verdict:
    """The QA verdict of one profile.

    Parameters
    ----------
    profile : station.store.Profile, pipeline.model_file.ModelFile, mapping or ProfileData
        The correction and its figures (see :func:`profile_data`).
    thresholds : QAConfig or mapping, optional
        ``max_holdout_d_px`` (default 0.05), ``max_distortion_px``,
        ``max_reference_deviation_px`` (``None``: not judged).
    reference : DistortionModel or any ``profile`` form, optional
        The golden reference correction of the same lens model; must be for
        the same image size (ValueError otherwise).

    Returns
    -------
    Verdict
        ``passed``, ``reasons`` (one per failed check), ``figures`` (px).
    """
    from pipeline.models.base import DistortionModel

    p = profile_data(profile)
    if reference is not None and not isinstance(reference, DistortionModel):
        r = profile_data(reference)
        if (r.width, r.height) != (p.width, p.height):
            raise ValueError(
                f"the reference is for {r.width}x{r.height} images, the profile for "
                f"{p.width}x{p.height}: they cannot be compared"
            )
        reference = r.model
    return evaluate(
        p.model, p.width, p.height, p.holdout_d, thresholds_from(thresholds), reference=reference, extra=p.extra()
    )


def combine(verdicts) -> str:
    """PASS only if every verdict passed (and there is at least one)."""
    verdicts = list(verdicts)
    return "PASS" if verdicts and all(v.passed for v in verdicts) else "FAIL"


@dataclass(frozen=True)
class ProfileVerdict:
    focus: float
    verdict: Verdict
    profile_id: int | None = None
    source: str = ""  # model file or "profile #id"


def session_models(session_path) -> list[tuple[int, float, object]]:
    """``(focus_idx, focus, ModelFile)`` of every profile a session directory holds."""
    import re
    from pathlib import Path

    from pipeline.model_file import read_model_file

    out = []
    for p in sorted(Path(session_path, "profiles").glob("focus*.yaml")):
        m = re.fullmatch(r"focus(\d+)\.yaml", p.name)
        if not m:
            continue
        mf = read_model_file(p)
        focus = mf.provenance.get("focus")
        out.append((int(m.group(1)), float(focus) if focus is not None else math.nan, mf))
    return sorted(out, key=lambda x: x[0])


def holdout_of(model_file) -> float | None:
    v = (model_file.merit or {}).get("holdout", {}).get("d")
    return float(v) if isinstance(v, (int, float)) else None


def interpolation_error(models_by_focus: dict, width: int, height: int):
    """Leave-one-out focus-interpolation error (list of ``(focus, rms_px, max_px)``),
    empty with fewer than 3 calibrated settings."""
    from pipeline.interpolate import leave_one_out_error

    if len(models_by_focus) < 3:
        return []
    return leave_one_out_error(models_by_focus, width, height)
