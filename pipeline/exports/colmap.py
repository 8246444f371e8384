"""COLMAP ``cameras.txt`` (one camera: ``OPENCV``, ``FULL_OPENCV``, ``OPENCV_FISHEYE`` or ``THIN_PRISM_FISHEYE``).

COLMAP's text model holds one camera a line, ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``, and
skips lines starting with ``#``. ``OPENCV`` takes ``fx fy cx cy k1 k2 p1 p2`` (OpenCV's model with
those 4 coefficients); ``FULL_OPENCV`` takes ``fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6``:
OpenCV's pin-hole projection with its 8 rational coefficients
(:class:`~pipeline.models.opencv_model.OpenCVModel`); ``OPENCV_FISHEYE`` takes ``fx fy cx cy
k1 k2 k3 k4``: OpenCV's ``cv::fisheye`` (Kannala-Brandt,
:class:`~pipeline.models.opencv_fisheye_model.OpenCVFisheyeModel`); ``THIN_PRISM_FISHEYE`` takes ``fx fy
cx cy k1 k2 p1 p2 k3 k4 sx1 sy1``: the equidistant fisheye with radial, tangential and thin-prism terms
(:class:`~pipeline.models.thin_prism_fisheye_model.ThinPrismFisheyeModel`). So the export is the OpenCV
4- or 8-coefficient, fisheye or thin-prism fisheye fit (:mod:`pipeline.exports.fit`; the registry
chooses: ``OPENCV`` when it is as exact as the calibration, else the closer of ``FULL_OPENCV`` and
``OPENCV_FISHEYE``, or ``THIN_PRISM_FISHEYE`` when the fisheye was tried and it is clearly closer); the
conversion figures, the choice, what the camera matrix means and the corrected image are in leading comments.

COLMAP's pixel convention differs from OpenCV's (and harp's): the centre of the top-left pixel is
at (0.5, 0.5), not (0, 0), so the file's ``cx``, ``cy`` are the OpenCV model's plus 0.5, and the
reader takes 0.5 off. COLMAP inverts the projection (``cam_from_img``) iteratively to
convergence, so the export needs no statement about a point solver.

The reader also takes COLMAP's other OpenCV-family models: ``RADIAL`` (``f cx cy k1 k2``), ``SIMPLE_RADIAL`` (``f cx cy k``), ``PINHOLE`` and
``SIMPLE_PINHOLE``.

References
----------
.. [1] COLMAP, "Output Format" (cameras.txt) and "Camera Models",
   https://colmap.github.io/format.html , https://colmap.github.io/cameras.html
.. [2] COLMAP source, ``src/colmap/sensor/models.h`` (the models' parameter order and equations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.exports.statement import Statement, hash_comments
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.thin_prism_fisheye_model import ThinPrismFisheyeModel

PIXEL_CENTRE = 0.5
"""COLMAP's coordinate of the centre of the top-left pixel (OpenCV's and harp's: 0)."""

CAMERA_ID = 1

COLMAP_MODELS = {
    "SIMPLE_PINHOLE": 3,
    "PINHOLE": 4,
    "SIMPLE_RADIAL": 4,
    "RADIAL": 5,
    "OPENCV": 8,
    "FULL_OPENCV": 12,
    "OPENCV_FISHEYE": 8,
    "THIN_PRISM_FISHEYE": 12,
}
"""The COLMAP camera models this module reads, with their number of parameters."""

PINHOLE_MODELS = {4: "OPENCV", 8: "FULL_OPENCV"}
"""The COLMAP pin-hole model of an OpenCV model with 4 (``k1 k2 p1 p2``) or 8 (rational) coefficients."""


@dataclass(frozen=True)
class ColmapCamera:
    """One line of a ``cameras.txt``."""

    camera_id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]


ColmapModel = OpenCVModel | OpenCVFisheyeModel | ThinPrismFisheyeModel


def colmap_model_name(model: ColmapModel) -> str:
    """``OPENCV_FISHEYE`` for the fisheye model, ``OPENCV`` / ``FULL_OPENCV`` for the 4- / 8-coefficient
    pin-hole one."""
    if isinstance(model, OpenCVFisheyeModel):
        return "OPENCV_FISHEYE"
    if isinstance(model, ThinPrismFisheyeModel):
        return "THIN_PRISM_FISHEYE"
    if len(model.dist) not in PINHOLE_MODELS:
        raise ValueError(f"COLMAP's OPENCV and FULL_OPENCV hold 4 or 8 OpenCV coefficients, not {len(model.dist)}")
    return PINHOLE_MODELS[len(model.dist)]


def colmap_line(model: ColmapModel, width: int, height: int, camera_id: int = CAMERA_ID) -> str:
    """``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`` of an OpenCV model (principal point in COLMAP's convention)."""
    name = colmap_model_name(model)
    params = [model.fx, model.fy, model.cx + PIXEL_CENTRE, model.cy + PIXEL_CENTRE, *model.dist]
    return f"{int(camera_id)} {name} {int(width)} {int(height)} " + " ".join(repr(float(v)) for v in params)


def colmap_text(
    model: ColmapModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
) -> str:
    """The ``cameras.txt`` text of one camera; the statement's ``stamp``: comment lines right after the title.

    With its ``frame``, comments state ``R`` and ``newK``: a point ``(x, y)`` of COLMAP's
    ``cam_from_img`` is at ``newK @ R @ (x, y, 1)`` in harp undistort's corrected image (harp pixels).
    """
    name = colmap_model_name(model)
    kind = {
        "OPENCV_FISHEYE": "OpenCV fisheye, Kannala-Brandt k1..k4",
        "THIN_PRISM_FISHEYE": "equidistant fisheye with k1..k4, tangential p1 p2 and thin prism sx1 sy1",
    }.get(name, f"OpenCV pin-hole, {len(model.dist)} coefficients")
    lines = [f"COLMAP camera list exported by harp station: 1 camera, {name} ({kind})"]
    frame = statement.frame
    lines += statement.lines(
        conventions=[
            "pixel convention: COLMAP's (the centre of the top-left pixel at 0.5, 0.5): cx, cy are OpenCV's + 0.5"
        ],
        frame=frame.ray_lines("COLMAP's cam_from_img") if frame is not None else (),
    )
    lines.append("CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]")
    return hash_comments(lines) + colmap_line(model, width, height) + "\n"


def parse_colmap_cameras(text: str, name: str = "<text>") -> list[ColmapCamera]:
    """Every camera line of a ``cameras.txt`` (ValueError naming the file and line if one is malformed)."""
    cams = []
    for i, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tok = line.split()
        if len(tok) < 4:
            raise ValueError(f"{name}: line {i}: a COLMAP camera needs CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]")
        model = tok[1]
        if model not in COLMAP_MODELS:
            raise ValueError(
                f"{name}: line {i}: COLMAP camera model {model!r} not read (this reads {', '.join(COLMAP_MODELS)})"
            )
        try:
            cid, w, h = int(tok[0]), int(tok[2]), int(tok[3])
            params = tuple(float(v) for v in tok[4:])
        except ValueError:
            raise ValueError(f"{name}: line {i}: non-numeric camera id, size or parameter") from None
        if len(params) != COLMAP_MODELS[model] or not all(math.isfinite(v) for v in params):
            raise ValueError(
                f"{name}: line {i}: {model} needs {COLMAP_MODELS[model]} finite parameters, got {len(params)}"
            )
        cams.append(ColmapCamera(cid, model, w, h, params))
    if not cams:
        raise ValueError(f"{name}: COLMAP cameras.txt without a camera line")
    return cams


def camera_model(cam: ColmapCamera) -> ColmapModel:
    """The OpenCV model of a COLMAP camera (principal point back to OpenCV's pixel convention)."""
    p = cam.params
    if cam.model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        f, cx, cy, fy = p[0], p[1], p[2], p[0]
        k = {"SIMPLE_PINHOLE": (0.0, 0.0), "SIMPLE_RADIAL": (p[3], 0.0), "RADIAL": (p[3], p[4])}[cam.model]
        dist: tuple[float, ...] = (k[0], k[1], 0.0, 0.0)
    else:
        f, fy, cx, cy = p[0], p[1], p[2], p[3]
        dist = (0.0, 0.0, 0.0, 0.0) if cam.model == "PINHOLE" else tuple(p[4:])
    cx, cy = cx - PIXEL_CENTRE, cy - PIXEL_CENTRE
    if cam.model == "OPENCV_FISHEYE":
        return OpenCVFisheyeModel(fx=f, fy=fy, cx=cx, cy=cy, dist=(dist[0], dist[1], dist[2], dist[3]))
    if cam.model == "THIN_PRISM_FISHEYE":
        d = dist
        return ThinPrismFisheyeModel(fx=f, fy=fy, cx=cx, cy=cy, dist=(d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]))
    return OpenCVModel(fx=f, fy=fy, cx=cx, cy=cy, dist=dist)


def read_colmap_text(
    text: str, name: str = "<text>", size: tuple[int, int] | None = None
) -> tuple[ColmapModel, tuple[int, int], str]:
    """The camera of a ``cameras.txt``: ``(model, (width, height), COLMAP model name)``.

    A file with several cameras: the one of ``size`` if exactly one has it, else ValueError.
    """
    cams = parse_colmap_cameras(text, name)
    if len(cams) > 1:
        fit = [c for c in cams if size is not None and (c.width, c.height) == tuple(size)]
        if len(fit) != 1:
            what = f"{len(fit)} of them for {size[0]}x{size[1]} images" if size is not None else "no image size"
            raise ValueError(f"{name}: {len(cams)} COLMAP cameras, {what}: give a cameras.txt with the one camera")
        cams = fit
    cam = cams[0]
    try:
        return camera_model(cam), (cam.width, cam.height), cam.model
    except ValueError as exc:
        raise ValueError(f"{name}: camera {cam.camera_id}: {exc}") from None


def sniff_colmap(data: bytes) -> bool:
    """Whether the first line that is not a comment is a COLMAP camera line."""
    for raw in data[:65536].splitlines():
        line = raw.strip()
        if not line or line.startswith(b"#"):
            continue
        tok = line.split()
        return (
            len(tok) >= 4
            and tok[1].decode("ascii", "replace") in COLMAP_MODELS
            and all(t.isdigit() for t in (tok[0], tok[2], tok[3]))
        )
    return False
