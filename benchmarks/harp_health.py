"""The harp checks itself (issue 19 item 4) on the realistic simulator: string bends found, the lens freed.

Usage::

    .venv/bin/python benchmarks/harp_health.py [--seeds 8] [--first-seed 0] [--places 1|2] [--size 1000x750]

Per seed: a lens of the seeded population (``pipeline.lens_population``), a harp drawn with
physical string shapes and a camera's effects (``pipeline.realism.realistic_session``: field-dependent
blur, vignetting, an uneven back-light turning with the harp, shot noise, Bayer and demosaicing), two
interior strings bent on purpose (bow modes of 0.06 and 0.05 px over the span), six shots at turntable
angles 0..150 degrees (``--places 2``: six about each of two places of the turntable axis, :data:`SHIFT`, each
group's rough shift given), measured as ``harp measure`` does. Fitted: ``radial4+tangential+prism`` alone
(``fit_distortion``) and with every string's deviation (``pipeline.harp_shape.fit_harp_shape``, the
turntable angles given). Truth: the exact lens (field error modulo homography over the whole image,
``compare_models``) and each string's exact centre line (``Harp.strings[k].deviation``) projected on
the fitted family (Legendre P2..P4 over the stretch of the string the shots show), read along the string in the
direction the fitted frame runs (``harp_along``, from the geometry). The last columns but two: the session's QA
of the same fit (``station.harp_health.harp_health``, ``station.qa.verdicts``: ``string_bend_max``), its verdict
and the strings it names, each with its drawn bend. The last line also counts the forced strings drawn beyond the
limit where the QA judges a string (within half the image diagonal of the axis and, beyond it, where two shots see
the string: ``pipeline.harp_shape.own_bends``), and how many of them it named; and the forced bends within 20 % when
both the drawn and the fitted bend are taken over that stretch only (the ends beyond half the diagonal that one shot
sees left out).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from lens_limits import widened

from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import BEND_LIMIT_PX, fit_harp_shape, legendre
from pipeline.lens_population import lens_population
from pipeline.measure import measure_image
from pipeline.realism import realistic_session, render_shots
from station.config import QAConfig
from station.harp_health import harp_health
from station.qa.verdicts import evaluate

TURNS = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
SHIFT = 150.0
"""``--places 2``: the turntable axis moved by -+(SHIFT, SHIFT / 2) px between the two groups of six shots (as
``benchmarks/axis_positions.py``, the harp widened by copies of its strings so that it fills the image)."""
SPEC = FitSpec("radial", 4, True, True)


def harp_along(frame, mount) -> int:  # type: ignore[no-untyped-def]
    """+1 when the fit's harp coordinate ``u`` runs along the drawn harp's ``+a`` (the strings' directions at
    turntable 0 agree, both in the ideal image), -1 when against: from the geometry, not from the bends. Then the
    fit's ``q`` is ``along`` times the drawn ``b`` as well (both normals are the direction turned by +90 deg)."""
    return 1 if float(frame.direction(0.0) @ np.asarray(mount.pose(0.0).direction)) > 0 else -1


def true_bend(harp, k: int, span: tuple[float, float], scale: float, along: int, judged=None) -> float:  # type: ignore[no-untyped-def]
    """String ``k``'s exact deviation, projected on P2..P4 over ``span`` (the fitted family), at its largest; with
    ``judged`` (the fitted ``StringShape``) only where the QA judges the string (``StringShape.judged``)."""
    u = np.linspace(span[0], span[1], 401)
    dev = harp.strings[k].deviation(along * u * scale)
    basis = np.vstack([np.ones_like(u), u, legendre(u, (2, 3, 4))])
    c, *_ = np.linalg.lstsq(basis.T, dev, rcond=None)
    shape = np.abs(c[2:] @ basis[2:])
    if judged is not None:
        shape = shape[judged.judged(u)]
    return float(np.max(shape)) if shape.size else float("nan")


def one(seed: int, w: int, h: int, places: int = 1) -> dict[str, object]:
    lens = lens_population(seed, 1, w, h)[0].model
    ses = realistic_session(seed, w, h, spacing_px=60.0, string_width_px=3.0)
    extra = int(np.hypot(SHIFT, SHIFT / 2) // ses.harp.spacing_px) + 1 if places == 2 else 0
    strings = list(widened(ses.harp, extra).strings) if extra else list(ses.harp.strings)
    mid = len(strings) // 2
    forced = (mid - 2, mid + 1)
    strings[forced[0]] = dataclasses.replace(strings[forced[0]], bow_px=(0.06, 0.0, 0.0))
    strings[forced[1]] = dataclasses.replace(strings[forced[1]], bow_px=(0.0, 0.05, 0.0))
    harp = dataclasses.replace(ses.harp, strings=tuple(strings))
    t0 = time.perf_counter()
    if places == 1:
        turns, groups, shifts = TURNS, None, None
        shots = render_shots(lens, harp, ses.mount, TURNS, w, h, ses.effects, seed=seed)
    else:  # the harp moved with its turntable by -+(SHIFT, SHIFT / 2) px; each group's shift given 2 % off
        turns, groups, shots = TURNS + TURNS, [-1] * len(TURNS) + [1] * len(TURNS), []
        shifts = {g: (1.02 * g * SHIFT, 1.02 * g * SHIFT / 2) for g in (-1, 1)}
        c = ses.mount.centre
        for g in (-1, 1):
            mount = dataclasses.replace(ses.mount, centre=(c[0] + g * SHIFT, c[1] + g * SHIFT / 2))
            shots += render_shots(lens, harp, mount, TURNS, w, h, ses.effects, seed=3 * seed + g + 1)
    lines = [[ln.points for ln in measure_image(s.image).lines] for s in shots]
    t_render = time.perf_counter() - t0
    plain = fit_distortion(lines, w, h, **SPEC.fit_arguments())
    t0 = time.perf_counter()
    fit = fit_harp_shape(lines, turns, w, h, SPEC, plain=plain, axis_groups=groups, axis_shifts=shifts)
    t_fit = time.perf_counter() - t0
    if not fit:
        return {"seed": seed, "failure": fit.reason}
    pos = np.array([s.position_px for s in harp.strings])
    along = harp_along(fit.frame, ses.mount)
    pairs = []  # (true bend, fitted bend, its standard error, forced?)
    drawn: dict[int, tuple[float, bool]] = {}  # fitted string -> (its drawn bend, forced?)
    judged: list[tuple[int, float, float]] = []  # forced strings: fitted string, drawn and fitted bend where judged
    for s in fit.strings:
        if not np.isfinite(s.bend_px):
            continue
        k = int(np.argmin(np.abs(pos - along * s.offset_px)))
        drawn[s.index] = (true_bend(harp, k, s.span, fit.frame.scale_px, along), k in forced)
        if k in forced:
            u = np.linspace(s.span[0], s.span[1], 401)
            fitted = float(np.max(np.abs(s.deviation(u[s.judged(u)]))))
            judged.append((s.index, true_bend(harp, k, s.span, fit.frame.scale_px, along, s), fitted))
        pairs.append((drawn[s.index][0], s.bend_px, s.bend_se_px, k in forced))
    # the session's QA of the same fit (station.harp_health.harp_health, station.qa.verdicts): its verdict and the
    # strings it names, each with its drawn bend
    health = harp_health([], turns, w, h, SPEC, joint=fit)
    check = next(
        c for c in evaluate(fit.model, w, h, 0.0, QAConfig(), harp_health=health).checks if c.name == "string_bend_max"
    )
    word = "FAIL" if check.passed is False else "PASS" if check.passed else "not judged"
    qa = (word, [(k, *drawn[k]) for k in health.get("bent_strings", [])])
    # forced strings drawn beyond the limit where the QA judges them, and whether it named them (a session not
    # judged names none)
    beyond_judged = [(b, k in health.get("bent_strings", [])) for k, b, _ in judged if b > BEND_LIMIT_PX]
    return {
        "seed": seed,
        "qa": qa,
        "beyond_judged": beyond_judged,
        "judged_pairs": [(b, f) for _, b, f in judged],
        "field_plain": compare_models(plain.model, lens, w, h, step=20).rms,
        "field_joint": compare_models(fit.model, lens, w, h, step=20).rms,
        "d_plain": plain.d_after,
        "d_joint": fit.d_after,
        "pairs": pairs,
        "axis_err": max(
            float(np.hypot(*(np.asarray(f.centre) - np.asarray(ses.mount.centre) - g * np.array([SHIFT, SHIFT / 2]))))
            for g, f in (fit.axis_groups or ((0, fit.frame),))
        ),
        "t_render": t_render,
        "t_fit": t_fit,
        "strings": len(fit.strings),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8, help="how many seeds")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--places", type=int, choices=(1, 2), default=1, help="turntable-axis places (2: twelve shots)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    print(
        f"# Harp self-check on the realistic simulator, {w}x{h}, 6 turntable angles about {args.places} axis place(s) ({os.cpu_count()} CPUs, "
        f"load {os.getloadavg()[0]:.1f}; `benchmarks/harp_health.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    print(
        "| seed | strings | axis error px | field RMS, lens alone px | field RMS, with strings px | d alone | "
        "d with strings | forced bends: true / fitted px | other strings: largest true / fitted px | "
        f"flagged > {BEND_LIMIT_PX} px (forced / others) | session QA: verdict, strings named (drawn bend px) | "
        "render+measure s | fit s |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---|---|---|---|---:|---:|")
    ratios, zs, gains, fp, qa_words, wrong, beyond, judged_ratios = [], [], [], 0, [], 0, [], []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        r = one(seed, w, h, args.places)
        if "failure" in r:
            print(f"| {seed} | failed: {r['failure']} |")
            continue
        pairs = r["pairs"]
        forced = [(a, b) for a, b, _, f in pairs if f]
        others = [(a, b) for a, b, _, f in pairs if not f]
        ratios += [b / a for a, b in forced if a > 0.01]
        judged_ratios += [b / a for a, b in r["judged_pairs"] if a > 0.01]
        zs += [(b - a) / se for a, b, se, f in pairs if f and a > 0.01 and se > 0]
        gains.append(r["field_joint"] / r["field_plain"])
        flag_f = sum(b > BEND_LIMIT_PX for _, b in forced)
        flag_o = sum(b > BEND_LIMIT_PX for a, b in others)
        fp += sum(b > BEND_LIMIT_PX and a < 0.5 * BEND_LIMIT_PX for a, b in others)
        big = max(others, key=lambda p: p[0]) if others else (float("nan"), float("nan"))
        word, named = r["qa"]
        verdict = word + "".join(f", {k}{' (forced)' if f else ''}: {t:.4f}" for k, t, f in named)
        qa_words.append(word)
        wrong += sum(t < BEND_LIMIT_PX for _, t, _ in named)
        beyond += r["beyond_judged"]
        print(
            f"| {seed} | {r['strings']} | {r['axis_err']:.2f} | {r['field_plain']:.4f} | {r['field_joint']:.4f} | "
            f"{r['d_plain']:.4f} | {r['d_joint']:.4f} | "
            + ", ".join(f"{a:.4f} / {b:.4f}" for a, b in forced)
            + f" | {big[0]:.4f} / {big[1]:.4f} | {flag_f} / {flag_o} | {verdict} | {r['t_render']:.0f} | {r['t_fit']:.1f} |"
        )
    print()
    if ratios:
        a = np.array(ratios)
        print(
            f"forced bends recovered: fitted / true {a.min():.2f}..{a.max():.2f} (median {np.median(a):.2f}), "
            f"{int(np.sum(np.abs(a - 1) <= 0.2))} of {len(a)} within 20 %, "
            f"{int(np.sum(np.abs(np.array(zs)) <= 2))} of {len(zs)} within two of their standard errors; "
            "field error with strings / alone: "
            f"median {np.median(gains):.2f}, worst {max(gains):.2f}; strings flagged whose true bend is below "
            f"{0.5 * BEND_LIMIT_PX} px: {fp}; session QA: {qa_words.count('FAIL')} FAIL, {qa_words.count('PASS')} PASS, "
            f"{qa_words.count('not judged')} not judged, strings named whose drawn bend is within the limit: {wrong}; "
            f"forced strings drawn beyond the limit where the QA judges them: {len(beyond)}, named: "
            f"{sum(n for _, n in beyond)}; forced bends within 20 % over the stretch the QA judges: "
            f"{int(np.sum(np.abs(np.array(judged_ratios) - 1) <= 0.2))} of {len(judged_ratios)}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
