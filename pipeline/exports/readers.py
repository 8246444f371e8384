"""The readers and sniffers of the export formats: a file's bytes to the correction it holds.

Each ``read_*`` takes the bytes and a :class:`ReadRequest` (the file's name, the image size) and
gives the :class:`Correction` the file holds, by the format's own reader; each ``sniff_*`` says
whether bytes look like its format. :data:`pipeline.exports.registry.FORMATS` lists them.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.exports import maps as maps_fmt
from pipeline.exports.basalt import read_basalt_text
from pipeline.exports.colmap import read_colmap_text
from pipeline.exports.harp_file import HARP_FORMAT_NAME
from pipeline.exports.kalibr import read_kalibr_text
from pipeline.exports.lcp import read_lcp_text
from pipeline.exports.lensfun import read_lensfun_text
from pipeline.exports.metashape import read_metashape_text
from pipeline.exports.mrcal import read_mrcal_text
from pipeline.exports.opencv import read_opencv_text
from pipeline.exports.ros import read_ros_text
from pipeline.model_file import parse_model_text
from pipeline.models.base import DistortionModel
from pipeline.models.remap_model import CorrectionMapModel


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


def decoded_text(data: bytes, name: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{name}: cannot read correction file (UnicodeDecodeError)") from None


def read_harp(data: bytes, req: ReadRequest) -> Correction:
    mf = parse_model_text(decoded_text(data, req.name), req.name)
    return Correction(mf.model, (mf.width, mf.height), f"harp:{mf.model.name}")


def read_opencv(data: bytes, req: ReadRequest) -> Correction:
    m, size = read_opencv_text(decoded_text(data, req.name), req.name)
    return Correction(m, size, "opencv-fisheye" if m.name == "opencv_fisheye" else "opencv")


def read_ros(data: bytes, req: ReadRequest) -> Correction:
    m, size = read_ros_text(decoded_text(data, req.name), req.name)
    return Correction(m, size, "ros-equidistant" if m.name == "opencv_fisheye" else "ros")


def read_lensfun(data: bytes, req: ReadRequest) -> Correction:
    m = read_lensfun_text(decoded_text(data, req.name), req.width, req.height, req.name, req.focal, req.lens_name)
    return Correction(m, None, f"lensfun:{m.kind}")


def read_mrcal(data: bytes, req: ReadRequest) -> Correction:
    m, size = read_mrcal_text(decoded_text(data, req.name), req.name)
    return Correction(m, size, "mrcal")


def read_colmap(data: bytes, req: ReadRequest) -> Correction:
    m, size, model = read_colmap_text(decoded_text(data, req.name), req.name, (req.width, req.height))
    return Correction(m, size, f"colmap:{model}")


def read_kalibr(data: bytes, req: ReadRequest) -> Correction:
    m, size, model = read_kalibr_text(decoded_text(data, req.name), req.name, (req.width, req.height))
    return Correction(m, size, f"kalibr:{model}")


def read_lcp(data: bytes, req: ReadRequest) -> Correction:
    m, entry = read_lcp_text(decoded_text(data, req.name), req.name, req.width, req.height, req.focal)
    return Correction(m, None, "lcp:" + ("FisheyeModel" if entry.fisheye else "PerspectiveModel"))


def read_basalt(data: bytes, req: ReadRequest) -> Correction:
    m, size, kind = read_basalt_text(decoded_text(data, req.name), req.name, (req.width, req.height))
    return Correction(m, size, f"basalt:{kind}")


def read_metashape(data: bytes, req: ReadRequest) -> Correction:
    m, size, proj = read_metashape_text(decoded_text(data, req.name), req.name)
    return Correction(m, size, f"metashape:{proj}")


def read_maps(data: bytes, req: ReadRequest) -> Correction:
    m = maps_fmt.read_maps_npz(data, req.name)
    return Correction(m, maps_fmt.maps_source_size(data) or (m.width, m.height), "maps")


def read_stmap(data: bytes, req: ReadRequest) -> Correction:
    m = maps_fmt.read_stmap_exr(data, req.name, (req.width, req.height))
    if isinstance(m, CorrectionMapModel):
        return Correction(m, (m.map_x.shape[1], m.map_x.shape[0]), "stmap-redistort")
    return Correction(m, None, "stmap")


def sniff_harp(d: bytes) -> bool:
    return HARP_FORMAT_NAME.encode() in d.lstrip()[:4096]


def sniff_lensfun(d: bytes) -> bool:
    return b"<lensdatabase" in d.lstrip()[:4096]


def sniff_opencv(d: bytes) -> bool:
    return b"opencv-matrix" in d or b"<opencv_storage" in d.lstrip()[:4096]


def sniff_ros(d: bytes) -> bool:
    return b"camera_matrix" in d and b"distortion_coefficients" in d and b"opencv-matrix" not in d


def never(d: bytes) -> bool:
    return False  # harp JSON is read by the harp reader (JSON is YAML)
