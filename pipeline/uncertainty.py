r"""Bootstrap uncertainty of a fitted correction field.

How well do the data determine the correction at each pixel? The bootstrap
(Efron 1979) answers without a noise model: refit the correction on
resampled data sets and look at how much the fitted field moves.

Resampling units. Points of one edge are not independent (the edge detector
and the t-smoothing correlate neighbours; a string may be slightly bent), so
the unit is a whole *string* (its two edges, lines ``2k, 2k+1`` as
:mod:`pipeline.measure` lists them, share the string's shape): each replicate
draws, within each image, as many strings as that image has, with replacement
(``resample="edges"``; keeps every orientation in every replicate, which the
fit needs). ``resample="images"``
draws whole shots instead, which also captures shot-to-shot effects but needs
many orientations (a replicate that lost the orientation spread is counted as
failed, not silently dropped).

Comparison modulo homography. A straight-line fit determines the correction
only up to a homography, so replicate :math:`b` with correction :math:`U_b`
is compared with the full-data fit :math:`U` after the best homography
:math:`H_b` (least squares over the grid, :func:`pipeline.compare.fit_homography`):

.. math::
    r_b(p) = H_b(U_b(p)) - U(p), \qquad
    \sigma(p) = \Big(\tfrac{1}{B-1}\sum_b |r_b(p) - \bar r(p)|^2\Big)^{1/2}

:math:`\sigma(p)` (pixels) is the per-pixel uncertainty map on a coarse grid
covering the image (corners included); its RMS and max over the grid are the
figures a profile stores.

Cost. Edges the full fit rejected as outliers are dropped before resampling,
and each replicate is a plain least-squares fit started from the full fit
(``robust=False``, ``init=``), so a replicate costs a few LM iterations.

References
----------
.. [1] B. Efron, "Bootstrap methods: another look at the jackknife",
   Ann. Statist. 7(1), 1979.
.. [2] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

from pipeline.compare import fit_homography
from pipeline.edgeset import FitFailure, FitResult
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import separated_job
from pipeline.models.base import DistortionModel

RESAMPLE = ("edges", "images")
DEFAULT_N_BOOT = 20
GRID_CELLS = 16
"""Default uncertainty grid: this many cells along the longer image side."""

RefitJob: TypeAlias = tuple[Sequence[Sequence[np.ndarray]], int, int, dict[str, Any]]
"""One replicate fit for :func:`refit_job`: ``(lines_per_image, width, height, fit_kwargs)``."""
RefitOutcome: TypeAlias = tuple[DistortionModel | None, str | None]
"""``(model, None)`` or ``(None, reason)``."""
MapFn: TypeAlias = Callable[[Callable[[Any], RefitOutcome], Iterable[Any]], Iterable[RefitOutcome]]
"""A ``map``-like runner of the replicate fits (``map`` itself, a process pool's ``map``)."""


@dataclass(frozen=True)
class FieldUncertainty:
    """Per-pixel bootstrap uncertainty of a correction (pixels).

    ``std[j, i]`` is the uncertainty at ``(xs[i], ys[j])``; ``rms`` / ``max``
    over the grid. ``model`` is the full-data fit the replicates are compared
    with; ``n_boot`` replicates succeeded, ``n_failed`` did not (reasons in
    ``failures``, at most a few).
    """

    rms: float
    max: float
    xs: np.ndarray
    ys: np.ndarray
    std: np.ndarray
    n_boot: int
    n_failed: int
    resample: str
    model: DistortionModel
    failures: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """Plain data (for JSON / a profile's details)."""
        return {
            "rms_px": self.rms,
            "max_px": self.max,
            "n_boot": self.n_boot,
            "n_failed": self.n_failed,
            "resample": self.resample,
            "xs": self.xs.tolist(),
            "ys": self.ys.tolist(),
            "std_px": self.std.tolist(),
        }


def uncertainty_grid(width: int, height: int, cells: int = GRID_CELLS) -> tuple[np.ndarray, np.ndarray]:
    """Coarse node coordinates ``(xs, ys)`` spanning the image, corners included."""
    step = (max(width, height) - 1) / float(cells)
    nx = max(2, int(round((width - 1) / step)) + 1)
    ny = max(2, int(round((height - 1) / step)) + 1)
    return np.linspace(0.0, width - 1.0, nx), np.linspace(0.0, height - 1.0, ny)


def field_spread(
    models: Sequence[DistortionModel], reference: DistortionModel, xs: np.ndarray, ys: np.ndarray
) -> np.ndarray:
    """Per-node std ``(ny, nx)`` of ``models`` modulo homography, aligned to ``reference``."""
    xx, yy = np.meshgrid(xs, ys)
    grid = np.stack([xx.ravel(), yy.ravel()], axis=1)
    ref = reference.undistort_points(grid)
    res = []
    for m in models:
        _, r = fit_homography(m.undistort_points(grid), ref)
        res.append(r)
    stacked = np.stack(res)  # (B, N, 2)
    var = np.sum(np.var(stacked, axis=0, ddof=1), axis=1)
    spread: NDArray[np.float64] = np.sqrt(var).reshape(xx.shape)
    return spread


def refit_job(job: RefitJob) -> RefitOutcome:
    """One replicate fit ``(lines_per_image, width, height, fit_kwargs)`` -> ``(model, None)``
    or ``(None, reason)``; module-level so that a process pool can run it."""
    lines, width, height, kw = job
    res = fit_distortion(lines, width, height, **kw)
    if not res:
        return None, res.reason
    return res.model, None


def bootstrap_field_uncertainty(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    spec: FitSpec | None = None,
    *,
    n_boot: int = DEFAULT_N_BOOT,
    seed: int = 0,
    resample: str = "edges",
    cells: int = GRID_CELLS,
    full_fit: FitResult | None = None,
    map_fn: MapFn = map,
    turntable_deg: Sequence[float] | None = None,
    separated_fn: Callable[[Any], RefitOutcome] | None = None,
    axis_groups: Sequence[Hashable] | None = None,
    axis_shifts: Mapping[Hashable, Sequence[float]] | None = None,
) -> FieldUncertainty | FitFailure:
    """Bootstrap the correction fit and map the spread of the fitted field.

    Parameters
    ----------
    lines_per_image : sequence over images of sequences of (M, 2) arrays
        The edge points the correction is fitted on (as for
        :func:`pipeline.fit.fit_distortion`).
    width, height : int
        Image size.
    spec : FitSpec, optional
        What to fit (default ``FitSpec()``, radial degree 4); every replicate fits
        exactly this spec, with ``robust=False`` and started from the full fit.
    n_boot : int
        Number of replicates (>= 2; default 20: cheap, and the RMS figure is
        then good to about +-15 %).
    seed : int
        Seed of the resampling RNG (same seed, same result).
    resample : {'edges', 'images'}
        Resampling unit (module doc).
    cells : int
        Grid cells along the longer image side for the map.
    full_fit : FitResult, optional
        The full-data fit of ``spec``, if already computed.
    map_fn : callable
        ``map``-like runner of the replicate fits (e.g. a process pool's
        ``map``, with :func:`refit_job` as the picklable job); results do not
        depend on it.
    turntable_deg : sequence of float, optional
        Each image's turntable angle; given, every replicate is the lens fitted with the strings'
        own bends separated (:func:`pipeline.harp_shape.separated_job`, the whole fit from the
        resampled edges) and ``full_fit`` should be that lens's
        (:func:`pipeline.harp_shape.lens_result`): the spread is then the separated lens's.
    separated_fn : callable, optional
        The job that fits such a replicate (default :func:`pipeline.harp_shape.separated_job`; e.g.
        :func:`pipeline.harp_shape.separated_kinks_job` to model each string's kinks as well).
    axis_groups, axis_shifts : optional
        With ``turntable_deg``, each image's turntable-axis group and the groups' rough image shifts when the
        harp was moved between groups of shots (:func:`pipeline.harp_shape.fit_harp_shape`): every replicate's
        images keep their groups.

    Returns
    -------
    FieldUncertainty or FitFailure
        A failure when the full fit fails or fewer than 2 replicates succeed.
    """
    if resample not in RESAMPLE:
        raise ValueError(f"unknown resampling unit {resample!r}; known: {', '.join(RESAMPLE)}")
    if int(n_boot) < 2:
        raise ValueError(f"n_boot must be >= 2, got {n_boot}")
    kw = (spec or FitSpec()).fit_arguments()
    full = full_fit if full_fit is not None else fit_distortion(lines_per_image, width, height, **kw)
    if not full:
        return FitFailure(f"full fit failed: {full.reason}")
    # the data the full fit used: without its rejected (outlier / unusable) edges
    dropped = {(r.image, r.line) for r in full.rejected}
    data = [
        [np.asarray(p, np.float64) for j, p in enumerate(lines) if (i, j) not in dropped]
        for i, lines in enumerate(lines_per_image)
    ]
    angles = (
        None if turntable_deg is None else [float(a) for a, lines in zip(turntable_deg, data, strict=True) if lines]
    )
    image_groups = None if axis_groups is None else [g for g, lines in zip(axis_groups, data, strict=True) if lines]
    data = [lines for lines in data if lines]
    # resampling units of "edges": strings, i.e. lines 2k, 2k+1 (pipeline.measure lists a string's
    # two edges next to each other), grouped before dropping so a rejected edge keeps the pairing
    strings = [
        [
            g
            for g in (
                [np.asarray(p, np.float64) for j, p in enumerate(lines) if j // 2 == k and (i, j) not in dropped]
                for k in range((len(lines) + 1) // 2)
            )
            if g
        ]
        for i, lines in enumerate(lines_per_image)
    ]
    string_angles = (
        None
        if turntable_deg is None
        else [float(a) for a, groups in zip(turntable_deg, strings, strict=True) if groups]
    )
    string_groups = None if axis_groups is None else [g for g, gs in zip(axis_groups, strings, strict=True) if gs]
    strings = [gs for gs in strings if gs]
    rkw = {**kw, "robust": False, "init": full.model}
    rng = np.random.default_rng(seed)
    jobs: list[Any] = []
    for _ in range(int(n_boot)):  # all resampling first: the result does not depend on map_fn
        if resample == "edges":
            sample = [[p for k in rng.integers(0, len(groups), len(groups)) for p in groups[k]] for groups in strings]
            sample_angles, sample_groups = string_angles, string_groups
        else:
            picks = rng.integers(0, len(data), len(data))
            sample = [data[k] for k in picks]
            sample_angles = None if angles is None else [angles[k] for k in picks]
            sample_groups = None if image_groups is None else [image_groups[k] for k in picks]
        if sample_angles is None:
            jobs.append((sample, width, height, rkw))
        elif sample_groups is None:
            jobs.append((sample, sample_angles, width, height, spec or FitSpec()))
        else:
            jobs.append((sample, sample_angles, width, height, spec or FitSpec(), sample_groups, axis_shifts))
    models: list[DistortionModel] = []
    failures: list[str] = []
    n_failed = 0
    job_fn = refit_job if turntable_deg is None else (separated_fn or separated_job)
    for model, reason in map_fn(job_fn, jobs):
        if model is None:
            n_failed += 1
            if len(failures) < 3 and reason is not None:  # (a failed replicate always has a reason)
                failures.append(reason)
            continue
        models.append(model)
    if len(models) < 2:
        return FitFailure(
            f"only {len(models)} of {n_boot} bootstrap replicates could be fitted"
            + (f" (e.g. {failures[0]})" if failures else "")
        )
    xs, ys = uncertainty_grid(width, height, cells)
    std = field_spread(models, full.model, xs, ys)
    return FieldUncertainty(
        rms=float(np.sqrt(np.mean(std**2))),
        max=float(std.max()),
        xs=xs,
        ys=ys,
        std=std,
        n_boot=len(models),
        n_failed=n_failed,
        resample=resample,
        model=full.model,
        failures=tuple(failures),
    )
