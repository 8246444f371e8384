r"""The realistic harp simulator: shots of a physical harp on a turntable through an exact
lens, with the effects a real photograph has, and their exact truth.

What a shot is made of, in order (each effect optional, all off in :class:`Effects`'s
defaults, drawn from physical ranges by :func:`draw_effects`):

=====================  ==========================================  =============================  ==========================
effect                 model                                       drawn range                    where it is documented
=====================  ==========================================  =============================  ==========================
string shapes          sag, bow, kink, twist per string, fixed     material constants, tension    :mod:`pipeline.harp_scene`
                       to the harp (sag follows gravity)           15-45 % of breaking load
harp on the turntable  strings at ``angle0 + dir * turntable``,    axis within 1 % of the         :class:`~pipeline.harp_scene.HarpMount`
                       about an axis near the image centre         diagonal of the centre
lens                   any exact ``DistortionModel``               :mod:`pipeline.lens_population`
field-dependent blur   isotropic PSF + astigmatic defocus          sigma 0.35-0.7 px, corners     :mod:`pipeline.optics`
                       growing as rho^2, tilt                      0.1-0.8 px, tilt 0-0.3 px
back-light             lamp behind a diffuser (cos^3) and the      lamp 1-3 half-diagonals away,  :mod:`pipeline.harp_scene`
                       sheet's mottle, fixed to the harp           mottle 0.5-2 %, 0.5-3 mm
vignetting             cos^4-like, sensor-fixed                    15-45 % at the corners         :mod:`pipeline.optics`
shot and read noise    Poisson electrons, Gaussian read noise      full well 15-40 ke-, read      :mod:`pipeline.sensor`
                                                                   2-8 e-, exposure 55-90 %
Bayer sensor           RGGB, raw channel responses                 R 0.45-0.75, B 0.5-0.85        :mod:`pipeline.sensor`
demosaicing            OpenCV bilinear / edge-aware, or half-size  one of the three               :mod:`pipeline.sensor`
tone curve, 8 bits     BT.709 or sRGB                              one of the two                 :mod:`pipeline.sensor`
JPEG                   libjpeg at a quality                        90-97 (only with ``jpeg``)     :mod:`pipeline.sensor`
=====================  ==========================================  =============================  ==========================

Rendering (:func:`render_shot`). Every raw sample (a sensor pixel; with a half-size
conversion, the 2x2 native pixels of each output pixel, at their own positions
:math:`x_{out} = (x_{native} - 1/2)/2`) is mapped to the ideal image by the lens,
:math:`u = U(x)`, and to harp coordinates :math:`(a, b)` by the pose. Its relative
irradiance is

.. math::
    E(x) = V(x)\,B(a, b)\,\Bigl[1 - (1 - \tau)\sum_k
        \bigl(\Phi(\tfrac{e_k + h^-_k}{\sigma_n(x)}) - \Phi(\tfrac{e_k - h^+_k}{\sigma_n(x)})\bigr)\Bigr],
    \qquad e_k = b - b_k - \delta_k(a)

(the two strings nearest to the sample), with :math:`h^\mp_k(a)` the half-widths,
:math:`\tau` the strings' transmission, :math:`B` the back-light, :math:`V` the vignetting
and :math:`\sigma_n^2 = n^T\Sigma(x)n + s^2/12` the PSF along the string normal plus the
box of a sample of side :math:`s` (1, or 1/2 for half-size). Then
:func:`pipeline.sensor.expose` (electrons, noise, ADC) and
:func:`pipeline.sensor.develop` (demosaicing, white balance, grey, tone, bits, JPEG).
The blur is applied along the string's normal in the ideal image; through a lens that
rotates directions by :math:`\epsilon` rad locally (< 0.03 rad at the corners of the
lenses here) the astigmatic variance differs by :math:`O(\epsilon)` of the corner defocus.

Exact truth (:class:`Shot`). ``Shot.edges`` holds every string edge whose curve reaches
the image, as :class:`~pipeline.render.EdgeTruth` with its shape (the bent ideal curve,
:meth:`~pipeline.render.EdgeTruth.ideal_points`), so that
:func:`pipeline.render.visible_edges` and the tests' whole-edge tracing
(``tests/pipeline/_harp_truth.py``) follow the *bent* edge exactly through the lens;
``Shot.harp.strings[k]`` gives each string's own deviation in harp coordinates
(:meth:`~pipeline.harp_scene.StringShape.deviation`). The truth is the geometric edge
(the half-level crossing of an isolated edge in linear light): what demosaicing, the
tone curve and the field-dependent blur do to a detector's edge is the realism this
module adds, not part of the truth.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from pipeline.backlight import Backlight
from pipeline.harp_scene import COIL_SET_VARIATION, Harp, HarpMount, HarpPose, draw_harp, edge_offsets
from pipeline.models.base import DistortionModel, IdentityModel
from pipeline.optics import PIXEL_BOX_VARIANCE, FieldBlur, Vignetting
from pipeline.render import EdgeTruth, ideal_border
from pipeline.sensor import Development, Sensor, develop, expose, raw_scale

# ---------------------------------------------------------------- drawn ranges
BLUR_SIGMA_PX = (0.35, 0.7)
"""Isotropic PSF (output px): diffraction at f/8 + anti-aliasing filter (:mod:`pipeline.optics`)."""
BLUR_CORNER_PX = (0.1, 0.8)
"""Defocus standard deviation at the corners, tangential and sagittal, each (:mod:`pipeline.optics`)."""
BLUR_TILT_PX = (0.0, 0.3)
"""A tilt's linear defocus at the corner."""
VIGNETTING_CORNER = (0.15, 0.45)
"""Fall-off at the corners (:mod:`pipeline.optics`)."""
LAMP_DISTANCE = (1.0, 3.0)
"""The back-light lamp's distance behind the sheet, in half-diagonals of the image."""
LAMP_OFFSET = 0.3
"""Largest distance of the lamp's foot from the turntable axis, in half-diagonals."""
MOTTLE = (0.005, 0.02)
"""RMS of the sheet's mottle (relative)."""
MOTTLE_SCALE_MM = (0.5, 3.0)
"""Correlation length of the sheet's mottle on the harp (mm)."""
EXPOSURE = (0.55, 0.9)
"""Fraction of the full well the lit sheet fills (green)."""
FULL_WELL_E = (15000.0, 40000.0)
"""Native pixel full well (:mod:`pipeline.sensor`)."""
READ_NOISE_E = (2.0, 8.0)
"""Read noise at base ISO (:mod:`pipeline.sensor`)."""
RESPONSE_R = (0.45, 0.75)
RESPONSE_B = (0.5, 0.85)
"""Raw responses of R and B to the back-light relative to G (:mod:`pipeline.sensor`)."""
JPEG_QUALITY = (90, 97)
"""A camera's "fine" JPEG, libjpeg scale."""
SPAN = (1.3, 1.8)
"""The strings' free length in image diagonals (the frame stays outside the image)."""
KEEP_LENS_MAP_SAMPLES = 12_000_000
"""Largest number of raw samples whose lens map :func:`render_shots` keeps for all its shots (16 bytes each)."""
AXIS_OFFSET = 0.01
"""Standard deviation of the turntable axis from the image centre, per axis, in image diagonals."""


@dataclass(frozen=True)
class Effects:
    """The optional effects of a realistic shot (all off by default; module docstring).

    Parameters
    ----------
    blur : the PSF over the field (default: the clean renderer's uniform 0.7 px).
    vignetting : sensor-fixed fall-off, or None.
    backlight : the sheet's brightness in harp coordinates, or None (uniform).
    sensor : exposure, noise, colour filter array.
    development : the raw conversion (demosaicing, tone, bits, JPEG).
    """

    blur: FieldBlur = FieldBlur()
    vignetting: Vignetting | None = None
    backlight: Backlight | None = None
    sensor: Sensor = Sensor()
    development: Development = Development()


@dataclass(frozen=True)
class Shot:
    """A rendered shot and its exact truth.

    ``image[y, x]`` (8- or 16-bit grey); ``lens`` the exact lens it was rendered through;
    ``harp`` and ``pose`` the harp and where it was; ``edges`` the string edges whose
    curves reach the image, with their shapes (a :class:`~pipeline.render.TruthSource`:
    :func:`pipeline.render.visible_edges` traces them through the lens); ``seed`` the seed
    of its noise.
    """

    image: np.ndarray
    lens: DistortionModel
    harp: Harp
    pose: HarpPose
    effects: Effects
    edges: tuple[EdgeTruth, ...]
    seed: int

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])

    def string_deviation(self, string_index: int, a: np.ndarray) -> np.ndarray:
        """String ``string_index``'s own centre-line deviation at harp positions ``a`` (no sag)."""
        return self.harp.strings[string_index].deviation(a)


def _deviation_bound(harp: Harp) -> float:
    """An upper bound (px) on how far any edge lies from its straight line."""
    t = harp.table
    cols = [4, 5, 6, 7, 9, 11, 14, 15]  # sag, bows, kink, ovality, off-centre, pick
    return float(np.max(np.sum(np.abs(t[:, cols]), axis=1)))


def string_cover(
    harp: Harp, a: np.ndarray, b: np.ndarray, gravity_cos: float, sigma_at: Callable[[np.ndarray | None], np.ndarray]
) -> np.ndarray:
    r"""How much of each sample the strings cover, blurred: the sum over the two nearest strings
    of :math:`\Phi((e + h^-)/\sigma) - \Phi((e - h^+)/\sigma)` (module docstring).

    ``sigma_at(mask)`` returns the blur :math:`\sigma_n` of the samples ``mask`` selects
    (it is evaluated only near the strings); ``sigma_at(None)`` an upper bound of it.
    """
    p = harp.spacing_px
    kf = (b - harp.first_position_px) / p
    k1 = harp.nearest(b)
    k2 = np.clip(k1 + np.where(kf >= k1, 1, -1), 0, len(harp.strings) - 1)
    reach = float(np.max(harp.table[:, 1])) + _deviation_bound(harp) + 10.0 * float(np.max(sigma_at(None)))
    cover = np.zeros_like(b)
    for j, kk in enumerate((k1, k2)):
        near = np.abs(b - harp.table[kk, 0]) < reach
        if j:
            near &= k2 != k1
        if not near.any():
            continue
        centre, minus, plus = edge_offsets(harp.table, kk[near], a[near], gravity_cos)
        e = b[near] - centre
        s = sigma_at(near)
        cover[near] += ndtr((e + minus) / s) - ndtr((e - plus) / s)
    return cover


def shot_edges(lens: DistortionModel, harp: Harp, pose: HarpPose, width: int, height: int) -> tuple[EdgeTruth, ...]:
    """The edges of ``harp.edges(pose)`` whose curves reach the ideal footprint of the image."""
    border = ideal_border(lens, width, height)
    border = border[np.all(np.isfinite(border), axis=1)]
    bound = _deviation_bound(harp) + 1.0
    out = []
    for e in harp.edges(pose):
        q = border @ np.asarray(e.normal) - e.offset
        if q.min() < bound and q.max() > -bound:
            out.append(e)
    return tuple(out)


def sample_positions(width: int, height: int, effects: Effects) -> tuple[np.ndarray, np.ndarray]:
    """The output-image coordinates ``(x, y)`` (1-D, columns and rows) of the raw samples:
    the pixel centres, or with a half-size conversion the native pixels' centres
    :math:`(i - 1/2)/2` (:func:`pipeline.sensor.raw_scale`)."""
    f = raw_scale(effects.sensor, effects.development)
    xs = (np.arange(width * f, dtype=np.float64) - 0.5 * (f - 1)) / f
    ys = (np.arange(height * f, dtype=np.float64) - 0.5 * (f - 1)) / f
    return xs, ys


def raw_ideal_grid(lens: DistortionModel, width: int, height: int, effects: Effects) -> np.ndarray:
    """``lens.undistort_points`` of every raw sample (:func:`sample_positions`), ``(rows, columns, 2)``."""
    xs, ys = sample_positions(width, height, effects)
    gx, gy = np.meshgrid(xs, ys)
    out: np.ndarray = lens.undistort_points(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(len(ys), len(xs), 2)
    return out


def render_shot(
    lens: DistortionModel | None,
    harp: Harp,
    mount: HarpMount,
    turntable_deg: float,
    width: int,
    height: int,
    effects: Effects = Effects(),
    seed: int = 0,
    chunk_pixels: int = 1 << 20,
    threads: int | None = None,
    ideal: np.ndarray | None = None,
) -> Shot:
    """Render one shot of ``harp`` at ``turntable_deg`` through ``lens`` (module docstring).

    Parameters
    ----------
    lens : the exact lens (distorted -> ideal), None for the identity.
    harp, mount, turntable_deg : the harp, how it sits on the turntable, the turntable angle.
    width, height : the output image's size (px).
    effects : the optional effects (:class:`Effects`).
    seed : the seed of the shot's noise (``numpy.random.default_rng(seed)``).
    chunk_pixels : raw samples evaluated at once (bounds the memory).
    threads : chunks rendered in parallel (default: the CPU count); the image does not depend on it.
    ideal : :func:`raw_ideal_grid` of this lens, size and effects, to render many shots through
        one lens without mapping every sample again (the image is the same).

    Returns
    -------
    Shot
        The image and its exact truth.
    """
    width, height = int(width), int(height)
    if width < 2 or height < 2:
        raise ValueError(f"image size must be at least 2x2, got {width}x{height}")
    if int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    lens = IdentityModel() if lens is None else lens
    pose = mount.pose(turntable_deg)
    f = raw_scale(effects.sensor, effects.development)
    rw, rh = width * f, height * f
    box = PIXEL_BOX_VARIANCE / (f * f)
    irradiance = np.empty((rh, rw))
    xs, all_ys = sample_positions(width, height, effects)

    if ideal is not None and ideal.shape != (rh, rw, 2):
        raise ValueError(f"ideal must be raw_ideal_grid(lens, {width}, {height}, effects), of shape {(rh, rw, 2)}")

    def rows_of(r0: int, r1: int) -> None:
        gx, gy = np.meshgrid(xs, all_ys[r0:r1])
        if ideal is not None:
            u = ideal[r0:r1]
        else:
            u = lens.undistort_points(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(r1 - r0, rw, 2)
        a, b = pose.to_harp(u)

        def sigma_at(mask: np.ndarray | None) -> np.ndarray:
            if mask is None:  # a bound: the largest blur anywhere in the image
                return np.array(math.sqrt(effects.blur.max_variance() + box))
            return np.sqrt(effects.blur.variance_along(gx[mask], gy[mask], pose.normal, width, height) + box)

        val = 1.0 - (1.0 - harp.transmission) * string_cover(harp, a, b, pose.gravity_cos, sigma_at)
        if effects.backlight is not None:
            val *= effects.backlight.at(a, b)
        if effects.vignetting is not None:
            val *= effects.vignetting.at(gx, gy, width, height)
        irradiance[r0:r1] = val

    rows = max(1, chunk_pixels // rw)
    chunks = [(r0, min(rh, r0 + rows)) for r0 in range(0, rh, rows)]
    workers = min(len(chunks), threads if threads is not None else (os.cpu_count() or 1))
    if workers > 1:  # numpy ufuncs release the GIL: chunks render in parallel (same result)
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(lambda rr: rows_of(*rr), chunks))
    else:
        for rr in chunks:
            rows_of(*rr)
    raw = expose(irradiance, effects.sensor, np.random.default_rng(int(seed)))
    image = develop(raw, effects.sensor, effects.development)
    return Shot(image, lens, harp, pose, effects, shot_edges(lens, harp, pose, width, height), int(seed))


def shot_seed(seed: int, index: int) -> int:
    """The noise seed of shot ``index`` of a session seeded ``seed`` (a 63-bit hash of both)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1, np.uint64)[0] >> np.uint64(1))


def render_shots(
    lens: DistortionModel | None,
    harp: Harp,
    mount: HarpMount,
    turntable_angles_deg: Sequence[float],
    width: int,
    height: int,
    effects: Effects = Effects(),
    seed: int = 0,
) -> tuple[Shot, ...]:
    """One :func:`render_shot` per turntable angle, shot ``i`` seeded :func:`shot_seed` ``(seed, i)``.

    The lens is applied to every raw sample once for all the shots (:func:`raw_ideal_grid`)
    when there are at most :data:`KEEP_LENS_MAP_SAMPLES` of them.
    """
    f = raw_scale(effects.sensor, effects.development)
    ideal = None
    if lens is not None and len(turntable_angles_deg) > 1 and width * height * f * f <= KEEP_LENS_MAP_SAMPLES:
        ideal = raw_ideal_grid(lens, width, height, effects)
    return tuple(
        render_shot(lens, harp, mount, ang, width, height, effects, shot_seed(seed, i), ideal=ideal)
        for i, ang in enumerate(turntable_angles_deg)
    )


# ---------------------------------------------------------------- drawn sessions
@dataclass(frozen=True)
class Session:
    """A harp, its mount and the effects of a camera, all drawn from one seed (:func:`realistic_session`)."""

    seed: int
    harp: Harp
    mount: HarpMount
    effects: Effects


def draw_effects(
    seed: int,
    width: int,
    height: int,
    mm_per_px: float,
    jpeg: bool = False,
    demosaic: str | None = None,
    tone: str | None = None,
) -> Effects:
    """Every effect with its magnitude drawn uniformly from its range (module constants).

    ``mm_per_px`` converts the sheet's mottle scale to pixels; ``jpeg`` adds JPEG
    compression (a camera's JPEG instead of a raw conversion); ``demosaic`` and ``tone``
    fix those choices (None: drawn).
    """
    rng = np.random.default_rng([int(seed), 0xEFFEC7])
    half_diag = 0.5 * math.hypot(width, height)
    blur = FieldBlur(
        sigma_px=float(rng.uniform(*BLUR_SIGMA_PX)),
        corner_tangential_px=float(rng.uniform(*BLUR_CORNER_PX)),
        corner_sagittal_px=float(rng.uniform(*BLUR_CORNER_PX)),
        tilt_px=float(rng.uniform(*BLUR_TILT_PX)),
        tilt_deg=float(rng.uniform(0.0, 360.0)),
    )
    r, phi = LAMP_OFFSET * half_diag * math.sqrt(float(rng.uniform())), float(rng.uniform(0, 2 * math.pi))
    backlight = Backlight(
        lamp_px=(r * math.cos(phi), r * math.sin(phi)),
        lamp_distance_px=float(rng.uniform(*LAMP_DISTANCE)) * half_diag,
        mottle=float(rng.uniform(*MOTTLE)),
        mottle_scale_px=float(rng.uniform(*MOTTLE_SCALE_MM)) / mm_per_px,
        seed=int(rng.integers(2**31)),
    )
    sensor = Sensor(
        exposure=float(rng.uniform(*EXPOSURE)),
        shot_noise=True,
        full_well_e=float(rng.uniform(*FULL_WELL_E)),
        read_noise_e=float(rng.uniform(*READ_NOISE_E)),
        cfa="RGGB",
        channel_response=(float(rng.uniform(*RESPONSE_R)), 1.0, float(rng.uniform(*RESPONSE_B))),
    )
    dm = str(rng.choice(["bilinear", "ea", "half-size"]))
    tc = str(rng.choice(["bt709", "srgb"]))
    q = int(rng.integers(JPEG_QUALITY[0], JPEG_QUALITY[1] + 1))
    development = Development(
        demosaic=dm if demosaic is None else demosaic,
        tone=tc if tone is None else tone,
        jpeg_quality=q if jpeg else None,
    )
    return Effects(blur, Vignetting(float(rng.uniform(*VIGNETTING_CORNER))), backlight, sensor, development)


def realistic_session(
    seed: int,
    width: int,
    height: int,
    spacing_px: float | tuple[float, float] = (40.0, 130.0),
    string_width_px: float | tuple[float, float] = (2.5, 4.0),
    angle0_deg: float | None = None,
    material: str | None = None,
    jpeg: bool = False,
    demosaic: str | None = None,
    tone: str | None = None,
    coil_set_variation: float = COIL_SET_VARIATION,
) -> Session:
    """A harp (:func:`~pipeline.harp_scene.draw_harp`), its mount and the camera's effects
    (:func:`draw_effects`), drawn from ``seed`` for ``width`` x ``height`` images.

    ``spacing_px`` and ``string_width_px`` are values or ``(low, high)`` ranges drawn
    uniformly (what the set-up's distance and the strings make of the image);
    ``angle0_deg`` the strings' angle at turntable 0 (None: drawn); the other arguments
    go to :func:`~pipeline.harp_scene.draw_harp` and :func:`draw_effects`.
    """
    rng = np.random.default_rng([int(seed), 0x4A5B])

    def value(v: float | tuple[float, float]) -> float:
        return float(rng.uniform(*v)) if isinstance(v, tuple) else float(v)

    pitch, w = value(spacing_px), value(string_width_px)
    diag = math.hypot(width, height)
    centre = (
        (width - 1) / 2.0 + float(rng.normal(0, AXIS_OFFSET)) * diag,
        (height - 1) / 2.0 + float(rng.normal(0, AXIS_OFFSET)) * diag,
    )
    reach = 0.5 * diag * 1.1 + math.hypot(centre[0] - (width - 1) / 2.0, centre[1] - (height - 1) / 2.0)
    n = 2 * int(math.ceil(reach / pitch)) + 3
    harp = draw_harp(
        int(rng.integers(2**31)),
        n,
        pitch,
        w,
        float(rng.uniform(*SPAN)) * diag,
        material=material,
        visible_px=0.5 * diag,
        coil_set_variation=coil_set_variation,
    )
    mount = HarpMount(
        centre,
        float(rng.uniform(0.0, 360.0)) if angle0_deg is None else float(angle0_deg),
        int(rng.choice([-1, 1])),
        90.0 + float(rng.normal(0.0, 1.0)),
    )
    effects = draw_effects(int(rng.integers(2**31)), width, height, harp.mm_per_px, jpeg, demosaic, tone)
    return Session(int(seed), harp, mount, effects)
