"""Does a twin corrupt ``harp calibrate``'s model choice? The choice with and without it, against the drawn lens.

Usage::

    .venv/bin/python benchmarks/twin_choice.py [--seeds 20] [--workers 2]

``harp calibrate`` of photographs with a twin (a shot at an angle already taken) fits and cross-validates every shot,
so one leave-one-shot-out fold holds out a twin whose sibling stays in: a fold nearer in-sample than the others,
which could favour a model that bends to the orientations it sees. The photographs' set-up of
``benchmarks/realism.py`` (1761x1174, strings at 81.4, 43.2 and 178.1 deg, every effect drawn from its documented
range, a stable lens with a field of up to 0.04 px RMS) plus a fourth shot at the first one's angle: the automatic
choice (:func:`pipeline.select.select_model`, the default candidates) made on the four shots and on the three
distinct ones, each chosen spec fitted on the four, and its field error against the drawn lens
(:func:`pipeline.compare.compare_models`, modulo homography, 20 px grid).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def _job(seed: int) -> tuple[int, dict[str, tuple[str, float]], float]:
    import threadpoolctl
    from realism import REAL_ANGLES, H, W, simulated_measurements

    from pipeline.compare import compare_models
    from pipeline.fit import fit_distortion
    from pipeline.select import select_model

    t0 = time.perf_counter()
    with threadpoolctl.threadpool_limits(1):
        ms, info = simulated_measurements(seed, string_angles=(*REAL_ANGLES, REAL_ANGLES[0]), angle_sd_deg=0.0)
        shots = [[ln.points for ln in m.lines] for m in ms]
        out = {}
        for name, chosen_on in (("chosen on the four", shots), ("chosen on the three distinct", shots[:3])):
            spec = select_model(chosen_on, W, H).choice
            fit = fit_distortion(shots, W, H, **spec.fit_arguments())
            err = compare_models(fit.model, info["model"], W, H, step=20).rms if fit else float("nan")
            out[name] = (spec.label, float(err))
    return seed, out, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    cmd = " ".join(["benchmarks/twin_choice.py", *(argv if argv is not None else sys.argv[1:])])
    print(
        f"# harp calibrate's choice with a twin (the photographs' set-up plus a shot at the first angle; "
        f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; `{cmd}`)"
    )
    print()
    with ProcessPoolExecutor(max(1, args.workers)) as pool:
        rows = list(pool.map(_job, range(args.seeds)))
    names = list(rows[0][1])
    print("| seed | " + " | ".join(f"{n}: spec, field error px" for n in names) + " |")
    print("|---:|" + "---|" * len(names))
    for seed, r, _dt in rows:
        print(f"| {seed} | " + " | ".join(f"{r[n][0]} {r[n][1]:.4f}" for n in names) + " |")
    a, b = (np.array([r[n][1] for _, r, _ in rows]) for n in names)
    same = sum(r[names[0]][0] == r[names[1]][0] for _, r, _ in rows)
    print()
    print(
        f"field error median: {names[0]} {np.median(a):.4f} px, {names[1]} {np.median(b):.4f} px; the same spec "
        f"chosen for {same} of {len(rows)}; with the twin in the folds worse by more than 5 %: "
        f"{int(np.sum(a > 1.05 * b))}, better by more than 5 %: {int(np.sum(a < b / 1.05))} "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
