import numpy as np
import pytest

from pipeline.straightness import fit_line, hf_rms, straightness


def _line(angle_deg, n=200, length=400.0, offset=(100.0, 50.0)):
    a = np.radians(angle_deg)
    s = np.linspace(0, length, n)
    return np.stack([offset[0] + s * np.cos(a), offset[1] + s * np.sin(a)], axis=1)


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0, 90.0, 135.0, 179.0])
def test_straight_line_has_zero_distance_and_right_angle(angle):
    st = straightness([_line(angle)])
    assert st.d < 1e-10 and st.d_max < 1e-10
    assert st.angle_deg[0] == pytest.approx(angle, abs=1e-9)
    assert st.length_px[0] == pytest.approx(400.0)
    assert st.n == (200,) and st.n_points == 200 and st.n_lines == 1


def test_known_sine_bend_gives_known_d_and_dmax():
    # y = A cos(2 pi k x / L), even in x over whole periods: uncorrelated
    # with x and of mean ~0, so the TLS line is y = 0 and S = y
    x = np.linspace(-500, 500, 2001)
    A = 2.0
    y = A * np.cos(2 * np.pi * 3 * x / 1000)
    pts = np.stack([x, y + 10], axis=1)
    st = straightness([pts])
    assert st.d == pytest.approx(A / np.sqrt(2), rel=1e-3)
    assert st.p2p[0] == pytest.approx(2 * A, rel=1e-3)
    assert st.d_max == pytest.approx(2 * A, rel=1e-3)
    # the fitted normal points to +y for a line at angle 0; S has the sign of y - 10
    f = st.fits[0]
    np.testing.assert_allclose(f.S, y, atol=1e-2)


def test_d_pools_points_and_dmax_averages_lines():
    rng = np.random.default_rng(0)
    a = _line(30.0, n=100)
    b = _line(120.0, n=300, offset=(500.0, 20.0))
    fa, fb = fit_line(a), fit_line(b)
    a = a + np.outer(rng.normal(0, 0.5, len(a)), fa.normal)
    b = b + np.outer(rng.normal(0, 2.0, len(b)), fb.normal)
    st = straightness([a, b])
    Sa, Sb = st.fits[0].S, st.fits[1].S
    assert st.d == pytest.approx(np.sqrt((np.sum(Sa**2) + np.sum(Sb**2)) / 400))
    pa, pb = np.ptp(Sa), np.ptp(Sb)
    assert st.d_max == pytest.approx(np.sqrt((pa**2 + pb**2) / 2))
    assert st.rms[0] == pytest.approx(np.sqrt(np.mean(Sa**2)))
    # TLS residuals are orthogonal: mean zero
    assert abs(Sa.mean()) < 1e-9 and abs(Sb.mean()) < 1e-9


def test_hf_rms_separates_smooth_bend_from_high_frequency_ripple():
    x = np.arange(0, 2000.0)
    smooth = np.stack([x, 5.0 * ((x - 1000) / 1000) ** 2], axis=1)  # 5 px sag: lens-like
    ripple = np.stack([x, 0.5 * np.sin(2 * np.pi * x / 10.0)], axis=1)  # 10 px period ripple
    assert hf_rms(smooth) < 0.01  # interior bias of the smoothing: y'' sigma^2 / 2 = 0.008
    assert hf_rms(ripple) == pytest.approx(0.5 / np.sqrt(2), rel=0.02)


def test_bad_input_raises():
    with pytest.raises(ValueError):
        straightness([])
    with pytest.raises(ValueError):
        straightness([np.zeros((1, 2))])


def _hf_rms_direct(points, sigma_px):
    """Brute-force Gaussian-weighted local linear regression (reference)."""
    p = np.asarray(points, float)
    S = fit_line(p).S
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
    step = s[-1] / (len(s) - 1)
    k = np.arange(len(S)) * step
    half = int(np.ceil(4.0 * sigma_px / step))
    smooth = np.empty_like(S)
    for i, k0 in enumerate(k):
        j = np.abs(np.arange(len(S)) - i) <= half
        wgt = np.exp(-0.5 * ((k[j] - k0) / sigma_px) ** 2)
        A = np.column_stack([np.ones(j.sum()), k[j] - k0]) * np.sqrt(wgt)[:, None]
        smooth[i] = np.linalg.lstsq(A, S[j] * np.sqrt(wgt), rcond=None)[0][0]
    return float(np.sqrt(np.mean((S - smooth) ** 2)))


@pytest.mark.parametrize("n, step", [(5, 30.0), (12, 30.0), (50, 1.0), (200, 1.0)])
def test_hf_rms_on_edges_shorter_than_its_kernel(n, step):
    # the Gaussian window (4 sigma each side) may be longer than the edge
    s = np.arange(n) * step
    rng = np.random.default_rng(3)
    p = np.column_stack([s, 1e-3 * (s - s.mean()) ** 2 / step**2 + 0.05 * rng.standard_normal(n)])
    assert hf_rms(p) == pytest.approx(_hf_rms_direct(p, 40.0), rel=1e-6, abs=1e-12)
    straight = np.column_stack([s, 0.25 * s])
    assert hf_rms(straight) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("slope", [-3e-16, -1e-16, -4e-17, 0.0, 4e-17])
def test_angle_of_a_horizontal_line_stays_in_0_180(slope):
    # rounding can leave the direction at (-1, +1e-16): its angle must read 0, never 180
    x = np.arange(500.0)
    p = np.column_stack([x, 100.0 + slope * x])
    a = straightness([p]).angle_deg[0]
    assert 0.0 <= a < 180.0
    assert a == pytest.approx(0.0, abs=1e-9)
