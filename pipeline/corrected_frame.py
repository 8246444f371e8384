r"""The corrected image: its size and where harp's ideal frame lies in it (one convention for every output).

A harp correction :math:`U` maps distorted pixels to *ideal* pixels, a pin-hole frame with unit
magnification at the lens' distortion centre :math:`p_0` (the radial model's ``center``, a fixed
point of :math:`U`). The corrected image — what ``harp undistort`` writes, what the ``maps`` /
``stmap`` exports hold, and what every OpenCV / ROS / mrcal export's own ``K, D, R, newK`` produce
in their consumers — is that frame under one affine map :math:`A`:

.. math::
    q = A(u) = c' + S\,(u - p_0), \qquad S = \operatorname{diag}(s_x, s_y)

(:class:`CorrectedFrame`: ``q`` a pixel of the corrected image, ``u`` an ideal pixel; pixel centres
at integers, x = column, y = row). By default the corrected image has the size of the photo and
:math:`A` is the identity (``q = u``: the photo's centre stays put, its corners are cropped by a
barrel lens). :func:`corrected_frame` builds the others, from a :class:`FrameChoice`:

- ``scale`` :math:`s` and ``size`` :math:`W' \times H'`: :math:`s_x = s_y = s`, the photo's centre
  :math:`c = ((W-1)/2, (H-1)/2)` at the new image's centre :math:`c_{new}`:
  :math:`c' = c_{new} + s\,(p_0 - c)`;
- ``alpha`` :math:`a \in [0, 1]` and ``size``: OpenCV's ``getOptimalNewCameraMatrix`` semantics
  (``centerPrincipalPoint=false``): the *inner* rectangle (largest axis-aligned rectangle whose
  every pixel has a source in the photo) and the *outer* one (the bounding box of the whole
  corrected photo), in ideal pixels, are each mapped onto :math:`[0, W'-1] \times [0, H'-1]`
  (pixel centres) and :math:`s_x, s_y, c'` are interpolated linearly: :math:`a = 0` keeps only
  valid pixels, :math:`a = 1` keeps every source pixel;
- ``overscan``: the scale kept (1 by default) and the image enlarged to hold the outer rectangle
  (every source pixel; for VFX, the canvas a CG render must cover).

The rectangles are found as OpenCV finds them, from the corrected images of the photo's border
(:data:`BORDER_SAMPLES` points along each side, pixel centres ``0 … W-1``; OpenCV 5 samples 9 per
side, with its default 5-iteration point solver: on a lens whose extremes lie at the sides' middles
and the corners the two agree to 1e-4 in the scale and 0.001 px in the principal point).

For a pin-hole or fisheye export with camera matrix :math:`K_e`, whose ideal pixels :math:`p` are
ours up to the homography its conversion fitted (:math:`u = H(p)`, :mod:`pipeline.exports.fit`), the
consumer writes the same corrected image when its output pixel :math:`q` reads the ray
:math:`n \propto (newK\,R)^{-1} q` with :math:`newK\,R \propto A\,H\,K_e` (:func:`rectification`:
``newK`` the corrected image's own camera matrix, the same for every export of a lens and for
``harp undistort``, and ``R`` the near-identity 3x3 that takes the export's ideal frame to ours): ROS's
``projection_matrix`` and ``rectification_matrix``, OpenCV's ``initUndistortRectifyMap(K, D, R, newK)``.
The corrected image is then the same, pixel for pixel, to within the export's conversion error
(modulo homography: the homography is in ``R``).

References
----------
.. [1] OpenCV, ``cv::getOptimalNewCameraMatrix`` and ``cv::initUndistortRectifyMap``,
   https://docs.opencv.org/master/d9/d0c/group__calib3d.html
.. [2] R. Hartley, A. Zisserman, *Multiple View Geometry*, 2nd ed., Sect. 6.1 (the camera matrix),
   Sect. 8.4 (images of a rotating camera: a homography :math:`K R K^{-1}`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pipeline.models.base import DistortionModel
from pipeline.models.homography import HomographyModel, apply_homography

Array = npt.NDArray[np.float64]

BORDER_SAMPLES = 65
"""Points along each side of the photo whose corrected positions give the inner and outer rectangles."""

MAX_SIDE_PX = 32768
"""Largest side of a corrected image (an overscan of a lens whose correction runs away is refused)."""


@dataclass(frozen=True)
class FrameChoice:
    """What the user asked of the corrected image (None: the default).

    ``size``: ``(width, height)``; ``scale`` or ``alpha`` (not both); ``overscan``: enlarge the image
    to hold every source pixel at the scale (not with ``size`` or ``alpha``)."""

    size: tuple[int, int] | None = None
    scale: float | None = None
    alpha: float | None = None
    overscan: bool = False

    def __post_init__(self) -> None:
        if self.scale is not None and self.alpha is not None:
            raise ValueError("--scale and --alpha are alternatives: give one")
        if self.overscan and (self.size is not None or self.alpha is not None):
            raise ValueError("--overscan sets the size from the scale: give neither --size nor --alpha with it")
        if self.scale is not None and not (math.isfinite(self.scale) and 0 < self.scale <= 16):
            raise ValueError(f"--scale: expected a number in (0, 16], got {self.scale:g}")
        if self.alpha is not None and not (math.isfinite(self.alpha) and 0 <= self.alpha <= 1):
            raise ValueError(f"--alpha: expected a number in [0, 1], got {self.alpha:g}")
        if self.size is not None:
            w, h = self.size
            if not (2 <= int(w) <= MAX_SIDE_PX and 2 <= int(h) <= MAX_SIDE_PX):
                raise ValueError(f"--size: expected WIDTHxHEIGHT of 2..{MAX_SIDE_PX} px each, got {w}x{h}")

    @property
    def is_default(self) -> bool:
        return self.size is None and self.scale is None and self.alpha is None and not self.overscan

    def describe(self) -> str:
        """The options as a user types them (for file comments)."""
        parts = []
        if self.size is not None:
            parts.append(f"--size {self.size[0]}x{self.size[1]}")
        if self.scale is not None:
            parts.append(f"--scale {self.scale:g}")
        if self.alpha is not None:
            parts.append(f"--alpha {self.alpha:g}")
        if self.overscan:
            parts.append("--overscan")
        return " ".join(parts) or "the default (the photo's size, scale 1)"


@dataclass(frozen=True)
class CorrectedFrame:
    r"""The corrected image: ``width`` x ``height`` pixels, :math:`q = c' + S (u - p_0)` (module docstring).

    Attributes: ``width``, ``height``; ``sx``, ``sy`` (:math:`S`); ``cx``, ``cy`` (:math:`c'`, where the
    principal point lands); ``px``, ``py`` (:math:`p_0`, the principal point in ideal pixels)."""

    width: int
    height: int
    sx: float = 1.0
    sy: float = 1.0
    cx: float = 0.0
    cy: float = 0.0
    px: float = 0.0
    py: float = 0.0

    @classmethod
    def identity(cls, width: int, height: int, p0: tuple[float, float] = (0.0, 0.0)) -> CorrectedFrame:
        """The default frame of a ``width`` x ``height`` photo: ``q = u``."""
        return cls(int(width), int(height), 1.0, 1.0, float(p0[0]), float(p0[1]), float(p0[0]), float(p0[1]))

    @property
    def is_identity(self) -> bool:
        return self.sx == 1.0 and self.sy == 1.0 and self.cx == self.px and self.cy == self.py

    @property
    def matrix(self) -> Array:
        """:math:`A` as a 3x3 matrix (``q = A u`` in homogeneous coordinates)."""
        return np.array(
            [[self.sx, 0.0, self.cx - self.sx * self.px], [0.0, self.sy, self.cy - self.sy * self.py], [0, 0, 1.0]]
        )

    def to_ideal(self, q: Array) -> Array:
        """Ideal pixels ``u`` of corrected-image pixels ``q`` ``(N, 2)``."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 2)
        return np.stack([self.px + (q[:, 0] - self.cx) / self.sx, self.py + (q[:, 1] - self.cy) / self.sy], axis=1)

    def from_ideal(self, u: Array) -> Array:
        """Corrected-image pixels ``q`` of ideal pixels ``u`` ``(N, 2)``."""
        u = np.asarray(u, dtype=np.float64).reshape(-1, 2)
        return np.stack([self.cx + self.sx * (u[:, 0] - self.px), self.cy + self.sy * (u[:, 1] - self.py)], axis=1)

    def new_camera_matrix(self, focal: float) -> Array:
        """The corrected image's camera matrix when the ideal frame's focal length is ``focal`` px."""
        return np.array([[self.sx * focal, 0.0, self.cx], [0.0, self.sy * focal, self.cy], [0.0, 0.0, 1.0]])

    def describe(self) -> str:
        """One line: size, scale, where the principal point lands."""
        scale = f"{self.sx:.6g}" if self.sx == self.sy else f"{self.sx:.6g} x {self.sy:.6g}"
        return (
            f"corrected image {self.width}x{self.height} px, scale {scale} (corrected px per ideal px), "
            f"principal point ({self.px:.3f}, {self.py:.3f}) of the ideal frame at ({self.cx:.3f}, {self.cy:.3f})"
        )


def principal_point(model: DistortionModel, width: int, height: int) -> tuple[float, float]:
    """:math:`p_0`: the distortion centre of ``model`` in ideal pixels.

    A radial model's ``center`` (a fixed point of its correction), a pin-hole or fisheye camera's
    ``(cx, cy)``, a correction followed by a homography: the homography of its base's; otherwise the
    corrected position of the photo's centre."""
    if isinstance(model, HomographyModel):
        base = principal_point(model.base, width, height)
        p = apply_homography(model.matrix, np.array([base]))[0]
        return float(p[0]), float(p[1])
    for obj in (model, getattr(model, "base", None)):
        c = getattr(obj, "center", None)
        if isinstance(c, tuple) and len(c) == 2 and type(obj).__name__ in ("RadialModel", "PolynomialModel"):
            return float(c[0]), float(c[1])
    if hasattr(model, "cx") and hasattr(model, "cy") and hasattr(model, "fx"):
        return float(model.cx), float(model.cy)
    u = model.undistort_points(np.array([[(width - 1) / 2.0, (height - 1) / 2.0]]))[0]
    if not np.all(np.isfinite(u)):
        return (width - 1) / 2.0, (height - 1) / 2.0
    return float(u[0]), float(u[1])


def border_points(width: int, height: int, n: int = BORDER_SAMPLES) -> tuple[Array, Array, Array, Array]:
    """Pixel centres along the left, right, top and bottom sides of the photo (corners included)."""
    ys = np.linspace(0.0, height - 1.0, n)
    xs = np.linspace(0.0, width - 1.0, n)
    left = np.stack([np.zeros(n), ys], axis=1)
    right = np.stack([np.full(n, width - 1.0), ys], axis=1)
    top = np.stack([xs, np.zeros(n)], axis=1)
    bottom = np.stack([xs, np.full(n, height - 1.0)], axis=1)
    return left, right, top, bottom


def rectangles(model: DistortionModel, width: int, height: int) -> tuple[Array, Array]:
    """``(inner, outer)``, each ``(x0, y0, x1, y1)`` in ideal pixels (module docstring; ValueError when the
    correction is not defined along the photo's border)."""
    left, right, top, bottom = (model.undistort_points(p) for p in border_points(width, height))
    every = np.concatenate([left, right, top, bottom])
    if not np.all(np.isfinite(every)):
        raise ValueError(
            "the correction is not defined along the whole border of the photo: its corrected extent "
            "(--alpha, --overscan) is unknown; give --scale and --size instead"
        )
    inner = np.array([left[:, 0].max(), top[:, 1].max(), right[:, 0].min(), bottom[:, 1].min()])
    outer = np.array([every[:, 0].min(), every[:, 1].min(), every[:, 0].max(), every[:, 1].max()])
    if not (inner[2] > inner[0] and inner[3] > inner[1]):
        raise ValueError("the corrected photo has no inner rectangle (its border folds): --alpha 0 is undefined")
    return inner, outer


def corrected_frame(
    model: DistortionModel, width: int, height: int, choice: FrameChoice | None = None
) -> CorrectedFrame:
    """The corrected image of ``model`` for ``width`` x ``height`` photos as ``choice`` asks (module docstring)."""
    choice = choice or FrameChoice()
    p0 = principal_point(model, width, height)
    if choice.is_default:
        return CorrectedFrame.identity(width, height, p0)
    px, py = p0
    if choice.alpha is not None:
        nw, nh = choice.size or (width, height)
        inner, outer = rectangles(model, width, height)
        a = float(choice.alpha)

        def fit(rect: Array) -> tuple[float, float, float, float]:
            sx = (nw - 1) / (rect[2] - rect[0])
            sy = (nh - 1) / (rect[3] - rect[1])
            return sx, sy, -sx * (rect[0] - px), -sy * (rect[1] - py)

        f0, f1 = fit(inner), fit(outer)
        sx, sy, cx, cy = (v0 * (1 - a) + v1 * a for v0, v1 in zip(f0, f1))
        return CorrectedFrame(int(nw), int(nh), sx, sy, cx, cy, px, py)
    s = 1.0 if choice.scale is None else float(choice.scale)
    if choice.overscan:
        _, outer = rectangles(model, width, height)
        x0, y0 = math.floor(s * (outer[0] - px) + 1e-9), math.floor(s * (outer[1] - py) + 1e-9)
        x1, y1 = math.ceil(s * (outer[2] - px) - 1e-9), math.ceil(s * (outer[3] - py) - 1e-9)
        nw, nh = x1 - x0 + 1, y1 - y0 + 1
        if max(nw, nh) > MAX_SIDE_PX:
            raise ValueError(f"--overscan: the corrected photo would be {nw}x{nh} px (more than {MAX_SIDE_PX})")
        return CorrectedFrame(int(nw), int(nh), s, s, float(-x0), float(-y0), px, py)
    nw, nh = choice.size or (width, height)
    c_old = ((width - 1) / 2.0, (height - 1) / 2.0)
    c_new = ((nw - 1) / 2.0, (nh - 1) / 2.0)
    return CorrectedFrame(
        int(nw), int(nh), s, s, c_new[0] + s * (px - c_old[0]), c_new[1] + s * (py - c_old[1]), px, py
    )


def rectification(frame: CorrectedFrame, h_ideal: Array, camera_matrix: Array, focal: float) -> tuple[Array, Array]:
    r"""``(R, newK)`` that make an export's consumer write this corrected image.

    ``h_ideal`` maps the export's ideal pixels to ours (:math:`u = H(p)`), ``camera_matrix`` is the
    export's :math:`K_e`, ``focal`` the focal length (px) the corrected image's camera matrix states.
    The consumer's output pixel :math:`q` reads the ray :math:`(newK\,R)^{-1} q`; ours is
    :math:`K_e^{-1} H^{-1} A^{-1} q`. ``newK`` is the corrected image's own camera matrix
    (:meth:`CorrectedFrame.new_camera_matrix`: the same for every export of a lens, and for
    ``harp undistort``), so :math:`R = newK^{-1} A\,H\,K_e`, scaled to determinant 1: the export's
    ideal frame to ours, a near-identity 3x3 (a rotation of the camera plus what the homography
    adds to it; OpenCV and ROS apply any 3x3 there).
    """
    new_k = frame.new_camera_matrix(focal)
    m = np.linalg.inv(new_k) @ frame.matrix @ np.asarray(h_ideal, dtype=np.float64) @ np.asarray(camera_matrix)
    det = float(np.linalg.det(m))
    if not (math.isfinite(det) and det > 0):
        raise ValueError(
            "the export's ideal frame is mirrored or degenerate: it cannot be rectified to the corrected image"
        )
    return np.asarray(m / np.cbrt(det), dtype=np.float64), new_k
