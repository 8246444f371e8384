r"""Choose the distortion model and degree by cross-validation over shots.

The candidates' CV table (holdout ``d`` of each, paired differences over the held-out edges,
one-standard-error rule [2]_) is :mod:`pipeline.cross_validation`'s; whether the shots cover enough
string orientations for a candidate is :mod:`pipeline.orientations`'. A richer model must earn its
parameters on unseen data, and a simpler one is
not taken when it is measurably worse: a relative tolerance on the CV ``d``
would hide a real model error under the measurement's noise floor (on a
wide-angle lens with thin strings, radial k up to rho^4 is 6 % above the
floor, 6.7 SE, and off by 0.45 px in the corners).

The choice has two tiers (:func:`select_model`). Leave-one-shot-out folds fit
one orientation fewer than the final model has, and with three to six shots
that is what decides them: the decentering terms and a free centre are poorly
determined by two or three orientations, so the shots' own systematic errors
(string bends, each orientation's measurement bias) move them far in the folds,
and a model without them, or with a centre prior, wins the folds and loses on
new shots once every orientation is in the fit. So leave-one-shot-out only sets
aside what fails on an unseen orientation (:data:`ORIENTATION_TOLERANCE`), and
the choice among the rest is cross-validated on alternate strings of every shot,
each fit with every orientation: the lowest CV d there, without the
one-standard-error rule's preference for fewer parameters
(:data:`TIER2_RULE`).

With fewer than three shots the folds leave out every other string of every shot
(``folds='edges'``); this checks over-fitting along the strings but
not generalisation to a new orientation, and the selection says so.

References
----------
.. [1] Z. Tang et al., "High-precision camera distortion measurements with a
   calibration harp", JOSA A 29(10), 2012 (cross-validation, Sect. 5).
.. [2] T. Hastie, R. Tibshirani, J. Friedman, *The Elements of Statistical
   Learning*, 2nd ed., Sect. 7.10 (cross-validation, one-standard-error rule).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pipeline.cross_validation import (
    DEFAULT_CANDIDATES,
    FALLBACK,
    STOP_FACTOR,
    CVRow,
    cross_validate,
    fold_mode,
    paired_difference,
)
from pipeline.fitspec import FitSpec
from pipeline.orientations import (
    distinct_orientations,
    orientation_shortfall,
    required_orientations,
    shot_orientation,
    support_problem,
)
from pipeline.separated_cv import MIN_FOLD_ORIENTATIONS, cross_validate_separated


@dataclass(frozen=True)
class Selection:
    """The chosen candidate, why, and the whole CV table."""

    choice: FitSpec
    reason: str
    folds: str  # 'images' or 'edges' or 'none'
    table: tuple[CVRow, ...] = field(default=())
    strings_table: tuple[CVRow, ...] = field(default=())  # tier 2: alternate strings, every orientation in the fit
    support: str | None = None  # why the shots do not support the choice well (too few orientations), or None

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.choice.to_dict(),
            "reason": self.reason,
            "folds": self.folds,
            "table": [r.to_dict() for r in self.table],
            "strings_table": [r.to_dict() for r in self.strings_table],
            "support": self.support,
        }


FLEXIBLE_MARGIN_SE = 2.0
"""Tier 1's bar for a flexible candidate (:func:`is_flexible`): it is the choice only when it is ahead of
the best radial candidate by more than this many paired standard errors in the leave-one-shot-out folds.
The flexible candidates are few but have 3-5 times the parameters, and the best of several compared on
the same few folds is ahead by chance more often than the one-standard-error rule assumes (the winner's
curse of choosing among candidates by the same CV figure [2]_ Sect. 7.10.2): a lens whose distortion is
radial had a degree-7 polynomial win six shots' folds by 1.6 SE and lose by 65 % on unseen shots
(``benchmarks/model_choice.py``). Two standard errors is a one-sided test at about 2 %; a lens with real
non-radial structure is ahead by far more (``tests/pipeline/test_select.py``)."""

ORIENTATION_TOLERANCE = 0.5
"""Tier 1 of the choice (:func:`select_model`): a candidate *generalises to an unseen orientation* when
its leave-one-shot-out CV d is at most this fraction above the best's (or within ``n_se`` paired
standard errors). This tier only sets aside the candidates that fail on a new orientation (a free
polynomial on three shots: 10-100x the best), not the choice itself: the folds fit one orientation
fewer than the final model has, and with two or three orientations the decentering terms and a free
centre are so poorly determined that systematic errors of each shot (string bends, an orientation's
own measurement bias) move them far; a model without them, or with a centre prior, then wins the
folds (by 15-35 % in the team's simulations, 3 % on the real photographs) and loses on new shots
with every orientation in the fit. Tolerances from 0.5 to 2 gave the same choices in those simulations
(``benchmarks/model_choice.py``), 0.05 kept the wrong ones."""


TIER2_RULE = "the lowest CV d"
"""How the choice is made among the candidates that generalise to an unseen orientation (tier 2 of
:func:`select_model`, alternate strings with every orientation in the fit) and among the folds with the strings
separated: the candidate with the lowest CV d, not the fewest parameters within one standard error. With
thousands of points per shot the extra terms of a richer radial model cost almost nothing in variance, while
the error of a model too simple is a smooth field that straightness residuals hardly see: the one-standard-error
rule then took radial2 where the lens needed more (a realistic tele lens: field error 0.0284 px against 0.0059).
On 60 realistic lenses (``benchmarks/choice_realistic.py``, what a session stores, field error against the exact
lens) the rule took 43 to 49 of 60 to 0.005 px or below (median 0.0040 -> 0.0025 px), and the folds with the
strings separated 47 to 51; on the point-set population (``benchmarks/choice_rules.py``) the field error's mean
ratio to the best candidate went 1.089 / 1.073 / 1.102 / 1.148 -> 1.097 / 1.054 / 1.065 / 1.145 (4 and 6 shots,
two seed sets) and the held-out d on unseen shots stayed within +-0.004. Parsimony still decides where the
orientation is not checked (fewer than three shots: alternate strings only, where a free polynomial could win)
and in tier 1."""


def _within(rows: Sequence[CVRow], best: CVRow, n_se: float, tolerance: float) -> list[CVRow]:
    """The rows as good as ``best``: paired difference within ``n_se`` SE, or CV d within ``tolerance``."""
    out = []
    for r in rows:
        delta, se = paired_difference(r, best)
        if (
            r is best
            or (np.isfinite(delta) and delta <= n_se * se)
            or (tolerance > 0 and r.cv_d <= (1.0 + tolerance) * best.cv_d)
        ):
            out.append(r)
    return out


def _with_free_twins(general: Sequence[CVRow], rows: Sequence[CVRow]) -> list[CVRow]:
    """``general`` and, for each candidate with a centre prior in it, its twin with a free centre (from ``rows``,
    cross-validated): a centre prior wins leave-one-shot-out folds because they fit one orientation fewer than
    the final model (with three shots, two, which leave a free centre nearly undetermined), not because the
    lens's centre is where the prior pulls it. Whether the twins generalise is the same question; tier 2,
    every orientation in the fit, decides between them."""
    out = list(general)
    have = {r.candidate for r in general}
    for r in rows:
        if r.candidate not in have and not r.candidate.center_prior and _prior_twin(r.candidate) in have:
            out.append(r)
    return out


def _prior_twin(spec: FitSpec) -> FitSpec:
    return replace(spec, center_prior=True)


def _fewest_within(rows: Sequence[CVRow], best: CVRow, n_se: float) -> CVRow:
    """The one-standard-error rule: of the rows within ``n_se`` paired standard errors of ``best``
    (:func:`_within`), the one with fewest parameters (ties in size: the lower CV d)."""
    return min(_within(rows, best, n_se, 0.0), key=lambda r: (r.n_params, r.cv_d))


def lowest_radial(rows: Iterable[CVRow]) -> CVRow | None:
    """The row of ``rows`` with the lowest CV d among the cross-validated radial (not :func:`is_flexible`)
    candidates, or None: what a flexible candidate is measured against, and what carries a field in place of a free
    polynomial (:func:`select_field`'s ``radial``)."""
    radial = [r for r in rows if np.isfinite(r.cv_d) and not is_flexible(r.candidate)]
    return min(radial, key=lambda r: r.cv_d) if radial else None


def _separates_strings(turntable_deg: Sequence[float] | None, n_shots: int, folds: str = "auto") -> bool:
    """Whether :func:`select_model`'s folds of ``n_shots`` shots at ``turntable_deg`` are fitted with the strings
    separated: leave-one-shot-out folds whose every fold keeps :data:`MIN_FOLD_ORIENTATIONS` turntable orientations."""
    return (
        turntable_deg is not None
        and fold_mode(folds, n_shots) == "images"
        and _fewest_fold_orientations(turntable_deg) >= MIN_FOLD_ORIENTATIONS
    )


def _fewest_fold_orientations(angles: Sequence[float]) -> int:
    """The fewest distinct orientations (:func:`distinct_orientations`) any leave-one-shot-out fold of shots at
    ``angles`` keeps."""
    return min(distinct_orientations(a for j, a in enumerate(angles) if j != h) for h in range(len(angles)))


def _nothing_cross_validated(table: Sequence[CVRow], how: str = "") -> Selection:
    """The :data:`FALLBACK` choice when no candidate of ``table`` could be cross-validated (``how``: the
    folds' kind, for the reason)."""
    reasons = sorted({r.failure for r in table if r.failure})
    return Selection(
        FALLBACK,
        f"no candidate could be cross-validated{how} ({'; '.join(reasons)[:200]}); using the default {FALLBACK.label}",
        "none",
        tuple(table),
    )


def select_model(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    candidates: Sequence[FitSpec] = DEFAULT_CANDIDATES,
    n_se: float = 1.0,
    folds: str = "auto",
    *,
    orientation_tolerance: float = ORIENTATION_TOLERANCE,
    flexible_margin_se: float = FLEXIBLE_MARGIN_SE,
    warm_start: bool = True,
    stop_factor: float | None = STOP_FACTOR,
    map_fn: Callable[..., Iterable[CVRow]] = map,
    turntable_deg: Sequence[float] | None = None,
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
    kink_t: int | None = None,
    **fit_kw: Any,
) -> Selection:
    r"""Choose model and degree by cross-validation over the shots.

    With three shots or more (``folds`` 'images') the choice has two tiers:

    1. **Orientations.** Each candidate is fitted with one shot left out and measured on it
       (:func:`cross_validate`). When the candidate with fewest parameters within ``n_se`` paired
       standard errors (:func:`paired_difference`) of the best is a flexible one (:func:`is_flexible`:
       a free polynomial) ahead of the best radial candidate by more than ``flexible_margin_se``
       (:data:`FLEXIBLE_MARGIN_SE`) paired standard errors, it is the choice: only unseen
       orientations can judge a model that bends to the orientations it is fitted on. Otherwise the radial candidates that generalise to an
       unseen orientation are those within ``n_se`` paired standard errors or within
       ``orientation_tolerance`` (:data:`ORIENTATION_TOLERANCE`) of the best radial CV d, and the
       free-centre twin of each centre-prior candidate among them: the folds' fewer orientations favour the
       prior, so tier 2 decides between the twins (on the point-set population with three shots, seed 2 of
       ``benchmarks/model_choice.py``: the prior won the folds by 57 % and lost on twelve unseen shots by 19 %).
    2. **Strings, with every orientation in the fit.** Those candidates are cross-validated again
       with alternate strings of every shot held out (``folds='edges'``), so that each fit has every
       orientation the final model has; the choice is the candidate with the lowest CV d there
       (:data:`TIER2_RULE`: not the fewest parameters within ``n_se`` standard errors). Leave-one-shot-out
       folds fit one orientation fewer than the final model: with three shots, two orientations,
       which leave a free centre and the decentering terms nearly undetermined and so favour a
       centre prior that, with every orientation, only bends the fit (on the real photographs the
       prior raises the alternate-string CV d from 0.0245 to 0.028 px and loses on unseen shots).

    With fewer shots only tier 2 is possible (the orientation is not checked), and the reason says
    so, as it says when the shots have fewer distinct orientations than the choice needs
    (:func:`support_problem`, also in :attr:`Selection.support`).

    **With the turntable angles** (``turntable_deg``, three shots or more, ``folds`` 'auto' or 'images')
    the folds are leave-one-shot-out with the strings separated instead
    (:func:`pipeline.separated_cv.cross_validate_separated`): each candidate fitted jointly with every
    string's own bend on the other shots, and judged on the held-out shot with those bends removed, so
    that the folds compare the lenses and not the strings. The choice is then one tier: the candidate
    with the lowest CV d (:data:`TIER2_RULE`); a flexible one only when it is ahead of the best radial
    candidate by more than ``flexible_margin_se`` paired standard errors (otherwise the best radial
    candidate). ``folds`` of the selection is
    :data:`SEPARATED_FOLDS`. Each fold must keep :data:`pipeline.separated_cv.MIN_FOLD_ORIENTATIONS`
    distinct turntable orientations (with two, a string's bend and the lens's terms trade); with fewer
    the folds are the plain ones and the reason says that the strings were not separated.

    Parameters
    ----------
    lines_per_image : edge point sets of each shot (as for :func:`pipeline.fit.fit_distortion`).
    candidates : configurations to compare (default :data:`DEFAULT_CANDIDATES`).
    n_se : standard errors of the one-standard-error rule, paired over the held-out edges (tier 1, and the
        choice on alternate strings alone with fewer than three shots).
    folds : 'auto' (shots if >= 3, else edges), 'images' or 'edges' (tier 2 only).
    orientation_tolerance : tier 1's relative tolerance on the leave-one-shot-out CV d.
    flexible_margin_se : tier 1's bar for a flexible candidate, in paired standard errors.
    warm_start, stop_factor, map_fn : see :func:`cross_validate`.
    turntable_deg : each shot's turntable angle (degrees), when known: the folds with the strings separated.
    axis_groups, axis_shifts : with ``turntable_deg``, each shot's turntable-axis group and the groups' rough
        image shifts (px) when the harp was moved with its turntable between groups of shots
        (:func:`pipeline.harp_shape.fit_harp_shape`); only the folds with the strings separated use them.
    kink_t : with ``turntable_deg``, the along-edge subsampling factor the points were measured with when the
        folds are to find and model every string's kinks as well, as the session's lens is fitted
        (``pipeline.strings: separate-kinks``; :func:`pipeline.separated_cv.cross_validate_separated`); None:
        the strings' smooth bends only. The plain folds do not use it.

    Returns
    -------
    Selection
        ``choice`` with a one-line ``reason``, the leave-one-shot-out ``table`` and the
        alternate-string ``strings_table``. If every candidate fails in some fold, the choice is
        :data:`FALLBACK` and the reason says so.
    """
    mode_now = fold_mode(folds, len(lines_per_image))
    if turntable_deg is not None and len(turntable_deg) != len(lines_per_image):
        raise ValueError(f"{len(lines_per_image)} shots but {len(turntable_deg)} turntable angles")
    unseparated = ""
    if _separates_strings(turntable_deg, len(lines_per_image), folds):
        assert turntable_deg is not None
        return _select_separated(
            lines_per_image, turntable_deg, width, height, candidates, flexible_margin_se,
            stop_factor=stop_factor, map_fn=map_fn, axis_groups=axis_groups, axis_shifts=axis_shifts, kink_t=kink_t,
            **fit_kw,
        )  # fmt: skip
    if turntable_deg is not None and mode_now == "images":
        fewest = _fewest_fold_orientations(turntable_deg)
        unseparated = (
            f"; turntable angles known, but a fold would have {fewest} turntable orientation"
            f"{'s' if fewest != 1 else ''} (separating the strings needs >= {MIN_FOLD_ORIENTATIONS}): "
            "strings not separated in the folds"
        )
    candidates, set_aside = _supported_when_unchecked(candidates, lines_per_image, mode_now)
    candidates, trefoil_aside = _trefoil_when_determined(candidates, lines_per_image, mode_now)
    set_aside += trefoil_aside
    notes = trefoil_aside + unseparated  # what the reasons of leave-one-shot-out choices end with
    table, mode = cross_validate(
        lines_per_image,
        width,
        height,
        candidates,
        folds,
        warm_start=warm_start,
        stop_factor=stop_factor,
        map_fn=map_fn,
        **fit_kw,
    )
    ok = [r for r in table if np.isfinite(r.cv_d)]
    if not ok:
        return _nothing_cross_validated(table)
    se_text = "one standard error" if n_se == 1.0 else f"{n_se:g} standard errors"
    best_row = min(ok, key=lambda r: r.cv_d)
    if mode != "images":
        pick = _fewest_within(ok, best_row, n_se)
        reason = (
            f"{pick.candidate.label}: alternate-edge (shots too few to leave one out) CV d {pick.cv_d:.4f} px, "
            f"fewest parameters ({pick.n_params}) within {se_text} (paired over the held-out edges) of the best "
            f"CV d {best_row.cv_d:.4f} px; the generalisation to an unseen orientation is not checked{set_aside}"
        )
        return _with_support(Selection(pick.candidate, reason, mode, table), lines_per_image)
    first = _fewest_within(ok, best_row, n_se)
    radial = [r for r in ok if not is_flexible(r.candidate)]
    best_radial = lowest_radial(ok)
    margin = _flexible_margin(first, best_radial)
    if is_flexible(first.candidate) and margin > flexible_margin_se:
        # a free polynomial (or field) that wins the folds is judged by them alone: with every
        # orientation in the fit it would bend to those orientations and win again, seen or not
        ahead = "" if best_radial is None else f" {margin:.1f} paired standard errors"
        reason = (
            f"{first.candidate.label}: leave-one-shot-out CV d {first.cv_d:.4f} px, fewest parameters "
            f"({first.n_params}) within {se_text} (paired over the held-out edges) of the best CV d "
            f"{best_row.cv_d:.4f} px,{ahead} ahead of every radial model on unseen orientations"
        )
        return _with_support(Selection(first.candidate, reason + notes, mode, table), lines_per_image)
    if best_radial is None:  # only flexible candidates, none clearly ahead: the folds decide alone
        reason = (
            f"{first.candidate.label}: leave-one-shot-out CV d {first.cv_d:.4f} px, fewest parameters "
            f"({first.n_params}) within {se_text} (paired over the held-out edges) of the best CV d "
            f"{best_row.cv_d:.4f} px (no radial candidate)"
        )
        return _with_support(Selection(first.candidate, reason + notes, mode, table), lines_per_image)
    within = _within(radial, best_radial, n_se, orientation_tolerance)
    general = _with_free_twins(within, radial)
    fits = {r.candidate: r.full_fit for r in general if r.full_fit is not None}
    strings, _ = cross_validate(
        lines_per_image,
        width,
        height,
        [r.candidate for r in general],
        "edges",
        warm_start=warm_start,
        stop_factor=None,
        map_fn=map_fn,
        full_fits=fits,
        **fit_kw,
    )
    ok2 = [r for r in strings if np.isfinite(r.cv_d)]
    loso = {r.candidate: r for r in general}
    if ok2:
        pick2 = min(ok2, key=lambda r: r.cv_d)
        choice = pick2.candidate
        tier2 = (
            f"of those, {TIER2_RULE} with every orientation in the fit (alternate-string CV d {pick2.cv_d:.4f} px, "
            f"{pick2.n_params} parameters)"
        )
    else:  # no candidate could be fitted on alternate strings: tier 1 alone
        pick1 = min(general, key=lambda r: (r.n_params, r.cv_d))
        choice = pick1.candidate
        tier2 = f"of those, fewest parameters ({pick1.n_params}) (no alternate-string fit possible)"
    tol = f"{100 * orientation_tolerance:g} %"
    passed = ""
    if is_flexible(first.candidate):
        passed = (
            f"; {first.candidate.label} won the folds by only {margin:.1f} paired standard errors "
            f"(a flexible model needs more than {flexible_margin_se:g})"
        )
    if choice not in {r.candidate for r in within}:  # in tier 2 by its centre-prior twin (_with_free_twins)
        twin = _prior_twin(choice)
        general_text = (
            f"generalises to an unseen orientation as its twin {twin.label} does (leave-one-shot-out CV d "
            f"{loso[twin].cv_d:.4f} px, within {se_text} or {tol} of the best radial model's {best_radial.cv_d:.4f} "
            f"px; its own {loso[choice].cv_d:.4f} px, a free centre judged by folds of one orientation fewer)"
        )
    else:
        general_text = (
            f"generalises to an unseen orientation (leave-one-shot-out CV d {loso[choice].cv_d:.4f} px, within "
            f"{se_text} or {tol} of the best radial model's {best_radial.cv_d:.4f} px)"
        )
    reason = f"{choice.label}: {general_text}; {tier2}{passed}"
    return _with_support(Selection(choice, reason + notes, mode, table, strings), lines_per_image)


SEPARATED_FOLDS = "images, strings separated"
""":attr:`Selection.folds` of a choice made by leave-one-shot-out folds with the strings separated."""


def _select_separated(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    candidates: Sequence[FitSpec],
    flexible_margin_se: float,
    *,
    stop_factor: float | None,
    map_fn: Callable[..., Iterable[Any]],
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
    kink_t: int | None = None,
    **fit_kw: Any,
) -> Selection:
    """The choice of :func:`select_model` when the turntable angles are known (its docstring)."""
    candidates, trefoil_aside = _trefoil_when_determined(candidates, lines_per_image, "images")
    table = cross_validate_separated(
        lines_per_image, turntable_deg, width, height, candidates, stop_factor=stop_factor, map_fn=map_fn,
        axis_groups=axis_groups, axis_shifts=axis_shifts, kink_t=kink_t, **fit_kw,
    )  # fmt: skip
    ok = [r for r in table if np.isfinite(r.cv_d)]
    if not ok:
        return _nothing_cross_validated(table, " with the strings separated")
    best = pick = min(ok, key=lambda r: r.cv_d)
    best_radial = lowest_radial(ok)
    margin = _flexible_margin(pick, best_radial)
    passed = ""
    if is_flexible(pick.candidate) and best_radial is not None and margin <= flexible_margin_se:
        passed = (
            f"; {pick.candidate.label} won the folds by only {margin:.1f} paired standard errors "
            f"(a flexible model needs more than {flexible_margin_se:g})"
        )
        pick = best_radial
    elif is_flexible(pick.candidate) and best_radial is not None:
        passed = f"; ahead of {best_radial.candidate.label} by {margin:.1f} paired standard errors"
    removed, left = pick.strings_removed or (0, 0)
    reason = (
        f"{pick.candidate.label}: strings separated, turntable angles known: leave-one-shot-out CV d "
        f"{pick.cv_d:.4f} px with each held-out shot's strings' fitted bends removed ({removed} held-out edges; "
        f"{left} left as they were, their string not fitted in the fold), {TIER2_RULE}"
        f"{'' if pick is best else ' of the radial candidates'} ({pick.n_params} parameters){passed}"
    )
    return _with_support(Selection(pick.candidate, reason + trefoil_aside, SEPARATED_FOLDS, table), lines_per_image)


def _supported_when_unchecked(
    candidates: Sequence[FitSpec], lines_per_image: Sequence[Sequence[np.ndarray]], mode: str
) -> tuple[tuple[FitSpec, ...], str]:
    """The candidates a choice without unseen orientations (``mode`` 'edges') may take, and the reason's note.

    Alternate strings cannot judge a flexible candidate (:func:`is_flexible`: a free polynomial or a
    residual field): fitted on every orientation, it bends to them and wins again, seen or not. So when
    the shots have fewer distinct orientations than a flexible candidate needs
    (:func:`required_orientations`) and a radial candidate remains, it is set aside before the
    cross-validation, and the reason says so. On the real photographs fitted on two shots, a residual
    field chosen by alternate strings left the third shot 0.108 px straight against the radial model's
    0.073 (``harp calibrate IMG_6931 IMG_6950 --holdout IMG_6964 --field auto``). With leave-one-shot-out
    folds (``mode`` 'images') nothing is set aside: unseen orientations judge every candidate.
    """
    if mode != "edges":
        return tuple(candidates), ""
    have = distinct_orientations(shot_orientation(s) for s in lines_per_image)
    aside = [c for c in candidates if is_flexible(c) and required_orientations(c) > have]
    kept = tuple(c for c in candidates if c not in aside)
    if not aside or not any(not is_flexible(c) for c in kept):
        return tuple(candidates), ""
    need = min(required_orientations(c) for c in aside)
    kinds = (
        "free polynomial, residual field or three-fold term"
        if any(c.trefoil for c in aside)
        else "free polynomial or residual field"
    )
    return kept, (
        f"; {len(aside)} flexible candidate{'s' if len(aside) > 1 else ''} ({kinds}) "
        f"set aside: alternate strings cannot judge them and they need >= {need} distinct string orientations, "
        f"the shots have {have}"
    )


def _trefoil_when_determined(
    candidates: Sequence[FitSpec], lines_per_image: Sequence[Sequence[np.ndarray]], mode: str
) -> tuple[tuple[FitSpec, ...], str]:
    """The candidates without those whose three-fold term some fit of the cross-validation cannot
    determine, and the reason's note.

    The three-fold (trefoil) term needs :func:`required_orientations` (4) distinct orientations in a fit
    (:data:`pipeline.orientations.REQUIRED_ORIENTATIONS_TREFOIL`): with fewer, the thin-prism and trefoil
    terms trade freely along a direction no fitted string sees, so a fold fitted that way says nothing
    about the lens (leave-one-shot-out folds have one orientation fewer than the shots, alternate-string
    folds all of them). Such candidates are set aside before the cross-validation, unless nothing else
    is left.
    """
    tref = [c for c in candidates if c.trefoil]
    if not tref:
        return tuple(candidates), ""
    angles = [shot_orientation(s) for s in lines_per_image]
    if mode == "images":
        seen = _fewest_fold_orientations(angles)
    else:
        seen = distinct_orientations(angles)
    aside = [c for c in tref if required_orientations(c) > seen]
    kept = tuple(c for c in candidates if c not in aside)
    if not aside or not kept:
        return tuple(candidates), ""
    need = min(required_orientations(c) for c in aside)
    return kept, (
        f"; {len(aside)} candidate{'s' if len(aside) > 1 else ''} with a three-fold term set aside: it needs "
        f">= {need} distinct string orientations in every fit, the folds have {seen}"
    )


def _flexible_margin(row: CVRow, best_radial: CVRow | None) -> float:
    """How many paired standard errors ``row`` is ahead of ``best_radial`` in the folds (inf without one)."""
    if best_radial is None:
        return float("inf")
    delta, se = paired_difference(best_radial, row)
    if not np.isfinite(delta):
        return float("-inf")
    return float("inf") if se <= 0 and delta > 0 else (delta / se if se > 0 else 0.0)


def is_flexible(spec: FitSpec) -> bool:
    """Whether ``spec`` can bend to the orientations it is fitted on (a free polynomial, or a radial
    model with a residual field or with the three-fold term): such a candidate is judged by
    leave-one-shot-out alone (:func:`select_model`), and chosen only when it is clearly ahead of every
    radial model there.

    The three-fold term has two parameters only, but what it changes is the bow every string of an
    orientation shares, which is also what a shot's own measurement bias is, and part of what a bow
    the whole harp shares looks like; alternate strings of the fitted shots share that bow and reward
    the term for it. (Even judged this way, it is not a default candidate: on 20 seeded lenses of
    ``benchmarks/model_choice.py`` with 6 shots it was chosen for lenses without the term and raised
    the worst ratio to the best candidate on unseen shots from 1.137 to 1.532.)"""
    return spec.kind != "radial" or spec.field is not None or spec.trefoil


FIELD_GRIDS: tuple[tuple[int, int], ...] = ((8, 6), (12, 9))
"""Control points ``(nx, ny)`` of the residual fields :func:`field_candidates` offers (a knot every
~150 and ~100 px on a 1000 x 750 image; both about the image's aspect)."""

FIELD_PENALTIES: tuple[float, ...] = (1e-4, 1e-3, 1e-2)
"""Roughness weights :func:`field_candidates` offers (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`):
on five orientations of 1000 x 750 point sets with 0.005 px noise, 1e-4-3e-4 follows a field of 0.05 px RMS
and 0.6-2 half-diagonal wavelengths (:mod:`pipeline.lens_population`) to 0.002-0.003 px of field error (the
radial model: 0.02-0.035), 1e-2 keeps the field near zero; on the realistic simulator the cross-validation
chose 1e-3 or 1e-4 (``benchmarks/residual_field.py``)."""


def field_candidates(
    base: FitSpec,
    grids: Sequence[tuple[int, int]] = FIELD_GRIDS,
    penalties: Sequence[float] = FIELD_PENALTIES,
) -> tuple[FitSpec, ...]:
    """``base`` (a radial spec without a field) and ``base`` with each residual field of ``grids`` x
    ``penalties``: the candidates of a choice of knot density and penalty by :func:`select_model`.
    ``base`` is always among them, so a field is chosen only when it wins on held-out shots (a field
    is :func:`is_flexible`: it must be ahead of ``base`` by :data:`FLEXIBLE_MARGIN_SE`)."""
    if base.kind != "radial" or base.field is not None:
        raise ValueError(f"field candidates need a radial spec without a field, got {base.label}")
    return (base, *(replace(base, field=g, field_penalty=p) for g in grids for p in penalties))


FIELD_MARGIN_SE = 1.0
"""How far ahead of the model a residual field must be in :func:`select_field`'s folds when they are fitted with the
strings separated: more than one paired standard error, where a free polynomial in the plain folds must be
:data:`FLEXIBLE_MARGIN_SE` ahead.

Measured on whole sessions (``benchmarks/field_sessions.py``: ``harp session run`` on the realistic simulated
station, twelve shots, ten seeds, each a unit of the demo lens with a field of 0.005-0.04 px RMS and the same unit
without; the folds with the strings' bends and kinks separated; ``benchmarks/RESULTS-residual-field.md``), the
field the folds took led the model by 1.9-8.5 paired standard errors on the nine lenses with a field where one was
taken (each stored lens better than without the stage, e.g. 0.0053 -> 0.0013 px), and on the lenses without a
field by 0.0-0.4 on five (four of them worse, e.g. 0.0008 -> 0.0020 px) and 1.6, 3.4 and 5.3 on three (all worse,
0.0071 -> 0.0123 px the most). With this bar those five keep the model; of the three, the two that led by 3.4 and
5.3 take no field since the field's part that turns with the harp about its axis is held off it
(:meth:`pipeline.models.radial_field.RadialFieldParametrisation.with_axis_gauge`), and one (1.4 SE now, 0.0071 ->
0.0122 px) still takes its field: with all three changes 9 of 10 lenses without a field store what they store
without the stage, and the lenses with a field keep every gain. With no bar (before, 2026-12-06) all eight took
their field; with two, the 1.9 SE field (0.0053 -> 0.0013 px) is lost. On twelve shots of ``benchmarks/lens_limits.py``'s population
(``benchmarks/field_leads.py --seeds 2,6,7``) the fields that lowered the stored lens's field error (0.0168 ->
0.0037, 0.0044 -> 0.0029, 0.0084 -> 0.0007 px) led by 6.0, 1.4 and 3.9 paired standard errors, and without a field
the lowest CV d was the model's, or a field's 0.2 SE ahead that stores the same 0.0028 px. The bar was set on these
same sessions, so they do not check it; ten fresh seeds (10..19) do: without a field 10 of 10 took none, with a field
10 of 10 took one (1.2-9.4 SE ahead, all better, e.g. 1.2 SE: 0.0070 -> 0.0045 px). The one field that rises,
seed 4's, comes from string bends one turntable axis cannot separate (a braid's twist, one to two periods along a
string; ``benchmarks/session_ablation.py``), which two axis places do: about two places, with the gauge about
both axes, 20 of 20 lenses without a field (seeds 0..19) took none and 19 of 20 with one stored at or below 0.005
px. The six-shot emulation (``benchmarks/choice_realistic.py``, folds without the kinks, before this bar) put the
cost of one standard error at 40 -> 35 of 60 lenses with a field at or below 0.005 px (without one: 50 -> 48 of
60); not measured again with the kinks modelled. The plain folds keep :data:`FLEXIBLE_MARGIN_SE`: there the
strings' bends hide a field and the winner's curse chooses one (a lower bar took 47 of 60 lenses without a field,
worst 0.031 px)."""


def select_field(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    base: FitSpec,
    *,
    grids: Sequence[tuple[int, int]] = FIELD_GRIDS,
    penalties: Sequence[float] = FIELD_PENALTIES,
    map_fn: Callable[..., Iterable[Any]] = map,
    turntable_deg: Sequence[float] | None = None,
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
    radial: FitSpec | None = None,
    kink_t: int | None = None,
    **fit_kw: Any,
) -> Selection:
    """Whether a residual field on top of ``base`` holds on unseen orientations (``pipeline.field: auto``).

    ``base`` (the model a session chose or was given) and ``base`` with each field of :func:`field_candidates`
    (``grids`` x ``penalties``) are cross-validated by :func:`select_model`, leave one shot out; with
    ``turntable_deg`` each fold is fitted with the strings' own bends separated and its held-out shot judged
    without them (:mod:`pipeline.separated_cv`), and a field is taken when its CV d is the lowest and it is more
    than :data:`FIELD_MARGIN_SE` paired standard errors ahead of ``base``; in the plain folds it must be ahead of
    ``base`` by more than
    :data:`FLEXIBLE_MARGIN_SE` paired standard errors (:func:`is_flexible`). The strings' bends are
    what a held-out shot's straightness shows besides the lens, and on the realistic simulator they hid the
    field from the plain folds (a tele lens with a 0.024 px field: CV d 0.0148 px for ``base`` against 0.0139 for
    the best field, while its field error fell from 0.0186 to 0.0088 px; with the strings separated 0.0115 against
    0.0102, the field taken; ``benchmarks/choice_realistic.py --lens-field``).

    ``base`` is kept, with the reason, when it cannot carry a field (not radial, or it has one) or when the shots
    have fewer distinct orientations than a field needs (:func:`pipeline.orientations.required_orientations`): a
    field fitted on fewer bends to the orientations it sees, and no fold could tell. With just enough, each fold
    has one orientation fewer than the field needs; the unseen orientation then judges a field that bends to its
    fold's, which errs towards keeping ``base``. The reason of the returned :class:`Selection` starts with
    ``"residual field: "``.

    ``radial``: when ``base`` is a free polynomial (which a field cannot be added to) and the folds separate the
    strings, the radial model to carry the fields instead (the choice's best radial candidate): ``base``, ``radial``
    and ``radial`` with each field are cross-validated together and the lowest CV d is taken. A polynomial wins
    the choice's plain folds where a lens has structure its radial candidates lack, and a radial model with a field
    follows that structure with its radial part kept: on the realistic simulator, where the choice took poly5 or
    poly7 for 21 of 60 lenses with a field (none of 90 without one), a radial model with a field won those folds for
    every lens checked and lowered the stored lens's field error for most (a tele lens 0.0084 -> 0.0041 px;
    ``benchmarks/RESULTS-residual-field.md``).

    ``kink_t``: with ``turntable_deg``, the folds find and model each string's kinks too, as the session's lens is
    fitted (``pipeline.strings: separate-kinks``; :func:`select_model`). Folds that model the strings' smooth
    bends only leave each kink's bump in the held-out shot, and a field takes the part of the bumps that sits in
    the same place of the image in every shot (kinks near the turntable axis): on twelve realistic shots of a
    lens without a field and with kinked steel strings it won every fold, and raised the stored lens's field
    error (``benchmarks/RESULTS-residual-field.md``).
    """
    separated = _separates_strings(turntable_deg, len(lines_per_image))
    carrier = base
    if base.kind == "poly" and radial is not None and separated and radial.kind == "radial" and radial.field is None:
        carrier = radial
    if carrier.kind != "radial" or carrier.field is not None:
        what = "it has one" if base.field is not None else "a field applies to the radial model only"
        return Selection(base, f"residual field: none added to {base.label} ({what})", "none")
    short = orientation_shortfall(replace(carrier, field=grids[0]), (shot_orientation(s) for s in lines_per_image))
    if short is not None:
        need, have = short
        return Selection(
            base,
            f"residual field: none added to {base.label} (a field needs >= {need} distinct string orientations, "
            f"the shots have {have}; add shots at other angles)",
            "none",
        )
    offered = field_candidates(carrier, grids, penalties)
    if carrier is not base:
        offered = (base, *offered)
    sel = select_model(
        lines_per_image, width, height, offered, map_fn=map_fn,
        turntable_deg=turntable_deg, axis_groups=axis_groups, axis_shifts=axis_shifts, kink_t=kink_t,
        flexible_margin_se=FIELD_MARGIN_SE if separated else FLEXIBLE_MARGIN_SE, **fit_kw,
    )  # fmt: skip
    if sel.choice not in offered:  # nothing could be cross-validated: the model stays, not select_model's fallback
        why = min((r.failure for r in sel.table if r.failure), default="")
        how = " with the strings separated" if separated else ""
        return replace(
            sel, choice=base, reason=f"residual field: none added to {base.label} (no candidate could be "
            f"cross-validated{how}: {why})",
        )  # fmt: skip
    return replace(sel, reason=f"residual field: {sel.reason}")


def _with_support(sel: Selection, lines_per_image: Sequence[Sequence[np.ndarray]]) -> Selection:
    """``sel`` with :func:`support_problem` of its choice in ``support`` and appended to the reason."""
    problem = support_problem(sel.choice, lines_per_image)
    if problem is None:
        return sel
    return replace(sel, reason=f"{sel.reason}; {problem}", support=problem)
