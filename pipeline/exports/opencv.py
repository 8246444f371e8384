"""OpenCV FileStorage calibration files (``camera_matrix`` + ``distortion_coefficients``).

Written and read with ``cv2.FileStorage`` itself (in memory), so OpenCV
loads the export unchanged. Fields: ``image_width``, ``image_height``,
``camera_matrix``, ``distortion_coefficients`` (1 x 5, 8, 12 or 14 for the
pin-hole model of ``cv::undistort`` / ``cv::initUndistortRectifyMap``; 1 x 4
``k1..k4`` for ``cv::fisheye``), ``distortion_model`` (``pinhole`` or
``fisheye``: which OpenCV functions take the coefficients),
``camera_matrix_kind`` (``nominal`` / ``given`` / ``placeholder``, see
:mod:`pipeline.exports.lens`), ``rectification_matrix``, ``new_camera_matrix``, ``new_image_width`` and
``new_image_height`` (with ``initUndistortRectifyMap(K, D, R, newK, size)`` they write harp undistort's
corrected image, :mod:`pipeline.exports.frame`) and the conversion error
``conversion_rms_px`` / ``conversion_max_px`` (4-corner normalised),
``conversion_rms_mod_h_px`` / ``conversion_max_mod_h_px`` (modulo
homography), ``conversion_d_px`` / ``conversion_d_max_px`` (straightness
left on a full-field harp) and, when known, ``conversion_shots_d_px`` (on
the fitting shots); the same figures as comments. Also reads OpenCV
calibrations made elsewhere (YAML or XML; names ``camera_matrix`` /
``distortion_coefficients``, or ``cameraMatrix`` / ``distCoeffs``, ``K`` / ``D``).

References
----------
.. [1] OpenCV, "Camera Calibration and 3D Reconstruction" (calib3d),
   https://docs.opencv.org/master/d9/d0c/group__calib3d.html
.. [2] OpenCV, ``cv::FileStorage`` (XML/YAML persistence),
   https://docs.opencv.org/master/da/d56/classcv_1_1FileStorage.html
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import cv2
import numpy as np

from pipeline.exports.colour import OpenCVChannel
from pipeline.exports.statement import Statement
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel

CAMERA_MATRIX_NAMES = ("camera_matrix", "cameraMatrix", "K")
DIST_NAMES = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D")


def opencv_text(
    model: OpenCVModel | OpenCVFisheyeModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
    *,
    xml: bool = False,
    comment: str | None = None,
    channels: Sequence[OpenCVChannel] = (),
) -> str:
    """FileStorage YAML (or XML) text of an OpenCV calibration (pin-hole or fisheye).

    ``channels``: red's and blue's cameras and coefficients
    (:func:`~pipeline.exports.colour.opencv_channels`), written as ``camera_matrix_red``,
    ``distortion_coefficients_red`` (and ``_blue``) with their conversion errors
    (``channel_conversion_rms_px_red``, ``channel_conversion_max_px_red``, ...).

    With the statement's ``frame`` the file holds ``rectification_matrix``, ``new_camera_matrix``, ``new_image_width``
    and ``new_image_height``: with them OpenCV writes harp undistort's corrected image
    (:mod:`pipeline.exports.frame`).

    Its ``stamp``: comment lines right after the title, before the figures. With its ``solver`` the file
    states what its point solver needs (comments, and the fields ``undistort_points_default_max_px``
    / ``undistort_points_iterations``, 0 when none suffices).
    """
    fisheye = isinstance(model, OpenCVFisheyeModel)
    error, camera, solver, frame = statement.error, statement.camera, statement.solver, statement.frame
    fs = cv2.FileStorage("calib.xml" if xml else "calib.yml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    kind = "fisheye (cv::fisheye, Kannala-Brandt k1..k4)" if fisheye else f"pinhole, {len(model.dist)} coefficients"
    fs.writeComment(comment or f"OpenCV {kind} distortion exported by harp station")
    for line in statement.lines(
        solver=solver.lines() if solver is not None else (),
        frame=frame.lines(fisheye) if frame is not None else (),
        notes=[c.line() for c in channels],
    ):
        fs.writeComment(line)
    fs.write("image_width", int(width))
    fs.write("image_height", int(height))
    fs.write("camera_matrix", model.camera_matrix)
    fs.write("distortion_coefficients", model.dist_coeffs.reshape(1, -1))
    fs.write("distortion_model", "fisheye" if fisheye else "pinhole")
    for c in channels:
        fs.write(f"camera_matrix_{c.name}", c.model.camera_matrix)
        fs.write(f"distortion_coefficients_{c.name}", c.model.dist_coeffs.reshape(1, -1))
        fs.write(f"channel_conversion_rms_px_{c.name}", float(c.rms_px))
        fs.write(f"channel_conversion_max_px_{c.name}", float(c.max_px))
    if frame is not None:
        fs.write("rectification_matrix", frame.rotation)
        fs.write("new_camera_matrix", frame.new_k)
        fs.write("new_image_width", int(frame.size[0]))
        fs.write("new_image_height", int(frame.size[1]))
    if camera is not None:
        fs.write("camera_matrix_kind", camera.kind)
        if camera.sd is not None:  # a measured camera matrix: 1 sigma of fx, fy, cx, cy
            fs.write("camera_matrix_sd_fx_fy_cx_cy", np.asarray(camera.sd, np.float64).reshape(1, 4))
    if error is not None:
        fs.write("conversion_rms_px", float(error.rms_px))
        fs.write("conversion_max_px", float(error.max_px))
        fs.write("conversion_rms_mod_h_px", float(error.rms_mod_h_px))
        fs.write("conversion_max_mod_h_px", float(error.max_mod_h_px))
        fs.write("conversion_d_px", float(error.d_px))
        fs.write("conversion_d_max_px", float(error.d_max_px))
        if math.isfinite(error.shots_d_px):
            fs.write("conversion_shots_d_px", float(error.shots_d_px))
            fs.write("conversion_shots_d_max_px", float(error.shots_d_max_px))
    if solver is not None:
        fs.write("undistort_points_default_max_px", float(solver.default_max_px))
        fs.write("undistort_points_iterations", int(solver.iterations or 0))
    return str(fs.releaseAndGetString())


def read_opencv_text(
    text: str, name: str = "<text>"
) -> tuple[OpenCVModel | OpenCVFisheyeModel, tuple[int, int] | None]:
    """Parse an OpenCV FileStorage calibration: ``(model, (width, height) or None)``.

    ``distortion_model: fisheye`` gives an :class:`OpenCVFisheyeModel`, anything
    else the pin-hole :class:`OpenCVModel`. Raises ValueError('<name>: <reason>')
    if it has no camera matrix / coefficients.
    """
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except cv2.error as exc:
        raise ValueError(f"{name}: not an OpenCV FileStorage file ({str(exc).strip().splitlines()[-1]})") from None
    try:
        if not fs.isOpened():
            raise ValueError(f"{name}: not an OpenCV FileStorage file")
        k, d, fisheye, size = _opencv_nodes(fs, name)
    except cv2.error as exc:  # a matrix whose data is not numbers ("readRawData can only be used ...")
        raise ValueError(f"{name}: not a readable OpenCV FileStorage file ({_cv2_reason(exc)})") from None
    finally:
        fs.release()
    try:
        if fisheye:
            return OpenCVFisheyeModel.from_matrices(k, d), size
        return OpenCVModel.from_matrices(k, d), size
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def _cv2_reason(exc: Exception) -> str:
    """OpenCV's own reason in an error's text (its last line, without the source file and function)."""
    text = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
    m = re.search(r"error: \(-?\d+:[^)]*\) (.*?)(?: in function '[^']*')?$", text)
    return m.group(1) if m else text


def _opencv_nodes(fs: cv2.FileStorage, name: str) -> tuple[np.ndarray, np.ndarray, bool, tuple[int, int] | None]:
    """``(camera matrix, coefficients, fisheye, size or None)`` of an open FileStorage."""
    k = next(
        (fs.getNode(n).mat() for n in CAMERA_MATRIX_NAMES if not fs.getNode(n).empty() and fs.getNode(n).isMap()),
        None,
    )
    d = next((fs.getNode(n).mat() for n in DIST_NAMES if not fs.getNode(n).empty() and fs.getNode(n).isMap()), None)
    if k is None or d is None:
        raise ValueError(f"{name}: OpenCV file without camera_matrix and distortion_coefficients matrices")
    dm = fs.getNode("distortion_model")
    fisheye = (not dm.empty()) and dm.isString() and dm.string().strip().lower() == "fisheye"
    size = None
    wn, hn = fs.getNode("image_width"), fs.getNode("image_height")
    if not wn.empty() and not hn.empty():
        size = (int(wn.real()), int(hn.real()))
    else:
        sn = fs.getNode("image_size")  # e.g. [w, h] sequences written by some tools
        if not sn.empty() and sn.isSeq() and sn.size() == 2:
            size = (int(sn.at(0).real()), int(sn.at(1).real()))
    return k, d, fisheye, size
