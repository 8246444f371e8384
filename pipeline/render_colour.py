r"""Synthetic colour and shaded harp shots: Bayer mosaics through exact per-channel lens maps.

Each colour channel ``c`` of a lens with lateral chromatic aberration has its own
map from sensor pixels to the ideal image, :math:`U_c`. The mosaic is made of the
three channels' images, each rendered through its own map
(:func:`pipeline.render.render_harp`, noise-free, 16 bits), of which every pixel
keeps the colour of its site in the pattern (:mod:`pipeline.cfa`): the red pixels
of the mosaic *are* the red image at the red sites, so the truth of each channel
is exact (each ideal string edge, traced through :math:`U_c`).

Light
-----
Before the noise every pixel is multiplied by a *shading* :math:`S(x)`: the lens's
vignetting :math:`V(x)` (a function of the position on the sensor) times the
back-light's own non-uniformity :math:`L`, which is part of the scene and turns with
the harp: with the harp at angle :math:`\theta` (its ``angle_deg``), the scene point
seen at the ideal position :math:`u = U(x)` is the back-light at
:math:`R(-\theta)(u - c)` in the harp's own coordinates (:func:`backlit_shading`,
:math:`c` the ideal image centre, the turntable's axis). The channel gains (a
white balance) multiply the same way.

Noise, as :func:`pipeline.render.render_harp`: optional shot noise (Poisson,
``electrons_per_level`` per 8-bit level), Gaussian read noise ``noise_sigma`` (8-bit
levels; a 16-bit image scales it by 65535/255), rounding and clipping; one generator
per shot, seeded by ``seed``.

References
----------
.. [1] Z. Tang et al., JOSA A 29(10), 2012 (the harp; :mod:`pipeline.render`).
.. [2] B. E. Bayer, US patent 3,971,065, 1976.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from pipeline.cfa import plane_offsets
from pipeline.models.base import DistortionModel, IdentityModel
from pipeline.render import HarpScene, ideal_grid, render_harp

Floats = NDArray[np.float64]
_LEVEL_16 = 65535.0 / 255.0
COLOURS = ("R", "G", "B")


@dataclass(frozen=True)
class RenderedColour:
    """A rendered shot: the image (a mosaic, or a grey image) and what made it."""

    image: NDArray[np.uint16] | NDArray[np.uint8]
    pattern: str | None
    scene: HarpScene
    lenses: Mapping[str, DistortionModel]
    shading: Floats | None


def _noisy(
    val: Floats, noise_sigma: float, shot_noise: bool, electrons_per_level: float, seed: int, bit_depth: int
) -> NDArray[np.uint16] | NDArray[np.uint8]:
    """``val`` (8-bit scale) with noise, rounded and clipped to ``bit_depth``."""
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth must be 8 or 16, got {bit_depth}")
    level = 1.0 if bit_depth == 8 else _LEVEL_16
    rng = np.random.default_rng(int(seed))
    out = np.clip(val, 0.0, None) * level
    if shot_noise:
        out = rng.poisson(out * (electrons_per_level / level)) / (electrons_per_level / level)
    if noise_sigma > 0:
        out = out + rng.standard_normal(out.shape) * (noise_sigma * level)
    out = np.clip(np.rint(out), 0, 2**bit_depth - 1)
    if bit_depth == 8:
        return out.astype(np.uint8)
    return out.astype(np.uint16)


def _clean(width: int, height: int, scene: HarpScene, lens: DistortionModel | None) -> Floats:
    """The noise-free image through ``lens`` (8-bit scale, no vignetting: :func:`backlit_shading` does it)."""
    r = render_harp(width, height, replace(scene, vignetting=0.0), lens=lens, noise_sigma=0.0, bit_depth=16)
    return r.image.astype(np.float64) / _LEVEL_16


def backlit_shading(
    width: int,
    height: int,
    vignetting: Callable[[Floats], Floats] | None = None,
    backlight: Callable[[Floats], Floats] | None = None,
    angle_deg: float = 0.0,
    lens: DistortionModel | None = None,
) -> Floats:
    """:math:`S(x) = V(x)\\,L(R(-\\theta)(U(x) - c))` on every pixel centre, shape ``(height, width)``.

    ``vignetting`` and ``backlight`` take ``(N, 2)`` points (pixels; the back-light's
    relative to the axis) and return ``(N,)`` factors; None is 1. ``lens`` is
    :math:`U` (None: the identity).
    """
    gx, gy = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    x = np.column_stack([gx.ravel(), gy.ravel()])
    s = np.ones(len(x))
    if vignetting is not None:
        s = s * np.asarray(vignetting(x), np.float64)
    if backlight is not None:
        u = x if lens is None or isinstance(lens, IdentityModel) else ideal_grid(lens, width, height).reshape(-1, 2)
        c = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        a = np.radians(angle_deg)
        rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])  # R(-theta)
        s = s * np.asarray(backlight((u - c) @ rot.T), np.float64)
    return s.reshape(height, width)


def render_mosaic(
    width: int,
    height: int,
    scene: HarpScene,
    lenses: Mapping[str, DistortionModel | None],
    pattern: str = "RGGB",
    gains: Mapping[str, float] | None = None,
    shading: Floats | None = None,
    noise_sigma: float = 1.5,
    shot_noise: bool = False,
    electrons_per_level: float = 40.0,
    bit_depth: int = 16,
    seed: int = 0,
) -> RenderedColour:
    """A Bayer mosaic of a harp, each channel through its own exact lens map.

    Parameters
    ----------
    width, height : mosaic size (even).
    scene : the harp (:class:`~pipeline.render.HarpScene`; its ``vignetting`` is not
        used: pass ``shading``).
    lenses : ``{"R": U_r, "G": U_g, "B": U_b}``, distorted -> ideal (None: identity).
    pattern : the CFA pattern (:data:`pipeline.cfa.CFA_PATTERNS`).
    gains : per-channel factors (white balance), default 1.
    shading : ``(height, width)`` factor on every pixel (:func:`backlit_shading`).
    noise_sigma, shot_noise, electrons_per_level, bit_depth, seed : the noise
        (module docstring).
    """
    if width % 2 or height % 2:
        raise ValueError(f"a Bayer mosaic has an even size, got {width}x{height}")
    missing = set(COLOURS) - set(lenses)
    if missing:
        raise ValueError(f"lenses must give R, G and B; missing {sorted(missing)}")
    val = np.empty((height, width))
    for name, (ox, oy) in plane_offsets(pattern).items():
        colour = name[0]
        img = _clean(width, height, scene, lenses[colour])
        g = 1.0 if gains is None else float(gains.get(colour, 1.0))
        val[oy::2, ox::2] = g * img[oy::2, ox::2]
    if shading is not None:
        val *= shading
    done = {c: (lens if lens is not None else IdentityModel()) for c, lens in lenses.items()}
    image = _noisy(val, noise_sigma, shot_noise, electrons_per_level, seed, bit_depth)
    return RenderedColour(image, pattern.upper(), scene, done, shading)


def render_shaded(
    width: int,
    height: int,
    scene: HarpScene,
    lens: DistortionModel | None = None,
    shading: Floats | None = None,
    noise_sigma: float = 1.5,
    shot_noise: bool = False,
    electrons_per_level: float = 40.0,
    bit_depth: int = 16,
    seed: int = 0,
) -> RenderedColour:
    """A grey harp shot multiplied by ``shading`` (vignetting and back-light, :func:`backlit_shading`)."""
    val = _clean(width, height, scene, lens)
    if shading is not None:
        val *= shading
    image = _noisy(val, noise_sigma, shot_noise, electrons_per_level, seed, bit_depth)
    return RenderedColour(image, None, scene, {"G": lens if lens is not None else IdentityModel()}, shading)
