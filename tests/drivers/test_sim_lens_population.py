"""A population of simulated lenses (issue 21 item 2): each lens serial its own unit of the demo lens.

``drivers.sim.lens.lens_unit(serial, spread)`` draws a unit's manufacturing deviations from a hash of
its serial. The truths here are the numbers the module documents (standard deviations 0.003 /
0.0015 / 0.0005 of k2 / k4 / k6, 0.005 half-diagonals of the centre, 3e-4 of p1 and p2, one unit in
20 bad with 4 times the decentring and tilt), and the rendered frames are checked against the
exact edge curves of the unit's lens by an independent scanline fit.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim.camera import SimulatedCamera
from drivers.sim.lens import NOMINAL, lens_for_focus, lens_unit
from drivers.sim.world import SimWorld
from pipeline.render import true_edge_curves
from tests.pipeline.scanline_fit import scanline_errors

N = 4000


@pytest.fixture(scope="module")
def population():
    return [lens_unit(f"LINE-{i:05d}", 1.0) for i in range(N)]


def test_a_serial_is_always_the_same_lens_and_another_serial_another(population):
    again = [lens_unit(f"LINE-{i:05d}", 1.0) for i in range(50)]
    assert again == population[:50]
    assert len({u.dk for u in population}) == N  # every serial a different unit
    assert lens_for_focus(0.5, 640, 480, population[0]) != lens_for_focus(0.5, 640, 480, population[1])
    # spread 0: the nominal demo lens for every serial, exactly as before the population existed
    assert lens_unit("LINE-00001", 0.0) == lens_unit("anything", 0.0) == NOMINAL
    assert lens_for_focus(0.3, 640, 480, lens_unit("X", 0.0)) == lens_for_focus(0.3, 640, 480)
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="lens_spread"):
            lens_unit("X", bad)


def test_the_spread_has_the_documented_size_and_scales_with_the_key(population):
    good = [u for u in population if not u.bad]
    dk = np.array([u.dk for u in good])
    centre = np.array([u.centre for u in good])
    tang = np.array([u.tangential for u in good])
    prism = np.array([u.prism for u in good])
    # sample standard deviations against the documented ones (N ~ 3800: within 5 %)
    for got, want in (
        (dk.std(0, ddof=1), [0.003, 0.0015, 0.0005]),
        (centre.std(0, ddof=1), [0.005, 0.005]),
        (tang.std(0, ddof=1), [3e-4, 3e-4]),
        (prism.std(0, ddof=1), [3e-4, 1e-4, 3e-4, 1e-4]),
    ):
        np.testing.assert_allclose(got, want, rtol=0.05)
    assert np.all(np.abs(dk.mean(0)) < 3 * np.array([0.003, 0.0015, 0.0005]) / np.sqrt(len(good)) + 1e-12)
    # the odd bad lens: 5 % of the units (binomial 4000 x 0.05: 200 +- 14), 4 times decentred and tilted
    bad = [u for u in population if u.bad]
    assert 150 <= len(bad) <= 250
    np.testing.assert_allclose(np.array([u.tangential for u in bad]).std(0, ddof=1), [1.2e-3, 1.2e-3], rtol=0.15)
    # the key scales every deviation of the same unit
    for s in ("LINE-00007", "LINE-00042"):
        one, two = lens_unit(s, 1.0), lens_unit(s, 2.0)
        np.testing.assert_allclose(two.dk, 2 * np.array(one.dk), rtol=1e-12)
        np.testing.assert_allclose(two.prism, 2 * np.array(one.prism), rtol=1e-12)


def test_the_camera_renders_the_unit_the_world_holds():
    """Frames of a camera whose world holds a unit lie on that unit's exact edges (independent
    scanline fit), not on the nominal lens's nor on another unit's."""
    unit, other = lens_unit("LINE-00001", 3.0), lens_unit("LINE-00002", 3.0)
    world = SimWorld(stage_deg=80.0, lens_unit=unit)
    with SimulatedCamera(world, width=480, height=360, noise_sigma=0.0, bit_depth=16) as cam:
        cam.lock_focus(0.5)
        cam.capture()
        r = cam.last_rendered
        world.lens_unit = None  # the nominal lens mounted instead: the kept lens map follows
        cam.capture()
        r_nominal = cam.last_rendered
    assert r.lens == lens_for_focus(0.5, 480, 360, unit) and r_nominal.lens == lens_for_focus(0.5, 480, 360)
    pts = np.concatenate(true_edge_curves(r, margin=12))
    for lens in (lens_for_focus(0.5, 480, 360), lens_for_focus(0.5, 480, 360, other)):
        moved = lens.distort_points(r.lens.undistort_points(pts))
        assert np.hypot(*(moved - pts).T).max() > 0.2  # the lenses differ measurably
    own = np.concatenate([scanline_errors(r), scanline_errors(r_nominal)])
    assert len(own) >= 40 and np.abs(own).max() < 0.005
    assert np.abs(scanline_errors(r, truth=r_nominal)).max() > 0.1
