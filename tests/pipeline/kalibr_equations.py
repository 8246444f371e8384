"""Kalibr's camera model equations (aslam_cv), written out from its documentation and sources for the tests:
no Kalibr is installed (a ROS/catkin package, not on PyPI). ``PinholeProjection``: ``u = fu x_d + pu``;
``RadialTangentialDistortion`` (``k1 k2 r1 r2``) and ``EquidistantDistortion`` (``k1..k4``): ``distort``
in closed form, ``undistort`` with Kalibr's own step counts (5 Gauss-Newton steps, 20 fixed-point steps).
"""

import numpy as np
import yaml


def radtan_distort(y, k):
    k1, k2, p1, p2 = k
    x0, x1 = y[:, 0], y[:, 1]
    mx2, my2, mxy = x0 * x0, x1 * x1, x0 * x1
    rho2 = mx2 + my2
    rad = k1 * rho2 + k2 * rho2 * rho2
    return np.stack(
        [x0 + x0 * rad + 2 * p1 * mxy + p2 * (rho2 + 2 * mx2), x1 + x1 * rad + 2 * p2 * mxy + p1 * (rho2 + 2 * my2)],
        axis=1,
    )


def radtan_jacobian(y, k):
    k1, k2, p1, p2 = k
    x0, x1 = y[:, 0], y[:, 1]
    mx2, my2 = x0 * x0, x1 * x1
    rho2 = mx2 + my2
    rad = k1 * rho2 + k2 * rho2 * rho2
    j00 = 1 + rad + k1 * 2 * mx2 + k2 * rho2 * 4 * mx2 + 2 * p1 * x1 + 6 * p2 * x0
    j10 = k1 * 2 * x0 * x1 + k2 * 4 * rho2 * x0 * x1 + p1 * 2 * x0 + 2 * p2 * x1
    j11 = 1 + rad + k1 * 2 * my2 + k2 * rho2 * 4 * my2 + 6 * p1 * x1 + 2 * p2 * x0
    return np.stack([np.stack([j00, j10], -1), np.stack([j10, j11], -1)], -2)


def radtan_undistort(y, k, steps=5):
    """Kalibr's RadialTangentialDistortion::undistort: Gauss-Newton from the distorted point, ``steps`` steps."""
    ybar = y.copy()
    for _ in range(steps):
        e = y - radtan_distort(ybar, k)
        ybar = ybar + np.linalg.solve(radtan_jacobian(ybar, k), e[..., None])[..., 0]
    return ybar


def equi_distort(y, k):
    r = np.hypot(y[:, 0], y[:, 1])
    t = np.arctan(r)
    td = t * (1 + k[0] * t**2 + k[1] * t**4 + k[2] * t**6 + k[3] * t**8)
    s = np.where(r > 1e-8, td / np.maximum(r, 1e-300), 1.0)
    return y * s[:, None]


def equi_undistort(y, k, steps=20):
    """Kalibr's EquidistantDistortion::undistort: ``steps`` fixed-point steps on theta."""
    td = np.hypot(y[:, 0], y[:, 1])
    t = td.copy()
    for _ in range(steps):
        t = td / (1 + k[0] * t**2 + k[1] * t**4 + k[2] * t**6 + k[3] * t**8)
    return y * (np.tan(t) / td)[:, None]


def equi_undistort_newton(y, k, steps=50):
    """The same inverse to convergence (Newton on theta; not Kalibr's: its fixed point need not converge)."""
    td = np.hypot(y[:, 0], y[:, 1])
    t = td.copy()
    for _ in range(steps):
        f = t * (1 + k[0] * t**2 + k[1] * t**4 + k[2] * t**6 + k[3] * t**8) - td
        t = t - f / (1 + 3 * k[0] * t**2 + 5 * k[1] * t**4 + 7 * k[2] * t**6 + 9 * k[3] * t**8)
    return y * (np.tan(t) / td)[:, None]


def kalibr_camera(data):
    """cam0 parsed with PyYAML: (fu, fv, pu, pv), distortion model, coefficients, resolution."""
    doc = yaml.safe_load(data)
    (cam,) = doc.values()
    assert cam["camera_model"] == "pinhole"
    return np.array(cam["intrinsics"], float), cam["distortion_model"], np.array(cam["distortion_coeffs"]), cam


def project(p, model, k, x):
    d = radtan_distort(x, k) if model == "radtan" else equi_distort(x, k)
    return np.stack([p[0] * d[:, 0] + p[2], p[1] * d[:, 1] + p[3]], axis=1)


def unproject(p, model, k, q, converged=False):
    """Pixels to the normalised plane: with Kalibr's own step counts, or ``converged``."""
    y = np.stack([(q[:, 0] - p[2]) / p[0], (q[:, 1] - p[3]) / p[1]], axis=1)
    if model == "radtan":
        return radtan_undistort(y, k, 50 if converged else 5)
    return equi_undistort_newton(y, k) if converged else equi_undistort(y, k, 20)
