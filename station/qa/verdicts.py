"""Factory QA: a PASS / FAIL verdict for a lens profile, judging the stored model itself.

Every check is a typed :class:`station.profile.Check` (name, value, comparison, limit,
passed, text) whose text says what happened: ``holdout d 0.0012 px > 0.001 px: FAIL``
for a check that failed, ``... <= 0.05 px: PASS`` for one that held, ``...: reported,
no threshold`` for a figure that is shown but not judged. The checks, in order:

``holdout_d``
    the cross-validated straightness after correction must not exceed
    ``max_holdout_d_px``: the correction must straighten shots it was not fitted on.
    When the measured edges the profile was fitted on are at hand (a session's
    ``measurements/``, :class:`Measurements`) and ``recompute=True``, the holdout d
    is *recomputed* from them (leave one orientation out, refitting the profile's
    spec, :func:`station.calibration.calibrate_shots`) and that value is judged;
``holdout_d_stored``
    (only when recomputed) the stored holdout d must agree with the recomputed one
    within :data:`HOLDOUT_AGREEMENT_PX` + :data:`HOLDOUT_AGREEMENT_REL` of it: a
    profile whose figures do not belong to its measurements fails;
``corrected_d``
    (measurements at hand) the straightness of those edges corrected by the
    profile's *stored model* must not exceed ``max_holdout_d_px``: a model that was
    changed after calibration (issue 14: ``k1 = 5.0``) no longer straightens them;
``defined``
    the correction is defined over the whole image: its inverse returns every
    point of a grid over the image (corners and borders included) to within
    :data:`DEFINED_TOL_PX` (a correction that folds the image, or whose inverse
    does not exist at the corners, fails);
``distortion_max``
    the largest displacement of the correction over the image, modulo the best
    homography (:func:`distortion_magnitude`), must not exceed
    ``max_distortion_px`` (a lens out of its specification); reported when unset;
``distortion_recorded``
    (the profile carries the verdict it was judged with at calibration) the
    distortion recomputed from the model must equal the one recorded then, within
    :data:`RECORDED_AGREEMENT_PX` + :data:`RECORDED_AGREEMENT_REL`: the model is
    the one that was judged;
``reference_deviation_max``
    (a golden reference is given) the largest field difference, modulo the best
    homography, from the reference (:func:`pipeline.compare.compare_models`) must
    not exceed ``max_reference_deviation_px``;
``twin_move``
    (two shots at one angle: a session's twin, ``capture.twin_deg``, or twins given to ``harp calibrate``) the
    lens's move across the strings between them must not exceed the record's limit
    (:data:`station.moving_lens.TWIN_MOVE_PX`): a lens that moved between shots has no one correction.

A FAIL has one reason per failed check. :func:`qa_verdict` judges one
:class:`station.profile.Profile`; :func:`evaluate` the same on a bare model.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.compare import compare_models
from pipeline.edgeset import EdgeSet, collect, edge_figures, straightness_of, tls
from pipeline.fit import fit_distortion
from pipeline.fitspec import FIELD_NONE, STRINGS_KINKS, STRINGS_SEPARATE
from pipeline.model_file import read_model_file
from pipeline.models.base import IdentityModel
from pipeline.plain import finite_or_none
from station.calibration import calibrate_focus, calibrate_shots
from station.config import QAConfig
from station.moving_lens import (
    MOVING_LENS_ADVICE,
    OWN_SHIFT_ADVICE,
    TWIN_MOVE_PX,
    TWINNED_ADVICE,
    largest_own_shift,
)
from station.profile import HOLDOUT_LEAVE_ONE_ORIENTATION_OUT, Check, Profile, Verdict
from station.qa.evidence import stored_measurement
from station.session import layout

THRESHOLD_FIELDS = ("max_holdout_d_px", "max_distortion_px", "max_reference_deviation_px")

DEFINED_TOL_PX = 0.01
"""Largest round trip (inverse, then correction) error over the image grid of a defined correction, px."""

HOLDOUT_AGREEMENT_PX = 0.001
HOLDOUT_AGREEMENT_REL = 0.05
"""A stored holdout d agrees with the recomputed one within 0.001 px + 5 % of it."""

RECORDED_AGREEMENT_PX = 0.01
RECORDED_AGREEMENT_REL = 0.01
"""The distortion recomputed from a model agrees with the one recorded at calibration within 0.01 px + 1 %."""

PASS, FAIL = "PASS", "FAIL"

_NEGATION = {"<=": ">", "<": ">=", ">": "<=", ">=": "<"}


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


def calibrated_thresholds(profile: Profile) -> dict[str, float | None] | None:
    """The thresholds a profile was judged with when it was calibrated (its stored verdict's), or None."""
    if profile.qa is None or not profile.qa.thresholds:
        return None
    known = {k: profile.qa.thresholds.get(k) for k in THRESHOLD_FIELDS}
    return known if known.get("max_holdout_d_px") is not None else None


def grid_step(width: int, height: int) -> float:
    """Spacing (px) of the grid on which QA compares corrections (:func:`distortion_magnitude`)."""
    return max(8.0, max(width, height) / 80)


def distortion_magnitude(model, width: int, height: int) -> tuple[float, float]:
    """(RMS, max) displacement of the correction modulo the best homography, px."""
    c = compare_models(model, IdentityModel(), width, height, step=grid_step(width, height))
    return c.rms, c.max


def round_trip_error(model, width: int, height: int, n: int = 9) -> float:
    """Largest distance (px) between a point of an ``n`` x ``n`` grid over the image (its
    corners and borders included) and the correction applied to the correction's inverse
    at that point (``inf`` where the inverse does not exist or is not finite)."""
    xs = np.linspace(0.0, width - 1.0, n)
    ys = np.linspace(0.0, height - 1.0, n)
    xx, yy = np.meshgrid(xs, ys)
    q = np.stack([xx.ravel(), yy.ravel()], axis=1)
    with np.errstate(all="ignore"):
        try:
            u = model.undistort_points(q)
            back = model.distort_points(u)
            err = np.hypot(*(back - q).T)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            return math.inf
    if not np.all(np.isfinite(u)) or not np.all(np.isfinite(err)):
        return math.inf
    return float(err.max())


def _fmt(v: float | None, digits: int) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def judged(
    name: str, label: str, value: float | None, comparison: str, limit: float, *, digits: int = 4, unit: str = "px"
) -> Check:
    """A judged check: ``value comparison limit`` (None / non-finite value: FAIL), its text
    stating what happened (the comparison that holds, then PASS or FAIL)."""
    ok = value is not None and math.isfinite(value) and _holds(value, comparison, limit)
    shown = comparison if ok else _NEGATION[comparison]
    if value is None or not math.isfinite(value):
        text = f"{label}: {'none' if value is None else 'not finite'}: {FAIL}"
    else:
        text = f"{label} {value:.{digits}f} {unit} {shown} {limit:g} {unit}: {PASS if ok else FAIL}"
    return Check(name, finite_or_none(value), comparison, float(limit), bool(ok), text)


def reported(name: str, label: str, value: float | None, comparison: str = "<=", *, digits: int = 4) -> Check:
    """A figure shown but not judged (no threshold)."""
    return Check(
        name, finite_or_none(value), comparison, None, None, f"{label} {_fmt(value, digits)} px: reported, no threshold"
    )


def _holds(value: float, comparison: str, limit: float) -> bool:
    return {
        "<=": value <= limit,
        "<": value < limit,
        ">": value > limit,
        ">=": value >= limit,
    }[comparison]


@dataclass(frozen=True)
class FittedAs:
    """How a session fitted its shots (:func:`station.session.profile_steps.fit_focus`): its ``pipeline``
    configuration, the focus index (its bootstrap seed), each shot's turntable angle and a two-axis capture's
    places (:class:`station.axis_places.AxisPlaces`, None: one place)."""

    pipeline: Any
    focus_idx: int
    turntable_deg: tuple[float, ...]
    axis_places: Any = None


@dataclass(frozen=True)
class Measurements:
    """The measured edges a profile was fitted on: per shot (orientation), its edges as (M, 2)
    arrays of distorted pixels, and where they come from (said in the check texts); ``fitted_as``: how the session
    fitted them (None: not a session's, or not known), so that its holdout is recomputed the same way."""

    shots: Sequence[Sequence[np.ndarray]]
    source: str
    fitted_as: FittedAs | None = None

    @property
    def n_edges(self) -> int:
        return sum(len(s) for s in self.shots)


def evaluate(
    model,
    width: int,
    height: int,
    holdout_d: float | None,
    thresholds: QAConfig,
    reference=None,
    extra: Mapping[str, Any] | None = None,
    *,
    measurements: Measurements | None = None,
    recomputed_holdout_d: float | None = None,
    recorded: Mapping[str, Any] | None = None,
    harp_health: Mapping[str, Any] | None = None,
    own_shift: Mapping[str, Any] | None = None,
    twins: Sequence[Mapping[str, Any]] | None = None,
) -> Verdict:
    """Judge one correction (a :class:`~pipeline.models.base.DistortionModel`); see the module docstring.

    ``holdout_d``: the stored holdout figure; ``recomputed_holdout_d``: the one recomputed
    from ``measurements`` (judged instead, and compared with the stored one);
    ``measurements``: the edges the model was fitted on (the ``corrected_d`` check);
    ``recorded``: the metrics of the verdict the profile was judged with at calibration (the
    ``distortion_recorded`` check); ``reference``: the golden correction of the same lens model
    for this image size (None: not compared; said when a threshold is set); ``extra``: figures
    reported with the verdict, not judged (the field uncertainty); ``harp_health``: the harp's
    self-check (:func:`station.harp_health.harp_health`): the session fails when a string is bent
    beyond its limit (the harp, not the lens: the correction would carry the string's bend); ``own_shift``: the
    held-out orientations' own axis shifts (:func:`station.moving_lens.own_shift_record`), reported, with what to do
    when each orientation wants the correction moved on its own (a lens whose decentering changes between shots);
    ``twins``: two shots at one angle compared (:func:`station.moving_lens.twin_record`, a session's twin
    :func:`station.moving_lens.session_twin_record`): the profile fails when the lens moved between them beyond the
    record's limit (the correction is the mean of a lens that did not hold still).
    """
    checks: list[Check] = []
    reasons: list[str] = []
    metrics: dict[str, Any] = {"holdout_d_px": holdout_d}
    metrics.update({k: v for k, v in (extra or {}).items() if v is not None})

    def add(check: Check, why: str = "") -> None:
        checks.append(check)
        if check.passed is False:
            reasons.append(check.text.rsplit(": ", 1)[0] + (f": {why}" if why else ""))

    t = thresholds.max_holdout_d_px
    judged_holdout = holdout_d
    label = "holdout d"
    if recomputed_holdout_d is not None:
        judged_holdout = recomputed_holdout_d
        label = "holdout d (recomputed from the measurements)"
        metrics.update(holdout_d_px=recomputed_holdout_d, holdout_d_stored_px=holdout_d)
    if judged_holdout is None:
        add(
            Check("holdout_d", None, "<=", t, False, f"holdout d: none recorded: {FAIL}"),
            "no cross-validated (holdout) straightness for this profile",
        )
    else:
        add(
            judged("holdout_d", label, judged_holdout, "<=", t),
            "the correction does not straighten shots it was not fitted on well enough",
        )
    if recomputed_holdout_d is not None and holdout_d is not None:
        tol = HOLDOUT_AGREEMENT_PX + HOLDOUT_AGREEMENT_REL * recomputed_holdout_d
        diff = abs(holdout_d - recomputed_holdout_d)
        ok = diff <= tol
        c = Check(
            "holdout_d_stored",
            diff,
            "<=",
            tol,
            ok,
            f"stored holdout d {holdout_d:.4f} px vs recomputed {recomputed_holdout_d:.4f} px: "
            f"difference {diff:.4f} px {'<=' if ok else '>'} {tol:.4f} px: {PASS if ok else FAIL}",
        )
        add(c, "the stored figures do not belong to the measurements this profile was fitted on")

    if measurements is not None and measurements.shots:
        with np.errstate(all="ignore"):
            d_corr, n_kept, n_out = corrected_d(model, measurements.shots, width, height)
        metrics.update(corrected_d_px=finite_or_none(d_corr), corrected_d_outlier_edges=n_out)
        add(
            judged(
                "corrected_d",
                f"d of the {len(measurements.shots)} measured shots ({measurements.source}; {n_kept} edges, "
                f"{n_out} outliers left out as the fit does) corrected by this model",
                finite_or_none(d_corr),
                "<=",
                t,
            ),
            "the stored correction does not straighten the shots it was fitted on",
        )

    rt = round_trip_error(model, width, height)
    metrics["round_trip_px"] = finite_or_none(rt)
    add(
        judged(
            "defined", "correction's inverse round trip over the image, corners included,", rt, "<=", DEFINED_TOL_PX
        ),
        "the correction is not defined over the whole image (its inverse does not return the corners)",
    )

    try:
        with np.errstate(all="ignore"):
            rms, mx = distortion_magnitude(model, width, height)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        rms = mx = math.nan
    metrics.update(distortion_rms_px=finite_or_none(rms), distortion_max_px=finite_or_none(mx))
    lim = thresholds.max_distortion_px
    label = "distortion max (modulo homography)"
    if not (math.isfinite(rms) and math.isfinite(mx)):
        add(
            Check("distortion_max", None, "<=", lim, False, f"{label}: not finite over the image: {FAIL}"),
            "the correction is not finite over the whole image",
        )
    elif lim is not None:
        add(judged("distortion_max", label, mx, "<=", lim, digits=3), "the lens is out of its specification")
    else:
        add(reported("distortion_max", label, mx, digits=3))

    then = finite_or_none((recorded or {}).get("distortion_max_px"))
    if then is not None and math.isfinite(mx):
        tol = RECORDED_AGREEMENT_PX + RECORDED_AGREEMENT_REL * then
        diff = abs(mx - then)
        ok = diff <= tol
        add(
            Check(
                "distortion_recorded",
                diff,
                "<=",
                tol,
                ok,
                f"distortion max {mx:.3f} px now, {then:.3f} px when judged at calibration: difference "
                f"{diff:.3f} px {'<=' if ok else '>'} {tol:.3f} px: {PASS if ok else FAIL}",
            ),
            "the correction was changed after it was calibrated and judged",
        )

    lim = thresholds.max_reference_deviation_px
    if reference is not None:
        c = compare_models(model, reference, width, height, step=grid_step(width, height))
        metrics.update(reference_rms_px=c.rms, reference_max_px=c.max)
        label = f"deviation from the reference max (RMS {c.rms:.4f} px)"
        if lim is not None:
            add(judged("reference_deviation_max", label, c.max, "<=", lim), "deviates from the reference")
        else:
            add(reported("reference_deviation_max", label, c.max))
    elif lim is not None:
        checks.append(
            Check(
                "reference_deviation_max",
                None,
                "<=",
                lim,
                None,
                "deviation from the reference: not checked, no reference given",
            )
        )

    if harp_health:
        limit = float(harp_health.get("limit_px") or 0.02)
        worst = harp_health.get("worst_bend_px")
        typical = harp_health.get("typical_bend_px")
        if harp_health.get("failure") or worst is None:
            why = harp_health.get("failure") or "no string seen in two shots"
            checks.append(Check("string_bend_max", None, "<=", limit, None, f"harp self-check: not made ({why})"))
        elif typical is not None and typical > limit:
            metrics["string_bend_max_px"] = worst
            checks.append(
                Check(
                    "string_bend_max",
                    finite_or_none(worst),
                    "<=",
                    limit,
                    None,
                    f"harp self-check: not judged: the median string bends by {typical:.4f} px (> {limit:g} px), "
                    "which a lens term the model lacks does as well as a bent harp",
                )
            )
        else:
            bent = list(harp_health.get("bent_strings") or [])
            own = {s.get("index"): s.get("own_bend_px") for s in harp_health.get("strings") or []}
            k = max(bent, key=lambda j: own.get(j) or 0.0) if bent else harp_health.get("worst_string")
            bend = float(own.get(k) or worst) if bent else worst
            metrics["string_bend_max_px"] = worst
            if bent:
                times = f" and {bend / typical:.0f}x the median string's" if typical else ""
                text = f"harp: largest string bend (string {k}) {bend:.4f} px > {limit:g} px{times}: {FAIL}"
            elif worst > limit:  # beyond the limit, yet not a finding: say why
                se = harp_health.get("worst_bend_se_px")
                if k in (harp_health.get("uncertain_strings") or []):
                    sig = harp_health.get("significance") or 2.0
                    why = f"within {sig:g} standard errors ({se:.4f} px) of a straight string" if se else "unsure"
                else:
                    factor = harp_health.get("outlier_factor") or 3.0
                    why = (
                        f"below {factor:g}x the median string's {typical:.4f} px: strings bending alike are a lens "
                        "term's the model lacks as much as the harp's"
                    )
                text = f"harp: largest string bend (string {k}) {worst:.4f} px > {limit:g} px, but {why}: {PASS}"
            else:
                text = f"harp: largest string bend (string {k}) {worst:.4f} px <= {limit:g} px: {PASS}"
            noisy = harp_health.get("noisy_shots") or []
            if noisy:
                angles = ", ".join(f"{n['turntable_deg']:g}" for n in noisy)
                ratio = max(n["noise_ratio"] for n in noisy)
                text += (
                    f" (shots at {angles} deg measured up to {ratio:.1f}x worse than the others, weighed by their "
                    "noise: strings along the pixel rows or columns? turn the harp on its mount by a few degrees)"
                )
            add(
                Check("string_bend_max", finite_or_none(worst), "<=", limit, not bent, text),
                f"string {k} of the harp is bent by {bend:.4f} px (limit {limit:g} px): the correction "
                "would carry its bend; straighten or replace the string, then capture again",
            )

    axes = (harp_health or {}).get("axes")
    if axes and axes.get("places"):
        _axis_places(axes, add, metrics)
    read = [t for t in twins or () if t.get("move_px") is not None]
    if own_shift and own_shift.get("judged") and own_shift.get("ratio_median") is not None:
        add(_own_shift_check(own_shift, twinned=bool(read)))
        metrics["holdout_own_shift_ratio"] = own_shift["ratio_median"]
    if read:
        worst = max(read, key=lambda t: abs(float(t["move_px"])))
        metrics["twin_move_px"] = abs(float(worst["move_px"]))
        if worst.get("twin_d_px") is not None:
            metrics["twin_d_px"] = worst["twin_d_px"]
        add(*_twin_check(worst))

    return Verdict(
        FAIL if reasons else PASS,
        tuple(reasons),
        metrics,
        tuple(checks),
        {k: getattr(thresholds, k) for k in THRESHOLD_FIELDS},
    )


def _twin_check(twin: Mapping[str, Any]) -> tuple[Check, str]:
    """The lens's move between two shots at one angle (the pair that moved most), judged against the record's limit
    (:data:`station.moving_lens.TWIN_MOVE_PX`), and why it fails."""
    move, limit = abs(float(twin["move_px"])), float(twin.get("limit_px") or TWIN_MOVE_PX)
    a, b = twin.get("paths") or ("?", "?")
    ok = move <= limit
    text = f"twins {a} and {b}: the lens moved {move:.2f} px across the strings between them"
    if twin.get("twin_d_px") is not None:
        text += f" (the twin, not fitted: d {float(twin['twin_d_px']):.4f} px)"
    text += f" {'<=' if ok else '>'} {limit:g} px: {PASS if ok else FAIL}"
    why = f"the lens moved between two shots at one angle; the correction is their mean: {MOVING_LENS_ADVICE}"
    return Check("twin_move", finite_or_none(move), "<=", limit, ok, text), why


def _own_shift_check(own_shift: Mapping[str, Any], twinned: bool = False) -> Check:
    """The held-out orientations' own axis shift, reported (:func:`station.moving_lens.own_shift_record`); its
    advice points at the twin's check when the profile has a twin read (``twinned``), else at taking one."""
    ratio, limit = float(own_shift["ratio_median"]), float(own_shift.get("limit") or 0.0)
    text = f"held-out orientations: the correction moved for each alone leaves {ratio:.2f} of its held-out d (median"
    text += f"; at or above {limit:g}, as a stable lens)" if not own_shift.get("moving") else f" < {limit:g})"
    if own_shift.get("moving"):
        size = largest_own_shift(own_shift)
        advice = OWN_SHIFT_ADVICE if not twinned else f"{MOVING_LENS_ADVICE}; {TWINNED_ADVICE}"
        text += (f", by up to {size:.1f} px" if size is not None else "") + f": {advice}"
    return Check("holdout_own_shift", finite_or_none(ratio), ">=", None, None, f"{text}: reported, not judged")


def _axis_places(axes: Mapping[str, Any], add: Callable[..., None], metrics: dict[str, Any]) -> None:
    """The check of a two-axis capture's turntable-axis places (:func:`station.axis_places.axis_record`): each
    place's axis as the joint fit found it, and whether it lies within half a pitch of where the linear stage's
    travel puts it (further, and the strings were numbered wrongly at that place)."""
    limit, worst = axes.get("limit_px"), axes.get("worst_off_px")
    where = ", ".join(
        f"{p['position_mm']:g} mm at ({p['centre_px'][0]:.1f}, {p['centre_px'][1]:.1f})" for p in axes["places"]
    )
    if limit is None or worst is None:
        add(Check("axis_places", None, "<=", limit, None, f"turntable axis places: {where}: not judged"))
        return
    metrics["axis_place_off_px"] = worst
    bad = list(axes.get("misplaced") or [])
    text = (
        f"turntable axis places ({where} px): largest disagreement with the stage's travel {worst:.2f} px "
        f"{'>' if bad else '<='} {limit:.2f} px (half a pitch): {FAIL if bad else PASS}"
    )
    add(
        Check("axis_places", worst, "<=", limit, not bad, text),
        f"the turntable axis at stage position {bad[0] if bad else 0:g} mm is {worst:.2f} px from where the "
        f"linear stage's travel puts it (more than half a pitch): its strings were numbered wrongly; check "
        "station.harp.shift_direction_deg and the stage, then fit again (harp reprocess)",
    )


def _fit_rejection() -> tuple[float, float]:
    """(reject_factor, max_reject_fraction) of the fit (:func:`pipeline.fit.fit_distortion`'s defaults)."""
    import inspect

    params = inspect.signature(fit_distortion).parameters
    return float(params["reject_factor"].default), float(params["max_reject_fraction"].default)


def corrected_d(model, shots: Sequence[Sequence[np.ndarray]], width: int, height: int) -> tuple[float, int, int]:
    """``(d, kept, outliers)``: the straightness of the measured edges of ``shots`` corrected by
    ``model``, the edges chosen as the fit chooses them — the edges :func:`pipeline.edgeset.collect`
    accepts, less the outliers: an edge whose RMS residual after correction exceeds ``reject_factor``
    x the median edge RMS, the worst ``max_reject_fraction`` of the edges at most
    (:func:`pipeline.fit.fit_distortion`). A correction that does not straighten the edges raises
    every edge's residual with the median, so it cannot hide behind the rule. NaN when no edge is usable."""
    edges, _rejected = collect([list(s) for s in shots], width, height)
    if not isinstance(edges, EdgeSet) or edges.n_edges == 0:
        return math.nan, 0, 0
    u = model.undistort_points(edges.xy)
    if not np.all(np.isfinite(u)):
        return math.nan, edges.n_edges, 0
    rms, _ = edge_figures(tls(u, edges.starts, edges.counts)[0], edges.starts, edges.counts)
    factor, fraction = _fit_rejection()
    bad = np.flatnonzero(rms > factor * max(float(np.median(rms)), 1e-6))
    bad = bad[np.argsort(rms[bad])[::-1][: int(fraction * edges.n_edges)]]
    keep = np.ones(edges.n_edges, bool)
    keep[bad] = False
    pieces = [u[a : a + c] for a, c, k in zip(edges.starts, edges.counts, keep) if k]
    return float(straightness_of(pieces)[0]), len(pieces), len(bad)


def reported_figures(profile: Profile) -> dict[str, float | None]:
    """The figures of a profile QA reports without judging them (px)."""
    m = profile.merit
    unc = m.field_uncertainty
    return {
        "holdout_d_max_px": finite_or_none(m.holdout.d_max) if m.holdout else None,
        "fit_d_px": finite_or_none(m.fit.d) if m.fit else None,
        "field_uncertainty_rms_px": finite_or_none(unc.rms) if unc else None,
        "field_uncertainty_max_px": finite_or_none(unc.max) if unc else None,
    }


def recompute_holdout(profile: Profile, measurements: Measurements, map_fn=map) -> tuple[float | None, str]:
    """(holdout d, note): the leave-one-orientation-out holdout d of ``profile`` recomputed from
    ``measurements`` by refitting its spec exactly as it was fitted: a profile whose lens was fitted with the
    strings' bends separated (``details["strings"]``), from a session's measurements (``fitted_as``), with every fold
    fitted so too (:func:`station.calibration.calibrate_focus`, as the session did); any other with the lens alone
    (:func:`station.calibration.calibrate_shots`); (None, why) when it cannot be."""
    hold = profile.merit.holdout
    if profile.spec is None:
        return None, "not recomputed: the profile does not record which model was fitted"
    if hold is not None and hold.scheme not in (None, HOLDOUT_LEAVE_ONE_ORIENTATION_OUT):
        return None, f"not recomputed: its holdout comes from {hold.scheme}, not from these measurements"
    if len(measurements.shots) < 2:
        return None, "not recomputed: fewer than 2 measured shots"
    shots = [list(s) for s in measurements.shots]
    strings = (profile.details or {}).get("strings") or {}
    how = measurements.fitted_as
    if how is not None and strings.get("separated"):  # its holdout's folds were fitted with the strings separated
        pipe = dataclasses.replace(
            how.pipeline,
            bootstrap=0,
            field=FIELD_NONE,
            strings=STRINGS_KINKS if "kinks" in strings else STRINGS_SEPARATE,
        )  # the spec carries the field the session chose; the bootstrap does not change the holdout
        cal = calibrate_focus(
            shots, profile.width, profile.height, pipe, how.focus_idx, profile.spec, map_fn=map_fn,
            turntable_deg=how.turntable_deg, axis_places=how.axis_places,
        )  # fmt: skip
        if not (cal.details.get("strings") or {}).get("separated"):
            return None, "not recomputed: the strings could not be separated again"
    else:
        cal = calibrate_shots(shots, profile.width, profile.height, profile.spec, holdout="orientations", map_fn=map_fn)
    if cal.failure is not None or cal.merit.holdout is None or cal.merit.holdout.d is None:
        return None, f"not recomputed: {cal.failure or 'no holdout figure'}"
    return float(cal.merit.holdout.d), ""


def qa_verdict(
    profile: Profile,
    thresholds=None,
    reference=None,
    *,
    measurements: Measurements | None = None,
    recompute: bool = False,
    map_fn=map,
) -> Verdict:
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
    measurements : Measurements, optional
        The edges the profile was fitted on (a session's kept measurements): the
        stored model is judged on them (``corrected_d``).
    recompute : bool
        With ``measurements``, recompute the holdout d from them and judge that
        (:func:`recompute_holdout`; a few fits, ``map_fn`` maps them).

    Returns
    -------
    Verdict
        ``passed``, ``reasons`` (one per failed check), ``figures`` (px), ``checks``, ``thresholds``.
    """
    if isinstance(reference, Profile):
        if (reference.width, reference.height) != (profile.width, profile.height):
            raise ValueError(
                f"the reference is for {reference.width}x{reference.height} images, the profile for "
                f"{profile.width}x{profile.height}: they cannot be compared"
            )
        reference = reference.model
    recomputed = None
    extra = reported_figures(profile)
    if measurements is not None and recompute:
        recomputed, note = recompute_holdout(profile, measurements, map_fn=map_fn)
        if note:
            extra["holdout_note"] = note
    return evaluate(
        profile.model,
        profile.width,
        profile.height,
        finite_or_none(profile.merit.holdout_d),
        thresholds_from(thresholds),
        reference=reference,
        extra=extra,
        measurements=measurements,
        recomputed_holdout_d=recomputed,
        recorded=profile.qa.metrics if profile.qa is not None else None,
        harp_health=(profile.details or {}).get("harp_health"),
        own_shift=(profile.details or {}).get("own_shift"),
        twins=(profile.details or {}).get("twins"),
    )


def combine(verdicts) -> str:
    """PASS only if every verdict passed (and there is at least one)."""
    verdicts = list(verdicts)
    return PASS if verdicts and all(v.passed for v in verdicts) else FAIL


def session_profiles(session_path) -> list[tuple[int, Profile]]:
    """``(focus_idx, profile)`` of every profile a session directory holds, by focus index
    (a profile file that does not record its focus gets the session's focus setting later)."""
    return [(f, Profile.from_model_file(read_model_file(p))) for f, p in layout.profile_files(session_path)]


def session_measurements(session, focus_idx: int) -> Measurements | None:
    """The measured edges a session kept for one focus setting (``measurements/``, the shots'
    current attempts), or None when any orientation lacks its kept measurement."""
    from station.session.profile_steps import axis_places  # defers the session's fit

    cap = session.config.capture
    shots = []
    for o in cap.fitted:  # the shots the fit took (a twin is compared, not fitted)
        m = stored_measurement(session, focus_idx, o)
        if m is None:
            return None
        shots.append([np.asarray(ln.points, np.float64) for ln in m.lines])
    how = FittedAs(
        session.config.pipeline,
        focus_idx,
        cap.fitted_angles_deg,
        axis_places(session, session.config, focus_idx),
    )
    return Measurements(shots, f"{session.path.name}/measurements, focus index {focus_idx}", how)


def interpolation_error(models_by_focus: dict, width: int, height: int):
    """Leave-one-out focus-interpolation error (list of ``(focus, rms_px, max_px)``),
    empty with fewer than 3 calibrated settings."""
    from pipeline.interpolate import leave_one_out_error  # defers scipy

    if len(models_by_focus) < 3:
        return []
    return leave_one_out_error(models_by_focus, width, height)
