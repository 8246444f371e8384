r"""Synthetic calibration-harp images with exact ground truth.

The scene is a back-lit sheet in front of which parallel opaque strings are
stretched. In the *ideal* (pin-hole) image the strings are straight lines; the
camera sees them through a known lens, given as a
:class:`~pipeline.models.base.DistortionModel`. Because a model maps
*distorted* pixels to *ideal* ones (``undistort_points``), the renderer needs
no inversion: every pixel centre ``(x, y)`` of the distorted image is mapped
to ideal coordinates ``u = U(x, y)`` and the (blurred) ideal scene is
evaluated there.

Image formation
---------------
Let :math:`\theta` be the string direction in the ideal image
(counter-clockwise from +x towards +y, as in the array), the unit normal
:math:`n = (-\sin\theta, \cos\theta)`, the ideal image centre
:math:`c = ((W-1)/2, (H-1)/2)` and :math:`q(u) = n\cdot(u - c) - \phi` the
signed distance from the string through the centre (``phase_px`` = :math:`\phi`).
String :math:`k` is centred at :math:`q = k\,p` (``spacing_px`` = :math:`p`) and has
width :math:`w`. With :math:`\Phi` the standard normal CDF, the grey level of a
pixel is

.. math::
    I(x) = e\,B\,V(x)\,D(x)\,F(u)\,\Bigl[1 - (1-c_s)\sum_k
           \bigl(\Phi(\tfrac{q - kp + w/2}{\sigma}) - \Phi(\tfrac{q - kp - w/2}{\sigma})\bigr)\Bigr]

* :math:`B` = ``background`` (grey level at the centre), :math:`c_s` =
  ``string_level / background`` (string transmission, or for bright strings on a
  dark background, ``string_level > background``, how much brighter a string is),
  :math:`e` = exposure scale.
* :math:`\sigma^2 = b^2 + 1/12`: the optical PSF is a Gaussian of standard
  deviation :math:`b` (``blur_px``); integration over a square pixel adds a
  box whose projection on *any* direction :math:`n` has variance
  :math:`(n_x^2 + n_y^2)/12 = 1/12`. Replacing box * Gaussian by the Gaussian of
  the same variance keeps the PSF symmetric, so every edge location is
  unchanged, at the cost of a profile shape differing from the box-integrated
  one by less than 0.1 % of the contrast (b = 0.7 px); it is exact in closed form and needs
  one evaluation per pixel where 3 x 3 supersampling would need nine. The
  blur is applied in ideal coordinates: through a lens whose local scale differs from 1 by
  :math:`\epsilon` the blur seen in the image differs by the same fraction
  (about 1 % at the corners for the demo lenses).
* :math:`V(x) = (1 + a r^2)^{-2}` is a cos\ :sup:`4`-like vignetting, with
  :math:`r` the distance to the sensor centre and :math:`a` chosen so that
  :math:`V = 1 - v` at the corners (``vignetting`` = :math:`v`).
* :math:`D(x) = \prod_j (1 - \delta_j \exp(-|x - x_j|^2 / 2 s_j^2))`: dust
  shadows on the sensor (``dust`` spots, positions drawn from ``dust_seed``).
* :math:`F(u) = 1 - (1 - c_f)\,\Phi((\pm q - f)/\sigma)`: the dark harp frame, a bar
  parallel to the strings entering the image by ``frame_depth_px`` from the
  farthest corner on side ``frame_side`` (only when ``frame``).

Then shot noise (Poisson, ``electrons_per_level`` electrons per 8-bit grey
level), read noise (Gaussian, ``noise_sigma``), rounding and clipping to the bit
depth (the noise of each block of 16 rows comes from its own generator
seeded by ``(seed, block)``, so the image does not depend on how rendering is
chunked or threaded). All grey levels (``background``, ``string_level``, ``frame_level``,
``noise_sigma``) are on the 8-bit scale; a 16-bit image multiplies them by
65535/255, so the signal-to-noise ratio does not depend on the bit depth.

Ground truth
------------
(The realistic simulator, :mod:`pipeline.realism`, renders bent strings: its
:class:`EdgeTruth` carry a ``shape``, the edge's displacement along the normal, and
:func:`visible_edges` traces those bent ideal curves through the lens the same way.)
The two edges of string :math:`k` are the ideal lines
:math:`q = kp \mp w/2`, i.e. ``{p : n . p = offset}`` (:class:`EdgeTruth`). The
distorted edge is exactly the image of that line by the lens
(``lens.distort_points``): along it the image is at the half level between
the local background and the local string level (up to the tail
:math:`\Phi(-w/\sigma)` of the opposite edge, below 1e-4 px for the defaults).
The maximum of the gradient magnitude, which is what gradient-based edge
detectors find, is displaced from the geometric edge by a constant amount
towards the outside of the string (the tail of the opposite edge, see
:func:`edge_peak_offset`: 1.2e-3 px for w = 3 px, b = 0.7 px; 0 for w = 8 px;
but 0.14 px for w = 3 px seen by a detector that first smooths with a
Gaussian of 1 px). A constant displacement does not bend an edge, so it
changes neither :math:`d` nor :math:`d_{max}` (through a lens it scales with
the local lens scale, i.e. varies by about 1 % of itself along an edge). Smooth multiplicative shading (vignetting,
dust) moves a gradient maximum by about :math:`2\sigma^2|\nabla V|/V`
(< 1e-3 px at v = 0.3 on a 2 MP image) but not the half-level crossing.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
.. [2] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", IPOL 7 (2017).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from scipy.special import ndtr

from pipeline.models.base import DistortionModel, IdentityModel

_LEVEL_16 = 65535.0 / 255.0
NOISE_BLOCK_ROWS = 16
"""Rows sharing one noise generator (seeded by ``(seed, row // NOISE_BLOCK_ROWS)``)."""


@dataclass(frozen=True)
class HarpScene:
    """What is in front of the camera (lengths in ideal-image pixels, levels 8-bit).

    Parameters
    ----------
    angle_deg : direction of the strings in the ideal image, degrees
        counter-clockwise from +x towards +y.
    spacing_px, string_width_px, phase_px : string pitch, width, and the
        signed offset (along the normal) of string 0 from the image centre.
    background, string_level : grey level of the lit sheet at the image
        centre and inside a string (before vignetting, exposure, noise);
        ``string_level > background`` renders bright strings on a dark
        background (strings lit from the front).
    blur_px : standard deviation of the Gaussian optical PSF.
    vignetting : fractional fall-off at the image corners, in [0, 1).
    dust, dust_seed : number of dust shadows and the seed placing them
        (fixed on the sensor, independent of the noise seed).
    dust_at : further dust shadows at given places, ``(x, y, sigma, depth)``
        each (image pixels; see :class:`DustSpot`).
    frame, frame_level, frame_depth_px, frame_side : the dark harp frame, a
        bar parallel to the strings entering by ``frame_depth_px`` (measured
        along the normal from the farthest image point) on side ``frame_side``
        (+1: towards +n, -1: towards -n).
    """

    angle_deg: float = 0.0
    spacing_px: float = 60.0
    string_width_px: float = 3.0
    phase_px: float = 0.0
    background: float = 200.0
    string_level: float = 30.0
    blur_px: float = 0.7
    vignetting: float = 0.3
    dust: int = 0
    frame: bool = False
    dust_seed: int = 1
    frame_level: float = 15.0
    frame_depth_px: float = 80.0
    frame_side: int = 1
    dust_at: tuple[tuple[float, float, float, float], ...] = ()

    @property
    def sigma_px(self) -> float:
        """Total blur: optical PSF and pixel integration, ``sqrt(blur^2 + 1/12)``."""
        return math.sqrt(self.blur_px**2 + 1.0 / 12.0)

    @property
    def direction(self) -> tuple[float, float]:
        """Unit vector along the strings (ideal image)."""
        a = math.radians(self.angle_deg)
        return (math.cos(a), math.sin(a))

    @property
    def normal(self) -> tuple[float, float]:
        """Unit normal ``n = (-sin, cos)``; string offsets grow along it."""
        a = math.radians(self.angle_deg)
        return (-math.sin(a), math.cos(a))


class EdgeShape(Protocol):
    """How far a bent edge lies from its straight line: a displacement along the normal.

    Called with positions ``s`` along the line (``s = t . p`` with ``t = (n_y, -n_x)``,
    ideal pixels), returns the displacement (ideal pixels, along ``+n``) of the edge
    there. :class:`pipeline.harp_scene.EdgeProfile` is the one the realistic
    simulator uses (a string's sag, bow, kink and twist).
    """

    def __call__(self, s: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class EdgeTruth:
    """One string edge: the ideal curve ``{p : n . p = offset + shape(t . p)}``, ``t = (n_y, -n_x)``.

    Without ``shape`` (the clean renderer's strings) the edge is the straight ideal
    line ``{p : n . p = offset}``; with it, it is that line bent by
    ``shape(s)`` along the normal at the position ``s`` along it (:class:`EdgeShape`).
    ``side`` is -1 for the edge at smaller ``n . p`` (crossing it along +n
    enters the string: the image gets darker for dark strings, brighter for
    bright ones) and +1 for the other one.
    """

    string_index: int
    side: int
    normal: tuple[float, float]
    offset: float
    shape: EdgeShape | None = None

    @property
    def along(self) -> tuple[float, float]:
        """The unit vector ``t = (n_y, -n_x)`` along the edge; ``s = t . p`` is the position on it."""
        return (self.normal[1], -self.normal[0])

    def displacement(self, s: np.ndarray) -> np.ndarray:
        """``shape(s)``, the edge's distance from its straight line along ``+n`` (zeros without a shape)."""
        s = np.asarray(s, np.float64)
        return np.zeros_like(s) if self.shape is None else np.asarray(self.shape(s), np.float64)

    def ideal_points(self, s: np.ndarray) -> np.ndarray:
        """The ideal points of the edge at positions ``s`` along it: ``(offset + shape(s)) n + s t``, ``(N, 2)``."""
        s = np.asarray(s, np.float64).ravel()
        n = np.asarray(self.normal, np.float64)
        t = np.asarray(self.along, np.float64)
        return (self.offset + self.displacement(s))[:, None] * n[None, :] + s[:, None] * t[None, :]

    def level(self, u: np.ndarray) -> np.ndarray:
        """``n . u - offset - shape(t . u)`` of ideal points ``u`` ``(N, 2)``: zero exactly on the edge.

        Its zero set is the edge; near it, it is the distance along ``n`` from the edge
        (to first order in the edge's slope ``shape'``).
        """
        u = np.asarray(u, np.float64).reshape(-1, 2)
        n = np.asarray(self.normal, np.float64)
        t = np.asarray(self.along, np.float64)
        out: np.ndarray = u @ n - self.offset
        if self.shape is not None:
            out = out - self.displacement(u @ t)
        return out


@runtime_checkable
class TruthSource(Protocol):
    """What the truth functions need of a rendered image: its edges, lens and size.

    :class:`Rendered` (the clean renderer) and :class:`pipeline.realism.Shot` (the
    realistic simulator) both are one.
    """

    @property
    def edges(self) -> tuple[EdgeTruth, ...]: ...

    @property
    def lens(self) -> DistortionModel: ...

    @property
    def width(self) -> int: ...

    @property
    def height(self) -> int: ...


@dataclass(frozen=True)
class DustSpot:
    """A dust shadow on the sensor: ``1 - depth * exp(-r^2 / (2 sigma^2))`` around ``(x, y)``."""

    x: float
    y: float
    sigma: float
    depth: float


@dataclass(frozen=True)
class Rendered:
    """A rendered image and everything needed to know the exact answer.

    ``edges`` lists the string edges visible in the image (not hidden by the
    frame nor within 6 sigma of it). ``frame_offset`` is the ideal line
    ``n . p = frame_offset`` bounding the frame (None without frame).
    """

    image: np.ndarray
    scene: HarpScene
    lens: DistortionModel
    edges: tuple[EdgeTruth, ...]
    dust: tuple[DustSpot, ...] = ()
    frame_offset: float | None = None

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])


# ---------------------------------------------------------------- helpers
def ideal_border(lens: DistortionModel, width: int, height: int, step: float = 8.0) -> np.ndarray:
    """Ideal coordinates ``lens.undistort_points`` of points every ``step`` px along the border of
    the image (its pixel-area outline, ``-0.5 .. width - 0.5``): the outline of the ideal footprint."""
    xs = np.append(np.arange(-0.5, width - 0.5, step), width - 0.5)
    ys = np.append(np.arange(-0.5, height - 0.5, step), height - 0.5)
    pts = np.concatenate(
        [
            np.stack([xs, np.full_like(xs, -0.5)], 1),
            np.stack([xs, np.full_like(xs, height - 0.5)], 1),
            np.stack([np.full_like(ys, -0.5), ys], 1),
            np.stack([np.full_like(ys, width - 0.5), ys], 1),
        ]
    )
    return lens.undistort_points(pts)


def _check(
    width: int, height: int, scene: HarpScene, bit_depth: int, noise_sigma: float, exposure: float, seed: int
) -> None:
    if int(width) != width or int(height) != height or width < 2 or height < 2:
        raise ValueError(f"image size must be integers >= 2, got {width}x{height}")
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth must be 8 or 16, got {bit_depth}")
    if not scene.string_width_px > 0:
        raise ValueError(f"string_width_px must be > 0, got {scene.string_width_px}")
    if not scene.spacing_px > scene.string_width_px:
        raise ValueError(f"spacing_px ({scene.spacing_px}) must exceed string_width_px ({scene.string_width_px})")
    if not 0 <= scene.vignetting < 1:
        raise ValueError(f"vignetting must be in [0, 1), got {scene.vignetting}")
    if scene.blur_px < 0 or noise_sigma < 0 or exposure < 0:
        raise ValueError("blur_px, noise_sigma and exposure must be >= 0")
    if not scene.background > 0:
        raise ValueError(f"background must be > 0, got {scene.background}")
    if int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    if scene.frame_side not in (-1, 1):
        raise ValueError(f"frame_side must be -1 or +1, got {scene.frame_side}")


def edge_peak_offset(string_width_px: float, sigma_px: float) -> float:
    """Displacement of the gradient-magnitude maximum from the geometric edge.

    For an isolated string of width ``w`` blurred by a Gaussian of standard
    deviation ``sigma`` (the profile of :mod:`pipeline.render`), returns how far
    (in pixels, >= 0, towards the outside of the string) the maximum of
    ``|dI/dq|`` near an edge lies from that edge. It is constant along a
    string and so does not bend the edge. Detectors that smooth first see
    ``sigma_eff = sqrt(sigma^2 + sigma_detector^2)``.
    """
    w, s = float(string_width_px), float(sigma_px)

    # gradient near the edge at q = -w/2 + t:  g(t) = phi(t/s) - phi((t - w)/s)
    # g'(t) = 0  <=>  t phi(t/s) = (t - w) phi((t - w)/s); solve by bisection on [-w/2, 0]
    def h(t: float) -> float:
        return t * math.exp(-0.5 * (t / s) ** 2) - (t - w) * math.exp(-0.5 * ((t - w) / s) ** 2)

    lo, hi = -0.5 * w, 0.0
    if h(hi) == 0.0:
        return 0.0
    if h(lo) * h(hi) > 0:  # strings so thin that the two edges merge
        return float("nan")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if h(lo) * h(mid) <= 0:
            hi = mid
        else:
            lo = mid
    return -0.5 * (lo + hi)


def string_edges(scene: HarpScene, lens: DistortionModel, width: int, height: int) -> tuple[EdgeTruth, ...]:
    """Every string edge whose ideal line crosses the ideal footprint of the image."""
    n = np.asarray(scene.normal)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    base = float(n @ c) + scene.phase_px
    q = ideal_border(lens, width, height) @ n - base
    q = q[np.isfinite(q)]
    w2 = 0.5 * scene.string_width_px
    k0 = math.ceil((q.min() - w2) / scene.spacing_px)
    k1 = math.floor((q.max() + w2) / scene.spacing_px)
    edges = []
    for k in range(k0, k1 + 1):
        for side in (-1, 1):
            edges.append(EdgeTruth(k, side, (float(n[0]), float(n[1])), base + k * scene.spacing_px + side * w2))
    return tuple(edges)


def _frame_offset(scene: HarpScene, lens: DistortionModel, width: int, height: int) -> float:
    """Ideal offset ``n . p`` of the frame's inner edge."""
    n = np.asarray(scene.normal)
    q = ideal_border(lens, width, height) @ n
    q = q[np.isfinite(q)]
    if scene.frame_side > 0:
        return float(q.max() - scene.frame_depth_px)
    return float(q.min() + scene.frame_depth_px)


def _dust_spots(scene: HarpScene, width: int, height: int) -> tuple[DustSpot, ...]:
    rng = np.random.default_rng(scene.dust_seed)
    spots = []
    for _ in range(int(scene.dust)):
        spots.append(
            DustSpot(
                float(rng.uniform(0, width - 1)),
                float(rng.uniform(0, height - 1)),
                float(rng.uniform(3.0, 12.0)),
                float(rng.uniform(0.15, 0.45)),
            )
        )
    for spec in scene.dust_at:
        x, y, sig, depth = (float(v) for v in spec)
        if not (sig > 0 and 0 <= depth <= 1):
            raise ValueError(f"dust_at spot {spec}: needs sigma > 0 and depth in [0, 1]")
        spots.append(DustSpot(x, y, sig, depth))
    return tuple(spots)


# ---------------------------------------------------------------- render
def ideal_grid(lens: DistortionModel, width: int, height: int) -> np.ndarray:
    """The ideal coordinates ``lens.undistort_points`` of every pixel centre, shape ``(height, width, 2)``.

    What :func:`render_harp` evaluates the scene at; pass it as ``ideal=`` to render many
    frames through one lens without mapping every pixel again (``16 * width * height`` bytes).
    """
    return _ideal_rows(lens, int(width), 0, int(height))


def _ideal_rows(lens: DistortionModel, width: int, r0: int, r1: int) -> np.ndarray:
    """Rows ``r0:r1`` of :func:`ideal_grid`, shape ``(r1 - r0, width, 2)``."""
    gx, gy = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(r0, r1, dtype=np.float64))
    u = lens.undistort_points(np.stack([gx.ravel(), gy.ravel()], 1))
    return np.ascontiguousarray(u, dtype=np.float64).reshape(r1 - r0, width, 2)


def render_harp(
    width: int,
    height: int,
    scene: HarpScene = HarpScene(),
    lens: DistortionModel | None = None,
    noise_sigma: float = 1.5,
    shot_noise: bool = False,
    bit_depth: int = 8,
    seed: int = 0,
    exposure: float = 1.0,
    electrons_per_level: float = 40.0,
    chunk_pixels: int = 1 << 20,
    threads: int | None = None,
    ideal: np.ndarray | None = None,
) -> Rendered:
    """Render a harp image of ``width`` x ``height`` pixels with exact truth.

    Parameters
    ----------
    width, height : image size in pixels.
    scene : the harp (:class:`HarpScene`).
    lens : distortion model, distorted -> ideal; None means the identity.
    noise_sigma : read noise, Gaussian standard deviation in 8-bit grey levels.
    shot_noise : add Poisson photon noise (``electrons_per_level`` electrons
        per 8-bit grey level, e.g. 40 -> 8000 e- at level 200).
    bit_depth : 8 (uint8) or 16 (uint16; levels scaled by 65535/255).
    seed : non-negative seed of the noise; each block of
        :data:`NOISE_BLOCK_ROWS` rows uses ``default_rng((seed, block))``, so
        the image depends only on the seed (not on chunking or threads).
    exposure : multiplies all intensities before noise; saturates at the
        top of the range.
    chunk_pixels : pixels evaluated at once (bounds memory on 24 MP images).
    threads : chunks rendered in parallel (default: CPU count); the result
        does not depend on it.
    ideal : optional ``(height, width, 2)`` array of the ideal coordinates of
        every pixel centre, :func:`ideal_grid` ``(lens, width, height)``: when
        many frames are rendered through one lens (a simulated camera at one
        focus), computing it once saves about half of each render. The image
        is the same as without it.

    Returns
    -------
    Rendered
        The image (``image[y, x]``) with scene, lens, the visible string edges,
        dust spots and frame line.

    Notes
    -----
    The image formation model and the exact meaning of the truth are in the
    module docstring. Each pixel is evaluated at its centre, integer ``(x, y)``.
    """
    _check(width, height, scene, bit_depth, noise_sigma, exposure, seed)
    seed = int(seed)
    width, height = int(width), int(height)
    if lens is None:
        lens = IdentityModel()
    identity = isinstance(lens, IdentityModel)
    level = 1.0 if bit_depth == 8 else _LEVEL_16
    top = float(2**bit_depth - 1)

    s = scene.sigma_px
    n = np.asarray(scene.normal)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    base = float(n @ c) + scene.phase_px
    p, w2 = float(scene.spacing_px), 0.5 * float(scene.string_width_px)
    # string contrast: > 0 for dark strings (string_level < background), < 0 for bright ones
    dark = 1.0 - max(scene.string_level / scene.background, 0.0)
    reach = w2 + 10.0 * s  # beyond this a string edge contributes < 1e-23
    # the nearest string is always summed; neighbour j only if some point can lie within reach of it
    n_near = max(0, int(math.ceil(reach / p + 0.5)) - 1)
    frame_off = _frame_offset(scene, lens, width, height) if scene.frame else None
    frame_dark = 1.0 - min(max(scene.frame_level / scene.background, 0.0), 1.0)
    r2_corner = c[0] ** 2 + c[1] ** 2
    a_vig = ((1.0 - scene.vignetting) ** -0.5 - 1.0) / r2_corner

    if ideal is not None and (ideal.shape != (height, width, 2) or identity):
        raise ValueError(
            f"ideal must be ideal_grid(lens, {width}, {height}) of a non-identity lens, got shape {ideal.shape}"
        )
    image = np.empty((height, width), np.uint8 if bit_depth == 8 else np.uint16)
    xs = np.arange(width, dtype=np.float64)
    dust = _dust_spots(scene, width, height)

    def render_rows(r0: int, r1: int) -> None:
        yy = np.arange(r0, r1, dtype=np.float64)
        if identity:
            q = (n[0] * xs)[None, :] + (n[1] * yy)[:, None]
        else:
            rows = ideal[r0:r1] if ideal is not None else _ideal_rows(lens, width, r0, r1)
            q = (rows.reshape(-1, 2) @ n).reshape(r1 - r0, width)
        q -= base
        dd = q - p * np.round(q / p)
        cover = np.zeros_like(dd)
        for j in range(-n_near, n_near + 1):
            e = dd + j * p if j else dd
            near = np.abs(e) < reach  # erf evaluated only where it is not 0
            en = e[near]
            cover[near] += ndtr((en + w2) / s) - ndtr((en - w2) / s)
        val = 1.0 - dark * cover
        if frame_off is not None:
            qf = scene.frame_side * (q + base - frame_off)
            val *= 1.0 - frame_dark * ndtr(qf / s)
        if a_vig:
            v = 1.0 + a_vig * (((xs - c[0]) ** 2)[None, :] + ((yy - c[1]) ** 2)[:, None])
            val /= v * v
        for sp in dust:  # shadows on the sensor
            rad = 5.0 * sp.sigma
            y0, y1 = max(r0, int(sp.y - rad)), min(r1, int(sp.y + rad) + 2)
            if y0 >= y1:
                continue
            x0, x1 = max(0, int(sp.x - rad)), min(width, int(sp.x + rad) + 2)
            dx2 = (np.arange(x0, x1) - sp.x) ** 2
            dy2 = (np.arange(y0, y1) - sp.y) ** 2
            val[y0 - r0 : y1 - r0, x0:x1] *= 1.0 - sp.depth * np.exp(-(dy2[:, None] + dx2[None, :]) / (2 * sp.sigma**2))
        val *= exposure * scene.background * level
        # noise: one generator per block of NOISE_BLOCK_ROWS rows, seeded by (seed, block),
        # so that the image does not depend on chunking or threads
        for b0 in range(r0, r1, NOISE_BLOCK_ROWS):
            blk = val[b0 - r0 : b0 - r0 + NOISE_BLOCK_ROWS]
            if not (shot_noise or noise_sigma > 0):
                break
            rng = np.random.default_rng((seed, b0 // NOISE_BLOCK_ROWS))
            if shot_noise:
                blk[:] = rng.poisson(np.clip(blk, 0, None) * (electrons_per_level / level)) / (
                    electrons_per_level / level
                )
            if noise_sigma > 0:
                blk += rng.standard_normal(blk.shape) * (noise_sigma * level)
        np.rint(val, out=val)
        np.clip(val, 0, top, out=val)
        image[r0:r1] = val

    rows_per_chunk = max(1, chunk_pixels // width // NOISE_BLOCK_ROWS) * NOISE_BLOCK_ROWS
    chunks = [(r0, min(height, r0 + rows_per_chunk)) for r0 in range(0, height, rows_per_chunk)]
    workers = min(len(chunks), threads if threads is not None else (os.cpu_count() or 1))
    if workers > 1:  # numpy / scipy ufuncs release the GIL: chunks render in parallel
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(lambda rr: render_rows(*rr), chunks))
    else:
        for rr in chunks:
            render_rows(*rr)

    edges = string_edges(scene, lens, width, height)
    if frame_off is not None:
        keep = 6.0 * s
        edges = tuple(e for e in edges if scene.frame_side * (e.offset - frame_off) < -keep)
    return Rendered(image, scene, lens, edges, dust, frame_off)


# ---------------------------------------------------------------- truth
def visible_edges(
    rendered_or_edges: TruthSource | Iterable[EdgeTruth],
    lens: DistortionModel | None = None,
    width: int | None = None,
    height: int | None = None,
    margin: float = 2.0,
    step: float = 1.0,
    min_length_px: float = 50.0,
) -> list[tuple[EdgeTruth, np.ndarray]]:
    """Like :func:`true_edge_curves` but pairs each curve with its :class:`EdgeTruth`."""
    if isinstance(rendered_or_edges, TruthSource):
        r = rendered_or_edges
        edges = r.edges
        lens = r.lens if lens is None else lens
        width = r.width if width is None else width
        height = r.height if height is None else height
    else:
        edges = tuple(rendered_or_edges)
        if lens is None or width is None or height is None:
            raise ValueError("lens, width and height are required when passing edges")
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    border = ideal_border(lens, width, height)
    border = border[np.all(np.isfinite(border), axis=1)]
    lo = np.array([margin, margin])
    hi = np.array([width - 1 - margin, height - 1 - margin])
    result = []
    for e in edges:
        t_dir = np.asarray(e.along)  # along the line
        t_b = border @ t_dir
        span = t_b.max() - t_b.min()
        t = np.arange(t_b.min() - 0.05 * span, t_b.max() + 0.05 * span + step, step)
        ideal = e.ideal_points(t)
        # only points whose ideal position is near the footprint need inverting
        pts = lens.distort_points(ideal)
        inside = np.all(np.isfinite(pts), axis=1)
        inside &= np.all((pts >= lo) & (pts <= hi), axis=1)
        if not inside.any():
            continue
        # longest contiguous run of inside points
        idx = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(np.int8), [0]])))
        starts, ends = idx[0::2], idx[1::2]
        j = int(np.argmax(ends - starts))
        curve = pts[starts[j] : ends[j]]
        if len(curve) < 2:
            continue
        length = float(np.sum(np.hypot(*np.diff(curve, axis=0).T)))
        if length < min_length_px:
            continue
        result.append((e, curve))
    return result


def true_edge_curves(
    rendered_or_edges: TruthSource | Iterable[EdgeTruth],
    lens: DistortionModel | None = None,
    width: int | None = None,
    height: int | None = None,
    margin: float = 2.0,
    step: float = 1.0,
    min_length_px: float = 50.0,
) -> list[np.ndarray]:
    """Exact distorted string-edge curves, clipped to the image minus ``margin``.

    Parameters
    ----------
    rendered_or_edges : a :class:`Rendered` or any :class:`TruthSource` (a realistic
        :class:`pipeline.realism.Shot`; its lens and size are used unless
        given) or a sequence of :class:`EdgeTruth` (then ``lens``, ``width``
        and ``height`` are required).
    margin : points closer than this to the image border are dropped. The
        default 2 px is about where a sub-pixel detector with smoothing
        sigma = 1 px stops finding edge points. :math:`d` and :math:`d_{max}`
        depend (by a few per cent) on how much of each edge is included, so
        compare a measurement with the truth over the same extent.
    step : spacing of the points along the *ideal* line (pixels); the spacing
        along the distorted curve differs by the local lens scale.
    min_length_px : curves shorter than this (after clipping) are dropped.

    Returns
    -------
    list of (N, 2) float64 arrays
        ``lens.distort_points`` of points on each ideal edge (the straight line, or the
        bent curve :meth:`EdgeTruth.ideal_points` of an edge with a shape), ordered
        along the line direction ``(n_y, -n_x)``; one contiguous run per edge
        (the longest, if the lens folds the line out of the image and back),
        in the order of ``edges``.

    Notes
    -----
    Strings hidden by the frame (or within 6 sigma of it) are not in
    ``Rendered.edges``; dust shadows are not removed from the curves (a
    shadow over an edge moves what a gradient detector finds there).
    """
    return [c for _, c in visible_edges(rendered_or_edges, lens, width, height, margin, step, min_length_px)]
