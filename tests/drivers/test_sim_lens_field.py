"""A residual field on a simulated lens unit (``simulation.lens_field_px``): what the field stage of a whole
simulated session is measured against (``benchmarks/field_sessions.py``).

Truths: the field is what the lens maps differ by, measured point by point through ``undistort_points`` of the
lens with and without it (its RMS over the image is the configured one, it is the unit's at every focus), and
rendered frames are checked against the exact edge curves of the lens with its field by an independent scanline
fit.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim.camera import SimulatedCamera
from drivers.sim.lens import lens_field, lens_for_focus, lens_unit, with_field
from drivers.sim.world import SimWorld
from pipeline.render import true_edge_curves
from tests.pipeline.scanline_fit import scanline_errors

W, H = 480, 360


def _grid(step: float = 4.0) -> np.ndarray:
    gx, gy = np.meshgrid(np.arange(0.0, W, step), np.arange(0.0, H, step))
    return np.stack([gx.ravel(), gy.ravel()], 1)


def _field(focus: float, serial: str, rms: float) -> np.ndarray:
    unit = lens_unit(serial, 1.0)
    base = lens_for_focus(focus, W, H, unit)
    pts = _grid()
    return np.asarray(
        with_field(base, lens_field(serial, rms), W, H).undistort_points(pts) - base.undistort_points(pts)
    )


def test_a_serial_has_its_own_field_of_the_configured_size_at_every_focus():
    f = _field(0.5, "FIELD-1", 0.02)
    rms = float(np.sqrt(np.mean(np.sum(f**2, 1))))
    assert rms == pytest.approx(0.02, rel=0.03)  # the configured RMS over the image (a finer grid than the draw's)
    # the unit's own: the same at another focus, the same serial again; another serial another shape
    np.testing.assert_allclose(_field(0.0, "FIELD-1", 0.02), f, atol=1e-12)
    np.testing.assert_array_equal(_field(0.5, "FIELD-1", 0.02), f)
    g = _field(0.5, "FIELD-2", 0.02)
    corr = float(np.sum(f * g) / np.sqrt(np.sum(f**2) * np.sum(g**2)))
    assert abs(corr) < 0.5, corr
    # the size scales the same shape
    np.testing.assert_allclose(_field(0.5, "FIELD-1", 0.04), 2 * f, rtol=1e-9, atol=1e-12)
    # 0: no field, the lens itself; a bad size is refused with the setting's name
    assert lens_field("FIELD-1", 0.0) is None
    unit = lens_unit("FIELD-1", 1.0)
    assert with_field(lens_for_focus(0.5, W, H, unit), None, W, H) == lens_for_focus(0.5, W, H, unit)
    for bad in (-0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="lens_field_px"):
            lens_field("FIELD-1", bad)


def test_the_camera_renders_the_unit_with_its_field():
    """Frames of a camera whose world holds a unit with a field lie on the exact edges of that lens with its
    field (independent scanline fit), not on the same unit's without it."""
    serial = "FIELD-3"
    unit, field = lens_unit(serial, 1.0), lens_field(serial, 0.3)  # large, so that the frames show it clearly
    world = SimWorld(stage_deg=80.0, lens_unit=unit, lens_field=field)
    with SimulatedCamera(world, width=W, height=H, noise_sigma=0.0, bit_depth=16) as cam:
        cam.lock_focus(0.5)
        cam.capture()
        r = cam.last_rendered
        world.lens_field = None  # the same unit without its field: the kept lens map follows
        cam.capture()
        r_plain = cam.last_rendered
    truth = with_field(lens_for_focus(0.5, W, H, unit), field, W, H)
    pts = np.concatenate(true_edge_curves(r, margin=12))
    np.testing.assert_allclose(r.lens.undistort_points(pts), truth.undistort_points(pts), atol=1e-12)
    assert r_plain.lens == lens_for_focus(0.5, W, H, unit)
    own = np.concatenate([scanline_errors(r), scanline_errors(r_plain)])
    assert len(own) >= 40 and np.abs(own).max() < 0.005
    assert np.abs(scanline_errors(r, truth=r_plain)).max() > 0.1
