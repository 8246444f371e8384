r"""Cross-validation of distortion models over shots: the CV table the model choice reads.

Each candidate (a :class:`pipeline.fitspec.FitSpec`: model kind, degree,
tangential / thin-prism terms, centre prior) is fitted
with one shot left out, and the left-out shot's edges are corrected by that
fit and measured: the *holdout* ``d`` (the paper's protocol: a correction is
judged on shots it was not fitted on). The CV figure of a candidate is the
RMS of the holdout residuals pooled over all folds (:func:`cross_validate`, one
:class:`CVRow` per candidate). Candidates are compared by
the one-standard-error rule [2]_ on paired held-out differences
(:func:`paired_difference`): with
:math:`S_{c,e}` the sum of squared held-out residuals of candidate :math:`c`
on held-out edge :math:`e` (:math:`n_e` points, :math:`N` in all, the same
edges for every candidate), :math:`D_e = S_{c,e} - S_{b,e}` against the best
candidate :math:`b`,

.. math:: \Delta = \frac{1}{N}\sum_e D_e, \qquad
          \mathrm{SE} = \frac{1}{N}\sqrt{\sum_e (D_e - n_e\Delta)^2},

and :math:`c` is as good as :math:`b` when :math:`\Delta \le` ``n_se`` SE (the
held-out edges are the independent units; the points of one edge are not).

With fewer than three shots, a shot cannot be left out (the rest would have
one orientation), so the folds leave out every other string (pair of
adjacent edges, as :mod:`pipeline.measure` lists them) of every shot
instead (``folds='edges'``, :func:`cv_folds`); this checks over-fitting along the strings but
not generalisation to a new orientation. The choice made of the table is :mod:`pipeline.select`'s.

References
----------
.. [1] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012 (cross-validation, Sect. 5).
.. [2] T. Hastie, R. Tibshirani, J. Friedman, *The Elements of Statistical
   Learning*, 2nd ed., Sect. 7.10 (cross-validation, one-standard-error rule).
.. [3] T. G. Dietterich, "Approximate statistical tests for comparing supervised
   classification learning algorithms", Neural Computation 10(7), 1998 (paired
   comparisons of cross-validated errors).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.edgeset import EdgeSet, FitResult, collect, held_out_edges, held_out_residuals
from pipeline.fit import MIN_EDGES, fit_distortion
from pipeline.fit_problem import make_parametrisation, normal_equations, residuals_and_jacobian
from pipeline.fitspec import FULL_RADIAL, FitSpec
from pipeline.models.base import DistortionModel
from pipeline.plain import finite_or_none

DEFAULT_CANDIDATES: tuple[FitSpec, ...] = tuple(
    [FitSpec("radial", d, t, p) for d in (2, 4, 6) for (t, p) in ((False, False), (True, False), (True, True))]
    + [FitSpec("radial", d, True, p, True) for d in (4, 6) for p in (False, True)]
    + [FitSpec("radial", 2, t, p, division=1) for (t, p) in ((False, False), (True, False), (True, True))]
    + [FitSpec("radial", 4, True, True, division=1)]
    + [FitSpec("poly", d) for d in (3, 5, 7)]
)
"""Radial k up to rho^2, rho^4, rho^6, each plain / +tangential / +tangential+prism (degrees 4, 6 also with
a centre prior); the division (rational) radial factor with one denominator term over k up to rho^2 (plain,
+tangential, +tangential+prism) and rho^4 (+tangential+prism), for wide-angle lenses; poly 3, 5, 7. Not the
three-fold term (:class:`~pipeline.models.radial.RadialModel`'s ``trefoil``): with 6 shots of 20 seeded lenses
whose harp has its own bends it was chosen for lenses without one and made unseen shots worse
(``benchmarks/RESULTS-model-choice.md``); a spec or a candidate list can name it."""

FALLBACK = FULL_RADIAL
"""Choice when no cross-validation is possible: physically motivated, generalises across orientations."""


def n_params(spec: FitSpec, width: int, height: int) -> int:
    """Number of free parameters of a fit of ``spec``."""
    return make_parametrisation(width, height, spec).n


@dataclass(frozen=True)
class CVRow:
    """Cross-validation figures of one candidate (pixels)."""

    candidate: FitSpec
    n_params: int
    cv_d: float  # pooled holdout d (RMS over all held-out points of all folds); NaN if a fold failed
    fold_d: tuple[float, ...]  # holdout d of each fold
    fit_d: tuple[float, ...]  # fit d of each fold
    failure: str | None = None
    edge_ss: tuple[float, ...] = field(default=(), repr=False)  # per held-out edge (all folds): sum of r^2
    edge_n: tuple[int, ...] = field(default=(), repr=False)  # per held-out edge: number of points
    full_fit: FitResult | None = field(default=None, repr=False, compare=False)  # fit on all shots (warm start)
    cv_d_bound: float = float("nan")  # a stopped candidate: its CV d is at least this (px)
    # folds with the strings separated (pipeline.separated_cv): held-out edges whose string's bend was
    # removed, and edges left as they were (their string not fitted in the fold); None for other folds
    strings_removed: tuple[int, int] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.candidate.to_dict(),
            "n_params": self.n_params,
            "cv_d": finite_or_none(self.cv_d),
            "fold_d": [finite_or_none(v) for v in self.fold_d],
            "fit_d": [finite_or_none(v) for v in self.fit_d],
            "failure": self.failure,
            "cv_d_bound": finite_or_none(self.cv_d_bound),
            **({} if self.strings_removed is None else {"strings_removed": list(self.strings_removed)}),
        }


def cv_folds(
    lines_per_image: Sequence[Sequence[np.ndarray]], mode: str
) -> list[tuple[list[list[np.ndarray]], list[np.ndarray]]]:
    """The folds of a cross-validation: a list of (train lines_per_image, held-out list of lines).

    ``mode`` 'images': each shot held out in turn; 'edges': every other string (the
    pair of edges ``2k, 2k+1``, :mod:`pipeline.measure`'s order) of every shot, twice.
    """
    out: list[tuple[list[list[np.ndarray]], list[np.ndarray]]] = []
    if mode == "images":
        for h in range(len(lines_per_image)):
            out.append(([list(s) for i, s in enumerate(lines_per_image) if i != h], list(lines_per_image[h])))
    else:
        # edges 2k, 2k+1 are the two sides of one string (pipeline.measure's order): hold out
        # every other *string*, never one side of a string whose twin stays in the fit
        for parity in (0, 1):
            train = [[p for j, p in enumerate(s) if (j // 2) % 2 != parity] for s in lines_per_image]
            held = [p for s in lines_per_image for j, p in enumerate(s) if (j // 2) % 2 == parity]
            out.append((train, held))
    return out


STOP_FACTOR = 4.0
"""A candidate is stopped once the held-out squared residuals of its folds so far exceed this many times
the whole CV mean square of the best candidate completed (its CV d would be at least twice as large)."""


def fold_mode(folds: str, n_shots: int) -> str:
    """The folds ``folds`` means for ``n_shots`` shots: 'auto' is 'images' (leave one shot out) with 3
    shots or more, else 'edges' (alternate strings); 'images' and 'edges' are themselves."""
    if folds == "auto":
        return "images" if n_shots >= 3 else "edges"
    return folds


def cross_validate(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    candidates: Sequence[FitSpec] = DEFAULT_CANDIDATES,
    folds: str = "auto",
    *,
    warm_start: bool = True,
    stop_factor: float | None = STOP_FACTOR,
    map_fn: Callable[..., Iterable[CVRow]] = map,
    full_fits: Mapping[FitSpec, FitResult] | None = None,
    **fit_kw: Any,
) -> tuple[tuple[CVRow, ...], str]:
    """CV table of the candidates; ``folds`` 'images' (leave one shot out), 'edges' or 'auto'.

    ``warm_start``: each candidate is first fitted on all shots (the robust procedure of
    :func:`pipeline.fit.fit_distortion`); every fold then starts from that fit, leaves out the
    edges it rejected as outliers and minimises the final least-squares pass's objective by
    Gauss-Newton steps until a step gains less than ``GN_RTOL`` of the cost (the folds differ
    from the full fit by one shot: 2-4 steps reach what a fit from scratch would, the held-out
    figures agree to 1e-5; a fold that does not converge so runs the final pass itself).
    Without it every fold is fitted from scratch. The fit on all shots
    of every candidate is kept (:attr:`CVRow.full_fit`); a candidate whose fit on all shots fails (a
    correction that folds over inside the image, say) fails with that reason and is not cross-validated:
    its folds could pass, but there would be no correction to store.
    ``stop_factor``: :data:`FALLBACK` (a good model on most lenses), or else the first
    candidate, is cross-validated first and is the reference; any other candidate is stopped,
    and reported with the reason and a lower bound of its CV d, once it cannot be chosen: when
    its fit on all shots already leaves a mean square above ``stop_factor`` times the
    reference's CV mean square (held-out residuals are larger than a fit's own), or when the
    held-out squared residuals of its folds so far exceed that; ``None``: never.
    ``map_fn``: a ``map`` over the candidates (a process pool's; the table keeps the candidates'
    order and does not depend on it), called twice: the reference's row with the others' fits on all
    shots, then the others' folds. ``full_fits``: fits on all shots already made (with the same
    ``fit_kw``; e.g. the leave-one-shot-out table's, for the alternate-string one), not made again.
    """
    folds = fold_mode(folds, len(lines_per_image))
    lines = [list(s) for s in lines_per_image]
    first = FALLBACK if FALLBACK in candidates else candidates[0]
    settings = (width, height, folds, warm_start, stop_factor, fit_kw)
    others = [c for c in candidates if c != first]
    # the largest candidates first (the costliest: a pool's workers then finish about together);
    # each row depends on its candidate and the reference only, not on the order
    order = sorted(others, key=lambda c: -n_params(c, width, height))
    # first the reference's whole row and, meanwhile, the other candidates' fits on all shots (they do
    # not need the reference); then the other candidates' folds, which the reference may stop
    known = dict(full_fits or {}) if warm_start else {}
    todo = [c for c in [first, *order] if c == first or c not in known]
    made = dict(zip(todo, map_fn(_first_pass, [(c, lines, settings, c == first, known.get(c)) for c in todo])))
    ref = made[first]
    first_pass = [ref, *(known[c] if c in known else made[c] for c in order)]
    ref_mse = ref.cv_d**2 if np.isfinite(ref.cv_d) else float("inf")
    jobs = [(c, lines, ref_mse, settings, full) for c, full in zip(order, first_pass[1:], strict=True)]
    done = dict(zip(order, map_fn(_cv_candidate, jobs)))
    done[first] = ref
    return tuple(done[c] for c in candidates), folds


def _first_pass(job: tuple[FitSpec, list[list[np.ndarray]], tuple[Any, ...], bool, FitResult | None]) -> Any:
    """The reference's :class:`CVRow` (from its fit on all shots when given), or another candidate's
    fit on all shots (None without warm starts); a picklable job for a pool (:func:`cross_validate`)."""
    cand, lines_per_image, settings, is_reference, known = job
    if is_reference:
        if known is not None:
            return _cv_candidate((cand, lines_per_image, float("inf"), settings, known))
        return _cv_candidate((cand, lines_per_image, float("inf"), settings))
    width, height, _, warm_start, _, fit_kw = settings
    return fit_distortion(lines_per_image, width, height, **cand.fit_arguments(), **fit_kw) if warm_start else None


def _cv_candidate(job: tuple[Any, ...]) -> CVRow:
    """The :class:`CVRow` of one candidate (see :func:`cross_validate`); a picklable job for a pool:
    ``(candidate, lines, reference CV mean square, settings)``, and its fit on all shots when it is
    already done (:func:`_first_pass`)."""
    cand, lines_per_image, ref_mse, (width, height, folds, warm_start, stop_factor, fit_kw) = job[:4]
    fl = cv_folds(lines_per_image, folds)
    n_held = float(sum(int(_held_out_counts(held).sum()) for _, held in fl))
    fold_d: list[float] = []
    fit_d: list[float] = []
    res_all: list[np.ndarray] = []
    ss_all: list[np.ndarray] = []
    n_all: list[np.ndarray] = []
    failure: str | None = None
    if len(job) > 4:
        full = job[4]
    else:
        full = fit_distortion(lines_per_image, width, height, **cand.fit_arguments(), **fit_kw) if warm_start else None
    if full is not None and not full:  # no correction from all the shots: nothing to choose, whatever the folds say
        return CVRow(cand, n_params(cand, width, height), float("nan"), (), (), f"its fit on all shots: {full.reason}")
    outliers: set[int] = set()
    if full:
        outliers = {id(lines_per_image[e.image][e.line]) for e in full.rejected if e.reason.startswith("outlier")}
    ss_so_far = 0.0
    bound = float("nan")
    stopping = stop_factor is not None and np.isfinite(ref_mse)
    todo = fl
    if full and stopping and full.d_after**2 > stop_factor * ref_mse:
        bound = float(full.d_after)
        failure = (
            f"stopped before the folds: its fit on all shots already leaves d {full.d_after:.4g} px, "
            f">= {np.sqrt(stop_factor):g}x the CV d {np.sqrt(ref_mse):.4g} px of {FALLBACK.label}"
        )
        todo = []
    start: _FoldStart | None = None
    if full and todo:
        start = _FoldStart(cand, lines_per_image, outliers, folds, width, height, full.model, fit_kw)
    for k, (train, held) in enumerate(todo):
        model: DistortionModel | None = None
        fd = float("nan")
        if full:
            kept = [[p for p in shot if id(p) not in outliers] for shot in train]
            step = _gauss_newton_fold(
                cand, kept, width, height, full.model, fit_kw, *(start.fold(k) if start else (None, None))
            )
            if step is not None:
                model, fd = step
            else:  # Gauss-Newton did not converge: the final least-squares pass from the full fit
                r = fit_distortion(
                    kept, width, height, **cand.fit_arguments(), init=full.model, **{**fit_kw, "robust": False}
                )
                if not r:
                    failure = r.reason
                else:
                    model, fd = r.model, r.d_after
        else:
            r = fit_distortion(train, width, height, **cand.fit_arguments(), **fit_kw)
            if not r:
                failure = r.reason
            else:
                model, fd = r.model, r.d_after
        if model is None:
            fold_d.append(float("nan"))
            fit_d.append(float("nan"))
            continue
        res = held_out_residuals(model, held)
        res_all.append(res)
        counts = _held_out_counts(held)
        if len(res):
            starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
            ss_all.append(np.add.reduceat(res**2, starts))
            n_all.append(counts)
        fold_d.append(float(np.sqrt(np.mean(res**2))) if len(res) else float("nan"))
        fit_d.append(fd)
        ss_so_far += float(np.sum(res**2))
        if stopping and k + 1 < len(fl) and ss_so_far / n_held > stop_factor * ref_mse:
            bound = float(np.sqrt(ss_so_far / n_held))
            failure = (
                f"stopped after {k + 1} of {len(fl)} folds: held-out d already >= {bound:.4g} px, "
                f"{np.sqrt(stop_factor):g}x the CV d {np.sqrt(ref_mse):.4g} px of {FALLBACK.label}"
            )
            break
    cv = float(np.sqrt(np.mean(np.concatenate(res_all) ** 2))) if res_all and failure is None else float("nan")
    ss = tuple(float(v) for v in np.concatenate(ss_all)) if ss_all and failure is None else ()
    nn = tuple(int(v) for v in np.concatenate(n_all)) if n_all and failure is None else ()
    return CVRow(
        cand,
        n_params(cand, width, height),
        cv,
        tuple(fold_d),
        tuple(fit_d),
        failure,
        ss,
        nn,
        full if full else None,
        bound,
    )


GN_MAX_STEPS = 8
"""Most Gauss-Newton steps of a warm-started fold (it converges in 2-4 from the fit on all shots)."""
GN_RTOL = 1e-10
"""A fold has converged when a step lowers its cost by less than this fraction."""


class _FoldStart:
    """The first Gauss-Newton step of every leave-one-shot-out fold, from one evaluation.

    Every fold starts from the fit on all shots, ``theta0``, and its training edges are all kept
    edges but one shot's; the edges' terms of the normal equations are independent, so they are
    computed once per shot at ``theta0`` (:func:`pipeline.fit_problem.normal_equations`) and each fold's
    first step sums the other shots' (``folds='images'`` only; otherwise :meth:`fold` is None)."""

    def __init__(
        self,
        cand: FitSpec,
        lines_per_image: Sequence[Sequence[np.ndarray]],
        outliers: set[int],
        folds: str,
        width: int,
        height: int,
        start: DistortionModel,
        fit_kw: dict[str, Any],
    ) -> None:
        self.blocks: dict[int, tuple[np.ndarray, np.ndarray, float]] | None = None
        if folds != "images":
            return
        kept = [[p for p in shot if id(p) not in outliers] for shot in lines_per_image]
        edges, _ = collect(kept, width, height)
        if not edges:
            return
        param = make_parametrisation(width, height, cand, w_center=fit_kw.get("w_center"), ridge=fit_kw.get("ridge"))
        self.theta0 = param.theta0(start)
        first = np.flatnonzero(np.diff(edges.image, prepend=-1))  # edges are listed shot by shot
        with np.errstate(all="ignore"):
            ata, atb, ss = normal_equations(param, edges, self.theta0, [int(e) for e in first])
        if not (np.all(np.isfinite(ata)) and np.all(np.isfinite(atb))):
            return
        self.blocks = {int(edges.image[e]): (ata[g], atb[g], float(ss[g])) for g, e in enumerate(first)}
        self.edges = edges

    def fold(self, held: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, float] | None, EdgeSet | None]:
        """``(theta0, sum J^T J, sum J^T r, sum r^2)`` over the shots but ``held`` (no regularisation),
        and the fold's edge set (the full fit's kept edges but shot ``held``'s)."""
        if self.blocks is None:
            return None, None
        parts = [v for k, v in self.blocks.items() if k != held]
        keep = self.edges.image != held
        if not parts or not keep.any():
            return None, None
        first = (
            self.theta0,
            np.sum([p[0] for p in parts], axis=0),
            np.sum([p[1] for p in parts], axis=0),
            float(sum(p[2] for p in parts)),
        )
        return first, self.edges.subset(keep)


def _gauss_newton_fold(
    cand: FitSpec,
    kept: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    start: DistortionModel,
    fit_kw: dict[str, Any],
    first: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None,
    fold_edges: EdgeSet | None = None,
) -> tuple[DistortionModel, float] | None:
    """The least-squares fit of ``kept`` (the fold's training edges, the full fit's outliers left out)
    by Gauss-Newton steps from ``start`` (the fit on all shots), the objective of
    :func:`pipeline.fit.fit_distortion`'s final pass: ``(model, its d)``, or None when a step does
    not lower the cost or it has not converged (the caller then runs that pass itself).

    Each step solves the normal equations (:func:`pipeline.fit_problem.normal_equations`); a trial point
    is first evaluated without its Jacobian (the last one, converged, needs none); ``first``: the
    normal equations at the start, already summed, and ``fold_edges`` the edge set of ``kept``
    (:class:`_FoldStart`)."""
    edges = collect(kept, width, height)[0] if fold_edges is None else fold_edges
    if not edges or edges.n_edges < MIN_EDGES:
        return None
    param = make_parametrisation(width, height, cand, w_center=fit_kw.get("w_center"), ridge=fit_kw.get("ridge"))
    n_pts = len(edges.xy)

    def regularised(t: np.ndarray, ata: np.ndarray, atb: np.ndarray, ss: float) -> tuple[np.ndarray, np.ndarray, float]:
        g, jg = param.regularisation(t, n_pts)
        return ata + jg.T @ jg, atb + jg.T @ g, ss + float(g @ g)

    def equations(t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        ata, atb, _ = normal_equations(param, edges, t)
        a, b, _ = regularised(t, ata[0], atb[0], 0.0)
        return (a, b) if np.all(np.isfinite(a)) and np.all(np.isfinite(b)) else None

    if first is not None:
        th = first[0]
        a, b, cost = regularised(th, first[1], first[2], first[3])
    else:
        th = param.theta0(start)
        r0, _ = residuals_and_jacobian(param, edges, th, jac=False)
        eq = equations(th)
        if eq is None or not np.all(np.isfinite(r0)):
            return None
        g0, _ = param.regularisation(th, n_pts)
        (a, b), cost = eq, float(r0 @ r0 + g0 @ g0)
    for _ in range(GN_MAX_STEPS):
        try:
            th_new = th - np.linalg.solve(a, b)
        except np.linalg.LinAlgError:
            return None
        r, _ = residuals_and_jacobian(param, edges, th_new, jac=False)
        g, _ = param.regularisation(th_new, n_pts)
        if not np.all(np.isfinite(r)):
            return None
        new_cost = float(r @ r + g @ g)
        if not np.isfinite(new_cost) or new_cost > cost * (1.0 + 1e-12):
            return None
        if cost - new_cost <= GN_RTOL * cost:
            return param.model(th_new), float(np.sqrt(np.mean(r**2)))
        eq = equations(th_new)
        if eq is None:
            return None
        (a, b), th, cost = eq, th_new, new_cost
    return None


def _held_out_counts(held: Sequence[np.ndarray]) -> np.ndarray:
    """Points of each held-out edge that :func:`pipeline.edgeset.held_out_residuals` keeps
    (:func:`pipeline.edgeset.held_out_edges`)."""
    return np.array([len(p) for p in held_out_edges(held)], dtype=np.int64)


def paired_difference(row: CVRow, best: CVRow) -> tuple[float, float]:
    """``(Delta, SE)`` of the CV mean squared residual of ``row`` minus ``best``'s, paired over the
    held-out edges (module docstring); ``(nan, nan)`` when their held-out edges differ."""
    a, b = np.asarray(row.edge_ss), np.asarray(best.edge_ss)
    n = np.asarray(row.edge_n)
    if a.shape != b.shape or not a.size or row.edge_n != best.edge_n:
        return float("nan"), float("nan")
    total = float(n.sum())
    dd = a - b
    delta = float(dd.sum()) / total
    se = float(np.sqrt(np.sum((dd - n * delta) ** 2))) / total
    return delta, se
