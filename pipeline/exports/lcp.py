r"""Adobe Lens Correction Profile (``.lcp``): XMP/RDF XML, one profile per (focal length, focus distance).

Adobe Camera Raw, Lightroom and Photoshop, RawTherapee and lensfun's ``lensfun-convert-lcp`` read
lens profiles as an XMP document whose ``photoshop:CameraProfiles`` sequence holds one
``rdf:li`` per calibration setting: the camera and lens (``stCamera:Make``, ``Model``, ``Lens``,
``SensorFormatFactor``, ``ImageWidth``, ``ImageLength``), the setting (``stCamera:FocalLength`` in
mm, ``FocusDistance`` in metres, ``ApertureValue`` in APEX), and the geometric model, either

- ``stCamera:PerspectiveModel`` (rectilinear lenses): an ideal point at normalised
  :math:`(x, y) = ((u - u_0)/f_x, (v - v_0)/f_y)` is seen at

  .. math::
      x_d = x (1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + 2 k_4 x y + k_5 (r^2 + 2x^2), \\
      y_d = y (1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + k_4 (r^2 + 2y^2) + 2 k_5 x y,

  ``RadialDistortParam1..3`` = :math:`k_{1..3}`, ``TangentialDistortParam1..2`` = :math:`k_4, k_5`:
  exactly OpenCV's 5-coefficient model (``k1 k2 p1 p2 k3`` with :math:`p_1 = k_4`, :math:`p_2 = k_5`);
- ``stCamera:FisheyeModel``: :math:`r_d = f (\theta + k_1\theta^3 + k_2\theta^5)`,
  :math:`\theta = \arctan(r / f)`, ``RadialDistortParam1..2``: OpenCV's ``cv::fisheye`` with
  :math:`k_3 = k_4 = 0` and :math:`f_x = f_y`

[1]_ [2]_. The camera is normalised so that one profile serves every resolution of the sensor:
:math:`f_x` = ``FocalLengthX`` :math:`\cdot D_{max}`, :math:`D_{max} = \max(W, H)`, and the
centre :math:`u_0` = ``ImageXCenter`` :math:`\cdot W`, :math:`v_0` = ``ImageYCenter`` :math:`\cdot H`
with pixel :math:`(i, j)` at :math:`(i, j)` — as RawTherapee's ``lcp.cc`` applies a profile (it notes
that Adobe's paper normalises the centre by :math:`D_{max}` too, which Adobe's own profiles, whose
``ImageYCenter`` is near 0.5 on 3:2 sensors, do not). ``ScaleFactor`` is 1 (Adobe's automatic
scale is left to the application).

So the export is the OpenCV 5-coefficient fit (:func:`~pipeline.exports.fit.fit_opencv`, pole-free)
or the 2-coefficient fisheye fit, whichever is closer (as COLMAP and Kalibr choose), converted to
those normalised fields; the document is built and merged with :mod:`xml.etree.ElementTree`: an
export into an existing profile of the same lens adds its (focal, focus) entry, replacing one of the
same setting.

References
----------
.. [1] S. Chen, H. Jin, J. Chien, E. Chan, D. Goldman, "Adobe Camera Model", Adobe technical report,
   2010 (geometric distortion models for rectilinear and fisheye lenses, the lens correction
   profile file format).
.. [2] RawTherapee, ``rtengine/lcp.cc`` (``LCPModelCommon::prepareParams``,
   ``LCPMapper::correctDistortion``): the open implementation the tests follow.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

from pipeline.exports.lens import LensInfo
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel

X_NS = "adobe:ns:meta/"
RDF_NS = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"
PHOTOSHOP_NS = "http://ns.adobe.com/photoshop/1.0/"
ST_NS = "http://ns.adobe.com/photoshop/1.0/camera-profile"
for _prefix, _uri in (("x", X_NS), ("rdf", RDF_NS), ("photoshop", PHOTOSHOP_NS), ("stCamera", ST_NS)):
    ET.register_namespace(_prefix, _uri)

LCP_PINHOLE_COEFFS = 5
"""The PerspectiveModel holds OpenCV's 5 coefficients (``k1 k2 p1 p2 k3``)."""

LCP_FISHEYE_COEFFS = 2
"""The FisheyeModel holds ``k1 k2`` of the Kannala-Brandt polynomial."""

AUTHOR = "harp station"


def _st(name: str) -> str:
    return f"{{{ST_NS}}}{name}"


def _rdf(name: str) -> str:
    return f"{{{RDF_NS}}}{name}"


def _num(v: float) -> str:
    return f"{float(v):.10g}"


@dataclass(frozen=True)
class LcpProfile:
    """One calibration setting of a lens profile.

    ``model`` is the fit in pixels of ``width`` x ``height`` images (:class:`OpenCVModel` with 5
    coefficients, or :class:`OpenCVFisheyeModel` with ``k3 = k4 = 0`` and ``fx = fy``);
    ``focal_mm`` and ``focus_distance_m`` the setting (None: not stated); ``comments`` lines kept
    beside the entry (its conversion error, the stamp).
    """

    model: OpenCVModel | OpenCVFisheyeModel
    width: int
    height: int
    focal_mm: float | None = None
    focus_distance_m: float | None = None
    comments: tuple[str, ...] = ()


def model_fields(model: OpenCVModel | OpenCVFisheyeModel, width: int, height: int) -> dict[str, float]:
    """The normalised ``stCamera`` fields of a fit for ``width`` x ``height`` images (module docstring)."""
    dmax = float(max(width, height))
    out = {
        "FocalLengthX": model.fx / dmax,
        "FocalLengthY": model.fy / dmax,
        "ImageXCenter": model.cx / width,
        "ImageYCenter": model.cy / height,
    }
    d = list(model.dist)
    if isinstance(model, OpenCVFisheyeModel):
        if abs(d[2]) > 0 or abs(d[3]) > 0:
            raise ValueError("the LCP FisheyeModel holds k1 k2 only (k3 = k4 = 0)")
        if abs(model.fx - model.fy) > 1e-9 * model.fx:
            raise ValueError("the LCP FisheyeModel holds one focal length (fx = fy)")
        out.update(RadialDistortParam1=d[0], RadialDistortParam2=d[1])
    else:
        if len(d) > LCP_PINHOLE_COEFFS and any(abs(v) > 0 for v in d[LCP_PINHOLE_COEFFS:]):
            raise ValueError(f"the LCP PerspectiveModel holds {LCP_PINHOLE_COEFFS} OpenCV coefficients, not {len(d)}")
        d = (d + [0.0] * 5)[:5]
        out.update(
            RadialDistortParam1=d[0],
            RadialDistortParam2=d[1],
            RadialDistortParam3=d[4],
            TangentialDistortParam1=d[2],
            TangentialDistortParam2=d[3],
        )
    out["ScaleFactor"] = 1.0
    return out


def model_of_fields(
    fields: dict[str, float], fisheye: bool, width: int, height: int
) -> OpenCVModel | OpenCVFisheyeModel:
    """The OpenCV model of an entry's normalised fields for ``width`` x ``height`` images (missing
    parameters are 0, a missing ``FocalLengthY`` is ``FocalLengthX``, a missing centre 0.5)."""
    dmax = float(max(width, height))
    if "FocalLengthX" not in fields:
        raise ValueError("no stCamera:FocalLengthX (a profile that needs the focal length from the photo is not read)")
    fx = fields["FocalLengthX"] * dmax
    fy = fields.get("FocalLengthY", fields["FocalLengthX"]) * dmax
    cx = fields.get("ImageXCenter", 0.5) * width
    cy = fields.get("ImageYCenter", 0.5) * height
    k = [fields.get(f"RadialDistortParam{i}", 0.0) for i in (1, 2, 3)]
    if fisheye:
        return OpenCVFisheyeModel(fx=fx, fy=fy, cx=cx, cy=cy, dist=(k[0], k[1], 0.0, 0.0))
    p1, p2 = fields.get("TangentialDistortParam1", 0.0), fields.get("TangentialDistortParam2", 0.0)
    return OpenCVModel(fx=fx, fy=fy, cx=cx, cy=cy, dist=(k[0], k[1], p1, p2, k[2]))


def _lens_fields(lens: LensInfo, width: int, height: int) -> dict[str, str]:
    out = {"Author": AUTHOR}
    if lens.camera_maker:
        out["Make"] = lens.camera_maker
    if lens.camera_model:
        out["Model"] = lens.camera_model
        out["UniqueCameraModel"] = lens.camera_body or lens.camera_model
    if lens.camera_body:
        out["CameraPrettyName"] = lens.camera_body
    out["Lens"] = lens.lens_model or lens.lens_name or "unknown lens"
    if lens.lens_name:
        out["LensPrettyName"] = lens.lens_name
    out["ProfileName"] = f"{lens.camera_body or 'camera'} ({lens.lens_name or 'lens'}) - {AUTHOR}"
    out["CameraRawProfile"] = "False"
    if lens.crop_factor is not None:
        out["SensorFormatFactor"] = _num(lens.crop_factor)
    out["ImageWidth"] = str(int(width))
    out["ImageLength"] = str(int(height))
    return out


def _entry_key(desc: ET.Element) -> tuple[float | None, float | None]:
    def num(name: str) -> float | None:
        v = _field(desc, name)
        return None if v is None else float(v)

    return num("FocalLength"), num("FocusDistance")


def _field(elem: ET.Element, name: str) -> str | None:
    """An ``stCamera`` property as an attribute or a child element's text."""
    v = elem.get(_st(name))
    if v is not None:
        return v
    child = elem.find(_st(name))
    return None if child is None or child.text is None else child.text.strip()


def _setting_text(key: tuple[float | None, float | None]) -> str:
    f, d = key
    return f"focal {'unstated' if f is None else f'{f:g} mm'}, focus distance {'unstated' if d is None else f'{d:g} m'}"


def _new_document() -> tuple[ET.Element, ET.Element]:
    root = ET.Element(f"{{{X_NS}}}xmpmeta", {f"{{{X_NS}}}xmptk": AUTHOR})
    rdf = ET.SubElement(root, _rdf("RDF"))
    desc = ET.SubElement(rdf, _rdf("Description"), {_rdf("about"): ""})
    profiles = ET.SubElement(desc, f"{{{PHOTOSHOP_NS}}}CameraProfiles")
    seq = ET.SubElement(profiles, _rdf("Seq"))
    return root, seq


def _parse(text: str, name: str) -> tuple[ET.Element, ET.Element]:
    """The root and the ``CameraProfiles`` sequence of an LCP document (ValueError naming ``name``)."""
    try:
        root = ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise ValueError(f"{name}: not a well-formed LCP file ({exc})") from None
    seq = root.find(f".//{{{PHOTOSHOP_NS}}}CameraProfiles/{_rdf('Seq')}")
    if seq is None:
        raise ValueError(f"{name}: not an LCP file (no photoshop:CameraProfiles sequence)")
    return root, seq


def _entries(seq: ET.Element) -> list[tuple[ET.Element, ET.Element]]:
    """``(li, description)`` of each entry (the description holds the setting and the models)."""
    out = []
    for li in seq.findall(_rdf("li")):
        desc = li.find(_rdf("Description"))
        out.append((li, desc if desc is not None else li))
    return out


def _kinds(seq: ET.Element) -> set[str]:
    return {k for _, desc in _entries(seq) for k in MODEL_KINDS if desc.find(_st(k)) is not None}


MODEL_KINDS = ("PerspectiveModel", "FisheyeModel")
"""The geometric models of an entry. A profile holds one kind: RawTherapee treats the whole profile as a
fisheye when any entry is one, and lensfun-convert-lcp refuses a mix."""


def check_existing(existing: str, lens: LensInfo, name: str) -> str | None:
    """The model kind of ``existing``'s entries (None: no entry), ValueError (naming ``name``) unless it is an
    LCP profile of ``lens`` (its ``stCamera:Lens``) holding one kind (:data:`MODEL_KINDS`)."""
    _, seq = _parse(existing, name)
    mine = _lens_fields(lens, 1, 1)["Lens"]
    for _, desc in _entries(seq):
        other = _field(desc, "Lens")
        if other is not None and other != mine:
            raise ValueError(
                f"{name}: a profile of lens '{other}', not '{mine}'; an LCP file holds one lens: write another file"
            )
    kinds = _kinds(seq)
    if len(kinds) > 1:
        raise ValueError(f"{name}: the profile mixes PerspectiveModel and FisheyeModel entries; write another file")
    return next(iter(kinds), None)


def lcp_text(
    profile: LcpProfile,
    lens: LensInfo,
    *,
    header: Sequence[str] = (),
    existing: str | None = None,
    existing_name: str = "<existing>",
) -> tuple[str, list[str]]:
    """The LCP document holding ``profile``, alone or added to ``existing``: ``(text, what was done)``.

    ``existing`` must be a profile of the same lens (``stCamera:Lens``; ValueError otherwise); an
    entry of the same (focal, focus distance) is replaced (said in what was done, ``"replaced ..."``).
    ``header``: lines stated as XML comments before the document (the stamp first).
    """
    fields = _lens_fields(lens, profile.width, profile.height)
    done: list[str] = []
    if existing is None:
        root, seq = _new_document()
    else:
        check_existing(existing, lens, existing_name)
        root, seq = _parse(existing, existing_name)
    key = (profile.focal_mm, profile.focus_distance_m)
    for li, desc in _entries(seq):
        if _entry_key(desc) == key:
            seq.remove(li)
            done.append(f"replaced the profile at {_setting_text(key)} in {existing_name}")
    attrs = {_st(k): v for k, v in fields.items()}
    if profile.focal_mm is not None:
        attrs[_st("FocalLength")] = _num(profile.focal_mm)
    if profile.focus_distance_m is not None:
        attrs[_st("FocusDistance")] = _num(profile.focus_distance_m)
    li = ET.Element(_rdf("li"))
    for line in profile.comments:
        li.append(ET.Comment(f" {line.replace('--', '- -')} "))
    desc = ET.SubElement(li, _rdf("Description"), attrs)
    kind = "FisheyeModel" if isinstance(profile.model, OpenCVFisheyeModel) else "PerspectiveModel"
    if _kinds(seq) - {kind}:
        raise ValueError(
            f"{existing_name}: the profile's entries are {', '.join(sorted(_kinds(seq)))}, not {kind}: "
            "a profile holds one kind (RawTherapee reads a profile with any FisheyeModel as a fisheye)"
        )
    model = ET.SubElement(desc, _st(kind))
    geo = {_st("Version"): "2"}
    geo.update({_st(k): _num(v) for k, v in model_fields(profile.model, profile.width, profile.height).items()})
    ET.SubElement(model, _rdf("Description"), geo)
    # entries in the order of their setting (no focal first), as Adobe's files list them
    items = [*((x, d) for x, d in _entries(seq)), (li, desc)]
    for x, _ in items[:-1]:
        seq.remove(x)
    items.sort(key=lambda it: tuple((v is not None, v or 0.0) for v in _entry_key(it[1])))
    for x, _ in items:
        seq.append(x)
    done.append(f"added the profile at {_setting_text(key)} ({kind}); the file holds {len(items)}")
    ET.indent(root, space=" ")
    head = "".join(f"<!-- {line.replace('--', '- -')} -->\n" for line in header)
    body = ET.tostring(root, encoding="unicode")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + head + body + "\n", done


@dataclass(frozen=True)
class LcpEntry:
    """An entry read from an LCP file: its setting, its model's kind and normalised fields."""

    focal_mm: float | None
    focus_distance_m: float | None
    fisheye: bool
    fields: dict[str, float]
    image_size: tuple[int, int] | None


def read_lcp_entries(text: str, name: str) -> list[LcpEntry]:
    """Every entry with a geometric model (ValueError naming ``name`` when none or a field is not a number)."""
    _, seq = _parse(text, name)
    out = []
    size: tuple[int, int] | None = None
    for _, desc in _entries(seq):
        try:
            w, h = _field(desc, "ImageWidth"), _field(desc, "ImageLength")
            if w is not None and h is not None:
                size = (int(float(w)), int(float(h)))
            focal, dist = _entry_key(desc)
        except ValueError as exc:
            raise ValueError(f"{name}: an entry's setting is not a number ({exc})") from None
        for kind in ("PerspectiveModel", "FisheyeModel"):
            m = desc.find(_st(kind))
            if m is None:
                continue
            geo = m.find(_rdf("Description"))
            geo = geo if geo is not None else m
            fields: dict[str, float] = {}
            for prop in (
                "FocalLengthX",
                "FocalLengthY",
                "ImageXCenter",
                "ImageYCenter",
                "RadialDistortParam1",
                "RadialDistortParam2",
                "RadialDistortParam3",
                "TangentialDistortParam1",
                "TangentialDistortParam2",
            ):
                v = _field(geo, prop)
                if v is None:
                    continue
                try:
                    fields[prop] = float(v)
                except ValueError:
                    raise ValueError(f"{name}: stCamera:{prop} is not a number: {v!r}") from None
                if not math.isfinite(fields[prop]):
                    raise ValueError(f"{name}: stCamera:{prop} is not finite: {v!r}")
            out.append(LcpEntry(focal, dist, kind == "FisheyeModel", fields, size))
            break
    if not out:
        raise ValueError(f"{name}: the LCP file holds no PerspectiveModel or FisheyeModel")
    return out


ASPECT_TOLERANCE = 0.01
"""An LCP profile is read for images whose aspect ratio is within this (relative) of its own."""


def read_lcp_text(
    text: str, name: str, width: int, height: int, focal: float | None = None
) -> tuple[OpenCVModel | OpenCVFisheyeModel, LcpEntry]:
    """The model of the entry for ``width`` x ``height`` images at focal ``focal`` (the nearest
    calibrated focal; without ``focal`` a file with entries at several focal lengths is refused),
    the farthest focus distance among that focal's entries: ``(model, entry)``."""
    entries = read_lcp_entries(text, name)
    focals = sorted({e.focal_mm for e in entries if e.focal_mm is not None})
    if focal is None and len(focals) > 1:
        raise ValueError(
            f"{name}: the profile holds {len(focals)} focal lengths ({', '.join(f'{f:g}' for f in focals)} mm): "
            "give the focal length of the shots"
        )
    pick = entries
    if focal is not None and focals:
        near = min(focals, key=lambda f: abs(f - focal))
        pick = [e for e in entries if e.focal_mm == near]
    entry = max(pick, key=lambda e: -1.0 if e.focus_distance_m is None else e.focus_distance_m)
    if entry.image_size is not None:
        a, b = entry.image_size[0] / entry.image_size[1], width / height
        if abs(a / b - 1) > ASPECT_TOLERANCE:
            raise ValueError(
                f"{name}: profile for {entry.image_size[0]}x{entry.image_size[1]} images (aspect {a:.4g}), "
                f"the shots are {width}x{height} (aspect {b:.4g})"
            )
    try:
        return model_of_fields(entry.fields, entry.fisheye, width, height), entry
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def sniff_lcp(data: bytes) -> bool:
    """Whether bytes look like an Adobe lens profile."""
    head = data.lstrip()[:8192]
    return ST_NS.encode() in head and b"CameraProfiles" in head
