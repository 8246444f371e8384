"""Basalt calibration JSON (one camera, ``kb4``: Kannala-Brandt with ``fx fy cx cy k1..k4``).

Basalt (TUM's visual-inertial odometry and calibration, ``basalt-headers``) reads its calibration
with cereal's JSON archive: one object ``value0`` holding ``T_imu_cam`` (one pose a camera: ``px
py pz qx qy qz qw``), ``intrinsics`` (one ``{camera_type, intrinsics}`` a camera), ``resolution``
(``[[width, height]]``), the IMU's ``calib_accel_bias`` (9), ``calib_gyro_bias`` (12),
``imu_update_rate``, ``accel_noise_std``, ``gyro_noise_std``, ``accel_bias_std``,
``gyro_bias_std``, ``cam_time_offset_ns`` and ``vignette`` [1]_. cereal finds the members of
``value0`` by name, so a member it does not know (``harp_station``, this file's statement: the
conversion error, the camera matrix, the corrected image) is skipped.

``kb4`` projects a ray ``(x, y, z)`` at ``theta = atan2(r, z)``, ``r = sqrt(x^2 + y^2)``, to
``u = fx theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8) x / r + cx`` (and ``v``
alike) [2]_: OpenCV's ``cv::fisheye``
(:class:`~pipeline.models.opencv_fisheye_model.OpenCVFisheyeModel`) with the same four
coefficients, so the export is the fisheye fit (:mod:`pipeline.exports.fit`). Pixel convention:
OpenCV's (Basalt's Kalibr converters copy Kalibr's ``pu pv`` unchanged). Basalt's ``unproject``
takes a fixed 3 Newton steps on ``theta`` from ``theta_d`` (``solve_theta<3>``):
:func:`unproject_shortfall_px` is what they leave on the lens, stated in the file.

A camera-only calibration: the IMU members are placeholders (identity ``T_imu_cam``, zero biases
and noise, 200 Hz), as the file says; Basalt's IMU calibration fills them.

References
----------
.. [1] basalt-headers, ``include/basalt/serialization/headers_serialization.h`` (the cereal
   names of ``Calibration`` and of each camera model), https://gitlab.com/VladyslavUsenko/basalt-headers ;
   Basalt's ``data/*_calib.json`` examples.
.. [2] basalt-headers, ``include/basalt/camera/kannala_brandt_camera4.hpp`` (``project``,
   ``unproject``, ``solve_theta``); V. Usenko, N. Demmel, D. Cremers, "The Double Sphere Camera
   Model", 3DV 2018 (the KB4 model as Basalt uses it).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from pipeline.exports.conversion_error import image_grid
from pipeline.exports.statement import OPENCV_PIXELS, Statement
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel

CAMERA_TYPE = "kb4"
KB4_KEYS = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")
STATEMENT_KEY = "harp_station"
BASALT_NEWTON_STEPS = 3
"""Newton steps Basalt's ``KannalaBrandtCamera4::unproject`` takes on ``theta`` (``solve_theta<3>``)."""

IMU_PLACEHOLDERS: dict[str, Any] = {
    "calib_accel_bias": [0.0] * 9,
    "calib_gyro_bias": [0.0] * 12,
    "imu_update_rate": 200.0,
    "accel_noise_std": [0.0, 0.0, 0.0],
    "gyro_noise_std": [0.0, 0.0, 0.0],
    "accel_bias_std": [0.0, 0.0, 0.0],
    "gyro_bias_std": [0.0, 0.0, 0.0],
    "cam_time_offset_ns": 0,
    "vignette": [],
}
"""The IMU members of a camera-only calibration (Basalt needs every member of ``value0``)."""


def _theta_d(k: tuple[float, ...], t: np.ndarray) -> np.ndarray:
    t2 = t * t
    out: np.ndarray = t * (1 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))
    return out


def unproject_shortfall_px(model: OpenCVFisheyeModel, width: int, height: int, n_long: int = 64) -> float:
    """The max distance (px, on the image plane at the file's focal) between Basalt's 3-Newton-step
    ``unproject`` and the converged inverse of ``model``, over the image (inf where it fails)."""
    g = image_grid(width, height, n_long)
    mx, my = (g[:, 0] - model.cx) / model.fx, (g[:, 1] - model.cy) / model.fy
    td = np.hypot(mx, my)
    k = model.dist
    t = td.copy()
    for _ in range(BASALT_NEWTON_STEPS):
        t2 = t * t
        d = 1 + t2 * (3 * k[0] + t2 * (5 * k[1] + t2 * (7 * k[2] + t2 * 9 * k[3])))
        t = t + (td - _theta_d(k, t)) / d
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(td > 1e-12, np.tan(t) / td, 1.0)
    basalt = np.stack([model.fx * mx * s + model.cx, model.fy * my * s + model.cy], axis=1)
    exact = model.undistort_points(g)
    ok = np.all(np.isfinite(exact), axis=1)  # rays that have a pin-hole image
    e = np.hypot(*(basalt[ok] - exact[ok]).T)
    return float(np.max(np.where(np.isfinite(e), e, np.inf))) if len(e) else float("inf")


def basalt_text(
    model: OpenCVFisheyeModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
) -> str:
    """The calibration JSON of one ``kb4`` camera; the statement (stamp first) is ``value0.harp_station``."""
    if not isinstance(model, OpenCVFisheyeModel):
        raise ValueError("Basalt's kb4 holds the fisheye (Kannala-Brandt k1..k4) model")
    short = unproject_shortfall_px(model, width, height)
    frame = statement.frame
    lines = statement.lines(
        conventions=[
            OPENCV_PIXELS,
            f"Basalt's kb4 project is closed form and holds this conversion error; its unproject takes "
            f"{BASALT_NEWTON_STEPS} Newton steps on theta, which leave up to {short:.3g} px on this lens",
            "camera only: T_imu_cam is the identity and the IMU members are placeholders (zero biases and noise, "
            "200 Hz), not measured: calibrate the IMU with Basalt before visual-inertial use",
        ],
        frame=frame.ray_lines("Basalt's unproject (x/z, y/z)") if frame is not None else (),
    )
    value0: dict[str, Any] = {
        STATEMENT_KEY: {"exported_by": "harp station", "statement": lines},
        "T_imu_cam": [{"px": 0.0, "py": 0.0, "pz": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}],
        "intrinsics": [
            {
                "camera_type": CAMERA_TYPE,
                "intrinsics": dict(zip(KB4_KEYS, (model.fx, model.fy, model.cx, model.cy, *model.dist), strict=True)),
            }
        ],
        "resolution": [[int(width), int(height)]],
        **IMU_PLACEHOLDERS,
    }
    return json.dumps({"value0": value0}, indent=4, ensure_ascii=False) + "\n"


def sniff_basalt(data: bytes) -> bool:
    head = data[:65536]
    return data.lstrip()[:1] == b"{" and b'"value0"' in head and b'"camera_type"' in head


def read_basalt_text(
    text: str, name: str = "<text>", size: tuple[int, int] | None = None
) -> tuple[OpenCVFisheyeModel, tuple[int, int] | None, str]:
    """The camera of a Basalt calibration: ``(model, (width, height) or None, camera_type)``.

    Reads ``kb4``. Several cameras: the one of ``size`` if exactly one has it, else ValueError naming
    the file.
    """
    try:
        doc = json.loads(text)
        cams = doc["value0"]["intrinsics"]
        res = doc["value0"].get("resolution") or []
        if not isinstance(cams, list) or not cams:
            raise TypeError
    except (json.JSONDecodeError, KeyError, TypeError, AttributeError):
        raise ValueError(f"{name}: not a Basalt calibration (no value0.intrinsics list)") from None
    sizes = [_size(res[i]) if i < len(res) else None for i in range(len(cams))]
    i = 0
    if len(cams) > 1:
        fit = [j for j, s in enumerate(sizes) if size is not None and s == tuple(size)]
        if len(fit) != 1:
            raise ValueError(
                f"{name}: {len(cams)} Basalt cameras, {len(fit)} of them for the shots' size: give a calibration of one"
            )
        i = fit[0]
    cam = cams[i] if isinstance(cams[i], dict) else {}
    what = f"{name}: intrinsics[{i}]"
    kind = str(cam.get("camera_type"))
    if kind != CAMERA_TYPE:
        raise ValueError(f"{what}: Basalt camera_type {kind!r} not read (this reads kb4)")
    p: Any = cam.get("intrinsics")
    try:
        vals = [float(p[k]) for k in KB4_KEYS]
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{what}: kb4 needs the numbers {', '.join(KB4_KEYS)}") from None
    if not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{what}: non-finite kb4 intrinsics")
    try:
        m = OpenCVFisheyeModel(
            fx=vals[0], fy=vals[1], cx=vals[2], cy=vals[3], dist=(vals[4], vals[5], vals[6], vals[7])
        )
    except ValueError as exc:
        raise ValueError(f"{what}: {exc}") from None
    return m, sizes[i], kind


def _size(r: Any) -> tuple[int, int] | None:
    try:
        return int(r[0]), int(r[1])
    except (TypeError, ValueError, IndexError, KeyError):
        return None
