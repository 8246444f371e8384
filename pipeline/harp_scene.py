r"""The physical harp of the realistic simulator: strings that are not perfectly straight,
the back-lit sheet behind them, and how the harp turns on its turntable.

Harp coordinates
----------------
Everything fixed to the harp is written in *harp coordinates* :math:`(a, b)`: ideal-image
pixels on the harp plane (the harp seen through a perfect pin-hole at this camera's
magnification; ``mm_per_px`` converts to millimetres), :math:`a` along the strings and
:math:`b` across them, origin on the turntable axis. At turntable angle :math:`\varphi`
(:class:`HarpMount`, :class:`HarpPose`) the strings run at

.. math::
    \theta = \theta_0 + s\,\varphi \qquad (s = \pm 1,\ \text{the mount's direction})

in the ideal image, and the harp point :math:`(a, b)` is the ideal image point
:math:`u = c + a\,d + b\,n`, :math:`d = (\cos\theta, \sin\theta)`,
:math:`n = (-\sin\theta, \cos\theta)`, :math:`c` the turntable axis in the ideal image.
A string therefore keeps its shape, and the sheet its pattern, as the harp rotates
between shots; only the sag, which follows gravity, changes with the angle. The back-lit sheet
behind the strings, which turns with the harp too, is :class:`pipeline.backlight.Backlight`.

A string and its edges
----------------------
String :math:`k` lies along :math:`b = b_k` (nominal pitch plus the frame's placement
error). Its two edges (side :math:`\sigma = -1` at smaller :math:`b`, :math:`+1` at larger)
are

.. math::
    b = b_k + \delta_k(a) + \sigma\,\bigl(r_k + \omega_{k,\sigma}(a)\bigr)

with :math:`r_k` half the nominal width, the centreline deviation :math:`\delta_k` and
the half-width variation :math:`\omega_{k,\sigma}`, each a sum of the terms below
(:math:`z = (a - a_c)/h \in [-1, 1]` over the span, :math:`L = 2h` the free length
between the frame's anchors, :math:`a_c` its middle):

* **sag** (follows gravity: the only term that changes with the pose). A string of
  linear density :math:`\mu` under tension :math:`T` over a span :math:`L` hangs in a
  parabola (the catenary to first order) of depth :math:`\mu g L^2 / (8T)` in the middle;
  only gravity's component along the string's normal in the harp plane bends the image:
  :math:`\delta_{sag} = \frac{\mu g L^2}{8T}\,(n\cdot\hat g)\,(1 - z^2)`, with
  :math:`\hat g` the direction of gravity in the ideal image (:attr:`HarpPose.gravity_cos`).
  A 0.3 mm nylon line at 30 % of its breaking load over 250 mm sags 0.3 µm (0.003 px at
  0.11 mm/px); a steel wire 0.7 µm.
* **bow** (residual curvature the tension does not pull out). A string of bending
  stiffness :math:`EI` (:math:`I = \pi D^4/64`) with a natural curvature
  :math:`\kappa_0(a)` (the coil set of a line unwound from its spool, :math:`\kappa_0 \le
  1/R_{coil}`) under tension :math:`T` obeys :math:`EI\,(w'''' - \kappa_0'') = T\,w''`;
  where :math:`\kappa_0` varies slowly against :math:`\lambda = \sqrt{EI/T}` this gives
  :math:`w = -\lambda^2\kappa_0(a)` up to a straight line. The variation
  :math:`\Delta\kappa_0` of the coil set along the span, drawn in
  :math:`[0, 1/R_{coil}]`, spread over the string's first three modes
  :math:`\sin(m\pi(z+1)/2)`, :math:`m = 1, 2, 3`, gives bows of 0.002–0.03 px for nylon,
  up to 0.1 px for a steel wire from a tight coil.
* **kink** (a crimp, from a knot or handling: an angle :math:`\alpha` in the natural
  shape at :math:`a_k`). The same equation gives :math:`w = \frac{\alpha\lambda}{2}
  e^{-|a - a_k|/\lambda}`: a cusp :math:`\lambda` long (0.2 mm for 0.3 mm nylon at
  20 N, 1.2 mm for steel wire), :math:`\alpha\lambda/2` high (0.01–0.1 px for nylon,
  up to 0.6 px for steel at :math:`\alpha` = 0.1 rad).
* **twist of a braided (or not quite round) string**. A cross-section of ovality
  :math:`\varepsilon` (major minus minor axis over the mean), twisted by one turn per
  :math:`P` as mounted, has a projected half-width :math:`r(1 + \frac{\varepsilon}{2}
  \cos 2\alpha)`, :math:`\alpha = 2\pi a/P + \phi`: both edges move out and in together
  (``ovality_px`` = :math:`r\varepsilon/2`, period :math:`P/2`); an off-centre section
  moves the centreline by :math:`e\cos\alpha`; a braid's carriers cross each edge every
  pick (:math:`\approx 3`–6 diameters), a ripple :math:`A_p\cos(2\pi a/P_p + \phi_\sigma)`
  with its own phase on each side.

:func:`draw_harp` draws all of it per string from a seed, from the physical ranges of
:data:`pipeline.string_materials.MATERIALS` (its docstring gives the values and their sources); the magnitudes
in pixels follow from the string's diameter and width in pixels (the image scale).

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera
   distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] S. P. Timoshenko, J. M. Gere, *Theory of Elastic Stability*, 2nd ed., McGraw-Hill,
   1961, Sect. 1.11 (beam-columns in tension: the boundary layer
   :math:`\sqrt{EI/T}`).
.. [3] H. M. Irvine, *Cable Structures*, MIT Press, 1981, Ch. 1 (the sag of a taut
   cable, :math:`\mu g L^2 / 8T`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.render import EdgeTruth
from pipeline.string_materials import MATERIALS, breaking_load_n, string_physics

TENSION_FRACTION = (0.15, 0.45)
"""Range of a harp's string tension as a fraction of the breaking load (hand-tensioned,
well below breaking, above the slack range); each string spreads by 10 % around it."""
KINK_PROBABILITY = 0.2
"""Chance that a string carries a kink."""
KINK_ANGLE_RAD = (0.005, 0.05)
"""Range of a kink's angle: a crimp the eye does not see on a mounted string (below 3 degrees)."""
COIL_SET_VARIATION = 0.3
"""Largest variation of the coil set's curvature along a span, as a fraction of the coil's
curvature (a coil's curvature is nearly uniform, and a uniform one leaves no bow; what varies
comes from unwinding and handling)."""
TWIST_PERIOD_MM = (30.0, 300.0)
"""Range of the length of one turn of twist a string was mounted with."""
PLACEMENT_MM = 0.05
"""Standard deviation of a string's position across the harp (the frame's holes or grooves)."""


# ---------------------------------------------------------------- one string
_COLUMNS = (
    "position_px",
    "radius_px",
    "span_centre_px",
    "half_span_px",
    "sag_px",
    "bow1_px",
    "bow2_px",
    "bow3_px",
    "kink_at_px",
    "kink_px",
    "kink_length_px",
    "ovality_px",
    "twist_period_px",
    "twist_phase",
    "offcentre_px",
    "pick_px",
    "pick_period_px",
    "pick_phase_minus",
    "pick_phase_plus",
)


@dataclass(frozen=True)
class StringShape:
    """One string in harp coordinates (ideal px; module docstring, *A string and its edges*).

    Parameters
    ----------
    index : the string's number across the harp (0 at the smallest ``b``).
    position_px : :math:`b_k`, where its straight line crosses the harp's ``b`` axis.
    radius_px : :math:`r_k`, half its nominal width.
    span_centre_px, half_span_px : :math:`a_c` and :math:`h`: the free length between the
        frame's anchors is :math:`[a_c - h, a_c + h]`.
    sag_px : :math:`\\mu g L^2 / 8T`, the sag in the middle of the span with gravity along
        the string's normal (scaled by :attr:`HarpPose.gravity_cos` in a pose).
    bow_px : coefficients of the modes :math:`\\sin(m\\pi(z + 1)/2)`, ``m = 1, 2, 3``.
    kink_at_px, kink_px, kink_length_px : a kink's position :math:`a_k`, height
        :math:`\\alpha\\lambda/2` (signed; 0: no kink) and length :math:`\\lambda`.
    ovality_px, twist_period_px, twist_phase : half-width modulation
        :math:`r\\varepsilon/2`, the twist's length per turn :math:`P` and its phase
        :math:`\\phi` (the width varies with period :math:`P/2`).
    offcentre_px : centreline modulation :math:`e` at the twist period.
    pick_px, pick_period_px, pick_phases : a braid's edge ripple, its period and its
        phase on side -1 and +1.
    """

    index: int
    position_px: float
    radius_px: float
    span_centre_px: float = 0.0
    half_span_px: float = 1e6
    sag_px: float = 0.0
    bow_px: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kink_at_px: float = 0.0
    kink_px: float = 0.0
    kink_length_px: float = 1.0
    ovality_px: float = 0.0
    twist_period_px: float = 1000.0
    twist_phase: float = 0.0
    offcentre_px: float = 0.0
    pick_px: float = 0.0
    pick_period_px: float = 10.0
    pick_phases: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not self.radius_px > 0:
            raise ValueError(f"string {self.index}: radius_px must be > 0, got {self.radius_px}")
        for name in ("half_span_px", "kink_length_px", "twist_period_px", "pick_period_px"):
            if not getattr(self, name) > 0:
                raise ValueError(f"string {self.index}: {name} must be > 0, got {getattr(self, name)}")

    def row(self) -> tuple[float, ...]:
        """The parameters in the order of the columns :func:`edge_offsets` reads."""
        return (
            self.position_px,
            self.radius_px,
            self.span_centre_px,
            self.half_span_px,
            self.sag_px,
            *self.bow_px,
            self.kink_at_px,
            self.kink_px,
            self.kink_length_px,
            self.ovality_px,
            self.twist_period_px,
            self.twist_phase,
            self.offcentre_px,
            self.pick_px,
            self.pick_period_px,
            *self.pick_phases,
        )

    def centreline(self, a: np.ndarray, gravity_cos: float = 0.0) -> np.ndarray:
        """:math:`b_k + \\delta_k(a)`: where the string's centre line crosses the harp's ``b`` at ``a``."""
        table = np.asarray([self.row()], np.float64)
        a = np.asarray(a, np.float64)
        centre, _, _ = edge_offsets(table, np.zeros(a.shape, np.intp), a, gravity_cos)
        return centre

    def deviation(self, a: np.ndarray, gravity_cos: float = 0.0) -> np.ndarray:
        """:math:`\\delta_k(a)`: the centre line's deviation from its straight line (harp px).

        With ``gravity_cos = 0`` (the default) it is the string's own shape, the same at
        every orientation (bow, kink, off-centre twist); the sag of a pose adds
        ``gravity_cos`` times the sag profile (:attr:`HarpPose.gravity_cos`).
        """
        return self.centreline(a, gravity_cos) - self.position_px

    def half_width(self, a: np.ndarray, side: int) -> np.ndarray:
        """:math:`r_k + \\omega_{k,\\sigma}(a)`: the distance from the centre line to the edge on ``side``."""
        table = np.asarray([self.row()], np.float64)
        a = np.asarray(a, np.float64)
        _, minus, plus = edge_offsets(table, np.zeros(a.shape, np.intp), a, 0.0)
        return minus if side < 0 else plus

    def edge_deviation(self, a: np.ndarray, side: int, gravity_cos: float = 0.0) -> np.ndarray:
        """The edge on ``side`` minus its straight line :math:`b_k + \\sigma r_k` (harp px):
        :math:`\\delta_k(a) + \\sigma\\,\\omega_{k,\\sigma}(a)`."""
        return self.deviation(a, gravity_cos) + side * (self.half_width(a, side) - self.radius_px)


def edge_offsets(
    table: np.ndarray, k: np.ndarray, a: np.ndarray, gravity_cos: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre line and half-widths of strings ``k`` at positions ``a``, vectorised.

    ``table`` holds one :meth:`StringShape.row` per string (``Harp.table``), ``k`` the
    string of each point (same shape as ``a``). Returns ``(centre, half_minus,
    half_plus)``: the string's centre line :math:`b_k + \\delta_k(a)` and its half-widths
    :math:`r_k + \\omega_{k,\\mp}(a)` (module docstring), each of the shape of ``a``.
    """
    index = {name: i for i, name in enumerate(_COLUMNS)}
    present = np.any(table != 0, axis=0)  # terms no string has are not evaluated (same result)

    def col(name: str) -> np.ndarray:
        out: np.ndarray = table[k, index[name]]
        return out

    def has(*names: str) -> bool:
        return bool(any(present[index[n]] for n in names))

    centre = col("position_px") + np.zeros_like(a)
    if has("bow1_px", "bow2_px", "bow3_px") or (gravity_cos != 0 and has("sag_px")):
        z = (a - col("span_centre_px")) / col("half_span_px")
        centre = centre + gravity_cos * col("sag_px") * (1.0 - z * z)
        for m in (1, 2, 3):
            if has(f"bow{m}_px"):
                centre = centre + col(f"bow{m}_px") * np.sin(m * math.pi * 0.5 * (z + 1.0))
    if has("kink_px"):
        centre = centre + col("kink_px") * np.exp(-np.abs(a - col("kink_at_px")) / col("kink_length_px"))
    half = col("radius_px") + np.zeros_like(a)
    if has("offcentre_px", "ovality_px"):
        alpha = 2.0 * math.pi * a / col("twist_period_px") + col("twist_phase")
        centre = centre + col("offcentre_px") * np.cos(alpha)
        half = half + col("ovality_px") * np.cos(2.0 * alpha)
    minus, plus = half, half
    if has("pick_px"):
        pick = 2.0 * math.pi * a / col("pick_period_px")
        minus = half + col("pick_px") * np.cos(pick + col("pick_phase_minus"))
        plus = half + col("pick_px") * np.cos(pick + col("pick_phase_plus"))
    return centre, minus, plus


# ---------------------------------------------------------------- the harp
@dataclass(frozen=True)
class Harp:
    """A harp: its strings in harp coordinates and what they are made of.

    Parameters
    ----------
    strings : one :class:`StringShape` per string, in order of ``position_px``.
    spacing_px : the nominal pitch (harp px).
    material : the key of :data:`MATERIALS` the strings are made of ("" for an abstract harp).
    mm_per_px : the scale of harp coordinates on the harp (millimetres per ideal pixel).
    tension_n : the nominal string tension (N; 0 for an abstract harp).
    transmission : the strings' transmission (0: opaque).
    """

    strings: tuple[StringShape, ...]
    spacing_px: float
    material: str = ""
    mm_per_px: float = 0.1
    tension_n: float = 0.0
    transmission: float = 0.0
    table: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.strings:
            raise ValueError("a harp needs at least one string")
        if not self.spacing_px > 0:
            raise ValueError(f"spacing_px must be > 0, got {self.spacing_px}")
        pos = np.array([s.position_px for s in self.strings])
        if np.any(np.diff(pos) <= 0):
            raise ValueError("strings must be in order of position_px")
        if np.any(np.abs(np.diff(pos) - self.spacing_px) > 0.25 * self.spacing_px):
            raise ValueError("string positions must stay within 25 % of spacing_px of the nominal pitch")
        if not 0 <= self.transmission < 1:
            raise ValueError(f"transmission must be in [0, 1), got {self.transmission}")
        table = np.asarray([s.row() for s in self.strings], np.float64)
        table.setflags(write=False)
        object.__setattr__(self, "table", table)

    @classmethod
    def straight(
        cls, n_strings: int, spacing_px: float, width_px: float, offset_px: float = 0.0, transmission: float = 0.0
    ) -> Harp:
        """``n_strings`` perfectly straight strings ``spacing_px`` apart, centred on ``b = offset_px``."""
        strings = tuple(
            StringShape(k, (k - (n_strings - 1) / 2.0) * spacing_px + offset_px, 0.5 * width_px)
            for k in range(n_strings)
        )
        return cls(strings, float(spacing_px), transmission=transmission)

    @property
    def first_position_px(self) -> float:
        """The nominal ``b`` of string 0 (the pitch grid the strings sit on)."""
        return float(np.mean([s.position_px - s.index * self.spacing_px for s in self.strings]))

    def nearest(self, b: np.ndarray) -> np.ndarray:
        """The index (into :attr:`strings`) of the string nearest to each ``b`` on the pitch grid."""
        k = np.rint((np.asarray(b, np.float64) - self.first_position_px) / self.spacing_px)
        return np.clip(k, 0, len(self.strings) - 1).astype(np.intp)

    def edges(self, pose: HarpPose) -> tuple[EdgeTruth, ...]:
        """Both edges of every string at ``pose``, as exact truths with their shapes.

        Each :class:`~pipeline.render.EdgeTruth` has the pose's normal ``n``, the offset
        ``n . c + b_k + side r_k`` of its straight line and an :class:`EdgeProfile` (the
        edge's deviation, sag included) as its shape. ``string_index`` is the string's index.
        """
        n = np.asarray(pose.normal)
        base = float(n @ np.asarray(pose.centre))
        out = []
        for s in self.strings:
            for side in (-1, 1):
                offset = base + s.position_px + side * s.radius_px
                out.append(
                    EdgeTruth(
                        s.index,
                        side,
                        pose.normal,
                        offset,
                        EdgeProfile(s, side, pose.along_origin, pose.gravity_cos),
                    )
                )
        return tuple(out)


@dataclass(frozen=True)
class EdgeProfile:
    """The :class:`~pipeline.render.EdgeShape` of one string edge in one pose.

    Called with positions ``s`` along the edge's line (``s = d . u`` in the ideal image),
    returns :meth:`StringShape.edge_deviation` at harp position ``a = s - along_origin``
    (``along_origin = d . c``, the turntable axis), sag scaled by ``gravity_cos``.
    """

    string: StringShape
    side: int
    along_origin: float
    gravity_cos: float

    def __call__(self, s: np.ndarray) -> np.ndarray:
        return self.string.edge_deviation(np.asarray(s, np.float64) - self.along_origin, self.side, self.gravity_cos)


# ---------------------------------------------------------------- the turntable
@dataclass(frozen=True)
class HarpPose:
    """The harp at one turntable angle: where its coordinates lie in the ideal image.

    ``angle_deg`` is the strings' direction :math:`\\theta` in the ideal image, ``centre``
    the turntable axis :math:`c` (ideal px), ``gravity_cos`` :math:`n\\cdot\\hat g` (the
    fraction of gravity that bends the strings' images).
    """

    turntable_deg: float
    angle_deg: float
    centre: tuple[float, float]
    gravity_cos: float

    @property
    def direction(self) -> tuple[float, float]:
        """:math:`d = (\\cos\\theta, \\sin\\theta)`, the strings' direction (harp ``+a``)."""
        t = math.radians(self.angle_deg)
        return (math.cos(t), math.sin(t))

    @property
    def normal(self) -> tuple[float, float]:
        """:math:`n = (-\\sin\\theta, \\cos\\theta)` (harp ``+b``)."""
        t = math.radians(self.angle_deg)
        return (-math.sin(t), math.cos(t))

    @property
    def along_origin(self) -> float:
        """:math:`d \\cdot c`: the position along the strings' lines of the turntable axis."""
        d = self.direction
        return d[0] * self.centre[0] + d[1] * self.centre[1]

    def to_harp(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Harp coordinates ``(a, b)`` of ideal image points ``u`` ``(..., 2)``."""
        u = np.asarray(u, np.float64)
        dx, dy = u[..., 0] - self.centre[0], u[..., 1] - self.centre[1]
        (cx, cy), (nx, ny) = self.direction, self.normal
        return cx * dx + cy * dy, nx * dx + ny * dy

    def to_image(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Ideal image points ``(..., 2)`` of harp coordinates ``(a, b)``."""
        a = np.asarray(a, np.float64)
        b = np.asarray(b, np.float64)
        (cx, cy), (nx, ny) = self.direction, self.normal
        return np.stack([self.centre[0] + a * cx + b * nx, self.centre[1] + a * cy + b * ny], axis=-1)


@dataclass(frozen=True)
class HarpMount:
    """How the harp sits on the turntable: turntable angle -> :class:`HarpPose`.

    Parameters
    ----------
    centre : the turntable axis in the ideal image (px).
    angle0_deg : the strings' angle in the ideal image at turntable angle 0.
    direction : +1 when a positive turntable angle turns the strings from +x towards +y
        in the ideal image, -1 the other way.
    gravity_deg : the direction of gravity in the ideal image (90: along +y, down the
        rows of an upright camera).
    gravity_in_plane : the fraction of gravity in the harp's plane (1 for a vertical harp
        facing a horizontal camera, :math:`\\cos` of its tilt otherwise).
    """

    centre: tuple[float, float]
    angle0_deg: float = 0.0
    direction: int = 1
    gravity_deg: float = 90.0
    gravity_in_plane: float = 1.0

    def __post_init__(self) -> None:
        if self.direction not in (-1, 1):
            raise ValueError(f"direction must be -1 or +1, got {self.direction}")

    def pose(self, turntable_deg: float) -> HarpPose:
        """The harp at ``turntable_deg``: strings at ``angle0_deg + direction * turntable_deg``."""
        angle = (self.angle0_deg + self.direction * float(turntable_deg)) % 360.0
        t, g = math.radians(angle), math.radians(self.gravity_deg)
        gcos = self.gravity_in_plane * (-math.sin(t) * math.cos(g) + math.cos(t) * math.sin(g))
        return HarpPose(float(turntable_deg), angle, (float(self.centre[0]), float(self.centre[1])), gcos)


# ---------------------------------------------------------------- drawing a harp
def draw_harp(
    seed: int,
    n_strings: int,
    spacing_px: float,
    width_px: float,
    span_px: float,
    material: str | None = None,
    offset_px: float | None = None,
    visible_px: float | None = None,
    transmission: float = 0.0,
    coil_set_variation: float = COIL_SET_VARIATION,
) -> Harp:
    """A harp with physically drawn string shapes (module docstring), from a seed.

    Parameters
    ----------
    seed : everything below that is drawn comes from ``numpy.random.default_rng(seed)``.
    n_strings, spacing_px, width_px : the strings and their nominal pitch and width
        (harp px); the width and the drawn diameter set the scale ``mm_per_px``.
    span_px : the free length between the frame's anchors (harp px); every string spans
        it, centred within 5 % of it on the turntable axis.
    material : a key of :data:`MATERIALS`; None draws one.
    offset_px : ``b`` of the harp's middle (None: drawn within half a pitch).
    visible_px : half the length over which kinks are placed (default: half the span).
    transmission : the strings' transmission.
    coil_set_variation : the largest variation of the coil set along a span, as a fraction of
        the coil's curvature (default :data:`COIL_SET_VARIATION`; 1 is the most a spool can
        leave: a string cut from one end of the coil's curvature to the other).
    """
    if n_strings < 1 or not spacing_px > width_px > 0 or not span_px > 0:
        raise ValueError("draw_harp needs n_strings >= 1, spacing_px > width_px > 0 and span_px > 0")
    rng = np.random.default_rng(seed)
    name = material if material is not None else str(rng.choice(sorted(MATERIALS)))
    if name not in MATERIALS:
        raise ValueError(f"unknown string material {name!r}; known: {', '.join(sorted(MATERIALS))}")
    mat = MATERIALS[name]
    diameter = float(rng.uniform(*mat.diameter_mm))
    mm_per_px = diameter / width_px
    span_mm = span_px * mm_per_px
    tension0 = float(rng.uniform(*TENSION_FRACTION)) * breaking_load_n(mat, diameter)
    offset = float(rng.uniform(-0.5, 0.5) * spacing_px) if offset_px is None else float(offset_px)
    a_c = float(rng.uniform(-0.05, 0.05) * span_px)
    reach = 0.5 * span_px if visible_px is None else float(visible_px)
    twist_mm = float(rng.uniform(*TWIST_PERIOD_MM))
    strings = []
    for k in range(n_strings):
        tension = tension0 * float(np.clip(1.0 + 0.1 * rng.standard_normal(), 0.7, 1.3))
        ph = string_physics(mat, diameter, tension, span_mm)
        lam_mm = ph["stiffness_length_mm"]
        # bow: -lambda^2 * (coil-set variation along the span), over modes 1..3
        dkappa = float(rng.uniform(0.0, coil_set_variation)) / float(rng.uniform(*mat.coil_radius_mm))  # 1/mm
        weights = rng.standard_normal(3) / np.array([1.0, 2.0, 3.0])
        weights /= max(float(np.abs(weights).sum()), 1e-12)
        bow = tuple(float(v) for v in lam_mm * lam_mm * dkappa * weights / mm_per_px)
        kink_at, kink = 0.0, 0.0
        if rng.uniform() < KINK_PROBABILITY:
            alpha = float(rng.uniform(*KINK_ANGLE_RAD)) * float(rng.choice([-1.0, 1.0]))
            kink_at = float(rng.uniform(-reach, reach))
            kink = 0.5 * alpha * lam_mm / mm_per_px
        eps = float(rng.uniform(*mat.ovality))
        strings.append(
            StringShape(
                index=k,
                position_px=(k - (n_strings - 1) / 2.0) * spacing_px
                + offset
                + float(rng.normal(0.0, PLACEMENT_MM)) / mm_per_px,
                radius_px=0.5 * width_px,
                span_centre_px=a_c,
                half_span_px=0.5 * span_px,
                sag_px=ph["sag_mm"] / mm_per_px,
                bow_px=(bow[0], bow[1], bow[2]),
                kink_at_px=kink_at,
                kink_px=kink,
                kink_length_px=max(lam_mm / mm_per_px, 1e-3),
                ovality_px=0.25 * width_px * eps,
                twist_period_px=twist_mm * float(rng.uniform(0.8, 1.25)) / mm_per_px,
                twist_phase=float(rng.uniform(0, 2 * math.pi)),
                offcentre_px=float(rng.uniform(*mat.offcentre)) * width_px,
                pick_px=float(rng.uniform(*mat.pick_ripple)) * width_px,
                pick_period_px=float(rng.uniform(*mat.pick_period)) * width_px,
                pick_phases=(float(rng.uniform(0, 2 * math.pi)), float(rng.uniform(0, 2 * math.pi))),
            )
        )
    return Harp(tuple(strings), float(spacing_px), name, mm_per_px, tension0, transmission)
