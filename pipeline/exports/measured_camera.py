"""The camera matrix an export uses, the measured one (``harp intrinsics``) when it fits the source.

:func:`measured_camera` takes the source's measured camera matrix when it is for its image size and
its distortion; :func:`export_camera` is the camera matrix a pin-hole or fisheye export is fitted
with (the measured one, else the nominal or placeholder of :func:`~pipeline.exports.lens.camera_matrix_choice`);
:func:`measured_lines` and :func:`camera_warnings` are what the export says of it.
"""

from __future__ import annotations

from pipeline.exports.fit import frame_error
from pipeline.exports.lens import CameraMatrixChoice, camera_matrix_choice
from pipeline.exports.source import ExportOptions, ExportSource
from pipeline.intrinsics import distortion_digest
from pipeline.models.base import DistortionModel


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


def export_camera(src: ExportSource, opt: ExportOptions) -> CameraMatrixChoice:
    if opt.focal_px is None:
        measured, _ = measured_camera(src)
        if measured is not None:
            return measured
    return camera_matrix_choice(src.lens, src.width, src.height, opt.focal_px)


def measured_lines(src: ExportSource, cam: CameraMatrixChoice, converted: DistortionModel) -> list[str]:
    """With a measured camera matrix, the conversion error in the camera's own frame."""
    if cam.camera is None:
        return []
    rms, mx = frame_error(src.model, converted, src.width, src.height)
    return [
        f"distortion fitted with the measured camera matrix fixed, in its frame (no homography): "
        f"RMS {rms:.4f} px, max {mx:.4f} px from the harp correction"
    ]


def camera_warnings(src: ExportSource, opt: ExportOptions) -> list[str]:
    if opt.focal_px is not None and src.intrinsics is not None:
        return ["--focal-px given: the measured camera matrix is not used"]
    return measured_camera(src)[1]
