import numpy as np
import pytest

from pipeline.alvarez import alvarez_energy, alvarez_initial_k, fit_alvarez
from pipeline.compare import compare_models
from pipeline.edgeset import FitFailure, FitResult
from pipeline.models import RadialModel
from tests.pipeline.harp_points import harp_point_sets
from tests.pipeline.rendered_shots import LENSES, H, W, measured_shots


def test_energy_is_zero_exactly_for_straight_lines():
    t = np.linspace(0, 1, 20)
    line = np.stack([10 + 300 * t, 20 + 100 * t], 1)
    assert abs(alvarez_energy([line])) < 1e-15 * (300**2 * 100**2)
    arc = np.stack([10 + 300 * t, 20 + 100 * t + 5 * t * (1 - t)], 1)
    assert alvarez_energy([arc]) > 1.0


def test_closed_form_k_recovers_a_pure_rho2_lens():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.04))  # u = c + (1 + k rho^2)(x - c)
    shots = harp_point_sets(lens, W, H, (0, 45, 90), noise=0.0)
    k = alvarez_initial_k([p for s in shots for p in s], W, H)
    assert k == pytest.approx(0.04, rel=1e-6)
    lines = [p for s in shots for p in s]
    assert alvarez_energy(lines, RadialModel.for_image(W, H, k=(1.0, 0.0, k))) < 1e-9 * alvarez_energy(lines)


def test_two_coefficients_on_point_sets():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.005))
    shots = harp_point_sets(lens, W, H, (0, 60, 120), noise=0.0)
    r = fit_alvarez(shots, W, H, n_k=2)
    assert isinstance(r, FitResult)
    assert r.model.k[2] == pytest.approx(0.03, rel=1e-3) and r.model.k[4] == pytest.approx(0.005, rel=2e-2)
    assert r.d_after < 1e-4


def test_automatic_edges_make_alvarez_automatic():
    """Tang et al. 2012 Sect. 6: harp edges found automatically feed Alvarez's algebraic method."""
    shots = measured_shots("barrel")[:2]  # a (1 + k1 r^2 + k2 r^4) lens, as in Alvarez's model
    r = fit_alvarez(shots, W, H, n_k=2)
    assert isinstance(r, FitResult)
    cmp = compare_models(r.model, LENSES["barrel"], W, H)
    print(f"Alvarez on automatic edges: d {r.d_before:.3f} -> {r.d_after:.4f} px, field RMS {cmp.rms:.4f} px")
    assert r.d_before > 0.5 and r.d_after < 0.02
    assert cmp.rms < 0.05


def test_alvarez_bad_input():
    assert isinstance(fit_alvarez([[np.zeros((2, 2))]], W, H), FitFailure)
    with pytest.raises(ValueError):
        alvarez_energy([np.zeros((2, 2))])
