r"""Compare two corrections modulo a homography; the 4-corner normalisation.

Two corrections that differ by a homography straighten exactly the same
lines, so a straight-line method can only determine a correction up to a
homography (Tang et al. 2012, Sect. 2). Two corrections :math:`U_a`,
:math:`U_b` are therefore compared by fitting the homography :math:`H` that
minimises :math:`\sum_p |H(U_a(p)) - U_b(p)|^2` over a dense grid of the image
(Gauss-Newton from the linear DLT solution,
:func:`pipeline.normalise.fit_homography`) and reporting what is left.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., Sect. 4.1 (DLT).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline import normalise
from pipeline.models.base import DistortionModel
from pipeline.models.homography import apply_homography


@dataclass(frozen=True)
class FieldComparison:
    """What is left between two corrections once the best homography is applied.

    ``rms`` and ``max`` are in pixels over the grid; ``homography`` (3x3,
    pixels) maps the corrected points of ``a`` onto those of ``b``.
    """

    rms: float
    max: float
    homography: np.ndarray
    n_points: int


def image_grid(width: int, height: int, step: float = 10.0) -> np.ndarray:
    """Grid of points (N, 2) covering the image, pixel-centre corners included."""
    xs = np.unique(np.append(np.arange(0.0, width - 1, step), width - 1.0))
    ys = np.unique(np.append(np.arange(0.0, height - 1, step), height - 1.0))
    xx, yy = np.meshgrid(xs, ys)
    return np.stack([xx.ravel(), yy.ravel()], axis=1)


def fit_homography(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares homography ``src -> dst`` (pixels); returns ``(H, residual vectors)``.

    ``H`` is :func:`pipeline.normalise.fit_homography`; the residuals
    ``H(src) - dst`` are over the points where both are finite.
    """
    src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 2)
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    h = normalise.fit_homography(src[ok], dst[ok])
    return h, apply_homography(h, src[ok]) - dst[ok]


def compare_models(
    a: DistortionModel, b: DistortionModel, width: int, height: int, step: float = 10.0
) -> FieldComparison:
    """Field difference of corrections ``a`` and ``b`` modulo the best homography.

    Parameters
    ----------
    a, b : DistortionModel
        Corrections (distorted -> ideal) of the same ``width x height`` camera.
    step : float
        Grid spacing in pixels (the grid includes the image corners).

    Returns
    -------
    FieldComparison
        RMS and max over the grid of ``|H(a.undistort(p)) - b.undistort(p)|``.
    """
    grid = image_grid(width, height, step)
    h, res = fit_homography(a.undistort_points(grid), b.undistort_points(grid))
    err = np.hypot(res[:, 0], res[:, 1])
    return FieldComparison(
        rms=float(np.sqrt(np.mean(err**2))), max=float(err.max()), homography=h, n_points=int(len(err))
    )


#: The 4-corner normalisation (Tang et al. 2012, Sect. 2), defined in :mod:`pipeline.normalise`.
corner_homography = normalise.corner_homography
corner_normalised = normalise.normalise_by_corners
