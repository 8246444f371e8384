"""Whether shots support a distortion model: the distinct string orientations they cover and what a model needs.

A free centre with decentering, thin-prism or division terms, and a free polynomial or residual field,
are determined only by strings seen in enough directions (:func:`required_orientations`); a shot's
direction is its strings' (:func:`shot_orientation`), and directions closer than
:data:`ORIENTATION_SEPARATION_DEG` count once (:func:`distinct_orientations`). :func:`support_problem`
says what is missing; the model choice (:mod:`pipeline.select`) and the calibration read it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from pipeline.fitspec import FitSpec

REQUIRED_ORIENTATIONS_FREE = 3
"""Distinct orientations a spec with a free centre and decentering / thin-prism / division terms needs
to be well supported. Two orientations determine those terms when the lens has nothing else (an exact
decentred lens fitted on two orientations leaves unseen ones straight to 0.001 px,
``tests/pipeline/test_trefoil.py``), but a quadratic term the spec lacks (the three-fold one,
:class:`~pipeline.models.radial.RadialModel`) is then taken up by the thin-prism and decentering terms
without a trace and bends the third orientation; with three, it shows as a bow the fitted shots keep.
On the real photographs, fitted on two orientations, the third is left 2-3x less straight than when it
is in the fit (``benchmarks/quadratic_sector.py``)."""

REQUIRED_ORIENTATIONS_TREFOIL = 4
"""Distinct orientations the three-fold (trefoil) term needs: a quadratic distortion field shows on the
strings of one orientation only as the bow they all share, one number per orientation, and modulo a
homography the quadratic fields are four-dimensional (thin-prism two, trefoil two)."""

REQUIRED_ORIENTATIONS_POLY = 4
"""Distinct orientations a free bivariate polynomial (or a residual field) needs: with fewer, it keeps the lines of
the shots straight with terms an unseen orientation sees bent."""

ORIENTATION_SEPARATION_DEG = 10.0
"""Two shots whose strings differ in direction by less than this are one orientation."""

MIN_ORIENTATION_SPREAD_DEG = 20.0
"""A fit needs strings at two directions at least this far apart (:func:`pipeline.fit.fit_distortion`'s default):
one direction cannot constrain the distortion along the strings."""


def holdout_problem(angles_deg: Sequence[float], spread_deg: float = MIN_ORIENTATION_SPREAD_DEG) -> str | None:
    """Why a leave-one-orientation-out of shots whose strings turn with ``angles_deg`` (a turntable's angles, one per
    fitted orientation) cannot be fitted, else None: some fold keeps its string directions (modulo 180 degrees)
    within an arc narrower than ``spread_deg``. A session fits every fold, so such a plan never gives a profile.

    Linear in the number of directions (a plan may have 100000): the directions sorted on the 180-degree circle,
    the widest gap between neighbours when each one in turn is left out (its two gaps merged)."""
    a = np.asarray(angles_deg, dtype=np.float64) % 180.0
    if a.size == 0:
        return None
    u, counts = np.unique(a, return_counts=True)
    m = len(u)
    if m == 1:
        lonely = 0  # one direction: every fold keeps it alone (or nothing)
    else:
        gaps = np.diff(np.append(u, u[0] + 180.0))  # gaps[i]: from u[i] to the next direction, round the circle
        before = np.roll(np.arange(m), 1)  # the gap ending at u[i]
        top = np.argsort(gaps)[::-1][:3]  # the widest gaps: one of them is neither of a left-out direction's two
        other = np.full(m, 0.0)
        for j in top[::-1]:
            other = np.where((before != j) & (np.arange(m) != j), gaps[j], other)
        widest = np.maximum(gaps[before] + gaps, other) if m > 2 else np.full(m, 180.0)
        fails = (180.0 - widest <= spread_deg) & (counts == 1)  # a direction another shot repeats leaves none out
        if not fails.any():
            return None
        lonely = int(np.flatnonzero(fails)[0])
    return (
        f"without the shot at {u[lonely]:g} deg the others keep no two string directions more than {spread_deg:g} "
        "deg apart (modulo 180), and the holdout fits every shot's fold"
    )


def shot_orientation(lines: Sequence[np.ndarray]) -> float:
    """Direction of a shot's strings, degrees in [0, 180): the length-weighted mean (on doubled angles)
    of its edges' directions; NaN when it has no edge of 3 points or more."""
    c = s = 0.0
    for p in lines:
        q = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        q = q[np.all(np.isfinite(q), axis=1)]
        if len(q) < 3:
            continue
        d = q - q.mean(axis=0)
        sxx, syy, sxy = float(d[:, 0] @ d[:, 0]), float(d[:, 1] @ d[:, 1]), float(d[:, 0] @ d[:, 1])
        two = np.arctan2(2.0 * sxy, sxx - syy)
        length = float(np.hypot(*(q[-1] - q[0])))
        c += length * np.cos(two)
        s += length * np.sin(two)
    if c == 0.0 and s == 0.0:
        return float("nan")
    return float(np.degrees(0.5 * np.arctan2(s, c)) % 180.0)


def distinct_orientations(angles_deg: Iterable[float], separation_deg: float = ORIENTATION_SEPARATION_DEG) -> int:
    """Number of distinct orientations among line directions (degrees, modulo 180): the most of them that lie
    pairwise at least ``separation_deg`` apart around the circle (taken greedily from the smallest; directions
    closer than that to one taken count with it). A dense sweep counts as many orientations as fit in it (36
    directions 5 deg apart: 18), not as one: linking every direction to its neighbour within ``separation_deg``
    (as this function did before 2026-12-07) made such a sweep a single orientation."""
    a = np.sort(np.array([v % 180.0 for v in angles_deg if np.isfinite(v)]))
    if not len(a):
        return 0
    taken = [float(a[0])]
    for v in a[1:]:
        if v - taken[-1] >= separation_deg:
            taken.append(float(v))
    if len(taken) > 1 and taken[0] + 180.0 - taken[-1] < separation_deg:  # the last one is the first, around
        taken.pop()
    return len(taken)


def required_orientations(spec: FitSpec) -> int:
    """Distinct orientations ``spec`` needs to be well supported (:data:`REQUIRED_ORIENTATIONS_FREE`,
    :data:`REQUIRED_ORIENTATIONS_POLY`, also for a residual field, :data:`REQUIRED_ORIENTATIONS_TREFOIL`);
    2 for a radial factor alone (or one with a centre prior)."""
    if spec.kind == "poly" or spec.field is not None:
        return REQUIRED_ORIENTATIONS_POLY
    if spec.trefoil:
        return REQUIRED_ORIENTATIONS_TREFOIL
    if (spec.tangential or spec.prism or spec.division) and not spec.center_prior:
        return REQUIRED_ORIENTATIONS_FREE
    return 2


def orientation_shortfall(spec: FitSpec, angles_deg: Iterable[float]) -> tuple[int, int] | None:
    """``(need, have)`` when line directions ``angles_deg`` (degrees) give fewer distinct orientations
    (:func:`distinct_orientations`) than ``spec`` needs (:func:`required_orientations`), else None."""
    have = distinct_orientations(angles_deg)
    need = required_orientations(spec)
    return None if have >= need else (need, have)


def support_problem(spec: FitSpec, lines_per_image: Sequence[Sequence[np.ndarray]]) -> str | None:
    """Why the shots do not support ``spec`` well (too few distinct orientations), or None."""
    short = orientation_shortfall(spec, (shot_orientation(s) for s in lines_per_image))
    if short is None:
        return None
    need, have = short
    return (
        f"not well supported: {spec.label} needs >= {need} distinct string orientations "
        f"(>= {ORIENTATION_SEPARATION_DEG:g} deg apart), the shots have {have}; add shots at other angles"
    )
