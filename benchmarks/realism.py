"""Do the realistic simulator's residuals look like the real photographs'?

Usage::

    .venv/bin/python benchmarks/realism.py [--seeds 24] [--clean 6] [--workers 2] [--real DIR]
        [--field-max PX] [--shot-decentre SD] [--centre-sd PX] [--coil-set V] [--bow PX]

The three shared photographs (``../shared/data/real-harp``: 1761x1174, strings near
81°, 43° and 178°) are measured (``pipeline.measure.measure_image``, t = 30) and fitted
with radial4+tangential+prism; the same is done to a population of simulated sessions,
one per seed: a lens of ``pipeline.lens_population`` (designs drawn, manufacturing spread,
non-parametric field of 0.005-0.04 px RMS), a harp, mount and camera effects of
``pipeline.realism.realistic_session`` (every magnitude drawn from its documented
physical range, none tuned to the photographs), three shots at the photographs' string
angles (each +- 3°), 1761x1174, string width 2.4-3.1 px and pitch 110-140 px (the
photographs' set-up). ``--clean`` adds sessions of the clean simulator (the same lenses
with their field, straight strings, uniform 0.7 px blur, 8-bit with read noise 1.5, no
colour filter array): what the team's synthetic world looked like before.

Statistics, each per shot, computed the same way for real and simulated shots:

* ``in-sample d``: d of each shot under the correction fitted on all three;
* ``held-out d``: d of a shot under the correction fitted on the other two;
* ``end / middle``: RMS residual (in-sample) of the first and last tenth of every edge's
  points, and of the rest;
* ``band >= 400 / 150-400 / 60-150 px``: RMS of the in-sample residual along each edge in
  wavelength bands (FFT of the residual sampled every t px; 60 px is the Nyquist limit);
* ``edge-pair corr``: median over strings of the correlation of the residuals of a string's
  two edges (signs along one normal per shot: +1 a shared centre-line deviation, -1 a
  width change);
* ``neighbour corr``: median over pairs of neighbouring strings of the correlation of
  their centre lines' residuals;
* ``centre-line / half-width RMS``: the residual decomposed into the mean of the two edges
  and half their difference (each string's means removed).

The table gives the real value of each photograph, the simulated population's median
and 10-90 % range over all its shots (3 per seed), and where the real value falls in
the simulated population (its percentile; "in" when within the population's 5-95 %).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.edgeset import held_out_residuals
from pipeline.fit import fit_distortion
from pipeline.fitspec import parse
from pipeline.measure import ImageMeasurement, measure_image

W, H = 1761, 1174
REAL = ("IMG_6931", "IMG_6950", "IMG_6964")
REAL_ANGLES = (81.4, 43.2, 178.1)  # the photographs' string angles, measured
SPEC = "radial4+tangential+prism"
BANDS = ((400.0, math.inf), (150.0, 400.0), (60.0, 150.0))
STATS = (
    ("in-sample d", "px"),
    ("held-out d", "px"),
    ("end tenth RMS", "px"),
    ("middle RMS", "px"),
    ("end / middle", ""),
    ("band >= 400 px", "px"),
    ("band 150-400 px", "px"),
    ("band 60-150 px", "px"),
    ("edge-pair corr", ""),
    ("neighbour corr", ""),
    ("centre-line RMS", "px"),
    ("half-width RMS", "px"),
)


# ---------------------------------------------------------------- statistics of one set of shots
def _residual(model, pts: np.ndarray, nref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corrected points' signed distances to their TLS line (normal oriented along ``nref``) and the points."""
    u = model.undistort_points(pts)
    c = u.mean(0)
    _, v = np.linalg.eigh(np.cov((u - c).T))
    n = v[:, 0] if v[:, 0] @ nref >= 0 else -v[:, 0]
    return (u - c) @ n, u


def _band_power(r: np.ndarray, spacing: float) -> np.ndarray:
    """Sum of squares of ``r`` (mean removed) in each wavelength band of :data:`BANDS` (Parseval)."""
    r = r - r.mean()
    n = len(r)
    spec = np.abs(np.fft.rfft(r)) ** 2 / n
    spec[1 : (n + 1) // 2] *= 2.0  # the negative frequencies
    freq = np.fft.rfftfreq(n, spacing)
    wl = np.where(freq > 0, 1.0 / np.where(freq > 0, freq, 1.0), np.inf)
    return np.array([spec[(wl >= lo) & (wl < hi)].sum() for lo, hi in BANDS])


def _on(ta: np.ndarray, tb: np.ndarray, sb: np.ndarray) -> np.ndarray:
    o = np.argsort(tb)
    return np.interp(ta, tb[o], sb[o], left=np.nan, right=np.nan)


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 8:
        return math.nan
    a, b = a[ok] - a[ok].mean(), b[ok] - b[ok].mean()
    den = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / den if den > 0 else math.nan


def shot_statistics(model, m: ImageMeasurement) -> dict[str, float]:
    """Every statistic of :data:`STATS` but the d figures, for one measured shot under ``model``."""
    lines = m.lines
    u0 = model.undistort_points(lines[0].points)
    d = u0[-1] - u0[0]
    d /= np.linalg.norm(d)
    nref = np.array([-d[1], d[0]])
    ends, mids, bands, npts = [], [], np.zeros(len(BANDS)), 0
    by: dict[int, dict[int, tuple[np.ndarray, np.ndarray]]] = {}
    offsets: dict[int, float] = {}
    for ln in lines:
        r, u = _residual(model, ln.points, nref)
        k = max(1, len(r) // 10)
        ends.append(np.concatenate([r[:k], r[-k:]]))
        mids.append(r[k:-k])
        spacing = float(np.mean(np.hypot(*np.diff(u, axis=0).T)))
        bands += _band_power(r, spacing)
        npts += len(r)
        by.setdefault(ln.string_id, {})[ln.polarity] = (u @ d, r)
        offsets[ln.string_id] = float(u.mean(0) @ nref)
    pair, centre, half, cl = [], [], [], {}
    for sid, sides in by.items():
        if len(sides) != 2:
            continue
        (ta, sa), (tb, sb) = sides[min(sides)], sides[max(sides)]
        sbi = _on(ta, tb, sb)
        pair.append(_corr(sa, sbi))
        ok = np.isfinite(sbi)
        c, h = 0.5 * (sa[ok] + sbi[ok]), 0.5 * (sa[ok] - sbi[ok])
        if len(c) >= 8:
            centre.append(c - c.mean())
            half.append(h - h.mean())
            cl[sid] = (ta[ok], c)
    order = sorted(cl, key=lambda s: offsets[s])
    neigh = [_corr(cl[a][1], _on(cl[a][0], *cl[b])) for a, b in zip(order, order[1:])]
    e, mid = np.concatenate(ends), np.concatenate(mids)
    rms = lambda x: float(np.sqrt(np.mean(np.square(x)))) if len(x) else math.nan  # noqa: E731
    out = {
        "end tenth RMS": rms(e),
        "middle RMS": rms(mid),
        "edge-pair corr": float(np.nanmedian(pair)) if pair else math.nan,
        "neighbour corr": float(np.nanmedian(neigh)) if neigh else math.nan,
        "centre-line RMS": rms(np.concatenate(centre)) if centre else math.nan,
        "half-width RMS": rms(np.concatenate(half)) if half else math.nan,
    }
    out["end / middle"] = out["end tenth RMS"] / out["middle RMS"]
    for (lo, hi), p in zip(BANDS, bands):
        out[f"band {lo:.0f}-{hi:.0f} px" if math.isfinite(hi) else f"band >= {lo:.0f} px"] = math.sqrt(p / npts)
    return out


def session_statistics(ms: list[ImageMeasurement]) -> list[dict[str, float]]:
    """The statistics of each shot of a session of measured shots (fit on all, and leave one out)."""
    spec = parse(SPEC).fit_arguments()
    shots = [[ln.points for ln in m.lines] for m in ms]
    full = fit_distortion(shots, W, H, **spec)
    if not full:
        raise RuntimeError(f"fit failed: {full}")
    out = []
    for i, m in enumerate(ms):
        st = shot_statistics(full.model, m)
        st["in-sample d"] = float(full.images[i].d_after)
        loo = fit_distortion([s for j, s in enumerate(shots) if j != i], W, H, **spec)
        st["held-out d"] = float(np.sqrt(np.mean(held_out_residuals(loo.model, shots[i]) ** 2))) if loo else math.nan
        out.append(st)
    return out


# ---------------------------------------------------------------- simulated sessions
def simulated_measurements(
    seed: int,
    clean: bool = False,
    coil_set: float | None = None,
    field_max: float | None = None,
    shot_decentre: float = 0.0,
    bow_px: float = 0.0,
    centre_sd_px: float = 0.0,
    string_angles: Sequence[float] = REAL_ANGLES,
    angle_sd_deg: float = 3.0,
) -> tuple[list[ImageMeasurement], dict[str, object]]:
    """Render and measure one simulated session (module docstring; :func:`session_statistics` analyses it): its
    shots' measurements and what was drawn (``info["model"]`` the lens, ``info["shot_models"]`` each shot's, moved when
    the lens moves between shots). ``shot_decentre``, ``centre_sd_px``: the lens's p1, p2 and distortion
    centre changed between shots by N(0, these) (:func:`pipeline.lens_population.shot_to_shot`); ``string_angles``:
    the shots' string angles (deg, each moved by N(0, ``angle_sd_deg``)), the photographs' by default."""
    from pipeline.harp_scene import COIL_SET_VARIATION, Harp, HarpMount
    from pipeline.lens_population import lens_population, shot_to_shot
    from pipeline.realism import Effects, realistic_session, render_shot, render_shots, shot_seed
    from pipeline.sensor import Development, Sensor

    fields = (0.005, 0.04 if field_max is None else field_max)
    lens = lens_population(2026, seed + 1, W, H, field=True, field_rms_px=fields)[seed]
    rng = np.random.default_rng([seed, 0xBE7C])
    angles = [a + float(rng.normal(0.0, angle_sd_deg)) for a in string_angles]
    s = realistic_session(
        seed,
        W,
        H,
        spacing_px=(110.0, 140.0),
        string_width_px=(2.4, 3.1),
        angle0_deg=angles[0],
        coil_set_variation=COIL_SET_VARIATION if coil_set is None else coil_set,
    )
    harp, mount, effects = s.harp, s.mount, s.effects
    if clean:
        harp = Harp.straight(len(harp.strings), harp.spacing_px, 2 * harp.strings[0].radius_px, harp.first_position_px)
        effects = Effects(sensor=Sensor(exposure=0.8, read_noise_e=1.5 * 25000.0 / 255.0), development=Development())
        mount = HarpMount(mount.centre, mount.angle0_deg, mount.direction)
    if bow_px > 0:  # sensitivity: every string bowed by modes of N(0, bow_px), on top of its physics
        extra = np.random.default_rng([seed, 0xB0E]).normal(0.0, bow_px, (len(harp.strings), 3))
        strings = tuple(
            dataclasses.replace(st, bow_px=tuple(float(b + e) for b, e in zip(st.bow_px, extra[i])))
            for i, st in enumerate(harp.strings)
        )
        harp = dataclasses.replace(harp, strings=strings)
    turntable = [mount.direction * (a - angles[0]) for a in angles]
    shot_models = [lens.model] * len(turntable)
    if shot_decentre > 0 or centre_sd_px > 0:  # sensitivity: the lens's decentering changes between shots
        jitter = np.random.default_rng([seed, 0x5407])
        shot_models = [shot_to_shot(lens.model, jitter, shot_decentre, centre_sd_px) for _ in turntable]
        shots = tuple(
            render_shot(m, harp, mount, t, W, H, effects, shot_seed(seed, i))
            for i, (m, t) in enumerate(zip(shot_models, turntable))
        )
    else:
        shots = render_shots(lens.model, harp, mount, turntable, W, H, effects, seed=seed)
    ms = [measure_image(sh.image, t=30) for sh in shots]
    info = {
        "lens": lens.serial,
        "field": lens.field_rms_px,
        "material": harp.material,
        "demosaic": effects.development.demosaic if effects.sensor.cfa else "none",
        "tone": effects.development.tone,
        "model": lens.model,
        "shot_models": shot_models,
    }
    return ms, info


def _drawn(info: dict[str, object]) -> dict[str, object]:
    """What :func:`simulated_measurements` drew, without its models (for a log line)."""
    return {k: v for k, v in info.items() if k not in ("model", "shot_models")}


def _job(
    args: tuple[int, bool, float | None, float | None, float, float, float],
) -> tuple[int, bool, list[dict[str, float]], dict[str, object], float]:
    import threadpoolctl

    t0 = time.perf_counter()
    with threadpoolctl.threadpool_limits(1):
        ms, info = simulated_measurements(*args)
        st = session_statistics(ms)
    return args[0], args[1], st, _drawn(info), time.perf_counter() - t0


# ---------------------------------------------------------------- the table
def _fmt(v: float) -> str:
    if not math.isfinite(v):
        return "-"
    return f"{v:.3f}" if abs(v) < 10 else f"{v:.1f}"


def table(real: list[dict[str, float]], sim: list[dict[str, float]], clean: list[dict[str, float]]) -> list[str]:
    head = "| statistic | " + " | ".join(REAL) + " | simulated median [10-90 %] | real's percentile in simulated |"
    if clean:
        head += " clean simulator median |"
    rows = [head, "|---|" + "---:|" * len(REAL) + "---|---|" + ("---:|" if clean else "")]
    for name, unit in STATS:
        label = f"{name} ({unit})" if unit else name
        sv = np.array([s[name] for s in sim if math.isfinite(s[name])])
        cells = [_fmt(r[name]) for r in real]
        pct = [100.0 * float(np.mean(sv < r[name])) for r in real if math.isfinite(r[name])] if len(sv) else []
        inside = ["in" if 5.0 <= p <= 95.0 else "OUT" for p in pct]
        spread = (
            f"{_fmt(float(np.median(sv)))} [{_fmt(float(np.percentile(sv, 10)))}, {_fmt(float(np.percentile(sv, 90)))}]"
            if len(sv)
            else "-"
        )
        where = ", ".join(f"{p:.0f} ({w})" for p, w in zip(pct, inside))
        row = f"| {label} | " + " | ".join(cells) + f" | {spread} | {where} |"
        if clean:
            cv = [c[name] for c in clean if math.isfinite(c[name])]
            row += f" {_fmt(float(np.median(cv))) if cv else '-'} |"
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=24, help="simulated sessions (3 shots each)")
    ap.add_argument("--clean", type=int, default=6, help="sessions of the clean simulator, for comparison")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--coil-set", type=float, default=None, help="coil-set variation of the strings (default: the documented 0.3)"
    )
    ap.add_argument(
        "--field-max", type=float, default=None, help="largest lens-field RMS px (default: the documented 0.04)"
    )
    ap.add_argument(
        "--shot-decentre", type=float, default=0.0, help="sensitivity: p1, p2 change by N(0, this) per shot"
    )
    ap.add_argument("--bow", type=float, default=0.0, help="sensitivity: extra string bows, N(0, this) px per mode")
    ap.add_argument(
        "--centre-sd",
        type=float,
        default=0.0,
        help="sensitivity: the lens's distortion centre moves by N(0, this) px per axis between shots",
    )
    ap.add_argument(
        "--real",
        default=os.environ.get("HARP_REAL_DATA", str(Path(__file__).resolve().parents[2] / "shared/data/real-harp")),
    )
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    from station.imageio import read_grey

    real_ms = [measure_image(read_grey(Path(args.real) / f"{n}.pgm"), t=30) for n in REAL]
    real = session_statistics(real_ms)
    jobs = [
        (s, False, args.coil_set, args.field_max, args.shot_decentre, args.bow, args.centre_sd)
        for s in range(args.seeds)
    ]
    jobs += [(s, True, None, args.field_max, 0.0, 0.0, 0.0) for s in range(args.clean)]
    sim: list[dict[str, float]] = []
    clean: list[dict[str, float]] = []
    infos = []
    with ProcessPoolExecutor(max(1, args.workers)) as pool:
        for seed, is_clean, st, info, dt in pool.map(_job, jobs):
            (clean if is_clean else sim).extend(st)
            if not is_clean:
                infos.append((seed, info, st, dt))
            print(
                f"# seed {seed}{' clean' if is_clean else ''}: {info} in-sample d "
                + " / ".join(f"{s['in-sample d']:.4f}" for s in st)
                + "  held-out d "
                + " / ".join(f"{s['held-out d']:.4f}" for s in st)
                + f"  ({dt:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    print(
        f"# Realistic simulator against the three real photographs: radial4+tangential+prism residuals "
        f"({args.seeds} simulated sessions x 3 shots, {args.clean} clean sessions; coil-set variation "
        f"{args.coil_set if args.coil_set is not None else 'default'}, lens field up to "
        f"{args.field_max if args.field_max is not None else 0.04} px"
        + (f", decentering changing by N(0, {args.shot_decentre:g}) between shots" if args.shot_decentre else "")
        + (f", extra string bows N(0, {args.bow:g}) px per mode" if args.bow else "")
        + (f", distortion centre moving by N(0, {args.centre_sd:g}) px between shots" if args.centre_sd else "")
        + f"; {os.cpu_count()} CPUs, "
        f"{time.perf_counter() - t0:.0f} s)"
    )
    print()
    for line in table(real, sim, clean):
        print(line)
    print()
    print("| seed | lens | field RMS px | strings | demosaic | tone | in-sample d (3 shots) | held-out d (3 shots) |")
    print("|---:|---|---:|---|---|---|---|---|")
    for seed, info, st, _ in infos:
        print(
            f"| {seed} | {info['lens']} | {float(info['field']):.3f} | {info['material']} | {info['demosaic']} | {info['tone']} | "
            + " / ".join(f"{s['in-sample d']:.4f}" for s in st)
            + " | "
            + " / ".join(f"{s['held-out d']:.4f}" for s in st)
            + " |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
