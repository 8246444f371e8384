"""What an export is made from and what it gives, and the lines every writer says of its source.

:class:`ExportSource` (the harp correction, its image size, the lens, the holdout figure, the fitting
shots' edges), the user's :class:`ExportOptions` and the written :class:`Export` (bytes, conversion
error, notes and warnings) are what every writer of :data:`pipeline.exports.registry.FORMATS` takes
and gives; :func:`conversion_warnings` and :func:`lens_notes` are what each of them says of the source.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.corrected_frame import FrameChoice
from pipeline.exports.colour import ColourCorrection
from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.lens import LensInfo
from pipeline.exports.solvers import SolverNeed
from pipeline.intrinsics import Intrinsics
from pipeline.models.base import DistortionModel

Array = npt.NDArray[np.float64]


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


def lens_notes(src: ExportSource) -> tuple[str, ...]:
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
