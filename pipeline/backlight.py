r"""The back-lit sheet behind the realistic simulator's harp (:mod:`pipeline.harp_scene`).

:class:`Backlight` is the sheet's brightness in harp coordinates (it turns with the
harp): a lamp at distance :math:`D` behind a Lambertian diffuser lights it as
:math:`(1 + |p - p_L|^2/D^2)^{-3/2}` (the :math:`\cos^3` law of a point source on a
plane), times :math:`1 + m(p)`, the sheet's mottle, a stationary Gaussian random texture
of RMS :math:`m` and autocorrelation :math:`\exp(-r^2/\ell^2)`, :math:`\ell` = ``mottle_scale_px``
(paper and opal diffusers:
fibre flocs of 0.5–3 mm, 0.5–2 % RMS).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@lru_cache(maxsize=8)
def _mottle_tile(seed: int, n: int) -> np.ndarray:
    """A periodic ``n x n`` Gaussian random texture of unit RMS, autocorrelation ``exp(-r^2 / 16)`` (r in cells):
    white noise filtered by a Gaussian of 2 cells, correlation length (1/e) 4 cells."""
    rng = np.random.default_rng([seed, 0x5EE7])
    f = np.fft.fftfreq(n)
    k2 = f[:, None] ** 2 + f[None, :] ** 2
    spectrum = np.fft.fft2(rng.standard_normal((n, n))) * np.exp(-2.0 * math.pi**2 * 4.0 * k2)
    tex = np.real(np.fft.ifft2(spectrum))
    tex -= tex.mean()
    out: np.ndarray = tex / tex.std()
    out.setflags(write=False)
    return out


MOTTLE_TILE = 512
"""Cells of the periodic mottle texture per side (4 cells per correlation length: it repeats
every 128 correlation lengths)."""


@dataclass(frozen=True)
class Backlight:
    """The back-lit sheet's relative brightness in harp coordinates (module docstring).

    Parameters
    ----------
    lamp_px : the foot of the lamp on the sheet, harp coordinates ``(a, b)``.
    lamp_distance_px : the lamp's distance behind the sheet (harp px); ``inf``: uniform.
    mottle, mottle_scale_px : the sheet texture's RMS (relative) and correlation length.
    seed : the texture's seed (the texture is fixed to the sheet).
    """

    lamp_px: tuple[float, float] = (0.0, 0.0)
    lamp_distance_px: float = math.inf
    mottle: float = 0.0
    mottle_scale_px: float = 12.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.lamp_distance_px > 0:
            raise ValueError(f"lamp_distance_px must be > 0, got {self.lamp_distance_px}")
        if not (0 <= self.mottle < 0.5 and self.mottle_scale_px > 0):
            raise ValueError(
                f"mottle must be in [0, 0.5) and mottle_scale_px > 0, got {self.mottle}, {self.mottle_scale_px}"
            )

    def at(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Relative brightness at harp points ``(a, b)`` (1 at the lamp's foot, before the mottle)."""
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        out = np.ones(np.broadcast(a, b).shape)
        if math.isfinite(self.lamp_distance_px):
            r2 = ((a - self.lamp_px[0]) ** 2 + (b - self.lamp_px[1]) ** 2) / self.lamp_distance_px**2
            out = (1.0 + r2) ** -1.5
        if self.mottle > 0:
            out = out * (1.0 + self.mottle * self._texture(a, b))
        return out

    def _texture(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The unit-RMS mottle at ``(a, b)``: the periodic tile, bilinear, 4 cells per correlation length."""
        import cv2

        tile = _mottle_tile(int(self.seed), MOTTLE_TILE).astype(np.float32)
        n = float(MOTTLE_TILE)
        # cell coordinates reduced modulo the tile (float32 keeps 1e-4 cell there); tile rows are a, columns b
        ga = np.mod(a * (4.0 / self.mottle_scale_px), n).astype(np.float32)
        gb = np.mod(b * (4.0 / self.mottle_scale_px), n).astype(np.float32)
        shape = ga.shape
        rows = ga.reshape(-1, shape[-1]) if ga.ndim >= 2 else ga.reshape(-1, 1)
        cols = gb.reshape(rows.shape)
        flat = cv2.remap(tile, cols, rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        out: np.ndarray = flat.reshape(shape).astype(np.float64)
        return out
