"""Sub-pixel edge detector (pipeline/edges.py) against analytic edges with exact positions."""

import cv2
import numpy as np
import pytest

from pipeline.edge_thresholds import auto_thresholds, gradient_noise
from pipeline.edges import EdgeChain, detect_edges, edge_points
from tests.pipeline.synthetic_edges import line_normal, quantise, render_disk, render_step, render_string

ANGLES = [0, 15, 30, 45, 60, 75, 90]
SHAPE = (64, 64)
MARGIN = 6  # ignore points near the image border (smoothing/gradient border effects)


def _distances(chain_xy, point, angle):
    xy = chain_xy
    inside = np.all((xy > MARGIN) & (xy < SHAPE[0] - 1 - MARGIN), axis=1)
    return (xy[inside] - point) @ line_normal(angle)


def _truth(seed):
    rng = np.random.default_rng(seed)
    point = (31.5 + rng.uniform(-0.5, 0.5), 31.5 + rng.uniform(-0.5, 0.5))
    return rng, point


@pytest.mark.parametrize("interp", ["continuous", "gaussian"])
@pytest.mark.parametrize("angle", ANGLES + [40, 44, 46, 50, 89])
def test_noise_free_edge_is_exact(angle, interp):
    # Float image, no noise: what remains is the interpolation model error.
    # Measured: |bias| <= 0.0010 px, spread <= 0.0002 px (Gaussian optics 0.7 px, sigma 1).
    for seed in range(3):
        _, p = _truth(seed)
        chains = detect_edges(render_step(SHAPE, angle, p), interpolation=interp)
        assert len(chains) == 1
        d = _distances(chains[0].xy, p, angle)
        assert d.size > 40
        assert abs(d.mean()) < 0.002, (angle, seed, d.mean())
        # no oscillation along the edge, in particular none around 45 degrees
        assert d.std() < 0.001, (angle, seed, d.std())


def test_classic_parabola_has_pixel_locking_that_the_default_removes():
    # Devernay's parabola on the modulus: systematic error of ~0.02 px at 0 deg for an
    # edge 0.3 px off a pixel centre; the default (continuous maximum) is 20x better.
    p = (31.8, 31.0)  # direction 90 deg -> vertical edge at x = 31.8
    img = render_step(SHAPE, 90, p)
    d_par = _distances(detect_edges(img, interpolation="parabola")[0].xy, p, 90)
    d_def = _distances(detect_edges(img)[0].xy, p, 90)
    assert 0.01 < abs(d_par.mean()) < 0.04
    assert abs(d_def.mean()) < 0.001
    with pytest.raises(ValueError, match="interpolation"):
        detect_edges(img, interpolation="cubic")


def test_thin_string_edges_have_no_pixel_locking():
    # A 3 px dark string at 0.4 deg: along 220 px the sub-pixel phase of its edges sweeps a
    # whole pixel. The two gradient peaks overlap, so the 3-point log-parabola misplaces the
    # edges by an amount that depends on the phase (measured 0.077 px peak-to-peak); the
    # continuous maximum of the same gradient does not (measured 0.0008 px).
    p, angle = (120.3, 20.2), 0.4
    img = render_string((40, 240), angle, p, 3.0)
    spread = {}
    for interp in ("continuous", "gaussian"):
        chains = detect_edges(img, interpolation=interp)
        assert len(chains) == 2
        for c in chains:
            inside = (c.xy[:, 0] > 8) & (c.xy[:, 0] < 231)
            d = (c.xy[inside] - p) @ line_normal(angle)
            assert inside.sum() > 200
            assert 1.6 < abs(d.mean()) < 1.85  # pushed ~0.2 px outwards, same everywhere
            spread[interp] = max(spread.get(interp, 0.0), float(np.ptp(d)))
    assert spread["continuous"] < 0.002
    assert spread["gaussian"] > 0.04


@pytest.mark.parametrize("noise", [0.0, 0.5, 1.5, 3.0])
def test_bias_and_rms_on_8bit_noisy_edges(noise):
    # 8-bit, bright 200 / dark 30, blur 0.7 px. Per-point noise of the detector is about
    # 0.008 px per grey level of noise at this contrast; 8-bit quantisation alone gives a
    # constant error up to ~0.007 px on an axis-aligned edge (every row has the same profile);
    # the bias of ~50 correlated points is a few thousandths. Measured maxima over 6 seeds x 7
    # angles: noise 0 -> 0.0066 / 0.0066, 1.5 -> |bias| 0.0075, RMS 0.0134;
    # 3 -> |bias| 0.0143, RMS 0.0250.
    for angle in ANGLES:
        rng, p = _truth(100 + angle)
        chains = detect_edges(quantise(render_step(SHAPE, angle, p), noise, rng))
        assert len(chains) == 1, (angle, [len(c) for c in chains])
        d = _distances(chains[0].xy, p, angle)
        assert d.size > 40
        assert abs(d.mean()) <= 0.008 + 0.004 * noise, (angle, d.mean())
        assert np.sqrt(np.mean(d**2)) <= 0.008 + 0.007 * noise, (angle, np.sqrt(np.mean(d**2)))


def test_no_extra_noise_at_45_degrees():
    # Interpolating along the gradient (original Devernay) oscillates around 45 deg; along an
    # image axis (IPOL 2017) the point noise at 45 deg is that at 0 deg. Measured (noise 1.5,
    # 4 seeds, 240 px edges): RMS 0.0101 px at 0 deg, 0.0105 px at 45 deg.
    rms = {}
    for angle in (0, 45):
        d = []
        for seed in range(3):
            rng, p = _truth(500 + seed)
            img = quantise(render_step((96, 96), angle, (p[0] + 16, p[1] + 16)), 1.5, rng)
            xy = detect_edges(img)[0].xy
            inside = np.all((xy > MARGIN) & (xy < 95 - MARGIN), axis=1)
            d.append((xy[inside] - (p[0] + 16, p[1] + 16)) @ line_normal(angle))
        rms[angle] = np.sqrt(np.mean(np.concatenate(d) ** 2))
    assert 0.005 < rms[0] < 0.02
    assert rms[45] < 1.3 * rms[0], rms


def test_gradient_points_dark_to_bright_and_chain_orientation():
    # vertical edge, dark on the left (x < 30.2), bright on the right
    p = (30.2, 31.0)
    img = render_step(SHAPE, 270, p)  # direction -y: normal (+1, 0) -> bright on +x side
    chains = detect_edges(img)
    assert len(chains) == 1
    c = chains[0]
    assert np.all(c.grad[:, 0] > 0) and np.all(np.abs(c.grad[:, 1]) < 1e-3 * c.grad[:, 0])
    # convention: t_x g_y - t_y g_x > 0 along the chain -> walking towards -y here
    t = np.diff(c.xy, axis=0)
    cross = t[:, 0] * c.grad[:-1, 1] - t[:, 1] * c.grad[:-1, 0]
    assert np.all(cross > 0)
    assert c.xy[0, 1] > c.xy[-1, 1]
    # gradient value: 170 grey levels across a Gaussian profile of std sqrt(0.7^2 + 1 + 1/12)
    peak = 170 / np.sqrt(2 * np.pi * (0.49 + 1 + 1 / 12 + 1 / 3))
    assert np.median(c.grad[:, 0]) == pytest.approx(peak, rel=0.03)


def test_chains_are_ordered_with_unit_steps():
    rng, p = _truth(7)
    for angle in [0, 20, 45, 70, 90, 135]:
        c = detect_edges(quantise(render_step(SHAPE, angle, p), 1.5, rng))[0]
        steps = np.linalg.norm(np.diff(c.xy, axis=0), axis=1)
        # one point per row or column: ~1/max(|cos|,|sin|) px apart; near 45 deg consecutive
        # points may be interpolated along different axes, hence up to ~2 px
        spacing = 1 / max(abs(np.cos(np.deg2rad(angle))), abs(np.sin(np.deg2rad(angle))))
        assert np.median(steps) == pytest.approx(spacing, rel=0.05), angle
        assert steps.min() > 0.5 and steps.max() < 2.2, angle
        # the chain spans the image: ordered, not zig-zagging back
        s = (c.xy - p) @ np.array([np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))])
        assert np.all(np.diff(s) < 0) or np.all(np.diff(s) > 0), angle


def test_circle_gives_one_closed_chain():
    centre, radius = (40.3, 39.6), 25.0
    rng = np.random.default_rng(3)
    img = quantise(render_disk((80, 80), centre, radius), 1.5, rng)
    chains = detect_edges(img)
    assert len(chains) == 1
    c = chains[0]
    r = np.hypot(c.xy[:, 0] - centre[0], c.xy[:, 1] - centre[1])
    assert np.abs(r - radius).max() < 0.1
    # covers the whole circle (~ 2 pi R points at <= 1.41 px spacing), closed: ends adjacent
    assert 0.7 * 2 * np.pi * radius < len(c) < 1.1 * 2 * np.pi * radius
    assert np.linalg.norm(c.xy[0] - c.xy[-1]) < 1.5
    steps = np.linalg.norm(np.diff(c.xy, axis=0), axis=1)
    assert steps.max() < 2.2


def test_dark_string_gives_two_chains_with_opposite_gradients():
    p = (31.7, 31.2)
    angle = 80
    img = quantise(render_string(SHAPE, angle, p, width=3.0), 1.0, np.random.default_rng(5))
    chains = detect_edges(img)
    assert len(chains) == 2
    n = line_normal(angle)
    sides = sorted(float(np.median((c.xy - p) @ n)) for c in chains)
    # each edge 1.5 px from the centre line, pushed outwards (symmetrically) by ~0.3 px because
    # the gradient profiles of the two edges (std ~1.4 px) overlap across a 3 px string
    assert 1.5 < -sides[0] < 2.0 and 1.5 < sides[1] < 2.0
    assert sides[0] + sides[1] == pytest.approx(0.0, abs=0.03)
    g = [np.median(c.grad, axis=0) for c in chains]
    assert np.dot(g[0], g[1]) < 0


def test_hysteresis_removes_isolated_noise_responses():
    rng = np.random.default_rng(11)
    noise = quantise(np.full((96, 96), 120.0), 2.0, rng)
    low, high = auto_thresholds(noise)
    # pure noise: points above `low` exist, but no chain reaches `high`
    xy, _ = edge_points(noise)
    assert xy.shape[0] > 0
    assert detect_edges(noise) == []
    # with high == low every noise point survives: the hysteresis is what removed them
    assert len(detect_edges(noise, low=low, high=low)) > 0
    # a real edge in the same noise is kept, and only it
    img = quantise(render_step((96, 96), 30, (47.3, 48.1)) - 120 + 120, 2.0, rng)
    chains = detect_edges(img)
    assert len(chains) == 1 and len(chains[0]) > 80


def test_weak_chain_needs_a_point_above_high():
    p = (31.4, 30.6)
    # modulus peak 30 / sqrt(2 pi (0.7^2 + 1 + 1/12 + 1/3)) = 8.7 grey/px
    img = render_step(SHAPE, 60, p, bright=130, dark=100)
    assert len(detect_edges(img, low=3.0, high=8.0)) == 1
    assert detect_edges(img, low=3.0, high=9.5) == []


def test_uint16_and_float_inputs_give_the_same_points():
    rng, p = _truth(21)
    img = render_step(SHAPE, 33, p) + rng.normal(0, 1.5, SHAPE)
    c8 = detect_edges(np.clip(np.round(img), 0, 255).astype(np.uint8))[0]
    c16 = detect_edges(np.round(img * 257).astype(np.uint16))[0]
    cf = detect_edges(img.astype(np.float32))[0]
    assert len(c16) == len(cf)
    assert np.allclose(c16.xy, cf.xy, atol=2e-3)  # only quantisation differs (1/257 grey)
    assert np.allclose(c16.grad / 257, cf.grad, rtol=1e-2, atol=0.05)
    d8 = _distances(c8.xy, p, 33)
    d16 = _distances(c16.xy, p, 33)
    assert abs(d8.mean()) < 0.01 and abs(d16.mean()) < 0.01
    # thresholds scale with the data: same chains whatever the bit depth
    lo8, _ = auto_thresholds(np.clip(np.round(img), 0, 255).astype(np.uint8))
    lo16, _ = auto_thresholds(np.round(img * 257).astype(np.uint16))
    assert lo16 / lo8 == pytest.approx(257, rel=0.1)


def _trimmed_rayleigh_scale(gx, gy):
    """The estimator of gradient_noise's docstring, written out plainly: median of the modulus,
    then four times the median of the moduli below 3 sigma over the truncated Rayleigh median."""
    m = np.hypot(np.asarray(gx, np.float64), np.asarray(gy, np.float64)).ravel()
    s = np.median(m) / np.sqrt(2 * np.log(2))
    trunc = np.sqrt(-2 * np.log(1 - 0.5 * (1 - np.exp(-4.5))))
    for _ in range(4):
        kept = m[m < 3 * s]
        if kept.size == 0:
            break
        s = np.median(kept) / trunc
    return float(s)


def test_gradient_noise_equals_the_plain_trimmed_median_estimator():
    # odd and even sample counts, edges covering a varying share of the samples, integer-valued
    # gradients (ties), an all-zero gradient
    for seed in range(24):
        rng = np.random.default_rng(seed)
        h, w = 40 + seed, 57 + 3 * seed
        gx = rng.normal(0, 1.5, (h, w))
        gy = rng.normal(0, 1.5, (h, w))
        gx[:, :: 3 + seed % 7] += rng.uniform(5, 60)
        if seed % 4 == 1:
            gx, gy = np.round(gx), np.round(gy)
        if seed == 23:
            gx, gy = np.zeros((h, w)), np.zeros((h, w))
        expected = _trimmed_rayleigh_scale(gx[2:-2, 2:-2], gy[2:-2, 2:-2])  # < 5e5 samples: all, 2 px border off
        assert gradient_noise(gx, gy) == expected, seed
    # by hand: moduli 1, 2, 3, 4 (all below 3 sigma): the median 2.5 over the truncated Rayleigh median
    g = np.zeros((5, 8))
    g[2, 2:6] = [1.0, 2.0, 3.0, 4.0]
    assert gradient_noise(g, np.zeros_like(g)) == pytest.approx(2.5 / np.sqrt(-2 * np.log(0.5 + 0.5 * np.exp(-4.5))))


def test_gradient_noise_is_measured_on_the_gradient_and_robust_to_edges():
    rng = np.random.default_rng(4)
    # white noise std 2 through Gaussian(1) + centred differences: gain 0.1586 (impulse response)
    img = render_string((128, 128), 20, (64, 64), width=3.0) + rng.normal(0, 2.0, (128, 128))
    f = img.astype(np.float32)
    gx = cv2.Sobel(cv2.GaussianBlur(f, (9, 9), 1.0), cv2.CV_32F, 1, 0, ksize=1, scale=0.5)
    gy = cv2.Sobel(cv2.GaussianBlur(f, (9, 9), 1.0), cv2.CV_32F, 0, 1, ksize=1, scale=0.5)
    assert gradient_noise(gx, gy) == pytest.approx(2.0 * 0.1586, rel=0.05)
    low, high = auto_thresholds(img)
    assert (low, high) == pytest.approx((4 * 2.0 * 0.1586, 8 * 2.0 * 0.1586), rel=0.05)
    # a dense harp: strings 24 px apart cover a third of the image with edge responses
    nrm = line_normal(25)
    dense = sum(render_string((120, 120), 25, tuple(60 + 24 * i * nrm), 3.0) - 200 for i in range(-3, 4))
    dense = 200 + dense + rng.normal(0, 2.0, (120, 120))
    assert auto_thresholds(dense)[0] == pytest.approx(4 * 2.0 * 0.1586, rel=0.06)
    # spatially correlated noise (as after demosaicing): the thresholds follow the real
    # gradient noise, so background pixels exceed `low` at the Rayleigh rate exp(-8)
    white = rng.normal(0, 6.0, (400, 400)).astype(np.float32)
    corr = 100 + cv2.GaussianBlur(white, (0, 0), 0.8)
    low, _ = auto_thresholds(corr)
    _, _, mod = (lambda g: (g[0], g[1], np.hypot(g[0], g[1])))(
        [
            cv2.Sobel(cv2.GaussianBlur(corr, (9, 9), 1.0), cv2.CV_32F, dx, 1 - dx, ksize=1, scale=0.5)[4:-4, 4:-4]
            for dx in (1, 0)
        ]
    )
    assert (mod > low).mean() < 1.5e-3
    assert detect_edges(corr) == []
    # noise-free: the quantisation floor
    lo0, _ = auto_thresholds(np.round(render_step((64, 64), 10, (32, 32))).astype(np.uint8))
    assert lo0 == pytest.approx(4 * 0.1586 / np.sqrt(12), rel=0.01)


def test_min_length_and_types():
    rng, p = _truth(2)
    chains = detect_edges(quantise(render_step(SHAPE, 10, p), 1.0, rng), min_length=10)
    assert all(isinstance(c, EdgeChain) and len(c) >= 10 for c in chains)
    c = chains[0]
    assert c.xy.dtype == np.float64 and c.grad.dtype == np.float64
    assert c.xy.shape == c.grad.shape == (len(c), 2)
    assert detect_edges(quantise(render_step(SHAPE, 10, p), 1.0, rng), min_length=1000) == []


def test_edge_points_are_the_unchained_detector_points():
    rng, p = _truth(9)
    img = quantise(render_step(SHAPE, 25, p), 1.0, rng)
    low, high = auto_thresholds(img)
    low /= 2  # let some noise maxima in
    xy, grad = edge_points(img, low=low, high=high)
    chains = detect_edges(img, low=low, high=high, min_length=1)
    pts = {tuple(np.r_[a, g]) for a, g in zip(xy, grad)}
    chained = [tuple(np.r_[a, g]) for c in chains for a, g in zip(c.xy, c.grad)]
    assert len(chained) == len(set(chained))  # no point in two chains
    assert set(chained) <= pts  # every chained point (and its gradient) is an edge point
    # the edge's own points are all chained; the others are weak noise maxima (> low, < high)
    near = np.abs((xy - p) @ line_normal(25)) < 1.0
    assert {tuple(np.r_[a, g]) for a, g in zip(xy[near], grad[near])} <= set(chained)
    assert (~near).sum() > 0 and np.hypot(*grad[~near].T).max() < high


def test_bad_input_is_rejected_clearly():
    with pytest.raises(ValueError, match="2-D"):
        detect_edges(np.zeros((10, 10, 3)))
    with pytest.raises(ValueError, match="too small"):
        detect_edges(np.zeros((3, 50)))
    with pytest.raises(ValueError, match="threshold"):
        detect_edges(np.zeros((20, 20)), low=5.0, high=1.0)
    bad = np.zeros((20, 20))
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        detect_edges(bad)
    assert detect_edges(np.zeros((20, 20), np.uint8)) == []


def test_edges_near_the_image_border_stay_accurate():
    # the continuous sub-pixel step mirrors the image at its border like the smoothing does
    for x0 in (2.6, 4.3, 6.8):
        p = (x0, 20.0)
        img = render_step((40, 40), 90, p)
        chains = detect_edges(img)
        assert len(chains) == 1
        d = (chains[0].xy[5:-5] - p) @ line_normal(90)
        # measured: <= 0.0005 px, even 2.6 px from the border
        assert np.abs(d).max() < 0.002, (x0, np.abs(d).max())
    with pytest.raises(ValueError, match="sigma"):
        detect_edges(img, sigma=-1.0)
    # sigma = 0 (no smoothing) and sigma < 0.5 (log-parabola fallback) still work
    assert len(detect_edges(render_step((40, 40), 30, (20.2, 19.7), blur=1.0), sigma=0)) == 1
    assert len(detect_edges(render_step((40, 40), 30, (20.2, 19.7)), sigma=0.4)) == 1


def test_bands_threads_and_the_provisional_threshold_give_exactly_the_points_of_one_pass(monkeypatch):
    """The dense stage runs by bands of rows, by two threads on large images, with a provisional
    lower threshold from a few noise rows (issue 8 item 6): the chains are bit for bit those of one
    band over the whole image with the exact threshold (here on a small harp, the limits lowered),
    also when the provisional threshold comes out too high and the bands are searched again."""
    import pipeline.edges as edges
    from pipeline.models.radial import RadialModel
    from pipeline.render import HarpScene, render_harp

    lens = RadialModel.for_image(480, 360, k=(1.0, 0.0, 0.03))
    img = render_harp(480, 360, HarpScene(angle_deg=35.0, spacing_px=30.0), lens=lens, noise_sigma=1.5, seed=4).image
    monkeypatch.setattr(edges, "THREADS", 1)
    monkeypatch.setattr(edges, "BAND_PX", 10**9)  # one band
    monkeypatch.setattr(edges, "NOISE_BOUND_ROWS", 10**9)  # the exact threshold first
    one = detect_edges(img)
    monkeypatch.setattr(edges, "THREADS", 2)
    monkeypatch.setattr(edges, "PARALLEL_MIN_PX", 1)
    monkeypatch.setattr(edges, "BAND_PX", 480 * 23)  # bands of 23 rows
    monkeypatch.setattr(edges, "NOISE_BOUND_ROWS", 8)
    banded = detect_edges(img)
    monkeypatch.setattr(edges, "NOISE_BOUND_FACTOR", 3.0)  # provisional threshold above the exact one
    again = detect_edges(img)
    assert len(one) == len(banded) == len(again) >= 20
    for a, b, c in zip(one, banded, again):
        assert np.array_equal(a.xy, b.xy) and np.array_equal(a.grad, b.grad)
        assert np.array_equal(a.xy, c.xy) and np.array_equal(a.grad, c.grad)


def test_chains_are_ordered_along_their_links_paths_and_cycles():
    """The chaining's ordering (list ranking by pointer jumping, issue 8 item 6) against a plain walk
    along the links: each component contiguous, in the order of its links, components in the order
    of their smallest point, a cycle opened at its smallest point, unlinked points last."""
    from pipeline.edge_chains import order_chains as _order_chains

    rng = np.random.default_rng(3)
    for _ in range(20):
        n = int(rng.integers(1, 600))
        ids = rng.permutation(n)
        nxt = np.full(n, -1, np.int64)
        prv = np.full(n, -1, np.int64)
        i = 0
        while i < n:
            seg = ids[i : i + int(rng.integers(1, 80))]
            i += len(seg)
            nxt[seg[:-1]], prv[seg[1:]] = seg[1:], seg[:-1]
            if len(seg) >= 2 and rng.random() < 0.3:  # close it
                nxt[seg[-1]], prv[seg[0]] = seg[0], seg[-1]
        seen = np.zeros(n, bool)
        comps = []
        for p in range(n):  # components by smallest point
            if seen[p] or (nxt[p] < 0 and prv[p] < 0):
                continue
            start = p
            while prv[start] >= 0 and prv[start] != p:  # back to the head of a path
                start = prv[start]
            if prv[start] == p:  # a cycle: opened at its smallest point, p
                start = p
            walk = [start]
            while nxt[walk[-1]] >= 0 and nxt[walk[-1]] != start:
                walk.append(int(nxt[walk[-1]]))
            seen[walk] = True
            comps.append(walk)
        singles = [p for p in range(n) if nxt[p] < 0 and prv[p] < 0]
        expected = [p for c in comps for p in c] + singles
        lab, order = _order_chains(nxt, prv)
        assert order.tolist() == expected
        sizes = [len(c) for c in comps] + [1] * len(singles)
        assert lab[order].tolist() == [k for k, s in enumerate(sizes) for _ in range(s)]
