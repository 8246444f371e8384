"""What the executor does with captured frames: average, check, measure.

Thin glue between the session and the pure :mod:`pipeline`: averaging the
frames of a shot and the acceptance checks (exposure, strings found, string
angle against the commanded orientation). The per-focus fit is
:func:`station.calibration.calibrate_shots`. No files, no devices.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

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
