"""Exposure figures of a frame (:mod:`pipeline.assess`, *Exposure*): histogram, saturated and dark
fractions, dynamic range."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

DARK_LEVEL = 0.02
"""A pixel at or below this fraction of full scale is dark (no usable signal)."""
HISTOGRAM_BINS = 64
"""Bins of :attr:`ExposureFigures.histogram` over ``[0, full scale]``."""


@dataclass(frozen=True)
class ExposureFigures:
    """What the exposure of a frame looks like.

    Attributes
    ----------
    full_scale : float
        The top code value (255 for 8-bit, 65535 for 16-bit frames).
    histogram : (HISTOGRAM_BINS,) int ndarray
        Pixel counts in equal bins over ``[0, full_scale]`` (the last bin
        holds the top value).
    saturated_fraction : float
        Fraction of pixels at (or above) ``full_scale``.
    dark_fraction : float
        Fraction of pixels at or below ``DARK_LEVEL * full_scale``.
    low, high : float
        The 0.5 and 99.5 percentiles (numpy's linear interpolation).
    dynamic_range : float
        ``(high - low) / full_scale``.
    mean : float
        Mean grey level.
    """

    full_scale: float
    histogram: NDArray[np.int64]
    saturated_fraction: float
    dark_fraction: float
    low: float
    high: float
    dynamic_range: float
    mean: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "full_scale": self.full_scale,
            "histogram": [int(c) for c in self.histogram],
            "saturated_fraction": self.saturated_fraction,
            "dark_fraction": self.dark_fraction,
            "low": self.low,
            "high": self.high,
            "dynamic_range": self.dynamic_range,
            "mean": self.mean,
        }


def full_scale_of(image: NDArray[Any]) -> float:
    """Top code value of an integer image's dtype; 255 for float images (8-bit scale)."""
    dt = np.asarray(image).dtype
    return float(np.iinfo(dt).max) if np.issubdtype(dt, np.integer) else 255.0


def _percentile_from_counts(counts: NDArray[np.int64], q: float) -> float:
    """numpy's linear percentile of the values ``0..len(counts)-1`` repeated ``counts`` times."""
    n = int(counts.sum())
    cum = np.cumsum(counts)
    pos = q / 100.0 * (n - 1)
    lo = math.floor(pos)
    frac = pos - lo
    v_lo = int(np.searchsorted(cum, lo, side="right"))
    v_hi = int(np.searchsorted(cum, min(lo + 1, n - 1), side="right"))
    return float(v_lo + frac * (v_hi - v_lo))


def exposure_figures(image: NDArray[Any], full_scale: float | None = None) -> ExposureFigures:
    """Histogram, saturated and dark fractions and dynamic range of a grey image.

    Parameters
    ----------
    image : 2-D ndarray
        uint8, uint16 or float grey image.
    full_scale : float or None
        Top code value (None: from the dtype, :func:`full_scale_of`).

    Returns
    -------
    ExposureFigures
        For integer images every figure is exact (read from the per-code
        histogram); float images (averaged frames) use ``np.percentile``.

    References
    ----------
    .. [1] numpy.percentile, method "linear" (Hyndman & Fan definition 7).
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"expected a non-empty 2-D grey image, got shape {img.shape}")
    full = full_scale_of(img) if full_scale is None else float(full_scale)
    if not full > 0:
        raise ValueError(f"full_scale must be > 0, got {full!r}")
    n = img.size
    dark_top = DARK_LEVEL * full
    if img.dtype in (np.uint8, np.uint16):
        codes = 256 if img.dtype == np.uint8 else 65536
        counts = cv2.calcHist([img], [0], None, [codes], [0, codes]).ravel().astype(np.int64)
        values = np.arange(codes, dtype=np.float64)
        saturated = float(counts[values >= full].sum()) / n
        dark = float(counts[values <= dark_top].sum()) / n
        low, high = _percentile_from_counts(counts, 0.5), _percentile_from_counts(counts, 99.5)
        mean = float(counts @ values) / n
        edges = np.minimum((values / full * HISTOGRAM_BINS).astype(np.int64), HISTOGRAM_BINS - 1)
        hist = np.bincount(edges, weights=counts, minlength=HISTOGRAM_BINS)[:HISTOGRAM_BINS].astype(np.int64)
    else:
        f = img.astype(np.float64, copy=False)
        saturated = float(np.count_nonzero(f >= full - 1e-9)) / n
        dark = float(np.count_nonzero(f <= dark_top)) / n
        low, high = (float(v) for v in np.percentile(f, [0.5, 99.5]))
        mean = float(f.mean())
        idx = np.clip((f / full * HISTOGRAM_BINS).astype(np.int64), 0, HISTOGRAM_BINS - 1)
        hist = np.bincount(idx.ravel(), minlength=HISTOGRAM_BINS).astype(np.int64)
    return ExposureFigures(full, hist, saturated, dark, low, high, (high - low) / full, mean)
