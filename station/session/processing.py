"""What the executor does with captured frames: average, check, measure.

Thin glue between the session and the pure :mod:`pipeline`: averaging the
frames of a shot, the check of each frame for transfer damage
(:func:`frame_stats`, :func:`frame_damage`: against the frames already accepted,
whatever the extent of the damage) and the acceptance checks of a shot
(exposure, strings found, string angle against the commanded orientation). The per-focus fit is
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


#: a row whose directional difference (:class:`FrameStats`) exceeds this fraction of full scale
#: is not image data: random bytes give 0.30; harps from 6 px spacing with sharp 3 px strings
#: to 60 px spacing give at most 0.054 at any angle (0.010-0.014 for the demo's), sensor noise
#: of sigma s grey levels 1.13 s
RANDOM_DIFFERENCE = 0.12
FRAME_BANDS = 16
"""Horizontal bands of a frame whose statistics are compared with the reference frame's."""

#: neighbour offsets (dx, dy), 8 directions 22.5 deg apart: one lies within 11.25 deg of any string
_DIRECTIONS = ((1, 0), (2, 1), (1, 1), (1, 2), (0, 1), (-1, 2), (-1, 1), (-2, 1))
_COLUMN_STEP = 2  # every other column is enough for a row's mean


@dataclass(frozen=True)
class FrameStats:
    """Row statistics of one frame, as fractions of full scale (:func:`frame_stats`).

    ``level[y]`` is the mean of row ``y``. ``difference[y]`` is the mean absolute
    difference between the pixels of row ``y`` and their neighbours one or two pixels
    away in the smoothest of 8 directions: an image of strings, at whatever angle and
    density, is nearly constant along the strings, so this is the sensor noise plus a
    little (at most 0.054 even for a dense, sharp harp), while random bytes — whose
    differences are the same in every direction — give 0.30. ``flat[y]`` says the row is
    one constant value below full scale (a zero-filled or dropped transfer; a sensor row
    has noise, and a saturated one is the exposure check's).
    """

    level: np.ndarray
    difference: np.ndarray
    flat: np.ndarray

    @property
    def rows(self) -> int:
        return len(self.level)

    def bands(self, n: int = FRAME_BANDS) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[int, int]]]:
        """Per-band mean level, mean difference, fraction of flat rows, and each band's rows ``[a, b)``."""
        edges = np.linspace(0, self.rows, min(n, self.rows) + 1).round().astype(int)
        spans = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
        lv = np.array([self.level[a:b].mean() for a, b in spans])
        df = np.array([self.difference[a:b].mean() for a, b in spans])
        fl = np.array([self.flat[a:b].mean() for a, b in spans])
        return lv, df, fl, spans


def frame_stats(image: np.ndarray, full: float) -> FrameStats:
    """The :class:`FrameStats` of a 2-D frame with full scale ``full``."""
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 3 or img.shape[1] < 5:
        raise ValueError(f"a frame must be a 2-D array of at least 5x3 pixels, got shape {img.shape}")
    f = img.astype(np.float32) * np.float32(1.0 / full)
    h, w = f.shape
    k = _COLUMN_STEP
    best = np.full(h, np.inf, np.float32)
    for dx, dy in _DIRECTIONS:
        x0 = max(0, -dx)
        x1 = w - max(0, dx)
        d = np.abs(f[: h - dy, x0:x1:k] - f[dy:, x0 + dx : x1 + dx : k]).mean(axis=1)
        if dy:  # the last rows have no neighbour below: they take their upper neighbour's figure
            d = np.concatenate([d, np.repeat(d[-1:], dy)])
        np.minimum(best, d, out=best)
    level = f.mean(axis=1)
    top = img.max(axis=1)
    flat = (top == img.min(axis=1)) & (top < full)  # constant, and not saturated (that is exposure's to judge)
    return FrameStats(level.astype(np.float64), best.astype(np.float64), flat)


def frame_damage(stats: FrameStats, reference: FrameStats | None = None, *, same_pose: bool = False) -> str | None:
    """Why a frame looks damaged (a corrupted or short transfer), or None.

    Whatever the extent of the damage — one row or all of them — a frame is judged
    against what a frame of this shot is expected to look like, never against the
    median of its own rows:

    * on its own: rows whose directional difference exceeds :data:`RANDOM_DIFFERENCE` of
      full scale are not image data (random bytes), however many there are;
    * against ``reference``, an accepted frame of the same session with the same
      image size (``same_pose``: of the same shot, where only noise differs): in each
      of :data:`FRAME_BANDS` horizontal bands, the mean level must not fall more than
      35 % below the reference's (same pose: stay within 5 % of full scale; a brighter
      frame is left to the shot's exposure check), the difference within
      3x + 0.05 (same pose 2x + 0.01) of the reference's, and flat rows must not appear
      where the reference has none. Bands, not rows, since the strings move with the
      orientation; over a band of many rows the string duty cycle, the vignetting and
      so the mean level barely change.
    """
    bad = stats.difference > RANDOM_DIFFERENCE
    why = "random data"
    if bad.any():
        return f"{_row_ranges(bad)} of {stats.rows} unlike an image ({why})"
    if reference is None or reference.rows != stats.rows:
        return None
    lv, rs, fl, spans = stats.bands()
    rlv, rrs, rfl, _ = reference.bands()
    if same_pose:
        level_bad = np.abs(lv - rlv) > 0.05
        res_bad = rs > 2.0 * rrs + 0.01
    else:  # darker only: a brighter frame is an exposure matter (the shot's checks), not a transfer's
        level_bad = rlv - lv > 0.35 * np.maximum(rlv, 0.05)
        res_bad = rs > 3.0 * rrs + 0.05
    flat_bad = fl > rfl + 0.1
    worst = level_bad | res_bad | flat_bad
    if not worst.any():
        return None
    rows = np.zeros(stats.rows, bool)
    for (a, b), w in zip(spans, worst):
        rows[a:b] = w
    k = int(np.argmax(worst))
    if flat_bad[k] and not (level_bad | res_bad).any():
        rows &= stats.flat  # name the constant rows themselves
    if flat_bad[k]:
        detail = f"{100 * fl[k]:.0f}% constant rows, the accepted frames {100 * rfl[k]:.0f}%"
    elif level_bad[k]:
        detail = f"mean level {lv[k]:.3f} of full scale where the accepted frames have {rlv[k]:.3f}"
    else:
        detail = f"pixel differences {rs[k]:.3f} of full scale where the accepted frames have {rrs[k]:.3f}"
    return f"{_row_ranges(rows)} of {stats.rows} unlike the accepted frames ({detail})"


def _row_ranges(mask: np.ndarray) -> str:
    """``rows 271-959`` / ``row 3`` / ``rows 0-9, 500-511`` of a boolean mask (at most 3 ranges shown)."""
    idx = np.flatnonzero(mask)
    runs: list[tuple[int, int]] = []
    for i in idx:
        if runs and i == runs[-1][1] + 1:
            runs[-1] = (runs[-1][0], int(i))
        else:
            runs.append((int(i), int(i)))
    text = ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in runs[:3])
    if len(runs) > 3:
        text += f" and {len(runs) - 3} more ranges"
    n = int(mask.sum())
    return f"{'row' if n == 1 else 'rows'} {text}"


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


def measure_shot(image: np.ndarray, pipeline: PipelineConfig, cfa: str | None = None) -> ShotMeasurement:
    """Run :func:`pipeline.measure.measure_image` on an averaged shot; a colour camera's raw mosaic
    (``cfa``: its Bayer pattern, :func:`station.session.colour.frames_cfa`) on its luma
    (:func:`pipeline.cfa.mosaic_luma`: no checkerboard, no shift)."""
    from pipeline.measure import measure_image  # defers cv2

    if cfa is not None:
        from pipeline.cfa import mosaic_luma  # defers cv2

        image = mosaic_luma(image)
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
