"""OpenCV's fisheye (Kannala–Brandt) camera model as a harp :class:`DistortionModel`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from pipeline.models.base import CameraMatrixModel, pinhole_from_matrix, set_pinhole_fields

Array = npt.NDArray[np.float64]

#: accuracy (px) to which :meth:`OpenCVFisheyeModel.undistort_points` inverts the projection
FISHEYE_INVERSE_TOL_PX = 1e-8


@dataclass(frozen=True)
class OpenCVFisheyeModel(CameraMatrixModel):
    r"""OpenCV's ``cv::fisheye`` projection (Kannala–Brandt, equidistant base), ROS ``equidistant``.

    The coefficients describe the *projection* ideal -> distorted. An ideal
    (pin-hole) pixel :math:`(x_u, y_u)` has normalised coordinates
    :math:`a = (x_u - c_x)/f_x`, :math:`b = (y_u - c_y)/f_y`, i.e. the ray at
    angle :math:`\theta = \arctan r`, :math:`r = \sqrt{a^2 + b^2}`, from the
    optical axis. It is recorded at

    .. math::
        \theta_d &= \theta\,(1 + k_1\theta^2 + k_2\theta^4 + k_3\theta^6 + k_4\theta^8) \\
        x_d &= f_x\,\frac{\theta_d}{r}\,a + c_x, \quad y_d = f_y\,\frac{\theta_d}{r}\,b + c_y

    (skew :math:`\alpha = 0`). With all :math:`k_i = 0` this is the
    equidistant fisheye :math:`R_d = f\theta`; the polynomial in :math:`\theta`
    represents equisolid, stereographic and real wide-angle lenses closely,
    beyond the reach of the pin-hole polynomial (which diverges as
    :math:`\theta \to 90°`).

    :meth:`distort_points` is this closed form (tested equal to
    ``cv2.fisheye.distortPoints``); :meth:`undistort_points` (the correction,
    distorted -> ideal pixels in the same camera matrix) starts from
    ``cv2.fisheye.undistortPoints`` and finishes with Newton steps on the
    closed form to ``FISHEYE_INVERSE_TOL_PX`` (NaN where it does not converge,
    or for rays at or beyond 90°, which have no pin-hole image).

    Parameter order as in OpenCV: ``fx, fy, cx, cy``, ``dist = (k1, k2, k3, k4)``.

    References
    ----------
    .. [1] J. Kannala, S. S. Brandt, "A generic camera model and calibration method
       for conventional, wide-angle, and fish-eye lenses", IEEE TPAMI 28(8), 2006.
    .. [2] OpenCV, "Fisheye camera model" (``cv::fisheye``),
       https://docs.opencv.org/master/db/d58/group__calib3d__fisheye.html
    """

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    name: str = field(default="opencv_fisheye", init=False, repr=False)

    def __post_init__(self) -> None:
        set_pinhole_fields(self, (4,), "OpenCV fisheye distortion needs 4 coefficients k1..k4", "OpenCV fisheye")

    def theta_d(self, theta: Array) -> Array:
        """The distorted angle :math:`\\theta_d(\\theta)`."""
        k1, k2, k3, k4 = self.dist
        t2 = theta * theta
        out: Array = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        return out

    def distort_points(self, xy: Array, max_iter: int = 50) -> Array:
        """Closed form ideal -> distorted pixels (OpenCV's ``fisheye::distortPoints``)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a = (xy[:, 0] - self.cx) / self.fx
        b = (xy[:, 1] - self.cy) / self.fy
        r = np.hypot(a, b)
        td = self.theta_d(np.arctan(r))
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(r > 1e-12, td / r, 1.0)
        return np.stack([self.fx * s * a + self.cx, self.fy * s * b + self.cy], axis=1)

    def undistort_points(self, xy: Array, max_iter: int = 30) -> Array:
        """Distorted -> ideal pixels: ``cv2.fisheye.undistortPoints`` then Newton to 1e-8 px."""
        target = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if len(target) == 0:
            return target.copy()
        k = self.camera_matrix
        x0 = cv2.fisheye.undistortPoints(target.reshape(-1, 1, 2), k, self.dist_coeffs, None, k)
        x = np.asarray(x0, dtype=np.float64).reshape(-1, 2)
        # 1-D Newton on the radius (the model is radial about (cx, cy) in normalised units)
        a = (target[:, 0] - self.cx) / self.fx
        b = (target[:, 1] - self.cy) / self.fy
        rd = np.hypot(a, b)
        r0 = np.hypot((x[:, 0] - self.cx) / self.fx, (x[:, 1] - self.cy) / self.fy)
        theta = np.where(np.isfinite(r0), np.arctan(r0), rd)
        k1, k2, k3, k4 = self.dist
        tol = FISHEYE_INVERSE_TOL_PX / max(self.fx, self.fy)
        done = np.zeros(len(theta), bool)
        for _ in range(max_iter):
            g = self.theta_d(theta) - rd
            done = np.abs(g) < tol
            if done.all():
                break
            t2 = theta * theta
            dg = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            with np.errstate(divide="ignore", invalid="ignore"):
                theta = np.where(done, theta, theta - g / dg)
        t2 = theta * theta
        slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
        ok = done & (theta >= 0) & (theta < np.pi / 2 - 1e-9) & (slope > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(rd > 1e-15, np.tan(theta) / rd, 1.0)
        ratio[~ok] = np.nan
        return np.stack([self.cx + self.fx * ratio * a, self.cy + self.fy * ratio * b], axis=1)

    def undistortion_maps(self, width: int, height: int) -> tuple[npt.NDArray[Any], npt.NDArray[Any]]:
        """``cv2.fisheye.initUndistortRectifyMap`` with the same camera matrix (OpenCV's own maps)."""
        k = self.camera_matrix
        mx, my = cv2.fisheye.initUndistortRectifyMap(
            k, self.dist_coeffs, np.eye(3), k, (int(width), int(height)), cv2.CV_32FC1
        )
        return np.asarray(mx), np.asarray(my)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> OpenCVFisheyeModel:
        return cls.from_matrices(d["camera_matrix"], d["distortion_coefficients"])

    @classmethod
    def from_matrices(cls, camera_matrix: npt.ArrayLike, dist_coeffs: npt.ArrayLike) -> OpenCVFisheyeModel:
        """From a 3x3 camera matrix (no skew) and ``k1..k4``."""
        fx, fy, cx, cy = pinhole_from_matrix(camera_matrix)
        d = np.asarray(dist_coeffs, dtype=np.float64).ravel()
        if len(d) != 4:
            raise ValueError(f"OpenCV fisheye distortion needs 4 coefficients k1..k4, got {len(d)}")
        return cls(fx=fx, fy=fy, cx=cx, cy=cy, dist=(d[0], d[1], d[2], d[3]))
