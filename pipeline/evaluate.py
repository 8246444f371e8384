r"""Residual distortion left by a correction (the harp paper's first application).

Given the measured (smoothed, subsampled) string-edge points of harp shots
taken through the lens, and *any* correction :math:`U` (ours, OpenCV's,
lensfun's...), correct the points, normalise by the homography :math:`H`
that maps the 4 corrected image corners back to the original corners (so the
figures are in pixels of an image of the original size, whatever scaling the
correction applies), and measure the straightness :math:`d`, :math:`d_{max}`
of :math:`H(U(p))` (Tang et al. 2012, Sect. 2 and 5).

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography
from pipeline.normalise import corner_homography
from pipeline.straightness import Straightness, straightness


def corrected_points(
    point_sets: Sequence[np.ndarray], correction: DistortionModel, width: int, height: int
) -> list[np.ndarray]:
    """``H(U(p))`` for every edge: corrected and 4-corner normalised points.

    Raises ValueError if the correction is undefined at some edge point.
    """
    h = corner_homography(correction, width, height)
    out = []
    for p in point_sets:
        q = apply_homography(h, correction.undistort_points(np.asarray(p, dtype=np.float64)))
        if not np.all(np.isfinite(q)):
            raise ValueError("the correction is undefined at some edge points (not invertible there)")
        out.append(q)
    return out


def residual_straightness(
    point_sets: Sequence[np.ndarray], correction: DistortionModel, width: int, height: int
) -> Straightness:
    """Straightness of the edges after ``correction`` and the 4-corner normalisation."""
    return straightness(corrected_points(point_sets, correction, width, height))
