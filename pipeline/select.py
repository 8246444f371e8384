"""Choose the distortion model and degree by cross-validation over shots.

Each candidate (a :class:`pipeline.fitspec.FitSpec`: model kind, degree,
tangential / thin-prism terms, centre prior) is fitted
with one shot left out, and the left-out shot's edges are corrected by that
fit and measured: the *holdout* ``d`` (the paper's protocol: a correction is
judged on shots it was not fitted on). The CV figure of a candidate is the
RMS of the holdout residuals pooled over all folds. The choice is the
simplest candidate (fewest parameters) whose CV ``d`` is within
``rel_tol`` / ``abs_tol`` of the best: a richer model must earn its
parameters on unseen shots.

With fewer than three shots, a shot cannot be left out (the rest would have
one orientation), so the folds leave out every other string (pair of
adjacent edges, as :mod:`pipeline.measure` lists them) of every shot
instead (``folds='edges'``); this checks over-fitting along the strings but
not generalisation to a new orientation, and the selection says so.

References
----------
.. [1] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012 (cross-validation, Sect. 5).
.. [2] T. Hastie, R. Tibshirani, J. Friedman, *The Elements of Statistical
   Learning*, 2nd ed., Sect. 7.10 (cross-validation, one-standard-error rule).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.edgeset import held_out_residuals
from pipeline.fit import fit_distortion, make_parametrisation
from pipeline.fitspec import FitSpec

DEFAULT_CANDIDATES: tuple[FitSpec, ...] = tuple(
    [FitSpec("radial", d, t, p) for d in (2, 4, 6) for (t, p) in ((False, False), (True, False), (True, True))]
    + [FitSpec("radial", d, True, p, True) for d in (4, 6) for p in (False, True)]
    + [FitSpec("poly", d) for d in (3, 5, 7)]
)
"""Radial k up to rho^2, rho^4, rho^6, each plain / +tangential / +tangential+prism (degrees 4, 6 also with
a centre prior); poly 3, 5, 7."""

FALLBACK = FitSpec("radial", 4, True, True)
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

    def to_dict(self) -> dict[str, Any]:
        def num(v: float) -> float | None:
            return None if not np.isfinite(v) else float(v)

        return {
            **self.candidate.to_dict(),
            "n_params": self.n_params,
            "cv_d": num(self.cv_d),
            "fold_d": [num(v) for v in self.fold_d],
            "fit_d": [num(v) for v in self.fit_d],
            "failure": self.failure,
        }


@dataclass(frozen=True)
class Selection:
    """The chosen candidate, why, and the whole CV table."""

    choice: FitSpec
    reason: str
    folds: str  # 'images' or 'edges' or 'none'
    table: tuple[CVRow, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.choice.to_dict(),
            "reason": self.reason,
            "folds": self.folds,
            "table": [r.to_dict() for r in self.table],
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


def cross_validate(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    candidates: Sequence[FitSpec] = DEFAULT_CANDIDATES,
    folds: str = "auto",
    **fit_kw: Any,
) -> tuple[tuple[CVRow, ...], str]:
    """CV table of the candidates; ``folds`` 'images' (leave one shot out), 'edges' or 'auto'."""
    if folds == "auto":
        folds = "images" if len(lines_per_image) >= 3 else "edges"
    fl = cv_folds(lines_per_image, folds)
    rows = []
    for cand in candidates:
        fold_d: list[float] = []
        fit_d: list[float] = []
        res_all: list[np.ndarray] = []
        failure: str | None = None
        for train, held in fl:
            r = fit_distortion(train, width, height, **cand.fit_arguments(), **fit_kw)
            if not r:
                failure = r.reason
                fold_d.append(float("nan"))
                fit_d.append(float("nan"))
                continue
            res = held_out_residuals(r.model, held)
            res_all.append(res)
            fold_d.append(float(np.sqrt(np.mean(res**2))) if len(res) else float("nan"))
            fit_d.append(r.d_after)
        cv = float(np.sqrt(np.mean(np.concatenate(res_all) ** 2))) if res_all and failure is None else float("nan")
        rows.append(CVRow(cand, n_params(cand, width, height), cv, tuple(fold_d), tuple(fit_d), failure))
    return tuple(rows), folds


def select_model(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    candidates: Sequence[FitSpec] = DEFAULT_CANDIDATES,
    rel_tol: float = 0.05,
    abs_tol: float = 0.001,
    folds: str = "auto",
    **fit_kw: Any,
) -> Selection:
    """Choose model and degree by cross-validation over the shots.

    Parameters
    ----------
    lines_per_image : edge point sets of each shot (as for :func:`pipeline.fit.fit_distortion`).
    candidates : configurations to compare (default :data:`DEFAULT_CANDIDATES`).
    rel_tol, abs_tol : a candidate is "as good as the best" if its CV d is
        ``<= best * (1 + rel_tol) + abs_tol``; the one with fewest parameters
        among those is chosen (ties: lower CV d).
    folds : 'auto' (shots if >= 3, else edges), 'images' or 'edges'.

    Returns
    -------
    Selection
        ``choice`` with a one-line ``reason`` and the full ``table``. If every
        candidate fails in some fold, the choice is :data:`FALLBACK` and the
        reason says so.
    """
    table, mode = cross_validate(lines_per_image, width, height, candidates, folds, **fit_kw)
    ok = [r for r in table if np.isfinite(r.cv_d)]
    if not ok:
        reasons = sorted({r.failure for r in table if r.failure})
        return Selection(
            FALLBACK,
            f"no candidate could be cross-validated ({'; '.join(reasons)[:200]}); using the default {FALLBACK.label}",
            "none",
            table,
        )
    best = min(r.cv_d for r in ok)
    good = [r for r in ok if r.cv_d <= best * (1 + rel_tol) + abs_tol]
    pick = min(good, key=lambda r: (r.n_params, r.cv_d))  # ties in size: the lower CV d
    what = "leave-one-shot-out" if mode == "images" else "alternate-edge (shots too few to leave one out)"
    reason = (
        f"{pick.candidate.label}: {what} CV d {pick.cv_d:.4f} px, fewest parameters ({pick.n_params}) "
        f"within {rel_tol:.0%} + {abs_tol:g} px of the best CV d {best:.4f} px"
    )
    return Selection(pick.candidate, reason, mode, table)
