"""What the configuration says about the optics, and the camera matrix it gives an export.

A harp measures the *shape* of the distortion field, not the focal length:
the camera matrix of an OpenCV / ROS / mrcal export is therefore either

- **nominal**: from the lens' nominal focal length (mm) and the pixel pitch
  (µm) of the images (or the sensor width in mm across the image width):
  :math:`f_x = f_y = f_{mm} / p_{mm}`, principal point = the fitted
  distortion centre. Good enough to start a 3-D calibration, not a
  measurement of it;
- **placeholder**: a scale (the image diagonal in pixels) the distortion
  coefficients are expressed in, chosen for the conversion. It must not be
  used for 3-D work (angles, triangulation); every export says so;
- **measured**: fx, fy, cx, cy measured from board views with the harp's
  distortion held fixed (:mod:`pipeline.intrinsics`, ``harp intrinsics``), with
  their standard deviations; every export that has a camera matrix then uses it
  (and the distortion is fitted in its frame), and says so.

References
----------
.. [1] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., Sect. 6.1
   (the camera matrix, focal length in pixels).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
"""Diagonal of the 35 mm frame (36 x 24 mm), the reference of a crop factor: 43.27 mm."""


@dataclass(frozen=True)
class LensInfo:
    """The lens, the camera body and the optics of a calibration; every field optional.

    Attributes
    ----------
    lens_maker, lens_model, lens_serial : str
        The lens (as the lens EXIF / the lensfun database name it).
    camera_maker, camera_model : str
        The camera body.
    mount : str
        Lens mount (lensfun's ``<mount>``, e.g. ``"Canon EF"``).
    crop_factor : float
        The camera's crop factor (35 mm diagonal / sensor diagonal).
    focal_mm : float
        Nominal focal length of the lens (at this zoom setting), mm.
    pixel_pitch_um : float
        Pixel pitch of the *images* (after any binning), µm.
    sensor_width_mm : float
        Width of the sensor area the image covers, mm (used when no pitch).
    focus : float
        Focus setting of the calibration (station units), recorded in comments.
    """

    lens_maker: str | None = None
    lens_model: str | None = None
    lens_serial: str | None = None
    camera_maker: str | None = None
    camera_model: str | None = None
    mount: str | None = None
    crop_factor: float | None = None
    focal_mm: float | None = None
    pixel_pitch_um: float | None = None
    sensor_width_mm: float | None = None
    focus: float | None = None

    def __post_init__(self) -> None:
        for name in ("crop_factor", "focal_mm", "pixel_pitch_um", "sensor_width_mm"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(float(v)) and float(v) > 0):
                raise ValueError(f"{name} must be a number > 0, got {v!r}")

    def with_overrides(self, **kw: Any) -> LensInfo:
        """A copy with the fields given (not None) replaced."""
        return replace(self, **{k: v for k, v in kw.items() if v is not None})

    def nominal_focal_px(self, width: int) -> float | None:
        """``f_mm / pitch_mm`` (or ``f_mm * width / sensor_width_mm``); None without the data."""
        if self.focal_mm is None:
            return None
        if self.pixel_pitch_um is not None:
            return float(self.focal_mm) / (float(self.pixel_pitch_um) * 1e-3)
        if self.sensor_width_mm is not None:
            return float(self.focal_mm) * int(width) / float(self.sensor_width_mm)
        return None

    def derived_crop_factor(self, width: int, height: int) -> float | None:
        r"""The crop factor the optics give for ``width`` x ``height`` images, or None without them.

        :math:`c = D_{35} / D`, :math:`D_{35} = \sqrt{36^2 + 24^2}` mm (the 35 mm
        frame's diagonal, :data:`FULL_FRAME_DIAGONAL_MM`), :math:`D` the diagonal
        of the sensor area the images cover: :math:`p\sqrt{W^2 + H^2}` from the
        pixel pitch :math:`p` (mm), or :math:`w_s\sqrt{W^2 + H^2}/W` from the
        sensor width :math:`w_s` across the image width.
        """
        diag_px = math.hypot(int(width), int(height))
        if self.pixel_pitch_um is not None:
            diag_mm = float(self.pixel_pitch_um) * 1e-3 * diag_px
        elif self.sensor_width_mm is not None:
            diag_mm = float(self.sensor_width_mm) * diag_px / int(width)
        else:
            return None
        return FULL_FRAME_DIAGONAL_MM / diag_mm

    @property
    def camera_body(self) -> str | None:
        """``"maker model"`` of the camera body, or None."""
        parts = [p for p in (self.camera_maker, self.camera_model) if p]
        return " ".join(parts) if parts else None

    @property
    def lens_name(self) -> str | None:
        """``"maker model"`` of the lens, or None."""
        parts = [p for p in (self.lens_maker, self.lens_model) if p]
        return " ".join(parts) if parts else None

    def ros_camera_name(self) -> str:
        """ROS ``camera_name`` from the camera body: lower case, ``[a-z0-9_]`` (``"camera"`` if none)."""
        body = self.camera_body
        if not body:
            return "camera"
        name = re.sub(r"[^a-z0-9]+", "_", body.lower()).strip("_")
        return name or "camera"


@dataclass(frozen=True)
class CameraMatrixChoice:
    """The focal length of an export's camera matrix and what it means.

    ``kind`` is ``"nominal"`` (from the configuration), ``"given"`` (set by the
    user in pixels), ``"placeholder"`` (a scale for the conversion) or
    ``"measured"`` (``camera``: fx, fy, cx, cy measured, ``sd`` their standard
    deviations, ``text`` the statement, :meth:`pipeline.intrinsics.Intrinsics.statement`).
    """

    focal_px: float
    kind: str
    source: str
    camera: tuple[float, float, float, float] | None = None
    sd: tuple[float, float, float, float] | None = None
    text: str | None = None

    @property
    def statement(self) -> str:
        """One line for the export's comments."""
        if self.text is not None:
            return self.text
        if self.kind == "placeholder":
            return (
                f"camera matrix: PLACEHOLDER scale fx = fy = {self.focal_px:.6g} px ({self.source}), chosen for the "
                "conversion; it is not a measured focal length and must not be used for 3-D work"
            )
        return f"camera matrix: {self.kind} fx = fy = {self.focal_px:.6g} px ({self.source}); principal point fitted"


def camera_matrix_choice(lens: LensInfo, width: int, height: int, focal_px: float | None = None) -> CameraMatrixChoice:
    """The focal of the camera matrix: given in pixels > nominal from the lens > placeholder (image diagonal)."""
    if focal_px is not None:
        if not (math.isfinite(focal_px) and focal_px > 0):
            raise ValueError(f"focal length must be > 0 px, got {focal_px}")
        return CameraMatrixChoice(float(focal_px), "given", "set on the command line")
    f = lens.nominal_focal_px(width)
    if f is not None:
        src = (
            f"nominal: {lens.focal_mm:g} mm / {lens.pixel_pitch_um:g} um pixel pitch"
            if lens.pixel_pitch_um is not None
            else f"nominal: {lens.focal_mm:g} mm, sensor width {lens.sensor_width_mm:g} mm over {width} px"
        )
        return CameraMatrixChoice(f, "nominal", src)
    return CameraMatrixChoice(float(np.hypot(width, height)), "placeholder", "the image diagonal")
