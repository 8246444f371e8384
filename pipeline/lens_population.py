r"""Seeded populations of realistic lenses: exact lens maps with manufacturing spread.

A population is drawn from a nominal :class:`LensDesign` (its radial distortion) and the
unit-to-unit spread of assembling it, every lens an exact
:class:`~pipeline.models.base.DistortionModel` (distorted -> ideal pixels) that the
renderers (:mod:`pipeline.render`, :mod:`pipeline.realism`) evaluate per pixel and the
tests and benchmarks compare fitted corrections with.

Each lens (normalised offsets :math:`\xi = (x - c_x)/s`, :math:`\eta = (y - c_y)/s`,
:math:`s` half the image diagonal) is a :class:`~pipeline.models.radial.RadialModel`

.. math::
    x_u = c + s\,\bigl[(1 + k_1\rho^2 + k_2\rho^4 + k_3\rho^6)(\xi, \eta) + T(\xi, \eta) + P(\rho)\bigr]

(Brown–Conrady decentering :math:`T` with :math:`p_1, p_2`, thin prism :math:`P` with
:math:`s_1 \dots s_4`), optionally plus a smooth non-parametric field
(:class:`RippleLens`, ``field=True``) that the radial + tangential + prism family cannot
express. What is drawn, per lens (normal distributions unless said otherwise):

* **radial** :math:`k_i`: the design's nominal value plus its spread (the tolerance of
  radii, thicknesses and spacings shifts a design's distortion by a few per cent of itself
  plus a small absolute amount: ``k_spread``);
* **distortion centre**: the image centre plus 0.5 % of :math:`s` per axis (the sensor's
  placement against the optical axis, ~0.1 mm on a 22 mm half-diagonal);
* **decentering** :math:`p_1, p_2`: :math:`\sigma = 3\cdot10^{-4}` each (element
  decentration of 10–30 µm; OpenCV calibrations of consumer lenses give
  :math:`|p| \sim 10^{-4}`–:math:`10^{-3}` in focal-length units, :math:`s/f` ≈ 0.4–1 times
  that here): 0.5–2 px at the corners of a 2 MP image;
* **thin prism** :math:`s_1, s_3`: :math:`\sigma = 3\cdot10^{-4}`, :math:`s_2, s_4`:
  :math:`10^{-4}` (element tilt of 1–3 arcmin, and the sensor's tilt);
* **the odd bad lens**: with probability ``bad_fraction`` (5 %) a lens whose decentering and
  tilt are 4 times the spread (a dropped or badly assembled unit);
* **non-parametric field** (``field=True``): the gradient of a random smooth potential,
  :math:`s\nabla\varphi`, :math:`\varphi = \sum_m A_m\cos(\kappa_m\cdot(\xi, \eta) + \phi_m)`,
  :data:`RIPPLE_WAVES` waves of wavelengths :data:`RIPPLE_WAVELENGTH` (half-diagonals),
  scaled to an RMS displacement drawn in ``field_rms_px`` (default 0.005–0.04 px). A
  thin irregular surface deflects rays by the gradient of its optical path error, hence a
  gradient field. Magnitude: an element surface irregularity of a quarter to half a
  fringe (0.15–0.3 µm, ISO 10110 tolerance class of consumer optics) over a beam
  footprint of ~20 mm has slopes of ~5e-5–1e-4 rad; through a glass of :math:`n - 1
  \approx 0.5` and ~40 mm to the sensor that moves the image by 1–2 µm, 0.1–0.2 px of
  10 µm pixels, of which the part varying faster than the radial terms can follow is a
  fraction. Sensor unflatness adds :math:`\Delta z\tan\beta` (2 µm at a chief-ray angle of
  20° moves the image by 0.7 µm).

References
----------
.. [1] D. C. Brown, "Decentering distortion of lenses", Photogrammetric Engineering
   32(3), 1966, pp. 444-462.
.. [2] J. Weng, P. Cohen, M. Herniou, "Camera calibration with distortion models and
   accuracy evaluation", IEEE TPAMI 14(10), 1992 (thin prism).
.. [3] ISO 10110-5:2015, Optics and photonics — Preparation of drawings for optical
   elements and systems — Part 5: Surface form tolerances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.models.base import DistortionModel
from pipeline.models.radial import RadialModel

RIPPLE_WAVES = 8
"""Plane waves of the non-parametric field's potential."""
RIPPLE_WAVELENGTH = (0.6, 2.0)
"""Range of their wavelengths, in half-diagonals (smooth over 300-1000 px on a 2 MP image)."""
CENTRE_SPREAD = 0.005
"""Standard deviation of the distortion centre from the image centre, per axis, in half-diagonals."""
TANGENTIAL_SPREAD = 3e-4
"""Standard deviation of p1 and p2."""
PRISM_SPREAD = (3e-4, 1e-4)
"""Standard deviations of (s1, s3) and of (s2, s4)."""
BAD_FACTOR = 4.0
"""How much more decentred and tilted the odd bad lens is."""


@dataclass(frozen=True)
class LensDesign:
    """A lens model's nominal radial distortion and its unit-to-unit spread.

    ``k`` are the nominal :math:`k_1, k_2, k_3` (coefficients of :math:`\\rho^2, \\rho^4,
    \\rho^6` in half-diagonal units), ``k_spread`` their standard deviations over units.
    """

    name: str
    k: tuple[float, float, float]
    k_spread: tuple[float, float, float]


DESIGNS: dict[str, LensDesign] = {
    # a normal lens: slight barrel (~1 % at the corners)
    "normal": LensDesign("normal", (0.012, -0.002, 0.0), (0.002, 0.001, 0.0003)),
    # a short lens: strong barrel, the demo's 12 mm-like
    "wide": LensDesign("wide", (0.045, -0.005, 0.0005), (0.003, 0.0015, 0.0005)),
    # a long lens: mild pincushion
    "tele": LensDesign("tele", (-0.012, 0.001, 0.0), (0.002, 0.001, 0.0003)),
    # a retrofocus zoom at its short end: barrel turning to pincushion (moustache)
    "moustache": LensDesign("moustache", (0.035, -0.03, 0.006), (0.003, 0.002, 0.001)),
}
"""The designs :func:`lens_population` draws from when given none."""


@dataclass(frozen=True, eq=False)
class RippleLens(DistortionModel):
    r"""A radial lens plus a smooth non-parametric field: :math:`x_u = R(x_d) + s\nabla\varphi(\xi, \eta)`.

    :math:`R` is ``base`` (a :class:`~pipeline.models.radial.RadialModel`),
    :math:`(\xi, \eta) = (x_d - c_0)/s` the offsets from the image centre :math:`c_0` in
    units of ``base.scale`` = :math:`s`, and

    .. math::
        \varphi = \sum_m A_m \cos(\kappa_m\cdot(\xi, \eta) + \phi_m), \qquad
        s\nabla\varphi = -s\sum_m A_m\,\kappa_m \sin(\kappa_m\cdot(\xi, \eta) + \phi_m)

    (``amplitudes`` :math:`A_m`, ``wavevectors`` :math:`\kappa_m`, ``phases``
    :math:`\phi_m`). A truth lens of the simulator (:mod:`pipeline.lens_population`), not a
    model a fit produces.
    """

    base: RadialModel
    image_centre: tuple[float, float]
    amplitudes: tuple[float, ...]
    wavevectors: tuple[tuple[float, float], ...]
    phases: tuple[float, ...]
    name: str = field(default="radial_ripple", init=False, repr=False)

    def __post_init__(self) -> None:
        if not len(self.amplitudes) == len(self.wavevectors) == len(self.phases):
            raise ValueError("RippleLens: amplitudes, wavevectors and phases must have the same length")

    def ripple(self, xy: np.ndarray) -> np.ndarray:
        """The non-parametric part :math:`s\\nabla\\varphi` at distorted points ``(N, 2)``, px."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        s = self.base.scale
        v = (xy - np.asarray(self.image_centre)) / s
        out: np.ndarray = np.zeros_like(v)
        x, y = np.ascontiguousarray(v[:, 0]), np.ascontiguousarray(v[:, 1])
        w = np.empty_like(x)
        for a, (kx, ky), ph in zip(self.amplitudes, self.wavevectors, self.phases, strict=True):
            np.multiply(x, kx, out=w)  # w = -s a sin(kappa . v + phi), in place
            w += ky * y
            w += ph
            np.sin(w, out=w)
            w *= -s * a
            out[:, 0] += kx * w
            out[:, 1] += ky * w
        return out

    def undistort_points(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        out: np.ndarray = self.base.undistort_points(xy) + self.ripple(xy)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.name,
            "base": self.base.to_dict(),
            "image_centre": list(self.image_centre),
            "amplitudes": list(self.amplitudes),
            "wavevectors": [list(k) for k in self.wavevectors],
            "phases": list(self.phases),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RippleLens:
        return cls(
            RadialModel.from_dict(d["base"]),
            (float(d["image_centre"][0]), float(d["image_centre"][1])),
            tuple(float(v) for v in d["amplitudes"]),
            tuple((float(k[0]), float(k[1])) for k in d["wavevectors"]),
            tuple(float(v) for v in d["phases"]),
        )


@dataclass(frozen=True)
class PopulationLens:
    """One lens of a population.

    ``model`` is the exact lens (a :class:`~pipeline.models.radial.RadialModel`, or a
    :class:`RippleLens` with a field); ``parametric`` its radial + tangential + prism part;
    ``field_rms_px`` the RMS over the image of the non-parametric part (0 without);
    ``bad`` whether it is the odd badly decentred unit; ``design`` its design's name.
    """

    index: int
    design: str
    model: DistortionModel
    parametric: RadialModel
    field_rms_px: float
    bad: bool

    @property
    def serial(self) -> str:
        """A serial number for the lens (its design and index in the population)."""
        return f"{self.design.upper()}-{self.index:04d}"


def _grid(width: int, height: int, step: float = 20.0) -> np.ndarray:
    xs = np.append(np.arange(0.0, width - 1, step), width - 1.0)
    ys = np.append(np.arange(0.0, height - 1, step), height - 1.0)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], 1)


@dataclass(frozen=True)
class UnitSpread:
    """What makes one unit of a lens design differ from the design (module docstring).

    ``dk`` are the deviations of :math:`k_1, k_2, k_3` from the nominal values, ``centre`` the
    distortion centre's offset from the image centre in half-diagonals :math:`s` (x, y),
    ``tangential`` the decentering :math:`p_1, p_2`, ``prism`` the thin prism
    :math:`s_1 \\dots s_4` (tilt); ``bad`` whether it is the odd badly assembled unit (its
    decentering and tilt :data:`BAD_FACTOR` times the spread).
    """

    dk: tuple[float, float, float]
    centre: tuple[float, float]
    tangential: tuple[float, float]
    prism: tuple[float, float, float, float]
    bad: bool


def draw_spread(
    rng: np.random.Generator,
    k_spread: tuple[float, float, float],
    bad_fraction: float = 0.05,
    scale: float = 1.0,
) -> UnitSpread:
    """One unit's :class:`UnitSpread`, drawn from ``rng``: normal deviations of standard deviation
    ``scale`` times ``k_spread``, :data:`CENTRE_SPREAD`, :data:`TANGENTIAL_SPREAD` and
    :data:`PRISM_SPREAD` (times :data:`BAD_FACTOR` for a bad unit, drawn with probability
    ``bad_fraction``). ``scale = 0`` is the nominal lens (every deviation 0, never bad)."""
    dk = tuple(float(rng.normal(0.0, scale * sd)) for sd in k_spread)
    centre = (float(rng.normal(0, scale * CENTRE_SPREAD)), float(rng.normal(0, scale * CENTRE_SPREAD)))
    bad = bool(rng.uniform() < bad_fraction) and scale > 0
    f = scale * (BAD_FACTOR if bad else 1.0)
    tang = (float(rng.normal(0, f * TANGENTIAL_SPREAD)), float(rng.normal(0, f * TANGENTIAL_SPREAD)))
    p2, p4 = f * PRISM_SPREAD[0], f * PRISM_SPREAD[1]
    prism = (float(rng.normal(0, p2)), float(rng.normal(0, p4)), float(rng.normal(0, p2)), float(rng.normal(0, p4)))
    return UnitSpread((dk[0], dk[1], dk[2]), centre, tang, prism, bad)


def draw_lens(
    rng: np.random.Generator,
    index: int,
    width: int,
    height: int,
    design: LensDesign,
    field: bool = False,
    field_rms_px: tuple[float, float] = (0.005, 0.04),
    bad_fraction: float = 0.05,
) -> PopulationLens:
    """One lens of ``design`` with its manufacturing spread (:func:`draw_spread`), drawn from ``rng``
    (module docstring)."""
    s = 0.5 * math.hypot(width, height)
    c0 = ((width - 1) / 2.0, (height - 1) / 2.0)
    unit = draw_spread(rng, design.k_spread, bad_fraction)
    k = [m + d for m, d in zip(design.k, unit.dk, strict=True)]
    centre = (c0[0] + unit.centre[0] * s, c0[1] + unit.centre[1] * s)
    base = RadialModel.for_image(
        width, height, k=(1.0, 0.0, k[0], 0.0, k[1], 0.0, k[2]), center=centre, tangential=unit.tangential,
        prism=unit.prism,
    )  # fmt: skip
    model: DistortionModel = base
    rms = 0.0
    if field:
        rms = float(rng.uniform(*field_rms_px))
        model = draw_ripple(rng, base, width, height, rms)
    return PopulationLens(index, design.name, model, base, rms, unit.bad)


def draw_ripple(rng: np.random.Generator, base: RadialModel, width: int, height: int, rms_px: float) -> RippleLens:
    """``base`` plus a non-parametric field drawn from ``rng`` (module docstring: :data:`RIPPLE_WAVES` plane waves
    of a potential, wavelengths in :data:`RIPPLE_WAVELENGTH` half-diagonals), scaled to an RMS displacement of
    ``rms_px`` over a ``width`` x ``height`` image (a 20 px grid, corners included). ValueError for an
    ``rms_px`` that is not a finite number > 0."""
    if not (math.isfinite(rms_px) and rms_px > 0):
        raise ValueError(f"a field's RMS must be a finite number > 0 px, got {rms_px!r}")
    c0 = ((width - 1) / 2.0, (height - 1) / 2.0)
    lam = rng.uniform(*RIPPLE_WAVELENGTH, RIPPLE_WAVES)
    direction = rng.uniform(0, 2 * math.pi, RIPPLE_WAVES)
    kappa = tuple((2 * math.pi / L * math.cos(t), 2 * math.pi / L * math.sin(t)) for L, t in zip(lam, direction))
    amps = rng.standard_normal(RIPPLE_WAVES) * lam / (2 * math.pi)  # each wave's displacement ~ N(0, 1) s
    phases = tuple(float(v) for v in rng.uniform(0, 2 * math.pi, RIPPLE_WAVES))
    ripple = RippleLens(base, c0, tuple(float(a) for a in amps), kappa, phases)
    now = float(np.sqrt(np.mean(np.sum(ripple.ripple(_grid(width, height)) ** 2, axis=1))))
    scale = rms_px / now
    return RippleLens(base, c0, tuple(float(a) * scale for a in amps), kappa, phases)


def lens_population(
    seed: int,
    n: int,
    width: int,
    height: int,
    design: str | LensDesign | None = None,
    field: bool = False,
    field_rms_px: tuple[float, float] = (0.005, 0.04),
    bad_fraction: float = 0.05,
) -> tuple[PopulationLens, ...]:
    """``n`` lenses for ``width`` x ``height`` images, drawn from ``seed`` (module docstring).

    Parameters
    ----------
    seed : the population's seed; lens ``i`` depends only on ``(seed, i)`` (a longer
        population starts with the same lenses).
    design : a key of :data:`DESIGNS` or a :class:`LensDesign`: a manufacturing-spread
        population of one lens model (a factory line); None draws each lens's design from
        :data:`DESIGNS` (a varied population, for judging model choice).
    field : add each lens a non-parametric field of RMS drawn in ``field_rms_px``.
    bad_fraction : the share of badly decentred units.
    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    if isinstance(design, str):
        if design not in DESIGNS:
            raise ValueError(f"unknown lens design {design!r}; known: {', '.join(sorted(DESIGNS))}")
        design = DESIGNS[design]
    out = []
    names = sorted(DESIGNS)
    for i in range(n):
        rng = np.random.default_rng([int(seed), i, 0x1E45])
        d = design if design is not None else DESIGNS[names[int(rng.integers(len(names)))]]
        out.append(draw_lens(rng, i, width, height, d, field, field_rms_px, bad_fraction))
    return tuple(out)


def shot_to_shot(
    model: DistortionModel, rng: np.random.Generator, tangential_sd: float, centre_sd_px: float = 0.0
) -> DistortionModel:
    """``model`` with its decentering changed as between two shots of an unstable lens.

    Adds :math:`N(0, \\sigma_p)` to :math:`p_1, p_2` and :math:`N(0, \\sigma_c)` px to the
    distortion centre of a :class:`~pipeline.models.radial.RadialModel` (or of a
    :class:`RippleLens`'s radial part): what an image stabiliser that re-centres, a zoom
    or focus group with play, or a lens knocked between shots does (consumer zoom lenses'
    interior orientation changes between images; Shortis et al., IAPRS vol. 36 part 5, 2006;
    Sanz-Ablanedo et al., Sensors 10(3), 2010). Off in every population: a sensitivity
    test (``benchmarks/realism.py --shot-decentre``), with no documented default magnitude.
    """
    base = model.base if isinstance(model, RippleLens) else model
    if not isinstance(base, RadialModel):
        raise TypeError(f"shot_to_shot needs a RadialModel or RippleLens, got {type(model).__name__}")
    p = base.tangential or (0.0, 0.0)
    tang = (p[0] + float(rng.normal(0, tangential_sd)), p[1] + float(rng.normal(0, tangential_sd)))
    centre = (base.center[0] + float(rng.normal(0, centre_sd_px)), base.center[1] + float(rng.normal(0, centre_sd_px)))
    moved = RadialModel(centre, base.k, base.scale, tang, base.prism, base.division)
    if isinstance(model, RippleLens):
        return RippleLens(moved, model.image_centre, model.amplitudes, model.wavevectors, model.phases)
    return moved
