"""A pin-hole or fisheye fit of an export, with what its file states.

:class:`Fitted` holds the fitted model, its conversion error, the camera matrix it is in
(:func:`~pipeline.exports.measured_camera.export_camera`), the measured-camera lines, the corrected
image's ``R`` and ``newK`` and the warnings; :func:`fit_pinhole`, :func:`fit_fisheye_export` and
:func:`fit_thin_prism` make them, and :func:`pinhole_or_fisheye` chooses between the pin-hole and the
fisheye fit by the rule of :func:`~pipeline.exports.auto_rule.fisheye_reason`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pipeline.exports.auto_rule import auto_limit, fisheye_reason
from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.fit import fit_fisheye, fit_fisheye_camera, fit_opencv, fit_opencv_camera, fit_thin_prism_fisheye
from pipeline.exports.frame import FrameStatement, frame_statement
from pipeline.exports.lens import CameraMatrixChoice
from pipeline.exports.measured_camera import camera_warnings, export_camera, measured_lines
from pipeline.exports.solvers import SolverNeed
from pipeline.exports.source import ExportOptions, ExportSource, conversion_warnings, lens_notes
from pipeline.exports.statement import Statement
from pipeline.models.base import DistortionModel
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.thin_prism_fisheye_model import ThinPrismFisheyeModel


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


def _frame_of(
    fmt: str, src: ExportSource, opt: ExportOptions, m: DistortionModel, k: Any, focal: float
) -> FrameStatement:
    """The export's ``R`` and ``newK`` for the corrected image the options ask (ValueError naming the format)."""
    try:
        return frame_statement(src.model, m, k, src.width, src.height, opt.frame, focal)
    except ValueError as exc:
        raise ValueError(f"{fmt}: {exc}") from None


@dataclass(frozen=True)
class Fitted:
    """A pin-hole or fisheye fit with what its file states: camera choice, measured-camera lines, frame, warnings."""

    model: OpenCVModel | OpenCVFisheyeModel | ThinPrismFisheyeModel
    error: ConversionError
    cam: CameraMatrixChoice
    measured: tuple[str, ...]
    frame: FrameStatement
    warnings: tuple[str, ...]

    def notes(self, src: ExportSource) -> tuple[str, ...]:
        return (*lens_notes(src), *self.measured)

    def statement(self, src: ExportSource, choice: str | None = None, solver: SolverNeed | None = None) -> Statement:
        """What the file of this fit states (:class:`~pipeline.exports.statement.Statement`): its conversion
        error, ``src``'s stamp, its camera choice and frame, the lens and measured-camera notes, and ``choice``
        (the model and why) and ``solver`` where the format states them."""
        return Statement(self.error, src.stamp, self.cam, choice, solver, self.frame, self.notes(src))


def fit_pinhole(fmt: str, src: ExportSource, opt: ExportOptions, n: int, hint: bool = True) -> Fitted:
    cam = export_camera(src, opt)
    if cam.camera is not None:
        m, err = fit_opencv_camera(src.model, src.width, src.height, cam.camera, n_coeffs=n, edges=src.edges)
    else:
        m, err = fit_opencv(src.model, src.width, src.height, n_coeffs=n, focal=cam.focal_px, edges=src.edges)
    warnings = camera_warnings(src, opt) + conversion_warnings(fmt, src, err)
    if warnings and hint and cam.camera is None:
        warnings += _fisheye_hint(fmt, src, err, cam.focal_px if cam.kind != "placeholder" else None)
    measured = tuple(measured_lines(src, cam, m))
    fr = _frame_of(fmt, src, opt, m, m.camera_matrix, cam.focal_px)
    return Fitted(m, err, cam, measured, fr, tuple(warnings))


def fit_fisheye_export(fmt: str, src: ExportSource, opt: ExportOptions, n_coeffs: int = 4) -> Fitted:
    cam = export_camera(src, opt)
    focal = None if cam.kind == "placeholder" else cam.focal_px
    if cam.camera is not None and n_coeffs == 4:
        m, err = fit_fisheye_camera(src.model, src.width, src.height, cam.camera, edges=src.edges)
    else:
        m, err = fit_fisheye(src.model, src.width, src.height, focal=focal, edges=src.edges, n_coeffs=n_coeffs)
    fr = _frame_of(fmt, src, opt, m, m.camera_matrix, cam.focal_px)
    if focal is None:
        cam = CameraMatrixChoice(m.fx, "placeholder", "fitted with the fisheye coefficients, not measured")
    measured = tuple(measured_lines(src, cam, m))
    warnings = camera_warnings(src, opt) + conversion_warnings(fmt, src, err)
    return Fitted(m, err, cam, measured, fr, tuple(warnings))


def fit_thin_prism(fmt: str, src: ExportSource, opt: ExportOptions, fe: Fitted) -> Fitted:
    """COLMAP's THIN_PRISM_FISHEYE fitted from the fisheye fit ``fe`` (no measured camera matrix), with what
    its file states."""
    assert isinstance(fe.model, OpenCVFisheyeModel)
    m, err = fit_thin_prism_fisheye(src.model, src.width, src.height, fe.model, edges=src.edges)
    fr = _frame_of(fmt, src, opt, m, m.camera_matrix, fe.cam.focal_px)
    warnings = camera_warnings(src, opt) + conversion_warnings(fmt, src, err)
    return Fitted(m, err, fe.cam, fe.measured, fr, tuple(warnings))


def pinhole_or_fisheye(
    fmt: str, src: ExportSource, opt: ExportOptions, n: int, names: tuple[str, str], fisheye_coeffs: int = 4
) -> tuple[Fitted, str]:
    """The pin-hole fit with ``n`` coefficients, or the fisheye fit when it is tried and closer: ``(fit, why)``
    (:func:`pinhole_or_fisheye_tried` without the fisheye fit)."""
    chosen, why, _ = pinhole_or_fisheye_tried(fmt, src, opt, n, names, fisheye_coeffs)
    return chosen, why


def pinhole_or_fisheye_tried(
    fmt: str, src: ExportSource, opt: ExportOptions, n: int, names: tuple[str, str], fisheye_coeffs: int = 4
) -> tuple[Fitted, str, Fitted | None]:
    """The pin-hole fit with ``n`` coefficients, or the fisheye fit when it is tried and closer:
    ``(fit, why, the fisheye fit if it was tried)``.

    For consumers that invert either model to convergence (or whose figures are the projection's):
    the fisheye model is fitted too exactly when :data:`AUTO` would fit it (:func:`fisheye_reason`:
    a wide-angle calibration, or a pin-hole fit less exact than the calibration), and the one with
    the smaller max conversion error modulo homography is kept. ``names``: the format's names of the
    two models, for the statement. A lens the pin-hole family cannot hold (a pole or fold,
    :mod:`pipeline.exports.pole_free`) is written with the fisheye model, saying why.
    ``fisheye_coeffs``: 4 (``k1..k4``) or 2 (``k1 k2``, the LCP's).
    """
    try:
        pin = fit_pinhole(fmt, src, opt, n, hint=False)
    except ValueError as exc:
        try:
            fe = fit_fisheye_export(fmt, src, opt, fisheye_coeffs)
        except ValueError:
            raise exc from None
        return fe, f"{names[1]}: {names[0]} cannot hold this lens ({str(exc).split('; ')[0]})", fe
    e = pin.error
    reason = fisheye_reason(src, e, e.max_mod_h_px)
    if reason is None:
        limit, what = auto_limit(src)
        return (
            pin,
            (
                f"{names[0]}: its conversion error (RMS {e.rms_mod_h_px:.4f} px, max {e.max_mod_h_px:.4f} px modulo "
                f"homography) is within {what} ({limit:.4f} px), {names[1]} not tried"
            ),
            None,
        )
    fe = fit_fisheye_export(fmt, src, opt, fisheye_coeffs)
    chosen = fe if fe.error.max_mod_h_px < e.max_mod_h_px else pin
    why = (
        f"{names[1] if chosen is fe else names[0]}, the closer in max ({reason}): {names[0]} RMS "
        f"{e.rms_mod_h_px:.4f} / max {e.max_mod_h_px:.4f} px, {names[1]} RMS {fe.error.rms_mod_h_px:.4f} / "
        f"max {fe.error.max_mod_h_px:.4f} px modulo homography"
    )
    return chosen, why, fe
