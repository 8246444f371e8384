"""Lensfun database XML (``<lensdatabase><lens>…<calibration><distortion …/>``).

Element and attribute names follow lensfun's database format (``lensdatabase``
with ``version``, ``camera`` and ``lens`` with ``maker``, ``model``,
``mount``, ``cropfactor``, a lens' ``aspect-ratio``, ``center`` and
``calibration``/``distortion`` with ``model`` = ``poly3`` | ``poly5`` |
``ptlens``, ``focal`` and the terms ``k1``[, ``k2``] or ``a``, ``b``, ``c``).
The aspect ratio written is the one lensfun computes for the image,
``(W-1)/(H-1)``, so lensfun's coordinate correction is exactly 1 for images
of the calibrated size and crop factor. The conversion error is stated in an
XML comment beside each calibration.

Maker, model, mount and crop factor come from the configuration
(:class:`~pipeline.exports.lens.LensInfo`): applications (darktable,
RawTherapee, digiKam, Hugin) find a lens by the camera's mount and the lens
name of the photo's EXIF, and scale the correction by the ratio of the
lens' calibration crop factor to the camera's, so the crop factor written is
the camera's. The focal length (``focal``) is the nominal one; lensfun has no
focus axis for distortion, so the focus setting (and the serial number) are
recorded in the comment beside the calibration. With the camera body known a
``<camera>`` entry (maker, model, mount, crop factor) is written too, for
bodies lensfun does not know.

One database holds several lenses: :func:`lensfun_database_text` adds
entries to an existing database, keyed by (maker, model, mount, crop
factor): a new key adds a ``<lens>``; a lens already there gets the
calibration at this focal added, or replaced if it had one at this focal
(lensfun keeps one calibration per focal and has no focus axis for distortion:
what was replaced, and the focus settings involved, are reported). Lensfun
merges lenses of one name and crop factor, and a lens' ``<center>`` and aspect
ratio apply to all its calibrations: a calibration with another centre replaces
the lens' centre when no other focal uses it, and is refused otherwise (see
:func:`add_to_database`).

References
----------
.. [1] Lensfun, "lfDistortionModel" and the lens database format,
   https://lensfun.github.io/manual/latest/
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from xml.sax.saxutils import escape as xml_escape

import numpy as np

from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.lens import LensInfo
from pipeline.models.lensfun_model import LENSFUN_TERMS, LENSFUN_TYPES, LensfunModel, geometry_focal
from pipeline.models.tca_model import LensfunTca
from pipeline.vignetting import LensfunVignetting

DEFAULT_MAKER = "harp station"
DEFAULT_MODEL = "harp calibration"
DEFAULT_MOUNT = "Generic"
DEFAULT_FOCAL_MM = 50.0


def lens_names(lens: LensInfo) -> tuple[str, str]:
    """``(maker, model)`` a lens is written under (the configured ones, or the defaults)."""
    return lens.lens_maker or DEFAULT_MAKER, lens.lens_model or DEFAULT_MODEL


@dataclass(frozen=True)
class LensfunEntry:
    """One calibration for a lensfun database: the fitted model, the lens, the figures."""

    model: LensfunModel
    lens: LensInfo = field(default_factory=LensInfo)
    error: ConversionError | None = None
    tca: LensfunTca | None = None
    vignetting: LensfunVignetting | None = None
    aperture: float = 8.0
    distance: float = 1000.0
    crop_note: str | None = None
    stamp: tuple[str, ...] = ()
    colour_lines: tuple[str, ...] = ()
    """The TCA's and vignetting's conversion errors (:class:`~pipeline.exports.colour.LensfunColour`), stated too."""

    @property
    def maker(self) -> str:
        return lens_names(self.lens)[0]

    @property
    def lens_model(self) -> str:
        return lens_names(self.lens)[1]

    @property
    def mount(self) -> str:
        return self.lens.mount or DEFAULT_MOUNT

    @property
    def cropfactor(self) -> float:
        return float(self.lens.crop_factor) if self.lens.crop_factor is not None else 1.0

    @property
    def focal(self) -> float:
        return float(self.lens.focal_mm) if self.lens.focal_mm is not None else DEFAULT_FOCAL_MM

    def aspect_ratio(self) -> float:
        """The aspect ratio written: lensfun's ``(W-1)/(H-1)`` (>= 1) of the calibrated images."""
        w, h = self.model.width, self.model.height
        ar = max(w - 1, h - 1) / min(w - 1, h - 1)
        if self.model.coord_scale != 1.0:  # a calibration of another aspect ratio: write that one
            ar = float(np.sqrt(self.model.coord_scale**2 * (ar * ar + 1) - 1))
        return float(ar)

    def note(self) -> str:
        """The comment written beside the calibration."""
        m = self.model
        parts = [*self.stamp, f"harp station calibration for {m.width}x{m.height} images at focal {self.focal:g} mm"]
        if self.lens.focus is not None:
            parts.append(f"focus setting {self.lens.focus:g} (lensfun has no focus axis for distortion)")
        if self.lens.lens_serial:
            parts.append(f"lens serial {self.lens.lens_serial}")
        if self.lens.camera_body:
            parts.append(f"camera {self.lens.camera_body}")
        if self.lens.focal_mm is None:
            parts.append(f"focal {DEFAULT_FOCAL_MM:g} mm is a placeholder (no nominal focal configured)")
        if self.crop_note is not None:
            parts.append(self.crop_note)
        elif self.lens.crop_factor is None:
            parts.append("crop factor 1 assumed (none configured)")
        if self.error is not None:
            parts.extend(self.error.lines())
        if self.vignetting is not None:
            parts.append(f"vignetting at f/{self.aperture:g}, focus distance {self.distance:g} m")
        parts.extend(self.colour_lines)
        return "; ".join(parts)


def _is_comment(el: ET.Element) -> bool:
    return el.tag is ET.Comment  # type: ignore[comparison-overlap]  # ElementTree tags comments by the factory


def _xml_comment(text: str) -> str:
    return " " + text.replace("--", "- -") + " "


def _text_of(el: ET.Element, tag: str) -> str:
    e = el.find(tag)
    return (e.text or "").strip() if e is not None else ""


def _key(el: ET.Element) -> tuple[str, str, str, float]:
    """(maker, model, mount, crop factor) of a ``<lens>`` or ``<camera>``."""
    try:
        crop = float(_text_of(el, "cropfactor") or "nan")
    except ValueError:
        crop = float("nan")
    return (_text_of(el, "maker"), _text_of(el, "model"), _text_of(el, "mount"), crop)


def _center_of(lens: ET.Element) -> tuple[float, float]:
    c = lens.find("center")
    return (float(c.get("x", 0)), float(c.get("y", 0))) if c is not None else (0.0, 0.0)


def _distortion_element(entry: LensfunEntry) -> ET.Element:
    attrs = {"model": entry.model.kind, "focal": repr(entry.focal)}
    attrs.update({n: repr(float(v)) for n, v in zip(LENSFUN_TERMS[entry.model.kind], entry.model.terms)})
    return ET.Element("distortion", attrs)


def _colour_elements(entry: LensfunEntry) -> list[ET.Element]:
    """The ``<tca>`` and ``<vignetting>`` elements of a calibration (issue 24), when it has them."""
    out = []
    if entry.tca is not None:
        out.append(ET.Element("tca", entry.tca.element_attributes(entry.focal)))
    if entry.vignetting is not None:
        attrs = entry.vignetting.element_attributes(entry.focal, entry.aperture, entry.distance)
        out.append(ET.Element("vignetting", attrs))
    return out


def _put_colour(cal: ET.Element, entry: LensfunEntry, after: ET.Element) -> None:
    """Put the colour elements after ``after``, replacing those of the same focal (and aperture, distance)."""
    for new in reversed(_colour_elements(entry)):
        for old in cal.findall(new.tag):
            if all(math.isclose(float(old.get(k, "nan")), float(new.get(k, "nan"))) for k in _COLOUR_KEYS[new.tag]):
                cal.remove(old)
        cal.insert(list(cal).index(after) + 1, new)


_COLOUR_KEYS = {"tca": ("focal",), "vignetting": ("focal", "aperture", "distance")}


def _new_lens(entry: LensfunEntry) -> ET.Element:
    lens = ET.Element("lens")
    ET.SubElement(lens, "maker").text = entry.maker
    ET.SubElement(lens, "model").text = entry.lens_model
    ET.SubElement(lens, "mount").text = entry.mount
    ET.SubElement(lens, "cropfactor").text = repr(entry.cropfactor)
    ET.SubElement(lens, "aspect-ratio").text = repr(entry.aspect_ratio())
    if entry.model.lens_type != "rectilinear":
        ET.SubElement(lens, "type").text = entry.model.lens_type
    if entry.model.center != (0.0, 0.0):
        ET.SubElement(lens, "center", {"x": repr(entry.model.center[0]), "y": repr(entry.model.center[1])})
    ET.SubElement(lens, "calibration")
    return lens


def _add_camera(root: ET.Element, entry: LensfunEntry) -> None:
    lens = entry.lens
    if not (lens.camera_maker and lens.camera_model):
        return
    if any(_key(c)[:2] == (lens.camera_maker, lens.camera_model) for c in root.findall("camera")):
        return
    cam = ET.Element("camera")
    ET.SubElement(cam, "maker").text = lens.camera_maker
    ET.SubElement(cam, "model").text = lens.camera_model
    ET.SubElement(cam, "mount").text = entry.mount
    ET.SubElement(cam, "cropfactor").text = repr(entry.cropfactor)
    cams = root.findall("camera")
    root.insert(list(root).index(cams[-1]) + 1 if cams else 0, cam)


CENTER_TOL = 1e-6
"""Two ``<center>`` offsets closer than this (lensfun units; ~1e-4 px) are the same centre."""


def _same_geometry(lens: ET.Element, entry: LensfunEntry) -> bool:
    """Whether the lens element has the entry's aspect ratio and distortion centre (they apply to all its calibrations)."""
    try:
        same_ar = math.isclose(float(_text_of(lens, "aspect-ratio") or "nan"), entry.aspect_ratio(), rel_tol=1e-9)
    except ValueError:
        same_ar = False
    c = _center_of(lens)
    same_type = (_text_of(lens, "type") or "rectilinear") == entry.model.lens_type
    return same_ar and same_type and all(abs(a - b) <= CENTER_TOL for a, b in zip(c, entry.model.center))


def _set_geometry(lens: ET.Element, entry: LensfunEntry) -> None:
    """Give the lens element the entry's aspect ratio and centre (it has no calibration they would change)."""
    for tag in ("aspect-ratio", "type", "center"):
        for el in lens.findall(tag):
            lens.remove(el)
    cal = lens.find("calibration")
    at = list(lens).index(cal) if cal is not None else len(lens)
    ar = ET.Element("aspect-ratio")
    ar.text = repr(entry.aspect_ratio())
    lens.insert(at, ar)
    if entry.model.lens_type != "rectilinear":
        at += 1
        typ = ET.Element("type")
        typ.text = entry.model.lens_type
        lens.insert(at, typ)
    if entry.model.center != (0.0, 0.0):
        lens.insert(at + 1, ET.Element("center", {"x": repr(entry.model.center[0]), "y": repr(entry.model.center[1])}))


def add_to_database(root: ET.Element, entry: LensfunEntry, name: str = "<existing>") -> str:
    """Add ``entry`` to a parsed ``<lensdatabase>`` in place; returns what was done (one line).

    Lensfun merges the lenses of one maker, model and crop factor into one, and a
    lens' aspect ratio and ``<center>`` apply to all its calibrations. So a lens
    already there gets this calibration (replacing the one at this focal); if its
    centre or aspect ratio differ, they are replaced when no calibration at another
    focal uses them, and otherwise ValueError(``name``: what to do), since one
    file cannot hold both.
    """
    _add_camera(root, entry)
    for lens in root.findall("lens"):
        k = _key(lens)
        if k[:3] != (entry.maker, entry.lens_model, entry.mount) or not math.isclose(k[3], entry.cropfactor):
            continue
        if not _same_geometry(lens, entry):
            cal_el = lens.find("calibration")
            kids = [] if cal_el is None else [el for el in cal_el if not _is_comment(el)]
            others = sorted(
                {
                    float(el.get("focal", "nan"))
                    for el in kids
                    if not math.isclose(float(el.get("focal", "nan")), entry.focal, rel_tol=1e-9)
                }
            )
            if others:
                focals = ", ".join(f"{f:g}" for f in others)
                raise ValueError(
                    f"{name}: lens {entry.maker} {entry.lens_model} (crop factor {entry.cropfactor:g}) is there with "
                    f"another distortion centre, aspect ratio or lens type, which its calibrations at {focals} mm use, and "
                    "lensfun holds one per lens name and crop factor: export with --lensfun-no-center, or into "
                    "another file"
                )
            _set_geometry(lens, entry)
        cal = lens.find("calibration")
        if cal is None:
            cal = ET.SubElement(lens, "calibration")
        kids = list(cal)
        for i, d in enumerate(kids):
            if d.tag == "distortion" and math.isclose(float(d.get("focal", "nan")), entry.focal, rel_tol=1e-9):
                before = kids[i - 1] if i > 0 and _is_comment(kids[i - 1]) else None
                pos = list(cal).index(d)
                cal.remove(d)
                if before is not None:
                    cal.remove(before)
                    pos -= 1
                cal.insert(pos, ET.Comment(_xml_comment(entry.note())))
                cal.insert(pos + 1, dist := _distortion_element(entry))
                _put_colour(cal, entry, dist)
                old = (before.text or "").strip() if before is not None else ""
                was = f" (it was: {old.split(';')[0]})" if old else ""
                line = f"replaced the calibration of {entry.maker} {entry.lens_model} at {entry.focal:g} mm{was}"
                old_focus = re.search(r"focus setting (\S+) \(", old)
                if old_focus is not None and entry.lens.focus is not None and old_focus[1] != f"{entry.lens.focus:g}":
                    line += (
                        f": lensfun holds one distortion per focal length and has no focus axis, so the focus "
                        f"{entry.lens.focus:g} calibration replaced the focus {old_focus[1]} one (keep one file per "
                        "focus setting, or export the focus the photos are taken at)"
                    )
                return line
        cal.append(ET.Comment(_xml_comment(entry.note())))
        cal.append(dist := _distortion_element(entry))
        _put_colour(cal, entry, dist)
        return f"added focal {entry.focal:g} mm to lens {entry.maker} {entry.lens_model}"
    lens = _new_lens(entry)
    cal = lens.find("calibration")
    assert cal is not None
    cal.append(ET.Comment(_xml_comment(entry.note())))
    cal.append(dist := _distortion_element(entry))
    _put_colour(cal, entry, dist)
    lenses = root.findall("lens")
    root.insert(list(root).index(lenses[-1]) + 1 if lenses else len(root), lens)
    return f"added lens {entry.maker} {entry.lens_model} ({entry.mount}, crop factor {entry.cropfactor:g})"


def parse_database(text: str, name: str = "<text>") -> ET.Element:
    """A lensfun database's root element, comments kept; ValueError('<name>: <reason>') if it is not one."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        root = ET.fromstring(text, parser=parser)
    except ET.ParseError as exc:
        raise ValueError(f"{name}: not valid XML ({exc})") from None
    if root.tag != "lensdatabase":
        raise ValueError(f"{name}: not a lensfun database (root <{root.tag}>, expected <lensdatabase>)")
    return root


def lensfun_database_text(
    entries: Sequence[LensfunEntry], existing: str | None = None, name: str = "<existing>"
) -> tuple[str, list[str]]:
    """Database XML holding ``entries`` (added to ``existing`` if given): ``(text, what was done)``."""
    root = parse_database(existing, name) if existing is not None else ET.Element("lensdatabase", {"version": "1"})
    done = [add_to_database(root, e, name) for e in entries]
    for el in root.iter():  # re-indent from scratch
        if el.text is not None and not el.text.strip():
            el.text = None
        el.tail = None
    ET.indent(root, space="    ")
    head = '<?xml version="1.0" encoding="UTF-8"?>\n'
    note = "<!-- exported by harp station; lensfun normalisation: unit = half the shorter side -->\n"
    return head + note + ET.tostring(root, encoding="unicode") + "\n", done


def lensfun_text(
    model: LensfunModel,
    error: ConversionError | None = None,
    *,
    maker: str = DEFAULT_MAKER,
    lens_model: str = DEFAULT_MODEL,
    mount: str = DEFAULT_MOUNT,
    cropfactor: float = 1.0,
    focal: float = DEFAULT_FOCAL_MM,
    lens: LensInfo | None = None,
) -> str:
    """Lensfun database XML text with one lens and one distortion calibration.

    ``lens`` (the configuration) takes precedence over the keyword values.
    """
    info = lens or LensInfo(
        lens_maker=maker, lens_model=lens_model, mount=mount, crop_factor=cropfactor, focal_mm=focal
    )
    text, _ = lensfun_database_text([LensfunEntry(model=model, lens=info, error=error)])
    return text


def _name(text: str) -> str:
    return " ".join(text.split()).casefold()


def installed_lens(databases: Sequence[tuple[str, str]], maker: str, model: str) -> str | None:
    """The first of ``databases`` (``(name, XML text)`` pairs) with a lens of this maker and model, or None.

    A lens matches when its ``<maker>`` and any of its ``<model>`` names (the
    untranslated one or a ``lang=`` one) equal ``maker`` and ``model``, case and
    runs of white space aside. Lensfun merges the lenses of every database it
    loads on (maker, model, crop factor), so a file with such a lens replaces
    the installed entry's calibrations (its TCA, vignetting, other focal
    lengths) instead of adding to them. Unreadable files are skipped: they are
    not ours to judge.
    """
    want_maker, want_model = _name(maker), _name(model)
    for name, text in databases:
        folded = text.casefold()
        if want_model not in folded and xml_escape(want_model) not in folded:  # cheap filter before parsing
            continue
        try:
            root = parse_database(text, name)
        except ValueError:
            continue
        for lens in root.iter("lens"):
            makers = {_name(m.text or "") for m in lens.findall("maker")}
            models = {_name(m.text or "") for m in lens.findall("model")}
            if want_maker in makers and want_model in models:
                return name
    return None


def read_lensfun_text(
    text: str,
    width: int,
    height: int,
    name: str = "<text>",
    focal: float | None = None,
    lens_name: str | None = None,
) -> LensfunModel:
    """The distortion of the lens of a lensfun XML, for images of ``width`` x ``height``.

    With several lenses, ``lens_name`` (``"maker model"`` or ``"model"``) picks
    one. With several ``<distortion>`` entries, ``focal`` picks the one at
    that focal length (no interpolation); ValueError('<name>: <reason>')
    otherwise. A calibration aspect ratio other than the images' gives
    lensfun's coordinate correction ``coord_scale`` (same crop factor assumed).
    """
    root = parse_database(text, name)
    lenses = root.findall("lens")
    if not lenses:
        raise ValueError(f"{name}: lensfun file without a <lens>")
    if lens_name is not None:
        lenses = [ln for ln in lenses if lens_name in (" ".join(_key(ln)[:2]), _key(ln)[1])]
        if not lenses:
            raise ValueError(f"{name}: no lens named {lens_name!r}")
    if len(lenses) > 1:
        names = "; ".join(" ".join(_key(ln)[:2]) for ln in lenses)
        raise ValueError(f"{name}: several lenses ({names}); choose one by name")
    lens = lenses[0]
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
    center = _center_of(lens)
    txt = _text_of(lens, "aspect-ratio")
    ar = 1.5  # lensfun's default for lenses
    if txt:
        try:
            ar = (float(txt.split(":")[0]) / float(txt.split(":")[1])) if ":" in txt else float(txt)
        except (ValueError, ZeroDivisionError):
            raise ValueError(f"{name}: invalid <aspect-ratio> {txt!r}") from None
        ar = max(ar, 1.0 / ar)
    img_ar = max(width - 1, height - 1) / min(width - 1, height - 1)
    kappa = float(np.sqrt(ar * ar + 1) / np.sqrt(img_ar * img_ar + 1))
    lens_type = _text_of(lens, "type") or "rectilinear"
    if lens_type not in LENSFUN_TYPES:
        raise ValueError(f"{name}: lens type {lens_type!r} is not one harp reads ({', '.join(LENSFUN_TYPES)})")
    gf = 0.0
    if lens_type != "rectilinear":
        try:
            crop = float(_text_of(lens, "cropfactor") or "nan")
            gf = geometry_focal(float(d.get("focal", "nan")), crop, ar)
        except ValueError:
            gf = float("nan")
        if not (np.isfinite(gf) and gf > 0):
            raise ValueError(f"{name}: a {lens_type} lens needs its <cropfactor> and the calibration's focal")
    return LensfunModel(
        kind=kind,
        terms=terms,
        width=width,
        height=height,
        center=center,
        coord_scale=kappa,
        lens_type=lens_type,
        geometry_focal=gf,
    )
