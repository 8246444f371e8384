"""COLMAP's ``THIN_PRISM_FISHEYE`` camera model as a harp :class:`DistortionModel`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.models.base import CameraMatrixModel, set_pinhole_fields
from pipeline.models.inverse import newton_inverse

Array = npt.NDArray[np.float64]

THIN_PRISM_INVERSE_TOL_PX = 1e-8
"""Accuracy (px) to which :meth:`ThinPrismFisheyeModel.undistort_points` inverts the projection."""


@dataclass(frozen=True)
class ThinPrismFisheyeModel(CameraMatrixModel):
    r"""The fisheye projection with radial, tangential and thin-prism terms of COLMAP's ``THIN_PRISM_FISHEYE``.

    An ideal (pin-hole) pixel :math:`(x_u, y_u)` has normalised coordinates :math:`a = (x_u - c_x)/f_x`,
    :math:`b = (y_u - c_y)/f_y`, :math:`r = \sqrt{a^2 + b^2}`; the ray's angle :math:`\theta = \arctan r`
    puts it at :math:`u = \theta a / r`, :math:`v = \theta b / r` (the equidistant fisheye), which is
    distorted, with :math:`\rho^2 = u^2 + v^2` and :math:`R = k_1\rho^2 + k_2\rho^4 + k_3\rho^6 + k_4\rho^8`,

    .. math::
        u' &= u + u R + 2 p_1 u v + p_2 (\rho^2 + 2u^2) + s_{x1}\rho^2 \\
        v' &= v + v R + 2 p_2 u v + p_1 (\rho^2 + 2v^2) + s_{y1}\rho^2

    and recorded at :math:`x_d = f_x u' + c_x`, :math:`y_d = f_y v' + c_y`. With :math:`p = s = 0` this
    is OpenCV's ``cv::fisheye`` (:class:`~pipeline.models.opencv_fisheye_model.OpenCVFisheyeModel`).

    :meth:`distort_points` is this closed form; :meth:`undistort_points` inverts the distortion of
    :math:`(u, v)` by Newton steps (analytic Jacobian) to :data:`THIN_PRISM_INVERSE_TOL_PX`, NaN where
    they do not converge, the Jacobian is not positive (a fold) or the ray is at or beyond 90 degrees.

    Parameters in COLMAP's order: ``fx, fy, cx, cy``, ``dist = (k1, k2, p1, p2, k3, k4, sx1, sy1)``;
    pixel convention harp's (COLMAP's ``cx, cy`` are these + 0.5).

    References
    ----------
    .. [1] COLMAP source, ``src/colmap/sensor/models.h``, ``ThinPrismFisheyeCameraModel``
       (``ImgFromCam``, ``Distortion``); https://colmap.github.io/cameras.html
    .. [2] J. Weng, P. Cohen, M. Herniou, "Camera calibration with distortion models and accuracy
       evaluation", IEEE TPAMI 14(10), 1992 (thin-prism distortion).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float, float, float, float] = (0.0,) * 8
    name: str = field(default="thin_prism_fisheye", init=False, repr=False)

    def __post_init__(self) -> None:
        set_pinhole_fields(
            self, (8,), "THIN_PRISM_FISHEYE needs 8 coefficients k1 k2 p1 p2 k3 k4 sx1 sy1", "THIN_PRISM_FISHEYE"
        )

    def _distorted(self, u: Array, v: Array) -> tuple[Array, Array]:
        k1, k2, p1, p2, k3, k4, sx, sy = self.dist
        r2 = u * u + v * v
        rad = r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
        du = u * rad + 2 * p1 * u * v + p2 * (r2 + 2 * u * u) + sx * r2
        dv = v * rad + 2 * p2 * u * v + p1 * (r2 + 2 * v * v) + sy * r2
        return u + du, v + dv

    def _jacobian(self, u: Array, v: Array) -> tuple[Array, Array, Array, Array]:
        k1, k2, p1, p2, k3, k4, sx, sy = self.dist
        r2 = u * u + v * v
        rad = r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
        drad = k1 + r2 * (2 * k2 + r2 * (3 * k3 + r2 * 4 * k4))  # d rad / d r2
        juu = 1 + rad + 2 * u * u * drad + 2 * p1 * v + 6 * p2 * u + 2 * sx * u
        juv = 2 * u * v * drad + 2 * p1 * u + 2 * p2 * v + 2 * sx * v
        jvu = 2 * u * v * drad + 2 * p2 * v + 2 * p1 * u + 2 * sy * u
        jvv = 1 + rad + 2 * v * v * drad + 2 * p2 * u + 6 * p1 * v + 2 * sy * v
        return juu, juv, jvu, jvv

    def distort_points(self, xy: Array, max_iter: int = 50) -> Array:
        """Closed form ideal -> distorted pixels (COLMAP's ``ImgFromCam``)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a, b = (xy[:, 0] - self.cx) / self.fx, (xy[:, 1] - self.cy) / self.fy
        r = np.hypot(a, b)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(r > 1e-12, np.arctan(r) / r, 1.0)
        ud, vd = self._distorted(a * s, b * s)
        return np.stack([self.fx * ud + self.cx, self.fy * vd + self.cy], axis=1)

    def undistort_points(self, xy: Array, max_iter: int = 30) -> Array:
        """Distorted -> ideal pixels: the distortion of the equidistant point inverted by the project's one
        safeguarded Newton (:func:`pipeline.models.inverse.newton_inverse`, with this model's Jacobian), then ``tan``."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        t = np.stack([(xy[:, 0] - self.cx) / self.fx, (xy[:, 1] - self.cy) / self.fy], axis=1)

        def forward(p: Array) -> Array:
            return np.stack(self._distorted(p[:, 0], p[:, 1]), axis=1)

        def jacobian(p: Array) -> tuple[Array, Array, Array, Array]:
            return self._jacobian(p[:, 0], p[:, 1])

        # both components below tol / sqrt(2): the residual's length below tol
        tol = THIN_PRISM_INVERSE_TOL_PX / max(self.fx, self.fy) / np.sqrt(2.0)
        inv = newton_inverse(forward, t, t, tol=tol, h=0.0, max_iter=max_iter, jacobian=jacobian)
        u, v = inv.points[:, 0], inv.points[:, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            juu, juv, jvu, jvv = self._jacobian(u, v)
            theta = np.hypot(u, v)
            ok = inv.ok & (juu * jvv - juv * jvu > 0) & (theta < np.pi / 2 - 1e-9)
            s = np.where(theta > 1e-15, np.tan(theta) / theta, 1.0)
        s[~ok] = np.nan
        return np.stack([self.cx + self.fx * u * s, self.cy + self.fy * v * s], axis=1)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ThinPrismFisheyeModel:
        k = np.asarray(d["camera_matrix"], dtype=np.float64)
        c = [float(v) for v in d["distortion_coefficients"]]
        if len(c) != 8:
            raise ValueError(f"THIN_PRISM_FISHEYE needs 8 coefficients, got {len(c)}")
        return cls(
            fx=k[0, 0], fy=k[1, 1], cx=k[0, 2], cy=k[1, 2], dist=(c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7])
        )
