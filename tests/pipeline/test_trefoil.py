"""The three-fold (trefoil) term of the radial model, and what string orientations determine.

Truth comes from exact lens maps written here in complex form, independently of
``pipeline.models.radial``: a lens ``z_d = z + k1 |z|^2 z + s |z|^2 + t conj(z)^2`` (normalised
offsets ``z = (x - c) / f``, complex ``s`` the thin-prism, complex ``t`` the three-fold term), and the
straightness of its strings after a correction is measured on noise-free lines of orientations the
fit never saw.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec, parse
from pipeline.models.radial import RadialModel
from pipeline.orientations import required_orientations
from pipeline.select import select_model

from .complex_lens import ComplexLens, worst_d
from .harp_points import harp_point_sets

W, H = 1200, 800
F = 1000.0  # the ComplexLens unit, px


CENTRE = ((W - 1) / 2.0, (H - 1) / 2.0)


def unseen_d(model, lens, angles):
    """Largest d (px) of noise-free strings of ``angles`` corrected by ``model``."""
    return worst_d(model, harp_point_sets(lens, W, H, angles, noise=0.0, seed=9))


def fit(lens, angles, trefoil, seed=1):
    shots = harp_point_sets(lens, W, H, angles, noise=0.002, seed=seed)
    r = fit_distortion(shots, W, H, "radial", 4, True, True, trefoil=trefoil)
    assert r, r
    return r, worst_d(r.model, shots)


def test_the_trefoil_terms_are_the_documented_formula():
    """``t1 (xi^2 - eta^2, -2 xi eta) + t2 (2 xi eta, xi^2 - eta^2)`` is ``(t1 + i t2) conj(z)^2``."""
    m = RadialModel(center=(600.0, 400.0), k=(1.0,), scale=500.0, trefoil=(0.03, -0.02))
    xy = np.random.default_rng(0).uniform([0, 0], [W, H], (50, 2))
    z = ((xy[:, 0] + 1j * xy[:, 1]) - (600 + 400j)) / 500.0
    want = (600 + 400j) + 500.0 * (z + (0.03 - 0.02j) * np.conj(z) ** 2)
    got = m.undistort_points(xy)
    assert np.allclose(got, np.c_[want.real, want.imag], atol=1e-9)
    assert np.allclose(m.distort_points(got), xy, atol=1e-6)
    assert RadialModel.from_dict(m.to_dict()) == m
    assert list(m.params()[-2:]) == [0.03, -0.02]


def test_a_trefoil_spec_is_spelled_read_and_stored_once():
    spec = parse("radial4+tangential+prism+trefoil")
    assert spec == FitSpec("radial", 4, True, True, trefoil=True)
    assert spec.label == "radial4+tangential+prism+trefoil"
    assert FitSpec.from_dict(spec.to_dict()) == spec
    assert FitSpec.from_fit_arguments(spec.fit_arguments()) == spec
    assert "trefoil" not in FitSpec("radial", 4, True, True).to_dict()  # files without it are unchanged
    assert required_orientations(spec) == 4
    with pytest.raises(ValueError, match="radial model only"):
        FitSpec("poly", 5, trefoil=True)


def test_two_orientations_determine_a_decentred_lens_without_a_three_fold_term():
    """Thin-prism, decentering and a free centre: two orientations leave every unseen one straight."""
    lens = ComplexLens(k1=-0.06, s=2e-4 - 1e-4j, t=0, centre=(W / 2 + 40, H / 2 - 25))
    r, _ = fit(lens, (90, 45), trefoil=False)
    assert unseen_d(r.model, lens, (0, 135, 20, 110)) < 0.002


def test_a_three_fold_term_needs_four_orientations_and_the_trefoil_spec_then_recovers_it():
    lens = ComplexLens(k1=-0.05, s=1e-4 + 1e-4j, t=2e-4 + 1e-4j, centre=CENTRE)
    unseen = (20, 160, 70, 110)
    # two orientations: the prism terms take the trefoil up; the fitted shots are straight, a third is not
    two, fitted_d = fit(lens, (90, 45), trefoil=False)
    assert fitted_d < 0.004
    assert unseen_d(two.model, lens, unseen) > 0.02
    # four orientations: without the term the shots keep a bow; with it every orientation is straight
    base, base_d = fit(lens, (0, 45, 90, 135), trefoil=False)
    full, _ = fit(lens, (0, 45, 90, 135), trefoil=True)
    assert base_d > 0.005
    assert unseen_d(base.model, lens, unseen) > 0.01
    assert unseen_d(full.model, lens, unseen) < 0.001
    # the fitted correction's term is the lens's own, undone (to first order: -t, rescaled to its normalisation)
    t_fit = complex(*full.model.trefoil)
    assert t_fit == pytest.approx(-(2e-4 + 1e-4j) * full.model.scale / F, rel=0.1)


def test_the_choice_takes_the_trefoil_with_six_orientations_and_sets_it_aside_with_three():
    lens = ComplexLens(k1=-0.05, s=1e-4 + 1e-4j, t=2e-4 + 1e-4j, centre=CENTRE)
    candidates = (FitSpec("radial", 4, True, True), FitSpec("radial", 4, True, True, trefoil=True))
    six = harp_point_sets(lens, W, H, (0, 30, 60, 90, 120, 150), noise=0.003, seed=3)
    sel = select_model(six, W, H, candidates)
    assert sel.choice.trefoil, sel.reason
    three = harp_point_sets(lens, W, H, (0, 50, 110), noise=0.003, seed=3)
    sel3 = select_model(three, W, H, candidates)
    assert not sel3.choice.trefoil
    assert "three-fold term set aside" in sel3.reason and "the folds have 2" in sel3.reason
    assert [r.candidate for r in sel3.table] == [candidates[0]]


def test_the_choice_keeps_the_model_without_the_term_when_the_lens_has_none():
    lens = ComplexLens(k1=-0.05, s=1e-4 + 1e-4j, t=0, centre=CENTRE)
    candidates = (FitSpec("radial", 4, True, True), FitSpec("radial", 4, True, True, trefoil=True))
    six = harp_point_sets(lens, W, H, (0, 30, 60, 90, 120, 150), noise=0.003, seed=4)
    sel = select_model(six, W, H, candidates)
    assert not sel.choice.trefoil, sel.reason
