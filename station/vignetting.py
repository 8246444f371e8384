"""Vignetting of harp shots read, measured and fitted with one-line errors (``harp vignetting``).

Each shot is read as a grey image (:func:`station.inputs.measure_file`, as ``harp measure``:
colour converted to luma), or, a camera RAW file (:func:`station.raw.is_raw_path`), as its first
green CFA plane at its own mosaic positions, black level subtracted (linear by construction, not
demosaiced), and its string edges measured; the lit sheet between the strings is
sampled away from every edge (:func:`pipeline.vignetting.backlit_samples`) and all shots are
fitted together with their turntable angles (:func:`pipeline.vignetting.fit_vignetting`: the
back-light turns with the harp, the lens's vignetting does not), the samples placed on the harp
through a distortion model file when one is given. The result: :func:`vignetting_document`
(what ``--out`` writes and ``--json`` prints), the flat-field image (:func:`flat_field_tiff`).

The images must be linear (a RAW conversion without tone curve, or a camera's linear output):
a gamma or tone curve bends the relative illumination. Every failure is an
:class:`~station.errors.InputError` naming the file or the option and what to do.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.cfa import cfa_planes, to_mosaic
from pipeline.edgeset import FitFailure
from pipeline.measure import measure_image
from pipeline.model_file import ModelFile, read_model_file
from pipeline.models.base import DistortionModel
from pipeline.resample import DEFAULT_T
from pipeline.tca import image_grid
from pipeline.vignetting import (
    BacklitSamples,
    LensfunVignetting,
    VignettingFit,
    backlit_samples,
    fit_vignetting,
    lensfun_pa,
    lensfun_radius,
)
from station.colour import read_document
from station.errors import InputError
from station.imageio import ImageReadError
from station.inputs import NO_STRINGS, measure_file
from station.raw import is_raw_path, read_raw

MAX_SATURATED_FRACTION = 0.01
"""A shot with more than this fraction of its pixels at the format's largest value is refused
(a clipped sheet reads as no vignetting)."""

FLAT_FIELD_DEPTHS = (32, 16)
"""``--flat-field-depth``: 32-bit float TIFF of :math:`V` (1 at the centre), or 16-bit TIFF of
:math:`65535\\,V / \\max V`."""


@dataclass(frozen=True)
class ShotSamples:
    """One shot: its path, turntable angle, edges measured and lit-sheet samples."""

    path: str
    angle_deg: float
    width: int
    height: int
    n_edges: int
    samples: BacklitSamples


def check_angles(paths: Sequence[str], angles: Sequence[float]) -> None:
    """InputError when the angles cannot serve: one per image, two or more, not all equal, finite."""
    if len(angles) != len(paths):
        raise InputError(
            f"--angles: {len(angles)} turntable angles for {len(paths)} images: give one angle (degrees) per image"
        )
    if len(paths) < 2:
        raise InputError("vignetting needs shots at two or more turntable angles (the back-light turns, the lens not)")
    if not all(np.isfinite(a) for a in angles):
        raise InputError("--angles: every angle must be a finite number of degrees")
    if len({float(a) % 360.0 for a in angles}) == 1:
        raise InputError(
            f"--angles: every shot is at {float(angles[0]):g} degrees: the back-light cannot be told from the "
            "vignetting; turn the harp between shots"
        )


def read_model(path: str | Path) -> ModelFile:
    """A distortion model file; InputError naming the file."""
    try:
        return read_model_file(path)
    except ValueError as exc:
        raise InputError(str(exc)) from None


def check_model_size(mf: ModelFile, width: int, height: int) -> None:
    """InputError when the model file is for another image size than the shots'."""
    if (mf.width, mf.height) != (width, height):
        raise InputError(f"{mf.path}: the model is for {mf.width}x{mf.height} images, the shots are {width}x{height}")


def _check_saturation(path: str, img: np.ndarray) -> None:
    if not np.issubdtype(img.dtype, np.integer):
        return
    top = np.iinfo(img.dtype).max
    frac = float(np.mean(img >= top))
    if frac > MAX_SATURATED_FRACTION:
        raise InputError(
            f"{path}: {100 * frac:.1f} % of the pixels are at {top} (saturated): the clipped sheet hides the "
            "vignetting; lower the exposure"
        )


def _raw_samples(path: str, t: int) -> tuple[int, int, int, BacklitSamples]:
    """A camera RAW shot's lit sheet (:func:`mosaic_samples`), its saturation checked."""
    try:
        raw = read_raw(path)
    except ImageReadError as exc:
        raise InputError(str(exc)) from None
    frac = float(np.mean(raw.mosaic >= raw.white_level))
    if frac > MAX_SATURATED_FRACTION:
        raise InputError(
            f"{path}: {100 * frac:.1f} % of the pixels are at the white level {raw.white_level:g} (saturated): "
            "the clipped sheet hides the vignetting; lower the exposure"
        )
    return mosaic_samples(raw.mosaic, raw.pattern, raw.black_level, t, path)


def mosaic_samples(
    mosaic: np.ndarray, pattern: str, black_level: float, t: int, path: str, measured: Any = None
) -> tuple[int, int, int, BacklitSamples]:
    """A raw mosaic's lit sheet on its first green plane: ``(width, height, edges, samples)``.

    The plane's pixels, ``black_level`` subtracted, at their own mosaic positions
    (:func:`pipeline.cfa.plane_to_mosaic`: nothing interpolated, nothing demosaiced); its edges
    measured on the plane (:func:`pipeline.cfa.measure_mosaic`'s scale) and brought to the mosaic.
    ``path`` names the shot in the InputError when no string is found; ``measured``: the plane's
    measurement when already made (:attr:`pipeline.cfa.MosaicMeasurement.planes` ``["G1"]``).
    """
    h, w = mosaic.shape
    plane = next(p for p in cfa_planes(mosaic, pattern) if p.name == "G1")
    m = measured
    if m is None:
        m = to_mosaic(measure_image(plane.image, t=max(2, int(t) // 2)), plane.offset, w, h)
    if m.n_lines == 0:
        raise InputError(f"{path}: {NO_STRINGS}")
    yy, xx = np.mgrid[0 : plane.image.shape[0], 0 : plane.image.shape[1]].astype(np.float64)
    positions = (2.0 * xx + plane.offset[0], 2.0 * yy + plane.offset[1])
    img = plane.image.astype(np.float64) - black_level
    s = backlit_samples(img, [ln.raw_points for ln in m.lines], positions=positions)
    return int(w), int(h), int(m.n_lines), s


def sample_shots(paths: Sequence[str], angles: Sequence[float], t: int = DEFAULT_T) -> list[ShotSamples]:
    """Read and measure every shot and sample its lit sheet (module docstring); InputError naming the file."""
    check_angles(paths, angles)
    shots: list[ShotSamples] = []
    for path, ang in zip(paths, angles):
        if is_raw_path(path):
            w, h, n, s = _raw_samples(path, t)
        else:
            img, m = measure_file(path, t)
            _check_saturation(path, img)
            s = backlit_samples(img, [ln.raw_points for ln in m.lines])
            w, h, n = int(m.width), int(m.height), int(m.n_lines)
        if len(s.value) == 0:
            raise InputError(f"{path}: no lit sheet found between the strings: is the back-light on?")
        shots.append(ShotSamples(str(path), float(ang), w, h, n, s))
    sizes = {(s.width, s.height) for s in shots}
    if len(sizes) > 1:
        listed = ", ".join(f"{w}x{h}" for w, h in sorted(sizes))
        raise InputError(f"the shots have different sizes ({listed}): give shots of one camera")
    return shots


def fit_shots(
    shots: Sequence[ShotSamples],
    model: DistortionModel | None = None,
    axis: tuple[float, float] | None = None,
) -> VignettingFit:
    """:func:`pipeline.vignetting.fit_vignetting` of the shots; its refusal as an InputError."""
    w, h = shots[0].width, shots[0].height
    f = fit_vignetting([s.samples for s in shots], [s.angle_deg for s in shots], w, h, axis=axis, lens=model)
    if isinstance(f, FitFailure):
        raise InputError(f.reason)
    return f


def landmarks(width: int, height: int) -> list[tuple[str, float, float]]:
    """The centre, the middles of the four edges and the four corners (pixel centres)."""
    x1, y1 = width - 1.0, height - 1.0
    cx, cy = x1 / 2.0, y1 / 2.0
    return [
        ("centre", cx, cy),
        ("left edge", 0.0, cy),
        ("right edge", x1, cy),
        ("top edge", cx, 0.0),
        ("bottom edge", cx, y1),
        ("top-left corner", 0.0, 0.0),
        ("top-right corner", x1, 0.0),
        ("bottom-left corner", 0.0, y1),
        ("bottom-right corner", x1, y1),
    ]


def backlight_unevenness(fit: VignettingFit, model: DistortionModel | None = None) -> float:
    """max/min - 1 of the fitted back-light over the image, the harp at angle 0."""
    g = image_grid(fit.width, fit.height, 8.0)
    u = g if model is None else np.asarray(model.undistort_points(g), np.float64)
    b = fit.backlight_factor(u - np.asarray(fit.axis))
    return float(b.max() / b.min() - 1.0)


def vignetting_document(
    fit: VignettingFit,
    pa: LensfunVignetting,
    shots: Sequence[ShotSamples],
    *,
    model_path: str | None = None,
    model: DistortionModel | None = None,
    lensfun_setting: tuple[float, float, float] | None = None,
) -> dict[str, Any]:
    """What ``harp vignetting --out`` writes and ``--json`` prints.

    ``lensfun_setting``: ``(focal mm, aperture, distance)`` of lensfun's ``<vignetting>`` element,
    written with the element's attributes when given.
    """
    marks = landmarks(fit.width, fit.height)
    xy = np.array([(x, y) for _, x, y in marks])
    v = fit.relative_illumination(xy)
    v_pa = pa.factor(lensfun_radius(xy, fit.width, fit.height))
    g = image_grid(fit.width, fit.height, 8.0)
    vg = fit.relative_illumination(g)
    e0 = fit.exposure[0]
    lensfun: dict[str, Any] = {
        "model": "pa",
        "k1": pa.k[0],
        "k2": pa.k[1],
        "k3": pa.k[2],
        "conversion_error": {"rms": pa.error_rms, "max": pa.error_max},
    }
    if lensfun_setting is not None:
        lensfun["element"] = pa.element_attributes(*lensfun_setting)
    return {
        "format": "harp-vignetting",
        "version": 1,
        "image_size": [fit.width, fit.height],
        "distortion_model": model_path,
        "images": [
            {
                "path": s.path,
                "angle_deg": s.angle_deg,
                "edges": s.n_edges,
                "samples": int(len(s.samples.value)),
                "exposure": float(np.exp(e - e0)),
            }
            for s, e in zip(shots, fit.exposure)
        ],
        "relative_illumination": {
            "points": [
                {"where": name, "x": x, "y": y, "fit": float(a), "lensfun_pa": float(b)}
                for (name, x, y), a, b in zip(marks, v, v_pa)
            ],
            "min": float(vg.min()),
            "max": float(vg.max()),
        },
        "backlight_unevenness": backlight_unevenness(fit, model),
        "residual_rms": fit.residual_rms,
        "lensfun": lensfun,
        "fit": fit.to_dict(),
    }


def flat_field_tiff(fit: VignettingFit, depth: int = 32) -> tuple[bytes, float]:
    """The flat-field image as TIFF bytes and the factor it holds :math:`V` with.

    ``depth`` 32: float32 :math:`V` (1 at the image centre; factor 1). 16: ``uint16``
    :math:`\\mathrm{round}(s V)` with :math:`s = 65535 / \\max V` (returned). Either way a shot
    divided by it (times the factor) is corrected.
    """
    import cv2

    v = fit.flat_field()
    if depth == 32:
        img, scale = v, 1.0
    elif depth == 16:
        scale = 65535.0 / float(v.max())
        img = np.clip(np.rint(v.astype(np.float64) * scale), 0, 65535).astype(np.uint16)
    else:
        raise ValueError(f"flat-field depth must be one of {FLAT_FIELD_DEPTHS}, got {depth}")
    ok, buf = cv2.imencode(".tiff", img)
    if not ok:
        raise InputError("cv2 could not encode the flat field as TIFF")
    return buf.tobytes(), scale


def vignetting_of(
    paths: Sequence[str],
    angles: Sequence[float],
    *,
    t: int = DEFAULT_T,
    model_path: str | None = None,
    axis: tuple[float, float] | None = None,
) -> tuple[list[ShotSamples], DistortionModel | None, VignettingFit, LensfunVignetting]:
    """Shots sampled, the model read (``model_path``), the fit and lensfun's ``pa``: InputError on any problem."""
    check_angles(paths, angles)
    mf = None if model_path is None else read_model(model_path)
    shots = sample_shots(paths, angles, t)
    if mf is not None:
        check_model_size(mf, shots[0].width, shots[0].height)
    model = None if mf is None else mf.model
    fit = fit_shots(shots, model, axis)
    return shots, model, fit, lensfun_pa(fit)


def read_vignetting_file(path, width: int, height: int) -> tuple[VignettingFit, float | None, float | None]:
    """The fit of a ``harp vignetting --out`` file and the aperture and distance it was filed under, if any.

    An :class:`~station.errors.InputError` naming the file when it is not a harp vignetting file,
    its fit is malformed, or it is for another image size than ``width`` x ``height``.
    """
    doc = read_document(path, "harp-vignetting", "a harp vignetting file", "harp vignetting --out")
    return vignetting_fit_of(doc, str(path), width, height)


def vignetting_fit_of(
    doc: dict[str, Any], path: str, width: int, height: int
) -> tuple[VignettingFit, float | None, float | None]:
    """:func:`read_vignetting_file` of a document already read (a profile's stored one); ``path`` names it."""
    try:
        fit = VignettingFit.from_dict(doc["fit"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: fit: missing or malformed ({exc})") from None
    if (fit.width, fit.height) != (width, height):
        raise InputError(
            f"{path}: the vignetting is for {fit.width}x{fit.height} images, the model for {width}x{height}"
        )
    element = ((doc.get("lensfun") or {}).get("element")) or {}
    try:
        aperture = float(element["aperture"]) if "aperture" in element else None
        distance = float(element["distance"]) if "distance" in element else None
    except (TypeError, ValueError):
        raise InputError(f"{path}: lensfun.element: aperture and distance must be numbers") from None
    return fit, aperture, distance
