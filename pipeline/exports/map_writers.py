"""The writers of the maps: ``cv2.remap`` maps (``.npz``), the STMap and the redistort STMap (OpenEXR).

Each holds exactly ``harp undistort``'s correction (:mod:`pipeline.exports.maps`) of the corrected
image the options ask (:mod:`pipeline.corrected_frame`), and states its interpolation and conversion
errors.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.corrected_frame import corrected_frame
from pipeline.exports import maps as maps_fmt
from pipeline.exports.conversion_error import conversion_error_in_frame
from pipeline.exports.measured_camera import measured_camera
from pipeline.exports.source import Export, ExportOptions, ExportSource, conversion_warnings, lens_notes
from pipeline.models.base import DistortionModel
from pipeline.models.homography import HomographyModel
from pipeline.models.remap_model import CorrectionMapModel, RemapModel


def _corrected(fmt: str, src: ExportSource, opt: ExportOptions) -> Any:
    """The corrected image the options ask (ValueError naming the format)."""
    try:
        return corrected_frame(src.model, src.width, src.height, opt.frame)
    except ValueError as exc:
        raise ValueError(f"{fmt}: {exc}") from None


def write_maps(fmt: str, src: ExportSource, opt: ExportOptions) -> Export:
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
    notes = (*src.stamp, note, f"{frame.describe()} ({opt.frame.describe()})", *k_note, *lens_notes(src))
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


def write_stmap_redistort(src: ExportSource, opt: ExportOptions) -> Export:
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
    notes = (*src.stamp, note, frame.describe(), *lens_notes(src))
    data = maps_fmt.stmap_redistort_exr_bytes(qx, qy, (frame.width, frame.height), notes)
    return Export(fmt, data, err, converted, (note,), tuple(conversion_warnings(fmt, src, err)))
