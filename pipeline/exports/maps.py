r"""Exact per-pixel exports: ``cv2.remap`` maps (``.npz``) and STMaps (32-bit float OpenEXR).

Both hold, for every pixel of the corrected image, where to read it in the
distorted image: the maps of ``harp undistort``
(:func:`pipeline.undistort_maps.fast_undistortion_maps`, the model's own
inverse, interpolated between exact nodes with a stated error), so that
``cv2.remap(img, map_x, map_y, ...)`` gives ``harp undistort``'s image.

**maps** (``.npz``, ``numpy.load``): ``map_x``, ``map_y`` float32 (H, W),
``width``, ``height``, and ``interp_rms_px`` / ``interp_max_px`` (the
interpolation error of the maps against the exact inverse, measured at
pixels), ``convention`` (text) and ``corners_ideal`` (4, 2) float64: the corrected
positions of the distorted image's corners (top-left, top-right, bottom-right,
bottom-left pixel centres), which ``harp evaluate``'s 4-corner normalisation needs and
which a wide lens's maps do not reach. Pixel centres at integers, x = column,
y = row, as in ``cv2.remap``.

Both hold the corrected image the options ask (``--size``, ``--scale``, ``--alpha``, ``--overscan``;
:mod:`pipeline.corrected_frame`), ``harp undistort``'s with the same options; the maps file stores its
``ideal_to_corrected`` 3x3 matrix :math:`A`.

**stmap** (``.exr``, 32-bit float, channels R, G, B, A; ZIP compression, lossless):
the convention of Nuke's and Natron's STMap node, whose coordinates put the
*edges* of the image at 0 and 1 and the bottom-left corner at the origin, so
a pixel centre (column :math:`i`, row :math:`j` from the top) sits at
:math:`((i + 0.5)/W,\ 1 - (j + 0.5)/H)`. For the corrected pixel whose
source is :math:`(m_x, m_y)` (our pixel-centre coordinates):

.. math::
    R = (m_x + 0.5) / W, \qquad G = 1 - (m_y + 0.5) / H, \qquad B = 0

with :math:`W \times H` the size of the *photo* (the STMap node's input; the STMap itself has the
corrected image's size), and :math:`A = 1` where the source lies on the photo
(:math:`-0.5 \le m_x \le W - 0.5`, likewise :math:`m_y`), 0 where the corrected image has no source
(Nuke: the STMap node's alpha, or a Merge to cut the empty border).

**stmap-redistort** (the other half of an STMap pair, for VFX): the STMap of the *photo's* size that
reads a render of the corrected image (e.g. a CG element rendered in the undistorted frame, with
``--overscan`` so that it covers the photo) back into the lens' distortion: for the photo pixel
:math:`x`, its source is the corrected-image pixel :math:`q = A(U(x))`, :math:`R = (q_x + 0.5)/W'`,
:math:`G = 1 - (q_y + 0.5)/H'` (:math:`W' \times H'` the corrected image), :math:`A = 1` where
:math:`q` lies on it. Its comments carry ``harp corrected_size: W' H'``. Blender's compositor
(Map UV node) reads the same 0-1, bottom-up coordinates.

(the identity STMap is ``R = (x + 0.5)/width``, ``G = (y + 0.5)/height`` in
Nuke's bottom-up pixel coordinates; the ``x / (width - 1)`` variant seen in
some tutorials is half a pixel off at the borders). The header carries a
``comments`` attribute with the convention and the figures, and the line
``harp corners_ideal: x0 y0 x1 y1 x2 y2 x3 y3`` (the same corners as the maps' ``corners_ideal``).

References
----------
.. [1] OpenCV, ``cv::remap``, https://docs.opencv.org/master/da/d54/group__imgproc__transform.html
.. [2] The Foundry, Nuke reference guide, "STMap" node; Natron, "STMap" node (``net.sf.openfx.STMap``).
.. [3] OpenEXR file layout, https://openexr.com/en/latest/OpenEXRFileLayout.html
"""

from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pipeline.corrected_frame import CorrectedFrame
from pipeline.models.base import DistortionModel, image_corners
from pipeline.models.remap_model import CorrectionMapModel, RemapModel
from pipeline.undistort_maps import DEFAULT_STEP_PX, RemapMaps, fast_undistortion_maps

Array = npt.NDArray[np.float64]

MAPS_CONVENTION = (
    "cv2.remap(img, map_x, map_y): corrected pixel (x, y) is read from the distorted image at "
    "(map_x[y, x], map_y[y, x]); x = column, y = row, pixel centres at integers"
)
STMAP_CONVENTION = (
    "STMap (Nuke/Natron): R = (src_x + 0.5) / width, G = 1 - (src_y + 0.5) / height, B = 0; "
    "src = position in the distorted image of each corrected pixel, pixel centres at integers, rows from the top"
)
STMAP_REDISTORT_CONVENTION = (
    "STMap (Nuke/Natron), redistort: R = (q_x + 0.5) / corrected_width, G = 1 - (q_y + 0.5) / corrected_height, "
    "B = 0, A = 1 where q is on the corrected image; q = the corrected-image pixel of each photo pixel"
)
CORNERS_TAG = "harp corners_ideal:"
SOURCE_TAG = "harp source_size:"
CORRECTED_TAG = "harp corrected_size:"
EXR_MAGIC = b"\x76\x2f\x31\x01"
NPZ_MAGIC = b"PK\x03\x04"


@dataclass(frozen=True)
class MapAccuracy:
    """How far stored maps are from the model's exact inverse, at pixels (distorted-image pixels)."""

    rms_px: float
    max_px: float
    n_points: int


def map_accuracy(model: DistortionModel, map_x: Array, map_y: Array, n: int = 20000, seed: int = 0) -> MapAccuracy:
    """|stored map - exact ``distort_points``| at ``n`` random pixels plus every border pixel (as stored, float32)."""
    h, w = map_x.shape
    rng = np.random.default_rng(seed)
    xs = np.concatenate([rng.integers(0, w, n), np.arange(w), np.arange(w), np.zeros(h, int), np.full(h, w - 1)])
    ys = np.concatenate([rng.integers(0, h, n), np.zeros(w, int), np.full(w, h - 1), np.arange(h), np.arange(h)])
    exact = model.distort_points(np.stack([xs, ys], axis=1).astype(np.float64))
    got = np.stack([map_x[ys, xs], map_y[ys, xs]], axis=1).astype(np.float64)
    e = np.linalg.norm(got - exact, axis=1)
    e = np.where(np.isfinite(e), e, np.inf)
    return MapAccuracy(rms_px=float(np.sqrt(np.mean(e**2))), max_px=float(e.max()), n_points=int(len(e)))


def export_maps(
    model: DistortionModel, width: int, height: int, step: int = DEFAULT_STEP_PX, frame: CorrectedFrame | None = None
) -> RemapMaps:
    """The maps of ``harp undistort`` for this model, image size and corrected image."""
    return fast_undistortion_maps(model, width, height, step=step, frame=frame)


def corners_ideal(model: DistortionModel, width: int, height: int, frame: CorrectedFrame | None = None) -> Array | None:
    """The corrected positions of the image corners ``(4, 2)`` (in ``frame``'s pixels when given; None
    where the model has none)."""
    u = np.asarray(model.undistort_points(image_corners(width, height)), dtype=np.float64)
    if frame is not None:
        u = frame.from_ideal(u)
    return u if np.all(np.isfinite(u)) else None


def redistort_map(model: DistortionModel, width: int, height: int, frame: CorrectedFrame) -> tuple[Array, Array]:
    """``(q_x, q_y)`` (H, W) float64: the corrected-image pixel of every photo pixel (the redistort STMap's
    source positions; NaN where the correction is undefined)."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    q = frame.from_ideal(model.undistort_points(np.stack([xx.ravel(), yy.ravel()], axis=1)))
    return q[:, 0].reshape(height, width), q[:, 1].reshape(height, width)


def maps_npz_bytes(
    maps: RemapMaps,
    accuracy: MapAccuracy,
    notes: tuple[str, ...] = (),
    corners: Array | None = None,
    frame: CorrectedFrame | None = None,
    source_size: tuple[int, int] | None = None,
) -> bytes:
    """The ``.npz`` file: float32 maps, size, convention, measured interpolation error, corrected corners
    and (with a frame) ``ideal_to_corrected``."""
    h, w = maps.map_x.shape
    buf = io.BytesIO()
    extra: dict[str, Any] = {} if corners is None else {"corners_ideal": np.asarray(corners, np.float64).reshape(4, 2)}
    if frame is not None:
        extra["ideal_to_corrected"] = frame.matrix
    if source_size is not None:
        extra["source_width"], extra["source_height"] = np.int64(source_size[0]), np.int64(source_size[1])
    np.savez_compressed(
        buf,
        **extra,
        map_x=np.asarray(maps.map_x, dtype=np.float32),
        map_y=np.asarray(maps.map_y, dtype=np.float32),
        width=np.int64(w),
        height=np.int64(h),
        interp_rms_px=np.float64(accuracy.rms_px),
        interp_max_px=np.float64(accuracy.max_px),
        convention=np.str_(MAPS_CONVENTION),
        notes=np.str_("\n".join(notes)),
    )
    return buf.getvalue()


def sniff_npz(head: bytes) -> bool:
    return head.startswith(NPZ_MAGIC) and b"map_x" in head[:4096]


def maps_source_size(data: bytes) -> tuple[int, int] | None:
    """The photo size a maps file states (``source_width``, ``source_height``), or None."""
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        if "source_width" in z and "source_height" in z:
            return int(z["source_width"]), int(z["source_height"])
    return None


def read_maps_npz(data: bytes, name: str = "<maps>") -> RemapModel:
    """The correction of a maps file; ValueError('<name>: <reason>') if it is not one."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            if "map_x" not in z or "map_y" not in z:
                raise ValueError(f"{name}: .npz without map_x and map_y arrays")
            corners = z["corners_ideal"] if "corners_ideal" in z else None
            return RemapModel(
                map_x=z["map_x"],
                map_y=z["map_y"],
                corners_ideal=None if corners is None else tuple((float(x), float(y)) for x, y in corners),
            )
    except (OSError, zipfile.BadZipFile, EOFError) as exc:
        raise ValueError(f"{name}: not a readable .npz maps file ({type(exc).__name__})") from None
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith(f"{name}:") else f"{name}: {msg}") from None


def stmap_channels(
    map_x: Array, map_y: Array, source_size: tuple[int, int] | None = None
) -> tuple[Array, Array, Array]:
    """``(R, G, A)`` float32 of the STMap of maps reading a ``source_size`` image (default: the maps' own
    size; see module docstring)."""
    w, h = source_size or (map_x.shape[1], map_x.shape[0])
    mx, my = np.asarray(map_x, dtype=np.float64), np.asarray(map_y, dtype=np.float64)
    r = (mx + 0.5) / w
    g = 1.0 - (my + 0.5) / h
    with np.errstate(invalid="ignore"):
        a = (mx >= -0.5) & (mx <= w - 0.5) & (my >= -0.5) & (my <= h - 0.5)
    return r.astype(np.float32), g.astype(np.float32), a.astype(np.float32)


def maps_from_stmap(r: Array, g: Array, source_size: tuple[int, int] | None = None) -> tuple[Array, Array]:
    """Inverse of :func:`stmap_channels` (float64)."""
    w, h = source_size or (r.shape[1], r.shape[0])
    return np.asarray(r, np.float64) * w - 0.5, (1.0 - np.asarray(g, np.float64)) * h - 0.5


def _size_line(tag: str, size: tuple[int, int]) -> str:
    return f"{tag} {int(size[0])} {int(size[1])}"


def _exr_bytes(lines: list[str], r: Array, g: Array, a: Array) -> bytes:
    import OpenEXR  # imported where used: only STMap exports pay for it

    header: dict[str, Any] = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "comments": "\n".join(lines),
    }
    channels = {"R": r, "G": g, "B": np.zeros_like(r), "A": a}
    buf = io.BytesIO()
    with OpenEXR.File(header, channels) as f:
        f.write(buf)
    return buf.getvalue()


def stmap_redistort_exr_bytes(
    qx: Array, qy: Array, corrected_size: tuple[int, int], notes: tuple[str, ...] = ()
) -> bytes:
    """The redistort STMap (module docstring) of the corrected-image positions ``q`` of the photo's pixels."""
    w, h = corrected_size
    fine = np.isfinite(qx) & np.isfinite(qy)
    qx, qy = np.where(fine, qx, -1.0), np.where(fine, qy, -1.0)
    r, g, a = stmap_channels(qx, qy, (w, h))
    a = np.where(fine, a, 0.0).astype(np.float32)
    return _exr_bytes([STMAP_REDISTORT_CONVENTION, *notes, _size_line(CORRECTED_TAG, (w, h))], r, g, a)


def stmap_exr_bytes(
    maps: RemapMaps,
    notes: tuple[str, ...] = (),
    corners: Array | None = None,
    source_size: tuple[int, int] | None = None,
) -> bytes:
    """The STMap as a 32-bit float OpenEXR file (written by the OpenEXR library)."""
    src = source_size or (maps.map_x.shape[1], maps.map_x.shape[0])
    r, g, a = stmap_channels(np.asarray(maps.map_x, np.float64), np.asarray(maps.map_y, np.float64), src)
    lines = [STMAP_CONVENTION, *notes, _size_line(SOURCE_TAG, src)]
    if corners is not None:
        lines.append(CORNERS_TAG + "".join(f" {float(v)!r}" for v in np.asarray(corners, dtype=np.float64).ravel()))
    return _exr_bytes(lines, r, g, a)


def sniff_exr(head: bytes) -> bool:
    return head.startswith(EXR_MAGIC)


def _exr_channels(data: bytes, name: str) -> tuple[Array, Array, str]:
    """``(R, G, comments)`` of an EXR (ValueError naming the file if it is not an STMap)."""
    import OpenEXR

    try:
        with OpenEXR.File(io.BytesIO(data), separate_channels=True) as f:  # the pixels are read while it is open
            ch = f.channels()
            rg = [np.asarray(ch[c].pixels, dtype=np.float64) for c in ("R", "G") if c in ch]
            comments = f.header().get("comments", "")
    except (RuntimeError, OSError, ValueError) as exc:  # ValueError: a truncated file ("file has 0 parts")
        raise ValueError(f"{name}: not a readable OpenEXR file ({str(exc).splitlines()[0][:120]})") from None
    if len(rg) != 2:
        raise ValueError(f"{name}: EXR without R and G channels (not an STMap)")
    return rg[0], rg[1], str(comments)


def stmap_kind(data: bytes) -> str:
    """``"stmap-redistort"`` for a redistort STMap (its comments say so), else ``"stmap"``."""
    return "stmap-redistort" if STMAP_REDISTORT_CONVENTION.encode()[:40] in data[:65536] else "stmap"


def read_stmap_exr(data: bytes, name: str = "<stmap>", source_size: tuple[int, int] | None = None) -> DistortionModel:
    """The correction of an STMap EXR (R, G channels); ValueError('<name>: <reason>') if it is not one.

    An undistort STMap (:class:`RemapModel`, corrected image -> photo) needs the photo's size (the
    ``harp source_size:`` comment line, else ``source_size``, else its own); a redistort one
    (:class:`CorrectionMapModel`, photo -> corrected image) the corrected image's (``harp corrected_size:``,
    else its own)."""
    r, g, comments = _exr_channels(data, name)
    if comments.startswith(STMAP_REDISTORT_CONVENTION[:40]):
        size = _size_of(comments, CORRECTED_TAG, name) or (r.shape[1], r.shape[0])
        qx, qy = maps_from_stmap(r, g, size)
        return CorrectionMapModel(map_x=qx, map_y=qy)
    src = _size_of(comments, SOURCE_TAG, name) or source_size
    mx, my = maps_from_stmap(r, g, src)
    return RemapModel(map_x=mx, map_y=my, corners_ideal=_stmap_corners(comments, name))


def _size_of(comments: str, tag: str, name: str) -> tuple[int, int] | None:
    for line in comments.splitlines():
        if line.startswith(tag):
            try:
                w, h = (int(t) for t in line[len(tag) :].split())
            except ValueError:
                raise ValueError(f"{name}: comments line {tag!r} must hold a width and a height") from None
            return w, h
    return None


def _stmap_corners(comments: str, name: str) -> tuple[tuple[float, float], ...] | None:
    """The ``harp corners_ideal:`` line of an STMap's comments (None without one)."""
    for line in comments.splitlines():
        if line.startswith(CORNERS_TAG):
            try:
                v = [float(t) for t in line[len(CORNERS_TAG) :].split()]
            except ValueError:
                v = []
            if len(v) != 8 or not all(np.isfinite(v)):
                raise ValueError(f"{name}: comments line {CORNERS_TAG!r} must hold 8 finite numbers")
            return tuple((v[2 * i], v[2 * i + 1]) for i in range(4))
    return None
