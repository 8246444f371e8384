"""What the executor does with captured frames: average, check, measure, fit.

Thin glue between the session and the pure :mod:`pipeline`: averaging the
frames of a shot, the acceptance checks (exposure, strings found, string
angle against the commanded orientation) and the per-focus fit with
leave-one-orientation-out cross-validation. No files, no devices.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from station.config import CheckConfig, PipelineConfig


def average_frames(images: Sequence[np.ndarray]) -> np.ndarray:
    """Mean of same-shaped frames, float64."""
    if not images:
        raise ValueError("no frames to average")
    acc = np.zeros(images[0].shape, np.float64)
    for im in images:
        if im.shape != acc.shape:
            raise ValueError(f"frame shape {im.shape} differs from {acc.shape}")
        acc += im
    return acc / len(images)


def full_scale(dtype: np.dtype, bit_depth: int | None = None) -> float:
    if bit_depth:
        return float(2 ** int(bit_depth) - 1)
    return float(np.iinfo(dtype).max)


def exposure_problems(image: np.ndarray, full: float, checks: CheckConfig) -> list[str]:
    """Over/under-exposure of an averaged shot, as reasons (empty = fine)."""
    problems = []
    saturated = float(np.mean(image >= full - 1e-9))
    if saturated > checks.max_saturated_fraction:
        problems.append(
            f"over-exposed: {100 * saturated:.2f}% of pixels saturated "
            f"(limit {100 * checks.max_saturated_fraction:.2f}%)"
        )
    lo, hi = np.percentile(image, [0.5, 99.5])
    dyn = (hi - lo) / full
    if dyn < checks.min_dynamic_range:
        problems.append(
            f"under-exposed or blank: dynamic range {dyn:.3f} of full scale (minimum {checks.min_dynamic_range:.3f})"
        )
    return problems


def garbage_rows(image: np.ndarray, full: float) -> int:
    """Number of rows that look like transfer garbage rather than a harp image.

    A back-lit harp is smooth along most of each row except at string
    edges, so the mean absolute difference between neighbouring pixels of a
    row is a few grey levels (noise plus a few edge jumps). Rows of random
    bytes (a truncated or corrupted transfer) have a mean absolute
    difference near ``full / 3``. A row counts as garbage when its figure
    exceeds both ``0.15 * full`` and 10 x the median row's.
    """
    img = np.asarray(image, np.float32)
    if img.shape[1] < 2:
        return 0
    row = np.mean(np.abs(np.diff(img, axis=1)), axis=1)
    limit = max(0.15 * full, 10.0 * float(np.median(row)))
    return int(np.count_nonzero(row > limit))


def angle_difference(a: float, b: float) -> float:
    """Smallest difference between two line angles (degrees, modulo 180)."""
    d = (a - b) % 180.0
    return min(d, 180.0 - d)


def dominant_angle(angles: Sequence[float]) -> float:
    """Mean of line angles modulo 180 (doubled-angle circular mean)."""
    a = np.deg2rad(np.asarray(angles, np.float64) * 2.0)
    return float(np.rad2deg(np.arctan2(np.sin(a).mean(), np.cos(a).mean())) / 2.0) % 180.0


@dataclass(frozen=True)
class ShotMeasurement:
    """Edges of one averaged shot (one orientation of one focus setting)."""

    lines: tuple[np.ndarray, ...]  # (N, 2) smoothed, subsampled edge points
    angle_deg: float  # dominant string angle
    d: float
    d_max: float
    measurement: object = None  # the pipeline.measure.ImageMeasurement it came from

    @property
    def n_lines(self) -> int:
        return len(self.lines)


def measure_shot(image: np.ndarray, pipeline: PipelineConfig) -> ShotMeasurement:
    """Run :func:`pipeline.measure.measure_image` on an averaged shot."""
    from pipeline.measure import measure_image

    m = measure_image(image, t=pipeline.t)
    return shot_from_measurement(m)


def shot_from_measurement(m) -> ShotMeasurement:
    """The :class:`ShotMeasurement` of a :class:`pipeline.measure.ImageMeasurement`."""
    lines = tuple(np.asarray(l.points, np.float64) for l in m.lines)
    angle = dominant_angle([l.angle_deg for l in m.lines]) if lines else float("nan")
    return ShotMeasurement(
        lines=lines,
        angle_deg=angle,
        d=float(m.d) if lines else float("nan"),
        d_max=float(m.d_max) if lines else float("nan"),
        measurement=m,
    )


def shot_problems(m: ShotMeasurement, expected_angle: float, checks: CheckConfig) -> list[str]:
    """Strings found and at the expected angle, as reasons (empty = fine)."""
    if m.n_lines < checks.min_lines:
        return [f"only {m.n_lines} string edges found (need {checks.min_lines})"]
    diff = angle_difference(m.angle_deg, expected_angle)
    if diff > checks.angle_tolerance_deg:
        return [
            f"strings at {m.angle_deg:.1f} deg, expected {expected_angle:.1f} deg "
            f"(off by {diff:.1f} > {checks.angle_tolerance_deg:g})"
        ]
    return []


@dataclass(frozen=True)
class FocusFit:
    """The correction of one focus setting and how well it generalises."""

    model: object | None  # DistortionModel, None on failure
    fit_d: float
    fit_d_max: float
    holdout_d: float
    holdout_d_max: float
    holdout_per_orientation: tuple[float, ...] = ()
    failure: str | None = None
    details: dict = field(default_factory=dict)
    uncertainty_rms: float | None = None  # bootstrap field uncertainty over the image, px
    uncertainty_max: float | None = None
    uncertainty: object = None  # the pipeline.uncertainty.FieldUncertainty (per-pixel map), or None


def fit_focus(
    shots: Sequence[ShotMeasurement],
    width: int,
    height: int,
    pipeline: PipelineConfig,
    *,
    bootstrap: int = 0,
    seed: int = 0,
    map_fn=map,
) -> FocusFit:
    """Fit one focus setting on all orientations, cross-validate it, bootstrap it.

    * Fit: :func:`pipeline.fit.fit_distortion` on the edges of every shot
      (``pipeline.model: auto``: model and degree chosen first by
      cross-validation over the shots, :func:`pipeline.select.select_model`).
    * Holdout: leave-one-orientation-out — for each orientation the model is
      fitted on the others and applied to the left-out orientation's edges;
      ``holdout_d`` / ``holdout_d_max`` are the straightness (Tang et al.
      2012) of all left-out edges together. Edges the full fit rejected as
      outliers (dust, frame, mis-grouped) are left out of the evaluation.
    * Field uncertainty (``bootstrap`` >= 2 replicates):
      :func:`pipeline.uncertainty.bootstrap_field_uncertainty` — each shot's
      kept edges are resampled with replacement and refitted (started from
      the full fit); the spread of the corrections modulo homography is the
      per-pixel uncertainty map (``FocusFit.uncertainty``), reported as its
      RMS and max over the image.

    ``map_fn`` runs the independent fits (a process pool's ``map`` to use
    several cores); results do not depend on it.
    """
    from pipeline.edgeset import corrected_straightness, straightness_of
    from pipeline.fit import fit_distortion

    lines = [list(s.lines) for s in shots]
    selection = None
    spec = pipeline.spec
    if spec is None:
        from pipeline.select import select_model

        selection = select_model(lines, width, height)
        spec = selection.choice
    kw = spec.fit_arguments()
    full = fit_distortion(lines, width, height, **kw)
    if not full:
        return FocusFit(None, np.nan, np.nan, np.nan, np.nan, failure=full.reason)
    outliers = {(r.image, r.line) for r in full.rejected}
    from pipeline.uncertainty import refit_job

    jobs = [([ls for j, ls in enumerate(lines) if j != k], width, height, kw) for k in range(len(lines))]
    results = list(map_fn(refit_job, jobs))

    held_out: list[np.ndarray] = []
    per_o: list[float] = []
    for k, (model, reason) in enumerate(results[: len(lines)]):
        if reason:
            return FocusFit(
                full.model,
                full.d_after,
                full.d_max_after,
                np.nan,
                np.nan,
                failure=f"cross-validation without orientation {k}: {reason}",
            )
        kept = [p for i, p in enumerate(lines[k]) if (k, i) not in outliers and len(p) >= 3]
        per_o.append(corrected_straightness(model, kept)[0])
        held_out.extend(model.undistort_points(p) for p in kept)
    hold_d, hold_d_max = straightness_of(held_out)
    details = {
        "d_before": full.d_before,
        "d_max_before": full.d_max_before,
        "n_points": full.n_points,
        "n_params": full.n_params,
        "rejected_edges": len(full.rejected),
        "warnings": list(full.warnings),
        "fit": {k: v for k, v in kw.items()},
    }
    if selection is not None:
        details["selection"] = {"choice": selection.choice.label, "reason": selection.reason, "folds": selection.folds}
    unc = None
    if bootstrap == 1:
        details["bootstrap_failed"] = "a bootstrap needs at least 2 replicates (pipeline.bootstrap: 1)"
    elif bootstrap:
        from pipeline.uncertainty import bootstrap_field_uncertainty

        res = bootstrap_field_uncertainty(
            lines, width, height, spec, n_boot=bootstrap, seed=seed, full_fit=full, map_fn=map_fn
        )
        if not res:
            details.update(bootstrap_replicates=0, bootstrap_failed=bootstrap, bootstrap_failure=res.reason)
        else:
            unc = res
            details.update(bootstrap_replicates=res.n_boot, bootstrap_failed=res.n_failed)
        details["bootstrap_scheme"] = "edges resampled with replacement within each shot"
    return FocusFit(
        model=full.model,
        fit_d=full.d_after,
        fit_d_max=full.d_max_after,
        holdout_d=hold_d,
        holdout_d_max=hold_d_max,
        holdout_per_orientation=tuple(per_o),
        details=details,
        uncertainty_rms=unc.rms if unc is not None else None,
        uncertainty_max=unc.max if unc is not None else None,
        uncertainty=unc,
    )
