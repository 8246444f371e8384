r"""Exact derivatives of an OpenCV pin-hole export's projection, for its fit (:mod:`pipeline.exports.fit`).

The fit's residual at a grid point is :math:`D_{K,k}(X) - x_d` with :math:`X = H(U(x_d))` the ideal
point (:func:`pipeline.exports.fit.fit_opencv`). ``cv2.projectPoints`` returns, beside the projection,
its derivatives with respect to the camera matrix, the distortion coefficients and the translation;
with the ray :math:`((X - c_x)/f_x, (Y - c_y)/f_y, 1)` and zero rotation and translation, those with
respect to the translation are the derivatives with respect to the normalised coordinates, so

.. math::
    \frac{\partial D}{\partial X} = \frac{1}{f_x}\frac{\partial D}{\partial t_x}, \quad
    \frac{\partial D}{\partial c_x} = \frac{\partial D}{\partial c_x}\Big|_{\text{ray}}
    - \frac{\partial D}{\partial X}

(and the same in :math:`y`): the principal point moves the ray as well as the image. The
homography's part is the chain rule through :math:`X = H(u)` (:func:`homography_jacobian`).

References
----------
.. [1] OpenCV, ``cv::projectPoints`` (calib3d), its ``jacobian`` output,
   https://docs.opencv.org/master/d9/d0c/group__calib3d.html
.. [2] R. Hartley and A. Zisserman, *Multiple View Geometry in Computer Vision*, 2nd ed.,
   Cambridge University Press, 2004, section 4.2 (derivatives of a homography's action).
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from pipeline.models.opencv_model import OpenCVModel

Array = npt.NDArray[np.float64]


def projection_jacobian(m: OpenCVModel, ideal: Array) -> tuple[Array, Array]:
    """Derivatives of ``m.distort_points(ideal)``: ``(J_params, J_ideal)``.

    ``J_params`` ``(N, 2, 2 + n)``: with respect to ``(cx, cy, dist[0], ..., dist[n-1])`` (the principal
    point moving the ray too); ``J_ideal`` ``(N, 2, 2)``: with respect to the ideal pixel ``(X, Y)``.
    """
    p = np.asarray(ideal, dtype=np.float64).reshape(-1, 2)
    obj = np.empty((len(p), 1, 3))
    obj[:, 0, 0] = (p[:, 0] - m.cx) / m.fx
    obj[:, 0, 1] = (p[:, 1] - m.cy) / m.fy
    obj[:, 0, 2] = 1.0
    _, jac = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), m.camera_matrix, m.dist_coeffs)
    j = np.asarray(jac, dtype=np.float64).reshape(len(p), 2, -1)
    j_ideal = np.stack([j[:, :, 3] / m.fx, j[:, :, 4] / m.fy], axis=2)
    j_params = np.concatenate([j[:, :, 8:10] - j_ideal, j[:, :, 10:]], axis=2)
    return j_params, j_ideal


def homography_jacobian(tinv: Array, hn8: Array, t: Array, u: Array) -> Array:
    """Derivatives ``(N, 2, 8)`` of ``X = T^-1 Hn T u`` with respect to the 8 free entries of ``Hn``
    (row-major, ``Hn[2, 2] = 1``), ``T`` an affine conditioning (:class:`pipeline.exports.fit._Problem`)."""
    v = np.c_[np.asarray(u, dtype=np.float64).reshape(-1, 2), np.ones(len(u))] @ t.T
    hn = np.append(hn8, 1.0).reshape(3, 3)
    w = v @ hn.T
    q = w[:, :2] / w[:, 2:3]
    out = np.zeros((len(v), 2, 8))
    for i in range(2):  # row i of Hn moves coordinate i; the last row moves both through the division
        out[:, i, 3 * i : 3 * i + 3] = v / w[:, 2:3]
        out[:, i, 6:8] = -q[:, i : i + 1] * v[:, :2] / w[:, 2:3]
    return np.asarray(np.einsum("ij,njk->nik", tinv[:2, :2], out), dtype=np.float64)
