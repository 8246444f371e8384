"""pipeline.assess against truths that do not pass through it.

* sharpness: the renderer's exact PSF (``HarpScene.sigma_px`` = sqrt(blur^2 + 1/12)), string
  width and contrast (1 - string_level / background);
* through focus: the simulated camera's documented defocus, best focus 0.37;
* exposure figures: numpy's own percentiles and counts;
* coverage: the exact image of every visible string edge through the simulated lens
  (``tests.pipeline._harp_truth.whole_edges``), binned here by the test's own loop.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from drivers.sim.camera import SimulatedCamera
from drivers.sim.lens import lens_for_focus
from pipeline.assess import (
    CELLS_ACROSS,
    DIRECTION_BIN_DEG,
    EDGE_WIDTH_PER_SIGMA,
    MIN_CELL_EDGE_FRACTION,
    MIN_SEPARATION_DEG,
    analysis_scale,
    assess_frame,
    edge_coverage,
    empty_coverage,
    exposure_figures,
    focus_peak,
    string_sharpness,
)
from pipeline.render import HarpScene, render_harp
from tests.pipeline._harp_truth import whole_edges


# ------------------------------------------------------------------ sharpness
@pytest.mark.parametrize(
    "blur, width, angle, tol",
    [
        (0.7, 8.0, 30.0, 0.02),
        (1.5, 8.0, 90.0, 0.02),
        (3.0, 8.0, 7.0, 0.02),
        (0.7, 3.0, 60.0, 0.02),
        (1.5, 3.0, 120.0, 0.04),  # sigma as large as half the string: width and depth start to trade off
    ],
)
def test_string_sharpness_matches_the_rendered_psf(blur, width, angle, tol):
    scene = HarpScene(angle_deg=angle, blur_px=blur, string_width_px=width)
    r = render_harp(360, 280, scene, seed=11)
    a = assess_frame(r.image)
    assert a.n_strings >= 4
    truth = EDGE_WIDTH_PER_SIGMA * scene.sigma_px  # 10-90 % of a Gaussian-blurred step
    ew = np.array([s.edge_width_px for s in a.strings])
    assert np.all(np.isfinite(ew))
    assert np.median(ew) == pytest.approx(truth, rel=tol)
    assert np.all(np.abs(ew / truth - 1) < 3 * tol), ew / truth
    contrast = np.array([s.contrast for s in a.strings])
    assert np.median(contrast) == pytest.approx(1 - scene.string_level / scene.background, abs=0.03)
    assert np.median([s.width_px for s in a.strings]) == pytest.approx(width, abs=0.15 if width > 3 else 0.3)
    for s in a.strings:
        d = (s.angle_deg - angle) % 180.0
        assert min(d, 180 - d) < 0.5
    assert a.focus_score == pytest.approx(1.0 / np.median(ew))


def test_sharpness_is_independent_of_the_exposure_and_of_bright_strings():
    base = HarpScene(angle_deg=20.0, blur_px=1.0, string_width_px=5.0)
    truth = EDGE_WIDTH_PER_SIGMA * base.sigma_px
    for scene, exposure in (
        (base, 0.5),
        (base, 1.2),
        (dataclasses.replace(base, background=40.0, string_level=200.0), 1.0),
    ):
        a = assess_frame(render_harp(360, 280, scene, seed=5, exposure=exposure).image)
        assert a.n_strings >= 4
        assert a.edge_width_px == pytest.approx(truth, rel=0.03), (scene, exposure)


def test_string_sharpness_reports_a_failed_string_as_nan():
    img = np.full((100, 100), 128, np.uint8)
    out = string_sharpness(img, [(0, np.array([[10.0, 10.0]]), np.array([[12.0, 10.0]]))])
    assert len(out) == 1 and out[0].cross_sections == 0 and math.isnan(out[0].edge_width_px)


# ------------------------------------------------------------------ through focus
def test_focus_score_peaks_at_the_simulated_best_focus():
    """A focus sweep on the simulated camera (best_focus 0.37, defocus_blur_px 8): the best sample
    and the fitted peak are within 0.02 of 0.37; each edge width follows the documented blur."""
    cam = SimulatedCamera(width=480, height=360, seed=3, best_focus=0.37, defocus_blur_px=8.0)
    settings = np.round(np.arange(0.21, 0.535, 0.02), 3)
    scores, th = [], None
    with cam:
        for f in settings:
            cam.lock_focus(float(f))
            frame = cam.capture()
            a = assess_frame(frame.image, thresholds=th)
            th = a.thresholds
            scores.append(a.focus_score)
            truth = EDGE_WIDTH_PER_SIGMA * math.sqrt(frame.extra["sim"]["blur_px"] ** 2 + 1 / 12)
            assert a.edge_width_px == pytest.approx(truth, rel=0.04), f
    best = float(settings[int(np.argmax(scores))])
    assert abs(best - 0.37) <= 0.02
    peak = focus_peak(settings, scores)
    assert peak is not None and peak.bracketed
    assert abs(peak.focus - 0.37) <= 0.02
    assert abs(peak.focus - 0.37) <= 0.005  # what the parabola actually achieves here
    print(f"\nfocus sweep: best sample {best:.3f}, fitted peak {peak.focus:.4f} (true 0.37)")


def test_focus_peak_of_an_exact_through_focus_curve():
    f = np.linspace(0.0, 1.0, 21)
    w2 = 4.0 + 900.0 * (f - 0.4137) ** 2  # squared edge width of sigma^2 = s0^2 + k^2 (f - f*)^2
    peak = focus_peak(f, 1.0 / np.sqrt(w2))
    assert peak is not None and peak.bracketed and peak.focus == pytest.approx(0.4137, abs=1e-9)
    assert peak.score == pytest.approx(0.5, rel=1e-9)
    # still rising at the end of the samples: the best one, not bracketed
    half = focus_peak(f[:7], 1.0 / np.sqrt(w2[:7]))
    assert half is not None and not half.bracketed and half.focus == pytest.approx(f[6])
    assert focus_peak([0.1, 0.2], [float("nan"), 0.0]) is None
    # repeated settings are averaged
    rep = focus_peak(np.repeat(f, 3), np.repeat(1.0 / np.sqrt(w2), 3))
    assert rep is not None and rep.focus == pytest.approx(0.4137, abs=1e-9) and rep.samples == 63


# ------------------------------------------------------------------ exposure
@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 65535)])
def test_exposure_figures_are_the_sessions_figures(dtype, top):
    rng = np.random.default_rng(4)
    img = np.clip(rng.normal(0.6 * top, 0.25 * top, (123, 97)), 0, top).astype(dtype)
    img[:5] = top
    img[-3:] = 0
    e = exposure_figures(img)
    lo, hi = np.percentile(img, [0.5, 99.5])
    assert e.low == lo and e.high == hi
    assert e.dynamic_range == pytest.approx((hi - lo) / top, abs=1e-12)
    assert e.saturated_fraction == np.mean(img >= top)
    assert e.dark_fraction == np.mean(img <= 0.02 * top)
    assert e.mean == pytest.approx(img.mean())
    assert e.histogram.sum() == img.size and len(e.histogram) == 64
    f = exposure_figures(img.astype(np.float64), full_scale=top)  # an averaged shot
    assert (f.low, f.high, f.saturated_fraction) == (lo, hi, e.saturated_fraction)


def test_exposure_figures_reject_a_non_image():
    with pytest.raises(ValueError, match="2-D"):
        exposure_figures(np.zeros((3, 4, 3), np.uint8))


# ------------------------------------------------------------------ coverage
def _true_coverage(rendered, width, height):
    """Covered cells from the exact visible edges: the test's own binning (not pipeline.assess)."""
    cell = max(width, height) / CELLS_ACROSS
    nx, ny = math.ceil(width / cell), math.ceil(height / cell)
    nb = round(180 / DIRECTION_BIN_DEG)
    length = np.zeros((ny, nx, nb))
    for e in whole_edges(rendered, margin=0.0):
        for piece in e.dense:
            for p, q in zip(piece[:-1], piece[1:]):
                m = 0.5 * (p + q)
                i, j = int((m[0] + 0.5) // cell), int((m[1] + 0.5) // cell)
                ang = math.degrees(math.atan2(q[1] - p[1], q[0] - p[0])) % 180
                length[min(j, ny - 1), min(i, nx - 1), min(int(ang // DIRECTION_BIN_DEG), nb - 1)] += math.dist(p, q)
    return length, cell


def _covered(length, cell):
    present = length >= MIN_CELL_EDGE_FRACTION * cell
    nb = length.shape[2]
    sep = math.ceil(MIN_SEPARATION_DEG / DIRECTION_BIN_DEG)
    out = np.zeros(length.shape[:2], bool)
    for j, i in np.ndindex(*length.shape[:2]):
        bins = np.nonzero(present[j, i])[0]
        out[j, i] = any(min(abs(a - b), nb - abs(a - b)) >= sep for a in bins for b in bins)
    return out


def test_coverage_misses_the_corners_after_one_orientation_and_fills_them_after_four():
    w, h = 480, 360
    lens = lens_for_focus(0.5, w, h)
    total = empty_coverage(w, h)
    truth = None
    for k, angle in enumerate((5.0, 50.0, 95.0, 140.0)):
        r = render_harp(w, h, HarpScene(angle_deg=angle), lens=lens, seed=k)
        a = assess_frame(r.image)
        length, cell = _true_coverage(r, w, h)
        truth = length if truth is None else np.maximum(truth, length)
        assert np.array_equal(a.coverage.present, length.max(axis=2) >= MIN_CELL_EDGE_FRACTION * cell)
        total = total.merge(a.coverage)
        assert np.array_equal(total.covered, _covered(truth, cell)), k
        if k == 0:
            assert not total.covered.any() and total.corners_covered == (False, False, False, False)
    assert total.covered.all() and total.corners_covered == (True, True, True, True)
    assert total.covered_fraction == 1.0


def test_coverage_with_the_harp_frame_in_view_follows_the_visible_edges():
    """The dark frame hides a side of the image at each orientation: the accumulated coverage
    equals the exact one cell by cell, away from the cells a string barely enters."""
    w, h = 480, 360
    total, truth = empty_coverage(w, h), None
    for k, angle in enumerate((0.0, 90.0)):
        scene = HarpScene(angle_deg=angle, frame=True, frame_depth_px=150.0)
        r = render_harp(w, h, scene, seed=20 + k)
        a = assess_frame(r.image)
        length, cell = _true_coverage(r, w, h)
        truth = length if truth is None else np.maximum(truth, length)
        total = total.merge(a.coverage)
    clear = np.all((truth < 0.1 * cell) | (truth > 0.5 * cell), axis=2)  # no direction near the threshold
    assert clear.mean() > 0.8
    assert np.array_equal(total.covered[clear], _covered(truth, cell)[clear])
    assert 0 < total.covered_fraction < 1  # the frame kept some cells to one direction


def test_edge_coverage_bins_by_direction_and_merges_by_maximum():
    horizontal = np.array([[0.0, 10.0], [10.0, 10.0], [20.0, 10.0], [30.0, 10.0]])  # 30 px at 0 deg, cell (0, 0)
    a = edge_coverage([horizontal], 800, 600)  # cells of 100 px
    assert a.shape == (6, 8) and a.length_px[0, 0, 0] == pytest.approx(30.0) and a.length_px.sum() == 30.0
    assert a.present[0, 0] and a.present.sum() == 1 and not a.covered.any()
    steep = np.linspace([50.0, 0.0], [50.0, 60.0], 7)  # 60 px at 90 deg
    b = edge_coverage([steep], 800, 600)
    assert b.length_px[0, 0, 6] == pytest.approx(60.0)
    both = a.merge(b)
    assert both.covered[0, 0] and both.covered.sum() == 1
    assert np.array_equal(both.merge(both).length_px, both.length_px)  # a frame seen twice adds nothing
    tilted = edge_coverage([np.array([[0.0, 0.0], [20.0, 20.0 * math.tan(math.radians(20))]])], 800, 600)
    assert not a.merge(tilted).covered[0, 0]  # 0 and 20 degrees: closer than MIN_SEPARATION_DEG
    gap = edge_coverage([np.array([[0.0, 10.0], [60.0, 10.0]])], 800, 600)
    assert gap.length_px.sum() == 0  # a segment longer than a quarter cell is a gap in the edge
    with pytest.raises(ValueError):
        a.merge(empty_coverage(801, 600))


# ------------------------------------------------------------------ scale
def test_analysis_scale_keeps_strings_wide_enough():
    assert analysis_scale(1280, 960) == 1.0
    assert analysis_scale(2592, 1944) == 2.0
    assert analysis_scale(2592, 1944, string_width_px=3.0) == 1.0  # 1.5 px strings would be lost
    assert analysis_scale(6000, 4000, string_width_px=12.0) == 4.0
    assert analysis_scale(6000, 4000) == 4.0


def test_tracked_assessment_measures_the_new_frame_and_sees_a_moved_harp():
    scene = HarpScene(angle_deg=30.0, blur_px=1.0, string_width_px=5.0)
    first = assess_frame(render_harp(360, 280, scene, seed=1).image)
    again = render_harp(360, 280, dataclasses.replace(scene, blur_px=1.6), seed=2).image  # refocused, new noise
    t = assess_frame(again, previous=first)
    assert t.tracked and t.edges == first.edges and t.n_strings == first.n_strings
    assert t.edge_width_px == pytest.approx(
        EDGE_WIDTH_PER_SIGMA * dataclasses.replace(scene, blur_px=1.6).sigma_px, rel=0.03
    )
    assert t.offset_px < 0.1
    moved = render_harp(360, 280, dataclasses.replace(scene, phase_px=1.5), seed=3).image  # the harp shifted 1.5 px
    m = assess_frame(moved, previous=first)
    assert m.offset_px == pytest.approx(1.5, abs=0.2)
    fresh = assess_frame(moved)
    assert not fresh.tracked and fresh.offset_px < 0.3


@pytest.mark.parametrize("width, blur, level", [(1.0, 1.5, 0.0), (1.5, 2.0, 0.0), (3.0, 1.5, 0.0), (2.0, 2.0, 60.0)])
def test_a_string_narrower_than_the_blur_never_has_a_contrast_above_one_and_keeps_its_shadow(width, blur, level):
    """Only the shadow |A| w of a string narrower than ~2 sigma is measurable; light below zero is not."""
    scene = HarpScene(angle_deg=30.0, blur_px=blur, string_width_px=width, string_level=level)
    a = assess_frame(render_harp(360, 280, scene, seed=11).image)
    assert a.n_strings >= 4
    contrast = np.array([s.contrast for s in a.strings])
    assert np.all(contrast <= 1.0) and np.all(contrast > 0)
    shadow = np.array([s.contrast * s.width_px for s in a.strings])
    truth = width * (1 - scene.string_level / scene.background)  # the rendered string's shadow, px
    np.testing.assert_allclose(shadow, truth, rtol=0.06)
