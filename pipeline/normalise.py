r"""Normalising a correction by the homography of its 4 corrected image corners.

A distortion correction is only defined up to a homography (lines stay
lines). To compare corrections, or to measure what one leaves, each is
composed with the homography :math:`H` that maps its corrected image corners
:math:`U(q_i)` back to the original corners :math:`q_i` (pixel centres
``(0, 0), (W-1, 0), (W-1, H-1), (0, H-1)``), so that corrected images keep
their size and position (Tang et al. 2012, Sect. 2).

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012, section 2.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from pipeline.models.base import DistortionModel
from pipeline.models.base import image_corners as image_corners  # defined beside the models (no import circle)
from pipeline.models.homography import HomographyModel, apply_homography


def _conditioning(p: np.ndarray) -> np.ndarray:
    """Similarity moving points ``p`` to their centroid, mean distance ``sqrt(2)`` (Hartley)."""
    c = p.mean(axis=0)
    s = np.sqrt(2) / max(np.mean(np.linalg.norm(p - c, axis=1)), 1e-300)
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def homography_from_4(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Exact homography ``H`` (``H[2,2] = 1``) with ``H(src_i) = dst_i`` for 4 points.

    Raises ValueError if three of the points are collinear (no unique H).
    """
    src = np.asarray(src, dtype=np.float64).reshape(4, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(4, 2)
    ts, td = _conditioning(src), _conditioning(dst)
    ps, pd = apply_homography(ts, src), apply_homography(td, dst)
    a = np.zeros((8, 8))
    b = np.zeros(8)
    for i, ((x, y), (u, v)) in enumerate(zip(ps, pd)):
        a[2 * i] = [x, y, 1, 0, 0, 0, -u * x, -u * y]
        a[2 * i + 1] = [0, 0, 0, x, y, 1, -v * x, -v * y]
        b[2 * i], b[2 * i + 1] = u, v
    if not np.all(np.isfinite(a)) or np.linalg.cond(a) > 1e12:
        raise ValueError("4-corner homography is degenerate (corners collinear or not finite)")
    hn = np.append(np.linalg.solve(a, b), 1.0).reshape(3, 3)
    h = np.linalg.inv(td) @ hn @ ts
    out: NDArray[np.float64] = h / h[2, 2]
    return out


def corner_homography(model: DistortionModel, width: int, height: int) -> np.ndarray:
    """``H`` mapping the model's corrected image corners back to the original corners
    (:meth:`~pipeline.models.base.DistortionModel.normalisation_points`)."""
    u, q = model.normalisation_points(width, height)
    if not np.all(np.isfinite(u)):
        raise ValueError("the correction is not defined at the image corners")
    return homography_from_4(u, q)


def normalise_by_corners(model: DistortionModel, width: int, height: int) -> HomographyModel:
    """The model composed with its :func:`corner_homography`: fixes the 4 image corners.

    This is the paper's normalisation (Tang et al. 2012, Sect. 2) making
    corrections from different methods comparable: it removes the homography
    a straight-line method cannot see, without changing any straightness.
    """
    h = corner_homography(model, width, height)
    return HomographyModel(base=model, homography=tuple(tuple(r) for r in h))


def fit_homography(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares homography ``H`` with ``H(src) ~ dst`` (pixels), Gauss-Newton refined.

    DLT on conditioned points followed by a few Gauss-Newton steps on the
    geometric (pixel) error, so the residual is the true minimum distance
    between two corrections modulo a homography.
    """
    src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 2)
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    src, dst = src[ok], dst[ok]
    ts, td = _conditioning(src), _conditioning(dst)
    ps, pd = apply_homography(ts, src), apply_homography(td, dst)
    n = len(ps)
    a = np.zeros((2 * n, 9))
    x, y, u, v = ps[:, 0], ps[:, 1], pd[:, 0], pd[:, 1]
    a[0::2, 0], a[0::2, 1], a[0::2, 2] = x, y, 1
    a[0::2, 6], a[0::2, 7], a[0::2, 8] = -u * x, -u * y, -u
    a[1::2, 3], a[1::2, 4], a[1::2, 5] = x, y, 1
    a[1::2, 6], a[1::2, 7], a[1::2, 8] = -v * x, -v * y, -v
    _, _, vt = np.linalg.svd(a, full_matrices=False)
    hn = vt[-1].reshape(3, 3)
    # Gauss-Newton on the geometric error in conditioned coordinates
    p = (hn / hn[2, 2]).ravel()[:8]
    for _ in range(10):
        hm = np.append(p, 1.0).reshape(3, 3)
        w = hm[2, 0] * x + hm[2, 1] * y + 1.0
        px = (hm[0, 0] * x + hm[0, 1] * y + hm[0, 2]) / w
        py = (hm[1, 0] * x + hm[1, 1] * y + hm[1, 2]) / w
        r = np.concatenate([px - u, py - v])
        j = np.zeros((2 * n, 8))
        j[:n, 0], j[:n, 1], j[:n, 2] = x / w, y / w, 1 / w
        j[:n, 6], j[:n, 7] = -px * x / w, -px * y / w
        j[n:, 3], j[n:, 4], j[n:, 5] = x / w, y / w, 1 / w
        j[n:, 6], j[n:, 7] = -py * x / w, -py * y / w
        step, *_ = np.linalg.lstsq(j, -r, rcond=None)
        p = p + step
        if np.max(np.abs(step)) < 1e-15:
            break
    hn = np.append(p, 1.0).reshape(3, 3)
    h = np.linalg.inv(td) @ hn @ ts
    out: NDArray[np.float64] = h / h[2, 2]
    return out
