r"""The string materials of the realistic simulator's harp (:mod:`pipeline.harp_scene`) and the
physics of one string: its linear density, bending stiffness, stiffness length
:math:`\lambda = \sqrt{EI/T}` [1]_, sag :math:`\mu g L^2 / 8T` [2]_ and breaking load.

References
----------
.. [1] S. P. Timoshenko, J. M. Gere, *Theory of Elastic Stability*, 2nd ed., McGraw-Hill,
   1961, Sect. 1.11 (beam-columns in tension: the boundary layer
   :math:`\sqrt{EI/T}`).
.. [2] H. M. Irvine, *Cable Structures*, MIT Press, 1981, Ch. 1 (the sag of a taut
   cable, :math:`\mu g L^2 / 8T`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

GRAVITY_M_S2 = 9.80665
"""Standard gravity."""


# ---------------------------------------------------------------- materials
@dataclass(frozen=True)
class Material:
    """A string material: what its sag, stiffness and cross-section follow from.

    ``density_kg_m3`` is the mass per volume of the round envelope (a braid's fibre
    density times its packing fraction), ``modulus_gpa`` the bending modulus on that
    envelope, ``strength_mpa`` the breaking load over the envelope's area. The ranges
    (``(low, high)``, drawn uniformly) are of ``diameter_mm``, ``ovality`` (major minus
    minor axis over the mean), ``offcentre`` (centroid off the silhouette's centre, in
    diameters), ``pick_ripple`` (braid edge ripple amplitude, in diameters),
    ``pick_period`` (in diameters) and ``coil_radius_mm`` (the spool the string was
    stored on).
    """

    name: str
    density_kg_m3: float
    modulus_gpa: float
    strength_mpa: float
    diameter_mm: tuple[float, float]
    ovality: tuple[float, float]
    offcentre: tuple[float, float] = (0.0, 0.0)
    pick_ripple: tuple[float, float] = (0.0, 0.0)
    pick_period: tuple[float, float] = (4.0, 4.0)
    coil_radius_mm: tuple[float, float] = (20.0, 40.0)


MATERIALS: dict[str, Material] = {
    # nylon 6.6 monofilament (fishing line): density 1140 kg/m3, drawn-filament modulus
    # 2-3 GPa; a 0.30 mm line is rated 6-7 kg (~800-900 MPa); round to ~1-2 %; spools of
    # 20-50 mm radius
    "nylon": Material("nylon", 1140.0, 2.5, 800.0, (0.2, 0.5), (0.0, 0.02), coil_radius_mm=(15.0, 40.0)),
    # UHMWPE 8-carrier braid: fibre density 970 kg/m3 x packing ~0.7; its ~300 15-um fibres
    # bend one by one, EI ~ 7e-8 N m2 for 0.3 mm (0.18 GPa on the envelope); rated
    # ~15-20 kg at 0.3 mm (~2 GPa); braids flatten (ovality 2-8 %), carriers cross the
    # edge every 3-6 diameters with a 1-3 % ripple
    "braid": Material(
        "braid",
        680.0,
        0.18,
        2000.0,
        (0.2, 0.4),
        (0.02, 0.08),
        offcentre=(0.0, 0.01),
        pick_ripple=(0.01, 0.03),
        pick_period=(3.0, 6.0),
        coil_radius_mm=(20.0, 40.0),
    ),
    # music wire (ASTM A228): 7850 kg/m3, 207 GPa, ~2.7 GPa tensile at 0.3 mm; drawn round
    # (< 0.5 %); coils of 50-150 mm radius
    "steel": Material("steel", 7850.0, 207.0, 2700.0, (0.2, 0.4), (0.0, 0.005), coil_radius_mm=(50.0, 150.0)),
}
"""The string materials :func:`draw_harp` chooses from, with their physical constants."""


def string_physics(material: Material, diameter_mm: float, tension_n: float, span_mm: float) -> dict[str, float]:
    """Sag, stiffness length and the like of one string (SI in, millimetres out).

    Returns ``linear_density_kg_m`` (:math:`\\mu = \\rho\\pi D^2/4`), ``bending_stiffness_nm2``
    (:math:`EI`, :math:`I = \\pi D^4/64`), ``stiffness_length_mm``
    (:math:`\\lambda = \\sqrt{EI/T}`) and ``sag_mm`` (:math:`\\mu g L^2/8T`).
    """
    d = diameter_mm * 1e-3
    mu = material.density_kg_m3 * math.pi * d * d / 4.0
    ei = material.modulus_gpa * 1e9 * math.pi * d**4 / 64.0
    span = span_mm * 1e-3
    return {
        "linear_density_kg_m": mu,
        "bending_stiffness_nm2": ei,
        "stiffness_length_mm": 1e3 * math.sqrt(ei / tension_n),
        "sag_mm": 1e3 * mu * GRAVITY_M_S2 * span * span / (8.0 * tension_n),
    }


def breaking_load_n(material: Material, diameter_mm: float) -> float:
    """The breaking load (N) of a string of ``material`` and ``diameter_mm``."""
    d = diameter_mm * 1e-3
    return material.strength_mpa * 1e6 * math.pi * d * d / 4.0
