r"""The harp's frame in the shots: the strings' angle and sense of turning, their pitch, the turntable axis.

The joint fit of the lens with each string's own deviation (:mod:`pipeline.harp_shape`) needs to know where
the harp is in every shot before it can tell a bend that turns with the harp from one that stays on the sensor.
This module finds that from the shots' edges, corrected by a plain lens fit (ideal pixels), and their turntable
angles, and numbers the strings across the shots.

The frame
---------
The harp is seen turned by the turntable angle :math:`\theta_i` in shot :math:`i`: its strings run at
:math:`\phi_i = \phi_0 + \sigma\theta_i` in the ideal image (:math:`\sigma = \pm 1`, the sense in which the
camera sees the turntable turn), with unit direction :math:`t_i` and normal :math:`n_i`, about a centre
:math:`c` (the turntable axis, in ideal pixels). A point :math:`p` of shot :math:`i` has harp coordinates
:math:`u = t_i\cdot(p - c)/s` along the strings (:math:`s` half the image diagonal) and
:math:`q = n_i\cdot(p - c)` across them; a string keeps its :math:`q` in every shot (:class:`HarpFrame`).
:math:`\phi_0` and :math:`\sigma` come from the shots' line directions (their circular mean modulo 180
degrees [2]_, :data:`MAX_ANGLE_SPREAD_DEG`); the distance between neighbouring strings (the pitch, what the
axis search is measured in) from the edges' offsets across the strings of a harp of uniform spacing [1]_
(:func:`shot_pitch`, :func:`harp_pitch`; :func:`string_pitch` needs no turntable angles).

The axis
--------
The strings are identified across shots by their distance from the axis :math:`c`, which is
found by making those distances agree between shots: about the true axis each string is one string,
seen with both its edges in every shot whose own strings lie on either side of it
(:func:`_consistency`). For a harp with uniform spacing :math:`p`, the distances agree modulo
:math:`p` about other points too: about a lattice of points for three turntable angles (about one
per square pitch for angles 60 degrees apart), about some points several pitches away for more (the
shots' strings then shift by whole pitches against each other). The axis is searched within
:data:`AXIS_REACH` pitches of the image centre; where places agree alike, the one with fewer strings
is the harp (its ends in view tell); where they have as many (three angles and a harp wider than
the image), the frame is refused with the reason (add angles spread over the half turn) rather than
guessed: :func:`harp_frame`, ``benchmarks/harp_frame_population.py``.

Shots about two turntable axes or more (the harp moved *with* its turntable between groups of shots) have a
frame per axis group, each placed on its group's shots, about a rough shift given per group or, with four
turntable angles or more per group, without one; a string keeps its distance from its group's axis in every
group (:func:`group_frames`).

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera distortion
   measurements with a calibration harp", JOSA A 29(10), 2012 (a harp of equally spaced straight strings).
.. [2] K. V. Mardia, P. E. Jupp, *Directional Statistics*, Wiley, 2000 (axial data: the mean direction of
   doubled angles; the mean resultant length).
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.edgeset import FitFailure
from pipeline.orientations import distinct_orientations

Floats = NDArray[np.float64]

MAX_ANGLE_SPREAD_DEG = 3.0
"""Largest spread of the shots' string angles about ``phi_0 + sigma * theta`` that is accepted."""

AXIS_SEARCH = 0.6
"""Half-width, in string pitches, of the search for the reference axis of :func:`group_frames` with shifts given
(about the image centre, all shots moved back by their group's shift)."""

AXIS_REACH = 2.5
r"""Radius, in string pitches, of the search for the turntable axis around the image centre (or the ``centre``
given) of :func:`harp_frame` (:func:`_place_axis`). Four angles evenly spread by :math:`\Delta` make the shots
agree about points :math:`p / (\cos(\Delta/2) - \cos(3\Delta/2))` off the axis (1.85 pitches for 45 degrees,
2.75 for 36, 3.9 for 30: a fold of five or seven angles leaving one out): beyond this radius for all but 45."""

AXIS_STEP = 1.0 / 6.0
"""Spacing, in string pitches, of the grid of trial axes of :func:`_place_axis`."""

AXIS_TOLERANCE = 0.125
"""How far, in string pitches, an edge's distance from the axis may stray from its string's in another shot
(:func:`_consistency`: the lens correction's and the axis grid's errors)."""

AXIS_TIE = 2.0
"""Scores of :func:`_consistency` within this of the best are alike (one string missed in one shot)."""

AXIS_DISAGREE = 0.6
"""Largest score of :func:`_consistency`, per edge, of a place of the axis that is taken: above it no place makes
the shots one harp (shots about two axes: about 1 per edge) and the frame is refused. A bootstrap replicate that
draws each shot's strings with replacement misses about a third of them in every shot (about 0.3 per edge)."""

AXIS_SEEDS = 32
"""Most local minima of the trial axes' grid that :func:`_place_axis` refines (the best first; three shots
make a lattice of equally good places, about one per square pitch)."""

GROUP_AXIS_SEARCH = 4.0
"""Radius, in string pitches, of the search for the turntable axis of each axis group of :func:`pipeline.harp_shape.fit_harp_shape`
given no shifts, around the image centre (:func:`_place_groups`); half-width of the comb search of
``station.axis_places.axes_of`` (``harp_frame(reach=)``, :func:`_coarse_axis`)."""

GROUP_AXIS_SEEDS = 64
"""Most local minima of the trial axes' grid refined per axis group by :func:`_place_groups` (every one that scores
alike, or the group is refused: three angles make a lattice of some 50 places within :data:`GROUP_AXIS_SEARCH`
pitches, more than :data:`AXIS_SEEDS`, and a place left out might be the axis)."""

MIN_GROUP_ANGLES = 4
"""Fewest distinct turntable angles (:func:`pipeline.orientations.distinct_orientations`) of an axis group whose
axis :func:`group_frames` searches without a shift. Three make the distances from every point of a lattice agree
(about a pitch apart, 60 degrees apart), and with a string or two left out of some shots (the plain fit's rejected
edges) a wrong place of the lattice can agree better than the axis (``benchmarks/axis_positions.py``, seed 39)."""

MAX_GROUP_COMBINATIONS = 4096
"""Most combinations of the axis groups' alike places that :func:`group_frames` without shifts scores together
(three shots per group leave some 30 places each within :data:`GROUP_AXIS_SEARCH` pitches: two groups 900)."""

SHIFT_SEARCH = 0.3
"""Half-width, in string pitches, of the search for an axis group's turntable axis about where its given shift
puts it (:func:`group_frames`): below half the distance to the nearest point about which three shots 60
degrees apart agree as well (about a pitch)."""

PAIR_RATIO = 2.5
"""Least ratio of the gaps between strings to a string's width for :func:`shot_pitch` to pair a string's two edges:
a string narrower than 1/3.5 of the pitch (the drawn and real harps: 2.5-4 px wide, 30-120 px apart). Strings that
show one edge each with some missing leave gaps of 1, 2, 3 pitches (ratios 2 and 1.5 between neighbours), below it;
a ratio of 3 or more among them would give a "string" more than two edges, and is not taken either."""

PITCH_FLOOR = 0.3
"""The first pitch of :func:`shot_pitch` is the smallest gap between the strings' centres of at least this times
their median gap: a median up to three pitches (two of every three strings missing) still finds one pitch."""


@dataclass(frozen=True)
class HarpFrame:
    """Where the harp is in every shot: strings at ``angle0_deg + sign * turntable`` (degrees, in the
    ideal image), turning about ``centre`` (ideal pixels); harp coordinates along the strings in units
    of ``scale_px`` (half the image diagonal); ``pitch_px`` the distance between neighbouring strings
    (:func:`harp_pitch`)."""

    angle0_deg: float
    sign: int
    centre: tuple[float, float]
    scale_px: float
    pitch_px: float

    def direction(self, turntable_deg: float) -> Floats:
        """Unit direction of the strings in a shot at ``turntable_deg``."""
        a = np.radians(self.angle0_deg + self.sign * turntable_deg)
        return np.array([np.cos(a), np.sin(a)])

    def normal(self, turntable_deg: float) -> Floats:
        """Unit normal ``(-sin, cos)`` of the strings: the direction in which ``q`` grows."""
        d = self.direction(turntable_deg)
        return np.array([-d[1], d[0]])

    def to_dict(self) -> dict[str, Any]:
        return {
            "angle0_deg": self.angle0_deg,
            "sign": self.sign,
            "centre": list(self.centre),
            "scale_px": self.scale_px,
            "pitch_px": self.pitch_px,
        }


def _circular_mean_180(angles_deg: Floats) -> tuple[float, float]:
    """Mean and spread (RMS of the wrapped differences) of line directions, degrees modulo 180."""
    two = np.radians(2.0 * np.asarray(angles_deg))
    mean = 0.5 * np.degrees(np.arctan2(np.mean(np.sin(two)), np.mean(np.cos(two)))) % 180.0
    diff = (np.asarray(angles_deg) - mean + 90.0) % 180.0 - 90.0
    return float(mean), float(np.sqrt(np.mean(diff**2)))


def _edge_angle(u: Floats) -> float:
    d = u - u.mean(axis=0)
    sxx, syy, sxy = float(d[:, 0] @ d[:, 0]), float(d[:, 1] @ d[:, 1]), float(d[:, 0] @ d[:, 1])
    return float(np.degrees(0.5 * np.arctan2(2.0 * sxy, sxx - syy)) % 180.0)


def gap_clusters(q: Floats, gap: float) -> NDArray[np.intp]:
    """Labels 0, 1, ... of 1-D single-linkage clusters (a gap wider than ``gap`` separates), in order."""
    order = np.argsort(q)
    labels = np.empty(len(q), dtype=np.intp)
    labels[order] = np.concatenate([[0], np.cumsum(np.diff(q[order]) > gap)])
    return labels


def shot_pitch(offsets: Floats) -> float:
    r"""The distance between neighbouring strings (px) of a harp of uniform pitch, from one shot's edge offsets
    across its strings (px, any order; a string's two edges as :mod:`pipeline.measure` lists them, or one; an
    edge listed twice, as a bootstrap replicate draws it, counts once).

    * **A string's two edges** are paired: the offsets' gaps are the strings' widths and, at least
      :data:`PAIR_RATIO` times wider, the gaps between strings. The widest jump between the sorted gaps splits
      them when it is that large and no string would get more than two edges (else every edge is its own
      string: a harp whose strings show one edge each, or whose only wide gaps are missing strings).
    * **Missing strings** (beyond the image's borders, or hidden inside it) leave gaps of whole pitches between
      the strings' centres :math:`c_j`. A first pitch :math:`p_0` is the smallest gap of at least
      :data:`PITCH_FLOOR` times the median gap (the strings' gaps are :math:`p` or a few :math:`p`); each gap
      counts :math:`\max(1, \mathrm{round}(\Delta c / p_0))` strings, which numbers the strings seen
      :math:`k_j`.
    * **The pitch** is the least-squares slope of :math:`c_j` against :math:`k_j` over the strings with both
      edges seen (all strings when fewer than two have): exact for a uniform harp whatever the strings' width
      (a median gap between edges is the pitch less a width) and whichever strings are missing.

    NaN when fewer than two strings or three edges are seen (two edges may be one string's).

    References
    ----------
    .. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera distortion
       measurements with a calibration harp", JOSA A 29(10), 2012 (a harp of equally spaced strings).
    """
    o = np.unique(np.asarray(offsets, np.float64)[np.isfinite(offsets)])  # an edge drawn twice (bootstrap) once
    if len(o) < 3:  # two edges: two strings or one string's two
        return float("nan")
    gaps = np.diff(o)
    lab = np.arange(len(o))
    g = np.sort(gaps[gaps > 0])
    if len(g) >= 2:
        jump = int(np.argmax(g[1:] / np.maximum(g[:-1], 1e-12)))
        if g[jump + 1] >= PAIR_RATIO * g[jump]:
            paired = np.concatenate([[0], np.cumsum(gaps > np.sqrt(g[jump] * g[jump + 1]))])
            if np.bincount(paired).max() <= 2:
                lab = paired
    count = np.bincount(lab)
    centre = np.bincount(lab, weights=o) / count
    if len(centre) < 2:
        return float("nan")
    dc = np.diff(centre)
    p0 = float(np.min(dc[dc >= PITCH_FLOOR * np.median(dc)]))
    k = np.concatenate([[0.0], np.cumsum(np.maximum(1.0, np.rint(dc / p0)))])
    both = count == 2
    use = both if np.sum(both) >= 2 else np.ones(len(centre), dtype=bool)
    kk, cc = k[use] - k[use].mean(), centre[use] - centre[use].mean()
    return float(kk @ cc / (kk @ kk))


def harp_pitch(offsets: Sequence[Floats]) -> float:
    """The harp's pitch (px) from several shots' edge offsets across their strings (one array per shot, each
    across its own strings' direction): the median of :func:`shot_pitch` over the shots that see two strings or
    more (robust to a shot whose strings were paired or numbered wrongly); NaN when none does."""
    per = [p for p in (shot_pitch(o) for o in offsets) if np.isfinite(p)]
    return float(np.median(per)) if per else float("nan")


def _phase_coherence(q: Floats, pitch: Floats | float) -> Floats:
    """How well distances ``q`` (last axis) fall on one comb of period ``pitch``: the squared mean
    resultants of ``q`` modulo ``pitch`` and ``pitch / 2`` summed (2 when every ``q`` is on the comb; the
    second harmonic keeps a string's two edges from cancelling when its width is near half the pitch)."""
    return sum(np.abs(np.mean(np.exp(2j * np.pi * h * q / pitch), axis=-1)) ** 2 for h in (1, 2))  # type: ignore[no-any-return]


def _coarse_axis(offsets: list[Floats], normals: list[Floats], pitch: float, c0: Floats, reach: float) -> Floats:
    """The turntable axis to ``pitch / 8`` within ``reach`` pitches of ``c0``, for a harp of (nearly) uniform
    pitch: the point about which every shot's string distances fall on one comb (:func:`_phase_coherence`);
    the pitch is :func:`harp_pitch`'s (a comb of the wrong period dephases over many strings). Six shots 30
    degrees apart make a comb again about a point some 8 pitches away: ``reach`` stays well below that."""
    oo = np.concatenate(offsets)
    nn = np.concatenate([np.repeat(n[None, :], len(o), axis=0) for n, o in zip(normals, offsets, strict=True)])
    steps = np.linspace(-reach, reach, 2 * int(np.ceil(reach / 0.125)) + 1) * pitch
    grid = c0 + np.array([(dx, dy) for dx in steps for dy in steps])
    out: Floats = grid[int(np.argmax(_phase_coherence(oo[None, :] - grid @ nn.T, pitch)))]
    return out


def _consistency(
    q: Floats, shot_of: NDArray[np.intp], n_shots: int, pitch: float, tol: float
) -> tuple[Floats, NDArray[np.intp]]:
    """How badly the edges' distances ``q`` from trial axes (one row per axis) fail to make one harp:
    ``(score, strings)`` per row.

    The edges are clustered into strings as :func:`harp_frame` numbers them (a gap over a third of a pitch
    separates). A string is *missed* by a shot when its distance lies within the range of that shot's own
    edges (``tol`` inside it) and the shot has no edge in it: a harp's strings are contiguous and the image
    convex, so between two strings a shot sees it sees every string, each with both its edges. The score is
    twice the misses (a string has two edges) plus, per edge, its squared distance from its string's mean in
    units of ``tol``, at most 1. About the true axis it is near 0; about a wrong one the shots' strings
    interleave (misses) or a string's edges spread, whatever the clustering makes of them: a string split
    into several, each seen in fewer shots, is missed (what the spread alone cannot see). ``strings``: the
    number of clusters."""
    q = np.atleast_2d(q)
    g, e = q.shape
    order = np.argsort(q, axis=1, kind="stable")
    qs = np.take_along_axis(q, order, axis=1)
    lab = np.zeros((g, e), dtype=np.intp)
    lab[:, 1:] = np.cumsum(np.diff(qs, axis=1) > pitch / 3.0, axis=1)
    strings = lab[:, -1] + 1
    gid = (lab + (np.arange(g) * e)[:, None]).ravel()
    count = np.bincount(gid, minlength=g * e)
    means = np.bincount(gid, weights=qs.ravel(), minlength=g * e) / np.maximum(count, 1)
    spread = np.minimum(((qs.ravel() - means[gid]) / tol) ** 2, 1.0).reshape(g, e).sum(axis=1)
    seen = np.zeros(g * e * n_shots, dtype=bool)
    seen[gid * n_shots + shot_of[order].ravel()] = True
    lo = np.full((g, n_shots), np.inf)
    hi = np.full((g, n_shots), -np.inf)
    for i in range(n_shots):
        mine = shot_of == i
        if mine.any():
            lo[:, i], hi[:, i] = q[:, mine].min(axis=1), q[:, mine].max(axis=1)
    top = int(strings.max())  # cluster slots in use (of e per row)
    m = means.reshape(g, e)[:, :top, None]
    inside = (m > lo[:, None, :] + tol) & (m < hi[:, None, :] - tol) & (count.reshape(g, e)[:, :top, None] > 0)
    misses = np.sum(inside & ~seen.reshape(g, e, n_shots)[:, :top], axis=(1, 2))
    return spread + 2.0 * misses, strings


def _place_axis(
    oo: Floats,
    nn: Floats,
    shot_of: NDArray[np.intp],
    n_shots: int,
    pitch: float,
    c0: Floats,
    refined: Any,
    reach: float = AXIS_REACH,
) -> Floats | FitFailure:
    """The turntable axis within ``reach`` pitches of ``c0`` (a disc, :data:`AXIS_REACH` by default) about which
    the edges (offsets ``oo`` along their shots' normals ``nn``) make one harp (:func:`_consistency`), refined by ``refined``.

    Every point of a grid :data:`AXIS_STEP` pitches apart is scored on each shot's strings (the mean of the edges
    of each, with a tolerance of twice the grid's spacing); its best local minima (up to :data:`AXIS_SEEDS`, those
    scoring within what the grid's placement may cost a place) are refined and scored again (a tolerance of
    :data:`AXIS_TOLERANCE` pitches; one refined out of the disc is dropped: with strings missing at random, as in
    a bootstrap replicate, a refinement may wander off). Where two places a quarter pitch apart or more score
    alike (within :data:`AXIS_TIE`), the one with fewer strings is the harp (about a wrong axis the shots' strings shift by
    whole pitches against each other: more strings, each seen in fewer shots); where they have as many, the
    turntable angles cannot place the axis (three angles never can, for a harp wider than the image:
    :func:`group_frames`) and the frame is refused rather than guessed. It is refused too where even the best
    place scores over :data:`AXIS_DISAGREE` per edge (no one axis makes the shots one harp). An axis beyond
    ``reach`` whose shots agree as well about a place within it is not seen (four angles 45 degrees
    apart: a place 1.85 pitches off).
    """
    alike = _axis_places(oo, nn, shot_of, n_shots, pitch, c0, refined, reach)
    if isinstance(alike, FitFailure):
        return alike
    refused = _ambiguous(alike, pitch)
    return alike[0][2] if refused is None else refused


def _axis_places(
    oo: Floats,
    nn: Floats,
    shot_of: NDArray[np.intp],
    n_shots: int,
    pitch: float,
    c0: Floats,
    refined: Any,
    reach: float = AXIS_REACH,
    seeds: int = AXIS_SEEDS,
    complete: bool = False,
) -> list[tuple[float, int, Floats]] | FitFailure:
    """The places ``(score, strings, centre)`` of :func:`_place_axis` that make the shots one harp alike
    (:func:`_alike`), or why none does; ``seeds`` local minima refined at most (:data:`AXIS_SEEDS`): with
    ``complete``, more minima scoring alike than that is refused (a place left out might be the axis)."""
    n = int(np.ceil(reach / AXIS_STEP))
    steps = np.arange(-n, n + 1) * AXIS_STEP * pitch
    gx, gy = np.meshgrid(steps, steps, indexing="ij")
    grid = c0 + np.column_stack([gx.ravel(), gy.ravel()])
    # the grid is scored on each shot's strings (its edges a third of a pitch apart or less, paired), half as many
    oc, nc, sc = [], [], []
    for i in range(n_shots):
        o = oo[shot_of == i]
        if len(o):
            lab = gap_clusters(o, pitch / 3.0)
            oc.append(np.bincount(lab, weights=o) / np.bincount(lab))
            nc.append(np.repeat(nn[shot_of == i][:1], len(oc[-1]), axis=0))
            sc.append(np.full(len(oc[-1]), i))
    o_s, n_s, s_s = np.concatenate(oc), np.concatenate(nc), np.concatenate(sc)
    disc = np.hypot(gx, gy).ravel() <= reach * pitch + 1e-9
    coarse = np.full(len(grid), np.inf)
    coarse[disc] = _consistency(o_s[None, :] - grid[disc] @ n_s.T, s_s, n_shots, pitch, 2 * AXIS_STEP * pitch)[0]
    sq = coarse.reshape(2 * n + 1, 2 * n + 1)
    padded = np.pad(sq, 1, constant_values=np.inf)
    neighbours = np.min(
        [padded[1 + dx : 2 * n + 2 + dx, 1 + dy : 2 * n + 2 + dy] for dx in (-1, 0, 1) for dy in (-1, 0, 1)
         if dx or dy], axis=0,
    )  # fmt: skip
    minima = np.flatnonzero((sq <= neighbours).ravel() & disc)
    minima = minima[np.argsort(coarse[minima], kind="stable")]
    # the coarse score of a place varies with where the grid falls about it (up to ~0.15 per edge)
    minima = minima[coarse[minima] <= coarse[minima[0]] + AXIS_TIE + 0.2 * len(o_s)]
    if complete and len(minima) > seeds:
        return FitFailure(
            f"the harp's axis is ambiguous with these turntable angles: more than {seeds} places within {reach:g} "
            "pitches make the shots' strings agree; add angles spread over the half turn"
        )
    minima = minima[:seeds]
    places: list[tuple[float, int, Floats]] = []
    for c in (refined(grid[j]) for j in minima):
        if np.hypot(*(c - c0)) > (reach + AXIS_STEP) * pitch:
            continue  # refined out of the disc searched: a place it does not vouch for
        if all(np.hypot(*(c - p)) > 0.25 * pitch for _, _, p in places):
            v, k = _consistency(oo - nn @ c, shot_of, n_shots, pitch, AXIS_TOLERANCE * pitch)
            places.append((float(v[0]), int(k[0]), c))
    best = min((v for v, _, _ in places), default=np.inf)
    if best > AXIS_DISAGREE * len(oo):
        return FitFailure(
            f"the shots' strings do not agree about any one turntable axis within {reach:g} string pitches of "
            f"the image centre (at best {best:.0f} of {len(oo)} edges off their string or missed): the harp moved "
            "between shots (give each shot's axis group), or its axis is farther off"
        )
    return _alike(places)


def _alike(places: Sequence[tuple[float, int, Floats]]) -> list[tuple[float, int, Floats]]:
    """The places ``(score, strings, centre)`` scoring within :data:`AXIS_TIE` of the best, fewest strings first
    (then the lowest score): the first is the harp's axis unless the second has as many strings."""
    best = min(v for v, _, _ in places)
    return sorted((p for p in places if p[0] <= best + AXIS_TIE), key=lambda p: (p[1], p[0]))


def _ambiguous(alike: Sequence[tuple[float, int, Floats]], pitch: float, where: str = "") -> FitFailure | None:
    """The refusal when the first two places of ``alike`` (:func:`_alike`) have as many strings, else None."""
    if len(alike) < 2 or alike[0][1] != alike[1][1]:
        return None
    far = max(float(np.hypot(*(c - alike[0][2]))) for _, _, c in alike[1:]) / pitch
    return FitFailure(
        f"the harp's axis is ambiguous with these turntable angles{where}: {len(alike)} places up to {far:.1f} "
        "pitches apart make the shots' strings agree; add angles spread over the half turn"
    )


def harp_frame(
    corrected: Sequence[Sequence[Floats]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    *,
    centre: Sequence[float] | Floats | None = None,
    reach: float | None = None,
    refine: bool = True,
    within: float = AXIS_REACH,
) -> tuple[HarpFrame, list[list[int]]] | FitFailure:
    """The harp's frame in the shots (:class:`HarpFrame`) and each edge's string number.

    ``corrected``: per shot, its edges corrected by a lens fit (ideal pixels). The strings' angle at
    turntable 0 and the sense of rotation come from the shots' line directions; the axis from making
    the strings' distances from it agree between shots (module docstring); the strings are the
    clusters of those distances, numbered from the lowest ``q``. The axis is searched within ``within``
    pitches (:data:`AXIS_REACH`) of ``centre`` (default the image centre) by how well its distances make
    one harp (:func:`_place_axis`, :func:`_consistency`: each string one cluster, seen in every shot
    whose strings lie on either side of it; the spread of the distances within their clusters alone
    misleads where a wrong axis splits each string into clusters of fewer shots); with ``reach``
    (pitches) instead within ``reach`` of ``centre`` by how well the distances fall on one comb
    (:func:`_coarse_axis`, :func:`group_frames`). Either is then refined with its clusters held (unless
    not ``refine``: where the shots do not share one axis exactly, the refinement may wander off).

    Returns
    -------
    (HarpFrame, list of list of int) or FitFailure
        The frame and each shot's edges' string numbers; a failure when the angles do not follow the
        turntable, the strings are too few, or (without ``reach``) two places of the axis a quarter pitch
        apart or more make the shots agree alike with as many strings ("the harp's axis is ambiguous with
        these turntable angles": add angles spread over the half turn).
    """
    if len(corrected) != len(turntable_deg):
        return FitFailure(f"{len(corrected)} shots but {len(turntable_deg)} turntable angles")
    across = _across(corrected, turntable_deg, width, height)
    if isinstance(across, FitFailure):
        return across
    c0 = np.array([(width - 1) / 2.0, (height - 1) / 2.0]) if centre is None else np.asarray(centre, np.float64)

    def refined(c: Floats) -> Floats:
        return across.refined(c, 3 if refine else 0)

    if reach is not None:
        return across.framed(refined(_coarse_axis(across.offsets, across.normals, across.pitch, c0, reach)))
    placed = _place_axis(across.oo, across.nn, across.shot_of, len(corrected), across.pitch, c0, refined, within)
    return placed if isinstance(placed, FitFailure) else across.framed(placed)


@dataclass(frozen=True)
class _Across:
    """The shots' edges across their strings, from which :func:`harp_frame` places the axis: the strings' angle at
    turntable 0 and the sense of turning, the pitch (:func:`harp_pitch`), per shot its harp normal and its edges'
    offsets along it, and the same per edge (``oo``, ``nn``, ``shot_of``)."""

    angle0: float
    sign: int
    scale: float
    pitch: float
    normals: list[Floats]
    offsets: list[Floats]
    oo: Floats
    nn: Floats
    shot_of: NDArray[np.intp]

    def labels(self, c: Floats) -> NDArray[np.intp]:
        """Each edge's string about the axis ``c``: the clusters of the distances, a third of a pitch apart."""
        return gap_clusters(self.oo - self.nn @ c, self.pitch / 3.0)

    def refined(self, c: Floats, rounds: int = 3) -> Floats:
        """The axis ``c`` refined with the clusters about it held: ``q_e + n_e . c = o_e`` is linear in ``(c, q_k)``."""
        for _ in range(rounds):
            lab = self.labels(c)
            a = np.zeros((len(self.oo), 2 + int(lab.max()) + 1))
            a[:, :2] = self.nn
            a[np.arange(len(self.oo)), 2 + lab] = 1.0
            sol, *_ = np.linalg.lstsq(a, self.oo, rcond=None)
            c = np.asarray(sol[:2], dtype=np.float64)
        return c

    def framed(self, c: Floats) -> tuple[HarpFrame, list[list[int]]]:
        """The frame about the axis ``c`` and each shot's edges' string numbers."""
        lab = self.labels(c)
        per_shot = [[int(v) for v in lab[self.shot_of == i]] for i in range(len(self.offsets))]
        return HarpFrame(self.angle0, self.sign, (float(c[0]), float(c[1])), self.scale, self.pitch), per_shot


def _across(
    corrected: Sequence[Sequence[Floats]], turntable_deg: Sequence[float], width: int, height: int
) -> _Across | FitFailure:
    """:class:`_Across` of the shots (:func:`harp_frame`'s first steps), or why the shots have none."""
    angles = np.array([_circular_mean_180(np.array([_edge_angle(e) for e in shot]))[0] for shot in corrected])
    theta = np.asarray(turntable_deg, dtype=np.float64)
    best: tuple[float, int, float] | None = None
    for sign in (1, -1):
        mean, spread = _circular_mean_180(angles - sign * theta)
        if best is None or spread < best[0]:
            best = (spread, sign, mean)
    assert best is not None
    spread, sign, angle0 = best
    if spread > MAX_ANGLE_SPREAD_DEG:
        return FitFailure(
            f"the shots' string angles do not follow the turntable angles (spread {spread:.1f} deg about "
            f"angle0 {sign:+d} x turntable): wrong angles, or the harp moved on the turntable"
        )
    scale = 0.5 * float(np.hypot(width, height))
    # per edge: its offset along its shot's harp normal, and that normal
    normals = [HarpFrame(angle0, sign, (0.0, 0.0), scale, 1.0).normal(t) for t in theta]
    offsets = [np.array([float(nrm @ e.mean(axis=0)) for e in shot]) for nrm, shot in zip(normals, corrected)]
    pitch = harp_pitch(offsets)
    if not np.isfinite(pitch):
        return FitFailure("too few strings to find the harp's pitch")
    nn = np.concatenate([np.repeat(nrm[None, :], len(o), axis=0) for nrm, o in zip(normals, offsets)])
    shot_of = np.concatenate([np.full(len(o), i) for i, o in enumerate(offsets)])
    return _Across(float(angle0), int(sign), scale, pitch, normals, offsets, np.concatenate(offsets), nn, shot_of)


def string_pitch(corrected: Sequence[Sequence[Floats]]) -> float:
    """The distance between neighbouring strings (px) in shots of a harp of uniform pitch, its edges ``corrected``
    by a lens fit (ideal pixels) or as measured: per shot the edges' offsets across the strings' mean direction,
    and :func:`harp_pitch` of those (what :func:`harp_frame` takes, across the turntable's directions). It needs no
    turntable axis or angles: what turns a linear stage's travel (mm) into an image shift of the axis (px) for
    :func:`group_frames`, with the harp's pitch in mm. NaN when no shot sees two strings."""
    offsets = []
    for shot in corrected:
        if len(shot):
            a = np.radians(_circular_mean_180(np.array([_edge_angle(np.asarray(e, np.float64)) for e in shot]))[0])
            nrm = np.array([-np.sin(a), np.cos(a)])
            offsets.append(np.array([float(nrm @ np.asarray(e, np.float64).mean(axis=0)) for e in shot]))
    return harp_pitch(offsets)


def group_frames(
    corrected: Sequence[Sequence[Floats]],
    turntable_deg: Sequence[float],
    axis_groups: Sequence[Hashable],
    width: int,
    height: int,
    shifts: Mapping[Hashable, Sequence[float]] | None = None,
) -> tuple[dict[Hashable, HarpFrame], list[list[int]]] | FitFailure:
    """The harp's frame in each axis group of shots (the harp moved with its turntable between groups, by a
    linear stage or by hand) and each edge's string number, one number per string in every group.

    Each group's frame is placed on its own shots as :func:`harp_frame` places one. Where its axis is searched:

    * ``shifts`` given (per group, the image shift of the axis from a reference place within
      :data:`AXIS_SEARCH` pitches of the image centre, known roughly: a stage's travel times the image
      scale): every shot moved back by its group's shift, all shots together place the reference axis
      (:func:`harp_frame` with ``reach``, not refined), and each group's own axis is searched within
      :data:`SHIFT_SEARCH` pitches of the reference plus its shift (the shifts' errors a sixth of a pitch
      or less, with as few as three shots in a group);
    * no ``shifts``: within :data:`GROUP_AXIS_SEARCH` pitches of the image centre, where each group's shots make
      one harp as :func:`harp_frame` places one axis (:func:`_axis_places`), and where a group's shots agree
      alike about several places, the places that make *all* the shots one harp together (:func:`_place_groups`);
      refused with the reason when that leaves several. For a harp of uniform pitch this needs four turntable
      angles or more per group, spread over the half turn: the distances from any point agree between three
      shots modulo the pitch on a lattice of points (about a pitch apart for angles 60 degrees apart, 2.7
      pitches for 30), so three shots cannot place their axis, alone or with another group of three.

    A string's distance ``q`` from the turntable axis is the same in every group, so the strings are the
    clusters of every group's distances together, numbered from the lowest ``q``.
    """
    if len(axis_groups) != len(corrected):
        return FitFailure(f"{len(corrected)} shots but {len(axis_groups)} axis groups")
    names = list(dict.fromkeys(axis_groups))
    guess: dict[Hashable, Floats | None] = dict.fromkeys(names)
    if shifts is not None:
        missing = [g for g in names if g not in shifts]
        if missing:
            return FitFailure(f"no axis shift for axis group {missing[0]!r}")
        s = {g: np.asarray(shifts[g], np.float64) for g in names}
        back = [[e - s[g] for e in shot] for shot, g in zip(corrected, axis_groups, strict=True)]
        framed = harp_frame(back, turntable_deg, width, height, reach=AXIS_SEARCH, refine=False)
        if not framed:
            return framed
        guess = {g: np.asarray(framed[0].centre) + s[g] for g in names}
    frames: dict[Hashable, HarpFrame] = {}
    q: list[Floats] = [np.zeros(0)] * len(corrected)
    members = {g: [i for i, h in enumerate(axis_groups) if h == g] for g in names}
    if shifts is None:
        placed = _place_groups(
            [[corrected[i] for i in members[g]] for g in names],
            [[turntable_deg[i] for i in members[g]] for g in names],
            names,
            width,
            height,
        )
        if isinstance(placed, FitFailure):
            return placed
        frames = dict(zip(names, placed, strict=True))
    for g in names:
        idx = members[g]
        if shifts is not None:
            shots, turns = [corrected[i] for i in idx], [turntable_deg[i] for i in idx]
            framed = harp_frame(shots, turns, width, height, centre=guess[g], reach=SHIFT_SEARCH)
            if not framed:
                return FitFailure(f"axis group {g!r}: {framed.reason}")
            frames[g] = framed[0]
        frame = frames[g]
        for i in idx:
            nrm, c = frame.normal(float(turntable_deg[i])), np.asarray(frame.centre)
            q[i] = np.array([float(nrm @ (e.mean(axis=0) - c)) for e in corrected[i]])
    lab = gap_clusters(np.concatenate(q), min(f.pitch_px for f in frames.values()) / 3.0)
    ends = np.cumsum([len(v) for v in q])
    return frames, [[int(v) for v in part] for part in np.split(lab, ends[:-1])]


def _place_groups(
    shots: Sequence[Sequence[Sequence[Floats]]],
    turns: Sequence[Sequence[float]],
    names: Sequence[Hashable],
    width: int,
    height: int,
) -> list[HarpFrame] | FitFailure:
    """Each axis group's frame without shifts (:func:`group_frames`): per group the places of its axis within
    :data:`GROUP_AXIS_SEARCH` pitches of the image centre that make its shots one harp alike (:func:`_axis_places`,
    as :func:`harp_frame` places one axis); where a group has several, the one combination of places, one per
    group, that makes *all* the shots one harp (:func:`_consistency` on every group's distances from its own axis:
    a string keeps its distance from the axis in every group) better than any other by :data:`AXIS_TIE`. Fewer
    strings do not decide here, alone or together: four angles 45 degrees apart make a harp wider than the image
    agree about places 1.85 pitches off with a string *fewer* than about its axis, and the places of groups of three
    angles (a lattice each) combine into harps of fewer strings too (``benchmarks/axis_positions.py``). Refused with
    the reason when a group's shots agree about no place, when no combination makes all the shots one harp
    (:data:`AXIS_DISAGREE`), or when several make them agree alike (up to :data:`MAX_GROUP_COMBINATIONS` are
    scored)."""
    parts: list[_Across] = []
    alike: list[list[tuple[float, int, Floats]]] = []
    c0 = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    for g, group, angles in zip(names, shots, turns, strict=True):
        if distinct_orientations(angles) < MIN_GROUP_ANGLES:
            return FitFailure(
                f"axis group {g!r}: {distinct_orientations(angles)} turntable angles cannot place its axis without a "
                f"shift (a harp of uniform pitch agrees about a lattice of places); give each group's shift, or "
                f"{MIN_GROUP_ANGLES} angles or more spread over the half turn"
            )
        across = _across(group, angles, width, height)
        if isinstance(across, FitFailure):
            return FitFailure(f"axis group {g!r}: {across.reason}")
        places = _axis_places(
            across.oo, across.nn, across.shot_of, len(group), across.pitch, c0, across.refined, GROUP_AXIS_SEARCH,
            GROUP_AXIS_SEEDS, complete=True,
        )  # fmt: skip
        if isinstance(places, FitFailure):
            return FitFailure(f"axis group {g!r}: {places.reason}")
        parts.append(across)
        alike.append(places)
    sizes = [len(a) for a in alike]
    if max(sizes) > 1:
        why = (
            "the harp's axis is ambiguous with these turntable angles in axis group"
            f"{'s' if sum(n > 1 for n in sizes) > 1 else ''} "
            + ", ".join(repr(g) for g, n in zip(names, sizes, strict=True) if n > 1)
        )
        if int(np.prod(sizes)) > MAX_GROUP_COMBINATIONS:
            return FitFailure(
                f"{why}: {int(np.prod(sizes))} combinations of places; add angles spread over the half turn"
            )
        combos = np.array(np.meshgrid(*[np.arange(n) for n in sizes], indexing="ij")).reshape(len(sizes), -1).T
        q = np.hstack(
            [
                a.oo[None, :] - np.array([c for _, _, c in places])[combos[:, j]] @ a.nn.T
                for j, (a, places) in enumerate(zip(parts, alike, strict=True))
            ]
        )
        shot_of = np.concatenate([a.shot_of + sum(len(s) for s in shots[:j]) for j, a in enumerate(parts)])
        pitch = float(np.median([a.pitch for a in parts]))
        v = _consistency(q, shot_of, sum(len(s) for s in shots), pitch, AXIS_TOLERANCE * pitch)[0]
        together = np.flatnonzero(v <= v.min() + AXIS_TIE)
        if v.min() > AXIS_DISAGREE * q.shape[1] or len(together) > 1:
            alike_n = len(together) if v.min() <= AXIS_DISAGREE * q.shape[1] else 0
            return FitFailure(
                f"{why}: {alike_n} of {len(combos)} combinations of places make all the shots' strings agree"
                "; add angles spread over the half turn, or give each group's shift"
            )
        alike = [[places[int(combos[together[0], j])]] for j, places in enumerate(alike)]
    return [a.framed(places[0][2])[0] for a, places in zip(parts, alike, strict=True)]
