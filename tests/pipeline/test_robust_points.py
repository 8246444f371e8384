"""The per-point robust fit (``fit_distortion(point_loss=...)``, :mod:`pipeline.robust_points`) against an
exact lens and exact straight strings with kinks injected on some of them."""

import numpy as np
import pytest

from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import fit_harp_shape
from pipeline.models import RadialModel
from pipeline.robust_points import robust_point_weights
from tests.pipeline.harp_points import turning_harp_point_sets

W, H = 1000, 750
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.005), center=(520, 365), tangential=(0.0008, -0.0005))
SPEC = dict(model="radial", degree=4, tangential=True, prism=True)


def kinked_shots(kink_px: float, noise: float = 0.02, seed: int = 0) -> tuple[list[list[np.ndarray]], int]:
    """Straight strings at 0, 60, 120 degrees, 80 px apart, points every 5 px, through ``LENS``; every third
    string of a shot bent by a kink (a cusp ``kink_px exp(-|s - s_k| / 15 px)`` across it, at a random place in
    the middle of its visible length, of random sign, in the ideal image), then ``noise`` px of Gaussian noise
    (enough that the kinked edges do not stand out as whole-edge outliers). Also how many strings are kinked."""
    rng = np.random.default_rng(seed)
    c = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    half = 0.5 * np.hypot(W, H)
    out, n_kinks = [], 0
    for k, ang in enumerate((0.0, 60.0, 120.0)):
        t = np.radians(ang)
        d = np.array([np.cos(t), np.sin(t)])
        nrm = np.array([-d[1], d[0]])
        s = np.arange(-half, half, 5.0)
        offsets = np.arange(-half + 17 * k % 80, half, 80.0)
        ideal = c + offsets[:, None, None] * nrm + s[None, :, None] * d  # (strings, points, 2)
        seen = LENS.distort_points(ideal.reshape(-1, 2)).reshape(ideal.shape)
        ok = np.all((seen > 5) & (seen < [W - 6, H - 6]), axis=2)
        bumps = np.zeros(ok.shape)
        for j in range(0, len(offsets), 3):
            if kink_px and ok[j].sum() >= 20:
                lo, hi = s[ok[j]].min(), s[ok[j]].max()
                at = rng.uniform(lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo))
                bumps[j] = kink_px * rng.choice([-1.0, 1.0]) * np.exp(-np.abs(s - at) / 15.0)
                n_kinks += 1
        bent = LENS.distort_points((ideal + bumps[:, :, None] * nrm).reshape(-1, 2)).reshape(ideal.shape)
        lines = [q[m] + rng.normal(0.0, noise, q[m].shape) for q, m in zip(bent, ok, strict=True) if m.sum() >= 20]
        out.append(lines)
    return out, n_kinks


def field_error(shots: list[list[np.ndarray]], **kw: object) -> float:
    f = fit_distortion(shots, W, H, **SPEC, **kw)  # type: ignore[arg-type]
    assert f, getattr(f, "reason", "")
    return float(compare_models(f.model, LENS, W, H).rms)


def test_robust_points_keep_kinks_out_of_the_lens():
    clean, _ = kinked_shots(0.0)
    kinked, n_kinks = kinked_shots(0.5)
    assert n_kinks >= 10
    reference = field_error(clean)  # the kink-free strings, the fit as it is
    plain = field_error(kinked)  # the kinks, the fit as it is: its edge-level rejection does not catch them
    robust = field_error(kinked, point_loss="tukey")
    assert reference < 0.003
    assert plain > 3.0 * reference, (plain, reference)
    # near the kink-free fit (what a kink's tails leave below the noise, an M-estimator cannot see)
    assert robust < 2.0 * reference and robust < 0.4 * plain, (robust, reference, plain)


def test_robust_point_weights_spare_a_bowed_edge_and_drop_its_kink():
    # one edge with a smooth bow (what the lens's misfit and a string's shape leave) and a kink
    rng = np.random.default_rng(3)
    a = np.arange(-400.0, 400.0, 5.0)
    bow = 0.05 * (1.0 - (a / 400.0) ** 2) + 0.02 * np.sin(np.pi * a / 400.0)
    kink = 0.3 * np.exp(-np.abs(a - 120.0) / 15.0)
    r = bow + kink + rng.normal(0.0, 0.01, len(a))
    starts, counts = np.array([0]), np.array([len(a)])
    w = None
    for _ in range(3):
        w = robust_point_weights(r, a, starts, counts, "tukey", previous=w)
    near = np.abs(a - 120.0) <= 15.0
    assert np.all(w[near] < 0.05)  # the kink's points (0.11..0.3 px): no weight
    far = np.abs(a - 120.0) > 60.0  # the bow's points (up to 0.06 px) keep (nearly) full weight
    assert np.median(w[far]) > 0.9 and np.mean(w[far] > 0.5) > 0.95


def test_unknown_point_loss_is_a_failure():
    line = np.stack([np.arange(10.0, 200.0, 10.0), np.full(19, 100.0)], axis=1)
    f = fit_distortion([[line]], W, H, **SPEC, point_loss="cauchy")  # type: ignore[arg-type]
    assert not f and "point_loss" in f.reason and "tukey" in f.reason
    f = fit_distortion([[line]], W, H, **SPEC, point_loss="tukey", point_scale=[[np.ones(3)]])
    assert not f and "point_scale" in f.reason and "one finite value > 0 per point (19)" in f.reason


@pytest.mark.parametrize("loss", ["tukey", "huber"])
def test_robust_point_weights_on_clean_noise_are_near_one(loss):
    rng = np.random.default_rng(5)
    a = np.arange(-300.0, 300.0, 2.0)
    r = rng.normal(0.0, 0.02, len(a))
    w = robust_point_weights(r, a, np.array([0]), np.array([len(a)]), loss)
    assert np.mean(w) > 0.85 and np.mean(w > 0.5) > 0.97


def test_the_joint_fit_with_the_strings_keeps_the_robust_weights():
    # a turning harp of straight strings; a kink pressed into every third edge (in the image: a cusp across
    # the edge, 15 px long); the lens fitted with every string's bend separated (fit_harp_shape), started
    # from the plain fit with and without the per-point stage
    turns = (0.0, 60.0, 120.0)
    shots, _ = turning_harp_point_sets(LENS, W, H, turns, [(0.0, 0.0, 0.0)] * 10, spacing=80.0, step=8.0, noise=0.02)
    rng = np.random.default_rng(7)
    kinked = []
    for shot in shots:
        out = []
        for j, p in enumerate(shot):
            if j % 3 == 0:
                s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
                t = (p[-1] - p[0]) / np.hypot(*(p[-1] - p[0]))
                at = rng.uniform(0.2, 0.8) * s[-1]
                p = p + 0.5 * np.exp(-np.abs(s - at) / 15.0)[:, None] * np.array([-t[1], t[0]])
            out.append(p)
        kinked.append(out)

    def separated(lines: list[list[np.ndarray]], **kw: object) -> float:
        plain = fit_distortion(lines, W, H, **SPEC, **kw)  # type: ignore[arg-type]
        assert plain, getattr(plain, "reason", "")
        joint = fit_harp_shape(lines, turns, W, H, FitSpec("radial", 4, True, True), plain=plain)
        assert joint, getattr(joint, "reason", "")
        return float(compare_models(joint.model, LENS, W, H).rms)

    reference, plain, robust = separated(shots), separated(kinked), separated(kinked, point_loss="tukey")
    assert plain > 3.0 * reference, (plain, reference)
    assert robust < 2.0 * reference and robust < 0.4 * plain, (robust, reference, plain)
