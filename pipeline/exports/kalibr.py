"""Kalibr camera-chain YAML (``camchain.yaml``, one camera ``cam0``: pinhole-radtan or pinhole-equi).

Kalibr (ETH Zurich's calibration toolbox, aslam_cv) reads and writes cameras as

.. code-block:: yaml

    cam0:
      camera_model: pinhole
      intrinsics: [fu, fv, pu, pv]
      distortion_model: radtan        # or equidistant
      distortion_coeffs: [k1, k2, r1, r2]   # equidistant: [k1, k2, k3, k4]
      resolution: [width, height]

``pinhole`` projects ``u = fu x_d + pu``; ``radtan`` distorts the normalised point as OpenCV's
plumb_bob without ``k3`` (``k1 k2`` radial, ``r1 r2`` = OpenCV's ``p1 p2``), ``equidistant`` as
OpenCV's ``cv::fisheye`` (``theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)``, ``theta =
atan(r)``) [1]_. So the export is the OpenCV 4-coefficient fit
(:data:`~pipeline.exports.fit.RADTAN_COEFFS`) or the fisheye fit, with OpenCV's pixel convention
(Kalibr detects its targets with OpenCV: the centre of the top-left pixel at 0, 0). Kalibr inverts
the projection with a fixed number of steps (5 Gauss-Newton steps for radtan, 20 fixed-point steps
for equidistant); the conversion figures are those of the closed-form projection (and of its
converged inverse), and the file says that Kalibr's fixed steps can stop short on a strong lens
(the equidistant file of a lens of 0.015 px RMS stops 6.7 px RMS short with them).

References
----------
.. [1] Kalibr wiki, "Supported models" and "YAML formats",
   https://github.com/ethz-asl/kalibr/wiki/supported-models ,
   https://github.com/ethz-asl/kalibr/wiki/yaml-formats ; aslam_cv
   ``RadialTangentialDistortion.hpp``, ``EquidistantDistortion.hpp``, ``PinholeProjection.hpp``.
"""

from __future__ import annotations

from typing import Any

import yaml

from pipeline.exports.fit import RADTAN_COEFFS
from pipeline.exports.statement import OPENCV_PIXELS, Statement, hash_comments
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel

CAMERA = "cam0"


def kalibr_models(model: OpenCVModel | OpenCVFisheyeModel) -> tuple[str, str]:
    """``(camera_model, distortion_model)``: pinhole with radtan (4 coefficients) or equidistant (fisheye)."""
    if isinstance(model, OpenCVFisheyeModel):
        return "pinhole", "equidistant"
    if len(model.dist) != RADTAN_COEFFS:
        raise ValueError(
            f"Kalibr's radtan holds {RADTAN_COEFFS} OpenCV coefficients (k1 k2 p1 p2), not {len(model.dist)}"
        )
    return "pinhole", "radtan"


def kalibr_text(
    model: OpenCVModel | OpenCVFisheyeModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
    *,
    rostopic: str = "/cam0/image_raw",
) -> str:
    """The camchain YAML of one camera; the statement's ``stamp``: comment lines right after the title. With its ``frame``,
    comments state ``R`` and ``newK`` (:meth:`~pipeline.exports.frame.FrameStatement.ray_lines`)."""
    cam_model, dist_model = kalibr_models(model)
    lines = [f"Kalibr camera chain exported by harp station: {CAMERA}, {cam_model}-{dist_model}"]
    frame = statement.frame
    lines += statement.lines(
        conventions=[
            OPENCV_PIXELS,
            "Kalibr's projection (distort, then fu x + pu) is closed form and holds this conversion error; Kalibr's "
            "keypoint undistortion stops after a fixed number of steps (radtan: 5 Gauss-Newton, equidistant: 20 "
            "fixed-point) and can stop short on a strong lens: invert to convergence (e.g. cv2.fisheye.undistortPoints "
            "with criteria, cv2.undistortPointsIter)",
        ],
        frame=frame.ray_lines("Kalibr's keypointToEuclidean (normalised)") if frame is not None else (),
    )
    nums = ", ".join

    def fl(vals: Any) -> str:
        return "[" + nums(repr(float(v)) for v in vals) + "]"

    body = [
        f"{CAMERA}:",
        f"  camera_model: {cam_model}",
        f"  intrinsics: {fl([model.fx, model.fy, model.cx, model.cy])}",
        f"  distortion_model: {dist_model}",
        f"  distortion_coeffs: {fl(model.dist)}",
        f"  resolution: [{int(width)}, {int(height)}]",
        f"  rostopic: {rostopic}",
        "  cam_overlaps: []",
    ]
    return hash_comments(lines) + "\n".join(body) + "\n"


def sniff_kalibr(data: bytes) -> bool:
    head = data[:65536]
    return b"camera_model:" in head and b"distortion_coeffs:" in head and b"intrinsics:" in head


def read_kalibr_text(
    text: str, name: str = "<text>", size: tuple[int, int] | None = None
) -> tuple[OpenCVModel | OpenCVFisheyeModel, tuple[int, int] | None, str]:
    """The camera of a Kalibr camchain: ``(model, (width, height) or None, "pinhole-radtan"...)``.

    Several cameras: the one of ``size`` if exactly one has it, else ValueError. Reads
    ``pinhole`` with ``radtan``, ``equidistant`` or ``none``.
    """
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"{name}: not a Kalibr camchain YAML ({str(exc).splitlines()[0]})") from None
    cams = (
        {k: v for k, v in doc.items() if isinstance(v, dict) and "camera_model" in v} if isinstance(doc, dict) else {}
    )
    if not cams:
        raise ValueError(f"{name}: not a Kalibr camchain (no camN with camera_model)")
    if len(cams) > 1:
        fit = {k: v for k, v in cams.items() if size is not None and _size(v) == tuple(size)}
        if len(fit) != 1:
            raise ValueError(
                f"{name}: {len(cams)} Kalibr cameras, {len(fit)} of them for the shots' size: give a camchain of one"
            )
        cams = fit
    key, cam = next(iter(cams.items()))
    what = f"{name}: {key}"
    cm, dm = str(cam.get("camera_model")), str(cam.get("distortion_model", "none"))
    if cm != "pinhole" or dm not in ("radtan", "equidistant", "none"):
        raise ValueError(
            f"{what}: Kalibr model {cm}-{dm} not read (this reads pinhole-radtan, pinhole-equi, pinhole-none)"
        )
    try:
        fu, fv, pu, pv = (float(v) for v in cam["intrinsics"])
        d = tuple(float(v) for v in cam.get("distortion_coeffs", []) or [])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{what}: intrinsics must be [fu, fv, pu, pv] and distortion_coeffs numbers") from None
    want = 0 if dm == "none" else 4
    if len(d) != want:
        raise ValueError(f"{what}: {dm} needs {want} distortion_coeffs, got {len(d)}")
    try:
        if dm == "equidistant":
            m: OpenCVModel | OpenCVFisheyeModel = OpenCVFisheyeModel(
                fx=fu, fy=fv, cx=pu, cy=pv, dist=(d[0], d[1], d[2], d[3])
            )
        else:
            m = OpenCVModel(fx=fu, fy=fv, cx=pu, cy=pv, dist=d or (0.0, 0.0, 0.0, 0.0))
    except ValueError as exc:
        raise ValueError(f"{what}: {exc}") from None
    return m, _size(cam), f"{cm}-{'equi' if dm == 'equidistant' else dm}"


def _size(cam: dict[str, Any]) -> tuple[int, int] | None:
    r = cam.get("resolution")
    try:
        return (int(r[0]), int(r[1])) if r is not None else None
    except (TypeError, ValueError, IndexError):
        return None
