r"""The harp checks itself: each string's own deviation from straightness, fitted with the lens.

A harp string is straight to a few micrometres, not exactly: it may bow, sag, carry a kink or the
twist of a braid. On one shot such a bend is indistinguishable from lens distortion. But the
station knows each shot's turntable angle, and a string keeps its shape *on the harp* as the harp
turns, while the lens's correction stays *on the sensor*: a bend that moves with the turntable is
the string's, one that stays is the lens's. This module fits both at once.

Model
-----
The harp's frame in the shots (:mod:`pipeline.harp_frame`, found first on the shots corrected by the plain
fit) has its strings run at :math:`\phi_i = \phi_0 + \sigma\theta_i` in the ideal image of shot :math:`i`
(turntable angle :math:`\theta_i`, :math:`\sigma = \pm 1`), with unit direction :math:`t_i` and normal
:math:`n_i`, about a centre :math:`c` (the turntable axis, in ideal pixels). A point :math:`x` of shot :math:`i`
has harp coordinates :math:`u = t_i\cdot(U(x) - c)/s` along the strings (:math:`s` half the image
diagonal) and :math:`q = n_i\cdot(U(x) - c)` across them. String :math:`k` lies at
:math:`q = q_k + \delta_k(u)` with its deviation

.. math:: \delta_k(u) = \sum_{j \in J} a_{kj} P_j(u),

:math:`P_j` the Legendre polynomials, :math:`J = \{2, 3, 4\}` by default (a bow, an S, a W:
the constant and linear parts are the string's own line, free in every shot anyway). The fit
minimises the straightness objective of :mod:`pipeline.fit` of the points corrected by the lens
*and* moved back by their string's deviation, :math:`U_\theta(x) - \delta_k(u)\,n_i`, over the
lens parameters :math:`\theta` and every :math:`a_{kj}` at once (Levenberg-Marquardt on the
normal equations, :func:`pipeline.fit_solver.solve`), with a weak ridge on the :math:`a_{kj}`
(:data:`STRING_RIDGE`).

What can and cannot be separated
--------------------------------
* A deviation that turns with the harp is separated from the lens's correction by the different
  places and directions the string takes in the image: it needs the string in two shots or more
  at different angles (strings seen in one shot, or over less than :data:`MIN_SPAN`, get no
  deviation terms).
* Only bends on scales longer than the along-edge smoothing are seen (:math:`\sigma = 0.8\sqrt{t^2-1}`,
  24 px at t = 30): a kink a few pixels long is smoothed into a bump of the smoother's own shape before
  any fit, and P2..P4 hold the smooth part of a string's shape over the stretch of it the image shows.
  With ``kinks=True`` the bumps that sit at the same harp coordinate in two shots or more are found
  and modelled as terms of their string's deviation (:mod:`pipeline.harp_kinks`).
* A rotationally symmetric (radial) lens correction about the turntable axis bends a line at
  distance :math:`q` from the axis the same way whatever its direction: for a harp turning about
  the distortion centre it is *exactly* a set of string deviations :math:`\delta_k` depending on
  :math:`q_k` only. That part cannot be told apart by turning the harp; the ridge gives it to the
  lens (no penalty there), which is the physical reading (a harp whose strings bow in proportion
  to a radial law of their distance from the axis is not plausible). The farther the axis from the
  distortion centre, the better the separation.
* Shots about two turntable axes or more (the harp moved *with* its turntable between groups of shots,
  ``fit_harp_shape(axis_groups=...)``) separate that part too: a string keeps its distance from the
  turntable axis while its distance from the distortion centre changes, and a radial term about the
  distortion centre plus a thin prism imitates string bends about one axis but not about two on opposite
  sides of it. Each group's axis is found on its own shots (or about a rough shift given per group,
  :func:`pipeline.harp_frame.group_frames`); no radial gauge is held. The ridge stays :data:`STRING_RIDGE`: it
  still takes a part of what two axes see (about half of it for the bends of ``tests/pipeline/test_harp_shape.py``'s
  two-axis case with axes 170 px from the centre), but a ten times weaker one was worse on realistic
  renders (``benchmarks/axis_positions.py --realistic``, ``benchmarks/RESULTS-strings.md``).
* A residual field (``FitSpec.field``) is fixed on the sensor, but its part that turns with a rotation about the
  turntable axis (radial and tangential displacements that depend on the distance from the axis only) looks the
  same in the harp's frame at every angle: it is a set of string deviations, one per string at its distance
  from the axis, and shots about one axis cannot tell the two apart. That part is held off the field
  (:meth:`pipeline.models.radial_field.RadialFieldParametrisation.with_axis_gauge`) and the strings take it; a
  shrink about the axis is such a part. In whole simulated sessions of twelve shots it had let a field take the
  strings' bends on lenses without one and win the folds by 3.4 and 5.3 paired standard errors
  (``benchmarks/RESULTS-residual-field.md``). About two axes or more, each axis's part is a set of bends in that
  axis's shots only, and the other axis's shots see little of it when the axes are a few hundred pixels apart:
  the union of every axis's part is held off the field. Held about one axis of two, a whole session about two
  places let a field take a lens without one from 0.0020 to 0.0039 px.
* A sag under gravity is not fixed to the harp (it follows the vertical as the harp turns); a sag
  of equal strings is, to second order, a thin-prism term of the lens, which absorbs it.
* The straightness of corrected edges is measured in corrected pixels, so a correction that shrinks
  the image straightens every edge by the same factor. With the distortion centre free (the scale is
  held to 1 only there), a joint fit, given room by the strings' terms and a weakly penalised field, can
  slide that way: the centre runs far outside the image while the image shrinks to a fraction of its
  size, and the held-out shots, corrected by the shrunken lens, look straighter too. Such a fit is made
  again with the centre held under the centre prior, and says so (:func:`_solve_joint`,
  :data:`pipeline.fit.MIN_CORRECTION_SCALE`).
* Without turntable angles (loose photographs) nothing ties a string of one shot to a string of
  another: string deviations cannot be separated from the lens at all, and a bent string shows
  only as residual straightness.

What a session keeps
--------------------
The lens of the joint fit, with the strings' deviations left out (:func:`lens_result` gives its figures on
the points corrected by the lens alone; :func:`separated_job` is one leave-one-orientation-out fold of it):
a lens fitted alone takes the part of the bends that every orientation shares into the correction.

The harp check's figures (each string's coefficients, bend and standard error) come from a second fit of the
strings alone with that lens held and a weaker ridge (:data:`REPORT_RIDGE`): the joint fit's ridge hands the lens
a part of every bend, which a held lens cannot take. That fit also measures the edges the plain fit rejected as
outliers that lie on a string (a bent string's edges, rejected where its bend shows most): the lens is fitted
without them, as before, and the check sees every string (``fit_harp_shape(readmit=...)``). A shot measured far
worse than the others (edges along the pixel rows or columns) is weighed by its noise in that fit
(:data:`SHOT_NOISE_FACTOR`), and where a string's own bend is judged is set by :func:`own_bends`.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera distortion
   measurements with a calibration harp", JOSA A 29(10), 2012 (string straightness, Sect. 2).
.. [2] G. H. Golub, V. Pereyra, "Separable nonlinear least squares: the variable projection
   method and its applications", Inverse Problems 19(2), 2003.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.edgeset import EdgeSet, FitFailure, FitResult, RejectedEdge, collect, edge_figures, summarise, tls
from pipeline.fit import collapses, correction_problem, fit_distortion, outlier_edges
from pipeline.fit_problem import make_parametrisation, normal_equations
from pipeline.fit_solver import solve
from pipeline.fitspec import CENTER_PRIOR_WEIGHT, FitSpec
from pipeline.harp_frame import AXIS_TOLERANCE, HarpFrame, gap_clusters, group_frames, harp_frame
from pipeline.harp_kinks import KINK_Z, Candidate, Kink, end_weights, peak_per_area, scan_string, stretches, template
from pipeline.models.base import DistortionModel
from pipeline.models.radial_field import ProjectedRows, RadialFieldParametrisation
from pipeline.plain import finite_or_none
from pipeline.resample import DEFAULT_T

Floats = NDArray[np.float64]

DEVIATION_TERMS: tuple[int, ...] = (2, 3, 4)
"""Legendre degrees of a string's deviation along the harp coordinate ``u``."""

STRING_RIDGE = 0.02
"""Weight of the ridge on the deviation coefficients: a coefficient of ``a`` px costs like a residual
of ``STRING_RIDGE * a`` px on every point (a bend of 0.02 px like 4e-4 px). It fixes what turning the harp
cannot see, and it hands the lens a part of what it sees: 10-30 % of a single string's bow on exact edges. The
bends the harp check reports are therefore fitted again with the lens held (:data:`REPORT_RIDGE`)."""

GAUGE_WEIGHT = 1.0
"""Weight of the constraint holding the string deviations off what a radial lens term can imitate
(:func:`_radial_gauge`): per point, like the ridge."""

MIN_SPAN = 0.8
"""Shortest stretch of ``u`` (half image diagonals) over which a string must be seen, in all its shots
together, to get deviation terms: over a shorter one P2..P4 are barely determined and the ridge
shrinks them to nothing (the outermost strings, seen only in the corners)."""

BEND_LIMIT_PX = 0.02
"""Default QA limit of a string's bend (largest ``|delta_k|`` over where it was seen)."""

REPORT_RIDGE = 0.25 * STRING_RIDGE
"""Weight of the ridge on the deviation coefficients when the harp check fits them again with the lens held
(:func:`fit_harp_shape`: the bends it reports). The joint fit's ridge (:data:`STRING_RIDGE`) steadies the lens, and
in doing so hands the lens part of every bend: on exact edges a single string bowed by 0.017 px was reported at
0.012 px. Fitted again with the lens held, a bend cannot leak into the lens; with no ridge at all, though, the
strings seen over little of their length (the image's corners) swing. ``benchmarks/harp_health.py``, ten realistic
harps with two strings bowed on purpose (seeds 0..9): within 20 % of the drawn bend 15 of 18 forced bends with this
ridge and with none, 11 with :data:`STRING_RIDGE`; strings drawn straighter than 0.01 px reported beyond 0.02 px:
1, 12 and 0 (``benchmarks/RESULTS-harp-health.md``, also on seeds 10..19)."""

REPORT_OUTLIER_FLOOR_PX = 0.1 * BEND_LIMIT_PX
"""Least residual RMS (px) of an edge that the harp check rejects as an outlier (:func:`_report_points`). On
exact edges the median edge RMS is some 1e-4 px and five times it rejected bowed strings whose Legendre terms
left 5e-4 px; an edge this straight carries no shape near the bend limit. Measured edges (0.005-0.01 px RMS)
never come near it."""

SHOT_NOISE_FACTOR = 2.0
"""A shot whose median edge residual (RMS, px) exceeds this times the median over all edges is weighed by its
variance in the harp check's fit of the strings (:func:`shot_weights`); the others keep weight 1. Edges that run
within a degree of the pixel grid are measured worse: their sub-pixel phase drifts slowly along them and the
detector's phase error (pixel locking) is a wave of a few hundred pixels that the along-edge smoother does not
remove. On ``benchmarks/harp_health.py``'s seed 11, whose strings lie along the rows and columns at two of the six
angles, those edges' residuals are 3.5 times the others' and they bent a string drawn straight to 0.039 px
(0.0436 px own bend, 2.7 standard errors) about two axis places; weighed, 0.007 px. Between ordinary shots the ratio
stays near or below 2: the largest on seeds 0..19 were 1.98 and 2.2 about one place, 2.1 about two (seed 11: 3.4-3.7).
Below the factor every shot keeps weight 1, as before: weighing every shot by its variance moved the forced bends of
seeds 0..9 (one place) from 15 to 13 of 18 within 20 %. A shot-wide figure does not single out a bent or kinked
string, which is in every shot: weighing each edge by its own residual did, and hid a kinked string (seed 2: 0.054
-> 0.023 px). Measured through the realistic renderer (``benchmarks/grid_angle.py``, ``RESULTS-edges.md``): an
edge's residual after the along-edge smoother is 0.03 px at 0.25-1 degree from the pixel grid with a Bayer demosaic
(bilinear or edge-aware), 0.011 px at 2 degrees, 0.002 px at 8 and beyond; 0.002-0.006 px with a half-size
conversion."""


def shot_weights(rms: Floats, image: NDArray[np.intp]) -> tuple[Floats, dict[int, float]]:
    r"""Per-edge weights from each shot's measurement noise: :math:`(m / m_s)^2` for the edges of a shot ``s``
    whose median edge residual :math:`m_s` exceeds :data:`SHOT_NOISE_FACTOR` times the median :math:`m` over all
    edges, 1 for the others; and those shots with :math:`m_s / m`. ``rms``: each edge's residual RMS (px),
    ``image``: its shot.

    References
    ----------
    .. [1] R. J. Carroll, D. Ruppert, *Transformation and Weighting in Regression*, Chapman & Hall, 1988, ch. 3
       (weights from variances estimated per group of observations).
    """
    m = float(np.median(rms))
    w = np.ones(len(rms))
    noisy = {}
    for s in np.unique(image):
        on = image == s
        ms = float(np.median(rms[on]))
        if m > 0 and ms > SHOT_NOISE_FACTOR * m:
            w[on] = (m / ms) ** 2
            noisy[int(s)] = ms / m
    return w, noisy


def legendre(u: Floats, degrees: Sequence[int]) -> Floats:
    """``P_j(u)`` for every degree ``j`` in ``degrees``, rows in that order (Bonnet's recursion)."""
    u = np.asarray(u, dtype=np.float64)
    top = max(degrees) if degrees else 0
    p = [np.ones_like(u), u]
    for n in range(1, top):
        p.append(((2 * n + 1) * u * p[n] - n * p[n - 1]) / (n + 1))
    return np.array([p[j] for j in degrees]).reshape(len(degrees), *u.shape)


@dataclass(frozen=True)
class StringShape:
    """One string's fitted deviation :math:`\\delta_k(u) = \\sum_j a_j P_j(u)` (pixels of the ideal image).

    ``offset_px``: its distance ``q_k`` from the axis; ``span``: the range of ``u`` where it was seen;
    ``bend_px``: the largest ``|delta_k|`` over that range, ``bend_se_px`` its standard error (from the
    covariance of lens and strings together, at the place of the largest deviation); ``shots``: in how many
    shots it was seen (deviation terms need two or more: otherwise ``coefficients`` is empty and ``bend_px``
    NaN). The coefficients are those of the strings fitted again with the lens held (:data:`REPORT_RIDGE`).
    ``seen_twice``: the stretch of ``u`` that two shots or more see (the hull of the overlaps of its shots'
    stretches, :func:`seen_twice`; NaN, NaN when no two shots overlap)."""

    index: int
    offset_px: float
    degrees: tuple[int, ...]
    coefficients: tuple[float, ...]
    standard_errors: tuple[float, ...]
    span: tuple[float, float]
    shots: int
    edges: int
    points: int
    bend_px: float
    bend_se_px: float
    seen_twice: tuple[float, float] = (float("nan"), float("nan"))

    def deviation(self, u: Floats) -> Floats:
        """``delta_k(u)`` (pixels); zero where the string has no deviation terms."""
        u = np.asarray(u, dtype=np.float64)
        if not self.coefficients:
            return np.zeros_like(u)
        out: Floats = np.asarray(self.coefficients) @ legendre(u.ravel(), self.degrees)
        return out.reshape(u.shape)

    def judged(self, u: Floats) -> NDArray[np.bool_]:
        """Where the QA judges this string's own bend (:func:`own_bends`): within its span, and there within half
        the image's diagonal of the axis (:math:`|u| \\le 1`) or where two shots or more see it (``seen_twice``)."""
        u = np.asarray(u, dtype=np.float64)
        lo, hi = self.seen_twice  # NaN, NaN: nowhere
        out: NDArray[np.bool_] = (
            (u >= self.span[0]) & (u <= self.span[1]) & ((np.abs(u) <= 1.0) | ((u >= lo) & (u <= hi)))
        )
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "offset_px": self.offset_px,
            "degrees": list(self.degrees),
            "coefficients": list(self.coefficients),
            "standard_errors": list(self.standard_errors),
            "span": list(self.span),
            "shots": self.shots,
            "edges": self.edges,
            "points": self.points,
            "bend_px": finite_or_none(self.bend_px),
            "bend_se_px": finite_or_none(self.bend_se_px),
            "seen_twice": [finite_or_none(v) for v in self.seen_twice],
        }


def seen_twice(u: Floats, shot: NDArray[np.intp]) -> tuple[float, float]:
    """The stretch of a string that two shots or more see: the hull of the overlaps of its shots' stretches of
    ``u`` (each point's ``u`` and shot); NaN, NaN when no two shots' stretches overlap."""
    ranges = [(float(u[shot == s].min()), float(u[shot == s].max())) for s in np.unique(shot)]
    lo, hi = np.inf, -np.inf
    for i, (a0, a1) in enumerate(ranges):
        for b0, b1 in ranges[i + 1 :]:
            if max(a0, b0) < min(a1, b1):
                lo, hi = min(lo, max(a0, b0)), max(hi, min(a1, b1))
    return (lo, hi) if lo < hi else (float("nan"), float("nan"))


def own_bends(strings: Sequence[StringShape], samples: int = 201) -> dict[int, float]:
    r"""Each string's bend *apart from what all strings share* (pixels): the largest
    :math:`|\delta_k(u) - \tilde\delta(u)|` where the string is judged, :math:`\tilde\delta` the median of the
    *other* strings' deviations at :math:`u` (where at least half of them reach). A part common to every string
    (a whole harp's sag, or a lens term the model lacks, which the fit can only put into the strings) is not one
    string's fault and cannot be told from the lens; a single bent string stands out of it. Strings without
    deviation terms are left out.

    **Where a string is judged:** within half the image's diagonal of the axis (:math:`|u| \le 1`), and beyond
    it where two shots or more see the string (``seen_twice``). About one axis place a string is seen within
    :math:`|u| \le 1` in shots 30 degrees apart that each see another stretch of it, and a bow is largest at the
    ends of the stretch the shots see together; beyond it (about a second place, or a harp wider than the image)
    a stretch one shot sees is the end of one edge, where a bend cannot be told from that edge's noise (a straight
    string of the demo harp read 0.024 px, three standard errors, at u = -1.22), while a stretch two shots see is
    where a bend about two places is largest. ``samples``: grid points per unit of ``u`` over [-1, 1], as many
    per unit beyond."""
    bent = [st for st in strings if st.coefficients]
    if not bent:
        return {}
    lo = min(-1.0, min(st.span[0] for st in bent))
    hi = max(1.0, max(st.span[1] for st in bent))
    u = np.linspace(lo, hi, int(np.ceil((samples - 1) * (hi - lo) / 2.0)) + 1)
    dev = np.vstack([st.deviation(u) for st in bent])
    inside = np.vstack([(u >= st.span[0]) & (u <= st.span[1]) for st in bent])
    judged = np.vstack([st.judged(u) for st in bent])
    enough = max(3, len(bent) // 2)  # where fewer strings reach, the median is not the others' (none taken)
    out = {}
    for i, st in enumerate(bent):
        others = np.delete(np.arange(len(bent)), i)
        common = np.zeros(len(u))
        for j in range(len(u)):
            reach = others[inside[others, j]]
            if len(reach) >= enough:
                common[j] = np.median(dev[reach, j])
        own = np.abs(dev[i] - common)[judged[i]]
        out[st.index] = float(own.max()) if own.size else float("nan")
    return out


@dataclass(frozen=True)
class HarpShapeFit:
    """The lens fitted with every string's deviation (:func:`fit_harp_shape`).

    ``model`` the lens correction fitted jointly, ``plain`` the fit without string terms (its start);
    ``d_after`` the straightness of the points corrected by both, ``d_lens_only`` of the same points
    corrected by ``model`` alone (pixels); ``axis_groups`` each axis group's frame when the harp was moved
    between groups of shots (``frame`` is then the first group's), empty otherwise; ``warnings`` what the fit
    had to do that changes the model's meaning (the distortion centre held when it collapsed the correction,
    :func:`_solve_joint`); ``rejected`` the edges given back to the harp check (``readmit``) that the strings'
    fit did not explain either, and why; ``noisy_shots`` the shots the check weighed by their variance
    (:func:`shot_weights`), each with its median edge residual over the median edge's."""

    model: DistortionModel
    plain: FitResult
    frame: HarpFrame
    strings: tuple[StringShape, ...]
    d_after: float
    d_lens_only: float
    n_params: int
    axis_groups: tuple[tuple[Hashable, HarpFrame], ...] = ()
    kinks: tuple[Kink, ...] = ()
    warnings: tuple[str, ...] = ()
    rejected: tuple[RejectedEdge, ...] = ()
    noisy_shots: tuple[tuple[int, float], ...] = ()

    @property
    def worst(self) -> StringShape | None:
        """The string with the largest bend (None when no string has deviation terms)."""
        bent = [s for s in self.strings if np.isfinite(s.bend_px)]
        return max(bent, key=lambda s: s.bend_px) if bent else None

    def own_bends(self, samples: int = 201) -> dict[int, float]:
        """Each string's bend apart from what all strings share (pixels): :func:`own_bends` of :attr:`strings`."""
        return own_bends(self.strings, samples)

    def bent_strings(self, limit_px: float = BEND_LIMIT_PX) -> tuple[StringShape, ...]:
        """The strings bent beyond ``limit_px``."""
        return tuple(s for s in self.strings if np.isfinite(s.bend_px) and s.bend_px > limit_px)

    def __bool__(self) -> Literal[True]:  # a result is true, a FitFailure false
        return True

    def to_dict(self) -> dict[str, Any]:
        return (
            {
                "frame": self.frame.to_dict(),
                "strings": [s.to_dict() for s in self.strings],
                "d_after": self.d_after,
                "d_lens_only": self.d_lens_only,
                "n_params": self.n_params,
                "kinks": [k.to_dict() for k in self.kinks],
                "model": self.model.to_dict(),
            }
            | ({"axis_groups": {str(g): f.to_dict() for g, f in self.axis_groups}} if self.axis_groups else {})
            | ({"warnings": list(self.warnings)} if self.warnings else {})
            | ({"noisy_shots": {str(i): r for i, r in self.noisy_shots}} if self.noisy_shots else {})
            | (
                {"rejected": [{"image": r.image, "line": r.line, "reason": r.reason} for r in self.rejected]}
                if self.rejected
                else {}
            )
        )


# ------------------------------------------------------------------ the joint fit
@dataclass(frozen=True)
class _Placed:
    """An edge set placed in the harp's frame: per edge its string (``edge_string``), per point its edge, shot,
    harp normal, ``u`` along the strings (half image diagonals) and ``q`` across them (px), the ideal points
    (``ideal``, by the plain fit's lens); the strings seen in each shot (``shots_of``), those with deviation terms
    (``with_terms``: two shots or more over :data:`MIN_SPAN`), per point its slot among them (``string_of``, -1
    for none) and the Legendre values (``basis``); ``rank`` the renumbering of the strings, when made."""

    edges: EdgeSet
    edge_string: NDArray[np.intp]
    point_edge: NDArray[np.intp]
    point_shot: NDArray[np.intp]
    normal: Floats
    u: Floats
    q: Floats
    ideal: Floats
    shots_of: dict[int, set[int]]
    with_terms: list[int]
    string_of: NDArray[np.intp]
    basis: Floats
    rank: NDArray[np.intp] | None

    @property
    def point_string(self) -> NDArray[np.intp]:
        out: NDArray[np.intp] = self.edge_string[self.point_edge]
        return out

    @property
    def stretch(self) -> Floats:
        """Each point's along-edge stretch (:func:`pipeline.harp_kinks.stretches`)."""
        return stretches(self.edges.xy, self.ideal, self.edges.starts, self.edges.counts)


def _placed(
    edges: EdgeSet,
    edge_string: NDArray[np.intp],
    shot_frame: Sequence[HarpFrame],
    turntable_deg: Sequence[float],
    model0: DistortionModel,
    scale: float,
    degrees: Sequence[int],
    renumber: bool = False,
) -> _Placed:
    """``edges`` (each edge's string ``edge_string``) in the harp's frame of its shot (:class:`_Placed`); with
    ``renumber`` the strings numbered again from the lowest ``q`` (a string found among edges given back)."""
    ideal = model0.undistort_points(edges.xy)
    point_edge = np.repeat(np.arange(edges.n_edges), edges.counts)
    point_shot = edges.image[point_edge]
    normals = np.array([f.normal(float(t)) for f, t in zip(shot_frame, turntable_deg, strict=True)])
    directions = np.array([f.direction(float(t)) for f, t in zip(shot_frame, turntable_deg, strict=True)])
    rel = ideal - np.array([f.centre for f in shot_frame])[point_shot]
    u = np.einsum("ij,ij->i", rel, directions[point_shot]) / scale
    q = np.einsum("ij,ij->i", rel, normals[point_shot])
    rank = None
    if renumber and edges.n_edges:
        ks = np.unique(edge_string)
        order = ks[np.argsort([np.median(q[edge_string[point_edge] == k]) for k in ks])]
        rank = np.zeros(int(ks.max()) + 1, np.intp)
        rank[order] = np.arange(len(order))
        edge_string = rank[edge_string]
    shots_of = {int(k): {int(edges.image[e]) for e in np.flatnonzero(edge_string == k)} for k in np.unique(edge_string)}
    point_string = edge_string[point_edge]
    reach = {k: float(np.ptp(u[point_string == k])) for k in shots_of}
    with_terms = sorted(k for k, v in shots_of.items() if len(v) >= 2 and reach[k] >= MIN_SPAN)
    slot = {k: s for s, k in enumerate(with_terms)}
    string_of = np.array([slot.get(int(edge_string[e]), -1) for e in point_edge], dtype=np.intp)
    return _Placed(
        edges, edge_string, point_edge, point_shot, normals[point_shot], u, q, ideal, shots_of, with_terms,
        string_of, legendre(u, degrees), rank,
    )  # fmt: skip


def _report_points(
    wider: tuple[EdgeSet, NDArray[np.intp], dict[tuple[int, int], tuple[int, int]]],
    shot_frame: Sequence[HarpFrame],
    turntable_deg: Sequence[float],
    model0: DistortionModel,
    scale: float,
    degrees: Sequence[int],
    joint: DistortionModel,
    placed: Sequence[tuple[int, Candidate]],
    kink_t: int,
    max_nfev: int,
) -> tuple[_Placed, dict[int, int], tuple[RejectedEdge, ...], _Held]:
    """The edges the harp check measures: the lens's and those given back (``wider``: :func:`_with_edges`), in the
    harp's frame with the strings numbered again; each kink's string in that numbering; the edges left out by
    :func:`pipeline.fit.fit_distortion`'s outlier rule (:func:`pipeline.fit.outlier_edges`, with
    :data:`REPORT_OUTLIER_FLOOR_PX`) on the residuals of the strings fitted with ``joint`` held; and that fit on
    the edges kept (:func:`_held_strings`)."""
    edges, edge_string, origin = wider
    rep = _placed(edges, edge_string, shot_frame, turntable_deg, model0, scale, degrees, renumber=True)
    kink_of = {k: k for k, _ in placed} if rep.rank is None else {k: int(rep.rank[k]) for k, _ in placed}
    held = _held_strings(rep, joint, placed, kink_of, scale, kink_t, max_nfev)
    if not np.all(np.isfinite(held.x)):
        return rep, kink_of, (), held
    rms = _edge_rms(held.problem, edges, held.x)
    bad, limit, _ = outlier_edges(rms, floor=REPORT_OUTLIER_FLOOR_PX)
    if not len(bad):
        return rep, kink_of, (), held
    rejected = tuple(
        RejectedEdge(*origin[(int(edges.image[e]), int(edges.line[e]))],
                     f"outlier of the strings' fit: residual RMS {rms[e]:.3g} px > {limit:.3g} px")
        for e in bad
    )  # fmt: skip
    keep = np.ones(edges.n_edges, bool)
    keep[bad] = False
    left = _placed(edges.subset(keep), rep.edge_string[keep], shot_frame, turntable_deg, model0, scale, degrees)
    return left, kink_of, rejected, _held_strings(left, joint, placed, kink_of, scale, kink_t, max_nfev)


def _held_strings(
    pts: _Placed,
    joint: DistortionModel,
    placed: Sequence[tuple[int, Candidate]],
    kink_of: Mapping[int, int],
    scale: float,
    kink_t: int,
    max_nfev: int,
) -> _Held:
    """The strings' terms and kinks' peaks over ``pts`` fitted with the lens ``joint`` held and the ridge
    :data:`REPORT_RIDGE` (the bends the harp check reports), then again with the shots measured worse than the
    others weighed by their variance (:func:`shot_weights`) when there are such."""
    held = _WithStrings(
        _HeldLens(joint), pts.string_of, pts.basis, pts.normal, len(pts.with_terms), REPORT_RIDGE, None,
        _kink_templates(pts, placed, kink_of, scale, kink_t),
    )  # fmt: skip
    e = pts.edges
    with np.errstate(all="ignore"):
        x = solve(held, e, held.theta0(None), max_nfev=max_nfev).x
    if not np.all(np.isfinite(x)):
        return _Held(held, x, None, {})
    w, noisy = shot_weights(_edge_rms(held, e, x), e.image)
    if not noisy:
        return _Held(held, x, None, {})
    with np.errstate(all="ignore"):
        x = solve(held, e, x, edge_weights=w, max_nfev=max_nfev).x
    return _Held(held, x, w, noisy)


def _edge_rms(param: _WithStrings, edges: EdgeSet, x: Floats) -> Floats:
    """Each edge's residual RMS (px) about its line, corrected by ``param`` at ``x``."""
    r = tls(param.evaluate(edges.xy, x, jac=False)[0], edges.starts, edges.counts)[0]
    out: Floats = edge_figures(r, edges.starts, edges.counts)[0]
    return out


@dataclass(frozen=True)
class _Held:
    """The harp check's fit of the strings with the lens held (:func:`_held_strings`): the problem, its solution,
    the edges' weights (None: all 1) and the shots weighed, each with its median edge residual over the median
    edge's."""

    problem: _WithStrings
    x: Floats
    edge_weights: Floats | None
    noisy: dict[int, float]


def _kink_templates(
    pts: _Placed, placed: Sequence[tuple[int, Candidate]], kink_of: Mapping[int, int], scale: float, t: int
) -> Floats:
    """The templates ``(kinks, N)`` of the kinks ``placed`` (string ``kink_of[k]`` in ``pts``' numbering) over the
    points of ``pts`` (:func:`pipeline.harp_kinks.template`, as :func:`_kink_columns` makes them)."""
    out = np.zeros((len(placed), len(pts.edges.xy)))
    if not placed:
        return out
    a_px, stretch, point_string = pts.u * scale, pts.stretch, pts.point_string
    for row, (k, c) in zip(out, placed, strict=True):
        idx = np.flatnonzero(point_string == kink_of[k])
        row[idx] = template(a_px[idx] - c.at_px, stretch[idx], t, c.length_px)
    return out


class _WithStrings:
    """Lens parameters and string deviation coefficients, for :func:`pipeline.fit_solver.solve` on one edge set.

    ``theta = [lens theta, a_kj for every string with terms]``; the corrected points are
    ``U(x) - delta_k(u) n`` (module docstring), ``u`` and ``n`` per point fixed from the start."""

    def __init__(
        self,
        lens: Any,
        string_of: NDArray[np.intp],
        basis: Floats,
        normal: Floats,
        n_strings: int,
        ridge: float,
        gauge: Floats | None = None,
        kinks: Floats | None = None,
    ) -> None:
        self.lens = lens
        self.string_of = string_of  # per point: index among the strings with terms, or -1
        self.basis = basis  # (m, N) Legendre values per point
        self.normal = normal  # (N, 2) harp normal per point
        self.m = basis.shape[0]
        self.k = n_strings
        self.kinks = np.zeros((0, len(string_of))) if kinks is None else kinks  # (kinks, N) templates g
        self.n = int(lens.n) + self.k * self.m + len(self.kinks)
        self.ridge = ridge
        self.gauge = np.zeros((0, self.k * self.m)) if gauge is None else gauge  # rows: directions held at 0
        has = string_of >= 0
        self._cols = [(np.flatnonzero(has & (string_of == s))) for s in range(n_strings)]

    def theta0(self, init: DistortionModel | None) -> Floats:
        out: Floats = np.concatenate([self.lens.theta0(init), np.zeros(self.k * self.m + len(self.kinks))])
        return out

    def model(self, th: Floats) -> DistortionModel:
        m: DistortionModel = self.lens.model(th[: self.lens.n])
        return m

    def deviation(self, th: Floats) -> Floats:
        """``delta_k(u)`` per point (0 for points of strings without terms), kinks included."""
        ks = self.k * self.m
        a = th[self.lens.n : self.lens.n + ks].reshape(self.k, self.m)
        out = np.zeros(len(self.string_of))
        for s, idx in enumerate(self._cols):
            out[idx] = a[s] @ self.basis[:, idx]
        if len(self.kinks):
            out += th[self.lens.n + ks :] @ self.kinks
        return out

    def evaluate(self, xy: Floats, th: Floats, jac: bool = True) -> tuple[Floats, Any]:
        u, _ = self.lens.evaluate(xy, th[: self.lens.n], jac=False)
        return u - self.deviation(th)[:, None] * self.normal, None

    def regularisation(self, th: Floats, n_points: int) -> tuple[Floats, Floats]:
        g, jg = self.lens.regularisation(th[: self.lens.n], n_points)
        w = np.sqrt(max(n_points, 1)) * self.ridge
        ks = self.k * self.m
        jr = np.zeros((ks, self.n))  # the kinks' peaks: no ridge
        jr[:, self.lens.n : self.lens.n + ks] = w * np.eye(ks)
        wg = np.sqrt(max(n_points, 1)) * GAUGE_WEIGHT
        jq = np.zeros((len(self.gauge), self.n))
        jq[:, self.lens.n : self.lens.n + ks] = wg * self.gauge
        jl = np.zeros((len(g), self.n))
        jl[:, : self.lens.n] = jg
        a = th[self.lens.n : self.lens.n + ks]
        rows: Floats = np.concatenate([g, w * a, wg * (self.gauge @ a)])
        return rows, np.vstack([jl, jr, jq])

    def project(self, xy: Floats, th: Floats, nrm: Floats, tan: Floats) -> tuple[Floats, Floats]:
        p_l, t_l = self.lens.project(xy, th[: self.lens.n], nrm, tan)
        p_mat = np.zeros((self.n, len(xy)))
        t_mat = np.zeros((self.n, len(xy)))
        p_mat[: self.lens.n], t_mat[: self.lens.n] = p_l, t_l
        self._own_rows(nrm, tan, p_mat, t_mat, self.lens.n)
        return p_mat, t_mat

    def project_rows(self, xy: Floats, th: Floats, nrm: Floats, tan: Floats) -> ProjectedRows:
        """:meth:`project` with a residual field's rows kept sparse (:class:`ProjectedRows`), the lens's when it
        has them (:meth:`RadialFieldParametrisation.project_rows`); else every row dense."""
        if not isinstance(self.lens, RadialFieldParametrisation):
            p_mat, t_mat = self.project(xy, th, nrm, tan)
            return ProjectedRows(self.n, np.arange(self.n), p_mat, t_mat, None)
        lens = self.lens.project_rows(xy, th[: self.lens.n], nrm, tan)
        n_l, n_own = len(lens.rows), self.n - self.lens.n
        p_mat = np.zeros((n_l + n_own, len(xy)))
        t_mat = np.zeros((n_l + n_own, len(xy)))
        p_mat[:n_l], t_mat[:n_l] = lens.p, lens.t
        self._own_rows(nrm, tan, p_mat, t_mat, n_l)
        rows = np.concatenate([lens.rows, np.arange(self.lens.n, self.n)])
        return ProjectedRows(self.n, rows, p_mat, t_mat, lens.field)

    def _own_rows(self, nrm: Floats, tan: Floats, p_mat: Floats, t_mat: Floats, at: int) -> None:
        """The strings' and kinks' rows of ``P`` and ``T`` written from row ``at`` on (zeros beforehand)."""
        dn = -np.einsum("ij,ij->i", self.normal, nrm)  # d(point)/d(delta) projected: -n_harp . n_line
        dt = -np.einsum("ij,ij->i", self.normal, tan)
        for s, idx in enumerate(self._cols):
            r0 = at + s * self.m
            p_mat[r0 : r0 + self.m, idx] = self.basis[:, idx] * dn[idx]
            t_mat[r0 : r0 + self.m, idx] = self.basis[:, idx] * dt[idx]
        r0 = at + self.k * self.m
        p_mat[r0:] = self.kinks * dn
        t_mat[r0:] = self.kinks * dt


class _HeldLens:
    """A lens held fixed: no free parameters (the harp check's fit of the strings, :func:`fit_harp_shape`)."""

    n = 0

    def __init__(self, model: DistortionModel) -> None:
        self._model = model

    def theta0(self, init: DistortionModel | None) -> Floats:
        return np.zeros(0)

    def model(self, th: Floats) -> DistortionModel:
        return self._model

    def evaluate(self, xy: Floats, th: Floats, jac: bool = True) -> tuple[Floats, Any]:
        out: Floats = self._model.undistort_points(xy)
        return out, None

    def regularisation(self, th: Floats, n_points: int) -> tuple[Floats, Floats]:
        return np.zeros(0), np.zeros((0, 0))

    def project(self, xy: Floats, th: Floats, nrm: Floats, tan: Floats) -> tuple[Floats, Floats]:
        return np.zeros((0, len(xy))), np.zeros((0, len(xy)))


def _readmitted(
    lines: Sequence[Sequence[Floats]],
    outliers: Sequence[tuple[int, int]],
    pts: _Placed,
    shot_frame: Sequence[HarpFrame],
    turntable_deg: Sequence[float],
    model: DistortionModel,
    pitch: float,
) -> dict[tuple[int, int], int]:
    """The plain fit's outlier edges ``(shot, line)`` that lie on a string of the harp, with that string: the
    distance of the edge's middle from its shot's axis within :data:`pipeline.harp_frame.AXIS_TOLERANCE` pitches of a kept edge's
    (of any shot), whose string it takes, or of other outlier edges' in other shots (a string the plain fit
    rejected in every shot, a new string); an edge that lies on no string (a frame's, a shadow's) stays out."""
    if not outliers:
        return {}
    edge_string = pts.edge_string
    q_kept = np.bincount(pts.point_edge, pts.q, minlength=len(edge_string)) / pts.edges.counts
    out: dict[tuple[int, int], int] = {}
    alone: list[tuple[float, tuple[int, int]]] = []
    for i, j in outliers:
        f = shot_frame[i]
        mid = model.undistort_points(np.asarray(lines[i][j], np.float64).reshape(-1, 2)).mean(axis=0)
        if not np.all(np.isfinite(mid)):
            continue
        q = float(f.normal(float(turntable_deg[i])) @ (mid - f.centre))
        near = int(np.argmin(np.abs(q_kept - q)))
        if abs(q_kept[near] - q) <= AXIS_TOLERANCE * pitch:
            out[(i, j)] = int(edge_string[near])
        else:
            alone.append((q, (i, j)))
    # a string the plain fit rejected in every shot: its edges at one distance from the axis in two shots or more
    if alone:
        qs = np.array([q for q, _ in alone])
        lab = gap_clusters(qs, AXIS_TOLERANCE * pitch)
        fresh = int(edge_string.max()) + 1 if len(edge_string) else 0
        for c in np.unique(lab):
            members = [alone[m][1] for m in np.flatnonzero(lab == c)]
            if len({i for i, _ in members}) >= 2:
                out.update({ij: fresh for ij in members})
                fresh += 1
    return out


def _with_edges(
    lines: Sequence[Sequence[Floats]],
    edges: EdgeSet,
    edge_string: NDArray[np.intp],
    origin: Mapping[tuple[int, int], tuple[int, int]],
    back: Mapping[tuple[int, int], int],
    width: int,
    height: int,
) -> tuple[EdgeSet, NDArray[np.intp], dict[tuple[int, int], tuple[int, int]]]:
    """``edges`` with the edges ``back`` (``(shot, line)`` of ``lines``: its string, :func:`_readmitted`) added to
    their shots (the points weighed as the median kept point where the kept ones are weighed); every edge's
    string, and its ``(shot, line)`` in ``lines``."""
    per_shot: list[list[tuple[Floats, tuple[int, int], Floats | None]]] = [[] for _ in lines]
    for e, pts in enumerate(edges.lines()):
        i, jj = int(edges.image[e]), int(edges.line[e])
        w = None if edges.weights is None else edges.weights[edges.starts[e] : edges.starts[e] + edges.counts[e]]
        per_shot[i].append((pts, origin[(i, jj)], w))
    fill = None if edges.weights is None else float(np.median(edges.weights))
    for i, j in back:
        pts = np.asarray(lines[i][j], np.float64).reshape(-1, 2)
        per_shot[i].append((pts, (i, j), None if fill is None else np.full(len(pts), fill)))
    got, _ = collect([[p for p, _, _ in s] for s in per_shot], width, height)
    if not got:
        return edges, edge_string, dict(origin)
    new_origin = {(int(got.image[e]), int(got.line[e])): per_shot[int(got.image[e])][int(got.line[e])][1]
                  for e in range(got.n_edges)}  # fmt: skip
    label = {origin[(int(edges.image[e]), int(edges.line[e]))]: int(edge_string[e]) for e in range(edges.n_edges)}
    label.update(back)
    if edges.weights is not None:
        got = replace(
            got, weights=np.concatenate([per_shot[int(got.image[e])][int(got.line[e])][2] for e in range(got.n_edges)])
        )
    strings = np.array([label[new_origin[(int(got.image[e]), int(got.line[e]))]] for e in range(got.n_edges)], np.intp)
    return got, strings, new_origin


def _radial_gauge(lens: Any, model0: DistortionModel, xy: Floats, pts: _Placed) -> Floats:
    """The string-deviation directions a radial lens term can imitate, one unit row per radial term.

    Each radial coefficient ``k_j`` moves the corrected points along the harp normal by
    ``P_j = n . dU/dk_j``; on every string that motion, fitted by the string's own line and P2..P4
    in ``u``, has P2..P4 coefficients ``g_j``: a set of deviations ``a = -g_j dk_j`` and the lens
    change ``dk_j`` leave every edge as it was (exactly so when the turntable axis is the
    distortion centre, module docstring). Holding ``g_j . a = 0`` gives that part to the lens."""
    normal, string_of, basis, u, n_strings = pts.normal, pts.string_of, pts.basis, pts.u, len(pts.with_terms)
    if not hasattr(lens, "degree") or n_strings == 0:
        return np.zeros((0, n_strings * basis.shape[0]))
    th = lens.theta0(model0)
    tan = np.column_stack([normal[:, 1], -normal[:, 0]])
    p_mat, _ = lens.project(xy, th, normal, tan)
    m = basis.shape[0]
    rows = []
    for j in range(2, 2 + int(lens.degree)):  # the radial coefficients k_1..k_N of theta
        g = np.zeros(n_strings * m)
        for s in range(n_strings):
            idx = np.flatnonzero(string_of == s)
            design = np.vstack([np.ones(len(idx)), u[idx], basis[:, idx]]).T
            c, *_ = np.linalg.lstsq(design, p_mat[j, idx], rcond=None)
            g[s * m : (s + 1) * m] = c[2:]
        norm = float(np.linalg.norm(g))
        if norm > 0:
            rows.append(g / norm)
    return np.array(rows).reshape(-1, n_strings * m)


def _solve_joint(
    param: _WithStrings,
    held: _WithStrings,
    edges: EdgeSet,
    th0: Floats,
    width: int,
    height: int,
    max_nfev: int,
    warnings: list[str],
) -> Floats:
    """The joint fit's solution from ``th0``. The straightness of corrected edges is measured in corrected
    pixels, and with the distortion centre free a fit can slide into shrinking the image
    (:data:`pipeline.fit.MIN_CORRECTION_SCALE`): the strings' terms and a weakly penalised field let it, where
    the plain fit stayed a lens. Then ``held`` (the centre under the centre prior) from ``th0`` is the fit, with
    a warning (released from there, the centre slid back into the collapse in every case seen, so it is not
    released)."""
    sol = solve(param, edges, th0, max_nfev=max_nfev)
    if not collapses(param, sol.x, width, height):
        return sol.x
    warnings.append(
        "the free distortion centre collapsed the joint fit's correction (it shrank the image); the fit with "
        "the centre held near the image centre (the centre prior) is kept"
    )
    return solve(held, edges, th0, max_nfev=max_nfev).x


def fit_harp_shape(
    lines_per_image: Sequence[Sequence[Floats]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    spec: FitSpec,
    *,
    degrees: Sequence[int] = DEVIATION_TERMS,
    ridge: float = STRING_RIDGE,
    plain: FitResult | None = None,
    max_nfev: int = 200,
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
    kinks: bool = False,
    kink_t: int = DEFAULT_T,
    kink_z: float = KINK_Z,
    readmit: bool = True,
) -> HarpShapeFit | FitFailure:
    """Fit the lens ``spec`` and every string's deviation together (module docstring).

    Parameters
    ----------
    lines_per_image : per shot, its edges (distorted pixels), as for :func:`pipeline.fit.fit_distortion`.
    turntable_deg : the turntable angle of each shot, degrees.
    width, height : the image size.
    spec : the lens model.
    degrees : Legendre degrees of each deviation (>= 2).
    ridge : weight of the ridge on the deviation coefficients (:data:`STRING_RIDGE`).
    plain : the fit of ``spec`` without string terms, when already made (its outliers are left out).
    axis_groups : a label per shot when the harp was moved (with its turntable) between groups of shots:
        each group's axis is found on its own (:func:`pipeline.harp_frame.group_frames`), a string is the same in every group.
        With two groups or more no radial gauge is held (:func:`_radial_gauge`): a radial correction
        cannot imitate string deviations about two axes at once, so the shots themselves separate it.
        None (the default): one axis for all shots, searched near the image centre.
    axis_shifts : with ``axis_groups``, each group's rough image shift of the axis, px (:func:`pipeline.harp_frame.group_frames`);
        None: each group's axis searched on its own shots.
    kinks : after the fit, find each string's kinks in its residuals pooled over the shots and fit again
        with a term for each (:mod:`pipeline.harp_kinks`; off by default).
    kink_t : the along-edge subsampling factor the points were measured with (sets the kinks' template:
        the points must have been smoothed as ``harp measure`` does).
    kink_z : least significance of a kink that is modelled (:data:`pipeline.harp_kinks.KINK_Z`).
    readmit : the harp check also measures the edges the plain fit rejected as outliers that lie on a string
        (:func:`_readmitted`). A bent string's edges are what a lens alone cannot straighten, and the plain
        fit's outlier rule rejects them in the shots where the bend shows most, or in all of them: the check
        would not see the string. The lens is fitted on the plain fit's edges either way; the edges given back
        that the strings' fit does not explain either are left out (``HarpShapeFit.rejected``). False: the
        check measures the plain fit's edges only.

    Returns
    -------
    HarpShapeFit or FitFailure
        A failure (falsy, with its reason) when the plain fit fails, the angles do not match the
        shots, or the joint fit does not converge to finite values.
    """
    degrees = tuple(int(j) for j in degrees)
    if not degrees or min(degrees) < 2:
        return FitFailure(f"deviation degrees must be >= 2 (0 and 1 are the line itself), got {degrees}")
    if len(turntable_deg) != len(lines_per_image):
        return FitFailure(f"{len(lines_per_image)} shots but {len(turntable_deg)} turntable angles")
    if axis_groups is not None and len(axis_groups) != len(lines_per_image):
        return FitFailure(f"{len(lines_per_image)} shots but {len(axis_groups)} axis groups")
    if plain is None:
        fitted = fit_distortion(lines_per_image, width, height, **spec.fit_arguments())
        if not fitted:
            return fitted
        plain = fitted
    out = {(r.image, r.line) for r in plain.rejected}
    kept = [
        [np.asarray(p, np.float64) for j, p in enumerate(s) if (i, j) not in out] for i, s in enumerate(lines_per_image)
    ]
    edges, _ = collect(kept, width, height)
    if not edges:
        return edges
    w_plain = plain.point_weights  # the plain fit's robust point weights (its kept points, in order)
    if w_plain is not None and len(w_plain) == len(edges.xy):
        edges = replace(edges, weights=w_plain)
    model0 = plain.model
    by_shot: list[list[Floats]] = [[] for _ in kept]
    for e, pts in enumerate(edges.lines()):
        by_shot[int(edges.image[e])].append(model0.undistort_points(pts))
    present = [i for i, s in enumerate(by_shot) if s]
    groups: dict[Hashable, HarpFrame] = {}
    if axis_groups is None:
        framed = harp_frame([by_shot[i] for i in present], [turntable_deg[i] for i in present], width, height)
        if not framed:
            return framed
        frame, labels = framed
        shot_frame = [frame] * len(lines_per_image)
    else:
        grouped = group_frames(
            [by_shot[i] for i in present],
            [turntable_deg[i] for i in present],
            [axis_groups[i] for i in present],
            width,
            height,
            axis_shifts,
        )
        if not grouped:
            return grouped
        groups, labels = grouped
        frame = next(iter(groups.values()))
        shot_frame = [groups.get(g, frame) for g in axis_groups]  # a shot with no edges: no points to place
    edge_string = np.empty(edges.n_edges, dtype=np.intp)
    cursor = {i: 0 for i in present}
    for e in range(edges.n_edges):
        i = int(edges.image[e])
        edge_string[e] = labels[present.index(i)][cursor[i]]
        cursor[i] += 1
    hp = _placed(edges, edge_string, shot_frame, turntable_deg, model0, frame.scale_px, degrees)
    one_axis = len(groups) < 2
    axes_d: list[tuple[float, float]] = []  # the axes in distorted pixels, where a field lives
    if spec.field is not None:
        centres = np.asarray([f.centre for f in (list(groups.values()) or [frame])], np.float64)
        axes_d = [(float(x), float(y)) for x, y in model0.distort_points(centres) if np.isfinite(x) and np.isfinite(y)]

    def lens_part(w_center: float | None = None) -> Any:
        # a field's part that turns with the harp about an axis is a set of string bends: held off the field
        part = make_parametrisation(width, height, spec, w_center=w_center)
        if isinstance(part, RadialFieldParametrisation) and axes_d:
            part = part.with_axis_gauge(*axes_d)
        return part

    lens = lens_part()
    gauge = _radial_gauge(lens, model0, edges.xy, hp) if one_axis else None

    def joint_param(columns: Floats | None = None, held: bool = False) -> _WithStrings:
        # held: the distortion centre under the centre prior (the continuation of _solve_joint)
        part = lens_part(max(spec.w_center, CENTER_PRIOR_WEIGHT)) if held else lens
        return _WithStrings(part, hp.string_of, hp.basis, hp.normal, len(hp.with_terms), ridge, gauge, columns)

    param = joint_param()
    th0 = param.theta0(model0)
    warnings: list[str] = []
    with np.errstate(all="ignore"):
        try:
            th = _solve_joint(param, joint_param(held=True), edges, th0, width, height, max_nfev, warnings)
        except (ValueError, np.linalg.LinAlgError) as exc:
            return FitFailure(f"the joint fit of lens and strings failed: {exc}")
    if not np.all(np.isfinite(th)):
        return FitFailure("the joint fit of lens and strings diverged (non-finite parameters)")
    placed: list[tuple[int, Candidate]] = []  # (string, detection) of each kink modelled
    if kinks:
        columns, placed, peaks = _kink_columns(
            param, edges, th, hp.u * frame.scale_px, hp.normal, hp.point_string, hp.point_edge,
            hp.point_shot, hp.stretch, kink_t, kink_z,
        )  # fmt: skip
        if placed:
            param = joint_param(columns)
            start = np.concatenate([th, peaks])
            with np.errstate(all="ignore"):
                try:
                    held = joint_param(columns, held=True)
                    th = _solve_joint(param, held, edges, start, width, height, max_nfev, warnings)
                except (ValueError, np.linalg.LinAlgError) as exc:
                    return FitFailure(f"the joint fit of lens, strings and kinks failed: {exc}")
            if not np.all(np.isfinite(th)):
                return FitFailure("the joint fit of lens, strings and kinks diverged (non-finite parameters)")
    joint = param.model(th)
    problem = correction_problem(joint, width, height)
    if problem:
        return FitFailure(f"the joint fit of lens and strings: {problem}")
    corrected, _ = param.evaluate(edges.xy, th, jac=False)
    r_joint = tls(corrected, edges.starts, edges.counts)[0]
    r_lens = tls(joint.undistort_points(edges.xy), edges.starts, edges.counts)[0]

    # the harp check: every string's shape fitted again with the lens held, on the edges given back too
    rep, kink_of = hp, {k: k for k, _ in placed}
    rejected: tuple[RejectedEdge, ...] = ()
    check: _Held | None = None
    if readmit:
        source = [(i, j) for i, s in enumerate(lines_per_image) for j in range(len(s)) if (i, j) not in out]
        origin = {(i, jj): ij for i in range(len(kept)) for jj, ij in enumerate(x for x in source if x[0] == i)}
        outliers = [(r.image, r.line) for r in plain.rejected if r.reason.startswith("outlier")]
        back = _readmitted(lines_per_image, outliers, hp, shot_frame, turntable_deg, model0, frame.pitch_px)
        if back:
            wider = _with_edges(lines_per_image, edges, edge_string, origin, back, width, height)
            rep, kink_of, rejected, check = _report_points(
                wider, shot_frame, turntable_deg, model0, frame.scale_px, degrees, joint, placed, kink_t, max_nfev
            )
    if check is None:
        check = _held_strings(rep, joint, placed, kink_of, frame.scale_px, kink_t, max_nfev)
    bends = check.x
    if not np.all(np.isfinite(bends)):
        return FitFailure("the strings' shapes with the lens held diverged (non-finite parameters)")
    th = np.concatenate([th[: lens.n], bends])
    # standard errors of the coefficients: (J^T W J)^-1 sigma^2 at the solution (lens and strings free; W the
    # shots' weights of the check, sigma^2 the variance of a residual of weight 1)
    rep_gauge = _radial_gauge(lens, model0, rep.edges.xy, rep) if one_axis else None
    free = _WithStrings(
        lens, rep.string_of, rep.basis, rep.normal, len(rep.with_terms), REPORT_RIDGE, rep_gauge, check.problem.kinks
    )
    ata, _, ss = normal_equations(free, rep.edges, th, edge_weights=check.edge_weights)
    _, jg = free.regularisation(th, len(rep.edges.xy))
    dof = max(len(rep.edges.xy) - free.n, 1)
    cov = np.linalg.pinv(ata[0] + jg.T @ jg) * float(ss[0]) / dof
    n_dev = len(rep.with_terms) * len(degrees)
    coefs = th[lens.n : lens.n + n_dev].reshape(len(rep.with_terms), len(degrees))
    slot = {k: s for s, k in enumerate(rep.with_terms)}
    found = []
    for j, (k, cand) in enumerate(placed):
        c = lens.n + n_dev + j
        peak, peak_se = float(th[c]), float(np.sqrt(max(cov[c, c], 0.0)))
        area = peak / peak_per_area(kink_t, cand.length_px)
        found.append(
            Kink(
                kink_of[k], cand.at_px / frame.scale_px, cand.at_px, peak, peak_se, area, cand.z, cand.shots,
                cand.length_px,
            )
        )  # fmt: skip
    strings = []
    for k in sorted(rep.shots_of):
        sel = np.flatnonzero(rep.edge_string == k)
        on = np.isin(rep.point_edge, sel)
        span = (float(rep.u[on].min()), float(rep.u[on].max()))
        twice = seen_twice(rep.u[on], rep.point_shot[on])
        offset = float(np.median(rep.q[on]))
        if k in slot:
            s = slot[k]
            a = coefs[s]
            block = slice(lens.n + s * len(degrees), lens.n + (s + 1) * len(degrees))
            c_k = cov[block, block]
            grid = np.linspace(span[0], span[1], 201)
            pb = legendre(grid, degrees)
            dev = a @ pb
            at = int(np.argmax(np.abs(dev)))
            bend = float(abs(dev[at]))
            bend_se = float(np.sqrt(max(pb[:, at] @ c_k @ pb[:, at], 0.0)))
            se = tuple(float(v) for v in np.sqrt(np.maximum(np.diag(c_k), 0.0)))
            a_t = tuple(float(v) for v in a)
        else:
            bend, bend_se, se, a_t = float("nan"), float("nan"), (), ()
        strings.append(
            StringShape(
                int(k), offset, degrees if a_t else (), a_t, se, span, len(rep.shots_of[k]), len(sel), int(on.sum()),
                bend, bend_se, twice,
            )
        )  # fmt: skip
    return HarpShapeFit(
        model=joint,
        plain=plain,
        frame=frame,
        strings=tuple(strings),
        d_after=float(np.sqrt(np.mean(r_joint**2))),
        d_lens_only=float(np.sqrt(np.mean(r_lens**2))),
        n_params=param.n,
        axis_groups=tuple(groups.items()),
        kinks=tuple(found),
        warnings=tuple(dict.fromkeys(warnings)),
        rejected=rejected,
        noisy_shots=tuple(sorted(check.noisy.items())),
    )


def _kink_columns(
    param: _WithStrings,
    edges: Any,
    th: Floats,
    a_px: Floats,
    normal: Floats,
    point_string: NDArray[np.intp],
    point_edge: NDArray[np.intp],
    point_shot: NDArray[np.intp],
    stretch: Floats,
    t: int,
    z_min: float,
) -> tuple[Floats, list[tuple[int, Candidate]], Floats]:
    """The kinks of every string in the residuals of the fit ``th`` (:func:`pipeline.harp_kinks.scan_string`):
    their templates over all points ``(kinks, N)``, ``(string, detection)`` of each and their matched-filter
    peaks (the refit's start)."""
    corrected, _ = param.evaluate(edges.xy, th, jac=False)
    r, _, nrm, _, _ = tls(corrected, edges.starts, edges.counts, edges.weights)
    r_harp = r * np.einsum("ij,ij->i", nrm, normal)  # along the harp normal (+q)
    w = end_weights(edges.xy, edges.starts, edges.counts, t)
    if edges.weights is not None:
        w = w * edges.weights
    columns, placed, peaks = [], [], []
    for k in np.unique(point_string):
        idx = np.flatnonzero(point_string == k)
        for c in scan_string(
            a_px[idx], r_harp[idx], w[idx], point_edge[idx], point_shot[idx], stretch[idx], t=t, z_min=z_min
        ):
            g = np.zeros(len(edges.xy))
            g[idx] = template(a_px[idx] - c.at_px, stretch[idx], t, c.length_px)
            columns.append(g)
            placed.append((int(k), c))
            peaks.append(c.peak_px)
    return np.array(columns).reshape(len(columns), len(edges.xy)), placed, np.array(peaks)


def lens_result(
    fit: HarpShapeFit, lines_per_image: Sequence[Sequence[Floats]], width: int, height: int
) -> FitResult | FitFailure:
    """The jointly fitted lens ``fit.model`` as a :class:`~pipeline.edgeset.FitResult` on the shots' edges
    (the points corrected by the lens *alone*, the strings' deviations left in them), with the plain fit's
    rejected edges left out: what :func:`pipeline.fit.fit_distortion` reports of a lens it fitted, so that a
    profile holds the lens with the strings separated exactly as it holds a plain fit. A failure when the lens
    folds over the image."""
    edges, _ = collect([[np.asarray(p, np.float64) for p in s] for s in lines_per_image], width, height)
    if not edges:
        return edges
    problem = correction_problem(fit.model, width, height)
    if problem:
        return FitFailure(problem)
    out = {(r.image, r.line) for r in fit.plain.rejected}
    keep = np.array([(int(i), int(j)) not in out for i, j in zip(edges.image, edges.line, strict=True)])
    return summarise(
        fit.model,
        edges,
        edges.subset(keep),
        fit.plain.rejected,
        message="the lens fitted with every string's own deviation (pipeline.harp_shape)",
        n_params=fit.n_params,
        warnings=(*fit.plain.warnings, *fit.warnings),
    )


SeparatedJob = (
    tuple[Sequence[Sequence[Floats]], Sequence[float], int, int, FitSpec]
    | tuple[
        Sequence[Sequence[Floats]], Sequence[float], int, int, FitSpec, Sequence[Hashable] | None,
        Mapping[Hashable, Sequence[float]] | None,
    ]
)  # fmt: skip
"""``(lines_per_image, turntable_deg, width, height, spec)``, or with ``(axis_groups, axis_shifts)`` after them
(the harp moved between groups of shots: :func:`fit_harp_shape`)."""


def try_fit_harp_shape(
    lines_per_image: Sequence[Sequence[Floats]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    spec: FitSpec,
    plain: FitResult | None = None,
    kinks: bool = False,
    kink_t: int = DEFAULT_T,
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
) -> HarpShapeFit | FitFailure:
    """:func:`fit_harp_shape` of a fold, whose odd data (too few strings seen twice, a singular system) may
    raise: the error becomes a :class:`~pipeline.edgeset.FitFailure` naming it."""
    try:
        return fit_harp_shape(
            lines_per_image, list(turntable_deg), width, height, spec, plain=plain, kinks=kinks, kink_t=kink_t,
            axis_groups=axis_groups, axis_shifts=axis_shifts,
        )  # fmt: skip
    except (ValueError, IndexError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return FitFailure(f"the joint fit failed: {type(exc).__name__}: {exc}")


def _job_fit(job: SeparatedJob, **kw: Any) -> HarpShapeFit | FitFailure:
    lines, angles, width, height, spec = job[:5]
    groups: Any = job[5] if len(job) > 5 else None
    shifts: Any = job[6] if len(job) > 6 else None
    return try_fit_harp_shape(lines, angles, width, height, spec, axis_groups=groups, axis_shifts=shifts, **kw)


def separated_job(job: SeparatedJob) -> tuple[DistortionModel | None, str | None]:
    """One fit of the lens with the strings separated (a :data:`SeparatedJob`)
    -> ``(model, None)`` or ``(None, reason)``; module-level so that a process pool can run it (the
    leave-one-orientation-out folds of a session)."""
    fit = _job_fit(job)
    return (fit.model, None) if fit else (None, fit.reason)


def separated_kinks_job(job: SeparatedJob, t: int = DEFAULT_T) -> tuple[DistortionModel | None, str | None]:
    """:func:`separated_job` with each string's kinks found and modelled (``fit_harp_shape(kinks=True)``, the
    points measured with subsampling factor ``t``; ``functools.partial`` of it is what a process pool runs)."""
    fit = _job_fit(job, kinks=True, kink_t=t)
    return (fit.model, None) if fit else (None, fit.reason)
