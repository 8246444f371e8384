"""The harp renderer: rendered edges sit exactly where the ground truth says.

Edge positions are checked by a method independent of the pipeline's edge
detector (:mod:`tests.pipeline.scanline_fit`): a least-squares fit of the
blurred-string model along image rows or columns.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.models.base import IdentityModel
from pipeline.models.radial import RadialModel
from pipeline.render import (
    EdgeTruth,
    HarpScene,
    edge_peak_offset,
    ideal_grid,
    render_harp,
    true_edge_curves,
    visible_edges,
)
from tests.pipeline.scanline_fit import scanline_errors

W, H = 360, 270


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0, 90.0, 123.0, 171.5])
@pytest.mark.parametrize("width", [3.0, 8.0])
def test_edges_match_truth_without_distortion(angle, width):
    scene = HarpScene(angle_deg=angle, spacing_px=40.0, string_width_px=width, phase_px=3.3, vignetting=0.3)
    r = render_harp(W, H, scene, noise_sigma=0.0, bit_depth=16)
    errs = scanline_errors(r)
    assert len(errs) >= 20
    assert np.abs(errs).max() < 0.005, np.abs(errs).max()


LENSES = {
    "barrel": RadialModel.for_image(W, H, k=(1.0, 0.0, 0.04)),
    "pincushion": RadialModel.for_image(W, H, k=(1.0, 0.0, -0.04, 0.0, 0.01)),
    "decentred": RadialModel.for_image(
        W, H, k=(1.0, 0.0, 0.03), center=(W / 2 + 17.0, H / 2 - 11.0), tangential=(0.002, -0.001)
    ),
}


@pytest.mark.parametrize("lens_name", sorted(LENSES))
@pytest.mark.parametrize("angle", [8.0, 60.0, 100.0])
def test_edges_match_truth_through_lens(lens_name, angle):
    lens = LENSES[lens_name]
    scene = HarpScene(angle_deg=angle, spacing_px=45.0, string_width_px=3.0, vignetting=0.2)
    r = render_harp(W, H, scene, lens=lens, noise_sigma=0.0, bit_depth=16)
    curves = true_edge_curves(r)

    # the lens really bends the edges: largest sagitta far above the tolerance
    def sagitta(c):
        chord = c[-1] - c[0]
        return np.ptp((c - c[0]) @ (np.array([-chord[1], chord[0]]) / np.hypot(*chord)))

    assert max(sagitta(c) for c in curves) > 1.0
    errs = scanline_errors(r)
    assert len(errs) >= 20
    assert np.abs(errs).max() < 0.005, np.abs(errs).max()


def test_truth_curves_are_the_lens_image_of_ideal_lines():
    lens = LENSES["decentred"]
    r = render_harp(W, H, HarpScene(angle_deg=33.0, spacing_px=50.0), lens=lens, noise_sigma=0.0)
    pairs = visible_edges(r, margin=4.0, step=0.5)
    assert len(pairs) == len(true_edge_curves(r, margin=4.0, step=0.5)) >= 10
    for e, c in pairs:
        ideal = lens.undistort_points(c)
        assert np.abs(ideal @ np.asarray(e.normal) - e.offset).max() < 1e-6
        assert c.min() >= 4.0 and c[:, 0].max() <= W - 5.0 and c[:, 1].max() <= H - 5.0
        steps = np.hypot(*np.diff(c, axis=0).T)
        assert np.all((steps > 0.4) & (steps < 0.6))  # ordered, about `step` apart
        d = np.diff(c, axis=0) @ np.array([math.cos(math.radians(33.0)), math.sin(math.radians(33.0))])
        assert np.all(d > 0)  # ordered along the string direction
    # both edges of each string, offsets w apart
    by = {}
    for e, _ in pairs:
        by.setdefault(e.string_index, []).append(e)
    for es in by.values():
        if len(es) == 2:
            assert abs(abs(es[0].offset - es[1].offset) - 3.0) < 1e-12


def test_edges_given_as_truth_list_need_lens_and_size():
    r = render_harp(W, H, HarpScene(angle_deg=90.0), noise_sigma=0.0)
    with pytest.raises(ValueError, match="lens, width and height"):
        true_edge_curves(r.edges)
    same = true_edge_curves(r.edges, IdentityModel(), W, H)
    assert [c.tolist() for c in same] == [c.tolist() for c in true_edge_curves(r)]
    # vertical strings: x constant and equal to the edge offset (normal (-1, 0))
    for e, c in visible_edges(r):
        assert isinstance(e, EdgeTruth)
        assert np.allclose(c[:, 0], -e.offset)


def test_gradient_peak_offset_is_tiny_and_quantified():
    s = HarpScene().sigma_px
    # against a dense numerical evaluation of the profile's gradient
    for w, bound in [(3.0, 0.002), (8.0, 1e-9)]:
        q = np.linspace(-w / 2 - 1.0, -w / 2 + 1.0, 400001)
        grad = np.exp(-0.5 * ((q + w / 2) / s) ** 2) - np.exp(-0.5 * ((q - w / 2) / s) ** 2)
        peak = q[np.argmax(np.abs(grad))]
        shift = -(peak + w / 2)
        assert abs(edge_peak_offset(w, s) - shift) < 1e-5
        assert 0 <= edge_peak_offset(w, s) < bound
    assert 0.0011 < edge_peak_offset(3.0, s) < 0.0013


def test_read_noise_statistics_and_seeds():
    scene = HarpScene(angle_deg=20.0, vignetting=0.0)
    clean = render_harp(W, H, scene, noise_sigma=0.0, bit_depth=16).image.astype(float) / (65535 / 255)
    noisy = render_harp(W, H, scene, noise_sigma=2.0, seed=7)
    diff = noisy.image.astype(float) - clean
    assert abs(diff.mean()) < 0.03
    assert abs(diff.std() - math.sqrt(4 + 1 / 12)) < 0.05
    again = render_harp(W, H, scene, noise_sigma=2.0, seed=7)
    other = render_harp(W, H, scene, noise_sigma=2.0, seed=8)
    assert np.array_equal(again.image, noisy.image)
    assert not np.array_equal(other.image, noisy.image)


def test_shot_noise_variance_follows_level():
    scene = HarpScene(angle_deg=0.0, spacing_px=200.0, vignetting=0.5)
    clean = render_harp(W, H, scene, noise_sigma=0.0, bit_depth=16).image.astype(float) / (65535 / 255)
    noisy = render_harp(
        W, H, scene, noise_sigma=0.0, shot_noise=True, electrons_per_level=20.0, bit_depth=16, seed=3
    ).image.astype(float) / (65535 / 255)
    var = (noisy - clean) ** 2
    for lo, hi in [(100, 140), (170, 205)]:
        m = (clean > lo) & (clean < hi)
        assert m.sum() > 2000
        assert abs(var[m].mean() / clean[m].mean() - 1 / 20.0) < 0.004


def test_bit_depth_exposure_and_saturation():
    scene = HarpScene(angle_deg=70.0)
    r8 = render_harp(W, H, scene, noise_sigma=0.0)
    r16 = render_harp(W, H, scene, noise_sigma=0.0, bit_depth=16)
    assert r8.image.dtype == np.uint8 and r16.image.dtype == np.uint16
    assert r8.image.shape == r16.image.shape == (H, W)
    assert np.abs(r16.image / (65535 / 255) - r8.image).max() <= 0.5 + 1e-9
    assert r8.image.max() == 200  # background at the centre, vignetting only darkens
    bright = render_harp(W, H, scene, noise_sigma=0.0, exposure=2.0)
    assert bright.image.max() == 255 and (bright.image == 255).mean() > 0.5
    half = render_harp(W, H, scene, noise_sigma=0.0, exposure=0.5, bit_depth=16)
    assert np.abs(half.image.astype(float) * 2 - r16.image).max() <= 1.0 + 1e-9
    with pytest.raises(ValueError, match="bit_depth"):
        render_harp(W, H, scene, bit_depth=12)
    with pytest.raises(ValueError, match="spacing_px"):
        render_harp(W, H, HarpScene(spacing_px=2.0))


def test_vignetting_reaches_configured_falloff_at_corners():
    r = render_harp(
        W,
        H,
        HarpScene(angle_deg=45.0, spacing_px=1000.0, phase_px=400.0, vignetting=0.3),
        noise_sigma=0.0,
        bit_depth=16,
    )
    img = r.image / (65535 / 255)
    for y, x in [(0, 0), (0, W - 1), (H - 1, 0), (H - 1, W - 1)]:
        assert abs(img[y, x] - 0.7 * 200) < 0.01
    assert abs(img[H // 2, W // 2] - 200) < 0.05


def test_dust_darkens_where_recorded_and_does_not_depend_on_noise_seed():
    scene = HarpScene(angle_deg=10.0, dust=6, dust_seed=4, vignetting=0.0)
    r = render_harp(W, H, scene, noise_sigma=0.0, bit_depth=16)
    ref = render_harp(W, H, HarpScene(angle_deg=10.0, vignetting=0.0), noise_sigma=0.0, bit_depth=16)
    assert len(r.dust) == 6
    ratio = (r.image.astype(float) + 1) / (ref.image.astype(float) + 1)
    for sp in r.dust:
        x, y = int(round(sp.x)), int(round(sp.y))
        expected = 1 - sp.depth * math.exp(-((x - sp.x) ** 2 + (y - sp.y) ** 2) / (2 * sp.sigma**2))
        assert abs(ratio[y, x] - expected) < 0.03
    far = np.ones((H, W), bool)
    yy, xx = np.mgrid[0:H, 0:W]
    for sp in r.dust:
        far &= (xx - sp.x) ** 2 + (yy - sp.y) ** 2 > (6 * sp.sigma) ** 2
    assert np.abs(ratio[far] - 1).max() < 1e-3
    other = render_harp(W, H, scene, noise_sigma=1.0, seed=99)
    assert other.dust == r.dust


def test_dust_at_given_places():
    scene = HarpScene(angle_deg=90.0, spacing_px=500.0, vignetting=0.0, dust_at=((50.0, 60.0, 6.0, 0.5),))
    r = render_harp(W, H, scene, noise_sigma=0.0)
    assert len(r.dust) == 1 and r.dust[0].x == 50.0
    assert r.image[60, 50] == 100 and r.image[60, 50 + 30] == 200
    assert np.argmin(r.image[60, :150]) == 50 and np.argmin(r.image[:150, 50]) == 60
    with pytest.raises(ValueError, match="dust_at"):
        render_harp(W, H, HarpScene(dust_at=((1.0, 2.0, 0.0, 0.5),)))


@pytest.mark.parametrize("side", [1, -1])
def test_frame_is_dark_beyond_its_line_and_hides_strings(side):
    scene = HarpScene(angle_deg=35.0, frame=True, frame_side=side, frame_depth_px=90.0, vignetting=0.0)
    r = render_harp(W, H, scene, noise_sigma=0.0)
    plain = render_harp(W, H, HarpScene(angle_deg=35.0, vignetting=0.0), noise_sigma=0.0)
    n = np.asarray(scene.normal)
    yy, xx = np.mgrid[0:H, 0:W]
    q = side * (np.stack([xx, yy], -1) @ n - r.frame_offset)
    s = scene.sigma_px
    assert (q > 4 * s).sum() > 1000
    assert r.image[q > 4 * s].max() <= 15  # frame level
    assert np.array_equal(r.image[q < -6 * s], plain.image[q < -6 * s])
    # no truth edge within 6 sigma of the frame or inside it; the others are all kept
    assert all(side * (e.offset - r.frame_offset) < -6 * s for e in r.edges)
    assert 0 < len(r.edges) < len(plain.edges)
    assert len(plain.edges) - len(r.edges) >= 2 * int(80.0 / scene.spacing_px)


def test_image_does_not_depend_on_chunking_or_threads():
    lens = LENSES["decentred"]
    scene = HarpScene(angle_deg=52.0, dust=3, frame=True)
    kw = dict(lens=lens, noise_sigma=1.5, shot_noise=True, seed=12)
    one = render_harp(W, H, scene, threads=1, chunk_pixels=1 << 20, **kw)
    many = render_harp(W, H, scene, threads=3, chunk_pixels=W * 16, **kw)
    assert np.array_equal(one.image, many.image)
    with pytest.raises(ValueError, match="seed"):
        render_harp(W, H, scene, seed=-1)


def test_a_precomputed_lens_map_gives_the_same_image():
    lens = LENSES["decentred"]
    grid = ideal_grid(lens, W, H)
    # the map is the lens at every pixel centre (x = column, y = row)
    assert grid.shape == (H, W, 2)
    assert np.allclose(grid[7, 11], lens.undistort_points(np.array([[11.0, 7.0]]))[0], atol=1e-12)
    for angle in (0.0, 52.0, 133.0):
        scene = HarpScene(angle_deg=angle, dust=2, frame=True)
        kw = dict(lens=lens, noise_sigma=1.5, seed=5, chunk_pixels=W * 16)
        assert np.array_equal(render_harp(W, H, scene, **kw).image, render_harp(W, H, scene, ideal=grid, **kw).image)
    with pytest.raises(ValueError, match="ideal"):
        render_harp(W, H + 1, HarpScene(), lens=lens, ideal=grid)
    with pytest.raises(ValueError, match="ideal"):
        render_harp(W, H, HarpScene(), ideal=grid)  # the identity lens has no map to pass
