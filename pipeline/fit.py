r"""Fit a distortion model that straightens every harp edge of every shot at once.

The objective (Tang et al. 2012, Sect. 3) is the sum over all points of the
squared signed distance of the *corrected* point to the total-least-squares
(TLS) line of its own corrected edge:

.. math::
    C(\theta) = \sum_{e} \sum_{i \in e} \big(n_e(\theta)\cdot(U_\theta(p_i) - m_e(\theta))\big)^2

where :math:`m_e` is the centroid and :math:`n_e` the unit normal of the TLS
line of :math:`\{U_\theta(p_i)\}_{i\in e}`. The lines are not free parameters:
they are recomputed from the corrected points at every evaluation (variable
projection); the Jacobian is analytic, including the derivative of the line
(centroid and angle) with respect to :math:`\theta` and the centre columns of
the radial model. It is minimised by
Levenberg–Marquardt, all edges of all images at once, in coordinates normalised
by half the image diagonal: MINPACK's algorithm (trust region, scaling, stopping
rules) on the normal equations :math:`J^T J`, :math:`J^T r`, which the per-edge
moments give without forming the :math:`N \times n` Jacobian
(:func:`pipeline.fit_problem.normal_equations`); MINPACK itself (``scipy.optimize.least_squares``)
when that cannot finish.

Uniqueness (gauge). Straight lines stay straight under any homography, so the
data determine the correction only up to a homography (8 degrees of freedom);
the fit fixes them as follows.

* ``radial``: the model can only express scale, not rotation, shear or
  translation (a shift of the centre is not a translation), so the scale is
  fixed by ``k0 = 1``. With tangential *and* thin-prism terms, the combination
  ``(p1, p2, s1, s3) = (a, b, -b, -a)`` is, to first order, the projective part
  of a homography; it is removed by a penalty on ``p1 - s3`` and ``p2 - s1``.
  The centre is only weakly determined (a shift of the centre is, to first
  order, a tangential term); a penalty ``w_center`` (default 1e-5: a free
  centre; a spec with a centre prior, :mod:`pipeline.fitspec`, uses 1e-2) keeps it
  near the image centre when the data cannot place it.
* ``poly``: the constant and linear terms are fixed to the identity
  (6 degrees of freedom: translation, rotation, scale, shear) and the
  first-order projective part is removed by constraining the quadratic terms
  to ``b_11 = -a_20`` and ``b_02 = -a_11`` (the projection on the two
  projective directions ``a_20 + b_11``, ``a_11 + b_02`` is zero). A weak
  ridge on the coefficients of degree >= 2 fixes what few orientations cannot
  see (e.g. with only horizontal and vertical strings, any ``x_u = g(x)``,
  ``y_u = h(y)`` keeps every string straight).
* ``radial`` with a residual field (:mod:`pipeline.models.radial_field`): the radial
  part as above; the field's affine part (translation, rotation, scale, shear: invisible,
  and the null space of its roughness penalty) is held at zero by a penalty on its
  projection, and its first-order projective (quadratic) part, like everything it could
  bend along strings few orientations cannot see, by the roughness penalty.

What to fit is a :class:`pipeline.fitspec.FitSpec` (its ``fit_arguments()`` are the
keyword arguments of :func:`fit_distortion`); each model's free parameters live beside
the model (:class:`~pipeline.models.radial.RadialParametrisation`,
:class:`~pipeline.models.polynomial.PolynomialParametrisation`); the edges, their TLS
lines and the result types are :mod:`pipeline.edgeset`'s.

Robustness: a first fit is followed by a fit where each edge is down-weighted
by the Huber weight ``min(1, 3 m / rms_e)`` of its RMS residual ``rms_e``
(``m`` the median edge RMS), then edges whose RMS residual is an outlier
(``> reject_factor x`` the median edge RMS) are rejected, reported with their
(image, line) index and reason, and the final fit (plain least squares) uses
the remaining edges. (When no edge is down-weighted the weighted fit is the
first one, and when moreover none is rejected the final fit is too: they are
not run again.)

Optionally (``point_loss``, default off) the final fit is followed by iteratively
reweighted least squares on each point (:mod:`pipeline.robust_points`): a point's
residual about its edge's smooth trend, judged against its own scale by Tukey's
biweight or Huber's weight, so that a string's kink (a few points far off their
edge's course) stops pulling the lens when the whole edge does not stand out
(off by default: it does not help the realistic population, benchmarks/RESULTS-robust-points.md).

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision
   camera distortion measurements with a calibration harp", JOSA A 29(10), 2012.
.. [2] Z. Tang et al., "Lens distortion correction with a calibration harp", ICIP 2011.
.. [3] G. H. Golub, V. Pereyra, "The differentiation of pseudo-inverses and
   nonlinear least squares problems whose variables separate", SIAM J. Numer.
   Anal. 10(2), 1973.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from pipeline.alvarez import alvarez_initial_k
from pipeline.edgeset import (
    EdgeSet,
    FitFailure,
    FitResult,
    RejectedEdge,
    collect,
    edge_figures,
    summarise,
    tls,
)
from pipeline.fit_problem import Parametrisation, make_parametrisation, residuals_and_jacobian
from pipeline.fit_solver import solve
from pipeline.fitspec import CENTER_PRIOR_WEIGHT, FREE_CENTER_WEIGHT, FitSpec, spec_problem
from pipeline.models.base import DistortionModel
from pipeline.models.radial import RadialParametrisation
from pipeline.models.radial_field import RadialFieldParametrisation
from pipeline.orientations import MIN_ORIENTATION_SPREAD_DEG
from pipeline.robust_points import POINT_LOSSES, PointLoss, robust_point_weights

MIN_EDGES = 4
"""A fit needs at least this many usable edges."""

REJECT_FACTOR = 5.0
"""An edge whose residual RMS exceeds this times the median edge RMS is an outlier (:func:`fit_distortion`;
the joint fit with the strings applies the same rule, :func:`pipeline.harp_shape.fit_harp_shape`)."""

MAX_REJECT_FRACTION = 0.25
"""At most this fraction of the edges is rejected as outliers (the worst first)."""

FAR_CENTRE = 0.05
"""A free distortion centre farther than this from the image centre (in half image diagonals) is
checked against the fit started from the centre-prior solution (:func:`fit_distortion`)."""

MIN_CORRECTION_SCALE = 0.8
"""Least linear scale of a fitted correction over the image (:func:`correction_scale`). The straightness
of corrected edges is measured in corrected pixels, so a correction that shrinks the whole image makes every
edge straighter by the same factor: with the distortion centre free (its scale is held to 1 only there) a fit
can slide that way, moving the centre far outside the image and shrinking the image to a fraction of its size
(seen to 0.12-0.34 in joint fits of a radial model with a weakly penalised field on realistic renders,
``pipeline.harp_shape``). A lens's correction is within a few per cent of 1 (0.987-1.036 over 200 lenses of
:mod:`pipeline.lens_population`; a -20 % pincushion at the corners would be needed for 0.8): below this the fit
has collapsed. :func:`fit_distortion` refuses it (:func:`correction_problem`); the joint fit of lens and strings
is made again with the centre held (:func:`pipeline.harp_shape.fit_harp_shape`)."""

POINT_ITERATIONS = 5
"""Most reweightings of the per-point robust stage (``fit_distortion(point_loss=...)``)."""
POINT_WEIGHT_TOL = 1e-3
"""The per-point robust stage stops when no point's weight changes by more than this."""
MIN_POINT_WEIGHT = 1e-6
"""A point's robust weight is kept above this (an edge whose points all lose their weight keeps a line)."""


def _kept_points(every: EdgeSet, kept: EdgeSet) -> np.ndarray:
    """Mask over ``every``'s points of those of the edges in ``kept`` (matched by image and line)."""
    keys = set(zip(kept.image.tolist(), kept.line.tolist(), strict=True))
    on = np.array([k in keys for k in zip(every.image.tolist(), every.line.tolist(), strict=True)])
    out: np.ndarray = np.repeat(on, every.counts)
    return out


def _times(base: np.ndarray | None, robust_w: np.ndarray) -> np.ndarray:
    """The points' weights in the least squares: their own (``base``, None for 1) times their robust ones."""
    return robust_w if base is None else base * robust_w


# ------------------------------------------------------------ input checks
def _orientation_problem(edges: EdgeSet, min_spread_deg: float) -> str | None:
    """None if the edges have at least two orientations, else the reason."""
    st, ct = edges.starts, edges.counts
    m = np.add.reduceat(edges.xy, st, axis=0) / ct[:, None]
    dev = edges.xy - np.repeat(m, ct, axis=0)
    sxx = np.add.reduceat(dev[:, 0] ** 2, st)
    syy = np.add.reduceat(dev[:, 1] ** 2, st)
    sxy = np.add.reduceat(dev[:, 0] * dev[:, 1], st)
    r = np.arctan2(2 * sxy, sxx - syy)  # doubled angle
    z = np.exp(1j * np.asarray(r))
    mean = np.angle(z.mean()) if abs(z.mean()) > 1e-9 else 0.0
    off = np.degrees(np.abs(np.angle(z * np.exp(-1j * mean)))) / 2.0
    n_off = int(np.sum(off > min_spread_deg / 2.0))
    if n_off < 2:
        return (
            f"all {len(z)} edges lie within {2 * float(off.max()):.1f} deg of one orientation "
            f"({np.degrees(mean) / 2 % 180:.1f} deg): one orientation cannot constrain the "
            f"distortion along the strings; give shots of the harp at >= 2 orientations "
            f"at least {min_spread_deg:g} deg apart"
        )
    return None


def _jacobian_determinants(model: DistortionModel, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """``(points (N, 2), det (N,))``: the correction's Jacobian determinant on a 25 x 19 grid over the image."""
    xs = np.linspace(-0.5, width - 0.5, 25)
    ys = np.linspace(-0.5, height - 0.5, 19)
    xx, yy = np.meshgrid(xs, ys)
    p = np.stack([xx.ravel(), yy.ravel()], axis=1)
    h = 0.5
    with np.errstate(all="ignore"):
        jx = (model.undistort_points(p + [h, 0]) - model.undistort_points(p - [h, 0])) / (2 * h)
        jy = (model.undistort_points(p + [0, h]) - model.undistort_points(p - [0, h])) / (2 * h)
        det = jx[:, 0] * jy[:, 1] - jx[:, 1] * jy[:, 0]
    return p, det


def correction_scale(model: DistortionModel, width: int, height: int) -> float:
    """The correction's linear scale over the image: the root of its mean Jacobian determinant (1 for the
    identity; a lens's correction is within a few per cent of 1, more than 1 for barrel distortion; NaN when
    the correction is not finite over the image)."""
    _, det = _jacobian_determinants(model, width, height)
    mean = float(np.mean(det))
    return float(np.sqrt(mean)) if np.isfinite(mean) and mean > 0 else float("nan")


def correction_problem(model: DistortionModel, width: int, height: int) -> str | None:
    """None if the fitted correction can be a lens's over the image, else the reason: it folds over
    (not locally invertible and orientation-preserving somewhere), or it has collapsed, shrinking the
    image below :data:`MIN_CORRECTION_SCALE` (:func:`correction_scale`)."""
    p, det = _jacobian_determinants(model, width, height)
    if not np.all(np.isfinite(det)) or det.min() <= 0.05:
        k = int(np.nanargmin(det)) if np.any(np.isfinite(det)) else 0
        return (
            f"the fitted correction folds over inside the image near ({p[k, 0]:.0f}, {p[k, 1]:.0f}) "
            f"(Jacobian determinant {det[k]:.3g}); too few orientations or too high a degree"
        )
    scale = float(np.sqrt(np.mean(det)))
    if scale < MIN_CORRECTION_SCALE:
        base = getattr(model, "base", model)
        centre = getattr(base, "center", None)
        where = "" if centre is None else f", its distortion centre at ({centre[0]:.0f}, {centre[1]:.0f})"
        return (
            f"the fitted correction has collapsed: it shrinks the image to {scale:.2f} of its size{where} "
            f"(a shrunken image is straighter by the same factor, no lens does this); hold the distortion "
            f"centre (a centre prior) or fit fewer parameters"
        )
    return None


def collapses(param: Parametrisation, th: np.ndarray, width: int, height: int) -> bool:
    """Whether ``param``'s correction at ``th`` shrinks the image below :data:`MIN_CORRECTION_SCALE`."""
    if not np.all(np.isfinite(th)):
        return False  # not a collapse: the caller's finiteness check says what it is
    scale = correction_scale(param.model(th), width, height)
    return bool(np.isfinite(scale) and scale < MIN_CORRECTION_SCALE)


# ------------------------------------------------------------------- API
def outlier_edges(
    rms: np.ndarray,
    reject_factor: float = REJECT_FACTOR,
    max_reject_fraction: float = MAX_REJECT_FRACTION,
    floor: float = 0.0,
) -> tuple[np.ndarray, float, int]:
    """The outlier rule on edges whose residual RMS are ``rms`` (px): the edges above ``reject_factor`` times the
    median (and above ``floor``), at most ``max_reject_fraction`` of them (then the worst, worst first); the
    threshold; how many were above it."""
    thresh = max(reject_factor * max(float(np.median(rms)), 1e-6), floor)
    bad = np.flatnonzero(rms > thresh)
    most = int(max_reject_fraction * len(rms))
    if len(bad) > most:
        return bad[np.argsort(rms[bad])[::-1][:most]], thresh, len(bad)
    return bad, thresh, len(bad)


def fit_distortion(
    lines_per_image: Sequence[Sequence[np.ndarray]],
    width: int,
    height: int,
    model: str = "radial",
    degree: int | None = None,
    tangential: bool = False,
    prism: bool = False,
    *,
    division: int = 0,
    trefoil: bool = False,
    field: tuple[int, int] | None = None,
    field_penalty: float | None = None,
    image_sizes: Sequence[tuple[int, int]] | None = None,
    init: DistortionModel | None = None,
    robust: bool = True,
    reject_factor: float = REJECT_FACTOR,
    max_reject_fraction: float = MAX_REJECT_FRACTION,
    min_orientation_spread_deg: float = MIN_ORIENTATION_SPREAD_DEG,
    ridge: float | None = None,
    w_center: float = FREE_CENTER_WEIGHT,
    max_nfev: int = 200,
    point_sigma: Sequence[Sequence[np.ndarray]] | None = None,
    point_loss: PointLoss | None = None,
    point_iterations: int = POINT_ITERATIONS,
    point_scale: Sequence[Sequence[np.ndarray]] | None = None,
) -> FitResult | FitFailure:
    """Fit a distortion correction straightening all edges of all images at once.

    Parameters
    ----------
    lines_per_image : sequence over images of sequences of (M, 2) arrays
        Edge points (pixels, distorted) of each string edge of each shot, as
        given by the measurement (smoothed, every t-th point).
    width, height : int
        Image size (all shots must share it).
    model, degree, tangential, prism
        What to fit, as :meth:`pipeline.fitspec.FitSpec.fit_arguments` gives it:
        ``model`` 'radial' (:class:`~pipeline.models.radial.RadialModel`, free centre,
        ``k0 = 1``, ``k1..k_degree``, degree 1..10, default 4) or 'poly'
        (:class:`~pipeline.models.polynomial.PolynomialModel`, total degree 3..11,
        default 5); radial only: decentering (p1, p2) / thin-prism (s1..s4) terms.
        The bounds are :data:`pipeline.fitspec.DEGREE_BOUNDS`.
    division : int
        Radial only: division (rational) denominator coefficients ``d1 .. dM`` (0..3,
        :class:`~pipeline.models.radial.RadialModel`), started at 0.
    trefoil : bool
        Radial only: the three-fold terms ``t1, t2`` (:class:`~pipeline.models.radial.RadialModel`),
        started at 0 (or at ``init``'s); four string orientations determine them.
    field, field_penalty
        Radial only: a residual field of ``(nx, ny)`` B-spline control points and its roughness
        weight (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`; default
        :data:`pipeline.fitspec.DEFAULT_FIELD_PENALTY`), started at 0 (or at ``init``'s).
    image_sizes : sequence of (width, height), optional
        Size of each shot; a mismatch gives a :class:`FitFailure`.
    init : DistortionModel, optional
        Start (default: identity for poly; Alvarez's closed-form k2 for radial).
    robust : bool
        Down-weight (Huber, per edge) then reject outlier edges (see module doc).
    reject_factor, max_reject_fraction : float
        An edge is rejected if its RMS residual exceeds ``reject_factor`` x
        the median edge RMS; at most this fraction of the edges is rejected.
    min_orientation_spread_deg : float
        At least 2 edges must differ by more than half this from the mean orientation.
    ridge : float, optional
        Weight of the ridge penalty (poly default 1e-4, radial default 0).
    w_center : float
        Radial: weight of the penalty keeping the centre near the image centre
        (a centre offset of ``delta`` (px) costs like a residual of
        ``w_center * delta`` px on every point); 1e-5 leaves it free.
    max_nfev : int
        Evaluation budget of each Levenberg–Marquardt run.
    point_sigma : sequence over images of sequences of (M,) arrays, optional
        Each point's standard deviation (px), shaped like ``lines_per_image``
        (:func:`pipeline.measure.point_sigmas`: the along-edge smoother's variance factor
        times the edge's noise). Given, every residual is weighted by ``1 / sigma`` in the
        least squares (weights ``1 / sigma^2`` scaled to mean 1,
        :func:`pipeline.edgeset.point_weights`) and each edge's line is its weighted TLS
        line; the reported figures (d, d_max, per edge) stay the paper's unweighted ones.
        None (default): every point weighs the same, as in Tang et al.
    point_loss : {'tukey', 'huber'}, optional
        After the edge-level stage, iteratively reweighted least squares on each point's residual
        about its edge's smooth trend (:mod:`pipeline.robust_points`: Tukey's biweight or Huber's
        weight against each point's own scale), so that a string's kink stops pulling the lens while
        ordinary points keep full weight; ``point_iterations`` reweightings at most. None (default):
        no per-point robust weights.
    point_scale : sequence over images of sequences of (M,) arrays, optional
        Shaped like ``lines_per_image``: each point's standard deviation (relative values suffice,
        :func:`pipeline.measure.point_sigmas`) used only as the robust stage's scale of each point
        (not as least-squares weights); default: ``point_sigma`` when given, else each edge's robust
        size of its detrended residuals.

    Returns
    -------
    FitResult or FitFailure
        Never raises for a data problem: a :class:`FitFailure` says why.
    """
    problem = spec_problem(model, degree, tangential, prism, division, field, field_penalty, trefoil)
    if problem:
        return FitFailure(problem)
    if point_loss is not None and point_loss not in POINT_LOSSES:
        return FitFailure(f"point_loss must be one of {', '.join(POINT_LOSSES)} or None, got {point_loss!r}")
    spec = FitSpec(
        model, degree, tangential, prism, division=division, field=field, field_penalty=field_penalty, trefoil=trefoil
    )
    if image_sizes is not None:
        sizes = {(int(w), int(h)) for w, h in image_sizes}
        if sizes != {(int(width), int(height))}:
            return FitFailure(
                f"images of different sizes {sorted(sizes)}: one model fits one image size ({width}x{height})"
            )
    if len(lines_per_image) == 0:
        return FitFailure("no images given")
    edges, rejected = collect(lines_per_image, width, height, point_sigma=point_sigma)
    if not edges:
        return edges
    scales: EdgeSet | None = None
    if point_scale is not None:
        got, _ = collect(lines_per_image, width, height, point_sigma=point_scale)
        if isinstance(got, FitFailure):
            return FitFailure(f"point_scale: {got.reason}")
        scales = got
    param = make_parametrisation(width, height, spec, w_center=w_center, ridge=ridge)
    n_e = edges.n_edges
    n_constraints = int(np.sum(edges.counts - 2))
    if n_e < MIN_EDGES:
        return FitFailure(f"too few edges: {n_e} usable (need >= {MIN_EDGES})")
    if n_constraints < 2 * param.n:
        return FitFailure(
            f"too few points: {n_constraints} constraints from {n_e} edges for "
            f"{param.n} parameters (need >= {2 * param.n}); lower the degree or add shots"
        )
    problem = _orientation_problem(edges, min_orientation_spread_deg)
    if problem:
        return FitFailure(problem)

    radial_like = isinstance(param, (RadialParametrisation, RadialFieldParametrisation))
    if init is None and radial_like:
        try:
            k2 = alvarez_initial_k(edges.lines(), width, height)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            k2 = 0.0
        th = np.zeros(param.n)
        if param.degree >= 2:
            th[3] = k2
    else:
        th = param.theta0(init)

    all_edges = edges
    robust_w: np.ndarray | None = None
    warnings: list[str] = []
    n_iter = 0
    rejected = list(rejected)
    try:
        with np.errstate(all="ignore"):
            sol = solve(param, edges, th, max_nfev=max_nfev)
            n_iter += sol.nfev
            if (
                init is None
                and isinstance(param, (RadialParametrisation, RadialFieldParametrisation))
                and param.w_center < CENTER_PRIOR_WEIGHT
                and float(np.hypot(*sol.x[:2])) > FAR_CENTRE
            ):
                # continuation: a free centre that ended far from the image centre may sit in a local
                # minimum (a lens decentred by 60 px on 1000x750 with tangential and prism terms ended
                # 300 px away); the same fit started from its centre-prior solution, the lower cost kept
                held = make_parametrisation(width, height, spec, w_center=CENTER_PRIOR_WEIGHT, ridge=ridge)
                pre = solve(held, edges, th, max_nfev=max_nfev)
                alt = solve(param, edges, pre.x, max_nfev=max_nfev)
                n_iter += pre.nfev + alt.nfev
                if alt.cost < sol.cost:
                    sol = alt
            th = sol.x
            if robust and n_e > MIN_EDGES:
                r, _ = residuals_and_jacobian(param, edges, th, jac=False)
                rms, _ = edge_figures(r, edges.starts, edges.counts)
                scale = 3.0 * max(float(np.median(rms)), 1e-6)
                weights = np.minimum(1.0, scale / np.maximum(rms, 1e-12))  # Huber weights per edge
                weighted = bool(np.any(weights < 1.0))
                if weighted:  # (all weights 1: the weighted problem is the one just solved)
                    sol = solve(param, edges, th, edge_weights=weights, max_nfev=max_nfev)
                    n_iter += sol.nfev
                    th = sol.x
                    r, _ = residuals_and_jacobian(param, edges, th, jac=False)
                    rms, _ = edge_figures(r, edges.starts, edges.counts)
                bad, thresh, above = outlier_edges(rms, reject_factor, max_reject_fraction)
                if above > len(bad):
                    warnings.append(
                        f"{above} edges above the outlier threshold {thresh:.3g} px; rejected only the worst {len(bad)}"
                    )
                if len(bad):
                    keep = np.ones(n_e, bool)
                    keep[bad] = False
                    for b in bad:
                        rejected.append(
                            RejectedEdge(
                                int(edges.image[b]),
                                int(edges.line[b]),
                                f"outlier: residual RMS {rms[b]:.3g} px > "
                                f"{thresh:.3g} px ({reject_factor:g} x median edge RMS)",
                            )
                        )
                    edges = edges.subset(keep)
                    if edges.n_edges < MIN_EDGES:
                        return FitFailure(f"too few edges left after rejecting outliers: {edges.n_edges}")
                    problem = _orientation_problem(edges, min_orientation_spread_deg)
                    if problem:
                        return FitFailure("after rejecting outlier edges, " + problem)
                if weighted or len(bad):  # (else the final plain fit is the first one)
                    sol = solve(param, edges, th, max_nfev=max_nfev)
                    n_iter += sol.nfev
                    th = sol.x
            if point_loss is not None:
                base = edges.weights
                if scales is not None and scales.weights is not None:
                    keep_pts = _kept_points(scales, edges)
                    sigma = 1.0 / np.sqrt(scales.weights[keep_pts])
                else:
                    sigma = None if base is None else 1.0 / np.sqrt(base)
                robust_w = None
                for _ in range(max(int(point_iterations), 0)):
                    current = base if robust_w is None else _times(base, robust_w)
                    u, _ = param.evaluate(edges.xy, th, jac=False)
                    r, a, *_ = tls(u, edges.starts, edges.counts, current)
                    new = robust_point_weights(r, a, edges.starts, edges.counts, point_loss, sigma, robust_w)
                    new = np.maximum(new, MIN_POINT_WEIGHT)
                    if robust_w is not None and float(np.max(np.abs(new - robust_w))) <= POINT_WEIGHT_TOL:
                        break
                    robust_w = new
                    sol = solve(param, replace(edges, weights=_times(base, robust_w)), th, max_nfev=max_nfev)
                    n_iter += sol.nfev
                    th = sol.x
    except (ValueError, np.linalg.LinAlgError) as exc:
        return FitFailure(f"optimisation failed: {exc}")
    if not np.all(np.isfinite(th)):
        return FitFailure("optimisation diverged (non-finite parameters)")
    fitted = param.model(th)
    problem = correction_problem(fitted, width, height)
    if problem:
        return FitFailure(problem)
    if sol.status <= 0:
        warnings.append(f"optimiser stopped early: {sol.message}")
    result = summarise(
        fitted,
        all_edges,
        edges,
        rejected,
        n_iter=n_iter,
        cost=float(sol.cost),
        message=str(sol.message),
        n_params=param.n,
        warnings=tuple(warnings),
    )
    if robust_w is not None:
        result = replace(result, point_weights=_times(edges.weights, robust_w))
    if result.d_after > result.d_before * 1.01 + 1e-9:
        return FitFailure(f"the fit made the edges less straight (d {result.d_before:.4g} -> {result.d_after:.4g} px)")
    return result
