"""Lensfun database XML (``<lensdatabase><lens>…<calibration><distortion …/>``).

Element and attribute names follow lensfun's database format (``lensdatabase``
with ``version``, ``lens`` with ``maker``, ``model``, ``mount``,
``cropfactor``, ``aspect-ratio``, ``calibration``/``distortion`` with
``model`` = ``poly3`` | ``poly5`` | ``ptlens``, ``focal`` and the terms
``k1``[, ``k2``] or ``a``, ``b``, ``c``). The aspect ratio written is the one
lensfun computes for the image, ``(W-1)/(H-1)``, so lensfun's coordinate
correction is exactly 1 for images of the calibrated size and crop factor.
The conversion error is stated in an XML comment.

References
----------
.. [1] Lensfun, "lfDistortionModel" and the lens database format,
   https://lensfun.github.io/manual/latest/
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from pipeline.exports.fit import ConversionError
from pipeline.models.lensfun_model import LENSFUN_TERMS, LensfunModel


def lensfun_text(
    model: LensfunModel,
    error: ConversionError | None = None,
    *,
    maker: str = "harp station",
    lens_model: str = "harp calibration",
    mount: str = "Generic",
    cropfactor: float = 1.0,
    focal: float = 50.0,
) -> str:
    """Lensfun database XML text with one lens and one distortion calibration."""
    root = ET.Element("lensdatabase", {"version": "1"})
    lens = ET.SubElement(root, "lens")
    ET.SubElement(lens, "maker").text = maker
    ET.SubElement(lens, "model").text = lens_model
    ET.SubElement(lens, "mount").text = mount
    ET.SubElement(lens, "cropfactor").text = repr(float(cropfactor))
    w, h = model.width, model.height
    ar = max(w - 1, h - 1) / min(w - 1, h - 1)
    if model.coord_scale != 1.0:  # a calibration of another aspect ratio: write that one
        ar = float(np.sqrt(model.coord_scale**2 * (ar * ar + 1) - 1))
    ET.SubElement(lens, "aspect-ratio").text = repr(float(ar))
    if model.center != (0.0, 0.0):
        ET.SubElement(lens, "center", {"x": repr(model.center[0]), "y": repr(model.center[1])})
    cal = ET.SubElement(lens, "calibration")
    attrs = {"model": model.kind, "focal": repr(float(focal))}
    attrs.update({n: repr(float(v)) for n, v in zip(LENSFUN_TERMS[model.kind], model.terms)})
    ET.SubElement(cal, "distortion", attrs)
    ET.indent(root, space="    ")
    head = '<?xml version="1.0" encoding="UTF-8"?>\n'
    note = (
        f"<!-- exported by harp station for {w}x{h} images; lensfun normalisation: unit = half the shorter side -->\n"
    )
    if error is not None:
        note += (
            f"<!-- conversion error vs the harp correction (4-corner normalised): RMS {error.rms_px:.4f} px, "
            f"max {error.max_px:.4f} px; modulo best homography: RMS {error.rms_mod_h_px:.4f} px, "
            f"max {error.max_mod_h_px:.4f} px; residual on a noise-free full-field harp: "
            f"d {error.d_px:.4f} px, d_max {error.d_max_px:.4f} px -->\n"
        )
    return head + note + ET.tostring(root, encoding="unicode") + "\n"


def read_lensfun_text(
    text: str, width: int, height: int, name: str = "<text>", focal: float | None = None
) -> LensfunModel:
    """The distortion of the (first) lens of a lensfun XML, for images of ``width`` x ``height``.

    With several ``<distortion>`` entries, ``focal`` picks the one at that
    focal length (no interpolation); ValueError('<name>: <reason>') otherwise.
    A calibration aspect ratio other than the images' gives lensfun's
    coordinate correction ``coord_scale`` (same crop factor assumed).
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ValueError(f"{name}: not valid XML ({exc})") from None
    if root.tag != "lensdatabase":
        raise ValueError(f"{name}: not a lensfun database (root <{root.tag}>, expected <lensdatabase>)")
    lens = root.find("lens")
    if lens is None:
        raise ValueError(f"{name}: lensfun file without a <lens>")
    dists = lens.findall("calibration/distortion")
    if not dists:
        raise ValueError(f"{name}: lens has no <calibration><distortion>")
    if focal is not None:
        dists = [d for d in dists if abs(float(d.get("focal", "nan")) - focal) < 1e-6]
        if not dists:
            raise ValueError(f"{name}: no distortion calibration at focal {focal}")
    elif len(dists) > 1:
        focals = ", ".join(d.get("focal", "?") for d in dists)
        raise ValueError(f"{name}: several distortion calibrations (focal {focals}); choose one with --focal")
    d = dists[0]
    kind = d.get("model")
    if kind not in LENSFUN_TERMS:
        raise ValueError(
            f"{name}: unsupported lensfun distortion model {kind!r} (supported: {', '.join(sorted(LENSFUN_TERMS))})"
        )
    try:
        terms = tuple(float(d.get(t, "0")) for t in LENSFUN_TERMS[kind])
    except ValueError:
        raise ValueError(f"{name}: non-numeric distortion terms") from None
    c = lens.find("center")
    center = (float(c.get("x", 0)), float(c.get("y", 0))) if c is not None else (0.0, 0.0)
    ar_el = lens.find("aspect-ratio")
    ar = 1.5  # lensfun's default for lenses
    if ar_el is not None and ar_el.text:
        txt = ar_el.text.strip()
        try:
            ar = (float(txt.split(":")[0]) / float(txt.split(":")[1])) if ":" in txt else float(txt)
        except (ValueError, ZeroDivisionError):
            raise ValueError(f"{name}: invalid <aspect-ratio> {txt!r}") from None
        ar = max(ar, 1.0 / ar)
    img_ar = max(width - 1, height - 1) / min(width - 1, height - 1)
    kappa = float(np.sqrt(ar * ar + 1) / np.sqrt(img_ar * img_ar + 1))
    return LensfunModel(kind=kind, terms=terms, width=width, height=height, center=center, coord_scale=kappa)
