"""Rendered and measured synthetic harp shots, cached for the whole test run (test helper)."""

from __future__ import annotations

from functools import cache

import numpy as np

from pipeline.models import PolynomialModel, RadialModel
from pipeline.models.polynomial import monomial_exponents

W, H = 1000, 750
ANGLES = (2.0, 32.0, 62.0, 92.0, 122.0, 152.0)
NOISE = 1.5


def nonradial_lens() -> PolynomialModel:
    """Barrel-like radial part plus non-radial terms (xi^2 eta, xi^3, xi^5)."""
    m = PolynomialModel.identity(W, H, 5)
    a, b = np.array(m.a), np.array(m.b)
    ex = {e: i for i, e in enumerate(monomial_exponents(5))}
    a[ex[3, 0]] = a[ex[1, 2]] = 0.02
    b[ex[2, 1]] = b[ex[0, 3]] = 0.02
    a[ex[2, 1]] = 0.004
    b[ex[3, 0]] = -0.003
    a[ex[5, 0]] = 0.002
    return PolynomialModel(m.center, 5, tuple(a), tuple(b), m.scale)


LENSES = {
    "barrel": RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.005)),
    "pincushion": RadialModel.for_image(W, H, k=(1.0, 0.0, -0.03, 0.0, -0.004)),
    "decentred": RadialModel.for_image(
        W, H, k=(1.0, 0.0, 0.02, 0.0, 0.003), center=(530.0, 355.0), tangential=(0.001, -0.0007)
    ),
    "nonradial": nonradial_lens(),
}


@cache
def measured_shots(lens_name: str, angles: tuple = ANGLES) -> tuple:
    """Edge point sets (one tuple of (M, 2) arrays per shot) of rendered shots, noise sigma 1.5."""
    from pipeline.measure import measure_image
    from pipeline.render import HarpScene, render_harp

    shots = []
    for i, ang in enumerate(angles):
        r = render_harp(
            W,
            H,
            HarpScene(angle_deg=ang, spacing_px=50.0, phase_px=11.0 * i),
            lens=LENSES[lens_name],
            noise_sigma=NOISE,
            seed=100 + i,
        )
        m = measure_image(r.image, t=30)
        shots.append(tuple(ln.points for ln in m.lines))
    return tuple(shots)


REAL = ("IMG_6931", "IMG_6964", "IMG_6950")  # near vertical, near horizontal, diagonal strings


@cache
def real_shots(directory: str) -> tuple:
    """``(width, height, (edge points, ...))`` of each real photo in :data:`REAL` (measured once per run)."""
    from pathlib import Path

    from pipeline.measure import measure_image
    from station.imageio import read_grey

    out = []
    for name in REAL:
        m = measure_image(read_grey(Path(directory) / f"{name}.pgm"), t=30)
        out.append((m.width, m.height, tuple(ln.points for ln in m.lines)))
    return tuple(out)


# ------------------------------------------------- exact closed-form lenses (issue 8)
MILD_SIZE = (1000, 750)
WIDE_SIZE = (1600, 1200)


def exact_lens(family: str):
    """The exact closed-form lens of a family of :mod:`tests.pipeline.lenses` (mild: 1000x750, wide: 1600x1200)."""
    from tests.pipeline.lenses import mild_lenses, wide_lenses

    if family.startswith("wide"):
        return wide_lenses(*WIDE_SIZE)[family]
    return mild_lenses(*MILD_SIZE)[family]


@cache
def exact_shots(family: str, angles: tuple = ANGLES) -> tuple:
    """Edge point sets of 6 (default) rendered orientations through the exact lens of ``family``
    (strings 3 px wide, 50 px apart on 1000x750, 60 px on 1600x1200, noise 1.5), measured once per run."""
    from pipeline.measure import measure_image
    from pipeline.render import HarpScene, render_harp

    lens = exact_lens(family)
    w, h = lens.width, lens.height
    spacing = 60.0 if family.startswith("wide") else 50.0
    shots = []
    for i, ang in enumerate(angles):
        r = render_harp(
            w,
            h,
            HarpScene(angle_deg=ang, spacing_px=spacing, phase_px=11.0 * i),
            lens=lens,
            noise_sigma=NOISE,
            seed=100 + i,
        )
        m = measure_image(r.image, t=30)
        shots.append(tuple(ln.points for ln in m.lines))
    return tuple(shots)
