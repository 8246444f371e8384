"""Adobe's lens profile (LCP) as RawTherapee reads and applies it, written out for the tests (no Adobe
software here): the XMP parsed the way ``rtengine/lcp.cc``'s expat handlers do (every ``stCamera``
property by its local name, as an attribute of an ``rdf:Description`` or as an element; the common
fields of the first entry; ``PerspectiveModel`` / ``FisheyeModel`` per ``rdf:li``), its normalisation
(``LCPModelCommon::prepareParams``: ``fx = FocalLengthX * max(W, H)``, ``x0 = ImageXCenter * W``,
``y0 = ImageYCenter * H``) and its mapping of a corrected pixel to the photo's pixel
(``LCPMapper::correctDistortion``, rectilinear and fisheye), independent of ``pipeline.exports.lcp``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

PARAM = {
    "RadialDistortParam1": 0,
    "RadialDistortParam2": 1,
    "RadialDistortParam3": 2,
    "RadialDistortParam4": 3,
    "TangentialDistortParam1": 3,
    "RadialDistortParam5": 4,
    "TangentialDistortParam2": 4,
}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1].rsplit(":", 1)[-1]


def read_profiles(data: bytes) -> dict:
    """``{"sensor_format_factor", "lens", "fisheye", "models": [{"focal", "focus", "foc_len_x", ...}]}``."""
    root = ET.fromstring(data)
    out: dict = {"sensor_format_factor": 1.0, "lens": None, "fisheye": False, "models": []}
    seq = next(e for e in root.iter() if _local(e.tag) == "CameraProfiles")
    first = True
    for li in (e for e in seq.iter() if _local(e.tag) == "li"):
        m = {"focal": 0.0, "focus": 0.0, "foc_len_x": -1.0, "foc_len_y": -1.0, "x": 0.5, "y": 0.5, "param": [0.0] * 5}
        in_model = False
        for e in li.iter():
            name = _local(e.tag)
            if name in ("PerspectiveModel", "FisheyeModel"):
                in_model = True
                out["fisheye"] |= name == "FisheyeModel"
            props = dict(e.attrib)
            if e.text and e.text.strip() and len(e) == 0:
                props[e.tag] = e.text.strip()
            for k, v in props.items():
                k = _local(k)
                if first and not in_model and k == "SensorFormatFactor":
                    out["sensor_format_factor"] = float(v)
                if first and not in_model and k == "Lens":
                    out["lens"] = v
                if k == "FocalLength":
                    m["focal"] = float(v)
                elif k == "FocusDistance":
                    m["focus"] = min(float(v), 10000.0)
                elif in_model and k == "FocalLengthX":
                    m["foc_len_x"] = float(v)
                elif in_model and k == "FocalLengthY":
                    m["foc_len_y"] = float(v)
                elif in_model and k == "ImageXCenter":
                    m["x"] = float(v)
                elif in_model and k == "ImageYCenter":
                    m["y"] = float(v)
                elif in_model and k in PARAM:
                    m["param"][PARAM[k]] = float(v)
        out["models"].append(m)
        first = False
    return out


def mapper(model: dict, width: int, height: int, focal_mm: float, sensor_format_factor: float = 1.0) -> dict:
    """``prepareParams`` for a full ``width`` x ``height`` image, not rotated."""
    dmax = max(width, height)
    fx, fy = model["foc_len_x"], model["foc_len_y"]
    if fx < 0:  # not given: from the focal length and the 35 mm equivalent
        fx = fy = focal_mm / (35.0 * focal_mm / (focal_mm * sensor_format_factor))
    return {"x0": model["x"] * width, "y0": model["y"] * height, "fx": fx * dmax, "fy": fy * dmax, "p": model["param"]}


def correct_distortion(mc: dict, xy: np.ndarray, fisheye: bool) -> np.ndarray:
    """``LCPMapper::correctDistortion``: corrected pixels ``xy`` -> where the photo is read (scale 1)."""
    x, y = np.asarray(xy, dtype=np.float64).T
    x0, y0, fx, fy, a = mc["x0"], mc["y0"], mc["fx"], mc["fy"], mc["p"]
    if fisheye:
        du, dv = x - x0, y - y0
        r = np.hypot(du, dv)
        f = np.sqrt(fx * fy)
        th = np.arctan2(r, f)
        th2 = th * th
        with np.errstate(invalid="ignore", divide="ignore"):
            cfact = np.where(r > 0, ((a[1] * th2 + a[0]) * th2 + 1) * th / r, 1.0 / f)
        return np.stack([cfact * fx * du + x0, cfact * fy * dv + y0], axis=1)
    xd, yd = (x - x0) / fx, (y - y0) / fy
    rsqr = xd * xd + yd * yd
    xfac, yfac = a[4], a[3]
    common = (((a[2] * rsqr + a[1]) * rsqr + a[0]) * rsqr + 1.0) + 2.0 * (yfac * yd + xfac * xd)
    return np.stack([(xd * common + xfac * rsqr) * fx + x0, (yd * common + yfac * rsqr) * fy + y0], axis=1)
