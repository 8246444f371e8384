"""The regularised residual field on top of the radial model (issue 19 item 3).

Truth: the exact lens maps of the realistic simulator's population (:mod:`pipeline.lens_population`:
a radial + tangential + prism lens, with or without the smooth non-parametric field a real lens
adds), straight ideal lines mapped through them (:mod:`tests.pipeline.harp_points`), and the field
error modulo a homography against that exact map (:func:`pipeline.compare.compare_models`)."""

import math
from dataclasses import replace

import numpy as np
import pytest
import threadpoolctl

from pipeline.compare import compare_models
from pipeline.cross_validation import n_params
from pipeline.edgeset import collect
from pipeline.exports.maps import map_accuracy
from pipeline.exports.registry import FORMATS, read_correction, write_export
from pipeline.exports.source import ExportOptions, ExportSource
from pipeline.fit import fit_distortion
from pipeline.fit_problem import make_parametrisation, normal_equations, residuals_and_jacobian
from pipeline.fitspec import DEFAULT_FIELD_PENALTY, FitSpec, parse
from pipeline.harp_shape import _WithStrings
from pipeline.lens_population import lens_population
from pipeline.model_file import model_file_text, parse_model_text
from pipeline.models import RadialFieldModel, RadialModel, model_from_dict
from pipeline.models.radial_field import bspline_weights, field_bounds
from pipeline.orientations import required_orientations
from pipeline.select import field_candidates, is_flexible, select_model
from tests.pipeline.harp_points import harp_point_sets

W, H = 1000, 750
ANGLES = (0, 36, 72, 108, 144)
BASE = FitSpec("radial", 4, True, True)
FIELD = FitSpec("radial", 4, True, True, field=(8, 6), field_penalty=1e-4)


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """The fits solve ~100 x 100 systems: BLAS threads only contend on the shared 2-core machine."""
    with threadpoolctl.threadpool_limits(1):
        yield


def _shots(field: bool, seed: int):
    lens = lens_population(seed, 1, W, H, field=field, field_rms_px=(0.05, 0.05))[0]
    return lens, harp_point_sets(lens.model, W, H, ANGLES, noise=0.005, seed=seed)


def _some_field_model() -> RadialFieldModel:
    rng = np.random.default_rng(3)
    base = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02), center=(505.0, 370.0), tangential=(1e-3, -5e-4))
    return RadialFieldModel(base, field_bounds(W, H), rng.normal(0, 0.3, (6, 8)), rng.normal(0, 0.3, (6, 8)))


# ------------------------------------------------------------------ the model
def test_bspline_basis_is_a_partition_of_unity_reproducing_cubics():
    x = np.linspace(-30.0, 1030.0, 501)  # beyond the domain too: the end pieces go on
    lo, hi, n = -20.0, 1020.0, 9
    k, b = bspline_weights(x, lo, hi, n)
    assert np.allclose(b.sum(axis=1), 1.0)
    # the coefficients of x^3 in the uniform cubic B-spline basis (Marsden's identity, knots t_i = lo + (i - 3) h)
    h = (hi - lo) / (n - 3)
    t = lo + (np.arange(n + 4) - 3) * h
    c = np.array([t[i + 1] * t[i + 2] * t[i + 3] for i in range(n)])
    got = np.sum(c[k[:, None] + np.arange(4)] * b, axis=1)
    assert np.allclose(got, x**3, rtol=1e-9, atol=1e-6)


def test_model_is_radial_plus_field_and_round_trips_through_the_model_file():
    m = _some_field_model()
    rng = np.random.default_rng(0)
    p = rng.uniform([0, 0], [W - 1, H - 1], (200, 2))
    assert np.allclose(m.undistort_points(p), m.base.undistort_points(p) + m.displacement(p))
    back = model_from_dict(m.to_dict())
    assert isinstance(back, RadialFieldModel)
    assert np.array_equal(back.undistort_points(p), m.undistort_points(p))
    parsed = parse_model_text(model_file_text(m, width=W, height=H), "field.yaml")
    assert np.allclose(parsed.model.undistort_points(p), m.undistort_points(p), atol=1e-12)
    q = m.distort_points(p)
    assert np.abs(m.undistort_points(q) - p).max() < 1e-8
    with pytest.raises(ValueError, match="nx, ny >= 4"):
        RadialFieldModel(m.base, m.bounds, np.zeros((3, 8)), np.zeros((3, 8)))


def test_the_fit_jacobian_with_a_field_is_the_finite_difference_one():
    lens, shots = _shots(True, 3)
    edges, _ = collect(shots, W, H)
    par = make_parametrisation(W, H, FitSpec("radial", 4, True, True, field=(6, 5)))
    rng = np.random.default_rng(0)
    th = rng.normal(0, 1e-3, par.n)
    th[par.n_radial :] = rng.normal(0, 0.1, 2 * par.n_field)
    _, jac = residuals_and_jacobian(par, edges, th)
    num = np.empty_like(jac)
    for i in range(par.n):
        e = np.zeros(par.n)
        e[i] = 1e-6
        rp, _ = residuals_and_jacobian(par, edges, th + e, jac=False)
        rm, _ = residuals_and_jacobian(par, edges, th - e, jac=False)
        num[:, i] = (rp - rm) / 2e-6
    assert np.abs(jac - num).max() < 1e-5 * np.abs(jac).max()


def _explicit_normal_equations(par, edges, th, edge_weights):
    """``J^T W J``, ``J^T W r``, ``r^T W r`` from the explicit Jacobian (:func:`residuals_and_jacobian`, dense)."""
    r, j = residuals_and_jacobian(par, edges, th)
    wp = edges.point_weights(edge_weights)
    jw = j * wp[:, None]
    return jw.T @ j, jw.T @ r, float((r * wp) @ r)


@pytest.mark.parametrize("strings", [False, True])
def test_the_normal_equations_with_a_field_are_those_of_the_explicit_jacobian(strings):
    """:func:`normal_equations` keeps a field's rows sparse (a product per cell of the grid): its results are
    those of the explicit dense Jacobian, with point and edge weights, for the lens alone and for the joint fit
    of lens and string bends (:mod:`pipeline.harp_shape`)."""
    lens, shots = _shots(True, 3)
    rng = np.random.default_rng(7)
    sig = [[rng.uniform(0.5, 3.0, len(p)) for p in s] for s in shots]
    edges, _ = collect(shots, W, H, point_sigma=sig)
    par = make_parametrisation(W, H, FitSpec("radial", 4, True, True, field=(12, 9)))
    th = rng.normal(0, 1e-3, par.n)
    th[par.n_radial :] = rng.normal(0, 0.1, 2 * par.n_field)
    if strings:
        n_pts, m, k = len(edges.xy), 3, 5
        string_of = np.repeat(rng.integers(-1, k, edges.n_edges), edges.counts)
        nrm = rng.normal(size=(n_pts, 2))
        kinks = rng.normal(size=(2, n_pts)) * (string_of == 1)
        par = _WithStrings(
            par, string_of, rng.normal(size=(m, n_pts)), nrm / np.hypot(*nrm.T)[:, None], k, 1e-3, None, kinks
        )
        th = np.concatenate([th, rng.normal(0, 0.01, par.n - len(th))])
    ew = rng.uniform(0.3, 1.0, edges.n_edges)
    ata, atb, ss = normal_equations(par, edges, th, edge_weights=ew)
    a_ref, b_ref, ss_ref = _explicit_normal_equations(par, edges, th, ew)
    assert np.allclose(ata[0], a_ref, rtol=1e-9, atol=1e-10 * np.abs(a_ref).max())
    assert np.allclose(atb[0], b_ref, rtol=1e-7, atol=1e-9 * np.abs(a_ref).max() ** 0.5)
    assert ss[0] == pytest.approx(ss_ref, rel=1e-12)


def test_the_field_basis_kept_between_evaluations_follows_the_points():
    """The parametrisation keeps the field's basis of the last points evaluated; points changed in place, or
    other points, get their own (as a new parametrisation computes it)."""
    _, shots = _shots(True, 3)
    edges, _ = collect(shots, W, H)
    spec = FitSpec("radial", 4, True, True, field=(8, 6))
    par = make_parametrisation(W, H, spec)
    th = np.random.default_rng(1).normal(0, 0.05, par.n)
    xy = edges.xy.copy()
    first, _ = par.evaluate(xy, th, jac=False)
    xy[::7] += 40.0
    moved, _ = par.evaluate(xy, th, jac=False)
    fresh, _ = make_parametrisation(W, H, spec).evaluate(xy, th, jac=False)
    assert np.array_equal(moved, fresh) and not np.allclose(moved, first)


# ------------------------------------------------------------------- the spec
def test_field_spec_labels_parse_back_and_count_their_parameters():
    s = parse("radial4+tangential+prism+field8x6@0.0001")
    assert s == FIELD and s.label == "radial4+tangential+prism+field8x6@0.0001"
    assert parse("radial4+field12x9").field_penalty == DEFAULT_FIELD_PENALTY
    assert FitSpec.from_dict(FIELD.to_dict()) == FIELD
    assert FIELD.fit_arguments()["field"] == (8, 6)
    assert n_params(FIELD, W, H) == n_params(BASE, W, H) + 2 * 8 * 6
    assert is_flexible(FIELD) and not is_flexible(BASE)
    assert required_orientations(FIELD) == 4
    for bad, why in (
        ("radial4+field3x6", "within 4..24"),
        ("radial4+field8", "field<nx>x<ny>"),
        ("radial4+field8x6@x", "must be a number"),
        ("radial4+field8x6@-1", "> 0"),
        ("poly5+field8x6", "radial model only"),
    ):
        with pytest.raises(ValueError, match=why):
            parse(bad)
    assert fit_distortion([], W, H, model="poly", field=(8, 6)).reason.startswith("a residual field applies")


# ------------------------------------------------------------- it must not over-fit
@pytest.mark.parametrize("seed", [0, 1])
def test_a_lens_with_a_field_is_followed_and_cross_validation_takes_the_field(seed):
    """A lens with 0.05 px RMS of smooth non-parametric field: the radial model leaves 0.02-0.035 px of
    field error, the field model under 0.005 px; leave-one-shot-out CV chooses the field."""
    lens, shots = _shots(True, seed)
    base = fit_distortion(shots, W, H, **BASE.fit_arguments())
    assert base
    e_base = compare_models(base.model, lens.model, W, H).rms
    cands = field_candidates(BASE, grids=((8, 6),), penalties=(1e-4, 1e-2))
    sel = select_model(shots, W, H, candidates=cands)
    assert sel.choice.field == (8, 6) and sel.choice.field_penalty == 1e-4, sel.reason
    assert "ahead of every radial model on unseen orientations" in sel.reason
    chosen = next(r for r in sel.table if r.candidate == sel.choice).full_fit
    assert chosen is not None and isinstance(chosen.model, RadialFieldModel)
    e_field = compare_models(chosen.model, lens.model, W, H).rms
    assert e_base > 0.02 and e_field < 0.005 and e_field < 0.2 * e_base


@pytest.mark.parametrize("seed", [0, 1])
def test_a_lens_without_a_field_keeps_the_radial_model(seed):
    """A plain radial + tangential + prism lens: every field candidate over-fits a little (0.0015-0.003 px
    against 0.0006-0.001 px); the cross-validation sees it and keeps the radial model, whose field error
    is therefore the choice's."""
    lens, shots = _shots(False, seed)
    cands = field_candidates(BASE, grids=((8, 6),), penalties=(1e-4, 1e-2))
    sel = select_model(shots, W, H, candidates=cands)
    assert sel.choice == BASE, sel.reason
    row = next(r for r in sel.table if r.candidate == BASE)
    assert row.full_fit is not None
    assert compare_models(row.full_fit.model, lens.model, W, H).rms < 0.0015


def test_with_two_orientations_a_field_is_set_aside_and_the_unseen_orientation_shows_why():
    """Two orientations (10 and 100 deg), so only alternate strings can judge: there the field wins
    (CV d 0.006 against 0.010 px), because it bends to both orientations. An unseen orientation of the
    exact lens (55 and 145 deg) is left twice as bent by the field as by the radial model, so the
    choice sets the field aside and says so."""
    from pipeline.straightness import straightness

    lens = lens_population(3, 1, W, H, field=True, field_rms_px=(0.05, 0.05))[0]
    shots = harp_point_sets(lens.model, W, H, (10, 100), noise=0.005, seed=3)
    unseen = [p for s in harp_point_sets(lens.model, W, H, (55, 145), noise=0.005, seed=53) for p in s]
    sel = select_model(shots, W, H, candidates=field_candidates(BASE, grids=((8, 6),), penalties=(1e-4,)))
    assert sel.choice == BASE and sel.folds == "edges", sel.reason
    assert "1 flexible candidate (free polynomial or residual field) set aside" in sel.reason
    assert "the shots have 2" in sel.reason
    assert [r.candidate for r in sel.table] == [BASE]
    field = fit_distortion(shots, W, H, **FIELD.fit_arguments())
    base = next(r.full_fit for r in sel.table if r.candidate == BASE)
    assert field and base is not None
    d_field = straightness([field.model.undistort_points(p) for p in unseen]).d
    d_base = straightness([base.model.undistort_points(p) for p in unseen]).d
    assert d_field > 1.5 * d_base, (d_field, d_base)
    # with leave-one-shot-out folds nothing is set aside: unseen orientations judge every candidate
    sel4 = select_model(
        harp_point_sets(lens.model, W, H, (10, 55, 100, 145), noise=0.005, seed=3),
        W,
        H,
        candidates=(BASE, FIELD),
    )
    assert {r.candidate for r in sel4.table} == {BASE, FIELD} and "set aside" not in sel4.reason


@pytest.mark.parametrize("field", [True, False])
def test_on_the_realistic_simulator_the_field_helps_where_the_lens_has_one_and_nowhere_else(field):
    """Rendered and measured shots of the realistic simulator (bent strings, field-dependent blur, Bayer,
    8 bits; ``benchmarks/residual_field.py``'s lens 1): with the lens's 0.02 px field the cross-validation
    takes the field and the field error falls to a quarter; the same lens without it keeps the radial model,
    whose field error the field would have doubled."""
    from pipeline.measure import measure_image
    from pipeline.realism import realistic_session, render_shots

    lens = lens_population(2026, 2, W, H, field=field, field_rms_px=(0.005, 0.04))[1]
    s = realistic_session(1, W, H, spacing_px=(60.0, 80.0), string_width_px=(2.5, 3.0))
    shots = render_shots(lens.model, s.harp, s.mount, [0, 36, 72, 108, 144], W, H, s.effects, seed=1)
    lines = [[ln.points for ln in measure_image(sh.image, t=30).lines] for sh in shots]
    with_field = replace(BASE, field=(8, 6), field_penalty=1e-3)
    sel = select_model(lines, W, H, candidates=(BASE, with_field))
    err = {r.candidate: compare_models(r.full_fit.model, lens.model, W, H).rms for r in sel.table if r.full_fit}
    if field:
        assert sel.choice == with_field, sel.reason
        assert err[BASE] > 0.008 and err[with_field] < 0.3 * err[BASE]
    else:
        assert sel.choice == BASE, sel.reason
        assert err[BASE] < 0.0012 < err[with_field]


# ------------------------------------------------------------------- exports
def test_maps_export_a_field_model_exactly():
    """maps / STMap: the field model's own inverse, to the interpolation error of harp undistort's maps
    (1e-3 px)."""
    m = _some_field_model()
    src = ExportSource(m, W, H, holdout_d=0.005)
    for name, file in (("maps", "field.npz"), ("stmap", "field.exr")):
        corr = read_correction(write_export(name, src).data, file, W, H)
        acc = map_accuracy(m, *_maps_of(corr.model))
        assert acc.max_px < 2e-3, name
    # the redistort STMap samples the model's own forward map: exact, and it says so
    e = write_export("stmap-redistort", src)
    assert e.error is not None and e.error.max_px < 2e-3


FITTED_FORMATS = [n for n in FORMATS if n not in ("maps", "stmap", "stmap-redistort", "json", "harp", "auto")]
"""Every format that fits its own model to the field model (one test each: the pole-free fits of a
field take from seconds to minutes, and so spread over the test workers)."""


@pytest.mark.parametrize("name", FITTED_FORMATS)
def test_every_other_format_states_its_error_on_a_field_model(name):
    """Every other format: a fit with its stated conversion error, and the error is true."""
    m = _some_field_model()
    src = ExportSource(m, W, H, holdout_d=0.005)
    e = write_export(name, src, ExportOptions(crop_factor=1.0))  # lensfun needs the camera's
    assert e.error is not None and e.converted is not None, name
    true = compare_models(e.converted, m, W, H).rms
    assert math.isclose(true, e.error.rms_mod_h_px, rel_tol=0.2, abs_tol=1e-3), name
    # a field of 0.3 px coefficients is not a pin-hole model: the conversion says it is worse than the fit
    assert e.error.rms_mod_h_px > 0.005 and any("less exact than the calibration" in w for w in e.warnings), name


def _maps_of(model):
    return model.map_x, model.map_y


def _control_points(bounds, shape):
    """``(ny nx, 2)``: where each control point of a ``shape`` grid over ``bounds`` stands (its basis function's
    peak: control point ``i`` at ``x0 + (i - 1) h``, ``h`` the domain over ``n - 3``), row by row, written out here."""
    ny, nx = shape
    x0, y0, x1, y1 = bounds
    jj, ii = np.mgrid[0:ny, 0:nx].astype(float)
    xs, ys = x0 + (ii - 1) * (x1 - x0) / (nx - 3), y0 + (jj - 1) * (y1 - y0) / (ny - 3)
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


def test_the_axis_gauge_spans_fields_that_turn_with_a_harp_about_its_axis():
    """``axis_basis``: a smooth field that turns with a rotation about the axis (radial and tangential parts that
    depend on the distance from it only; truth from that geometry) has its control-point coefficients in the span,
    and its B-spline field does turn so (nearly the same polar components at every angle about the axis); a field that
    does not turn so (a uniform shear) is mostly outside the span. The gauge's rows hold the spanned part of a fit's
    field at zero."""
    from pipeline.models.radial_field import axis_basis, field_matrix

    w, h, shape, axis = 1000, 750, (9, 12), (430.0, 402.0)
    bounds = field_bounds(w, h)
    q = axis_basis(axis, bounds, shape)
    ny, nx = shape
    nf = ny * nx
    assert q.shape[0] == 2 * nf and np.allclose(q.T @ q, np.eye(q.shape[1]), atol=1e-9)

    def g(r):
        return 0.1 * np.sin(r / 200.0)

    def hh(r):
        return 0.05 * np.cos(r / 300.0)

    cp = _control_points(bounds, shape)
    rel = cp - np.array(axis)
    r = np.hypot(*rel.T)
    e_r = rel / r[:, None]
    field = g(r)[:, None] * e_r + hh(r)[:, None] * np.stack([-e_r[:, 1], e_r[:, 0]], axis=1)
    c = np.concatenate([field[:, 0], field[:, 1]])
    assert np.linalg.norm(c - q @ (q.T @ c)) < 0.05 * np.linalg.norm(c)
    phi = np.radians(np.arange(0.0, 360.0, 7.5))
    for radius in (150.0, 250.0, 350.0):
        pts = np.array(axis) + radius * np.stack([np.cos(phi), np.sin(phi)], axis=1)
        b = field_matrix(pts, bounds, shape).T
        u = np.stack([b @ c[:nf], b @ c[nf:]], axis=1)
        d = (pts - np.array(axis)) / radius
        radial = np.einsum("ij,ij->i", u, d)
        tangential = u[:, 1] * d[:, 0] - u[:, 0] * d[:, 1]
        for comp, truth in ((radial, g(radius)), (tangential, hh(radius))):
            assert np.ptp(comp) < 0.15 * abs(comp.mean()), (radius, np.ptp(comp), comp.mean())  # turns with the harp
            assert comp.mean() == pytest.approx(truth, rel=0.25)  # the spline smooths its control values
    shear = np.concatenate([cp[:, 1] / 1000.0, np.zeros(nf)])  # u_x = y: no turn about any axis
    assert np.linalg.norm(q.T @ shear) < 0.7 * np.linalg.norm(shear)


def test_the_axis_gauge_about_two_axes_holds_what_turns_about_either():
    """``with_axis_gauge(a, b)``: the gauge rows are orthonormal and hold at zero every field that turns about
    ``a`` and every field that turns about ``b`` (each axis's own :func:`axis_basis`, built independently), and
    they are more than either axis's alone; a field that turns about neither (a ripple) is mostly free."""
    from pipeline.models.radial_field import axis_basis

    w, h, shape = 1000, 750, (9, 12)
    a, b = (380.0, 330.0), (620.0, 430.0)
    part = make_parametrisation(w, h, FitSpec("radial", 4, True, True, field=(12, 9), field_penalty=1e-3))
    nf = shape[0] * shape[1]
    assert part._axis.shape == (0, 2 * nf)
    both = part.with_axis_gauge(a, b)._axis
    assert np.allclose(both @ both.T, np.eye(len(both)), atol=1e-9)
    one_a, one_b = axis_basis(a, field_bounds(w, h), shape), axis_basis(b, field_bounds(w, h), shape)
    assert len(both) > max(one_a.shape[1], one_b.shape[1])
    for q in (one_a, one_b):
        assert np.allclose(both.T @ (both @ q), q, atol=1e-8)  # every column of either lies in the gauge's span
    alone = part.with_axis_gauge(a)._axis
    assert np.allclose(alone.T @ alone, one_a @ one_a.T, atol=1e-9)  # one axis: that axis's span
    cx, cy = _control_points(field_bounds(w, h), shape).T
    ripple = np.concatenate([np.sin(2 * np.pi * cx / 250) * np.sin(2 * np.pi * cy / 250), np.zeros(nf)])
    assert np.linalg.norm(both @ ripple) < 0.4 * np.linalg.norm(ripple)  # turns about neither: mostly free
