r"""A string's kink, found and modelled explicitly in the joint fit of lens and strings (:mod:`pipeline.harp_shape`).

A kink (a crimp at harp position :math:`a_k`, :mod:`pipeline.harp_scene`) is a cusp
:math:`w(a) = h\,e^{-|a - a_k|/\lambda}` of length :math:`\lambda` a few pixels and height
:math:`h = \alpha\lambda/2`. The measurement smooths every edge along itself
(:mod:`pipeline.resample`, scale :math:`\sigma = 0.8\sqrt{t^2 - 1}`, 24 px at t = 30) far more than
:math:`\lambda`, so a measured edge carries the kink as its area :math:`A = \int w\,da = 2h\lambda`
times the smoother's equivalent kernel :math:`l` (:func:`pipeline.resample.equivalent_kernel`):

.. math:: w_{\text{measured}}(a) = A\,l\bigl(\gamma\,(a - a_k)\bigr) = p\,g(a - a_k),
          \qquad g(d) = l(\gamma d) / l(0),

a bump one or two measured points wide, :math:`p = A\,l(0)` its peak (px), :math:`\gamma` the
lens's local stretch from ideal to distorted arclength (the smoothing runs along the distorted edge).
The kink is fixed to the harp: it sits at the *same* harp coordinate :math:`a_k` of the same string
in every shot, at different places of the image, which no lens correction can imitate.

Detection (:func:`scan_string`)
-------------------------------
After the joint fit, each string's residuals :math:`r_i` (the corrected points' distances to their
edge's line, along the harp normal) are pooled over its shots and its two edges and scanned with the
matched filter of :math:`g` at candidate positions :math:`a_c` every :data:`SCAN_STEP` :math:`\sigma`:
with :math:`g_i^\perp` the template less its weighted least-squares line per edge (each edge's own
line is free in the fit),

.. math:: \hat p(a_c) = \frac{\sum_i w_i g_i^\perp r_i}{\sum_i w_i g_i^\perp{}^2}, \qquad
          \operatorname{se}(\hat p) = \frac{s}{\sqrt{\sum_i w_i g_i^\perp{}^2}}, \qquad
          z = \hat p / \operatorname{se},

:math:`w_i` each point's weight (the fit's robust point weight over the smoother's noise gain at
the edge's ends squared, :func:`pipeline.resample.noise_gain`), :math:`s` the string's robust residual
scale (1.4826 median :math:`|r_i|\sqrt{w_i}`, never below
:data:`pipeline.robust_points.SCALE_FLOOR_PX`, the noise of any measured edge). The position of largest :math:`|z|` is taken when
:math:`|z| \ge` ``z_min`` (:data:`KINK_Z`, set on kink-free strings of the realistic simulator so that
they seldom get one: ``benchmarks/RESULTS-strings.md``) and when the string was seen there in at least
``min_shots`` shots (:data:`MIN_KINK_SHOTS`: seen in one shot only, a localised bump is the lens's
local misfit as much as the string's), at least :math:`\sigma` inside the stretch of the string each
of them shows (near an edge's end the smoother is one-sided and the template does not hold); its bump is taken out and the scan repeated, at most
:data:`MAX_KINKS` per string, each at least :data:`KINK_SEPARATION` :math:`\sigma` from the others.

Modelling: each kink found becomes a term :math:`p_j\,g(a - a_{k,j})` of its string's deviation
(position fixed, peak :math:`p_j` linear, no ridge) and the lens and every string are fitted again.

References
----------
.. [1] G. L. Turin, "An introduction to matched filters", IRE Trans. Information Theory 6(3), 1960.
.. [2] J. Fan, I. Gijbels, *Local Polynomial Modelling and Its Applications*, Chapman & Hall, 1996,
   Sect. 3.2.2 (equivalent kernels).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.resample import DEFAULT_T, TRUNCATE, equivalent_kernel, noise_gains, smoothing_sigma
from pipeline.robust_points import MAD_TO_SIGMA, SCALE_FLOOR_PX

Floats = NDArray[np.float64]

KINK_Z = 10.0
"""Least significance (matched-filter peak over its standard error) at which a kink is modelled: on the
kink-free strings of the realistic simulator's lenses 0..19 the scan's largest is 8.5 (residual scales
and neighbouring points' correlation make the nominal z no Gaussian one); ``benchmarks/RESULTS-strings.md``."""
MAX_KINKS = 2
"""Most kinks modelled on one string."""
MIN_KINK_SHOTS = 2
"""Fewest shots in which a kink's place must be seen."""
SCAN_STEP = 0.25
"""Spacing of the candidate positions, in smoothing sigmas."""
KINK_SEPARATION = 2.0
"""Least distance between two kinks of one string, in smoothing sigmas."""
KINK_LENGTHS = (0.0, 0.25, 0.5, 0.75)
"""The cusp lengths :math:`\\lambda` tried, in smoothing sigmas (0 to 18 px at t = 30; drawn kinks are
0.2-1.2 mm, 2-13 px at 0.1 mm/px): the one matching best is taken."""


@dataclass(frozen=True)
class Kink:
    """One kink found on a string and fitted (module docstring).

    ``string``: the string's index (:class:`pipeline.harp_shape.StringShape`); ``u``: its harp coordinate
    (half image diagonals from the axis), ``at_px`` the same in ideal pixels; ``peak_px`` the fitted
    peak :math:`p` of the smoothed bump along the harp normal, ``peak_se_px`` its standard error;
    ``area_px2`` :math:`A = p / (l * c_\\lambda)(0)` (:math:`2h\\lambda` for a cusp of height :math:`h` and
    length :math:`\\lambda`); ``length_px`` the :math:`\\lambda` of the template that matched best
    (:data:`KINK_LENGTHS`); ``z`` the detection's significance (the scan's, before the refit); ``shots``
    in how many shots its place was seen."""

    string: int
    u: float
    at_px: float
    peak_px: float
    peak_se_px: float
    area_px2: float
    z: float
    shots: int
    length_px: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


_TABLE_STEP = 0.25  # px: the tabulated smoothed cusps


@lru_cache(maxsize=64)
def _smoothed_cusp(length_px: float, t: int) -> tuple[Floats, Floats]:
    """Offsets (px, from 0) and values of :math:`(l * c_\\lambda)(d)`, :math:`c_\\lambda` the cusp of unit area
    :math:`e^{-|s|/\\lambda}/2\\lambda` (a delta for ``length_px`` 0)."""
    sig = max(smoothing_sigma(t), 1.0)
    reach = TRUNCATE * sig + 8.0 * length_px + 2.0
    d = np.arange(0.0, reach + _TABLE_STEP, _TABLE_STEP)
    if length_px <= 0:
        return d, equivalent_kernel(d, t)
    s = np.arange(-reach - 8.0 * length_px, reach + 8.0 * length_px + _TABLE_STEP, _TABLE_STEP)
    cusp = np.exp(-np.abs(s) / length_px) / (2.0 * length_px) * _TABLE_STEP
    kernel = equivalent_kernel(s, t)
    full = np.convolve(kernel, cusp, mode="same")  # centred: s has an odd number of samples about 0
    mid = len(s) // 2
    return d, full[mid : mid + len(d)]


def template(d_px: Floats, stretch: Floats | float = 1.0, t: int = DEFAULT_T, length_px: float = 0.0) -> Floats:
    """:math:`g(d)`: the measured shape, peak 1, of a kink ``length_px`` long (its :math:`\\lambda`, ideal px)
    at ideal distance ``d_px`` from it: the cusp smoothed by the measurement, :math:`l * c_\\lambda`, at
    :math:`\\gamma d` over its value at 0."""
    d, v = _smoothed_cusp(float(length_px), int(t))
    out: Floats = np.interp(np.abs(np.asarray(d_px) * stretch), d, v, right=0.0) / float(v[0])
    return out


def peak_per_area(t: int = DEFAULT_T, length_px: float = 0.0) -> float:
    """:math:`(l * c_\\lambda)(0)`: the measured bump's peak per unit of kink area (1/px)."""
    return float(_smoothed_cusp(float(length_px), int(t))[1][0])


def end_weights(xy: Floats, starts: NDArray[np.intp], counts: NDArray[np.intp], t: int = DEFAULT_T) -> Floats:
    r"""Per point ``1 / gain^2``, ``gain`` the smoother's noise at the point's place on its edge over the
    middle's (:func:`pipeline.resample.noise_gain`: 2.6 at the end points for t = 30, 1 from about
    :math:`2\sigma` in), arclengths along the (distorted) points as given.

    A point's gain depends on the piece's samples within its window only: on an edge long enough that no
    window reaches both ends, a point near the start has the gain it has on any such edge, one near the end
    the gain of the place as far from the last sample on any such edge, and the middle the interior gain at
    its offset from the sample grid; all of those are taken from one reference edge in one call."""
    out = np.ones(len(xy))
    sig = smoothing_sigma(t)
    if sig == 0:
        return out
    reach = TRUNCATE * sig
    m = int(np.ceil(reach)) + int(np.ceil(TRUNCATE * sig)) + 2  # no window of a point within reach of one
    pos: list[Floats] = []  # end of a piece 2m samples long reaches the other end (nor the middle's)
    where: list[NDArray[np.intp]] = []
    mids: list[float] = []
    for s0, c in zip(starts, counts, strict=True):
        p = xy[s0 : s0 + c]
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
        length = float(s[-1])
        if length <= 0:
            continue
        ends = np.flatnonzero((s < reach) | (s > length - reach))
        last = float(np.floor(length + 1e-9))
        if last < 2 * m:  # a short edge: its own piece
            gains = noise_gains(np.concatenate([[0.5 * length], s[ends]]), length, t)
            out[s0 + ends] = (gains[0] / gains[1:]) ** 2
            continue
        half = 0.5 * length
        mids.append(half - np.floor(half) + m)
        pos.append(np.where(s[ends] < reach, s[ends], s[ends] - last + 2 * m))
        where.append(s0 + ends)
    if mids:
        n = np.array([len(w) for w in where])
        gains = noise_gains(np.concatenate([np.array(mids), *pos]), float(2 * m), t)
        mid = np.repeat(gains[: len(mids)], n)
        out[np.concatenate(where)] = (mid / gains[len(mids) :]) ** 2
    return out


def stretches(xy: Floats, ideal: Floats, starts: NDArray[np.intp], counts: NDArray[np.intp]) -> Floats:
    """Per point :math:`\\gamma`, distorted over ideal arclength along its edge (1 for edges of < 2 points)."""
    out = np.ones(len(xy))
    for s0, c in zip(starts, counts, strict=True):
        if c < 2:
            continue
        sl = slice(s0, s0 + c)
        ds = np.hypot(*np.gradient(xy[sl], axis=0).T)
        di = np.hypot(*np.gradient(ideal[sl], axis=0).T)
        out[sl] = np.where(di > 0, ds / np.maximum(di, 1e-12), 1.0)
    return out


def _without_lines(g: Floats, a: Floats, w: Floats, edge: NDArray[np.intp]) -> Floats:
    """``g`` (P, C) less, per edge, its ``w``-weighted least-squares line in ``a`` (rows of edges with fewer
    than three points set to 0: such an edge cannot tell a bump from its line). All edges at once, from the
    weighted sums of the 2 x 2 normal equations :math:`[W, S_a; S_a, S_{aa}]`."""
    _, e, n = np.unique(edge, return_inverse=True, return_counts=True)
    ne = len(n)
    sw = np.bincount(e, w, ne)
    x = a - (np.bincount(e, w * a, ne) / np.where(sw > 0, sw, 1.0))[e]  # centred per edge: S_a = 0
    sxx = np.bincount(e, w * x * x, ne)
    member = (e[None, :] == np.arange(ne)[:, None]).astype(np.float64)  # (edges, P)
    wg = w[:, None] * g
    sg = member @ wg
    sxg = member @ (x[:, None] * wg)
    c0 = sg / np.where(sw > 0, sw, 1.0)[:, None]
    c1 = sxg / np.where(sxx > 0, sxx, 1.0)[:, None]
    out: Floats = g - c0[e] - x[:, None] * c1[e]
    out[(n < 3)[e]] = 0.0
    return out


@dataclass(frozen=True)
class Candidate:
    """A kink the scan found on one string: place (ideal px), matched-filter peak, its standard error,
    significance and number of shots seeing it."""

    at_px: float
    peak_px: float
    se_px: float
    z: float
    shots: int
    length_px: float


def scan_string(
    a: Floats,
    r: Floats,
    w: Floats,
    edge: NDArray[np.intp],
    shot: NDArray[np.intp],
    stretch: Floats,
    *,
    t: int = DEFAULT_T,
    z_min: float = KINK_Z,
    max_kinks: int = MAX_KINKS,
    min_shots: int = MIN_KINK_SHOTS,
) -> list[Candidate]:
    """The kinks of one string (module docstring, *Detection*), strongest first.

    ``a``: each point's harp coordinate along the strings (ideal px); ``r``: its residual along the
    harp normal (px); ``w``: its weight; ``edge``, ``shot``: its edge and shot (any integer labels);
    ``stretch``: :math:`\\gamma` per point.
    """
    sig = smoothing_sigma(t)
    if len(a) < 6 or sig == 0 or max_kinks < 1:
        return []
    scale = max(MAD_TO_SIGMA * float(np.median(np.abs(r) * np.sqrt(w))), SCALE_FLOOR_PX)
    grid = np.arange(float(a.min()), float(a.max()) + 1e-9, SCAN_STEP * sig)
    lengths = [f * sig for f in KINK_LENGTHS]
    g = np.stack(
        [_without_lines(template(a[:, None] - grid[None, :], stretch[:, None], t, lam), a, w, edge) for lam in lengths]
    )
    den = np.einsum("i,lic,lic->lc", w, g, g)
    shots = np.unique(shot)
    lo = np.array([a[shot == i].min() for i in shots])
    hi = np.array([a[shot == i].max() for i in shots])
    seen = np.sum((lo[None, :] <= grid[:, None] - sig) & (hi[None, :] >= grid[:, None] + sig), axis=1)
    ok = (den > 0) & (seen >= min_shots)[None, :]
    se = scale / np.sqrt(np.where(den > 0, den, 1.0))  # (unused where den is 0: ok is false there)
    res = r.copy()
    out: list[Candidate] = []
    for _ in range(max_kinks):
        num = np.einsum("i,lic,i->lc", w, g, res)
        peak = np.where(ok, num / np.where(den > 0, den, 1.0), 0.0)
        z = np.where(ok, peak / se, 0.0)
        li, ci = np.unravel_index(int(np.argmax(np.abs(z))), z.shape)
        if not abs(z[li, ci]) >= z_min:
            break
        out.append(
            Candidate(
                float(grid[ci]), float(peak[li, ci]), float(se[li, ci]), float(z[li, ci]), int(seen[ci]), lengths[li]
            )
        )
        res = res - peak[li, ci] * g[li, :, ci]
        ok &= (np.abs(grid - grid[ci]) >= KINK_SEPARATION * sig)[None, :]
    return out
