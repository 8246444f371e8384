"""The realistic simulator's shots: exact truth for bent strings, seeds, drawn sessions.

A bent string's truth is its ideal curve traced through the lens by Newton's method
(``tests/pipeline/_harp_truth.py``), independently of the renderer's per-pixel
evaluation and of the measurement; the renderer's straight edges are checked by the
independent scanline fit (:mod:`tests.pipeline.scanline_fit`).
"""

from __future__ import annotations

import dataclasses
import math
from functools import cache

import numpy as np
import pytest

from pipeline import realism
from pipeline.harp_scene import Harp, HarpMount, StringShape
from pipeline.measure import measure_image
from pipeline.models.radial import RadialModel
from pipeline.realism import Effects, raw_ideal_grid, realistic_session, render_shot, render_shots
from pipeline.render import EdgeTruth, visible_edges
from pipeline.sensor import Development
from tests.pipeline import _harp_truth as truth
from tests.pipeline.scanline_fit import scanline_errors

W, H = 800, 600
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03), center=(W / 2 + 17, H / 2 - 11), tangential=(0.002, -0.001))
CENTRE = ((W - 1) / 2 + 5.0, (H - 1) / 2 - 3.0)
LINEAR16 = Effects(development=Development(bit_depth=16))


@pytest.mark.parametrize("lens", [None, LENS], ids=["identity", "decentred"])
@pytest.mark.parametrize("angle", [0.0, 17.0, 60.0, 100.0, 171.5])
def test_straight_strings_sit_on_their_exact_edges(lens, angle):
    harp = Harp.straight(21, 40.0, 3.0, 3.3)
    shot = render_shot(lens, harp, HarpMount(CENTRE, angle), 0.0, 360, 270, LINEAR16)
    errs = scanline_errors(shot)
    assert len(errs) >= 20
    assert np.abs(errs).max() < 0.005


def _bent_harp(kinks: bool) -> Harp:
    """Bows of ~0.4 px; with ``kinks`` also a 0.3 px kink per string and a twisted oval section
    (half-width +-0.05 px every 200 px): detail the along-edge smoothing (t = 30) cannot follow."""
    rng = np.random.default_rng(1)
    strings = []
    for k in range(15):
        strings.append(
            StringShape(
                k,
                (k - 7) * 60.0,
                1.5,
                half_span_px=600.0,
                bow_px=tuple(float(v) for v in rng.normal(0.0, 0.4, 3)),
                kink_at_px=float(rng.uniform(-250, 250)),
                kink_px=0.3 if kinks else 0.0,
                kink_length_px=12.0,
                ovality_px=0.05 if kinks else 0.0,
                twist_period_px=400.0,
            )
        )
    return Harp(tuple(strings), 60.0)


@cache
def _bent(angle: float, kinks: bool):
    shot = render_shot(LENS, _bent_harp(kinks), HarpMount(CENTRE, angle), 0.0, W, H, LINEAR16)
    m = measure_image(shot.image)
    return shot, m, truth.compare(shot, m)


def _offsets(te: truth.TrueEdge, pts: np.ndarray) -> np.ndarray:
    """Distance of ``pts`` to the exact curve, less its median (the constant outward offset of the
    detector's gradient maxima), for the points inside the truth's margin."""
    inside = truth._inside(
        pts, np.array([truth.MARGIN_PX] * 2), np.array([W - 1 - truth.MARGIN_PX, H - 1 - truth.MARGIN_PX])
    )
    d = truth.curve_distance(te, pts[inside])
    return d - np.median(d)


@pytest.mark.parametrize("angle", [10.0, 75.0])
def test_a_bent_string_is_measured_on_its_exact_traced_curve(angle):
    shot, m, c = _bent(angle, kinks=True)
    assert len(c.matches) >= 20 and all(te.length < 100 for te in c.missing)
    bends, raw = [], []
    for mt in c.matches:
        te = c.truths[mt.truth]
        bends.append(np.ptp(truth.signed_distances(te.points)))
        raw.append(_offsets(te, m.lines[mt.line].raw_points))
    raw = np.concatenate(raw)
    # the strings really bend (lens and shape together), and the raw edge points follow the bent curve
    assert np.median(bends) > 0.5
    assert float(np.sqrt(np.mean(raw**2))) < 0.025
    # whole-edge d of the truth = measured d (the kinks' 12 px cusps are smoothed away by t = 30: < 0.5 %)
    assert m.d == pytest.approx(c.true.d, rel=5e-3)


def test_a_smooth_bend_survives_the_along_edge_smoothing():
    shot, m, c = _bent(40.0, kinks=False)
    # every smoothed point but each edge's first and last (put on the image border by the
    # measurement's extrapolation: pipeline.measure) lies on the bent curve
    sm = np.concatenate([_offsets(c.truths[mt.truth], m.lines[mt.line].points[1:-1]) for mt in c.matches])
    assert float(np.sqrt(np.mean(sm**2))) < 0.006
    assert m.d == pytest.approx(c.true.d, rel=2e-3)
    # the straight-line truth of the same edges misses the bend: the test can fail
    straight = [dataclasses.replace(e, shape=None) for e in shot.edges]
    flat = dataclasses.replace(shot, edges=tuple(straight))
    cf = truth.compare(flat, m, max_dist=3.0)
    off = np.concatenate([_offsets(cf.truths[mt.truth], m.lines[mt.line].points[1:-1]) for mt in cf.matches])
    assert float(np.sqrt(np.mean(off**2))) > 0.05


def test_the_truth_lists_every_edge_that_reaches_the_image_and_their_shapes():
    shot, m, c = _bent(75.0, kinks=True)
    everything = visible_edges(shot.harp.edges(shot.pose), LENS, W, H, min_length_px=1.0)
    listed = {(e.string_index, e.side) for e in shot.edges}
    assert {(e.string_index, e.side) for e, _ in everything} <= listed
    for e, curve in visible_edges(shot, margin=4.0, step=0.5):
        assert isinstance(e, EdgeTruth) and e.shape is not None
        # each traced point maps through the lens onto the bent ideal edge
        assert np.abs(e.level(LENS.undistort_points(curve))).max() < 1e-6
        # the shape is the string's own deviation in harp coordinates (these strings do not sag)
        u = LENS.undistort_points(curve)
        a, b = shot.pose.to_harp(u)
        st = shot.harp.strings[e.string_index]
        assert np.allclose(e.displacement(u @ np.asarray(e.along)), st.edge_deviation(a, e.side), atol=1e-12)
        assert np.allclose(b, st.position_px + e.side * st.radius_px + st.edge_deviation(a, e.side), atol=1e-6)
    assert np.allclose(
        shot.string_deviation(3, np.array([0.0, 100.0])), shot.harp.strings[3].deviation(np.array([0.0, 100.0]))
    )


def test_shots_are_seeded_and_do_not_depend_on_chunks_threads_or_a_kept_lens_map():
    s = realistic_session(4, 320, 240, spacing_px=40.0, string_width_px=3.0, demosaic="bilinear")
    one = render_shots(LENS, s.harp, s.mount, [0.0, 35.0], 320, 240, s.effects, seed=9)
    two = render_shots(LENS, s.harp, s.mount, [0.0, 35.0], 320, 240, s.effects, seed=9)
    other = render_shots(LENS, s.harp, s.mount, [0.0, 35.0], 320, 240, s.effects, seed=10)
    assert all(np.array_equal(a.image, b.image) for a, b in zip(one, two))
    assert not np.array_equal(one[0].image, other[0].image)
    assert one[0].seed != one[1].seed == realism.shot_seed(9, 1)
    lens = LENS
    kw = dict(effects=s.effects, seed=5)
    base = render_shot(lens, s.harp, s.mount, 20.0, 320, 240, **kw)
    chunked = render_shot(lens, s.harp, s.mount, 20.0, 320, 240, chunk_pixels=320 * 7, threads=3, **kw)
    kept = render_shot(lens, s.harp, s.mount, 20.0, 320, 240, ideal=raw_ideal_grid(lens, 320, 240, s.effects), **kw)
    assert np.array_equal(base.image, chunked.image) and np.array_equal(base.image, kept.image)
    with pytest.raises(ValueError, match="ideal"):
        render_shot(lens, s.harp, s.mount, 20.0, 320, 240, ideal=np.zeros((2, 2, 2)), **kw)
    with pytest.raises(ValueError, match="seed"):
        render_shot(lens, s.harp, s.mount, 20.0, 320, 240, seed=-1)


def test_a_drawn_session_draws_every_effect_within_its_documented_range():
    for seed in range(8):
        s = realistic_session(seed, 1761, 1174, spacing_px=(110.0, 140.0), string_width_px=(2.4, 3.1))
        e = s.effects
        assert realism.BLUR_SIGMA_PX[0] <= e.blur.sigma_px <= realism.BLUR_SIGMA_PX[1]
        for c in (e.blur.corner_tangential_px, e.blur.corner_sagittal_px):
            assert realism.BLUR_CORNER_PX[0] <= c <= realism.BLUR_CORNER_PX[1]
        assert (
            e.vignetting is not None
            and realism.VIGNETTING_CORNER[0] <= e.vignetting.corner <= realism.VIGNETTING_CORNER[1]
        )
        assert e.backlight is not None and realism.MOTTLE[0] <= e.backlight.mottle <= realism.MOTTLE[1]
        assert realism.FULL_WELL_E[0] <= e.sensor.full_well_e <= realism.FULL_WELL_E[1] and e.sensor.shot_noise
        assert e.sensor.cfa == "RGGB" and e.development.jpeg_quality is None
        assert 110.0 <= s.harp.spacing_px <= 140.0 and 2.4 <= 2 * s.harp.strings[0].radius_px <= 3.1
        # the strings cover the image at every angle and the span keeps the frame outside it
        diag = math.hypot(1761, 1174)
        assert min(st.half_span_px - abs(st.span_centre_px) for st in s.harp.strings) > 0.55 * diag
        b = [st.position_px for st in s.harp.strings]
        assert min(b) < -0.55 * diag and max(b) > 0.55 * diag
        assert s == realistic_session(seed, 1761, 1174, spacing_px=(110.0, 140.0), string_width_px=(2.4, 3.1))
    assert realistic_session(1, 640, 480, jpeg=True).effects.development.jpeg_quality in range(90, 98)


def test_a_realistic_shot_is_measured_and_its_edges_are_where_the_truth_says():
    s = realistic_session(2, 640, 480, spacing_px=50.0, string_width_px=3.0, demosaic="bilinear", tone="bt709")
    shot = render_shot(
        LENS.__class__.for_image(640, 480, k=(1.0, 0.0, 0.03)), s.harp, s.mount, 30.0, 640, 480, s.effects, seed=2
    )
    assert shot.image.dtype == np.uint8 and shot.image.shape == (480, 640)
    m = measure_image(shot.image)
    c = truth.compare(shot, m)
    assert len(c.matches) >= 18
    # all effects together: every measured edge within a few hundredths of its exact curve, d within 2 %
    med = [float(np.median(truth.curve_distance(c.truths[mt.truth], m.lines[mt.line].points))) for mt in c.matches]
    assert max(med) < 0.3
    assert m.d == pytest.approx(c.true.d, rel=0.02)
