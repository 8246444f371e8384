"""ROS camera_info calibration YAML (``camera_calibration_parsers`` format).

The file ``camera_info_manager`` loads: ``image_width``, ``image_height``,
``camera_name``, ``camera_matrix``, ``distortion_model`` (``plumb_bob`` for
5 coefficients, ``rational_polynomial`` for 8, ``equidistant`` for the
fisheye ``k1..k4`` of ``cv::fisheye``, which ROS 2's image_geometry
rectifies; Debian's python image_geometry 1.16 rectifies only the first
two), ``distortion_coefficients``,
``rectification_matrix`` and ``projection_matrix`` (``R`` and ``[newK | 0]`` of
:mod:`pipeline.exports.frame`: image_geometry then writes harp undistort's corrected image; without a
frame, identity and ``[K | 0]``), each matrix as ``{rows, cols, data}``. The conversion error
and what the camera matrix means (nominal or a placeholder scale, see
:mod:`pipeline.exports.lens`) are stated in leading comments (the format has
no field for them).

References
----------
.. [1] ROS ``sensor_msgs/CameraInfo`` message,
   https://docs.ros.org/en/api/sensor_msgs/html/msg/CameraInfo.html
.. [2] ROS ``camera_calibration_parsers`` package,
   https://wiki.ros.org/camera_calibration_parsers
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from pipeline.exports.statement import Statement, hash_comments
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel

ROS_FIELDS = (
    "image_width",
    "image_height",
    "camera_name",
    "camera_matrix",
    "distortion_model",
    "distortion_coefficients",
    "rectification_matrix",
    "projection_matrix",
)
ROS_DISTORTION_MODELS = {5: "plumb_bob", 8: "rational_polynomial"}
ROS_FISHEYE_MODEL = "equidistant"
ROS_EQUIDISTANT_READERS = (
    "distortion_model 'equidistant' is read by the C++ image_geometry (PinholeCameraModel, since "
    "vision_opencv pull request #358, 2020); ROS 1's Python image_geometry (e.g. Debian's "
    "python3-image-geometry 1.16.2) ignores distortion_model and applies these 4 coefficients as "
    "plumb_bob, which is wrong by hundreds of pixels on a wide lens: check that your consumer reads "
    "'equidistant', or export --format ros (pin-hole) for it"
)
"""Which ROS consumers read an ``equidistant`` camera_info, stated in the file and warned on export."""


def _mat(a: npt.ArrayLike) -> dict[str, Any]:
    a = np.atleast_2d(np.asarray(a, dtype=np.float64))
    return {"rows": int(a.shape[0]), "cols": int(a.shape[1]), "data": [float(v) for v in a.ravel()]}


def ros_text(
    model: OpenCVModel | OpenCVFisheyeModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
    *,
    camera_name: str = "camera",
) -> str:
    """camera_info YAML text for a 5- or 8-coefficient OpenCV model, or a fisheye one (``equidistant``).

    The statement's ``stamp``: comment lines right after the title. With its ``solver`` the comments state what
    rectifyPoint's solver needs on this lens. With its ``frame`` the rectification and projection matrices
    are its ``R`` and ``[newK | 0]`` (image_geometry then writes harp undistort's corrected image); ROS
    rectifies to the raw image's size, so a frame of another size is refused (ValueError)."""
    if isinstance(model, OpenCVFisheyeModel):
        dm = ROS_FISHEYE_MODEL
    else:
        n = len(model.dist)
        if n not in ROS_DISTORTION_MODELS:
            raise ValueError(f"ROS camera_info supports 5 (plumb_bob) or 8 (rational_polynomial) coefficients, got {n}")
        dm = ROS_DISTORTION_MODELS[n]
    k = model.camera_matrix
    rect, proj = np.eye(3), k
    frame, solver = statement.frame, statement.solver
    if frame is not None:
        if frame.size != (int(width), int(height)):
            raise ValueError(
                f"ROS rectifies to the raw image's size ({width}x{height}): a corrected image of "
                f"{frame.size[0]}x{frame.size[1]} cannot be written in a camera_info; use --scale or --alpha without --size"
            )
        rect, proj = frame.rotation, frame.new_k
    doc = {
        "image_width": int(width),
        "image_height": int(height),
        "camera_name": str(camera_name),
        "camera_matrix": _mat(k),
        "distortion_model": dm,
        "distortion_coefficients": _mat(model.dist_coeffs.reshape(1, -1)),
        "rectification_matrix": _mat(rect),
        "projection_matrix": _mat(np.hstack([proj, np.zeros((3, 1))])),
    }
    head = "# ROS camera_info calibration exported by harp station\n"
    lines = statement.lines(
        caveats=[ROS_EQUIDISTANT_READERS] if dm == ROS_FISHEYE_MODEL else [],
        solver=solver.lines(ros=True) if solver is not None else (),
        frame=frame.lines(isinstance(model, OpenCVFisheyeModel)) if frame is not None else (),
    )
    head += hash_comments(lines)
    return head + str(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=200))


def read_ros_text(text: str, name: str = "<text>") -> tuple[OpenCVModel | OpenCVFisheyeModel, tuple[int, int] | None]:
    """Parse a camera_info YAML: ``(model, (width, height))``; ValueError on defects."""
    try:
        doc = yaml.safe_load(text)
        k = np.asarray(doc["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)
        d = np.asarray(doc["distortion_coefficients"]["data"], dtype=np.float64)
        dm = doc.get("distortion_model", "plumb_bob")
    except (yaml.YAMLError, TypeError, KeyError, ValueError) as exc:
        raise ValueError(f"{name}: not a ROS camera_info YAML ({type(exc).__name__})") from None
    if dm not in ("plumb_bob", "rational_polynomial", ROS_FISHEYE_MODEL):
        raise ValueError(f"{name}: unsupported ROS distortion_model {dm!r}")
    size = None
    if "image_width" in doc and "image_height" in doc:
        size = (int(doc["image_width"]), int(doc["image_height"]))
    try:
        if dm == ROS_FISHEYE_MODEL:
            return OpenCVFisheyeModel.from_matrices(k, d), size
        return OpenCVModel.from_matrices(k, d), size
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
