r"""Cross-validation with the strings separated: a held-out shot judged without its strings' own bends.

Leave-one-shot-out folds (:mod:`pipeline.cross_validation`) judge a candidate by the straightness of a
shot it was not fitted on. On a harp whose strings are not perfectly straight, that straightness is
mostly the strings' own: the same strings are in every shot, bent the same way on the harp, and no
lens correction removes a bend that turns with the harp. The folds then compare the strings, not the
lenses, and a too-simple model passes within one standard error (``benchmarks/RESULTS-strings.md``: on
the realistic simulator every candidate's held-out d was 0.0126-0.0147 px, and radial2 was chosen with
five times the field error of radial4+tangential+prism).

When the turntable angles are known, each fold is fitted with every string's deviation separated
(:func:`pipeline.harp_shape.fit_harp_shape` on the other shots), and the held-out shot is judged with
the deviations that fold fitted removed (:func:`held_out_without_strings`; with ``kink_t``, the kinks it found on
each string too, as a session with ``pipeline.strings: separate-kinks`` fits its lens): each held-out edge is given
to the string at its distance from the turntable axis in the fold's ideal image (the rule of
:func:`pipeline.harp_frame.harp_frame`), and its corrected points are moved back by that string's
deviation :math:`\delta_k(u)\,n` before its straightness is measured. What is left is the lens's misfit,
the measurement's noise and what the fold could not learn of the strings (a string seen in fewer than two
of the fold's shots gets no deviation: its edges are left as they are and counted).

The CV table (:func:`cross_validate_separated`) is the same :class:`~pipeline.cross_validation.CVRow` per
candidate as the plain one, held-out residuals pooled over the folds, so the choice reads it by the same
paired differences (:func:`pipeline.cross_validation.paired_difference`); :func:`pipeline.select.select_model`
uses it when given the turntable angles.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera distortion
   measurements with a calibration harp", JOSA A 29(10), 2012 (held-out straightness, Sect. 5).
.. [2] T. Hastie, R. Tibshirani, J. Friedman, *The Elements of Statistical Learning*, 2nd ed.,
   Sect. 7.10 (cross-validation).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.cross_validation import FALLBACK, STOP_FACTOR, CVRow, n_params
from pipeline.edgeset import held_out_edges, tls
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_kinks import Kink, stretches, template
from pipeline.harp_shape import HarpShapeFit, try_fit_harp_shape
from pipeline.resample import DEFAULT_T

Floats = NDArray[np.float64]

MIN_FOLD_ORIENTATIONS = 3
"""Distinct turntable orientations (:func:`pipeline.orientations.distinct_orientations`) every fold must keep
for :func:`pipeline.select.select_model` to separate the strings in it: with two, each string is seen along
two lines only, and its bend and the lens's terms trade."""

MATCH_PITCHES = 1.0 / 3.0
"""A held-out edge belongs to the fold's string nearest to it across the strings when within this many
string pitches (the distance between neighbouring strings' centres, :func:`pipeline.harp_frame.shot_pitch`)."""


@dataclass(frozen=True)
class HeldOutStrings:
    """A held-out shot's residuals with its strings' fitted deviations removed (:func:`held_out_without_strings`).

    ``residuals``: per point, the edges concatenated in order (:func:`pipeline.edgeset.held_out_edges`, as
    :func:`pipeline.edgeset.held_out_residuals` keeps them); ``counts``: the points of each
    of those edges; ``removed``: edges whose string's deviation was removed; ``without_terms``: edges of a
    string the fold fitted no deviation for (seen in fewer than two of its shots, or over too short a
    stretch); ``unmatched``: edges at no string of the fold (a string the fold never saw); the last two are
    left as they are."""

    residuals: Floats
    counts: NDArray[np.int64]
    removed: int
    without_terms: int
    unmatched: int

    @property
    def d(self) -> float:
        """RMS of the residuals (px); NaN without any."""
        return float(np.sqrt(np.mean(self.residuals**2))) if len(self.residuals) else float("nan")

    @property
    def edge_ss(self) -> Floats:
        """Sum of squared residuals of each edge."""
        if not len(self.counts):
            return np.zeros(0)
        starts = np.concatenate([[0], np.cumsum(self.counts)[:-1]]).astype(int)
        out: Floats = np.add.reduceat(self.residuals**2, starts)
        return out


def held_out_without_strings(
    fit: HarpShapeFit,
    lines: Sequence[NDArray[np.float64]],
    turntable_deg: float,
    group: Hashable | None = None,
    kink_t: int = DEFAULT_T,
) -> HeldOutStrings:
    r"""The residuals of a held-out shot's edges (distorted pixels) corrected by ``fit.model``, each moved
    back by its string's deviation as ``fit`` fitted it (module docstring).

    The harp coordinates of a point are those of the fit (:class:`pipeline.harp_frame.HarpFrame` at the
    shot's ``turntable_deg``, from the points corrected by the fit's start ``fit.plain.model``, as
    :func:`pipeline.harp_shape.fit_harp_shape` takes them); an edge's string is the one whose offset
    :math:`q_k` is nearest to the edge's median :math:`q`, within :data:`MATCH_PITCHES` pitches. The
    deviation is evaluated over the stretch of ``u`` where the fold saw the string and held at its end
    value beyond it (a polynomial is not extrapolated); the kinks the fold found on the string (``fit.kinks``,
    :func:`pipeline.harp_shape.fit_harp_shape` with ``kinks=True``) are removed with it, each its fitted peak
    times its template (:func:`pipeline.harp_kinks.template`, the points measured with subsampling factor
    ``kink_t``) at the point's harp coordinate: a kink is fixed to the harp like the rest of the bend. Every
    edge's residual is its distance from its own total-least-squares line (:func:`pipeline.edgeset.tls`), as for the plain held-out figure. A shot of axis
    group ``group`` (the harp moved with its turntable between groups, ``fit_harp_shape(axis_groups=...)``)
    is placed in that group's frame; a group the fit did not see leaves every edge unmatched.
    """
    pts = held_out_edges(lines)
    if not pts:
        return HeldOutStrings(np.zeros(0), np.zeros(0, dtype=np.int64), 0, 0, 0)
    frame = fit.frame if group is None else dict(fit.axis_groups).get(group)
    if frame is None:
        return _unmatched([fit.model.undistort_points(p) for p in pts])
    d, n = frame.direction(float(turntable_deg)), frame.normal(float(turntable_deg))
    c = np.asarray(frame.centre)
    offsets = np.array([s.offset_px for s in fit.strings])
    kinks_of: dict[int, list[Kink]] = {}
    for kink in fit.kinks:
        kinks_of.setdefault(int(kink.string), []).append(kink)
    moved = []
    removed = without = unmatched = 0
    for p in pts:
        ideal = fit.plain.model.undistort_points(p)  # the fit's harp coordinates are of these
        rel = ideal - c
        q = rel @ n
        corrected = fit.model.undistort_points(p)
        qe = float(np.nanmedian(q)) if np.any(np.isfinite(q)) else float("nan")
        k = int(np.argmin(np.abs(offsets - qe))) if len(offsets) and np.isfinite(qe) else -1
        if k < 0 or abs(offsets[k] - qe) > MATCH_PITCHES * frame.pitch_px:
            unmatched += 1
        elif not fit.strings[k].coefficients:
            without += 1
        else:
            st = fit.strings[k]
            a_px = rel @ d
            u = np.clip(a_px / frame.scale_px, st.span[0], st.span[1])
            dev = st.deviation(u)
            mine = kinks_of.get(int(st.index), [])
            if mine:
                stretch = stretches(np.asarray(p, np.float64), ideal, np.array([0]), np.array([len(p)]))
                for kink in mine:
                    dev = dev + kink.peak_px * template(a_px - kink.at_px, stretch, kink_t, kink.length_px)
            corrected = corrected - dev[:, None] * n
            removed += 1
        moved.append(corrected)
    counts = np.array([len(p) for p in moved], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    r = tls(np.concatenate(moved), starts, counts)[0]
    return HeldOutStrings(r, counts, removed, without, unmatched)


def _unmatched(pts: list[Floats]) -> HeldOutStrings:
    """Every edge of a held-out shot (corrected points) left as it is, none matched to a string."""
    counts = np.array([len(p) for p in pts], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    r = tls(np.concatenate(pts), starts, counts)[0]
    return HeldOutStrings(r, counts, 0, 0, len(pts))


# ------------------------------------------------------------------ the CV table
Groups = tuple[tuple[Hashable, ...], dict[Hashable, tuple[float, ...]] | None] | None
"""Each shot's axis group and the groups' rough shifts (``fit_harp_shape(axis_groups=, axis_shifts=)``), or
None: one turntable axis."""
Settings = tuple[int, int, tuple[float, ...], float | None, dict[str, Any], Groups, int | None]
"""``(width, height, turntable_deg, stop_factor, fit_kw, groups, kink_t)``: ``kink_t`` the subsampling factor the
points were measured with when the folds find and model the strings' kinks, None when they do not."""


def _kink_arguments(kink_t: int | None) -> tuple[bool, int]:
    """:func:`pipeline.harp_shape.try_fit_harp_shape`'s ``(kinks, kink_t)`` for a :data:`Settings` ``kink_t``."""
    return kink_t is not None, kink_t or DEFAULT_T


def _full_fits(cand: FitSpec, lines: list[list[Floats]], settings: Settings) -> tuple[Any, Any]:
    """A candidate's fit on all shots, alone and with the strings separated (either may be a failure)."""
    width, height, angles, _, fit_kw, groups, kink_t = settings
    plain = fit_distortion(lines, width, height, **cand.fit_arguments(), **fit_kw)
    if not plain:
        return plain, plain
    labels, shifts = groups or (None, None)
    return plain, try_fit_harp_shape(
        lines, angles, width, height, cand, plain, *_kink_arguments(kink_t), labels, shifts
    )


def _first_pass(job: tuple[FitSpec, list[list[Floats]], Settings, bool]) -> Any:
    """The reference's whole :class:`CVRow`, or another candidate's fits on all shots (:func:`_full_fits`)."""
    cand, lines, settings, is_reference = job
    if is_reference:
        return _row((cand, lines, float("inf"), settings, _full_fits(cand, lines, settings)))
    return _full_fits(cand, lines, settings)


def _row(job: tuple[FitSpec, list[list[Floats]], float, Settings, tuple[Any, Any]]) -> CVRow:
    """One candidate's :class:`CVRow` from its leave-one-shot-out folds fitted with the strings separated;
    stopped as :func:`pipeline.cross_validation.cross_validate` stops one (its joint fit on all shots, or its
    held-out residuals so far, already beyond ``stop_factor`` times the reference's CV mean square)."""
    cand, lines, ref_mse, settings, (plain, joint) = job
    width, height, angles, stop_factor, fit_kw, groups, kink_t = settings
    labels, shifts = groups or (None, None)
    size = n_params(cand, width, height)
    full = plain if plain else None
    if not plain or not joint:
        return CVRow(cand, size, float("nan"), (), (), f"its fit on all shots: {plain.reason if not plain else joint.reason}", full_fit=full)  # fmt: skip
    held_total = float(sum(len(p) for shot in lines for p in held_out_edges(shot)))
    factor = float("inf") if stop_factor is None else float(stop_factor)
    stopping = np.isfinite(factor) and np.isfinite(ref_mse)
    if stopping and joint.d_after**2 > factor * ref_mse:
        return CVRow(
            cand, size, float("nan"), (), (),
            f"stopped before the folds: its fit on all shots with the strings separated already leaves d "
            f"{joint.d_after:.4g} px, >= {np.sqrt(factor):g}x the CV d {np.sqrt(ref_mse):.4g} px of the reference",
            full_fit=full, cv_d_bound=float(joint.d_after),
        )  # fmt: skip
    fold_d: list[float] = []
    fit_d: list[float] = []
    res: list[Floats] = []
    ss: list[Floats] = []
    nn: list[NDArray[np.int64]] = []
    removed = left = 0
    so_far = 0.0
    find_kinks, template_t = _kink_arguments(kink_t)
    for h in range(len(lines)):
        train = [s for i, s in enumerate(lines) if i != h]
        train_angles = [a for i, a in enumerate(angles) if i != h]
        train_groups = None if labels is None else [g for i, g in enumerate(labels) if i != h]
        fold_plain = fit_distortion(train, width, height, **cand.fit_arguments(), init=plain.model, **fit_kw)
        fold = (
            try_fit_harp_shape(
                train, train_angles, width, height, cand, fold_plain, find_kinks, template_t, train_groups, shifts
            )
            if fold_plain
            else fold_plain
        )
        if not fold:
            return CVRow(cand, size, float("nan"), tuple(fold_d), tuple(fit_d), f"without shot {h}: {fold.reason}", full_fit=full)  # fmt: skip
        held = held_out_without_strings(fold, lines[h], angles[h], None if labels is None else labels[h], template_t)
        removed += held.removed
        left += held.without_terms + held.unmatched
        res.append(held.residuals)
        ss.append(held.edge_ss)
        nn.append(held.counts)
        fold_d.append(held.d)
        fit_d.append(fold.d_after)
        so_far += float(np.sum(held.residuals**2))
        if stopping and h + 1 < len(lines) and so_far / held_total > factor * ref_mse:
            bound = float(np.sqrt(so_far / held_total))
            return CVRow(
                cand, size, float("nan"), tuple(fold_d), tuple(fit_d),
                f"stopped after {h + 1} of {len(lines)} folds: held-out d already >= {bound:.4g} px, "
                f"{np.sqrt(factor):g}x the CV d {np.sqrt(ref_mse):.4g} px of the reference",
                full_fit=full, cv_d_bound=bound,
            )  # fmt: skip
    allr = np.concatenate(res)
    return CVRow(
        cand,
        size,
        float(np.sqrt(np.mean(allr**2))) if len(allr) else float("nan"),
        tuple(fold_d),
        tuple(fit_d),
        None,
        tuple(float(v) for v in np.concatenate(ss)),
        tuple(int(v) for v in np.concatenate(nn)),
        full,
        strings_removed=(removed, left),
    )


def cross_validate_separated(
    lines_per_image: Sequence[Sequence[Floats]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    candidates: Sequence[FitSpec],
    *,
    stop_factor: float | None = STOP_FACTOR,
    map_fn: Callable[..., Iterable[Any]] = map,
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
    kink_t: int | None = None,
    **fit_kw: Any,
) -> tuple[CVRow, ...]:
    """The CV table of ``candidates``, each fold fitted with the strings separated on all shots but one and
    judged on that shot with its strings' fitted deviations removed (module docstring).

    Parameters
    ----------
    lines_per_image : per shot, its edges (distorted pixels); three shots or more.
    turntable_deg : each shot's turntable angle (degrees).
    width, height : the image size.
    candidates : the configurations compared.
    stop_factor : as for :func:`pipeline.cross_validation.cross_validate`: :data:`FALLBACK` (or else the first
        candidate) is the reference, any other candidate is stopped once its joint fit on all shots, or its
        held-out residuals so far, exceed this many times the reference's CV mean square; None: never.
    map_fn : a ``map`` over the candidates (a process pool's; the table does not depend on it), called twice:
        the reference's row with the others' fits on all shots, then the others' folds.
    axis_groups, axis_shifts : each shot's axis group and the groups' rough shifts, px, when the harp was moved
        with its turntable between groups (:func:`pipeline.harp_shape.fit_harp_shape`); each fold and the
        held-out shot are placed in their group's frame.
    kink_t : the along-edge subsampling factor the points were measured with, when every fold is to find and
        model each string's kinks as a session's lens is fitted (``pipeline.strings: separate-kinks``,
        :func:`pipeline.harp_shape.fit_harp_shape` with ``kinks=True``) and the held-out shot's are to be removed
        with its strings' bends (:func:`held_out_without_strings`); None: bends only.
    fit_kw : passed to :func:`pipeline.fit.fit_distortion`.

    Returns
    -------
    tuple of CVRow
        In the order of ``candidates``; :attr:`CVRow.full_fit` is each candidate's fit on all shots without
        the strings (the start of its joint fit), :attr:`CVRow.fit_d` each fold's d with the strings
        separated, :attr:`CVRow.strings_removed` how many held-out edges had their string's bend removed
        and how many were left as they are.
    """
    if len(turntable_deg) != len(lines_per_image):
        raise ValueError(f"{len(lines_per_image)} shots but {len(turntable_deg)} turntable angles")
    if len(lines_per_image) < 3:
        raise ValueError(f"leave-one-shot-out folds with the strings separated need 3 shots or more, got {len(lines_per_image)}")  # fmt: skip
    lines = [[np.asarray(p, dtype=np.float64) for p in s] for s in lines_per_image]
    if axis_groups is not None and len(axis_groups) != len(lines_per_image):
        raise ValueError(f"{len(lines_per_image)} shots but {len(axis_groups)} axis groups")
    groups: Groups = (
        None
        if axis_groups is None
        else (tuple(axis_groups), None if axis_shifts is None else {g: tuple(v) for g, v in axis_shifts.items()})
    )
    settings: Settings = (
        width, height, tuple(float(a) for a in turntable_deg), stop_factor, dict(fit_kw), groups, kink_t
    )  # fmt: skip
    first = FALLBACK if FALLBACK in candidates else candidates[0]
    order = sorted((c for c in candidates if c != first), key=lambda c: -n_params(c, width, height))
    made = list(map_fn(_first_pass, [(c, lines, settings, c == first) for c in [first, *order]]))
    ref: CVRow = made[0]
    ref_mse = ref.cv_d**2 if np.isfinite(ref.cv_d) else float("inf")
    jobs = [(c, lines, ref_mse, settings, fits) for c, fits in zip(order, made[1:], strict=True)]
    done = dict(zip(order, map_fn(_row, jobs)))
    done[first] = ref
    return tuple(done[c] for c in candidates)
