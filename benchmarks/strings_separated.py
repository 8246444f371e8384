"""The lens with the strings' own shapes separated (issue 19 items 4 and 5) across a seeded population.

Usage::

    .venv/bin/python benchmarks/strings_separated.py [--seeds 20] [--first-seed 0] [--size 1000x750]

Per seed: a lens of the seeded population (``pipeline.lens_population``), a harp with its strings as
drawn (``pipeline.realism.realistic_session``: sag, bow, kink and braid twist of the documented physical
magnitudes, nothing forced), the camera's effects (field-dependent blur, vignetting, back-light, shot
noise, Bayer and demosaicing), six shots at turntable angles 0..150 degrees (what a session fits) and
three more at 17, 77 and 137 degrees (never fitted), measured as ``harp measure`` does. Fitted on the six:
``radial4+tangential+prism`` alone (``fit_distortion``) and with every string's deviation
(``pipeline.harp_shape.fit_harp_shape``, the turntable angles given; what a session stores,
``station.calibration.calibrate_focus``). Truth: the exact lens, field error modulo homography over the
whole image (``compare_models``); the unseen shots' d (whole edges) corrected by each lens alone.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.compare import compare_models
from pipeline.edgeset import corrected_straightness
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import fit_harp_shape
from pipeline.lens_population import lens_population
from pipeline.measure import measure_image
from pipeline.realism import realistic_session, render_shots

FITTED = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
UNSEEN = (17.0, 77.0, 137.0)
SPEC = FitSpec("radial", 4, True, True)


def one(seed: int, w: int, h: int) -> dict[str, object]:
    member = lens_population(seed, 1, w, h)[0]
    lens = member.model
    ses = realistic_session(seed, w, h)
    t0 = time.perf_counter()
    shots = render_shots(lens, ses.harp, ses.mount, FITTED + UNSEEN, w, h, ses.effects, seed=seed)
    lines = [[ln.points for ln in measure_image(s.image).lines] for s in shots]
    fitted, unseen = lines[: len(FITTED)], [p for s in lines[len(FITTED) :] for p in s]
    t_render = time.perf_counter() - t0
    plain = fit_distortion(fitted, w, h, **SPEC.fit_arguments())
    if not plain:
        return {"seed": seed, "failure": plain.reason}
    t0 = time.perf_counter()
    joint = fit_harp_shape(fitted, FITTED, w, h, SPEC, plain=plain)
    t_fit = time.perf_counter() - t0
    if not joint:
        return {"seed": seed, "failure": joint.reason}
    return {
        "seed": seed,
        "kind": member.design + (f" field {member.field_rms_px:.3f}" if member.field_rms_px else ""),
        "field_plain": compare_models(plain.model, lens, w, h, step=20).rms,
        "field_joint": compare_models(joint.model, lens, w, h, step=20).rms,
        "unseen_plain": corrected_straightness(plain.model, unseen)[0],
        "unseen_joint": corrected_straightness(joint.model, unseen)[0],
        "worst_bend": max((s.bend_px for s in joint.strings if np.isfinite(s.bend_px)), default=float("nan")),
        "t_render": t_render,
        "t_fit": t_fit,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--size", default="1000x750")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    cmd = " ".join(argv if argv is not None else sys.argv[1:])
    print(
        f"# Strings separated from the lens on a seeded population, {w}x{h}, {len(FITTED)} fitted + "
        f"{len(UNSEEN)} unseen orientations ({os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}; "
        f"`benchmarks/strings_separated.py {cmd}`)"
    )
    print()
    print(
        "| seed | lens | field RMS, lens alone px | field RMS, strings separated px | ratio | unseen d, lens alone px "
        "| unseen d, strings separated px | largest fitted bend px | render+measure s | joint fit s |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        r = one(seed, w, h)
        if "failure" in r:
            print(f"| {seed} | failed: {r['failure']} | | | | | | | | |")
            continue
        rows.append(r)
        print(
            f"| {seed} | {r['kind']} | {r['field_plain']:.4f} | {r['field_joint']:.4f} | "
            f"{r['field_joint'] / r['field_plain']:.2f} | {r['unseen_plain']:.4f} | {r['unseen_joint']:.4f} | "
            f"{r['worst_bend']:.4f} | {r['t_render']:.0f} | {r['t_fit']:.1f} |",
            flush=True,
        )
    if rows:
        fp = np.array([r["field_plain"] for r in rows])
        fj = np.array([r["field_joint"] for r in rows])
        up = np.array([r["unseen_plain"] for r in rows])
        uj = np.array([r["unseen_joint"] for r in rows])
        ratio = fj / fp
        print()
        print(
            f"{len(rows)} lenses: field error median lens alone {np.median(fp):.4f} -> strings separated "
            f"{np.median(fj):.4f} px (ratio median {np.median(ratio):.2f}, best {ratio.min():.2f}, worst "
            f"{ratio.max():.2f}; lower for {int(np.sum(ratio < 0.95))}, within 5 % for "
            f"{int(np.sum(np.abs(ratio - 1) <= 0.05))}, higher for {int(np.sum(ratio > 1.05))}); at or below "
            f"0.005 px: {int(np.sum(fp <= 0.005))} -> {int(np.sum(fj <= 0.005))}; unseen d median "
            f"{np.median(up):.4f} -> {np.median(uj):.4f} px (worst ratio {np.max(uj / up):.2f})"
        )
    print(f"# load average at end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
