"""Along-edge resampling and smoothing (pipeline/resample.py), with exact answers."""

import numpy as np
import pytest

from pipeline.edges import detect_edges
from pipeline.resample import (
    TRUNCATE,
    noise_gain,
    point_sigma,
    resample_polyline,
    sample_noise,
    smooth_subsample,
    smoothing_sigma,
    subsample_grid,
)
from tests.pipeline.synthetic_edges import line_normal, quantise, render_step


def test_resample_polyline_uniform_arclength():
    rng = np.random.default_rng(0)
    # irregularly sampled straight segment from (1, 2) along direction (3, 4)/5, length 50
    s = np.sort(np.concatenate([[0.0, 50.0], rng.uniform(0, 50, 30)]))
    xy = np.array([1.0, 2.0]) + s[:, None] * np.array([0.6, 0.8])
    r = resample_polyline(xy, step=0.7)
    assert r.shape == (int(50 / 0.7) + 1, 2)
    assert np.allclose(r[0], xy[0])
    assert np.allclose(np.linalg.norm(np.diff(r, axis=0), axis=1), 0.7)
    assert np.allclose((r - [1.0, 2.0]) @ np.array([0.8, -0.6]), 0.0, atol=1e-12)


def test_resample_polyline_follows_corners_and_repeats():
    xy = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 0.0], [2.0, 3.0]])  # L-shape, repeated point
    r = resample_polyline(xy, 1.0)
    assert np.allclose(r, [[0, 0], [1, 0], [2, 0], [2, 1], [2, 2], [2, 3]])
    assert resample_polyline(np.zeros((0, 2))).shape == (0, 2)
    assert np.allclose(resample_polyline(np.array([[3.0, 4.0], [3.0, 4.0]])), [[3.0, 4.0]])
    with pytest.raises(ValueError, match="step"):
        resample_polyline(xy, 0.0)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        resample_polyline(np.zeros((4, 3)))


def test_smoothing_sigma_formula():
    assert smoothing_sigma(30) == pytest.approx(0.8 * np.sqrt(899))
    assert smoothing_sigma(1) == 0.0


def test_grid_spans_the_whole_piece_at_most_t_apart():
    for length, t in [(0.0, 30), (10.0, 30), (30.0, 30), (31.0, 30), (899.5, 30), (1000.0, 7)]:
        g = subsample_grid(length, t)
        assert g[0] == 0.0 and g[-1] == pytest.approx(length)
        assert len(g) == (1 if length == 0 else max(2, int(np.ceil(length / t)) + 1))
        if len(g) > 1:
            assert np.allclose(np.diff(g), length / (len(g) - 1)) and np.diff(g).max() <= t + 1e-9
    with pytest.raises(ValueError, match="t must"):
        subsample_grid(10.0, 0)


@pytest.mark.parametrize("t", [30, 10])
def test_local_quadratic_reproduces_quadratic_curves_to_their_ends(t):
    # x(s), y(s) polynomials of degree <= 2 in the arclength are reproduced exactly, at the
    # ends of the piece as in its middle; the grid spans the whole piece
    s = np.arange(0.0, 500.0, 1.0)
    u, nrm = np.array([np.cos(0.4), np.sin(0.4)]), np.array([-np.sin(0.4), np.cos(0.4)])
    xy = np.array([20.0, 30.0]) + s[:, None] * u + (3e-5 * s**2)[:, None] * nrm  # a gentle parabola
    out = smooth_subsample(xy, t=t)
    # the truth on the smoother's own parameter (the polyline's arclength), at the grid positions
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    sk = subsample_grid(arc[-1], t)
    truth = np.column_stack([np.interp(sk, arc, xy[:, 0]), np.interp(sk, arc, xy[:, 1])])
    assert out.shape == truth.shape
    # exact up to the parabola being quadratic in s, not quite in its arclength (~1e-5 px here)
    assert np.allclose(out[0], xy[0], atol=2e-5) and np.allclose(out[-1], xy[-1], atol=2e-5)
    assert np.abs(out - truth).max() < 2e-5
    # a straight line sampled irregularly is reproduced exactly, ends included
    rng = np.random.default_rng(3)
    s2 = np.sort(np.concatenate([[0.0, 300.0], rng.uniform(0, 300, 400)]))
    line = np.array([5.0, 7.0]) + s2[:, None] * u
    lq = smooth_subsample(line, t=t)
    assert np.allclose(lq[[0, -1]], line[[0, -1]], atol=1e-9)
    assert np.abs((lq - [5.0, 7.0]) @ nrm).max() < 1e-9
    # the plain Gaussian (valid part only) loses 3 sigma at each end
    g = smooth_subsample(xy, t=t, method="gaussian")
    assert np.linalg.norm(g[0] - xy[0]) >= int(np.ceil(TRUNCATE * smoothing_sigma(t))) - 1


def test_local_quadratic_on_a_circle_keeps_the_ends_on_it():
    # a curved edge keeps its curvature at the ends (bias O(sigma^3 x^(3)) there, O(sigma^4 x^(4))
    # in the middle), far below the plain Gaussian's sigma^2 / 2R shrinkage
    R = 2000.0
    phi = np.linspace(0.0, 800.0 / R, 16001)
    xy = np.column_stack([R * np.cos(phi), R * np.sin(phi)])
    out = smooth_subsample(xy, t=30)
    r = np.hypot(out[:, 0], out[:, 1])
    assert len(out) == 28
    assert np.abs(r - R).max() < 1e-4
    assert np.linalg.norm(out[0] - xy[0]) < 1e-3 and np.linalg.norm(out[-1] - xy[-1]) < 1e-3
    g = smooth_subsample(xy, t=30, method="gaussian")
    sig = smoothing_sigma(30)
    assert np.hypot(g[:, 0], g[:, 1]).mean() == pytest.approx(R - sig**2 / (2 * R), abs=0.02)  # 0.14 px


def test_noise_gain_at_the_ends():
    # standard deviation relative to the plain Gaussian: 3.5x at the end points, 1.33x in the middle
    assert noise_gain(0.0, 2000.0) == pytest.approx(3.50, abs=0.01)
    assert noise_gain(2000.0, 2000.0) == pytest.approx(3.50, abs=0.01)
    assert noise_gain(1000.0, 2000.0) == pytest.approx(1.33, abs=0.01)
    assert noise_gain(10.0, 2000.0) == pytest.approx(1.83, abs=0.01)
    # independently: the interior factor of the untruncated kernel is sqrt(27/16)
    assert np.sqrt(27 / 16) == pytest.approx(noise_gain(1000.0, 2000.0), abs=0.03)
    # and empirically: white noise across a straight edge (small: the arclength stays that of the line)
    rng = np.random.default_rng(5)
    base = np.column_stack([np.arange(0.0, 601.0), np.zeros(601)])
    ends, mid = [], []
    for _ in range(400):
        out = smooth_subsample(base + np.column_stack([np.zeros(601), rng.normal(0, 0.01, 601)]), t=30)
        ends.extend(out[[0, -1], 1])
        mid.extend(out[8:-8, 1])
    plain = 0.01 / np.sqrt(2 * np.sqrt(np.pi) * smoothing_sigma(30))  # std of the plain Gaussian mean
    assert np.std(ends) / plain == pytest.approx(3.50, rel=0.1)
    assert np.std(mid) / plain == pytest.approx(1.33, rel=0.1)


def test_smooth_subsample_gaussian_option_keeps_straight_line_exact_and_spacing():
    s = np.arange(0, 400.0, 0.9)
    xy = np.array([10.0, 20.0]) + s[:, None] * np.array([np.cos(0.3), np.sin(0.3)])
    out = smooth_subsample(xy, t=30, method="gaussian")
    half = int(np.ceil(TRUNCATE * smoothing_sigma(30)))
    n_res = int(s[-1]) + 1
    assert out.shape[0] == (n_res - 2 * half - 1) // 30 + 1
    assert np.allclose(np.linalg.norm(np.diff(out, axis=0), axis=1), 30.0)
    assert np.allclose((out - [10.0, 20.0]) @ np.array([-np.sin(0.3), np.cos(0.3)]), 0, atol=1e-10)
    # centred in the valid range: first and last kept points equally far from the ends
    a = np.linalg.norm(out[0] - xy[0])
    b = (n_res - 1) - np.linalg.norm(out[-1] - xy[0])
    assert abs(a - b) <= 1.0 and a >= half
    # the default keeps the whole piece, still exactly on the line
    lq = smooth_subsample(xy, t=30)
    assert np.allclose(lq[[0, -1]], xy[[0, -1]], atol=1e-9)
    assert np.allclose((lq - [10.0, 20.0]) @ np.array([-np.sin(0.3), np.cos(0.3)]), 0, atol=1e-10)


def test_smooth_subsample_gaussian_option_on_circle_has_no_end_effect():
    # Gaussian blur along a circle of radius R shrinks it by the factor sum_k w_k cos(k / R),
    # the same for every output point (valid mode: no end effect).
    R, t = 150.0, 30
    phi = np.linspace(0.0, 4.0, 40001)  # an arc of 600 px, densely sampled
    xy = np.column_stack([R * np.cos(phi), R * np.sin(phi)])
    out = smooth_subsample(xy, t=t, method="gaussian")
    sig = smoothing_sigma(t)
    k = np.arange(-int(np.ceil(TRUNCATE * sig)), int(np.ceil(TRUNCATE * sig)) + 1)
    w = np.exp(-0.5 * (k / sig) ** 2)
    factor = np.sum(w * np.cos(k / R)) / w.sum()
    r = np.hypot(out[:, 0], out[:, 1])
    assert out.shape[0] >= 14
    assert np.allclose(r, R * factor, atol=2e-5)
    assert R - r.mean() > 1.0  # the shrinkage is real (sigma^2 / 2R ~ 1.9 px), not a no-op


def test_smooth_subsample_short_edges_and_t1():
    half = int(np.ceil(TRUNCATE * smoothing_sigma(30)))
    line = np.column_stack([np.arange(2 * half + 1.0), np.zeros(2 * half + 1)])
    assert smooth_subsample(line, 30, method="gaussian").shape == (1, 2)
    assert smooth_subsample(line[:-1], 30, method="gaussian").shape == (0, 2)
    assert smooth_subsample(np.zeros((0, 2)), 30).shape == (0, 2)
    assert np.allclose(smooth_subsample(line, t=1, step=2.0), line[::2])
    # the default keeps short pieces: 10 px give their two ends
    assert np.allclose(smooth_subsample(line[:11], 30), line[[0, 10]])
    assert np.allclose(smooth_subsample(line[:2], 30), [[0.5, 0.0]])  # too short for a quadratic: its mean
    with pytest.raises(ValueError, match="t must"):
        smooth_subsample(line, t=0)
    with pytest.raises(ValueError, match="unknown smoothing"):
        smooth_subsample(line, method="median")


def _step_edge_distances(method):
    n = 240
    mid, ends = [], []
    for angle in [0, 3, 15, 30, 45, 60, 75, 87, 90]:
        for seed in range(2):
            rng = np.random.default_rng(1000 * seed + angle)
            p = (n / 2 + rng.uniform(-0.5, 0.5), n / 2 + rng.uniform(-0.5, 0.5))
            img = quantise(render_step((n, n), angle, p, bright=200, dark=30, blur=0.7), 1.5, rng)
            chains = detect_edges(img)
            assert len(chains) == 1
            xy = chains[0].xy
            xy = xy[np.all((xy >= 4) & (xy <= n - 5), axis=1)]  # the measurement's 4 px border
            sm = smooth_subsample(xy, t=30, method=method)
            assert sm.shape[0] >= 3
            d = (sm - p) @ line_normal(angle)
            if method == "gaussian":
                mid.append(d)
            else:
                mid.append(d[1:-1])
                ends.append(d[[0, -1]])
    return np.concatenate(mid), (np.concatenate(ends) if ends else np.zeros(0))


def test_after_t30_smoothing_rms_to_true_line_is_below_5_thousandths_px():
    # Issue #2 requirement: 8-bit, background 200 / string 30, optical blur 0.7 px,
    # noise sigma 1.5 grey levels; after t=30 smoothing the RMS distance of the
    # points to the TRUE line is <= 0.005 px. Pooled over angles 0..90 deg and 2 seeds.
    # Plain Gaussian (56 points, 4 px border trimmed): RMS 0.0026 px, max 0.0062 px.
    d, _ = _step_edge_distances("gaussian")
    assert np.sqrt(np.mean(d**2)) <= 0.005
    assert np.abs(d).max() <= 0.012
    # Local quadratic over the whole piece (issue 8): inside RMS 0.0032 px (the interior noise
    # gain 1.33), the end points 0.0065 px (noise gain 3.5; <= 0.01 asked).
    mid, ends = _step_edge_distances("local-quadratic")
    print(f"local quadratic: inside RMS {np.sqrt(np.mean(mid**2)):.4f} px, ends RMS {np.sqrt(np.mean(ends**2)):.4f} px")
    assert np.sqrt(np.mean(mid**2)) <= 0.005
    assert np.sqrt(np.mean(ends**2)) <= 0.01


def test_point_sigma_is_the_spread_of_the_smoothed_points():
    """Each smoothed point's standard deviation, the smoother's row through white noise, against the
    spread of the smoothed points of many noisy copies of one gently curved edge (both smoothers)."""
    rng = np.random.default_rng(11)
    x = np.arange(0.0, 701.0)
    base = np.column_stack([x, 2e-5 * (x - 350.0) ** 2])
    noise = 0.03 * (1.0 + 2.0 * (x > 600))  # the last 100 px three times as noisy (known)
    for method in ("local-quadratic", "gaussian"):
        runs = np.array(
            [
                smooth_subsample(base + np.column_stack([0 * x, rng.normal(0, 1, x.size) * noise]), 30, method=method)[
                    :, 1
                ]
                for _ in range(300)
            ]
        )
        predicted = point_sigma(base, noise, 30, method=method)
        assert predicted.shape == (runs.shape[1],)
        assert np.allclose(runs.std(axis=0), predicted, rtol=0.15)
    lq = point_sigma(base, noise, 30)
    assert lq[-1] > 5 * lq[len(lq) // 2] and lq[0] > 2 * lq[len(lq) // 2]  # the noisy, one-sided end


def test_sample_noise_recovers_the_noise_and_its_growth():
    rng = np.random.default_rng(12)
    x = np.arange(0.0, 1501.0)
    curve = 1e-5 * (x - 700.0) ** 2
    assert sample_noise(np.column_stack([x, curve + rng.normal(0, 0.01, x.size)])) == pytest.approx(0.01, rel=0.1)
    sd = np.where(x > 1300, 0.03, 0.01)
    xy = np.column_stack([x, curve + rng.normal(0, 1, x.size) * sd])
    local = sample_noise(xy, local=True)
    assert local.shape == (1501,)
    assert local[600] == pytest.approx(0.01, rel=0.15) and local[-1] == pytest.approx(0.03, rel=0.2)
    # correlated noise (a 3-sample moving average of white noise 0.01: long-run standard deviation 0.01,
    # plain scatter 0.01 / sqrt(3)): the effective level, not the scatter
    w = rng.normal(0, 0.01, x.size + 2)
    ma = (w[:-2] + w[1:-1] + w[2:]) / 3.0
    assert sample_noise(np.column_stack([x, ma])) == pytest.approx(0.01 / np.sqrt(3) * np.sqrt(3), rel=0.15)
    assert np.isnan(sample_noise(xy[:4])) and sample_noise(xy[:4], local=True).shape == (0,)
