"""OpenCV's pinhole distortion model as a harp :class:`DistortionModel`.

Lets a calibration made with OpenCV (camera matrix + distortion coefficients)
be used, compared and evaluated like any harp correction.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike

from pipeline.models.base import CameraMatrixModel, pinhole_from_matrix, set_pinhole_fields
from pipeline.models.inverse import OUTSIDE_DOMAIN, Inverse, monotonic_reach, newton_inverse, radial_start

#: accuracy (px) to which :meth:`OpenCVModel.undistort_points` inverts the projection
OPENCV_INVERSE_TOL_PX = 1e-8
_VALID_NCOEFFS = (4, 5, 8, 12, 14)
#: largest normalised ideal radius ``r = tan(angle)`` (85 deg) :meth:`OpenCVModel.undistort_points` inverts to
OPENCV_REACH_LIMIT = 11.5


@dataclass(frozen=True)
class OpenCVModel(CameraMatrixModel):
    r"""OpenCV's pinhole camera distortion (``cv::projectPoints`` convention).

    OpenCV's coefficients describe the *projection* ideal -> distorted. With
    the camera matrix :math:`K = [[f_x, 0, c_x], [0, f_y, c_y], [0, 0, 1]]`,
    an ideal pixel :math:`(x_u, y_u)` has normalised coordinates
    :math:`x = (x_u - c_x)/f_x`, :math:`y = (y_u - c_y)/f_y`,
    :math:`r^2 = x^2 + y^2`, and is recorded at

    .. math::
        x'' &= x \frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}
               + 2 p_1 x y + p_2 (r^2 + 2x^2) + s_1 r^2 + s_2 r^4 \\
        y'' &= y \frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}
               + p_1 (r^2 + 2y^2) + 2 p_2 x y + s_3 r^2 + s_4 r^4 \\
        x_d &= f_x\, x''' + c_x, \quad y_d = f_y\, y''' + c_y

    where :math:`(x''', y''')` is :math:`(x'', y'')` after the sensor tilt
    :math:`(\tau_x, \tau_y)` (14-coefficient form only). Coefficient order as
    in OpenCV: ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, taux, tauy]]]]``.

    :meth:`distort_points` is this closed form (in numpy, tested equal to
    ``cv2.projectPoints`` to 1e-9 px; by ``cv2.projectPoints`` itself with tilt);
    :meth:`undistort_points` (the correction, distorted -> ideal, pixels in the
    same camera matrix) starts from the exact inverse of the radial part (bracketed on the radius
    inside :attr:`reach`, where the radial part increases: before its first fold or pole) and
    finishes with damped Newton steps on the closed form kept inside that disc
    (:func:`pipeline.models.inverse.newton_inverse`), to ``OPENCV_INVERSE_TOL_PX`` (1e-8 px)
    wherever the projection is invertible; NaN elsewhere (:meth:`undistort_inverse` says why).

    References
    ----------
    .. [1] OpenCV, "Camera Calibration and 3D Reconstruction" (calib3d),
       https://docs.opencv.org/master/d9/d0c/group__calib3d.html
    .. [2] D. C. Brown, "Close-range camera calibration", Photogrammetric
       Engineering 37(8), 1971.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    name: str = field(default="opencv", init=False, repr=False)

    def __post_init__(self) -> None:
        set_pinhole_fields(self, _VALID_NCOEFFS, "OpenCV distortion needs 4, 5, 8, 12 or 14 coefficients", "OpenCV")

    # ------------------------------------------------------------- matrices
    @classmethod
    def from_matrices(cls, camera_matrix: ArrayLike, dist_coeffs: ArrayLike) -> OpenCVModel:
        """From a 3x3 camera matrix and a coefficient vector (skew must be 0)."""
        fx, fy, cx, cy = pinhole_from_matrix(camera_matrix)
        return cls(fx=fx, fy=fy, cx=cx, cy=cy, dist=tuple(np.asarray(dist_coeffs, dtype=np.float64).ravel()))

    # ----------------------------------------------------------------- maps
    def distort_points(self, xy: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Closed form ideal -> distorted pixels (OpenCV's projection)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if len(xy) == 0:
            return xy.copy()
        if len(self.dist) < 14:  # closed form in numpy (tested equal to cv2.projectPoints)
            d = np.zeros(12)
            d[: len(self.dist)] = self.dist
            k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
            x = (xy[:, 0] - self.cx) / self.fx
            y = (xy[:, 1] - self.cy) / self.fy
            r2 = x * x + y * y
            r4 = r2 * r2
            rad = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
            yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
            return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=1)
        obj = np.empty((len(xy), 1, 3))
        obj[:, 0, 0] = (xy[:, 0] - self.cx) / self.fx
        obj[:, 0, 1] = (xy[:, 1] - self.cy) / self.fy
        obj[:, 0, 2] = 1.0
        out, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), self.camera_matrix, self.dist_coeffs)
        return out.reshape(-1, 2)

    def radial_map(self, r: np.ndarray) -> np.ndarray:
        """The radial part of the projection, ``r * (1 + k1 r^2 + ...) / (1 + k4 r^2 + ...)`` (normalised radii)."""
        d = np.zeros(8)
        d[: min(len(self.dist), 8)] = self.dist[:8]
        k1, k2, _p1, _p2, k3, k4, k5, k6 = d
        r = np.asarray(r, dtype=np.float64)
        r2 = r * r
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        with np.errstate(divide="ignore", invalid="ignore"):
            out: np.ndarray = np.where(den > 0, r * num / den, np.nan)
        return out

    @cached_property
    def reach(self) -> float:
        """Normalised ideal radius up to which the radial part of the projection increases (its first
        fold or pole; at most ``OPENCV_REACH_LIMIT``): the domain of :meth:`undistort_points`."""
        return monotonic_reach(self.radial_map, OPENCV_REACH_LIMIT, step=2e-3)

    def undistort_points(self, xy: np.ndarray, max_iter: int = 20) -> np.ndarray:
        """Distorted -> ideal pixels, to 1e-8 px (:meth:`undistort_inverse`)."""
        return self.undistort_inverse(xy, max_iter).points

    def undistort_inverse(self, xy: np.ndarray, max_iter: int = 20) -> Inverse:
        """:meth:`undistort_points` with, per point, why there is no inverse (see the class docstring)."""
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        f, c = np.array([self.fx, self.fy]), np.array([self.cx, self.cy])
        off = (target - c) / f
        rd = np.hypot(off[:, 0], off[:, 1])
        reach = self.reach
        r, ok = radial_start(self.radial_map, rd, reach, tol=0.1 * OPENCV_INVERSE_TOL_PX / max(self.fx, self.fy))
        with np.errstate(divide="ignore", invalid="ignore"):
            unit = np.where(rd[:, None] > 0, off / rd[:, None], 0.0)
        start = c + f * np.minimum(r, reach * (1 - 1e-9))[:, None] * unit
        pure = not any(self.dist[2:4]) and not any(self.dist[8:])  # no tangential, prism or tilt terms
        if pure:
            start[~ok] = np.nan

        def inside(x: np.ndarray) -> np.ndarray:
            n = (x - c) / f
            out: np.ndarray = np.hypot(n[:, 0], n[:, 1]) < reach
            return out

        inv = newton_inverse(
            self.distort_points, target, start, tol=OPENCV_INVERSE_TOL_PX, h=1e-3, max_iter=max_iter, inside=inside
        )
        if pure:
            inv.reason[~ok & np.all(np.isfinite(target), axis=1)] = OUTSIDE_DOMAIN
        return inv

    def undistortion_maps(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.initUndistortRectifyMap`` with the same camera matrix (OpenCV's own maps)."""
        k = self.camera_matrix
        return cv2.initUndistortRectifyMap(k, self.dist_coeffs, None, k, (int(width), int(height)), cv2.CV_32FC1)

    # ------------------------------------------------------------ file form
    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> OpenCVModel:
        return cls.from_matrices(d["camera_matrix"], d["distortion_coefficients"])
