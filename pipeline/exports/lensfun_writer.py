"""The writer of the lensfun database XML: the camera's crop factor, the lens type, the colour.

:func:`lensfun_crop_factor` finds the crop factor lensfun scales a correction by, and
:func:`write_lensfun` fits lensfun's model (for :data:`~pipeline.exports.auto_rule.AUTO` lens type,
the closest of rectilinear and the fisheye types) and writes it with the lens's TCA and vignetting.
"""

from __future__ import annotations

from dataclasses import replace

from pipeline.exports.auto_rule import AUTO
from pipeline.exports.colour import lensfun_colour
from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.fit import fit_lensfun
from pipeline.exports.lens import LensInfo
from pipeline.exports.lensfun import LensfunEntry, installed_lens, lens_names, lensfun_database_text
from pipeline.exports.measured_camera import measured_camera
from pipeline.exports.readers import decoded_text
from pipeline.exports.source import Export, ExportOptions, ExportSource, conversion_warnings
from pipeline.models.lensfun_model import LENSFUN_FISHEYE_TYPES, LensfunModel
from pipeline.models.lensfun_model import geometry_focal as lensfun_geometry_focal

CROP_FACTOR_MISMATCH = 0.15
"""Relative difference between a configured crop factor and the one the pixel pitch gives that is warned of.

Above what an image of another aspect ratio than the sensor explains (a 16:9 or 4:3 image of a 3:2
sensor's width has a 4-9 % shorter or longer diagonal), below a wrong camera (1.0 or 1.6 for 7.2)."""


def lensfun_crop_factor(lens: LensInfo, width: int, height: int) -> tuple[LensInfo, str | None, list[str]]:
    """The lens with the camera's crop factor lensfun needs: ``(lens, how it was found, warnings)``.

    Lensfun scales a correction by the ratio of the calibration's crop factor to
    the camera's, so a wrong one moves every corrected pixel (3.2-3.5 px on a
    crop-7 camera written as 1.0). Configured (or ``--crop``) wins; otherwise it
    is derived from the pixel pitch or sensor width
    (:meth:`LensInfo.derived_crop_factor`); without either, ValueError naming
    what to give.
    """
    derived = lens.derived_crop_factor(width, height)
    if lens.crop_factor is not None:
        warnings = []
        if derived is not None and abs(lens.crop_factor / derived - 1) > CROP_FACTOR_MISMATCH:
            optic = "pixel pitch" if lens.pixel_pitch_um is not None else "sensor width"
            warnings.append(
                f"lensfun: crop factor {lens.crop_factor:g} written, but the {optic} gives {derived:.4g} for "
                f"{width}x{height} images; lensfun scales the correction by the crop factor: check which is the camera's"
            )
        return lens, None, warnings
    if derived is None:
        raise ValueError(
            "lensfun: the camera's crop factor is not known and lensfun scales the correction by it; give --crop FACTOR "
            "(1 for a full-frame camera), or camera_body.crop_factor, pixel_pitch_um or sensor_width_mm in the configuration"
        )
    if lens.pixel_pitch_um is not None:
        how = f"crop factor {derived:.4g} derived from the pixel pitch {lens.pixel_pitch_um:g} um over {width}x{height} images"
    else:
        how = f"crop factor {derived:.4g} derived from the sensor width {lens.sensor_width_mm:g} mm over {width} px"
    return replace(lens, crop_factor=round(derived, 4)), how, []


LENSFUN_FISHEYE_TRY_PX = 1.0
""":data:`AUTO` lens type: a rectilinear lensfun fit whose max error (modulo homography) exceeds this
(px), or a calibration that chose a wide-angle model, is tried as every lensfun fisheye type too
(five more fits). Above what ptlens leaves on ordinary lenses (0.77 px on the shared real camera),
below what it leaves on a fisheye (12 px on a 115 degree lens)."""


LENSFUN_TYPE_MARGIN = 0.8
"""A fisheye type replaces rectilinear only when its max error is below this fraction of rectilinear's:
a rectilinear file needs no geometry conversion in the consumer."""


def _fit_lensfun_type(
    src: ExportSource, opt: ExportOptions, lens: LensInfo
) -> tuple[LensfunModel, ConversionError, list[str]]:
    """The lensfun fit of the lens type asked for (``opt.lensfun_type``), or for :data:`AUTO` the
    closest of rectilinear and the fisheye types (max error modulo homography); with what to say."""

    def fit(lens_type: str) -> tuple[LensfunModel, ConversionError]:
        gf = 0.0
        if lens_type != "rectilinear":
            if lens.focal_mm is None:
                raise ValueError(
                    f"lensfun: a {lens_type} lens needs the nominal focal length (lensfun converts its geometry "
                    "with it): give --focal-mm or lens.focal_mm"
                )
            w, h = src.width, src.height
            gf = lensfun_geometry_focal(
                float(lens.focal_mm), float(lens.crop_factor or 1.0), max(w - 1, h - 1) / min(w - 1, h - 1)
            )
        return fit_lensfun(
            src.model,
            src.width,
            src.height,
            kind=opt.lensfun_model,
            fit_center=opt.lensfun_center,
            edges=src.edges,
            lens_type=lens_type,
            geometry_focal=gf,
        )

    if opt.lensfun_type != AUTO:
        m, err = fit(opt.lensfun_type)
        return m, err, _type_notes(m)
    m, err = fit("rectilinear")
    if not (src.wide_angle or err.max_mod_h_px > LENSFUN_FISHEYE_TRY_PX) or lens.focal_mm is None:
        return m, err, []
    tried = {"rectilinear": (m, err)}
    for t in LENSFUN_FISHEYE_TYPES:
        try:
            tried[t] = fit(t)
        except ValueError:  # a type that cannot hold the lens over the image (its projection ends inside)
            continue
    best = min(tried, key=lambda t: tried[t][1].max_mod_h_px)
    if best != "rectilinear" and tried[best][1].max_mod_h_px >= LENSFUN_TYPE_MARGIN * err.max_mod_h_px:
        best = "rectilinear"
    figures = ", ".join(f"{t} {e.max_mod_h_px:.3g}" for t, (_, e) in tried.items())
    m, err = tried[best]
    return m, err, [f"lensfun: lens type {best} (max error modulo homography, px: {figures})", *_type_notes(m)]


def _type_notes(m: LensfunModel) -> list[str]:
    if m.lens_type == "rectilinear":
        return []
    return [
        f"lensfun: a {m.lens_type} lens: lensfun corrects it to the ideal {m.lens_type} projection, and lines are "
        "straight after its geometry conversion to rectilinear too (darktable: lens correction, geometry "
        "'rectilinear'; lensfunpy: flags DISTORTION | GEOMETRY, targeom RECTILINEAR)"
    ]


def write_lensfun(src: ExportSource, opt: ExportOptions) -> Export:
    lens, crop_how, warnings = lensfun_crop_factor(
        src.lens.with_overrides(crop_factor=opt.crop_factor, mount=opt.mount), src.width, src.height
    )
    maker, model = lens_names(lens)
    clash = installed_lens(opt.installed_lensfun, maker, model)
    if clash is not None:
        raise ValueError(
            f"lensfun: lens '{model}' of {maker} is in the installed lensfun database "
            f"{clash}; lensfun merges lenses by name, so a file under that name replaces that entry's calibrations "
            "(its TCA, vignetting, other focal lengths): export under another name (--lens-model, e.g. with the "
            "serial number)"
        )
    m, err, type_notes = _fit_lensfun_type(src, opt, lens)
    existing = decoded_text(opt.existing, opt.existing_name) if opt.existing is not None else None
    entry = LensfunEntry(model=m, lens=lens, error=err, crop_note=crop_how, stamp=src.stamp)
    colour_lines: list[str] = []
    if src.colour is not None:
        problem = src.colour.size_problem(src.width, src.height)
        if problem is not None:
            raise ValueError(f"lensfun: {problem}")
        lc = lensfun_colour(src.colour, m.center, opt.lensfun_tca)
        colour_lines = [f"lensfun: {line}" for line in lc.lines()]
        entry = replace(
            entry,
            tca=None if lc.tca is None else lc.tca.model,
            vignetting=lc.vignetting,
            aperture=src.colour.aperture if src.colour.aperture is not None else entry.aperture,
            distance=src.colour.distance,
            colour_lines=tuple(lc.lines()),
        )
    text, done = lensfun_database_text([entry], existing, opt.existing_name)
    notes = [
        d for d in done if not d.startswith("replaced ")
    ]  # replacing a calibration in the user's file is warned of
    warnings += [f"lensfun: {d}" for d in done if d.startswith("replaced ")]
    notes += type_notes
    notes += colour_lines
    if crop_how is not None:
        notes.append(f"lensfun: {crop_how}")
    if lens.focal_mm is None:
        notes.append("lensfun: no nominal focal length configured, filed under 50 mm")
    measured, why_not = measured_camera(src)
    if measured is not None:
        notes.append(
            "lensfun holds no camera matrix (it files the lens under its nominal focal length): the measured one "
            f"(fx {measured.camera[0]:.3f}, fy {measured.camera[1]:.3f}, cx {measured.camera[2]:.3f}, "
            f"cy {measured.camera[3]:.3f} px) is not in this file"
            if measured.camera is not None
            else ""
        )
    warnings += why_not
    warnings += conversion_warnings("lensfun", src, err)
    return Export("lensfun", text.encode(), err, m, tuple(notes), tuple(warnings))
