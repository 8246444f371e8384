"""Sharpness, contrast and width of each string by the slanted-edge profile fit on the
full-resolution pixels (:mod:`pipeline.assess`, *Sharpness of a string*)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from pipeline.plain import finite_or_none

Points = NDArray[np.float64]
Floats = NDArray[np.float64]

CROSS_SECTIONS = 24
"""Cross-sections per string on which sharpness, contrast and width are measured."""
EDGE_WIDTH_PER_SIGMA = 2.0 * 1.2815515655446004
"""10-90 % rise distance of a Gaussian-blurred step, in units of its sigma (2 Phi^-1(0.9))."""
PIXEL_VARIANCE = 1.0 / 12.0
"""Variance (px^2) a unit pixel adds along any direction."""
_MAX_GN_ITER = 12
_WIDTH_TO_SIGMA = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 9.0, 14.0)


@dataclass(frozen=True)
class StringSharpness:
    """Figures of one string, measured on the full-resolution frame (:mod:`pipeline.assess`).

    Attributes
    ----------
    string_id : int
        The grouping's string number (0, 1, ... across the harp).
    sigma_px : float
        Standard deviation of the fitted PSF across the string (optics and
        pixel integration), px; NaN when the fit failed.
    edge_width_px : float
        10-90 % width of one edge, ``EDGE_WIDTH_PER_SIGMA * sigma_px``.
    contrast : float
        ``|A| / max(B, B + A)``: the fraction of the brighter level the string
        takes away (dark strings) or adds (bright ones); at most 1 (an opaque
        string). For a string narrower than about 2 sigma only ``contrast *
        width_px`` (its shadow) is well determined (:mod:`pipeline.assess`).
    width_px : float
        Fitted string width, px.
    angle_deg : float
        Direction of the string in ``[0, 180)`` (pipeline convention).
    centre : (float, float)
        A point of the string's centre line near its middle, ``(x, y)``.
    cross_sections : int
        Cross-sections that entered the fit.
    residual : float
        RMS residual of the fit relative to ``|A|``.
    offset_px : float
        Median distance between the centre line given (from the edges) and the one refined on
        the pixels: how far the string is from where it was looked for.
    """

    string_id: int
    sigma_px: float
    edge_width_px: float
    contrast: float
    width_px: float
    angle_deg: float
    centre: tuple[float, float]
    cross_sections: int
    residual: float
    offset_px: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {
            "string": self.string_id,
            "sigma_px": finite_or_none(self.sigma_px),
            "edge_width_px": finite_or_none(self.edge_width_px),
            "contrast": finite_or_none(self.contrast),
            "width_px": finite_or_none(self.width_px),
            "angle_deg": finite_or_none(self.angle_deg),
            "centre": [self.centre[0], self.centre[1]],
            "cross_sections": self.cross_sections,
            "residual": finite_or_none(self.residual),
            "offset_px": finite_or_none(self.offset_px),
        }


def _interp_along(xy: Points, u_of: Floats, u: Floats) -> Points:
    return np.stack([np.interp(u, u_of, xy[:, 0]), np.interp(u, u_of, xy[:, 1])], axis=1)


def _cross_sections(a: Points, b: Points, k: int, direction: Points) -> tuple[Points, Points, float] | None:
    """Centres, unit normals (``(k, 2)`` each) and width of a string from its two edges."""
    ua, ub = a @ direction, b @ direction
    oa, ob = np.argsort(ua), np.argsort(ub)
    ua, ub, a, b = ua[oa], ub[ob], a[oa], b[ob]
    lo, hi = max(ua[0], ub[0]), min(ua[-1], ub[-1])
    if not hi - lo > 4.0:
        return None
    u = lo + (hi - lo) * (np.arange(k) + 0.5) / k
    pa, pb = _interp_along(a, ua, u), _interp_along(b, ub, u)
    centre = 0.5 * (pa + pb)
    h = min(8.0, 0.25 * (hi - lo) / k + 2.0)
    ta = _interp_along(a, ua, np.minimum(u + h, hi)) - _interp_along(a, ua, np.maximum(u - h, lo))
    tb = _interp_along(b, ub, np.minimum(u + h, hi)) - _interp_along(b, ub, np.maximum(u - h, lo))
    t = ta + tb
    t /= np.maximum(np.hypot(t[:, 0], t[:, 1]), 1e-12)[:, None]
    normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
    width = float(np.median(np.abs(np.sum((pb - pa) * normal, axis=1))))
    return centre, normal, width


def _profile(s: Floats, w: Floats, sig: Floats) -> Floats:
    """``g(s)`` of the module docstring (a blurred box of width ``w``)."""
    return np.asarray(ndtr((s + 0.5 * w) / sig) - ndtr((s - 0.5 * w) / sig), np.float64)


class _Rows:
    """Samples grouped by cross-section, with the sums of the linear model that do not change.

    The linear part of the model is ``v ~ B + C s + A g`` per cross-section (row): the slope
    ``C`` absorbs the shading across one cross-section (vignetting). Only the sums involving
    ``g`` change while ``(w, sigma)`` are fitted.
    """

    def __init__(self, s: Floats, v: Floats, row: NDArray[np.intp], nrows: int) -> None:
        self.s, self.v, self.row, self.nrows = s, v, row, nrows
        self.n = np.bincount(row, minlength=nrows).astype(np.float64)
        self.ss, self.sss = self._sum(row, s), self._sum(row, s * s)
        self.sv, self.ssv = self._sum(row, v), self._sum(row, s * v)

    def _sum(self, row: NDArray[np.intp], x: Floats) -> Floats:
        return np.bincount(row, weights=x, minlength=self.nrows).astype(np.float64)

    def project(self, g: Floats, sel: NDArray[np.intp] | None = None) -> tuple[Floats, Floats, Floats, Floats]:
        """``B``, ``C``, ``A`` per row and the residual of the samples ``sel`` (all: None).

        ``g`` is the profile at the samples ``sel``; rows not in ``sel`` get meaningless values.
        """
        s, v, row = (self.s, self.v, self.row) if sel is None else (self.s[sel], self.v[sel], self.row[sel])
        sg, sgg, ssg, sgv = self._sum(row, g), self._sum(row, g * g), self._sum(row, s * g), self._sum(row, g * v)
        ata = np.empty((self.nrows, 3, 3))
        ata[:, 0, 0], ata[:, 1, 1], ata[:, 2, 2] = self.n, self.sss, sgg
        ata[:, 0, 1] = ata[:, 1, 0] = self.ss
        ata[:, 0, 2] = ata[:, 2, 0] = sg
        ata[:, 1, 2] = ata[:, 2, 1] = ssg
        atb = np.stack([self.sv, self.ssv, sgv], axis=1)
        scale = np.maximum(ata[:, 0, 0] + ata[:, 1, 1] + ata[:, 2, 2], 1e-300)
        coef = np.asarray(
            np.linalg.solve(ata / scale[:, None, None] + 1e-12 * np.eye(3), (atb / scale[:, None])[..., None])[..., 0],
            np.float64,
        )
        bg, slope, amp = coef[:, 0], coef[:, 1], coef[:, 2]
        return bg, slope, amp, v - bg[row] - slope[row] * s - amp[row] * g


def _fit_strings(
    rows: _Rows,
    string_of_row: NDArray[np.intp],
    w0: Floats,
    sig0: Floats,
) -> tuple[Floats, Floats, Floats]:
    """Variable-projection Levenberg-Marquardt for ``(w, sigma)`` of every string at once.

    Each string stops iterating once converged (the others go on without it).
    Returns ``w``, ``sigma`` and the cost (sum of squared residuals) per string.
    """
    ns = len(w0)
    st = string_of_row[rows.row]
    p = np.stack([np.log(np.maximum(w0, 0.5)), np.log(np.maximum(sig0, 0.3))], axis=1)
    lam = np.full(ns, 1e-3)
    s = rows.s

    def resid(q: Floats, sel: NDArray[np.intp]) -> Floats:
        k = st[sel]
        return rows.project(_profile(s[sel], np.exp(q[k, 0]), np.exp(q[k, 1])), sel)[3]

    def per_string(sel: NDArray[np.intp], x: Floats) -> Floats:
        return np.bincount(st[sel], weights=x, minlength=ns).astype(np.float64)

    everything = np.arange(len(s))
    r = resid(p, everything)
    c = per_string(everything, r * r)
    active = np.ones(ns, bool)
    eps = 1e-5
    for _ in range(_MAX_GN_ITER):
        sel = np.nonzero(active[st])[0]
        if not len(sel):
            break
        rs = r[sel]
        j0 = (resid(p + [eps, 0.0], sel) - rs) / eps
        j1 = (resid(p + [0.0, eps], sel) - rs) / eps
        a00, a01, a11 = per_string(sel, j0 * j0), per_string(sel, j0 * j1), per_string(sel, j1 * j1)
        g0, g1 = per_string(sel, j0 * rs), per_string(sel, j1 * rs)
        a00d, a11d = a00 * (1.0 + lam) + 1e-12, a11 * (1.0 + lam) + 1e-12
        det = a00d * a11d - a01 * a01
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        step = np.stack([-(a11d * g0 - a01 * g1) / det, -(a00d * g1 - a01 * g0) / det], axis=1)
        step = np.where(active[:, None], np.clip(step, -0.7, 0.7), 0.0)
        q = p + step
        q[:, 1] = np.maximum(q[:, 1], math.log(0.2))
        rq = resid(q, sel)
        cq = np.where(active, per_string(sel, rq * rq), np.inf)
        better = cq < c
        small = better & ((np.abs(step).max(axis=1) < 1e-3) | (c - cq < 1e-5 * c))
        p = np.where(better[:, None], q, p)
        r[sel] = np.where(better[st[sel]], rq, rs)
        c = np.where(better, cq, c)
        lam = np.where(better, lam * 0.2, lam * 10.0)
        active &= ~(small | (lam > 1e4))
    return np.exp(p[:, 0]), np.exp(p[:, 1]), c


def _gather(
    img: NDArray[Any], centre: Points, normal: Points, reach: float
) -> tuple[Floats, Floats, NDArray[np.bool_]]:
    """Pixels of one row or column through each centre, with their distance along the normal.

    Returns ``(K, J)`` arrays: signed distance ``s`` to the centre line,
    value, and a mask of the pixels inside the image and within ``reach``.
    """
    h, w = img.shape
    along_x = np.abs(normal[:, 0]) >= np.abs(normal[:, 1])  # walk a row (else a column)
    comp = np.where(along_x, np.abs(normal[:, 0]), np.abs(normal[:, 1]))
    half = int(math.ceil(reach / math.sqrt(0.5))) + 1
    j = np.arange(-half, half + 1, dtype=np.float64)[None, :]
    xs = np.where(along_x[:, None], np.round(centre[:, 0:1]) + j, np.round(centre[:, 0:1]))
    ys = np.where(along_x[:, None], np.round(centre[:, 1:2]), np.round(centre[:, 1:2]) + j)
    xs = np.broadcast_to(xs, (len(centre), j.size))
    ys = np.broadcast_to(ys, (len(centre), j.size))
    inside = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    xi = np.clip(xs, 0, w - 1).astype(np.intp)
    yi = np.clip(ys, 0, h - 1).astype(np.intp)
    vals = img[yi, xi].astype(np.float64)
    s = (xs - centre[:, 0:1]) * normal[:, 0:1] + (ys - centre[:, 1:2]) * normal[:, 1:2]
    mask = inside & (np.abs(s) <= reach) & (comp[:, None] > 0)
    return s, vals, mask


def string_sharpness(
    image: NDArray[Any],
    strings: Sequence[tuple[int, Points, Points]],
    *,
    cross_sections: int = CROSS_SECTIONS,
    reach_px: float | None = None,
) -> tuple[StringSharpness, ...]:
    """Sharpness, contrast, width and angle of each string (module docstring, *Sharpness*).

    Parameters
    ----------
    image : 2-D ndarray
        The full-resolution grey frame, ``image[y, x]``.
    strings : sequence of (string_id, edge_a, edge_b)
        The two edges of each string, ``(N, 2)`` points ``(x, y)`` in the
        frame's pixels (any order along the edge, any accuracy to about a
        pixel: the centre of each cross-section is refined on the pixels).
    cross_sections : int
        Cross-sections per string.
    reach_px : float or None
        Half-length of a cross-section beyond the string's half width
        (None: 16 px, at most 45 % of the string pitch minus the half width).

    Returns
    -------
    tuple of StringSharpness
        One per string, in the given order; a string too short or a fit that
        fails gives NaN figures (``cross_sections == 0``).

    References
    ----------
    .. [1] ISO 12233:2017 (slanted-edge sampling).
    .. [2] G. Golub, V. Pereyra, Inverse Problems 19(2), 2003.
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"expected a 2-D grey image, got shape {img.shape}")
    k = max(2, int(cross_sections))
    nan = float("nan")
    prepared: list[tuple[int, Points, Points, float, float, tuple[float, float]] | None] = []
    centres_all = []
    for sid, a, b in strings:
        pa, pb = np.asarray(a, np.float64), np.asarray(b, np.float64)
        if len(pa) < 2 or len(pb) < 2:
            prepared.append(None)
            continue
        c0 = np.concatenate([pa, pb]).mean(axis=0)
        direction = _direction(pa, pb)
        cs = _cross_sections(pa, pb, k, direction)
        if cs is None:
            prepared.append(None)
            continue
        centre, normal, width = cs
        angle = math.degrees(math.atan2(direction[1], direction[0])) % 180.0
        mid = centre[len(centre) // 2]
        prepared.append((sid, centre, normal, width, angle, (float(mid[0]), float(mid[1]))))
        centres_all.append((c0, direction, width))
    if reach_px is None:
        pitch = _pitch(centres_all)
        half_w = max((p[3] for p in prepared if p is not None), default=0.0) / 2.0
        extra = 16.0 if not math.isfinite(pitch) else max(4.0, min(16.0, 0.45 * pitch - half_w))
    else:
        extra = float(reach_px)
    live = [i for i, p in enumerate(prepared) if p is not None]
    fitted = _fit_batch(img, [p for p in prepared if p is not None], extra) if live else []
    out = [StringSharpness(int(sid), nan, nan, nan, nan, nan, (nan, nan), 0, nan) for sid, _, _ in strings]
    for i, fig in zip(live, fitted):
        p = prepared[i]
        assert p is not None
        sid, _, _, _, angle, mid = p
        out[i] = StringSharpness(int(sid), fig[0], fig[1], fig[2], fig[3], angle, mid, fig[4], fig[5], fig[6])
    return tuple(out)


def _direction(a: Points, b: Points) -> Points:
    """Unit direction of a string: the length-weighted doubled-angle mean of its edges' own
    total-least-squares directions (two edges of unequal extent would tilt a joint fit)."""
    acc = np.zeros(2)
    for xy in (a, b):
        c = xy - xy.mean(axis=0)
        val, vec = np.linalg.eigh(c.T @ c)
        t = vec[:, 1]
        ang = 2.0 * math.atan2(t[1], t[0])
        acc += math.sqrt(max(float(val[1]), 0.0)) * np.array([math.cos(ang), math.sin(ang)])
    half = 0.5 * math.atan2(acc[1], acc[0])
    return np.array([math.cos(half), math.sin(half)])


def _pitch(lines: Sequence[tuple[Points, Points, float]]) -> float:
    """Median distance between neighbouring string centre lines (NaN with fewer than two)."""
    if len(lines) < 2:
        return float("nan")
    d = np.mean(
        [ln[1] for ln in lines if ln[1] @ lines[0][1] >= 0] + [-ln[1] for ln in lines if ln[1] @ lines[0][1] < 0],
        axis=0,
    )
    n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-12)
    off = np.sort([float(ln[0] @ n) for ln in lines])
    gaps = np.diff(off)
    gaps = gaps[gaps > 1.0]
    return float(np.median(gaps)) if len(gaps) else float("nan")


def _line_fit(s: Floats, v: Floats, m: NDArray[np.bool_]) -> tuple[Floats, Floats]:
    """Per row least-squares line ``v ~ b0 + b1 s`` over the masked samples (``(R, J)`` arrays)."""
    mf = m.astype(np.float64)
    n, ss, sv = mf.sum(-1), (s * mf).sum(-1), (v * mf).sum(-1)
    sss, ssv = (s * s * mf).sum(-1), (s * v * mf).sum(-1)
    det = n * sss - ss * ss
    ok = det > 1e-9
    b1 = np.where(ok, (n * ssv - ss * sv) / np.where(ok, det, 1.0), 0.0)
    b0 = np.where(n > 0, (sv - b1 * ss) / np.maximum(n, 1.0), 0.0)
    return b0, b1


def _centre(s: Floats, d: Floats, m: NDArray[np.bool_]) -> tuple[Floats, Floats]:
    """Per row centroid and variance of the darkness ``d`` over the mask (noise averages out: not clipped)."""
    wt = d * m
    tot = wt.sum(-1)
    good = tot > 1e-9
    mean = np.where(good, (wt * s).sum(-1) / np.where(good, tot, 1.0), 0.0)
    var = np.where(good, (wt * s * s).sum(-1) / np.where(good, tot, 1.0) - mean**2, np.nan)
    return mean, var


def _fit_batch(
    img: NDArray[Any],
    live: Sequence[tuple[int, Points, Points, float, float, tuple[float, float]]],
    extra: float,
) -> list[tuple[float, float, float, float, int, float, float]]:
    """Fit every string at once; per string (sigma, edge width, contrast, width, sections, residual, offset)."""
    ns = len(live)
    widths = np.array([p[3] for p in live])
    reach = float(np.max(widths)) / 2.0 + extra
    gathered = [_gather(img, p[1], p[2], reach) for p in live]
    s = np.concatenate([g[0] for g in gathered])  # (R, J): every cross-section of every string
    v = np.concatenate([g[1] for g in gathered])
    m0 = np.concatenate([g[2] for g in gathered])
    nrows = len(s)
    sor = np.repeat(np.arange(ns), [len(g[0]) for g in gathered]).astype(np.intp)  # string of each row
    half = widths[sor][:, None] / 2.0
    inner_lim, outer_lim = half + 0.6 * extra, half + extra
    # a cross-section is used only with background on both sides (not cut by the image border)
    both = (np.any(m0 & (s <= -inner_lim), axis=-1) & np.any(m0 & (s >= inner_lim), axis=-1))[:, None]
    m0 = m0 & both & (np.abs(s) <= outer_lim)
    # first guess: a background line through the outer pixels, the amplitude at the extreme,
    # then centre and sigma from the moments of the darkness (variance w^2 / 12 + sigma^2)
    b0, b1 = _line_fit(s, v, m0 & (np.abs(s) >= inner_lim))
    dev = np.where(m0, v - b0[:, None] - b1[:, None] * s, 0.0)
    inner = m0 & (np.abs(s) < inner_lim)
    lo, hi = np.where(inner, dev, np.inf).min(-1), np.where(inner, dev, -np.inf).max(-1)
    amp = np.where(np.abs(lo) > np.abs(hi), lo, hi)
    amp = np.where(np.isfinite(amp) & (np.abs(amp) > 1e-12), amp, 1.0)
    moved = np.zeros(nrows)  # how far each cross-section's centre was moved
    sd = np.full(ns, extra / 3.0)  # the profile's standard deviation, sqrt(w^2 / 12 + sigma^2)
    for _ in range(3):
        win = np.minimum(3.0 * sd + 1.0, widths / 2.0 + 0.6 * extra)[sor][:, None]
        shift, var = _centre(s, dev / amp[:, None], m0 & (np.abs(s) <= win))
        s = s - shift[:, None]
        moved += shift
        with np.errstate(all="ignore"):
            var_s = np.array(
                [np.nanmedian(var[sor == i]) if np.isfinite(var[sor == i]).any() else np.nan for i in range(ns)]
            )
        sd = np.where(np.isfinite(var_s), np.sqrt(np.clip(var_s, 0.09, None)), 1.0)
    # split that variance between the string width and the blur: the best of a few ratios w / sigma
    rr, jj = np.nonzero(m0 & (np.abs(s) <= np.minimum(4.0 * sd + 3.0, widths / 2.0 + extra)[sor][:, None]))
    rows = _Rows(s[rr, jj], v[rr, jj], rr.astype(np.intp), nrows)
    st = sor[rr]
    best = np.full(ns, np.inf)
    w_fit, sig_fit = np.maximum(widths, 1.0), np.maximum(sd / 2.0, 0.3)
    for rho in _WIDTH_TO_SIGMA:
        sig = sd / math.sqrt(rho * rho / 12.0 + 1.0)
        res = rows.project(_profile(rows.s, rho * sig[st], sig[st]))[3]
        c = np.bincount(st, weights=res * res, minlength=ns)
        take = c < best
        best = np.where(take, c, best)
        w_fit, sig_fit = np.where(take, rho * sig, w_fit), np.where(take, sig, sig_fit)
    cost = np.zeros(ns)
    rr = np.zeros(0, np.intp)
    bg = amp_f = np.zeros(nrows)
    for rnd in range(2):
        # fit on the string and enough background on both sides: w/2 + 5 sigma + 3 (within the reach)
        fit_win = np.minimum(w_fit / 2.0 + 5.0 * sig_fit + 3.0, widths / 2.0 + extra)
        rr, jj = np.nonzero(m0 & (np.abs(s) <= fit_win[sor][:, None]))
        rr = rr.astype(np.intp)
        rows = _Rows(s[rr, jj], v[rr, jj], rr, nrows)
        w_fit, sig_fit, cost = _fit_strings(rows, sor, w_fit, sig_fit)
        bg, slope, amp_f, _ = rows.project(_profile(rows.s, w_fit[sor[rr]], sig_fit[sor[rr]]))
        if rnd == 0:  # re-centre each cross-section on the fitted model's darkness
            a_safe = np.where(np.abs(amp_f) > 1e-12, amp_f, 1.0)[:, None]
            win = (w_fit / 2.0 + 3.0 * sig_fit + 1.0)[sor][:, None]
            shift, _ = _centre(s, (v - bg[:, None] - slope[:, None] * s) / a_safe, m0 & (np.abs(s) <= win))
            s = s - shift[:, None]
            moved += shift
    counts = np.bincount(rr, minlength=nrows)
    n_str = np.bincount(sor, weights=counts, minlength=ns)
    out = []
    for i in range(ns):
        ok = (sor == i) & (counts >= 5) & (np.abs(amp_f) > 0)
        a, b = amp_f[ok], bg[ok]
        if ok.sum() < 2 or not (0.2 < sig_fit[i] < 0.5 * extra + 10.0):
            out.append((float("nan"),) * 4 + (0, float("nan"), float("nan")))
            continue
        contrast = float(np.median(np.abs(a) / np.maximum(np.maximum(b, b + a), 1e-12)))
        width = float(w_fit[i])
        if contrast > 1.0:  # light below zero: an opaque string narrower than the blur (:mod:`pipeline.assess`)
            width, contrast = width * contrast, 1.0
        rel = math.sqrt(cost[i] / max(n_str[i], 1.0)) / max(float(np.median(np.abs(a))), 1e-12)
        sg = float(sig_fit[i])
        offset = float(np.median(np.abs(moved[ok])))
        out.append((sg, EDGE_WIDTH_PER_SIGMA * sg, contrast, width, int(ok.sum()), rel, offset))
    return out
