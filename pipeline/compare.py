r"""Compare two corrections modulo a homography; the 4-corner normalisation.

Two corrections that differ by a homography straighten exactly the same
lines, so a straight-line method can only determine a correction up to a
homography (Tang et al. 2012, Sect. 2). Two corrections :math:`U_a`,
:math:`U_b` are therefore compared by fitting the homography :math:`H` that
minimises :math:`\sum_p |H(U_a(p)) - U_b(p)|^2` over a dense grid of the image
(Levenberg–Marquardt from the linear DLT solution) and reporting what is left.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., Sect. 4.1 (DLT).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from pipeline.models.base import DistortionModel
from pipeline.models.homography import HomographyModel, apply_homography


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


def _dlt(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Linear homography estimate src -> dst (normalised inputs), H[2,2] = 1."""
    x, y = src[:, 0], src[:, 1]
    u, v = dst[:, 0], dst[:, 1]
    z, o = np.zeros_like(x), np.ones_like(x)
    a = np.concatenate([np.stack([x, y, o, z, z, z, -u * x, -u * y, -u], 1),
                        np.stack([z, z, z, x, y, o, -v * x, -v * y, -v], 1)])
    h = np.linalg.svd(a, full_matrices=False)[2][-1].reshape(3, 3)
    return h / h[2, 2]


def fit_homography(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares homography ``src -> dst`` (pixels); returns ``(H, residual vectors)``."""
    src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 2)
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    src, dst = src[ok], dst[ok]
    c = src.mean(axis=0)
    s = max(float(np.sqrt(np.mean(np.sum((src - c) ** 2, axis=1)))), 1e-12)
    norm = np.array([[1 / s, 0, -c[0] / s], [0, 1 / s, -c[1] / s], [0, 0, 1.0]])
    sn = (src - c) / s
    dn = (dst - c) / s
    h0 = _dlt(sn, dn)

    def fun(p):
        return (apply_homography(np.append(p, 1.0).reshape(3, 3), sn) - dn).ravel() * s

    sol = least_squares(fun, h0.ravel()[:8], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    hn = np.append(sol.x, 1.0).reshape(3, 3)
    h = np.linalg.inv(norm) @ hn @ norm
    h = h / h[2, 2]
    return h, apply_homography(h, src) - dst


def compare_models(a: DistortionModel, b: DistortionModel, width: int, height: int,
                   step: float = 10.0) -> FieldComparison:
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
    return FieldComparison(rms=float(np.sqrt(np.mean(err ** 2))), max=float(err.max()), homography=h,
                           n_points=int(len(err)))


def corner_homography(model: DistortionModel, width: int, height: int) -> np.ndarray:
    """The homography mapping the 4 *corrected* image corners back to the original corners.

    Same as :func:`pipeline.normalise.corner_homography` (corners = pixel centres
    ``(0, 0), (W-1, 0), (W-1, H-1), (0, H-1)``).
    """
    from pipeline.normalise import corner_homography as _ch

    return _ch(model, width, height)


def corner_normalised(model: DistortionModel, width: int, height: int) -> HomographyModel:
    """``model`` followed by :func:`corner_homography`: leaves the 4 image corners fixed.

    This is the paper's normalisation (Tang et al. 2012, Sect. 2) making
    corrections from different methods comparable: it removes the homography
    a straight-line method cannot see, without changing any straightness.
    """
    from pipeline.normalise import normalise_by_corners

    return normalise_by_corners(model, width, height)
