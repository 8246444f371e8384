"""Basalt's ``kb4`` camera (basalt-headers ``KannalaBrandtCamera4``), written out from its source for the tests:
no Basalt is installed (a C++ library, not on PyPI). ``project``: ``theta = atan2(r, z)``, ``r_theta = theta (1
+ k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``, ``u = fx r_theta x / r + cx``; ``unproject``: Newton on
theta from ``theta_d``, 3 steps (``solve_theta<3>``), the ray ``(sin theta mx / theta_d, sin theta my / theta_d,
cos theta)``. And the calibration file's members as cereal reads them (``headers_serialization.h``).
"""

import json

import numpy as np

CALIBRATION_MEMBERS = (  # basalt::Calibration's cereal names, in its order
    "T_imu_cam",
    "intrinsics",
    "resolution",
    "calib_accel_bias",
    "calib_gyro_bias",
    "imu_update_rate",
    "accel_noise_std",
    "gyro_noise_std",
    "accel_bias_std",
    "gyro_bias_std",
    "cam_time_offset_ns",
    "vignette",
)
KB4 = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")


def _poly(k, t):
    t2 = t * t
    return t * (1 + k[0] * t2 + k[1] * t2**2 + k[2] * t2**3 + k[3] * t2**4)


def _dpoly(k, t):
    t2 = t * t
    return 1 + 3 * k[0] * t2 + 5 * k[1] * t2**2 + 7 * k[2] * t2**3 + 9 * k[3] * t2**4


def project(p, xyz):
    """Rays (N, 3) to pixels with the kb4 intrinsics ``p`` (fx fy cx cy k1..k4)."""
    x, y, z = xyz.T
    r = np.hypot(x, y)
    theta = np.arctan2(r, z)
    rt = _poly(p[4:], theta)
    s = np.where(r > 1e-8, rt / np.maximum(r, 1e-300), 1 / z)
    return np.stack([p[0] * x * s + p[2], p[1] * y * s + p[3]], axis=1)


def unproject(p, uv, steps=3):
    """Pixels to rays (N, 3) as Basalt does (``steps`` Newton steps on theta; 3 in Basalt)."""
    mx, my = (uv[:, 0] - p[2]) / p[0], (uv[:, 1] - p[3]) / p[1]
    td = np.hypot(mx, my)
    t = td.copy()
    for _ in range(steps):
        t = t + (td - _poly(p[4:], t)) / _dpoly(p[4:], t)
    s = np.where(td > 1e-8, np.sin(t) / np.maximum(td, 1e-300), 1.0)
    return np.stack([mx * s, my * s, np.cos(t)], axis=1)


def normalised(rays):
    """The rays' points on the plane z = 1."""
    return rays[:, :2] / rays[:, 2:]


def basalt_camera(data):
    """The file parsed with the json module: (kb4 intrinsics as an array, resolution, value0)."""
    doc = json.loads(data)
    assert list(doc) == ["value0"]  # cereal reads the root's first member as value0
    v = doc["value0"]
    (cam,) = v["intrinsics"]
    assert cam["camera_type"] == "kb4" and set(cam["intrinsics"]) == set(KB4)
    return np.array([cam["intrinsics"][k] for k in KB4], float), v["resolution"][0], v
