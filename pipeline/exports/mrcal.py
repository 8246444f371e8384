"""mrcal ``.cameramodel`` files (``LENSMODEL_OPENCV8`` / ``LENSMODEL_OPENCV12``).

A ``.cameramodel`` is a Python dict literal (comments allowed) read by
``mrcal.cameramodel(path)``: ``lensmodel``, ``intrinsics`` = ``fx, fy, cx, cy``
followed by the OpenCV distortion coefficients in OpenCV's order,
``imagersize`` = ``[width, height]`` and ``extrinsics`` (``rt_fromref``, zero
for a single camera). mrcal's ``LENSMODEL_OPENCVn`` is OpenCV's pin-hole
projection (:class:`~pipeline.models.opencv_model.OpenCVModel`), so the
export is the OpenCV fit with 8 or 12 coefficients; the conversion figures
and what the camera matrix means are in leading comments.

References
----------
.. [1] D. Kogan, mrcal, "Camera model representation in a file",
   https://mrcal.secretsauce.net/cameramodels.html ; "Lens models",
   https://mrcal.secretsauce.net/lensmodels.html
"""

from __future__ import annotations

import ast
from typing import Any

from pipeline.exports.statement import Statement
from pipeline.models.opencv_model import OpenCVModel

MRCAL_LENSMODELS = {4: "LENSMODEL_OPENCV4", 5: "LENSMODEL_OPENCV5", 8: "LENSMODEL_OPENCV8", 12: "LENSMODEL_OPENCV12"}


def mrcal_text(
    model: OpenCVModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
) -> str:
    """The ``.cameramodel`` text of an OpenCV model with 4, 5, 8 or 12 coefficients; the statement's ``stamp``:
    comment lines right after the title. With its ``frame``, the keys ``harp_rectification_matrix``,
    ``harp_new_camera_matrix`` and ``harp_new_imagersize`` (mrcal ignores keys it does not know): a ray
    ``v`` that ``mrcal.unproject`` gives is at ``newK R v`` in harp undistort's corrected image."""
    n = len(model.dist)
    if n not in MRCAL_LENSMODELS:
        raise ValueError(f"mrcal has LENSMODEL_OPENCV4/5/8/12, not {n} coefficients")
    intr = [model.fx, model.fy, model.cx, model.cy, *model.dist]
    frame = statement.frame
    frame_lines = (
        [
            f"corrected image = harp undistort's with {frame.choice.describe()}: {frame.frame.describe()}",
            "a ray v of mrcal.unproject is at harp_new_camera_matrix @ harp_rectification_matrix @ v in it",
        ]
        if frame is not None
        else []
    )
    lines = [f"# mrcal camera model exported by harp station ({MRCAL_LENSMODELS[n]})"]
    lines += [f"# {s}" for s in statement.lines(frame=frame_lines)]
    lines += [
        "{",
        f"    'lensmodel':  '{MRCAL_LENSMODELS[n]}',",
        "    # intrinsics are fx,fy,cx,cy,distortion0,distortion1,....",
        "    'intrinsics': [ " + ", ".join(repr(float(v)) for v in intr) + " ],",
        "    # extrinsics are rt_fromref",
        "    'extrinsics': [ 0.0, 0.0, 0.0, 0.0, 0.0, 0.0 ],",
        f"    'imagersize': [ {int(width)}, {int(height)} ],",
    ]
    if frame is not None:
        lines += [
            f"    'harp_rectification_matrix': {_rows(frame.rotation)},",
            f"    'harp_new_camera_matrix': {_rows(frame.new_k)},",
            f"    'harp_new_imagersize': [ {frame.size[0]}, {frame.size[1]} ],",
        ]
    lines += ["}"]
    return "\n".join(lines) + "\n"


def _rows(m: Any) -> str:
    return "[ " + ", ".join("[ " + ", ".join(repr(float(v)) for v in row) + " ]" for row in m) + " ]"


def sniff_mrcal(head: bytes) -> bool:
    return b"'lensmodel'" in head[:8192] or b'"lensmodel"' in head[:8192]


def read_mrcal_text(text: str, name: str = "<text>") -> tuple[OpenCVModel, tuple[int, int] | None]:
    """Parse a ``.cameramodel`` with an OpenCV lens model: ``(model, (width, height))``."""
    try:
        doc: Any = ast.literal_eval(text.strip())
    except (ValueError, SyntaxError, MemoryError, RecursionError):
        raise ValueError(f"{name}: not an mrcal .cameramodel (not a Python dict literal)") from None
    if not isinstance(doc, dict) or "lensmodel" not in doc or "intrinsics" not in doc:
        raise ValueError(f"{name}: not an mrcal .cameramodel (no 'lensmodel' and 'intrinsics')")
    lm = str(doc["lensmodel"])
    known = {v: k for k, v in MRCAL_LENSMODELS.items()}
    if lm not in known:
        raise ValueError(f"{name}: unsupported mrcal lens model {lm!r} (this reads {', '.join(known)})")
    try:
        intr = [float(v) for v in doc["intrinsics"]]
    except (TypeError, ValueError):
        raise ValueError(f"{name}: non-numeric intrinsics") from None
    if len(intr) != 4 + known[lm]:
        raise ValueError(f"{name}: {lm} needs {4 + known[lm]} intrinsics, got {len(intr)}")
    size = None
    if "imagersize" in doc:
        w, h = doc["imagersize"]
        size = (int(w), int(h))
    try:
        return OpenCVModel(fx=intr[0], fy=intr[1], cx=intr[2], cy=intr[3], dist=tuple(intr[4:])), size
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
