"""Synthetic harp edge point sets with an exact answer (test helper).

Ideal straight lines at given orientations, sampled every ``step`` px,
mapped through a true lens (``distort_points``: ideal -> distorted), kept
inside the image, plus Gaussian noise of the size t-smoothing leaves.
"""

from __future__ import annotations

import numpy as np


def harp_point_sets(lens, width, height, angles_deg, spacing=50.0, step=30.0, noise=0.005, seed=0, margin=5.0):
    """One list of (M, 2) edge point arrays per angle."""
    rng = np.random.default_rng(seed)
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    half = 0.5 * np.hypot(width, height)
    shots = []
    for k, ang in enumerate(angles_deg):
        t = np.radians(ang)
        d = np.array([np.cos(t), np.sin(t)])
        n = np.array([-d[1], d[0]])
        lines = []
        phase = (k * 0.37 % 1.0) * spacing
        for off in np.arange(-half + phase, half, spacing):
            s = np.arange(-half, half, step)
            ideal = np.array([cx, cy]) + off * n + s[:, None] * d
            dist = lens.distort_points(ideal)
            ok = (
                np.all(np.isfinite(dist), axis=1)
                & (dist[:, 0] > margin)
                & (dist[:, 0] < width - 1 - margin)
                & (dist[:, 1] > margin)
                & (dist[:, 1] < height - 1 - margin)
            )
            p = dist[ok]
            if len(p) >= 8:
                lines.append(p + rng.normal(0.0, noise, p.shape))
        shots.append(lines)
    return shots


def turning_harp_point_sets(
    lens, width, height, turntable_deg, bends, *, angle0=20.0, axis=None, spacing=60.0, string_width=3.0,
    step=30.0, noise=0.003, seed=0, margin=5.0,
):  # fmt: skip
    """Edge point sets of a harp turning on a turntable, its strings bent (test helper, exact truth).

    The harp's strings run at ``angle0 + turntable`` degrees about ``axis`` (ideal pixels, default the
    image centre); string ``k`` (offset ``(k - K/2) spacing`` from the axis, ``K = len(bends)``) lies at
    ``q = q_k + delta_k(u)`` with ``delta_k(u) = sum_j bends[k][j] P_{j+2}(u)``, ``u`` the position along
    the string from the axis in half image diagonals (the model of :mod:`pipeline.harp_shape`, written
    out here on its own). Both edges of each string (``q +- string_width / 2``) are sampled every
    ``step`` px, mapped through ``lens.distort_points`` and given Gaussian noise. Returns the shots
    (lists of (M, 2) arrays, the two edges of a string next to each other) and the offsets ``q_k``."""
    rng = np.random.default_rng(seed)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0]) if axis is None else np.asarray(axis, float)
    half = 0.5 * np.hypot(width, height)
    n_str = len(bends)
    offsets = (np.arange(n_str) - (n_str - 1) / 2.0) * spacing
    shots = []
    for theta in turntable_deg:
        a = np.radians(angle0 + theta)
        d = np.array([np.cos(a), np.sin(a)])
        n = np.array([-d[1], d[0]])
        lines = []
        for q, coef in zip(offsets, bends):
            t = np.arange(-1.6 * half, 1.6 * half, step)
            u = t / half
            p2, p3, p4 = 0.5 * (3 * u**2 - 1), 0.5 * (5 * u**3 - 3 * u), (35 * u**4 - 30 * u**2 + 3) / 8
            dev = coef[0] * p2 + coef[1] * p3 + coef[2] * p4
            for side in (-0.5, 0.5):
                ideal = c + t[:, None] * d + (q + side * string_width + dev)[:, None] * n
                dist = lens.distort_points(ideal)
                ok = np.all(np.isfinite(dist), axis=1) & np.all(
                    (dist > margin) & (dist < [width - 1 - margin, height - 1 - margin]), axis=1
                )
                p = dist[ok]
                if len(p) >= 8:
                    lines.append(p + rng.normal(0.0, noise, p.shape))
        shots.append(lines)
    return shots, offsets


def kinked_harp_point_sets(
    lens, width, height, turntable_deg, n_strings, kinks, *, angle0=20.0, axis=None, spacing=60.0,
    string_width=3.0, t=30, noise=0.01, seed=0, margin=5.0,
):  # fmt: skip
    """Measured-like edge point sets of a turning harp whose strings carry kinks (test helper, exact truth).

    As :func:`turning_harp_point_sets` with straight strings, but string ``k`` in ``kinks`` (a dict
    ``k -> (a_k, h, lam)``) carries the cusp of :mod:`pipeline.harp_scene`, ``h exp(-|a - a_k| / lam)`` across
    it at harp position ``a`` (ideal px along the string from the axis), on both edges. Each edge is traced
    densely (every ideal pixel) through ``lens.distort_points``, smoothed along itself as ``harp measure``
    does (``pipeline.resample.smooth_subsample`` with ``t``) and given Gaussian noise of ``noise`` px per
    smoothed point. Returns the shots and the offsets ``q_k``."""
    from pipeline.resample import smooth_subsample

    rng = np.random.default_rng(seed)
    c = np.array([(width - 1) / 2.0, (height - 1) / 2.0]) if axis is None else np.asarray(axis, float)
    half = 0.5 * np.hypot(width, height)
    offsets = (np.arange(n_strings) - (n_strings - 1) / 2.0) * spacing
    shots = []
    for theta in turntable_deg:
        a = np.radians(angle0 + theta)
        d = np.array([np.cos(a), np.sin(a)])
        n = np.array([-d[1], d[0]])
        lines = []
        for k, q in enumerate(offsets):
            s = np.arange(-half - 8.0, half + 8.0, 1.0)  # the image lies within half a diagonal of the axis
            dev = np.zeros_like(s)
            if k in kinks:
                at, h, lam = kinks[k]
                dev = h * np.exp(-np.abs(s - at) / lam)
            for side in (-0.5, 0.5):
                ideal = c + s[:, None] * d + (q + side * string_width + dev)[:, None] * n
                dist = lens.distort_points(ideal)
                ok = np.all(np.isfinite(dist), axis=1) & np.all(
                    (dist > margin) & (dist < [width - 1 - margin, height - 1 - margin]), axis=1
                )
                idx = np.flatnonzero(ok)
                if len(idx) < 8 * t:
                    continue
                run = idx[: np.argmax(np.diff(np.concatenate([idx, [idx[-1] + 2]])) > 1) + 1]  # first inside run
                p = smooth_subsample(dist[run], t=t)
                lines.append(p + rng.normal(0.0, noise, p.shape))
        shots.append(lines)
    return shots, offsets


def drawn_harp_point_sets(lens, width, height, turntable_deg, harp, mount, *, step=10.0, noise=0.01, seed=0):
    """Edge point sets of a drawn harp (``pipeline.harp_scene.draw_harp``: bows, kinks, twist) turning on
    ``mount`` (``pipeline.harp_scene.HarpMount``), with each edge's string number (test helper, exact truth).

    Every edge that reaches the image (``pipeline.realism.shot_edges``) is traced through the exact lens every
    ``step`` ideal px and clipped to the image (``pipeline.render.visible_edges``: its longest run inside, 50 px
    or longer), then given Gaussian noise of ``noise`` px. Returns the shots (lists of (M, 2) arrays) and, per
    shot, the drawn string index of each edge."""
    from pipeline.realism import shot_edges
    from pipeline.render import visible_edges

    rng = np.random.default_rng(seed)
    shots, strings = [], []
    for theta in turntable_deg:
        pose = mount.pose(float(theta))
        curves = visible_edges(shot_edges(lens, harp, pose, width, height), lens, width, height, step=step)
        shots.append([c + rng.normal(0.0, noise, c.shape) for _, c in curves])
        strings.append([int(e.string_index) for e, _ in curves])
    return shots, strings
