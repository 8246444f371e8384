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
from pipeline.harp_shape import (
    SHOT_NOISE_FACTOR,
    HarpShapeFit,
    fit_harp_shape,
    lens_result,
    separated_job,
    separated_kinks_job,
    shot_weights,
)
from pipeline.orientations import distinct_orientations, support_problem
from pipeline.own_shift import OwnShift, own_axis_shift
from pipeline.plain import finite_or_none
from pipeline.resample import DEFAULT_T
from pipeline.select import lowest_radial, select_field, select_model
from pipeline.uncertainty import bootstrap_field_uncertainty, refit_job
from station.axis_places import Axes, AxisPlaces, axes_of, axis_fit_arguments
from station.equipment import Identity
from station.harp_health import MIN_HEALTH_ORIENTATIONS, harp_health
from station.moving_lens import MIN_OWN_SHIFT_ORIENTATIONS, own_shift_record
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


def shot_own_shifts(
    shots: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    spec: FitSpec,
    rejected: Sequence[Any] = (),
    map_fn: MapFn = map,
) -> dict[str, Any] | None:
    """The own-shift record (:func:`station.moving_lens.own_shift_record`) of shots without turntable angles (``harp calibrate``): each
    shot held out in turn, ``spec`` fitted on the others (``map_fn`` maps the fits), its edges but the full fit's
    ``rejected`` measured under that fit and under it moved for them alone (two shots at one angle are compared
    directly by :func:`station.moving_lens.twin_record`). None with fewer than
    :data:`station.moving_lens.MIN_OWN_SHIFT_ORIENTATIONS` shots or when a fold's fit fails."""
    if len(shots) < MIN_OWN_SHIFT_ORIENTATIONS:
        return None
    loo = _refit_holdout(shots, width, height, spec.fit_arguments(), rejected, map_fn)
    return own_shift_record(loo.own) if isinstance(loo, _OrientationHoldout) else None


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
        shifts (:func:`station.axis_places.axes_of`) for those folds.
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
    """How the spec was chosen, as a profile keeps it: ``{"reason", "folds"}``, and ``"support"`` when the shots
    do not support it well (:func:`pipeline.orientations.support_problem`: too few string orientations; the QA
    report shows it as a warning).

    ``selection``: the :class:`pipeline.select.Selection` of an automatic choice (its reason, which says it, its
    folds and support), or None for a given spec (``given_by``: :data:`GIVEN_BY_CONFIG` or
    :data:`GIVEN_ON_COMMAND_LINE`, followed by ``support``, why the shots do not support that spec well,
    when they do not; folds ``"none"``). The one place a selection reason is written.
    """
    if selection is None:
        rec = {"reason": given_by if support is None else f"{given_by}; {support}", "folds": "none"}
    else:
        rec = {"reason": selection.reason, "folds": selection.folds}
        support = selection.support
    return rec if support is None else {**rec, "support": support}


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
    (:func:`station.axis_places.axes_of`; ``joint`` fitted with them), which every fold and replicate is fitted with too."""
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
            turntable_deg=turntable_deg, separated_fn=kink_job, **axis_fit_arguments(axes),
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
    (:func:`station.harp_health.harp_health`, kept in ``details["harp_health"]``) and, with ``pipeline.strings`` =
    ``"separate-kinks"`` (the default: each string's kinks found and modelled as well) or ``"separate"`` and
    :data:`station.harp_health.MIN_HEALTH_ORIENTATIONS` or more orientations, the profile's
    lens is the one fitted with the strings' own bends separated (:func:`separate_strings`), and an automatic
    choice (``spec`` None) with ``pipeline.choice_folds`` = ``"strings-separated"`` cross-validates every candidate
    so too: each fold fitted with the strings separated, each held-out shot judged with its strings' fitted bends
    removed (:mod:`pipeline.separated_cv`; not the default: :data:`pipeline.fitspec.CHOICE_FOLDS`); with
    ``"separate-kinks"`` those folds, and the field stage's, find and model each string's kinks as well, as the
    stored lens is fitted.
    ``axis_places``: each shot's linear-stage position of a two-axis capture (``capture.shift_positions_mm``);
    when the shots span two places or more, the joint fit, its folds and its bootstrap replicates find each
    place's turntable axis (:func:`station.axis_places.axes_of`), as do an automatic choice's strings-separated folds, and the harp's
    self-check reports them (:func:`station.axis_places.axis_record`). One place, or None: nothing changes. ``pipeline.field`` =
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
        **axis_fit_arguments(axes),
    )
    if turntable_deg is None or cal.failure is not None or cal.spec is None:
        return cal
    joint: HarpShapeFit | FitFailure | None = None
    if distinct_orientations(turntable_deg) >= MIN_HEALTH_ORIENTATIONS and cal.fit:
        joint = fit_harp_shape(
            [list(s) for s in shots], list(turntable_deg), width, height, cal.spec, plain=cal.fit, kinks=kinks,
            kink_t=kink_t, **axis_fit_arguments(axes),
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
