"""The writers of the formats whose file holds a pin-hole or a fisheye model, the closer one.

COLMAP (OPENCV, FULL_OPENCV, OPENCV_FISHEYE or THIN_PRISM_FISHEYE), Kalibr (pinhole-radtan or
pinhole-equi), Agisoft Metashape (frame or fisheye camera), Basalt (``kb4``) and the Adobe lens
profile (PerspectiveModel or FisheyeModel), each choosing by
:func:`~pipeline.exports.fitted.pinhole_or_fisheye` and stating the choice and why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from pipeline.exports.auto_rule import auto_limit, fisheye_reason
from pipeline.exports.basalt import basalt_text
from pipeline.exports.colmap import colmap_model_name, colmap_text
from pipeline.exports.fit import RADTAN_COEFFS
from pipeline.exports.fitted import (
    Fitted,
    fit_fisheye_export,
    fit_pinhole,
    fit_thin_prism,
    pinhole_or_fisheye,
    pinhole_or_fisheye_tried,
)
from pipeline.exports.kalibr import kalibr_text
from pipeline.exports.lcp import LCP_FISHEYE_COEFFS, LCP_PINHOLE_COEFFS, LcpProfile, check_existing, lcp_text
from pipeline.exports.metashape import PINHOLE_COEFFS as METASHAPE_PINHOLE_COEFFS
from pipeline.exports.metashape import metashape_text
from pipeline.exports.readers import decoded_text
from pipeline.exports.source import Export, ExportOptions, ExportSource, lens_notes
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel

COLMAP_PINHOLE_COEFFS = 8
"""COLMAP's FULL_OPENCV holds OpenCV's 8 rational coefficients (no thin prism)."""


def _write_chosen_family(
    fmt: str, src: ExportSource, opt: ExportOptions, n: int, names: tuple[str, str], text_of: Callable[..., str]
) -> Export:
    """The file of a format that holds a pin-hole fit with ``n`` coefficients or the fisheye fit, as
    :func:`pinhole_or_fisheye` chooses, written by ``text_of`` (:func:`~pipeline.exports.colmap.colmap_text`,
    :func:`~pipeline.exports.kalibr.kalibr_text`, :func:`~pipeline.exports.metashape.metashape_text`)."""
    chosen, choice = pinhole_or_fisheye(fmt, src, opt, n, names)
    return _write_fitted(fmt, src, chosen, choice, text_of)


def _write_fitted(fmt: str, src: ExportSource, chosen: Fitted, choice: str, text_of: Callable[..., str]) -> Export:
    """The file of one fit, written by ``text_of`` with the statement every format makes (``choice``: the
    model and why)."""
    text = text_of(chosen.model, src.width, src.height, chosen.statement(src, choice=f"model {choice}"))
    notes = (f"{fmt}: {choice}", chosen.cam.statement, *chosen.measured)
    return Export(fmt, text.encode(), chosen.error, chosen.model, notes, chosen.warnings)


def write_colmap(src: ExportSource, opt: ExportOptions) -> Export:
    """COLMAP ``cameras.txt``: OPENCV (the OpenCV 4-coefficient fit, ``k1 k2 p1 p2``) when it is as exact
    as the calibration (:func:`fisheye_reason` finds no reason to try more: not a wide-angle calibration,
    RMS, residual ``d`` and max within the limit of :func:`auto_limit`); otherwise FULL_OPENCV (the
    8-coefficient fit) or OPENCV_FISHEYE (the fisheye fit), as :func:`pinhole_or_fisheye` chooses, or,
    when the fisheye was tried (and no measured camera matrix is held), THIN_PRISM_FISHEYE fitted from
    it (:func:`~pipeline.exports.fit.fit_thin_prism_fisheye`) if its max is below
    :data:`COLMAP_THIN_PRISM_MARGIN` times the choice's.
    COLMAP inverts every model iteratively to convergence (``cam_from_img``), so, unlike OpenCV's
    default point solvers, the conversion error is what it sees."""
    try:
        simple = fit_pinhole("colmap", src, opt, RADTAN_COEFFS, hint=False)
    except ValueError:  # 4 coefficients cannot hold the lens without a fold: the richer models decide
        simple = None
    if simple is not None and fisheye_reason(src, simple.error, simple.error.max_mod_h_px) is None:
        limit, what = auto_limit(src)
        e = simple.error
        choice = (
            f"OPENCV (k1 k2 p1 p2): its conversion error (RMS {e.rms_mod_h_px:.4f} px, max {e.max_mod_h_px:.4f} px "
            f"modulo homography) is within {what} ({limit:.4f} px), FULL_OPENCV and OPENCV_FISHEYE not tried"
        )
        return _write_fitted("colmap", src, simple, choice, colmap_text)
    names = ("FULL_OPENCV", "OPENCV_FISHEYE")
    chosen, choice, fe = pinhole_or_fisheye_tried("colmap", src, opt, COLMAP_PINHOLE_COEFFS, names)
    if fe is not None and fe.cam.camera is None and isinstance(fe.model, OpenCVFisheyeModel):
        prism = fit_thin_prism("colmap", src, opt, fe)
        e = prism.error
        if e.max_mod_h_px < COLMAP_THIN_PRISM_MARGIN * chosen.error.max_mod_h_px:
            choice = (
                f"THIN_PRISM_FISHEYE, closer in max than {colmap_model_name(chosen.model)} by more than "
                f"{1 - COLMAP_THIN_PRISM_MARGIN:.0%} (RMS {e.rms_mod_h_px:.4f} / max {e.max_mod_h_px:.4f} px modulo "
                f"homography); {choice}"
            )
            return _write_fitted("colmap", src, prism, choice, colmap_text)
        choice += f"; THIN_PRISM_FISHEYE RMS {e.rms_mod_h_px:.4f} / max {e.max_mod_h_px:.4f} px is not closer enough"
    return _write_fitted("colmap", src, chosen, choice, colmap_text)


COLMAP_THIN_PRISM_MARGIN = 0.8
"""COLMAP's THIN_PRISM_FISHEYE replaces the FULL_OPENCV or OPENCV_FISHEYE choice only when its max error is
below this fraction of the choice's: the simpler models are read by more tools (COLMAP's undistorter,
OpenCV-based readers of cameras.txt)."""


def write_basalt(src: ExportSource, opt: ExportOptions) -> Export:
    """Basalt calibration JSON: ``kb4``, the fisheye fit (Basalt's Kannala-Brandt is OpenCV's fisheye)."""
    fitted = fit_fisheye_export("basalt", src, opt)
    e = fitted.error
    choice = (
        f"kb4 (Basalt's Kannala-Brandt, OpenCV's fisheye fit): RMS {e.rms_mod_h_px:.4f} px, max "
        f"{e.max_mod_h_px:.4f} px modulo homography"
    )
    return _write_fitted("basalt", src, fitted, choice, basalt_text)


def write_metashape(src: ExportSource, opt: ExportOptions) -> Export:
    """Agisoft Metashape calibration XML: a frame camera (the OpenCV 5-coefficient fit, Metashape's p1/p2
    swapped, ``K4 = 0``) or a fisheye camera (the fisheye fit, ``K1..K4``), as :func:`pinhole_or_fisheye`
    chooses."""
    names = ("frame", "fisheye")
    return _write_chosen_family("metashape", src, opt, METASHAPE_PINHOLE_COEFFS, names, metashape_text)


def write_kalibr(src: ExportSource, opt: ExportOptions) -> Export:
    """Kalibr camchain YAML: pinhole-radtan (the OpenCV 4-coefficient fit, ``k1 k2 p1 p2``) or
    pinhole-equi (the fisheye fit)."""
    names = ("pinhole-radtan", "pinhole-equi")
    return _write_chosen_family("kalibr", src, opt, RADTAN_COEFFS, names, kalibr_text)


def write_lcp(src: ExportSource, opt: ExportOptions) -> Export:
    """Adobe lens profile (:mod:`pipeline.exports.lcp`): the PerspectiveModel (the OpenCV 5-coefficient
    fit) or the FisheyeModel (the fisheye fit with ``k1 k2``), whichever is closer, filed under the
    nominal focal length and ``opt.focus_distance_m``; added to ``opt.existing`` when it is a profile of
    the same lens. The camera matrix is the nominal one (a measured one is not used: the profile's
    ``FocalLengthX`` is a scale of its coefficients, the centre the fitted distortion centre)."""
    names = ("PerspectiveModel (k1 k2 k3, tangential k4 k5)", "FisheyeModel (k1 k2)")
    existing = decoded_text(opt.existing, opt.existing_name) if opt.existing is not None else None
    # before the fit: a file of another lens is refused at once; a profile holds one model kind
    kind = None if existing is None else check_existing(existing, src.lens, opt.existing_name)
    plain = replace(src, intrinsics=None)
    if kind is None:
        chosen, choice = pinhole_or_fisheye("lcp", plain, opt, LCP_PINHOLE_COEFFS, names, LCP_FISHEYE_COEFFS)
    else:
        fisheye = kind == "FisheyeModel"
        try:
            chosen = (
                fit_fisheye_export("lcp", plain, opt, LCP_FISHEYE_COEFFS)
                if fisheye
                else fit_pinhole("lcp", plain, opt, LCP_PINHOLE_COEFFS, hint=False)
            )
        except ValueError as exc:
            raise ValueError(
                f"{opt.existing_name} holds {kind} entries and a profile holds one kind: {exc}; write another file"
            ) from None
        e = chosen.error
        choice = (
            f"{names[1] if fisheye else names[0]}, the kind of the profile's other entries (RMS {e.rms_mod_h_px:.4f} / "
            f"max {e.max_mod_h_px:.4f} px modulo homography)"
        )
    lens = src.lens.with_overrides(crop_factor=opt.crop_factor, mount=opt.mount)
    notes = [f"lcp: {choice}", chosen.cam.statement]
    if lens.crop_factor is None:
        derived = lens.derived_crop_factor(src.width, src.height)
        if derived is not None:
            lens = replace(lens, crop_factor=round(derived, 4))
            notes.append(
                f"lcp: SensorFormatFactor {lens.crop_factor:g} derived from the optics (43.27 mm over the image diagonal)"
            )
        else:
            notes.append("lcp: no crop factor known: no SensorFormatFactor written (give --crop)")
    if lens.focal_mm is None:
        notes.append("lcp: no nominal focal length (--focal-mm): the profile states none, for any focal length")
    if opt.focus_distance_m is None:
        notes.append("lcp: no focus distance (--distance): the profile states none")
    if src.intrinsics is not None:
        notes.append("lcp: the measured camera matrix is not used (the profile's focal and centre are the fit's)")
    e = chosen.error
    comments = (
        *src.stamp,
        *lens_notes(src),
        f"{AUTHOR_LINE}: {choice}",
        *e.lines(),
        chosen.cam.statement,
    )
    header = (
        *src.stamp,
        f"{AUTHOR_LINE}: Adobe lens profile; centre = ImageXCenter * width, ImageYCenter * height, pixel (i, j) at "
        "(i, j); focal = FocalLengthX * max(width, height) (RawTherapee's reading, rtengine/lcp.cc)",
    )
    assert isinstance(chosen.model, (OpenCVModel, OpenCVFisheyeModel))  # the 5- or 2-coefficient fits
    profile = LcpProfile(chosen.model, src.width, src.height, lens.focal_mm, opt.focus_distance_m, tuple(comments))
    text, done = lcp_text(profile, lens, header=header, existing=existing, existing_name=opt.existing_name)
    warnings = [*chosen.warnings, *(f"lcp: {d}" for d in done if d.startswith("replaced "))]
    notes += [f"lcp: {d}" for d in done if not d.startswith("replaced ")]
    return Export("lcp", text.encode(), e, chosen.model, tuple(notes), tuple(warnings))


AUTHOR_LINE = "harp station"
