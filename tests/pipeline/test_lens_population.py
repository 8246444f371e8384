"""Seeded lens populations: reproducible, spread as documented, a field the parametric family lacks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.lens_population import (
    BAD_FACTOR,
    DESIGNS,
    TANGENTIAL_SPREAD,
    RippleLens,
    lens_population,
    shot_to_shot,
)
from pipeline.models import RadialModel, model_from_dict

W, H = 1000, 750
S = 0.5 * math.hypot(W, H)


def _grid(step: float) -> np.ndarray:
    gx, gy = np.meshgrid(np.arange(0.0, W, step), np.arange(0.0, H, step))
    return np.stack([gx.ravel(), gy.ravel()], 1)


def test_a_population_is_seeded_and_grows_by_appending():
    a = lens_population(7, 5, W, H, field=True)
    b = lens_population(7, 8, W, H, field=True)
    xy = _grid(50.0)
    for p, q in zip(a, b):
        assert p.serial == q.serial
        assert np.array_equal(p.model.undistort_points(xy), q.model.undistort_points(xy))
    other = lens_population(8, 5, W, H, field=True)
    assert not np.array_equal(a[0].model.undistort_points(xy), other[0].model.undistort_points(xy))
    assert {p.design for p in lens_population(1, 40, W, H)} == set(DESIGNS)


def test_one_design_spreads_as_documented():
    pop = lens_population(3, 300, W, H, design="wide", bad_fraction=0.0)
    k1 = np.array([p.parametric.k[2] for p in pop])
    d = DESIGNS["wide"]
    assert k1.mean() == pytest.approx(d.k[0], abs=3 * d.k_spread[0] / math.sqrt(300))
    assert k1.std() == pytest.approx(d.k_spread[0], rel=0.15)
    tang = np.array([p.parametric.tangential for p in pop])
    assert tang.std() == pytest.approx(TANGENTIAL_SPREAD, rel=0.15)
    centre = np.array([p.parametric.center for p in pop]) - [(W - 1) / 2, (H - 1) / 2]
    assert np.abs(centre).std() < 0.01 * S and all(p.field_rms_px == 0.0 and not p.bad for p in pop)
    assert all(isinstance(p.model, RadialModel) for p in pop)


def test_the_odd_bad_lens_is_four_times_as_decentred():
    pop = lens_population(5, 600, W, H, design="normal", bad_fraction=0.05)
    bad = [p for p in pop if p.bad]
    assert 14 <= len(bad) <= 48  # 30 expected: binomial(600, 0.05) within +-3 sigma
    tb = np.array([p.parametric.tangential for p in bad])
    assert tb.std() == pytest.approx(BAD_FACTOR * TANGENTIAL_SPREAD, rel=0.3)


def test_the_field_has_its_drawn_rms_and_is_not_radial_tangential_or_prism():
    for p in lens_population(11, 6, W, H, field=True, field_rms_px=(0.01, 0.03)):
        assert isinstance(p.model, RippleLens)
        assert 0.01 <= p.field_rms_px <= 0.03
        xy = _grid(7.0)
        f = p.model.undistort_points(xy) - p.parametric.undistort_points(xy)
        assert float(np.sqrt(np.mean(np.sum(f * f, axis=1)))) == pytest.approx(p.field_rms_px, rel=0.03)
        # least squares of the field on the whole radial4 + tangential + prism family plus an affine map:
        # most of it is left over (what a residual-field model is for)
        xi, eta = (xy[:, 0] - (W - 1) / 2) / S, (xy[:, 1] - (H - 1) / 2) / S
        r2 = xi * xi + eta * eta
        zero, one = np.zeros_like(xi), np.ones_like(xi)
        cols = [(one, zero), (zero, one), (xi, zero), (eta, zero), (zero, xi), (zero, eta)]
        cols += [(xi * np.sqrt(r2) ** m, eta * np.sqrt(r2) ** m) for m in range(1, 5)]
        cols += [(2 * xi * eta, r2 + 2 * eta * eta), (r2 + 2 * xi * xi, 2 * xi * eta)]
        cols += [(r2, zero), (r2 * r2, zero), (zero, r2), (zero, r2 * r2)]
        a = np.array([np.concatenate(c) for c in cols]).T
        rhs = np.concatenate([f[:, 0], f[:, 1]])
        coef, *_ = np.linalg.lstsq(a, rhs, rcond=None)
        left = rhs - a @ coef
        assert np.sqrt(np.mean(left**2)) > 0.25 * np.sqrt(np.mean(rhs**2))


def test_a_ripple_lens_reads_back_and_inverts():
    p = lens_population(2, 1, W, H, field=True)[0]
    m = p.model
    back = model_from_dict(m.to_dict())
    xy = _grid(37.0)
    assert np.array_equal(back.undistort_points(xy), m.undistort_points(xy))
    assert np.abs(m.undistort_points(m.distort_points(xy)) - xy).max() < 1e-8
    with pytest.raises(ValueError, match="design"):
        lens_population(0, 1, W, H, design="fisheye")


def test_shot_to_shot_changes_only_the_decentering():
    p = lens_population(4, 1, W, H, field=True)[0]
    moved = shot_to_shot(p.model, np.random.default_rng(0), tangential_sd=1e-4, centre_sd_px=0.5)
    assert isinstance(moved, RippleLens) and moved.amplitudes == p.model.amplitudes
    assert moved.base.k == p.parametric.k and moved.base.prism == p.parametric.prism
    dt = np.subtract(moved.base.tangential, p.parametric.tangential)
    dc = np.subtract(moved.base.center, p.parametric.center)
    assert 0 < np.abs(dt).max() < 5e-4 and 0 < np.abs(dc).max() < 2.5
    same = shot_to_shot(p.parametric, np.random.default_rng(0), 0.0)
    xy = _grid(50.0)
    assert np.array_equal(same.undistort_points(xy), p.parametric.undistort_points(xy))
