"""Agisoft Metashape camera calibration XML (``frame`` or ``fisheye`` projection).

The file Metashape's Camera Calibration dialog loads and saves ("Agisoft Camera Calibration"):

.. code-block:: xml

    <calibration>
      <projection>frame</projection>
      <width>W</width> <height>H</height>
      <f>..</f> <cx>..</cx> <cy>..</cy> <b1>..</b1> <b2>..</b2>
      <k1>..</k1> <k2>..</k2> <k3>..</k3> <k4>..</k4> <p1>..</p1> <p2>..</p2>
    </calibration>

Metashape's frame camera (its user manual, appendix "Camera models") projects ``x = X/Z``, ``y =
Y/Z``, ``r^2 = x^2 + y^2``:

- ``x' = x (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + (P1 (r^2 + 2 x^2) + 2 P2 x y)``,
- ``y' = y (1 + K1 r^2 + K2 r^4 + K3 r^6 + K4 r^8) + (P2 (r^2 + 2 y^2) + 2 P1 x y)``,
- ``u = w/2 + cx + x' f + x' B1 + y' B2``, ``v = h/2 + cy + y' f``,

with ``u, v`` from the image's top-left corner (the centre of the top-left pixel at 0.5, 0.5). So it
is OpenCV's plumb_bob (``k1 k2 p1 p2 k3``) with ``P1`` = OpenCV's ``p2`` and ``P2`` = OpenCV's ``p1``
(swapped), ``f = fy``, ``B1 = fx - fy``, ``cx``, ``cy`` offsets of the principal point from the image
centre, and one more radial term ``K4``. The fisheye camera first maps ``x`` to ``x atan(r0) / r0``
(``r0`` its radius), then the same polynomial: with ``P1 = P2 = 0`` OpenCV's ``cv::fisheye`` with
``K1..K4`` = ``k1..k4``. So the export is the OpenCV 5-coefficient fit (``K4 = 0``) or the fisheye
fit (:mod:`pipeline.exports.fit`; the registry chooses); the statement is in XML comments.

The reader also takes Metashape's project form (``<calibration type="frame">`` with ``<resolution
width=".." height=".."/>``), refusing what OpenCV's models cannot hold (``K4`` in a frame camera,
``B2`` skew, tangential terms of a fisheye camera) with a message naming the field.

References
----------
.. [1] Agisoft Metashape User Manual, Professional Edition, appendix "Camera models" (frame and
   fisheye cameras), https://www.agisoft.com/downloads/user-manuals/
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

from pipeline.exports.statement import Statement
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel

PIXEL_CENTRE = 0.5
"""Metashape's coordinate of the centre of the top-left pixel (OpenCV's and harp's: 0)."""

PINHOLE_COEFFS = 5
"""The OpenCV coefficients a Metashape frame camera holds (``k1 k2 p1 p2 k3``; its ``K4`` is left 0)."""


def _num(v: float) -> str:
    return repr(float(v))


def metashape_params(model: OpenCVModel | OpenCVFisheyeModel, width: int, height: int) -> dict[str, float | str]:
    """Metashape's parameters of an OpenCV model (``projection``, ``f``, ``cx`` ... ``p2``)."""
    common = {
        "f": model.fy,
        "cx": model.cx + PIXEL_CENTRE - 0.5 * width,
        "cy": model.cy + PIXEL_CENTRE - 0.5 * height,
        "b1": model.fx - model.fy,
        "b2": 0.0,
    }
    if isinstance(model, OpenCVFisheyeModel):
        k1, k2, k3, k4 = model.dist
        return {"projection": "fisheye", **common, "k1": k1, "k2": k2, "k3": k3, "k4": k4, "p1": 0.0, "p2": 0.0}
    if len(model.dist) != PINHOLE_COEFFS:
        raise ValueError(f"a Metashape frame camera is written from OpenCV's 5 coefficients, not {len(model.dist)}")
    k1, k2, p1, p2, k3 = model.dist
    return {"projection": "frame", **common, "k1": k1, "k2": k2, "k3": k3, "k4": 0.0, "p1": p2, "p2": p1}


def _comment(line: str) -> str:
    return "<!-- " + line.replace("--", "- -") + " -->"


def metashape_text(
    model: OpenCVModel | OpenCVFisheyeModel,
    width: int,
    height: int,
    statement: Statement = Statement(),
) -> str:
    """The calibration XML of an OpenCV 5-coefficient or fisheye model; the statement in comments."""
    p = metashape_params(model, width, height)
    frame = statement.frame
    lines = statement.lines(
        conventions=[
            "Metashape's conventions: u = w/2 + cx + x'(f + b1) + y' b2, v = h/2 + cy + y' f, from the image's "
            "top-left corner (the centre of the top-left pixel at 0.5, 0.5); p1 and p2 are OpenCV's p2 and p1 "
            "(swapped)",
        ],
        frame=frame.ray_lines("Metashape's unprojection (x = X/Z, y = Y/Z)") if frame is not None else (),
    )
    body = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        _comment(f"Agisoft Metashape camera calibration exported by harp station: {p['projection']} camera"),
        *(_comment(s) for s in lines),
        "<calibration>",
        f"  <projection>{p['projection']}</projection>",
        f"  <width>{int(width)}</width>",
        f"  <height>{int(height)}</height>",
        *(
            f"  <{k}>{_num(float(p[k]))}</{k}>"
            for k in ("f", "cx", "cy", "b1", "b2", "k1", "k2", "k3", "k4", "p1", "p2")
        ),
        "</calibration>",
    ]
    return "\n".join(body) + "\n"


def sniff_metashape(data: bytes) -> bool:
    head = data[:65536]
    return b"<calibration" in head and (b"<projection>" in head or b"<resolution" in head)


def read_metashape_text(
    text: str, name: str = "<text>"
) -> tuple[OpenCVModel | OpenCVFisheyeModel, tuple[int, int], str]:
    """The camera of a Metashape calibration XML: ``(model, (width, height), projection)``."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"{name}: not a Metashape calibration XML ({exc})") from None
    cal = root if root.tag == "calibration" else root.find(".//calibration")
    if cal is None:
        raise ValueError(f"{name}: not a Metashape calibration XML (no <calibration>)")
    proj = (cal.findtext("projection") or cal.get("type") or "frame").strip()
    if proj not in ("frame", "fisheye"):
        raise ValueError(f"{name}: Metashape projection {proj!r} not read (this reads frame and fisheye)")

    def num(key: str, default: float | None = 0.0) -> float:
        t = cal.findtext(key)
        if t is None:
            if default is None:
                raise ValueError(f"{name}: Metashape calibration without <{key}>")
            return default
        try:
            v = float(t)
        except ValueError:
            raise ValueError(f"{name}: <{key}> is not a number ({t.strip()!r})") from None
        if not math.isfinite(v):
            raise ValueError(f"{name}: <{key}> is not finite")
        return v

    res = cal.find("resolution")
    if res is not None:
        try:
            w, h = int(res.get("width", "")), int(res.get("height", ""))
        except ValueError:
            raise ValueError(f"{name}: <resolution> needs integer width and height") from None
    else:
        w, h = int(num("width", None)), int(num("height", None))
    f, cx, cy, b1, b2 = num("f", None), num("cx"), num("cy"), num("b1"), num("b2")
    k = [num(f"k{i}") for i in range(1, 5)]
    p1, p2 = num("p1"), num("p2")
    if b2 != 0.0:
        raise ValueError(f"{name}: <b2> (skew) {b2:g} is not read: OpenCV's models hold no skew")
    for extra in ("p3", "p4"):
        if num(extra) != 0.0:
            raise ValueError(f"{name}: <{extra}> is not read: OpenCV's models hold p1, p2 only")
    fx, fy = f + b1, f
    ocx, ocy = 0.5 * w + cx - PIXEL_CENTRE, 0.5 * h + cy - PIXEL_CENTRE
    try:
        if proj == "fisheye":
            if p1 != 0.0 or p2 != 0.0:
                raise ValueError(
                    "the tangential terms <p1>, <p2> of a fisheye camera are not read (OpenCV's fisheye has none)"
                )
            return OpenCVFisheyeModel(fx=fx, fy=fy, cx=ocx, cy=ocy, dist=(k[0], k[1], k[2], k[3])), (w, h), proj
        if k[3] != 0.0:
            raise ValueError("<k4> of a frame camera is not read (OpenCV's pin-hole model has no r^8 term)")
        return OpenCVModel(fx=fx, fy=fy, cx=ocx, cy=ocy, dist=(k[0], k[1], p2, p1, k[2])), (w, h), proj
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
