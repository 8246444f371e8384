"""The writers of the OpenCV-model files: OpenCV, ROS and mrcal (pin-hole), their fisheye, and ``auto``.

:func:`write_pinhole` writes the ``opencv``, ``ros`` and ``mrcal`` formats (OpenCV's pin-hole model
with the format's coefficients), :func:`write_fisheye` the ``opencv-fisheye`` and ``ros-equidistant``
ones (Kannala-Brandt), and :func:`write_auto` whichever of OpenCV's two its consumer finds closer.
"""

from __future__ import annotations

from dataclasses import replace

from pipeline.exports.auto_rule import auto_limit, consumer_max_px, fisheye_reason
from pipeline.exports.colour import OpenCVChannel, opencv_channels
from pipeline.exports.fitted import fit_fisheye_export, fit_pinhole
from pipeline.exports.mrcal import mrcal_text
from pipeline.exports.opencv import opencv_text
from pipeline.exports.ros import ROS_EQUIDISTANT_READERS, ros_text
from pipeline.exports.solvers import solver_need
from pipeline.exports.source import Export, ExportOptions, ExportSource
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel


def _coeffs(fmt: str, opt: ExportOptions, allowed: tuple[int, ...], default: int) -> int:
    n = default if opt.coeffs is None else int(opt.coeffs)
    if n not in allowed:
        raise ValueError(f"--coeffs {n}: the {fmt} export takes {', '.join(map(str, allowed))} coefficients")
    return n


def write_pinhole(
    fmt: str, src: ExportSource, opt: ExportOptions, allowed: tuple[int, ...], default: int, hint: bool = True
) -> Export:
    f = fit_pinhole(fmt, src, opt, _coeffs(fmt, opt, allowed, default), hint)
    m, err, cam = f.model, f.error, f.cam
    assert isinstance(m, OpenCVModel)
    sn = None
    channel_lines: tuple[str, ...] = ()
    if fmt == "opencv":
        sn = solver_need(src.model, m, src.width, src.height)
        channels = _opencv_channels(src, m)
        channel_lines = tuple(f"opencv: {c.line()}" for c in channels)
        text = opencv_text(m, src.width, src.height, f.statement(src, solver=sn), xml=opt.xml, channels=channels)
    elif fmt == "ros":
        sn = solver_need(src.model, m, src.width, src.height)
        name = opt.camera_name or src.lens.ros_camera_name()
        text = ros_text(m, src.width, src.height, f.statement(src, solver=sn), camera_name=name)
    else:  # mrcal's unproject iterates to convergence: no solver statement
        text = mrcal_text(m, src.width, src.height, f.statement(src))
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


def write_fisheye(fmt: str, src: ExportSource, opt: ExportOptions) -> Export:
    f = fit_fisheye_export(fmt, src, opt)
    m, err, cam = f.model, f.error, f.cam
    assert isinstance(m, OpenCVFisheyeModel)
    sn = solver_need(src.model, m, src.width, src.height)
    statement = f.statement(src, solver=sn)
    if fmt == "opencv-fisheye":
        text = opencv_text(m, src.width, src.height, statement, xml=opt.xml)
    else:
        name = opt.camera_name or src.lens.ros_camera_name()
        text = ros_text(m, src.width, src.height, statement, camera_name=name)
    warnings = f.warnings + ((ROS_EQUIDISTANT_READERS,) if fmt == "ros-equidistant" else ())
    return Export(fmt, text.encode(), err, m, (cam.statement, *f.measured), warnings, sn)


def write_auto(src: ExportSource, opt: ExportOptions) -> Export:
    """OpenCV pin-hole (12 coefficients, or ``opt.coeffs``) or OpenCV fisheye, whichever its consumer finds closer.

    Each candidate is judged as its consumer uses it, with OpenCV's own default solver
    (:func:`consumer_max_px`: the closed-form maps and ``cv2.undistortPoints`` /
    ``cv2.fisheye.undistortPoints`` with their default criteria, :mod:`pipeline.exports.solvers`).
    The fisheye model is fitted too when :func:`fisheye_reason` gives a reason: the calibration
    chose a wide-angle model (``src.wide_angle``), or the pin-hole is less exact than the
    calibration: its RMS or residual ``d`` exceeds the limit (the holdout ``d``, or
    :data:`AUTO_BAR_PX` without one) or its max so judged exceeds :data:`AUTO_MAX_FACTOR` times the
    limit; the export is then the one with the smaller max so judged. The file states what its
    points need (:class:`SolverNeed`).
    """
    pin = write_pinhole("opencv", src, opt, (5, 8, 12, 14), 12, hint=False)
    assert pin.error is not None and pin.solver is not None
    n = _coeffs("opencv", opt, (5, 8, 12, 14), 12)
    e = pin.error
    pin_max = consumer_max_px(pin)
    reason = fisheye_reason(src, e, pin_max)
    if reason is None:
        limit, what = auto_limit(src)
        why = (
            f"auto: opencv (pin-hole, {n} coefficients): its conversion error (RMS {e.rms_mod_h_px:.4f} px, "
            f"max {pin_max:.4f} px modulo homography, maps and cv2.undistortPoints' default criteria) is within "
            f"{what} ({limit:.4f} px), fisheye not tried"
        )
        return replace(pin, notes=(why, *pin.notes))
    fe = write_fisheye("opencv-fisheye", src, opt)
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
