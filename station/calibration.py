"""Calibrating a set of shots: the one way from measured edges to a profile's content.

:func:`calibrate_shots` serves both ``harp calibrate`` (shots given on the command
line, optional held-out shots) and a session (one shot per orientation of a focus
setting, each orientation held out in turn, bootstrap). It

1. chooses what to fit when no :class:`~pipeline.fitspec.FitSpec` is given, by
   cross-validation over the shots (:func:`pipeline.select.select_model`);
2. fits it on every shot at once (:func:`pipeline.fit.fit_distortion`);
3. measures how well it generalises: ``holdout='orientations'`` fits the spec
   without each shot in turn and measures that shot corrected by it (the edges the
   full fit rejected as outliers are left out, as in the fit); ``held_out`` shots
   (never fitted) are corrected by the full fit and measured; the figure is the
   straightness (Tang et al. 2012) of all held-out edges together;
4. with ``bootstrap >= 2`` replicates, maps the field uncertainty
   (:func:`pipeline.uncertainty.bootstrap_field_uncertainty`, same spec).

The result, a :class:`Calibration`, holds the fit, the spec and how it was chosen,
the typed :class:`~station.profile.Merit` and the evidence (uncertainty map,
per-shot figures); :meth:`Calibration.profile` makes the
:class:`~station.profile.Profile` of it.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.cross_validation import DEFAULT_CANDIDATES
from pipeline.edgeset import FitFailure, FitResult, corrected_straightness, straightness_of
from pipeline.fit import fit_distortion
from pipeline.fitspec import (
    CHOICE_FOLDS_PLAIN,
    CHOICE_FOLDS_STRINGS,
    FIELD_AUTO,
    FIELD_CHOICES,
    FIELD_NONE,
    STRINGS_KINKS,
    STRINGS_SEPARATE,
    FitSpec,
)
from pipeline.harp_frame import GROUP_AXIS_SEARCH, MIN_GROUP_ANGLES, harp_frame, string_pitch
from pipeline.harp_shape import (
    BEND_LIMIT_PX,
    SHOT_NOISE_FACTOR,
    HarpShapeFit,
    fit_harp_shape,
    lens_result,
    separated_job,
    separated_kinks_job,
    shot_weights,
)
from pipeline.models.base import DistortionModel
from pipeline.orientations import distinct_orientations, shot_orientation, support_problem
from pipeline.own_shift import OwnShift, own_axis_shift, twin_shift
from pipeline.plain import finite_or_none
from pipeline.resample import DEFAULT_T
from pipeline.select import lowest_radial, select_field, select_model
from pipeline.uncertainty import bootstrap_field_uncertainty, refit_job
from station.equipment import Identity
from station.profile import (
    HOLDOUT_LEAVE_ONE_ORIENTATION_OUT,
    HOLDOUT_SHOTS,
    Figures,
    Holdout,
    Merit,
    Profile,
    Provenance,
    UncertaintySummary,
)

MapFn = Callable[[Callable[[Any], Any], Iterable[Any]], Iterator[Any]]

BOOTSTRAP_SCHEME = "edges resampled with replacement within each shot"

GIVEN_BY_CONFIG = "pipeline.model of the configuration"
"""The selection reason of a spec the session's configuration names (``pipeline.model``)."""
GIVEN_ON_COMMAND_LINE = "given on the command line"
"""The selection reason of a spec a command's option names (``harp calibrate --model``, ``harp reprocess --spec``)."""


OWN_SHIFT_RATIO = 0.7
"""A session's held-out orientations are said to carry a term of their own when moving the correction's axis for
each one alone (:func:`pipeline.own_shift.own_axis_shift`) leaves, in the median over them, less than this part of
its held-out d. Set on realistic sessions of six shots (``benchmarks/own_shift.py --shots 6``, 20 lenses each,
radial4+tangential+prism folds): a stable lens's per-session median is 0.91-1.00 (lens field up to 0.04 px RMS) or
0.78-1.00 (up to 0.1), none below; a lens whose distortion centre moves N(0, 6 px) between shots, or its p1, p2
N(0, 1e-4), is below for 11 of 20, N(0, 5e-5) for 1 of 20."""

MIN_OWN_SHIFT_ORIENTATIONS = 4
"""Fewest orientations for the own-shift figure: with three, each fold is fitted on two orientations, which leave a
quadratic term undetermined that the held-out one then shows (``benchmarks/quadratic_sector.py``); its own shift
takes that away too, so a stable lens can read as low as 0.54 (``benchmarks/own_shift.py``)."""


MOVING_LENS_ADVICE = (
    "the lens's decentering may change between shots (an image stabiliser, a focus or zoom group with play): switch "
    "stabilisation off, lock focus and zoom, and capture again"
)
"""What to do about a lens that moves between shots (QA's and ``harp calibrate``'s warnings)."""

OWN_SHIFT_ADVICE = (
    f"{MOVING_LENS_ADVICE}; two shots at the same angle (a session's capture.twin_deg) tell it from a lens term that "
    "bends each orientation its own way"
)
"""What QA and ``harp calibrate`` say when the held-out shots carry a term of their own (``moving``)."""


def largest_own_shift(record: Mapping[str, Any]) -> float | None:
    """The largest own axis shift (px) of an own-shift record (:func:`own_shift_record`); None when none is known."""
    shifts = [o.get("shift_px") or [] for o in record.get("per_orientation") or []]
    sizes = [float(np.hypot(*v)) for v in shifts if len(v) == 2 and None not in v]
    return max(sizes) if sizes else None


def own_shift_record(own: Sequence[OwnShift]) -> dict[str, Any]:
    """The held-out orientations' own axis shifts as a profile keeps them (``details["own_shift"]``): per
    orientation its held-out d, the d with its own shift and the shift (px); the median ratio; ``moving`` when that
    median is below :data:`OWN_SHIFT_RATIO` with :data:`MIN_OWN_SHIFT_ORIENTATIONS` orientations or more (the lens's
    decentering may change between shots: :mod:`pipeline.own_shift`)."""
    ratios = [o.ratio for o in own if np.isfinite(o.ratio)]
    median = float(np.median(ratios)) if ratios else float("nan")
    return {
        "ratio_median": finite_or_none(median),
        "limit": OWN_SHIFT_RATIO,
        "judged": len(ratios) >= MIN_OWN_SHIFT_ORIENTATIONS,
        "moving": bool(len(ratios) >= MIN_OWN_SHIFT_ORIENTATIONS and median < OWN_SHIFT_RATIO),
        "per_orientation": [
            {
                "d_held_px": finite_or_none(o.d_held),
                "d_own_px": finite_or_none(o.d_own),
                "shift_px": [finite_or_none(v) for v in o.shift_px],
            }
            for o in own
        ],
    }


def shot_own_shifts(
    shots: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    spec: FitSpec,
    rejected: Sequence[Any] = (),
    map_fn: MapFn = map,
) -> dict[str, Any] | None:
    """The own-shift record (:func:`own_shift_record`) of shots without turntable angles (``harp calibrate``): each
    shot held out in turn, ``spec`` fitted on the others (``map_fn`` maps the fits), its edges but the full fit's
    ``rejected`` measured under that fit and under it moved for them alone (two shots at one angle are compared
    directly by :func:`twin_record`). None with fewer than
    :data:`MIN_OWN_SHIFT_ORIENTATIONS` shots or when a fold's fit fails."""
    if len(shots) < MIN_OWN_SHIFT_ORIENTATIONS:
        return None
    loo = _refit_holdout(shots, width, height, spec.fit_arguments(), rejected, map_fn)
    return own_shift_record(loo.own) if isinstance(loo, _OrientationHoldout) else None


TWIN_ANGLE_DEG = 2.0
"""Two shots are twins (:func:`twin_record`) when their strings run within this of each other (degrees,
:func:`pipeline.orientations.shot_orientation`): a harp turned back to an angle by hand comes back within a degree or
two, and a term of the lens bends strings 2 degrees apart alike."""

TWIN_MOVE_PX = 1.0
"""The lens is said to have moved between twins when the move across their strings
(:func:`pipeline.own_shift.twin_shift`) is larger than this (px). Set on realistic twins (``benchmarks/twins.py``,
the photographs' set-up plus a shot at the first one's angle, 20 lenses per camera): a stable lens reads at most
0.23 px (40 lenses, fields up to 0.04 and 0.1 px RMS); on lenses whose centre moves N(0, 3 px) or N(0, 6 px) the move
read is within 0.06-0.15 px RMS of the move drawn (at most 0.36 px off), and every one of the 58 drawn beyond 1 px is
read beyond it. Whole realistic sessions with a twin (``benchmarks/session_twins.py``, six angles and the twin, 30
sessions): stable lenses read at most 0.10 px, moves are read within 0.04 px RMS, and all 17 drawn beyond 1 px are
read beyond it."""


def twin_record(
    model: DistortionModel, shots: Sequence[Sequence[np.ndarray]], names: Sequence[str]
) -> list[dict[str, Any]]:
    """Every pair of ``shots`` whose strings run within :data:`TWIN_ANGLE_DEG` of each other, compared under the
    correction ``model`` (:func:`pipeline.own_shift.twin_shift`): per pair the two ``names``, the strings' angle, d
    with one shift for both and with a shift each, ``ratio``, the lens's move across the strings (``move_px``) and
    ``moved`` beyond :data:`TWIN_MOVE_PX`. Two shots at one angle tell a lens that moved between them (a shift each)
    from a term of the lens at that angle (one shift for both), which one shot per angle cannot
    (:mod:`pipeline.own_shift`); the harp must not have been moved otherwise between them. Every edge of both twins
    is compared, those a fit rejected too: the twins see the same strings, and an edge dropped from one twin but
    not from the other reads as a move (a session's twin compared with its first shot less the fit's rejected edges
    read the move 15 % short, ``benchmarks/RESULTS-realism.md``). Empty without such a pair."""
    angles = [shot_orientation(lines) for lines in shots]
    out = []
    for i in range(len(shots)):
        for j in range(i + 1, len(shots)):
            gap = abs(angles[i] - angles[j]) % 180.0
            if min(gap, 180.0 - gap) <= TWIN_ANGLE_DEG:
                out.append(_twin_entry(model, shots[i], shots[j], (names[i], names[j]), angles[i]))
    return out


def session_twin_record(
    model: DistortionModel, first: Sequence[np.ndarray], twin: Sequence[np.ndarray], names: tuple[str, str]
) -> dict[str, Any]:
    """A session's twin (``capture.twin_deg``: the shot ``twin`` taken again, after the others and not fitted, at
    the angle of the shot ``first``) compared with that shot under the session's correction ``model``, as
    :func:`twin_record` compares a pair (every edge of both), with ``twin_d_px``: the twin's straightness under the
    correction, a shot it was not fitted on."""
    entry = _twin_entry(model, first, twin, names, shot_orientation(first))
    return {**entry, "twin_d_px": finite_or_none(corrected_straightness(model, twin)[0])}


def _twin_entry(
    model: DistortionModel, a: Sequence[np.ndarray], b: Sequence[np.ndarray], names: tuple[str, str], angle: float
) -> dict[str, Any]:
    """One pair of twins' record (:func:`twin_record`)."""
    got = twin_shift(model, a, b)
    return {
        "paths": list(names),
        "angle_deg": finite_or_none(angle),
        "d_common_px": finite_or_none(got.d_common),
        "d_each_px": finite_or_none(got.d_each),
        "ratio": finite_or_none(got.ratio),
        "move_px": finite_or_none(got.move_px),
        "limit_px": TWIN_MOVE_PX,
        "moved": bool(np.isfinite(got.move_px) and abs(got.move_px) > TWIN_MOVE_PX),
    }


def twin_warnings(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """``harp calibrate``'s warning for each pair of twins between which the lens moved (:func:`twin_record`)."""
    return [
        f"{r['paths'][0]} and {r['paths'][1]} (strings at {r['angle_deg']:.1f} deg): the lens moved "
        f"{abs(r['move_px']):.1f} px across the strings between these two shots at one angle, beyond "
        f"{r['limit_px']:g} px; the correction is their mean: {MOVING_LENS_ADVICE}"
        for r in records
        if r.get("moved")
    ]


def own_shift_warning(record: Mapping[str, Any] | None) -> str | None:
    """``harp calibrate``'s warning when its held-out shots each want the correction moved on their own (the record's
    ``moving``, :func:`shot_own_shifts`); None otherwise."""
    if not record or not record.get("moving"):
        return None
    size = largest_own_shift(record)
    return (
        f"each shot held out wants the correction moved on its own: {record['ratio_median']:.2f} of its held-out d is "
        f"left (median, below {record['limit']:g})" + (f", by up to {size:.1f} px" if size is not None else "")
        + f": {OWN_SHIFT_ADVICE}"
    )  # fmt: skip


@dataclass(frozen=True)
class HeldOutShot:
    """Straightness of one held-out shot before and after the correction (px)."""

    before: Figures
    after: Figures


@dataclass(frozen=True)
class Calibration:
    """What :func:`calibrate_shots` found. ``failure`` is None when ``fit`` is a result.

    ``spec``/``selection``: what was fitted and why (``selection`` is the
    :class:`pipeline.select.Selection` of an automatic choice, else None);
    ``merit``: the figures of merit; ``held_out``: per held-out shot (``held_out``
    mode); ``uncertainty``: the bootstrap map (``FieldUncertainty``) or None;
    ``details``: fit diagnostics kept with the profile; ``support``: why the shots do not support a given
    ``spec`` well (:func:`pipeline.orientations.support_problem`; an automatic choice says it in its reason).
    """

    fit: FitResult | FitFailure
    spec: FitSpec | None
    selection: Any = None
    merit: Merit = field(default_factory=Merit)
    held_out: tuple[HeldOutShot, ...] = ()
    uncertainty: Any = None
    details: Mapping[str, Any] = field(default_factory=dict)
    failure: str | None = None
    support: str | None = None

    def profile(
        self,
        width: int,
        height: int,
        *,
        provenance: Provenance,
        given_by: str = GIVEN_BY_CONFIG,
        details: Mapping[str, Any] | None = None,
        merit_extra: Mapping[str, Any] | None = None,
        lens: Identity | None = None,
        camera: Identity | None = None,
        focus: float | None = None,
    ) -> Profile:
        """The profile of this calibration (raises ValueError for a failed one): the one builder under a
        session's and a reprocess's :func:`focus_profile` and ``harp calibrate``.

        ``given_by``: the selection reason of a given spec (:func:`selection_record`); ``details``: kept
        after this calibration's own; ``merit_extra``: written into the merit beside its figures
        (:attr:`station.profile.Merit.extra`, e.g. ``harp calibrate``'s rejected edges)."""
        if self.failure is not None or not self.fit:
            raise ValueError(f"no profile of a failed calibration: {self.failure}")
        merit = self.merit if merit_extra is None else dataclasses.replace(self.merit, extra=dict(merit_extra))
        return Profile(
            model=self.fit.model,
            width=int(width),
            height=int(height),
            spec=self.spec,
            selection=selection_record(self.selection, given_by, self.support),
            merit=merit,
            lens=lens,
            camera=camera,
            focus=focus,
            provenance=provenance,
            details={**self.details, **dict(details or {})},
        )


def _figures(d: float, d_max: float) -> Figures:
    return Figures(finite_or_none(d), finite_or_none(d_max))


@dataclass(frozen=True)
class _OrientationHoldout:
    """:func:`_orientation_holdout`'s figure and each held-out orientation's own axis shift."""

    holdout: Holdout
    own: tuple[OwnShift, ...]


def _orientation_holdout(
    lines: Sequence[Sequence[np.ndarray]],
    rejected: Sequence[Any],
    job_fn: Callable[[Any], tuple[Any, str | None]],
    jobs: Sequence[Any],
    map_fn: MapFn,
) -> _OrientationHoldout | tuple[int, str]:
    """The leave-one-orientation-out figure: ``job_fn(jobs[k])`` fits without orientation ``k``, and its
    model corrects orientation ``k``'s edges (those the full fit did not reject, ``rejected``); the
    straightness of all of them together, and per orientation; and per orientation the same edges under its fold's
    model with the model's axis moved for them alone (:func:`pipeline.own_shift.own_axis_shift`).
    ``(k, reason)`` for the first fold whose fit failed."""
    outliers = {(r.image, r.line) for r in rejected}
    held_lines: list[np.ndarray] = []
    per_o: list[float | None] = []
    own: list[OwnShift] = []
    for k, (model, reason) in enumerate(map_fn(job_fn, jobs)):
        if model is None:
            return k, str(reason)
        kept = [p for i, p in enumerate(lines[k]) if (k, i) not in outliers and len(p) >= 3]
        per_o.append(finite_or_none(corrected_straightness(model, kept)[0]))
        held_lines.extend(model.undistort_points(p) for p in kept)
        own.append(own_axis_shift(model, kept))
    d, d_max = straightness_of(held_lines)
    hold = Holdout(finite_or_none(d), finite_or_none(d_max), HOLDOUT_LEAVE_ONE_ORIENTATION_OUT, tuple(per_o))
    return _OrientationHoldout(hold, tuple(own))


def _refit_holdout(
    lines: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    kw: Mapping[str, Any],
    rejected: Sequence[Any],
    map_fn: MapFn,
) -> _OrientationHoldout | tuple[int, str]:
    """:func:`_orientation_holdout` with each fold fitted by :func:`pipeline.fit.fit_distortion` (``kw``, a spec's
    fit arguments) on the other shots."""
    jobs = [([ls for j, ls in enumerate(lines) if j != k], width, height, kw) for k in range(len(lines))]
    return _orientation_holdout(lines, rejected, refit_job, jobs, map_fn)


def calibrate_shots(
    shots: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    spec: FitSpec | None = None,
    *,
    holdout: str | None = None,
    held_out: Sequence[Sequence[np.ndarray]] = (),
    image_sizes: Sequence[tuple[int, int]] | None = None,
    bootstrap: int = 0,
    seed: int = 0,
    map_fn: MapFn = map,
    candidates: Sequence[FitSpec] | None = None,
    turntable_deg: Sequence[float] | None = None,
    axis_groups: Sequence[Any] | None = None,
    axis_shifts: Mapping[Any, Sequence[float]] | None = None,
    field: str = FIELD_NONE,
    field_turntable_deg: Sequence[float] | None = None,
    kink_t: int | None = None,
) -> Calibration:
    """Calibrate the edges of ``shots`` (see the module docstring).

    Parameters
    ----------
    shots : per shot, its edges as (M, 2) arrays (pixels, distorted).
    width, height : the image size.
    spec : what to fit; None: chosen by cross-validation over the shots.
    holdout : ``'orientations'`` (leave each shot out in turn; a session) or None.
    held_out : shots never used in the fit, measured after correction.
    image_sizes : size of each shot (a mismatch is a failure).
    bootstrap : replicates of the field uncertainty (0: none; 1 is recorded as failed).
    seed : of the bootstrap resampling.
    map_fn : ``map`` over independent fits (a process pool's); results do not depend on it.
    candidates : what the cross-validation chooses among when ``spec`` is None (default
        :data:`pipeline.cross_validation.DEFAULT_CANDIDATES`; e.g. :func:`pipeline.select.field_candidates`).
    turntable_deg : each shot's turntable angle, when known: the automatic choice cross-validates every
        candidate with the strings separated (:func:`pipeline.select.select_model`'s ``turntable_deg``).
    axis_groups, axis_shifts : with ``turntable_deg`` or ``field_turntable_deg``, a two-axis capture's groups and
        shifts (:func:`axes_of`) for those folds.
    field : ``"auto"``: a residual field added to the model (chosen or given) when it holds on unseen orientations
        (:func:`pipeline.select.select_field`; :data:`pipeline.fitspec.FIELD_CHOICES`); ``"none"``: never.
    field_turntable_deg : each shot's turntable angle for the field's folds, fitted with the strings' bends
        separated (None: the plain folds).
    kink_t : the folds with the strings separated (``turntable_deg``, ``field_turntable_deg``) find and model each
        string's kinks too, the points measured with this subsampling factor, as the lens a session stores is
        fitted (``pipeline.strings: separate-kinks``; :func:`pipeline.select.select_field`); None: bends only.
    """
    if field not in FIELD_CHOICES:
        raise ValueError(f"unknown field choice {field!r}; known: {', '.join(FIELD_CHOICES)}")
    lines = [list(s) for s in shots]
    selection = None
    support = None if spec is None else support_problem(spec, lines)
    if spec is None:
        angles = None if turntable_deg is None else [float(a) for a in turntable_deg]
        offered = DEFAULT_CANDIDATES if candidates is None else candidates
        selection = select_model(
            lines, width, height, offered, map_fn=map_fn, turntable_deg=angles, axis_groups=axis_groups,
            axis_shifts=axis_shifts, kink_t=None if angles is None else kink_t,
        )  # fmt: skip
        spec = selection.choice
    tables = [] if selection is None else [selection.table]
    if field == FIELD_AUTO:
        given = spec
        # a polynomial chosen over the radial candidates: the best of them may carry a field instead
        radial = lowest_radial(selection.table) if selection else None
        on_field = select_field(
            lines, width, height, spec, map_fn=map_fn,
            turntable_deg=None if field_turntable_deg is None else [float(a) for a in field_turntable_deg],
            axis_groups=axis_groups, axis_shifts=axis_shifts,
            radial=None if radial is None else radial.candidate,
            kink_t=None if field_turntable_deg is None else kink_t,
        )  # fmt: skip
        tables.append(on_field.table)
        spec = on_field.choice
        if selection is None:  # a given model: the field's selection says why it has one or not
            note = "" if support is None else f"; {support}"
            selection = dataclasses.replace(on_field, reason=f"{given.label} given{note}; {on_field.reason}")
        else:
            kept = selection.support if spec == given else None  # a field is taken on enough orientations only
            selection = dataclasses.replace(
                selection, choice=spec, reason=f"{selection.reason}; {on_field.reason}", support=kept
            )
    kw = spec.fit_arguments()
    same_size = image_sizes is None or {(int(w), int(h)) for w, h in image_sizes} == {(int(width), int(height))}
    # the cross-validation fitted every candidate on all shots (its folds start there): the same fit
    cv_fit = next((r.full_fit for t in tables for r in t if r.candidate == spec), None)
    full = cv_fit if cv_fit and same_size else fit_distortion(lines, width, height, **kw, image_sizes=image_sizes)
    if not full:
        return Calibration(full, spec, selection, failure=full.reason, support=support)
    fit_figures = _figures(full.d_after, full.d_max_after)
    before = _figures(full.d_before, full.d_max_before)
    details: dict[str, Any] = {
        "n_points": full.n_points,
        "n_params": full.n_params,
        "rejected_edges": len(full.rejected),
        "warnings": list(full.warnings),
    }
    if selection is not None:
        details["selection"] = {"choice": selection.choice.label, **selection_record(selection)}

    hold: Holdout | None = None
    per_shot: list[HeldOutShot] = []
    if holdout == "orientations":
        loo = _refit_holdout(lines, width, height, kw, full.rejected, map_fn)
        if not isinstance(loo, _OrientationHoldout):
            return Calibration(
                full, spec, selection, Merit(fit=fit_figures, before=before), details=details,
                failure=f"cross-validation without orientation {loo[0]}: {loo[1]}",
            )  # fmt: skip
        hold = loo.holdout
        details["own_shift"] = own_shift_record(loo.own)
    elif holdout is not None:
        raise ValueError(f"unknown hold-out scheme {holdout!r}; known: 'orientations'")
    if held_out:
        for s in held_out:
            b = straightness_of(list(s))
            a = corrected_straightness(full.model, list(s))
            per_shot.append(HeldOutShot(_figures(*b), _figures(*a)))
        d, d_max = corrected_straightness(full.model, [p for s in held_out for p in s])
        hold = Holdout(finite_or_none(d), finite_or_none(d_max), HOLDOUT_SHOTS)

    unc = None
    unc_summary = None
    if bootstrap == 1:
        details["bootstrap_failed"] = "a bootstrap needs at least 2 replicates (pipeline.bootstrap: 1)"
    elif bootstrap:
        res = bootstrap_field_uncertainty(
            lines, width, height, spec, n_boot=bootstrap, seed=seed, full_fit=full, map_fn=map_fn
        )
        if not res:
            details.update(bootstrap_replicates=0, bootstrap_failed=bootstrap, bootstrap_failure=res.reason)
        else:
            unc = res
            unc_summary = UncertaintySummary(float(res.rms), float(res.max), int(res.n_boot))
            details.update(bootstrap_replicates=res.n_boot, bootstrap_failed=res.n_failed)
        details["bootstrap_scheme"] = BOOTSTRAP_SCHEME
    merit = Merit(fit=fit_figures, holdout=hold, before=before, field_uncertainty=unc_summary)
    return Calibration(full, spec, selection, merit, tuple(per_shot), unc, details, support=support)


def size_problem(shots: Sequence[tuple[str, int, int]]) -> str | None:
    """Why shots ``(name, width, height)`` cannot be calibrated together (one model fits one
    image size), or None."""
    if len({(w, h) for _, w, h in shots}) <= 1:
        return None
    listing = ", ".join(f"{p} {w}x{h}" for p, w, h in shots)
    return f"images of different sizes ({listing}): one model fits one image size"


def shot_count_problem(n_shots: int, spec: FitSpec | None) -> str | None:
    """Why ``n_shots`` shots cannot choose a model (``spec`` None), or None."""
    if spec is None and n_shots < 2:
        return (
            "need at least 2 shots at different harp orientations "
            "(one orientation cannot constrain the distortion along the strings)"
        )
    return None


def holdout_warning(held_lines: Sequence[np.ndarray], holdout_d: float | None) -> str | None:
    """A warning when the correction leaves the held-out edges ``held_lines`` (uncorrected)
    less straight than they were (``holdout_d`` after correction): it does not generalise."""
    d0, _ = straightness_of(list(held_lines))
    if holdout_d is not None and holdout_d > d0:
        return (
            f"the model leaves the held-out shots less straight than uncorrected (d {d0:.4f} px "
            f"before, {holdout_d:.4f} px after): it does not generalise to other orientations"
        )
    return None


def noisy_shot_warnings(fit: FitResult, names: Sequence[str]) -> list[str]:
    """A warning per shot whose edges the correction leaves far less straight than the others' (``fit``'s kept edges;
    ``names[i]`` shot ``i``'s name): its median edge residual beyond
    :data:`pipeline.harp_shape.SHOT_NOISE_FACTOR` times the median edge's (:func:`pipeline.harp_shape.shot_weights`,
    the harp check's rule). A dim, blurred or moved shot is, and so are edges within a degree or two of the pixel grid
    after a Bayer demosaic (``benchmarks/grid_angle.py``). None with fewer than three shots (two shots' median is
    neither's)."""
    kept = [e for e in fit.edges if not e.rejected and np.isfinite(e.rms_after)]
    if len({e.image for e in kept}) < 3:
        return []
    _, noisy = shot_weights(np.array([e.rms_after for e in kept]), np.array([e.image for e in kept]))
    return [
        f"{names[i]}: its edges stay {r:.1f}x as far from straight as the median edge after the correction (beyond "
        f"{SHOT_NOISE_FACTOR:g}x: a dim, blurred or moved shot, or strings within a degree or two of the pixel rows or "
        "columns after a Bayer demosaic): check the shot, turn the harp on its mount by a few degrees if its strings "
        "lie along the grid, and capture it again"
        for i, r in sorted(noisy.items())
    ]


# ------------------------------------------------------- a focus setting


def selection_record(selection: Any, given_by: str = GIVEN_BY_CONFIG, support: str | None = None) -> dict[str, Any]:
    """How the spec was chosen, as a profile keeps it: ``{"reason", "folds"}``.

    ``selection``: the :class:`pipeline.select.Selection` of an automatic choice (its reason and
    folds), or None for a given spec (``given_by``: :data:`GIVEN_BY_CONFIG` or
    :data:`GIVEN_ON_COMMAND_LINE`, followed by ``support``, why the shots do not support that spec well,
    when they do not; folds ``"none"``). The one place a selection reason is written.
    """
    if selection is None:
        return {"reason": given_by if support is None else f"{given_by}; {support}", "folds": "none"}
    return {"reason": selection.reason, "folds": selection.folds}


# ------------------------------------------------------- two turntable-axis places
@dataclass(frozen=True)
class AxisPlaces:
    """Two-axis capture (``capture.shift_positions_mm``): the linear stage that carries the turntable sideways, per
    shot its position as the plan commanded it (the shot's axis group) and as it read back (mm); how a stage move
    shows in the image: ``direction_deg`` (``station.harp.shift_direction_deg``, from +x towards +y; None: unknown,
    each place's axis searched on its own shots, which needs four turntable angles or more there) and the harp's
    pitch in mm (``station.harp.string_spacing_mm``): the pitch the shots show in px over it is the image scale of
    the harp's plane, in which the stage moves the axis."""

    commanded_mm: tuple[float, ...]
    read_mm: tuple[float, ...]
    direction_deg: float | None
    spacing_mm: float


@dataclass(frozen=True)
class Axes:
    """What the joint fit is told of a two-axis capture (:func:`axes_of`): each shot's axis group (its stage
    position's label, :func:`place_label`), each group's rough image shift of the axis from where the axis is with
    the stage halfway between its outermost positions (px; None: each group's axis searched), the strings' pitch
    in the shots (px) and the image scale (px per mm of stage travel)."""

    places: AxisPlaces
    groups: tuple[str, ...]
    shifts: dict[str, tuple[float, float]] | None
    pitch_px: float
    px_per_mm: float

    def fit_arguments(self) -> dict[str, Any]:
        """``axis_groups`` and ``axis_shifts`` for :func:`pipeline.harp_shape.fit_harp_shape` (and the fits that
        pass them on)."""
        return {"axis_groups": self.groups, "axis_shifts": self.shifts}

    def fold(self, k: int) -> tuple[list[str], dict[str, tuple[float, float]] | None]:
        """``(axis_groups, axis_shifts)`` of the shots without shot ``k`` (a leave-one-orientation-out fold)."""
        return [g for j, g in enumerate(self.groups) if j != k], self.shifts


def place_label(mm: float) -> str:
    """The axis group of the shots taken with the linear stage at ``mm``."""
    return f"{mm:g} mm"


def _read_back(places: AxisPlaces, groups: Sequence[str]) -> dict[str, float]:
    """Each axis group's mean read-back position of the stage (mm), in the order the groups first appear."""
    return {
        g: float(np.mean([r for h, r in zip(groups, places.read_mm, strict=True) if h == g]))
        for g in dict.fromkeys(groups)
    }


def _fit_arguments(axes: Axes | None) -> dict[str, Any]:
    """:meth:`Axes.fit_arguments`, or none for one axis place."""
    return {} if axes is None else axes.fit_arguments()


def axes_of(
    places: AxisPlaces | None,
    shots: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    turntable_deg: Sequence[float],
) -> Axes | None:
    """The axis groups and rough shifts of a two-axis capture for :func:`pipeline.harp_shape.fit_harp_shape`
    (None when every shot was taken at one place: nothing changes), from the shots' edges as measured.

    The image scale is the strings' pitch in the shots (:func:`pipeline.harp_frame.string_pitch`; the lens's
    distortion changes it by its local scale only) over the harp's pitch in mm. Each group's shift is its shots'
    mean read-back position less the middle of the commanded positions, times the scale, along ``direction_deg``;
    the axis at that middle is then found, to an eighth of a pitch, on every shot moved back by its group's shift
    (:func:`pipeline.harp_frame.harp_frame` within :data:`pipeline.harp_frame.GROUP_AXIS_SEARCH` pitches of the
    image centre; it needs four turntable angles or more, else it is taken at the image centre) and the shifts are
    given from the image centre to there: :func:`pipeline.harp_frame.group_frames` searches each group's axis
    within a third of a pitch of where its shift puts it. Without ``direction_deg`` no shift is given (each group's
    axis searched on its own shots)."""
    if places is None or len(set(places.commanded_mm)) < 2:
        return None
    raw = [[np.asarray(p, np.float64) for p in s] for s in shots]
    pitch = string_pitch(raw)
    ppm = pitch / places.spacing_mm
    groups = tuple(place_label(m) for m in places.commanded_mm)
    shifts = None
    if places.direction_deg is not None and np.isfinite(ppm):
        mid = 0.5 * (min(places.commanded_mm) + max(places.commanded_mm))
        a = np.radians(places.direction_deg)
        rel = {g: (mm - mid) * ppm * np.array([np.cos(a), np.sin(a)]) for g, mm in _read_back(places, groups).items()}
        ref = np.zeros(2)  # where the axis is with the stage at the middle, from the image centre
        if distinct_orientations(turntable_deg) >= MIN_GROUP_ANGLES:
            back = [[p - rel[g] for p in s] for s, g in zip(raw, groups, strict=True) if s]
            framed = harp_frame(
                back, [float(t) for t, s in zip(turntable_deg, raw, strict=True) if s], width, height,
                reach=GROUP_AXIS_SEARCH, refine=False,
            )  # fmt: skip
            if framed:
                ref = np.asarray(framed[0].centre) - np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        shifts = {g: (float(v[0] + ref[0]), float(v[1] + ref[1])) for g, v in rel.items()}
    return Axes(places, groups, shifts, float(pitch), float(ppm))


def axis_record(axes: Axes, fit: HarpShapeFit) -> dict[str, Any]:
    """Each place's turntable axis as the joint fit found it (``HarpShapeFit.axis_groups``) against where the
    stage's travel puts it, as a profile keeps it (``harp_health["axes"]``): per place its position (mm, the
    commanded one), shots, the axis found (ideal px) and how far it is from where the travel puts it relative to
    the other places (``off_px``: with ``direction_deg`` the difference of the two displacements from their means;
    without, of the distances from the first place's axis). More than half a pitch (``limit_px``) and the strings
    were numbered at the wrong place: ``misplaced`` lists those places (QA fails the profile)."""
    found = {str(g): f for g, f in fit.axis_groups}
    labels = [g for g in dict.fromkeys(axes.groups) if g in found]
    read = _read_back(axes.places, axes.groups)
    mm = {g: read[g] for g in labels}
    centre = {g: np.asarray(found[g].centre, np.float64) for g in labels}
    off: dict[str, float] = {}
    if axes.places.direction_deg is not None:
        a = np.radians(axes.places.direction_deg)
        want = {g: mm[g] * axes.px_per_mm * np.array([np.cos(a), np.sin(a)]) for g in labels}
        mc = np.mean([centre[g] for g in labels], axis=0)
        mw = np.mean([want[g] for g in labels], axis=0)
        off = {g: float(np.hypot(*((centre[g] - mc) - (want[g] - mw)))) for g in labels}
    elif labels:
        first = labels[0]
        off = {
            g: abs(float(np.hypot(*(centre[g] - centre[first]))) - abs(mm[g] - mm[first]) * axes.px_per_mm)
            for g in labels
        }
    limit = 0.5 * axes.pitch_px
    places = [
        {
            "position_mm": float(axes.places.commanded_mm[axes.groups.index(g)]),
            "shots": axes.groups.count(g),
            "centre_px": [float(centre[g][0]), float(centre[g][1])],
            "off_px": finite_or_none(off.get(g, float("nan"))),
        }
        for g in labels
    ]
    worst = max(off.values()) if off else float("nan")
    return {
        "pitch_px": finite_or_none(axes.pitch_px),
        "px_per_mm": finite_or_none(axes.px_per_mm),
        "direction_deg": axes.places.direction_deg,
        "shift_given": axes.shifts is not None,
        "limit_px": finite_or_none(limit),
        "places": places,
        "worst_off_px": finite_or_none(worst),
        "misplaced": [p["position_mm"] for p, g in zip(places, labels, strict=True) if off.get(g, 0.0) > limit],
    }


OUTLIER_FACTOR = 3.0
"""A string is bent (QA) when its own bend exceeds the limit *and* this many times the median string's.
A lens term the fitted model lacks bends the fits of many strings at once (a test session of straight
strings whose model left d = 0.019 px showed own bends of 0.05-0.06 px on several strings); one bent
string stands out of the others. When the median string itself is beyond the limit the harp cannot be
told from the lens and QA says so without judging."""

BEND_SIGNIFICANCE = 2.0
"""A string is named bent (QA) only when its own bend is also this many standard errors or more
(``bend_se_px``): a bend that cannot be told from none is not a finding. The strings seen over little of their
length (the image's corners) carry standard errors as large as the limit: on ``benchmarks/harp_health.py``'s
harps (seeds 0..19, six angles) one session failed on a string drawn at 0.0032 px, reported at 0.0207 +- 0.0188
px, while the strings named rightly had their own bends 2.4 to 11 standard errors from none (a probe over the same
fits). About two axis places one session of twenty named a string drawn at 0.0003 px, reported at 0.0436 +- 0.0159
px: two of its shots' edges lay along the pixel grid and were measured 3.5 times worse than the others, which the
check now weighs by their noise (:data:`pipeline.harp_shape.SHOT_NOISE_FACTOR`; ``benchmarks/RESULTS-harp-health.md``).
"""

MIN_HEALTH_ORIENTATIONS = 3
"""Turntable angles the harp's self-check needs: with two, a string's bend and the lens's terms
trade (each string is seen along two lines only), and the bends found are not the strings'."""


def harp_health(
    shots: Sequence[Sequence[np.ndarray]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    spec: FitSpec,
    *,
    joint: HarpShapeFit | FitFailure | None = None,
    axes: Axes | None = None,
) -> dict[str, Any]:
    """The harp's self-check (issue 19 item 4) as a profile keeps it (``details["harp_health"]``).

    Every string's own bend fitted beside the lens ``spec`` with the shots' turntable angles
    (:func:`pipeline.harp_shape.fit_harp_shape`): per string its bend, its own bend apart from what
    every string shares (:meth:`pipeline.harp_shape.HarpShapeFit.own_bends`: a common part is a whole
    harp's or a lens term's, not one string's fault; judged within half the image's diagonal of the
    axis and, beyond it, where two shots or more see the string: ``seen_twice``) and the standard error
    (px); the worst string and the strings whose own bend exceeds :data:`pipeline.harp_shape.BEND_LIMIT_PX`,
    :data:`OUTLIER_FACTOR` times the median string's and :data:`BEND_SIGNIFICANCE` standard errors, as QA judges
    them (``bent_strings``), and those
    beyond the limit whose bend cannot be told from none (``uncertain_strings``); the shots the check weighed by
    their noise (``noisy_shots``: :data:`pipeline.harp_shape.SHOT_NOISE_FACTOR`, with each one's turntable angle);
    ``d`` with and without the strings' terms; ``{"failure": reason}`` when the joint fit cannot be made.
    ``joint``: that fit when already made (:func:`calibrate_focus` makes it once for this and the lens);
    ``axes``: the shots' turntable-axis places of a two-axis capture (:func:`axes_of`), each place's axis found
    and compared with where the stage was sent (``"axes"``: :func:`axis_record`).
    """

    if distinct_orientations(turntable_deg) < MIN_HEALTH_ORIENTATIONS:
        return {
            "limit_px": BEND_LIMIT_PX,
            "failure": f"needs >= {MIN_HEALTH_ORIENTATIONS} turntable angles 10 deg apart to tell a string's bend "
            f"from the lens (the plan has {distinct_orientations(turntable_deg)})",
        }
    hs = (
        joint
        if joint is not None
        else fit_harp_shape(
            [list(s) for s in shots],
            list(turntable_deg),
            width,
            height,
            spec,
            **_fit_arguments(axes),
        )  # fmt: skip
    )
    if not hs:
        return {"limit_px": BEND_LIMIT_PX, "failure": str(getattr(hs, "reason", "the joint fit failed"))}
    own = {k: v for k, v in hs.own_bends().items() if np.isfinite(v)}
    worst = max(own, key=lambda k: own[k]) if own else None
    typical = float(np.median(list(own.values()))) if own else float("nan")
    by_index = {s.index: s for s in hs.strings}
    se = {k: float(by_index[k].bend_se_px) for k in own}
    beyond = {k: v for k, v in own.items() if v > BEND_LIMIT_PX and v > OUTLIER_FACTOR * typical}
    return {
        "limit_px": BEND_LIMIT_PX,
        "worst_string": worst,
        "worst_bend_px": None if worst is None else own[worst],
        "worst_bend_se_px": None if worst is None else finite_or_none(by_index[worst].bend_se_px),
        "bent_strings": sorted(k for k, v in beyond.items() if v >= BEND_SIGNIFICANCE * se[k]),
        "uncertain_strings": sorted(k for k, v in beyond.items() if not v >= BEND_SIGNIFICANCE * se[k]),
        "significance": BEND_SIGNIFICANCE,
        "outlier_factor": OUTLIER_FACTOR,
        "typical_bend_px": typical,
        "strings": [
            {
                "index": s.index,
                "bend_px": finite_or_none(s.bend_px),
                "own_bend_px": own.get(s.index),
                "bend_se_px": finite_or_none(s.bend_se_px),
                "shots": s.shots,
                "span": [float(s.span[0]), float(s.span[1])],
                "seen_twice": [finite_or_none(v) for v in s.seen_twice],
            }
            for s in hs.strings
        ],
        "noisy_shots": [
            {"shot": i, "turntable_deg": float(turntable_deg[i]), "noise_ratio": r} for i, r in hs.noisy_shots
        ],
        "d_with_strings_px": finite_or_none(hs.d_after),
        "d_lens_only_px": finite_or_none(hs.d_lens_only),
    } | ({} if axes is None else {"axes": axis_record(axes, hs)})


def separate_strings(
    cal: Calibration,
    shots: Sequence[Sequence[np.ndarray]],
    turntable_deg: Sequence[float],
    width: int,
    height: int,
    joint: HarpShapeFit,
    *,
    map_fn: MapFn = map,
    bootstrap: int = 0,
    seed: int = 0,
    kinks: bool = False,
    kink_t: int = DEFAULT_T,
    axes: Axes | None = None,
) -> Calibration:
    """``cal`` with its lens replaced by the lens fitted jointly with every string's own deviation (``joint``,
    :func:`pipeline.harp_shape.fit_harp_shape` of the same shots, angles and spec).

    A string is straight to a few micrometres, not exactly; a lens fitted alone takes the part of the
    strings' bends that all orientations share into the correction (the realistic simulator's field error
    was dominated by it). The joint fit gives that part back to the strings (issue 19 items 4 and 5:
    ``benchmarks/strings_separated.py``). The figures are re-made for the stored lens: the fit's
    (points corrected by the lens alone, :func:`pipeline.harp_shape.lens_result`) and the
    leave-one-orientation-out hold-out, each fold fitted with the strings separated on the other
    orientations (:func:`pipeline.harp_shape.separated_job`), and with ``bootstrap >= 2`` replicates the
    field uncertainty of the separated lens (every replicate fitted with the strings separated, ``seed``
    as for the lens alone). With ``kinks`` (``joint`` fitted with them) ``details["strings"]["kinks"]`` lists
    those of ``joint`` (``kink_t``: the subsampling factor the edges were measured with, which sets the kinks'
    template), and when ``joint`` found any, the hold-out's folds and the bootstrap's replicates find and model
    each string's kinks too (:mod:`pipeline.harp_kinks`). When it found none they do not look: a fold or a
    replicate sees a subset of the same strings' points, and a kink's significance grows with the shots that see
    it, so one the fit on all shots does not find is not significant in a fold either; this keeps a session
    whose strings have no kink at the cost of one scan per focus. ``details["strings"]`` records what
    was done and the lens-alone figures; when the lens cannot be separated (a fold fails, the lens folds)
    ``cal`` is returned with the reason there and its plain lens. ``axes``: a two-axis capture's groups and shifts
    (:func:`axes_of`; ``joint`` fitted with them), which every fold and replicate is fitted with too."""
    spec = cal.spec
    full = cal.fit
    if spec is None or not full:
        return cal
    lines = [list(s) for s in shots]
    plain_record: dict[str, Any] = {
        "fit_d_lens_alone_px": finite_or_none(full.d_after),
        "holdout_d_lens_alone_px": None if cal.merit.holdout is None else cal.merit.holdout.d,
    }

    def kept_plain(reason: str) -> Calibration:
        rec = {"separated": False, "reason": reason, **plain_record}
        return dataclasses.replace(cal, details={**cal.details, "strings": rec})

    res = lens_result(joint, lines, width, height)
    if not res:
        return kept_plain(f"the lens with the strings separated: {res.reason}")
    # a fold or a replicate looks for kinks only where the fit on all shots found some (docstring)
    kink_job = functools.partial(separated_kinks_job, t=kink_t) if kinks and joint.kinks else None
    hold = cal.merit.holdout
    if hold is not None and hold.scheme == HOLDOUT_LEAVE_ONE_ORIENTATION_OUT:
        jobs: list[Any] = [
            (
                [ls for j, ls in enumerate(lines) if j != k],
                [float(a) for j, a in enumerate(turntable_deg) if j != k],
                width,
                height,
                spec,
                *(() if axes is None else axes.fold(k)),
            )
            for k in range(len(lines))
        ]
        job_fn = kink_job if kink_job is not None else separated_job
        loo = _orientation_holdout(lines, full.rejected, job_fn, jobs, map_fn)
        if not isinstance(loo, _OrientationHoldout):
            return kept_plain(f"without orientation {loo[0]} the strings cannot be separated: {loo[1]}")
        hold = loo.holdout
        own_record: dict[str, Any] | None = own_shift_record(loo.own)
    else:
        own_record = None
    record: dict[str, Any] = {
        "separated": True,
        "d_with_strings_px": finite_or_none(joint.d_after),
        **plain_record,
    }
    if kinks:
        record["kinks"] = [k.to_dict() for k in joint.kinks]
    details: dict[str, Any] = {**cal.details, "n_params": res.n_params}
    if own_record is not None:  # the stored lens's folds: with the strings separated
        details["own_shift"] = own_record
    unc, unc_summary = cal.uncertainty, cal.merit.field_uncertainty
    if bootstrap >= 2:
        boot = bootstrap_field_uncertainty(
            lines, width, height, spec, n_boot=bootstrap, seed=seed, full_fit=res, map_fn=map_fn,
            turntable_deg=turntable_deg, separated_fn=kink_job, **_fit_arguments(axes),
        )  # fmt: skip
        if cal.merit.field_uncertainty is not None:
            record["field_uncertainty_lens_alone_px"] = cal.merit.field_uncertainty.rms
        if not boot:
            unc, unc_summary = None, None
            details.update(bootstrap_replicates=0, bootstrap_failed=bootstrap, bootstrap_failure=boot.reason)
        else:
            unc = boot
            unc_summary = UncertaintySummary(float(boot.rms), float(boot.max), int(boot.n_boot))
            details.pop("bootstrap_failure", None)
            details.update(bootstrap_replicates=boot.n_boot, bootstrap_failed=boot.n_failed)
    merit = dataclasses.replace(
        cal.merit, fit=_figures(res.d_after, res.d_max_after), holdout=hold, field_uncertainty=unc_summary
    )
    details["strings"] = record
    return dataclasses.replace(cal, fit=res, merit=merit, uncertainty=unc, details=details)


def calibrate_focus(
    shots: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    pipeline: Any,
    focus_idx: int,
    spec: FitSpec | None,
    *,
    map_fn: MapFn = map,
    turntable_deg: Sequence[float] | None = None,
    axis_places: AxisPlaces | None = None,
) -> Calibration:
    """The calibration of one focus setting of a session: its orientations' edges (``shots``, one
    per orientation) fitted by :func:`calibrate_shots` with each orientation held out in turn,
    the configuration's bootstrap (``pipeline.bootstrap``) and seed (``pipeline.seed + 1000 *
    focus_idx``). ``spec``: what to fit (None: chosen by cross-validation). The executor and
    ``harp reprocess`` both call this, so re-processing fits what the session fitted.
    ``turntable_deg``: each shot's turntable angle; given, the harp checks itself
    (:func:`harp_health`, kept in ``details["harp_health"]``) and, with ``pipeline.strings`` =
    ``"separate-kinks"`` (the default: each string's kinks found and modelled as well) or ``"separate"`` and
    :data:`MIN_HEALTH_ORIENTATIONS` or more orientations, the profile's
    lens is the one fitted with the strings' own bends separated (:func:`separate_strings`), and an automatic
    choice (``spec`` None) with ``pipeline.choice_folds`` = ``"strings-separated"`` cross-validates every candidate
    so too: each fold fitted with the strings separated, each held-out shot judged with its strings' fitted bends
    removed (:mod:`pipeline.separated_cv`; not the default: :data:`pipeline.fitspec.CHOICE_FOLDS`); with
    ``"separate-kinks"`` those folds, and the field stage's, find and model each string's kinks as well, as the
    stored lens is fitted.
    ``axis_places``: each shot's linear-stage position of a two-axis capture (``capture.shift_positions_mm``);
    when the shots span two places or more, the joint fit, its folds and its bootstrap replicates find each
    place's turntable axis (:func:`axes_of`), as do an automatic choice's strings-separated folds, and the harp's
    self-check reports them (:func:`axis_record`). One place, or None: nothing changes. ``pipeline.field`` =
    ``"auto"``: a residual field is added to the model when it holds on unseen orientations
    (:func:`pipeline.select.select_field`), its folds fitted with the strings separated when they are."""
    strings = getattr(pipeline, "strings", STRINGS_KINKS)
    separate = strings in (STRINGS_SEPARATE, STRINGS_KINKS)
    kinks = separate and strings == STRINGS_KINKS
    kink_t = getattr(pipeline, "t", DEFAULT_T)  # the kinks' template follows the edges' subsampling
    by_strings = getattr(pipeline, "choice_folds", CHOICE_FOLDS_PLAIN) == CHOICE_FOLDS_STRINGS
    known = turntable_deg is not None and len(turntable_deg) == len(shots)
    axes = axes_of(axis_places, shots, width, height, turntable_deg) if known and turntable_deg is not None else None
    cal = calibrate_shots(
        [list(s) for s in shots],
        width,
        height,
        spec,
        holdout="orientations",
        bootstrap=pipeline.bootstrap,
        seed=pipeline.seed + 1000 * focus_idx,
        map_fn=map_fn,
        turntable_deg=turntable_deg if separate and by_strings and known else None,
        field=getattr(pipeline, "field", FIELD_NONE),
        field_turntable_deg=turntable_deg if separate and known else None,
        kink_t=kink_t if kinks else None,
        **_fit_arguments(axes),
    )
    if turntable_deg is None or cal.failure is not None or cal.spec is None:
        return cal
    joint: HarpShapeFit | FitFailure | None = None
    if distinct_orientations(turntable_deg) >= MIN_HEALTH_ORIENTATIONS and cal.fit:
        joint = fit_harp_shape(
            [list(s) for s in shots], list(turntable_deg), width, height, cal.spec, plain=cal.fit, kinks=kinks,
            kink_t=kink_t, **_fit_arguments(axes),
        )  # fmt: skip
    health = harp_health(shots, turntable_deg, width, height, cal.spec, joint=joint, axes=axes)
    cal = dataclasses.replace(cal, details={**cal.details, "harp_health": health})
    if not separate:
        return cal
    if not isinstance(joint, HarpShapeFit):
        reason = health.get("failure", "the strings cannot be separated")
        rec = {"separated": False, "reason": reason}
        return dataclasses.replace(cal, details={**cal.details, "strings": rec})
    return separate_strings(
        cal, shots, turntable_deg, width, height, joint, map_fn=map_fn, bootstrap=pipeline.bootstrap,
        seed=pipeline.seed + 1000 * focus_idx, kinks=kinks, kink_t=kink_t, axes=axes,
    )  # fmt: skip


def focus_profile(
    cal: Calibration,
    width: int,
    height: int,
    config: Any,
    focus_idx: int,
    *,
    provenance: Provenance,
    given_by: str = GIVEN_BY_CONFIG,
    details: Mapping[str, Any] | None = None,
    intrinsics: Any = None,
    judge: Callable[[Profile], Any] | None = None,
) -> Profile:
    """The judged profile of a focus setting's calibration ``cal`` (:func:`calibrate_focus`).

    ``intrinsics``: its measured camera matrix (:class:`pipeline.intrinsics.Intrinsics`, the session's
    ``intrinsics`` stage), kept before it is judged; None: none measured.

    The session's identities (lens, camera body, focus, a zoom session's focal length, optics), the selection record
    (:func:`selection_record`), the capture's details (orientations, frames per orientation,
    ``t``) plus ``details``, and the verdict ``judge(profile)`` (QA, passed in: the QA imports
    this module; :func:`station.qa.verdicts.qa_verdict` of the configuration's thresholds on the
    edges it was fitted on). ``judge`` None: not judged. Raises ValueError for a failed calibration.
    """
    profile = cal.profile(
        width,
        height,
        provenance=provenance,
        lens=config.lens,
        camera=config.camera_body,
        focus=config.focus_settings[focus_idx],
        given_by=given_by,
        details={
            **dict(details or {}),
            "orientations_deg": list(config.capture.orientations_deg),
            **({"twin_deg": config.capture.twin_deg} if config.capture.twin_deg is not None else {}),
            **({"shift_positions_mm": list(shifts)} if (shifts := config.capture.shift_positions_mm) else {}),
            "frames_per_orientation": config.capture.frames_per_orientation,
            "t": config.pipeline.t,
        },
    )
    profile = profile.with_(
        focal=getattr(config, "focal", None),  # a zoom session's part: its focal length (mm)
        optics=config.optics,  # for exports: nominal focal, pixel pitch, crop factor, mount
    )
    if intrinsics is not None:
        profile = profile.with_(intrinsics=intrinsics)
    if judge is None:
        return profile
    return profile.with_(qa=judge(profile))
