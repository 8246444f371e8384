"""The export formats of a harp correction, each with ``write``, ``read`` and ``sniff``.

One table, :data:`FORMATS`, names every format harp station writes for other
software (and reads back, so that ``harp evaluate`` can measure any of them
on harp shots). Each :class:`ExportFormat` has

- ``write(source, options) -> Export``: the file's bytes from an
  :class:`ExportSource` (the model, its image size, the lens configuration,
  the holdout figure and the fitting shots' edges), with the conversion error
  and any warning (e.g. the conversion error exceeds the model's own
  holdout ``d``) for the command to print;
- ``read(data, request) -> Correction``: the correction a file holds, as a
  :class:`~pipeline.models.base.DistortionModel`;
- ``sniff(data) -> bool``: whether bytes look like this format.

:func:`read_correction` detects the format of any correction file and reads
it for an image size. Everything here works on bytes: the commands do the
file I/O.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.corrected_frame import FrameChoice, corrected_frame
from pipeline.exports import maps as maps_fmt
from pipeline.exports.basalt import basalt_text, read_basalt_text, sniff_basalt
from pipeline.exports.colmap import colmap_model_name, colmap_text, read_colmap_text, sniff_colmap
from pipeline.exports.colour import ColourCorrection, OpenCVChannel, lensfun_colour, opencv_channels
from pipeline.exports.fit import (
    RADTAN_COEFFS,
    ConversionError,
    conversion_error_in_frame,
    fit_fisheye,
    fit_fisheye_camera,
    fit_lensfun,
    fit_opencv,
    fit_opencv_camera,
    fit_thin_prism_fisheye,
    frame_error,
)
from pipeline.exports.frame import FrameStatement, frame_statement
from pipeline.exports.kalibr import kalibr_text, read_kalibr_text, sniff_kalibr
from pipeline.exports.lcp import (
    LCP_FISHEYE_COEFFS,
    LCP_PINHOLE_COEFFS,
    LcpProfile,
    check_existing,
    lcp_text,
    read_lcp_text,
    sniff_lcp,
)
from pipeline.exports.lens import CameraMatrixChoice, LensInfo, camera_matrix_choice
from pipeline.exports.lensfun import (
    LensfunEntry,
    installed_lens,
    lens_names,
    lensfun_database_text,
    read_lensfun_text,
)
from pipeline.exports.metashape import PINHOLE_COEFFS as METASHAPE_PINHOLE_COEFFS
from pipeline.exports.metashape import metashape_text, read_metashape_text, sniff_metashape
from pipeline.exports.mrcal import mrcal_text, read_mrcal_text, sniff_mrcal
from pipeline.exports.opencv import opencv_text, read_opencv_text
from pipeline.exports.ros import ROS_EQUIDISTANT_READERS, read_ros_text, ros_text
from pipeline.exports.solvers import SolverNeed, solver_need
from pipeline.exports.statement import hash_comments
from pipeline.intrinsics import Intrinsics, distortion_digest
from pipeline.model_file import FORMAT_VERSION, model_file_text, parse_model_text
from pipeline.models.base import DistortionModel
from pipeline.models.homography import HomographyModel
from pipeline.models.lensfun_model import LENSFUN_FISHEYE_TYPES, LensfunModel
from pipeline.models.lensfun_model import geometry_focal as lensfun_geometry_focal
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.remap_model import CorrectionMapModel, RemapModel
from pipeline.models.thin_prism_fisheye_model import ThinPrismFisheyeModel
from pipeline.plain import json_default

Array = npt.NDArray[np.float64]

HARP_FORMAT_NAME = "harp-distortion-model"


@dataclass(frozen=True)
class ExportSource:
    """What an export is made from.

    Attributes
    ----------
    model : DistortionModel
        The harp correction (distorted -> ideal pixels).
    width, height : int
        The image size it is for.
    lens : LensInfo
        Lens, camera body and optics from the configuration.
    holdout_d : float, optional
        The model's own holdout ``d`` (px): an export whose conversion error
        exceeds it is less exact than the calibration, and says so.
    edges : sequence of (N, 2) arrays, optional
        Measured edge points of the shots the model was fitted on.
    merit, provenance : mapping
        The model file's records (written by the ``harp``/``json`` formats).
    wide_angle : bool
        The calibration chose a wide-angle model: :data:`AUTO` then fits the
        fisheye export too and writes the closer of the two.
    stamp : tuple of str
        Lines every format states first, in its own comment or header
        mechanism (a comment line each in the text formats, an XML comment in
        lensfun, the ``notes`` of the maps and the comments of the STMap, a
        ``stamp`` list in json): what a reader of the file must know before
        using it, e.g. that the profile failed QA.
    intrinsics : Intrinsics, optional
        The camera matrix measured with this correction held fixed (``harp intrinsics``):
        the OpenCV, ROS and mrcal exports use it (:func:`measured_camera`), the others say
        how they hold it.
    colour : ColourCorrection, optional
        The red and blue channels' TCA fields and the lens's vignetting (``harp tca``,
        ``harp vignetting``): the lensfun export writes them as ``<tca>`` and ``<vignetting>``
        (:func:`~pipeline.exports.colour.lensfun_colour`).
    """

    model: DistortionModel
    width: int
    height: int
    lens: LensInfo = field(default_factory=LensInfo)
    holdout_d: float | None = None
    edges: Sequence[Array] | None = None
    merit: Mapping[str, Any] = field(default_factory=dict)
    provenance: Mapping[str, Any] = field(default_factory=dict)
    wide_angle: bool = False
    stamp: tuple[str, ...] = ()
    intrinsics: Intrinsics | None = None
    colour: ColourCorrection | None = None


@dataclass(frozen=True)
class ExportOptions:
    """Choices of the user for one export (None: the format's default)."""

    coeffs: int | None = None
    focal_px: float | None = None
    xml: bool = False
    lensfun_model: str = "ptlens"
    lensfun_center: bool = True
    lensfun_type: str = "auto"
    lensfun_tca: str = "poly3"
    crop_factor: float | None = None
    mount: str | None = None
    camera_name: str | None = None
    existing: bytes | None = None
    existing_name: str = "<existing>"
    frame: FrameChoice = field(default_factory=FrameChoice)
    """The corrected image (``--size``, ``--scale``, ``--alpha``, ``--overscan``; :mod:`pipeline.corrected_frame`):
    the maps and STMaps hold it, the pin-hole and fisheye files state the ``R`` and ``newK`` that write it."""
    installed_lensfun: tuple[tuple[str, str], ...] = ()
    focus_distance_m: float | None = None
    """The focus distance (metres) an LCP profile files the calibration under (None: not stated)."""
    """The lensfun databases lensfun loads on this machine, ``(path, XML text)``: a lensfun export
    under the name of a lens in one of them is refused (see :func:`~pipeline.exports.lensfun.installed_lens`)."""


@dataclass(frozen=True)
class Export:
    """A written export: the bytes, the conversion error, what to tell the user."""

    format: str
    data: bytes
    error: ConversionError | None = None
    converted: DistortionModel | None = None
    notes: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    solver: SolverNeed | None = None


@dataclass(frozen=True)
class ReadRequest:
    """What a reader needs besides the bytes: the file's name (for messages) and the image size."""

    name: str
    width: int
    height: int
    focal: float | None = None
    lens_name: str | None = None


@dataclass(frozen=True)
class Correction:
    """The correction held by a file: the model, the image size the file states (if any), its kind."""

    model: DistortionModel
    size: tuple[int, int] | None
    kind: str


@dataclass(frozen=True)
class ExportFormat:
    """One export format (see module docstring)."""

    name: str
    summary: str
    suffix: str
    binary: bool
    write: Callable[[ExportSource, ExportOptions], Export]
    read: Callable[[bytes, ReadRequest], Correction]
    sniff: Callable[[bytes], bool]
    coeffs: tuple[int, ...] = ()
    default_coeffs: int | None = None


# ------------------------------------------------------------------ helpers
def _text(data: bytes, name: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{name}: cannot read correction file (UnicodeDecodeError)") from None


def _coeffs(fmt: str, opt: ExportOptions, allowed: tuple[int, ...], default: int) -> int:
    n = default if opt.coeffs is None else int(opt.coeffs)
    if n not in allowed:
        raise ValueError(f"--coeffs {n}: the {fmt} export takes {', '.join(map(str, allowed))} coefficients")
    return n


def conversion_warnings(fmt: str, src: ExportSource, err: ConversionError) -> list[str]:
    """A warning when the conversion error exceeds the model's own holdout ``d``."""
    if src.holdout_d is None or not math.isfinite(src.holdout_d):
        return []
    worst = max(err.rms_mod_h_px, err.d_px if math.isfinite(err.d_px) else 0.0)
    if worst <= src.holdout_d:
        return []
    return [
        f"{fmt}: the conversion error (RMS {err.rms_mod_h_px:.4f} px modulo homography, residual d "
        f"{err.d_px:.4f} px) exceeds the model's own holdout d {src.holdout_d:.4f} px: "
        "this export is less exact than the calibration"
    ]


def _fisheye_hint(fmt: str, src: ExportSource, err: ConversionError, focal: float | None) -> list[str]:
    """When a pin-hole export is not good enough, say whether the fisheye model is closer."""
    try:
        _, fe = fit_fisheye(src.model, src.width, src.height, focal=focal)
    except ValueError:
        return []
    if fe.rms_mod_h_px < 0.5 * err.rms_mod_h_px:
        alt = "opencv-fisheye" if fmt.startswith("opencv") else "ros-equidistant"
        return [
            f"{fmt}: the fisheye (Kannala-Brandt) model is closer to this lens: --format {alt} converts with "
            f"RMS {fe.rms_mod_h_px:.4f} px, max {fe.max_mod_h_px:.4f} px modulo homography"
        ]
    return []


def measured_camera(src: ExportSource) -> tuple[CameraMatrixChoice | None, list[str]]:
    """The measured camera matrix of ``src`` as an export's choice, or None with why it is not used:
    ``(choice, warnings)``. Not used (a warning each): measured for another image size, or with
    another distortion than ``src.model`` (its digest differs: the lens was calibrated again since).
    A camera matrix with skew is refused (ValueError): the OpenCV, ROS and mrcal files hold none."""
    i = src.intrinsics
    if i is None:
        return None, []
    if (i.width, i.height) != (int(src.width), int(src.height)):
        return None, [
            f"the measured camera matrix is for {i.width}x{i.height} images, not {src.width}x{src.height}: not used"
        ]
    if i.distortion and i.distortion != distortion_digest(src.model):
        return None, [
            "the measured camera matrix was measured with another distortion than this profile's: not used "
            "(run harp intrinsics again with this model)"
        ]
    if i.skew_fitted and abs(i.skew) > 1e-9 * i.fx:
        raise ValueError(
            f"the measured camera matrix has skew {i.skew:.4g} px, which OpenCV, ROS and mrcal files cannot hold; "
            "measure it again without --skew"
        )
    return (
        CameraMatrixChoice(
            i.fx,
            "measured",
            i.source,
            camera=(i.fx, i.fy, i.cx, i.cy),
            sd=(i.sd[0], i.sd[1], i.sd[2], i.sd[3]),
            text=i.statement(),
        ),
        [],
    )


def _camera(src: ExportSource, opt: ExportOptions) -> CameraMatrixChoice:
    if opt.focal_px is None:
        measured, _ = measured_camera(src)
        if measured is not None:
            return measured
    return camera_matrix_choice(src.lens, src.width, src.height, opt.focal_px)


def _frame_of(
    fmt: str, src: ExportSource, opt: ExportOptions, m: DistortionModel, k: Any, focal: float
) -> FrameStatement:
    """The export's ``R`` and ``newK`` for the corrected image the options ask (ValueError naming the format)."""
    try:
        return frame_statement(src.model, m, k, src.width, src.height, opt.frame, focal)
    except ValueError as exc:
        raise ValueError(f"{fmt}: {exc}") from None


def _measured_lines(src: ExportSource, cam: CameraMatrixChoice, converted: DistortionModel) -> list[str]:
    """With a measured camera matrix, the conversion error in the camera's own frame."""
    if cam.camera is None:
        return []
    rms, mx = frame_error(src.model, converted, src.width, src.height)
    return [
        f"distortion fitted with the measured camera matrix fixed, in its frame (no homography): "
        f"RMS {rms:.4f} px, max {mx:.4f} px from the harp correction"
    ]


def _camera_warnings(src: ExportSource, opt: ExportOptions) -> list[str]:
    if opt.focal_px is not None and src.intrinsics is not None:
        return ["--focal-px given: the measured camera matrix is not used"]
    return measured_camera(src)[1]


def _lens_notes(src: ExportSource) -> tuple[str, ...]:
    parts = []
    if src.lens.lens_name:
        parts.append(f"lens {src.lens.lens_name}" + (f" s/n {src.lens.lens_serial}" if src.lens.lens_serial else ""))
    if src.lens.camera_body:
        parts.append(f"camera {src.lens.camera_body}")
    if src.lens.focus is not None:
        parts.append(f"focus setting {src.lens.focus:g}")
    out = ["; ".join(parts)] if parts else []
    if src.holdout_d is not None and math.isfinite(src.holdout_d):
        out.append(f"the harp correction's own holdout d: {src.holdout_d:.4f} px")
    return tuple(out)


# ------------------------------------------------------------------ writers
@dataclass(frozen=True)
class _Fitted:
    """A pin-hole or fisheye fit with what its file states: camera choice, measured-camera lines, frame, warnings."""

    model: OpenCVModel | OpenCVFisheyeModel | ThinPrismFisheyeModel
    error: ConversionError
    cam: CameraMatrixChoice
    measured: tuple[str, ...]
    frame: FrameStatement
    warnings: tuple[str, ...]

    def notes(self, src: ExportSource) -> tuple[str, ...]:
        return (*_lens_notes(src), *self.measured)


def _fit_pinhole(fmt: str, src: ExportSource, opt: ExportOptions, n: int, hint: bool = True) -> _Fitted:
    cam = _camera(src, opt)
    if cam.camera is not None:
        m, err = fit_opencv_camera(src.model, src.width, src.height, cam.camera, n_coeffs=n, edges=src.edges)
    else:
        m, err = fit_opencv(src.model, src.width, src.height, n_coeffs=n, focal=cam.focal_px, edges=src.edges)
    warnings = _camera_warnings(src, opt) + conversion_warnings(fmt, src, err)
    if warnings and hint and cam.camera is None:
        warnings += _fisheye_hint(fmt, src, err, cam.focal_px if cam.kind != "placeholder" else None)
    measured = tuple(_measured_lines(src, cam, m))
    fr = _frame_of(fmt, src, opt, m, m.camera_matrix, cam.focal_px)
    return _Fitted(m, err, cam, measured, fr, tuple(warnings))


def _fit_fisheye_export(fmt: str, src: ExportSource, opt: ExportOptions, n_coeffs: int = 4) -> _Fitted:
    cam = _camera(src, opt)
    focal = None if cam.kind == "placeholder" else cam.focal_px
    if cam.camera is not None and n_coeffs == 4:
        m, err = fit_fisheye_camera(src.model, src.width, src.height, cam.camera, edges=src.edges)
    else:
        m, err = fit_fisheye(src.model, src.width, src.height, focal=focal, edges=src.edges, n_coeffs=n_coeffs)
    fr = _frame_of(fmt, src, opt, m, m.camera_matrix, cam.focal_px)
    if focal is None:
        cam = CameraMatrixChoice(m.fx, "placeholder", "fitted with the fisheye coefficients, not measured")
    measured = tuple(_measured_lines(src, cam, m))
    warnings = _camera_warnings(src, opt) + conversion_warnings(fmt, src, err)
    return _Fitted(m, err, cam, measured, fr, tuple(warnings))


def _write_pinhole(
    fmt: str, src: ExportSource, opt: ExportOptions, allowed: tuple[int, ...], default: int, hint: bool = True
) -> Export:
    f = _fit_pinhole(fmt, src, opt, _coeffs(fmt, opt, allowed, default), hint)
    m, err, cam, fr, notes = f.model, f.error, f.cam, f.frame, f.notes(src)
    assert isinstance(m, OpenCVModel)
    sn = None
    channel_lines: tuple[str, ...] = ()
    if fmt == "opencv":
        sn = solver_need(src.model, m, src.width, src.height)
        channels = _opencv_channels(src, m)
        channel_lines = tuple(f"opencv: {c.line()}" for c in channels)
        text = opencv_text(
            m,
            src.width,
            src.height,
            err,
            xml=opt.xml,
            camera=cam,
            notes=notes,
            stamp=src.stamp,
            solver=sn,
            frame=fr,
            channels=channels,
        )
    elif fmt == "ros":
        sn = solver_need(src.model, m, src.width, src.height)
        name = opt.camera_name or src.lens.ros_camera_name()
        text = ros_text(
            m,
            src.width,
            src.height,
            err,
            camera_name=name,
            camera=cam,
            notes=notes,
            stamp=src.stamp,
            solver=sn,
            frame=fr,
        )
    else:  # mrcal's unproject iterates to convergence: no solver statement
        text = mrcal_text(m, src.width, src.height, err, camera=cam, notes=notes, stamp=src.stamp, frame=fr)
    return Export(fmt, text.encode(), err, m, (cam.statement, *f.measured, *channel_lines), f.warnings, sn)


def _opencv_channels(src: ExportSource, green: OpenCVModel) -> tuple[OpenCVChannel, ...]:
    """Red's and blue's coefficients when the source has TCA fields (ValueError naming the format)."""
    if src.colour is None or src.colour.tca is None:
        return ()
    problem = src.colour.size_problem(src.width, src.height)
    if problem is not None:
        raise ValueError(f"opencv: {problem}")
    try:
        return opencv_channels(green, src.colour.tca, src.width, src.height)
    except ValueError as exc:
        raise ValueError(f"opencv: a colour channel: {exc}") from None


def _write_fisheye(fmt: str, src: ExportSource, opt: ExportOptions) -> Export:
    f = _fit_fisheye_export(fmt, src, opt)
    m, err, cam, fr, notes = f.model, f.error, f.cam, f.frame, f.notes(src)
    assert isinstance(m, OpenCVFisheyeModel)
    sn = solver_need(src.model, m, src.width, src.height)
    if fmt == "opencv-fisheye":
        text = opencv_text(
            m, src.width, src.height, err, xml=opt.xml, camera=cam, notes=notes, stamp=src.stamp, solver=sn, frame=fr
        )
    else:
        name = opt.camera_name or src.lens.ros_camera_name()
        text = ros_text(
            m,
            src.width,
            src.height,
            err,
            camera_name=name,
            camera=cam,
            notes=notes,
            stamp=src.stamp,
            solver=sn,
            frame=fr,
        )
    warnings = f.warnings + ((ROS_EQUIDISTANT_READERS,) if fmt == "ros-equidistant" else ())
    return Export(fmt, text.encode(), err, m, (cam.statement, *f.measured), warnings, sn)


def _pinhole_or_fisheye(
    fmt: str, src: ExportSource, opt: ExportOptions, n: int, names: tuple[str, str], fisheye_coeffs: int = 4
) -> tuple[_Fitted, str]:
    """The pin-hole fit with ``n`` coefficients, or the fisheye fit when it is tried and closer: ``(fit, why)``
    (:func:`_pinhole_or_fisheye_tried` without the fisheye fit)."""
    chosen, why, _ = _pinhole_or_fisheye_tried(fmt, src, opt, n, names, fisheye_coeffs)
    return chosen, why


def _pinhole_or_fisheye_tried(
    fmt: str, src: ExportSource, opt: ExportOptions, n: int, names: tuple[str, str], fisheye_coeffs: int = 4
) -> tuple[_Fitted, str, _Fitted | None]:
    """The pin-hole fit with ``n`` coefficients, or the fisheye fit when it is tried and closer:
    ``(fit, why, the fisheye fit if it was tried)``.

    For consumers that invert either model to convergence (or whose figures are the projection's):
    the fisheye model is fitted too exactly when :data:`AUTO` would fit it (:func:`_fisheye_reason`:
    a wide-angle calibration, or a pin-hole fit less exact than the calibration), and the one with
    the smaller max conversion error modulo homography is kept. ``names``: the format's names of the
    two models, for the statement. A lens the pin-hole family cannot hold (a pole or fold,
    :mod:`pipeline.exports.pole_free`) is written with the fisheye model, saying why.
    ``fisheye_coeffs``: 4 (``k1..k4``) or 2 (``k1 k2``, the LCP's).
    """
    try:
        pin = _fit_pinhole(fmt, src, opt, n, hint=False)
    except ValueError as exc:
        try:
            fe = _fit_fisheye_export(fmt, src, opt, fisheye_coeffs)
        except ValueError:
            raise exc from None
        return fe, f"{names[1]}: {names[0]} cannot hold this lens ({str(exc).split('; ')[0]})", fe
    e = pin.error
    reason = _fisheye_reason(src, e, e.max_mod_h_px)
    if reason is None:
        limit, what = _auto_limit(src)
        return (
            pin,
            (
                f"{names[0]}: its conversion error (RMS {e.rms_mod_h_px:.4f} px, max {e.max_mod_h_px:.4f} px modulo "
                f"homography) is within {what} ({limit:.4f} px), {names[1]} not tried"
            ),
            None,
        )
    fe = _fit_fisheye_export(fmt, src, opt, fisheye_coeffs)
    chosen = fe if fe.error.max_mod_h_px < e.max_mod_h_px else pin
    why = (
        f"{names[1] if chosen is fe else names[0]}, the closer in max ({reason}): {names[0]} RMS "
        f"{e.rms_mod_h_px:.4f} / max {e.max_mod_h_px:.4f} px, {names[1]} RMS {fe.error.rms_mod_h_px:.4f} / "
        f"max {fe.error.max_mod_h_px:.4f} px modulo homography"
    )
    return chosen, why, fe


COLMAP_PINHOLE_COEFFS = 8
"""COLMAP's FULL_OPENCV holds OpenCV's 8 rational coefficients (no thin prism)."""


def _write_chosen_family(
    fmt: str, src: ExportSource, opt: ExportOptions, n: int, names: tuple[str, str], text_of: Callable[..., str]
) -> Export:
    """The file of a format that holds a pin-hole fit with ``n`` coefficients or the fisheye fit, as
    :func:`_pinhole_or_fisheye` chooses, written by ``text_of`` (:func:`~pipeline.exports.colmap.colmap_text`,
    :func:`~pipeline.exports.kalibr.kalibr_text`, :func:`~pipeline.exports.metashape.metashape_text`)."""
    chosen, choice = _pinhole_or_fisheye(fmt, src, opt, n, names)
    return _write_fitted(fmt, src, chosen, choice, text_of)


def _write_fitted(fmt: str, src: ExportSource, chosen: _Fitted, choice: str, text_of: Callable[..., str]) -> Export:
    """The file of one fit, written by ``text_of`` with the statement every format makes (``choice``: the
    model and why)."""
    text = text_of(
        chosen.model,
        src.width,
        src.height,
        chosen.error,
        camera=chosen.cam,
        choice=f"model {choice}",
        notes=chosen.notes(src),
        stamp=src.stamp,
        frame=chosen.frame,
    )
    notes = (f"{fmt}: {choice}", chosen.cam.statement, *chosen.measured)
    return Export(fmt, text.encode(), chosen.error, chosen.model, notes, chosen.warnings)


def _write_colmap(src: ExportSource, opt: ExportOptions) -> Export:
    """COLMAP ``cameras.txt``: OPENCV (the OpenCV 4-coefficient fit, ``k1 k2 p1 p2``) when it is as exact
    as the calibration (:func:`_fisheye_reason` finds no reason to try more: not a wide-angle calibration,
    RMS, residual ``d`` and max within the limit of :func:`_auto_limit`); otherwise FULL_OPENCV (the
    8-coefficient fit) or OPENCV_FISHEYE (the fisheye fit), as :func:`_pinhole_or_fisheye` chooses, or,
    when the fisheye was tried (and no measured camera matrix is held), THIN_PRISM_FISHEYE fitted from
    it (:func:`~pipeline.exports.fit.fit_thin_prism_fisheye`) if its max is below
    :data:`COLMAP_THIN_PRISM_MARGIN` times the choice's.
    COLMAP inverts every model iteratively to convergence (``cam_from_img``), so, unlike OpenCV's
    default point solvers, the conversion error is what it sees."""
    try:
        simple = _fit_pinhole("colmap", src, opt, RADTAN_COEFFS, hint=False)
    except ValueError:  # 4 coefficients cannot hold the lens without a fold: the richer models decide
        simple = None
    if simple is not None and _fisheye_reason(src, simple.error, simple.error.max_mod_h_px) is None:
        limit, what = _auto_limit(src)
        e = simple.error
        choice = (
            f"OPENCV (k1 k2 p1 p2): its conversion error (RMS {e.rms_mod_h_px:.4f} px, max {e.max_mod_h_px:.4f} px "
            f"modulo homography) is within {what} ({limit:.4f} px), FULL_OPENCV and OPENCV_FISHEYE not tried"
        )
        return _write_fitted("colmap", src, simple, choice, colmap_text)
    names = ("FULL_OPENCV", "OPENCV_FISHEYE")
    chosen, choice, fe = _pinhole_or_fisheye_tried("colmap", src, opt, COLMAP_PINHOLE_COEFFS, names)
    if fe is not None and fe.cam.camera is None and isinstance(fe.model, OpenCVFisheyeModel):
        prism = _fit_thin_prism("colmap", src, opt, fe)
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


def _fit_thin_prism(fmt: str, src: ExportSource, opt: ExportOptions, fe: _Fitted) -> _Fitted:
    """COLMAP's THIN_PRISM_FISHEYE fitted from the fisheye fit ``fe`` (no measured camera matrix), with what
    its file states."""
    assert isinstance(fe.model, OpenCVFisheyeModel)
    m, err = fit_thin_prism_fisheye(src.model, src.width, src.height, fe.model, edges=src.edges)
    fr = _frame_of(fmt, src, opt, m, m.camera_matrix, fe.cam.focal_px)
    warnings = _camera_warnings(src, opt) + conversion_warnings(fmt, src, err)
    return _Fitted(m, err, fe.cam, fe.measured, fr, tuple(warnings))


def _write_basalt(src: ExportSource, opt: ExportOptions) -> Export:
    """Basalt calibration JSON: ``kb4``, the fisheye fit (Basalt's Kannala-Brandt is OpenCV's fisheye)."""
    fitted = _fit_fisheye_export("basalt", src, opt)
    e = fitted.error
    choice = (
        f"kb4 (Basalt's Kannala-Brandt, OpenCV's fisheye fit): RMS {e.rms_mod_h_px:.4f} px, max "
        f"{e.max_mod_h_px:.4f} px modulo homography"
    )
    return _write_fitted("basalt", src, fitted, choice, basalt_text)


def _write_metashape(src: ExportSource, opt: ExportOptions) -> Export:
    """Agisoft Metashape calibration XML: a frame camera (the OpenCV 5-coefficient fit, Metashape's p1/p2
    swapped, ``K4 = 0``) or a fisheye camera (the fisheye fit, ``K1..K4``), as :func:`_pinhole_or_fisheye`
    chooses."""
    names = ("frame", "fisheye")
    return _write_chosen_family("metashape", src, opt, METASHAPE_PINHOLE_COEFFS, names, metashape_text)


def _write_kalibr(src: ExportSource, opt: ExportOptions) -> Export:
    """Kalibr camchain YAML: pinhole-radtan (the OpenCV 4-coefficient fit, ``k1 k2 p1 p2``) or
    pinhole-equi (the fisheye fit)."""
    names = ("pinhole-radtan", "pinhole-equi")
    return _write_chosen_family("kalibr", src, opt, RADTAN_COEFFS, names, kalibr_text)


def _write_lcp(src: ExportSource, opt: ExportOptions) -> Export:
    """Adobe lens profile (:mod:`pipeline.exports.lcp`): the PerspectiveModel (the OpenCV 5-coefficient
    fit) or the FisheyeModel (the fisheye fit with ``k1 k2``), whichever is closer, filed under the
    nominal focal length and ``opt.focus_distance_m``; added to ``opt.existing`` when it is a profile of
    the same lens. The camera matrix is the nominal one (a measured one is not used: the profile's
    ``FocalLengthX`` is a scale of its coefficients, the centre the fitted distortion centre)."""
    names = ("PerspectiveModel (k1 k2 k3, tangential k4 k5)", "FisheyeModel (k1 k2)")
    existing = _text(opt.existing, opt.existing_name) if opt.existing is not None else None
    # before the fit: a file of another lens is refused at once; a profile holds one model kind
    kind = None if existing is None else check_existing(existing, src.lens, opt.existing_name)
    plain = replace(src, intrinsics=None)
    if kind is None:
        chosen, choice = _pinhole_or_fisheye("lcp", plain, opt, LCP_PINHOLE_COEFFS, names, LCP_FISHEYE_COEFFS)
    else:
        fisheye = kind == "FisheyeModel"
        try:
            chosen = (
                _fit_fisheye_export("lcp", plain, opt, LCP_FISHEYE_COEFFS)
                if fisheye
                else _fit_pinhole("lcp", plain, opt, LCP_PINHOLE_COEFFS, hint=False)
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
        *_lens_notes(src),
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


def _write_lensfun(src: ExportSource, opt: ExportOptions) -> Export:
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
    existing = _text(opt.existing, opt.existing_name) if opt.existing is not None else None
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


def _corrected(fmt: str, src: ExportSource, opt: ExportOptions) -> Any:
    """The corrected image the options ask (ValueError naming the format)."""
    try:
        return corrected_frame(src.model, src.width, src.height, opt.frame)
    except ValueError as exc:
        raise ValueError(f"{fmt}: {exc}") from None


def _write_maps(fmt: str, src: ExportSource, opt: ExportOptions) -> Export:
    frame = _corrected(fmt, src, opt)
    fr = None if frame.is_identity and (frame.width, frame.height) == (src.width, src.height) else frame
    maps = maps_fmt.export_maps(src.model, src.width, src.height, frame=fr)
    exact = src.model if fr is None else _in_frame(src.model, fr)
    acc = maps_fmt.map_accuracy(exact, maps.map_x, maps.map_y)
    corners = maps_fmt.corners_ideal(src.model, src.width, src.height, fr)
    converted = RemapModel(
        map_x=maps.map_x,
        map_y=maps.map_y,
        corners_ideal=None if corners is None else tuple((float(x), float(y)) for x, y in corners),
    )
    err = conversion_error_in_frame(src.model, converted, src.width, src.height, edges=src.edges, frame=fr)
    note = (
        f"maps = harp undistort's (nodes every {maps.step} px, bicubic between); interpolation error against the "
        f"exact inverse at {acc.n_points} pixels: RMS {acc.rms_px:.2e} px, max {acc.max_px:.2e} px"
    )
    measured, why_not = measured_camera(src)
    k_note = (
        (f"the corrected image is the measured camera's ideal image: {measured.statement}",)
        if measured is not None
        else ()
    )
    notes = (*src.stamp, note, f"{frame.describe()} ({opt.frame.describe()})", *k_note, *_lens_notes(src))
    data = (
        maps_fmt.maps_npz_bytes(maps, acc, notes, corners, fr, (src.width, src.height))
        if fmt == "maps"
        else maps_fmt.stmap_exr_bytes(maps, notes, corners, (src.width, src.height))
    )
    return Export(fmt, data, err, converted, (note, *k_note), tuple(why_not + conversion_warnings(fmt, src, err)))


def _in_frame(model: DistortionModel, frame: Any) -> DistortionModel:
    """``model`` with its corrected points in ``frame``'s pixels."""
    a = frame.matrix
    rows = tuple((float(r[0]), float(r[1]), float(r[2])) for r in a)
    return HomographyModel(base=model, homography=rows)


def _write_stmap_redistort(src: ExportSource, opt: ExportOptions) -> Export:
    fmt = "stmap-redistort"
    frame = _corrected(fmt, src, opt)
    qx, qy = maps_fmt.redistort_map(src.model, src.width, src.height, frame)
    converted = CorrectionMapModel(map_x=np.nan_to_num(qx, nan=-1.0), map_y=np.nan_to_num(qy, nan=-1.0))
    err = conversion_error_in_frame(
        src.model, converted, src.width, src.height, edges=src.edges, frame=frame, whole_photo=True
    )
    note = (
        f"the redistort STMap of the corrected image {frame.width}x{frame.height} ({opt.frame.describe()}): "
        "apply it to a render of that image to put it back into the lens' distortion"
    )
    notes = (*src.stamp, note, frame.describe(), *_lens_notes(src))
    data = maps_fmt.stmap_redistort_exr_bytes(qx, qy, (frame.width, frame.height), notes)
    return Export(fmt, data, err, converted, (note,), tuple(conversion_warnings(fmt, src, err)))


def harp_model_doc(src: ExportSource) -> dict[str, Any]:
    """The model-file record of a source (the layout of :mod:`pipeline.model_file`)."""
    return {
        "format": HARP_FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        **({"stamp": list(src.stamp)} if src.stamp else {}),
        "model": src.model.to_dict(),
        "image": {"width": int(src.width), "height": int(src.height)},
        "merit": dict(src.merit),
        "provenance": dict(src.provenance),
        **({"intrinsics": src.intrinsics.to_dict()} if src.intrinsics is not None else {}),
    }


def _write_json(src: ExportSource, opt: ExportOptions) -> Export:
    return Export("json", (json.dumps(harp_model_doc(src), indent=2, default=json_default) + "\n").encode())


def _write_harp(src: ExportSource, opt: ExportOptions) -> Export:
    text = model_file_text(
        src.model,
        width=src.width,
        height=src.height,
        merit=dict(src.merit),
        provenance=dict(src.provenance),
        intrinsics=src.intrinsics,
    )
    head = hash_comments(src.stamp)
    return Export("harp", (head + text).encode())


AUTO = "auto"
"""The name :func:`write_export` takes for "OpenCV, pin-hole or fisheye, whichever is closer"."""

AUTO_BAR_PX = 0.01
"""Without a holdout ``d``, the RMS (modulo homography) within which :data:`AUTO` takes the
pin-hole export without trying the fisheye one (the station's precision bar)."""

AUTO_MAX_FACTOR = 5.0
"""... and its max must be within this many times that RMS limit (issue 10's targets for the
default OpenCV export: 0.01 px RMS, 0.05 px max)."""


def consumer_max_px(ex: Export) -> float:
    """The max error (px) a consumer of ``ex`` sees, judged with its own default solver: the worst of
    the closed-form maps (the conversion error, modulo homography) and the default point solver."""
    assert ex.error is not None
    worst = ex.error.max_mod_h_px
    if ex.solver is not None:
        worst = max(worst, ex.solver.consumer_max_px)
    return float(worst)


def _auto_limit(src: ExportSource) -> tuple[float, str]:
    """The limit a pin-hole export is held to before the fisheye model is tried, and what it is."""
    if src.holdout_d is not None and math.isfinite(src.holdout_d):
        return float(src.holdout_d), "the holdout d"
    return AUTO_BAR_PX, f"the {AUTO_BAR_PX:g} px bar"


def _fisheye_reason(src: ExportSource, err: ConversionError, pin_max: float) -> str | None:
    """Why the fisheye model is fitted too (None: the pin-hole export suffices).

    A wide-angle calibration, or a pin-hole export less exact than the calibration: RMS or
    residual ``d`` above the limit (:func:`_auto_limit`), or ``pin_max`` (its max as its consumer
    sees it) above :data:`AUTO_MAX_FACTOR` times the limit.
    """
    limit, _ = _auto_limit(src)
    worst = max(err.rms_mod_h_px, err.d_px if math.isfinite(err.d_px) else 0.0)
    if src.wide_angle:
        return "the calibration chose a wide-angle model"
    if worst <= limit and pin_max <= AUTO_MAX_FACTOR * limit:
        return None
    return f"the pin-hole is less exact than {limit:.4f} px RMS / {AUTO_MAX_FACTOR * limit:.4f} px max"


def _write_auto(src: ExportSource, opt: ExportOptions) -> Export:
    """OpenCV pin-hole (12 coefficients, or ``opt.coeffs``) or OpenCV fisheye, whichever its consumer finds closer.

    Each candidate is judged as its consumer uses it, with OpenCV's own default solver
    (:func:`consumer_max_px`: the closed-form maps and ``cv2.undistortPoints`` /
    ``cv2.fisheye.undistortPoints`` with their default criteria, :mod:`pipeline.exports.solvers`).
    The fisheye model is fitted too when :func:`_fisheye_reason` gives a reason: the calibration
    chose a wide-angle model (``src.wide_angle``), or the pin-hole is less exact than the
    calibration: its RMS or residual ``d`` exceeds the limit (the holdout ``d``, or
    :data:`AUTO_BAR_PX` without one) or its max so judged exceeds :data:`AUTO_MAX_FACTOR` times the
    limit; the export is then the one with the smaller max so judged. The file states what its
    points need (:class:`SolverNeed`).
    """
    pin = _write_pinhole("opencv", src, opt, (5, 8, 12, 14), 12, hint=False)
    assert pin.error is not None and pin.solver is not None
    n = _coeffs("opencv", opt, (5, 8, 12, 14), 12)
    e = pin.error
    pin_max = consumer_max_px(pin)
    reason = _fisheye_reason(src, e, pin_max)
    if reason is None:
        limit, what = _auto_limit(src)
        why = (
            f"auto: opencv (pin-hole, {n} coefficients): its conversion error (RMS {e.rms_mod_h_px:.4f} px, "
            f"max {pin_max:.4f} px modulo homography, maps and cv2.undistortPoints' default criteria) is within "
            f"{what} ({limit:.4f} px), fisheye not tried"
        )
        return replace(pin, notes=(why, *pin.notes))
    fe = _write_fisheye("opencv-fisheye", src, opt)
    assert fe.error is not None and fe.solver is not None
    fe_max = consumer_max_px(fe)
    figures = (
        f"as their consumers see them, with OpenCV's default point solvers: pin-hole ({n}) RMS "
        f"{pin.error.rms_mod_h_px:.4f} / max {pin_max:.4f} px (cv2.undistortPoints' default alone: "
        f"{pin.solver.consumer_max_px:.4f} px), fisheye RMS {fe.error.rms_mod_h_px:.4f} / max {fe_max:.4f} px "
        "modulo homography"
    )
    if fe_max < pin_max:
        return replace(fe, notes=(f"auto: opencv-fisheye ({reason}; {figures})", *fe.notes))
    return replace(pin, notes=(f"auto: opencv (pin-hole) ({reason}; {figures})", *pin.notes))


# ------------------------------------------------------------------ readers
def _read_harp(data: bytes, req: ReadRequest) -> Correction:
    mf = parse_model_text(_text(data, req.name), req.name)
    return Correction(mf.model, (mf.width, mf.height), f"harp:{mf.model.name}")


def _read_opencv(data: bytes, req: ReadRequest) -> Correction:
    m, size = read_opencv_text(_text(data, req.name), req.name)
    return Correction(m, size, "opencv-fisheye" if m.name == "opencv_fisheye" else "opencv")


def _read_ros(data: bytes, req: ReadRequest) -> Correction:
    m, size = read_ros_text(_text(data, req.name), req.name)
    return Correction(m, size, "ros-equidistant" if m.name == "opencv_fisheye" else "ros")


def _read_lensfun(data: bytes, req: ReadRequest) -> Correction:
    m = read_lensfun_text(_text(data, req.name), req.width, req.height, req.name, req.focal, req.lens_name)
    return Correction(m, None, f"lensfun:{m.kind}")


def _read_mrcal(data: bytes, req: ReadRequest) -> Correction:
    m, size = read_mrcal_text(_text(data, req.name), req.name)
    return Correction(m, size, "mrcal")


def _read_colmap(data: bytes, req: ReadRequest) -> Correction:
    m, size, model = read_colmap_text(_text(data, req.name), req.name, (req.width, req.height))
    return Correction(m, size, f"colmap:{model}")


def _read_kalibr(data: bytes, req: ReadRequest) -> Correction:
    m, size, model = read_kalibr_text(_text(data, req.name), req.name, (req.width, req.height))
    return Correction(m, size, f"kalibr:{model}")


def _read_lcp(data: bytes, req: ReadRequest) -> Correction:
    m, entry = read_lcp_text(_text(data, req.name), req.name, req.width, req.height, req.focal)
    return Correction(m, None, "lcp:" + ("FisheyeModel" if entry.fisheye else "PerspectiveModel"))


def _read_basalt(data: bytes, req: ReadRequest) -> Correction:
    m, size, kind = read_basalt_text(_text(data, req.name), req.name, (req.width, req.height))
    return Correction(m, size, f"basalt:{kind}")


def _read_metashape(data: bytes, req: ReadRequest) -> Correction:
    m, size, proj = read_metashape_text(_text(data, req.name), req.name)
    return Correction(m, size, f"metashape:{proj}")


def _read_maps(data: bytes, req: ReadRequest) -> Correction:
    m = maps_fmt.read_maps_npz(data, req.name)
    return Correction(m, maps_fmt.maps_source_size(data) or (m.width, m.height), "maps")


def _read_stmap(data: bytes, req: ReadRequest) -> Correction:
    m = maps_fmt.read_stmap_exr(data, req.name, (req.width, req.height))
    if isinstance(m, CorrectionMapModel):
        return Correction(m, (m.map_x.shape[1], m.map_x.shape[0]), "stmap-redistort")
    return Correction(m, None, "stmap")


def _sniff_harp(d: bytes) -> bool:
    return HARP_FORMAT_NAME.encode() in d.lstrip()[:4096]


def _sniff_lensfun(d: bytes) -> bool:
    return b"<lensdatabase" in d.lstrip()[:4096]


def _sniff_opencv(d: bytes) -> bool:
    return b"opencv-matrix" in d or b"<opencv_storage" in d.lstrip()[:4096]


def _sniff_ros(d: bytes) -> bool:
    return b"camera_matrix" in d and b"distortion_coefficients" in d and b"opencv-matrix" not in d


def _never(d: bytes) -> bool:
    return False  # harp JSON is read by the harp reader (JSON is YAML)


# ------------------------------------------------------------------- table
FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat(
            "opencv",
            "OpenCV FileStorage YAML/XML, pin-hole model (12 coefficients: rational + thin prism)",
            ".yml",
            False,
            lambda s, o: _write_pinhole("opencv", s, o, (5, 8, 12, 14), 12),
            _read_opencv,
            _sniff_opencv,
            (5, 8, 12, 14),
            12,
        ),
        ExportFormat(
            "opencv-fisheye",
            "OpenCV FileStorage YAML/XML for cv::fisheye (Kannala-Brandt k1..k4)",
            ".yml",
            False,
            lambda s, o: _write_fisheye("opencv-fisheye", s, o),
            _read_opencv,
            _never,
        ),
        ExportFormat(
            "ros",
            "ROS camera_info YAML (rational_polynomial, 8 coefficients; plumb_bob with --coeffs 5)",
            ".yaml",
            False,
            lambda s, o: _write_pinhole("ros", s, o, (5, 8), 8),
            _read_ros,
            _sniff_ros,
            (5, 8),
            8,
        ),
        ExportFormat(
            "ros-equidistant",
            "ROS camera_info YAML, equidistant (fisheye k1..k4)",
            ".yaml",
            False,
            lambda s, o: _write_fisheye("ros-equidistant", s, o),
            _read_ros,
            _never,
        ),
        ExportFormat(
            "lensfun",
            "lensfun database XML (ptlens; adds to an existing database)",
            ".xml",
            False,
            _write_lensfun,
            _read_lensfun,
            _sniff_lensfun,
        ),
        ExportFormat(
            "mrcal",
            "mrcal .cameramodel (LENSMODEL_OPENCV12, or 8)",
            ".cameramodel",
            False,
            lambda s, o: _write_pinhole("mrcal", s, o, (8, 12), 12),
            _read_mrcal,
            sniff_mrcal,
            (8, 12),
            12,
        ),
        ExportFormat(
            "colmap",
            "COLMAP cameras.txt, OPENCV (k1 k2 p1 p2) when as exact as the calibration, else FULL_OPENCV (8 "
            "coefficients) or OPENCV_FISHEYE for a wide lens, whichever is closer",
            ".txt",
            False,
            _write_colmap,
            _read_colmap,
            sniff_colmap,
        ),
        ExportFormat(
            "kalibr",
            "Kalibr camchain YAML, pinhole-radtan (k1 k2 p1 p2) or pinhole-equi for a wide lens, whichever is closer",
            ".yaml",
            False,
            _write_kalibr,
            _read_kalibr,
            sniff_kalibr,
        ),
        ExportFormat(
            "lcp",
            "Adobe lens profile (.lcp, XMP): PerspectiveModel (OpenCV's 5 coefficients) or FisheyeModel for a wide "
            "lens, whichever is closer; adds its (focal, focus distance) to an existing profile of the lens",
            ".lcp",
            False,
            _write_lcp,
            _read_lcp,
            sniff_lcp,
        ),
        ExportFormat(
            "basalt",
            "Basalt calibration JSON, kb4 (Kannala-Brandt fx fy cx cy k1..k4; the IMU members placeholders)",
            ".json",
            False,
            _write_basalt,
            _read_basalt,
            sniff_basalt,
        ),
        ExportFormat(
            "metashape",
            "Agisoft Metashape calibration XML, frame (k1 k2 k3 p1 p2, p1/p2 swapped from OpenCV's) or fisheye "
            "(k1..k4) for a wide lens, whichever is closer",
            ".xml",
            False,
            _write_metashape,
            _read_metashape,
            sniff_metashape,
        ),
        ExportFormat(
            "maps",
            "float32 map_x/map_y for cv2.remap (.npz), exactly harp undistort's",
            ".npz",
            True,
            lambda s, o: _write_maps("maps", s, o),
            _read_maps,
            maps_fmt.sniff_npz,
        ),
        ExportFormat(
            "stmap",
            "STMap for Nuke/Natron (32-bit float OpenEXR), exactly harp undistort's",
            ".exr",
            True,
            lambda s, o: _write_maps("stmap", s, o),
            _read_stmap,
            maps_fmt.sniff_exr,
        ),
        ExportFormat(
            "stmap-redistort",
            "the redistort STMap of an STMap pair (32-bit float OpenEXR): a render of the corrected image back "
            "into the lens' distortion",
            ".exr",
            True,
            _write_stmap_redistort,
            _read_stmap,
            _never,
        ),
        ExportFormat("json", "harp model file as JSON", ".json", False, _write_json, _read_harp, _never),
        ExportFormat("harp", "harp model file (YAML)", ".yaml", False, _write_harp, _read_harp, _sniff_harp),
    )
}

SNIFF_ORDER = (
    "stmap",
    "maps",
    "harp",
    "lensfun",
    "lcp",
    "metashape",
    "basalt",
    "mrcal",
    "colmap",
    "kalibr",
    "opencv",
    "ros",
)
"""The order in which :func:`sniff_format` tries the formats (binary magic first)."""

RECOGNISED = (
    "harp model, OpenCV YAML/XML, ROS camera_info YAML, lensfun XML, mrcal .cameramodel, COLMAP cameras.txt, Kalibr camchain, "
    "Adobe LCP, Basalt calibration JSON, Metashape calibration XML, maps .npz or STMap .exr"
)


def get_format(name: str) -> ExportFormat:
    """The format called ``name``; ValueError listing the known ones."""
    if name not in FORMATS:
        raise ValueError(f"unknown export format {name!r}; known: {', '.join(FORMATS)}")
    return FORMATS[name]


def sniff_format(data: bytes) -> ExportFormat | None:
    """The format these bytes look like, or None."""
    for name in SNIFF_ORDER:
        if FORMATS[name].sniff(data):
            return FORMATS[name]
    return None


def write_export(name: str, source: ExportSource, options: ExportOptions | None = None) -> Export:
    """Write ``source`` in format ``name`` or :data:`AUTO` (ValueError on a bad option or an
    unconvertible model); the written format is ``Export.format``."""
    opt = options or ExportOptions()
    if name == AUTO:
        return _write_auto(source, opt)
    fmt = get_format(name)
    if opt.coeffs is not None and not fmt.coeffs:
        raise ValueError(f"--coeffs {opt.coeffs}: the {name} export has no choice of coefficients")
    return fmt.write(source, opt)


def read_correction(
    data: bytes, name: str, width: int, height: int, *, focal: float | None = None, lens_name: str | None = None
) -> Correction:
    """The correction of any supported file, for ``width`` x ``height`` images.

    Raises ValueError('<name>: <reason>') if the format is not recognised, the
    file is defective, or it is for another image size.
    """
    fmt = sniff_format(data)
    if fmt is None:
        raise ValueError(f"{name}: not a recognised correction ({RECOGNISED})")
    c = fmt.read(data, ReadRequest(name=name, width=width, height=height, focal=focal, lens_name=lens_name))
    if c.size is not None and tuple(c.size) != (width, height):
        what = "model" if c.kind.startswith("harp:") else "calibration"
        raise ValueError(f"{name}: {what} is for {c.size[0]}x{c.size[1]} images, the shots are {width}x{height}")
    return c
