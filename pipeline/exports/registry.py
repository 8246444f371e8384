"""The export formats of a harp correction, each with ``write``, ``read`` and ``sniff``.

One table, :data:`FORMATS`, names every format harp station writes for other
software (and reads back, so that ``harp evaluate`` can measure any of them
on harp shots). Each :class:`ExportFormat` has

- ``write(source, options) -> Export``: the file's bytes from an
  :class:`~pipeline.exports.source.ExportSource` (the model, its image size, the lens configuration,
  the holdout figure and the fitting shots' edges), with the conversion error
  and any warning (e.g. the conversion error exceeds the model's own
  holdout ``d``) for the command to print (:mod:`pipeline.exports.opencv_writers`,
  :mod:`~pipeline.exports.family_writers`, :mod:`~pipeline.exports.lensfun_writer`,
  :mod:`~pipeline.exports.map_writers`, :mod:`~pipeline.exports.harp_file`);
- ``read(data, request) -> Correction``: the correction a file holds, as a
  :class:`~pipeline.models.base.DistortionModel` (:mod:`pipeline.exports.readers`);
- ``sniff(data) -> bool``: whether bytes look like this format.

:func:`write_export` writes any of them (or :data:`~pipeline.exports.auto_rule.AUTO`), and
:func:`read_correction` detects the format of any correction file and reads
it for an image size. Everything here works on bytes: the commands do the
file I/O.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pipeline.exports import maps as maps_fmt
from pipeline.exports.auto_rule import AUTO
from pipeline.exports.basalt import sniff_basalt
from pipeline.exports.colmap import sniff_colmap
from pipeline.exports.family_writers import write_basalt, write_colmap, write_kalibr, write_lcp, write_metashape
from pipeline.exports.harp_file import write_harp, write_json
from pipeline.exports.kalibr import sniff_kalibr
from pipeline.exports.lcp import sniff_lcp
from pipeline.exports.lensfun_writer import write_lensfun
from pipeline.exports.map_writers import write_maps, write_stmap_redistort
from pipeline.exports.metashape import sniff_metashape
from pipeline.exports.mrcal import sniff_mrcal
from pipeline.exports.opencv_writers import write_auto, write_fisheye, write_pinhole
from pipeline.exports.readers import (
    Correction,
    ReadRequest,
    never,
    read_basalt,
    read_colmap,
    read_harp,
    read_kalibr,
    read_lcp,
    read_lensfun,
    read_maps,
    read_metashape,
    read_mrcal,
    read_opencv,
    read_ros,
    read_stmap,
    sniff_harp,
    sniff_lensfun,
    sniff_opencv,
    sniff_ros,
)
from pipeline.exports.source import Export, ExportOptions, ExportSource
from pipeline.model_file import not_finite
from pipeline.models.remap_model import CorrectionMapModel, RemapModel


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


FORMATS: dict[str, ExportFormat] = {
    f.name: f
    for f in (
        ExportFormat(
            "opencv",
            "OpenCV FileStorage YAML/XML, pin-hole model (12 coefficients: rational + thin prism)",
            ".yml",
            False,
            lambda s, o: write_pinhole("opencv", s, o, (5, 8, 12, 14), 12),
            read_opencv,
            sniff_opencv,
            (5, 8, 12, 14),
            12,
        ),
        ExportFormat(
            "opencv-fisheye",
            "OpenCV FileStorage YAML/XML for cv::fisheye (Kannala-Brandt k1..k4)",
            ".yml",
            False,
            lambda s, o: write_fisheye("opencv-fisheye", s, o),
            read_opencv,
            never,
        ),
        ExportFormat(
            "ros",
            "ROS camera_info YAML (rational_polynomial, 8 coefficients; plumb_bob with --coeffs 5)",
            ".yaml",
            False,
            lambda s, o: write_pinhole("ros", s, o, (5, 8), 8),
            read_ros,
            sniff_ros,
            (5, 8),
            8,
        ),
        ExportFormat(
            "ros-equidistant",
            "ROS camera_info YAML, equidistant (fisheye k1..k4)",
            ".yaml",
            False,
            lambda s, o: write_fisheye("ros-equidistant", s, o),
            read_ros,
            never,
        ),
        ExportFormat(
            "lensfun",
            "lensfun database XML (ptlens; adds to an existing database)",
            ".xml",
            False,
            write_lensfun,
            read_lensfun,
            sniff_lensfun,
        ),
        ExportFormat(
            "mrcal",
            "mrcal .cameramodel (LENSMODEL_OPENCV12, or 8)",
            ".cameramodel",
            False,
            lambda s, o: write_pinhole("mrcal", s, o, (8, 12), 12),
            read_mrcal,
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
            write_colmap,
            read_colmap,
            sniff_colmap,
        ),
        ExportFormat(
            "kalibr",
            "Kalibr camchain YAML, pinhole-radtan (k1 k2 p1 p2) or pinhole-equi for a wide lens, whichever is closer",
            ".yaml",
            False,
            write_kalibr,
            read_kalibr,
            sniff_kalibr,
        ),
        ExportFormat(
            "lcp",
            "Adobe lens profile (.lcp, XMP): PerspectiveModel (OpenCV's 5 coefficients) or FisheyeModel for a wide "
            "lens, whichever is closer; adds its (focal, focus distance) to an existing profile of the lens",
            ".lcp",
            False,
            write_lcp,
            read_lcp,
            sniff_lcp,
        ),
        ExportFormat(
            "basalt",
            "Basalt calibration JSON, kb4 (Kannala-Brandt fx fy cx cy k1..k4; the IMU members placeholders)",
            ".json",
            False,
            write_basalt,
            read_basalt,
            sniff_basalt,
        ),
        ExportFormat(
            "metashape",
            "Agisoft Metashape calibration XML, frame (k1 k2 k3 p1 p2, p1/p2 swapped from OpenCV's) or fisheye "
            "(k1..k4) for a wide lens, whichever is closer",
            ".xml",
            False,
            write_metashape,
            read_metashape,
            sniff_metashape,
        ),
        ExportFormat(
            "maps",
            "float32 map_x/map_y for cv2.remap (.npz), exactly harp undistort's",
            ".npz",
            True,
            lambda s, o: write_maps("maps", s, o),
            read_maps,
            maps_fmt.sniff_npz,
        ),
        ExportFormat(
            "stmap",
            "STMap for Nuke/Natron (32-bit float OpenEXR), exactly harp undistort's",
            ".exr",
            True,
            lambda s, o: write_maps("stmap", s, o),
            read_stmap,
            maps_fmt.sniff_exr,
        ),
        ExportFormat(
            "stmap-redistort",
            "the redistort STMap of an STMap pair (32-bit float OpenEXR): a render of the corrected image back "
            "into the lens' distortion",
            ".exr",
            True,
            write_stmap_redistort,
            read_stmap,
            never,
        ),
        ExportFormat("json", "harp model file as JSON", ".json", False, write_json, read_harp, never),
        ExportFormat("harp", "harp model file (YAML)", ".yaml", False, write_harp, read_harp, sniff_harp),
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
        return write_auto(source, opt)
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
    try:
        c = fmt.read(data, ReadRequest(name=name, width=width, height=height, focal=focal, lens_name=lens_name))
    except ValueError as exc:  # every reader's line names the file
        text = " ".join(str(exc).split())
        if text.startswith(f"{name}:"):
            raise
        raise ValueError(f"{name}: {text}") from None
    if not isinstance(c.model, (RemapModel, CorrectionMapModel)):  # the maps check their own values
        bad = not_finite(c.model.to_dict())
        if bad is not None:
            raise ValueError(
                f"{name}: a parameter is {bad[1]} (the {c.model.name} model's {bad[0]} as read from this {fmt.name} "
                "file); every parameter must be a finite number"
            )
    if c.size is not None and tuple(c.size) != (width, height):
        what = "model" if c.kind.startswith("harp:") else "calibration"
        raise ValueError(f"{name}: {what} is for {c.size[0]}x{c.size[1]} images, the shots are {width}x{height}")
    return c
