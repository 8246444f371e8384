"""Two shots at one angle: does the lens move between them? Realistic sessions with a twin shot.

Usage::

    .venv/bin/python benchmarks/twins.py [--seeds 20] [--workers 2]

The photographs' set-up (``benchmarks/realism.py``: 1761x1174, strings at 81.4, 43.2 and 178.1 deg, every effect drawn
from its documented range) plus a fourth shot at the first one's angle, the harp not moved otherwise (the twin). The
correction radial4+tangential+prism is fitted on all four (as ``harp calibrate`` of four photographs fits it), and
:func:`pipeline.own_shift.twin_shift` compares the twins under it: ``ratio`` = d with a shift each / d with one shift
for both (near 1: nothing moved, or a term of the lens at that angle; below 1: the lens moved between them) and the
move across the strings it reads, against the move drawn (the difference of the twins' distortion centres across
the strings).

Cameras: a stable lens (non-parametric field up to 0.04 px RMS, the default, and up to 0.1 px) and lenses whose
distortion centre moves between shots by N(0, 3 px) and N(0, 6 px) per axis (``realism.py --centre-sd``; 6 px with
the 0.1 px field is the camera whose residuals hold the photographs', ``benchmarks/RESULTS-realism.md``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import cast

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

CONFIGS = (  # (label, largest lens-field RMS px, distortion-centre SD px)
    ("stable lens, field <= 0.04 px", 0.04, 0.0),
    ("stable lens, field <= 0.1 px", 0.1, 0.0),
    ("centre moving N(0, 3 px), field <= 0.04 px", 0.04, 3.0),
    ("centre moving N(0, 6 px), field <= 0.04 px", 0.04, 6.0),
    ("centre moving N(0, 6 px), field <= 0.1 px", 0.1, 6.0),
)
LIMITS = (0.9, 0.8)


def _job(args: tuple[int, float, float]) -> tuple[tuple[int, float, float], tuple[float, float, float, float], float]:
    import threadpoolctl
    from realism import REAL_ANGLES, SPEC, H, W, simulated_measurements

    from pipeline.fit import fit_distortion
    from pipeline.fitspec import parse
    from pipeline.models.base import DistortionModel
    from pipeline.own_shift import twin_shift

    t0 = time.perf_counter()
    seed, field_max, centre_sd = args
    with threadpoolctl.threadpool_limits(1):
        angles = (*REAL_ANGLES, REAL_ANGLES[0])
        ms, drawn = simulated_measurements(
            seed, field_max=field_max, centre_sd_px=centre_sd, string_angles=angles, angle_sd_deg=0.0
        )
        shots = [[ln.points for ln in m.lines] for m in ms]
        res = fit_distortion(shots, W, H, **parse(SPEC).fit_arguments())
        if not res:
            return args, (np.nan,) * 4, time.perf_counter() - t0
        got = twin_shift(res.model, shots[0], shots[3])
        own = cast(list[DistortionModel], drawn["shot_models"])
        centres = [np.asarray(getattr(m, "base", m).center, dtype=np.float64) for m in (own[0], own[3])]
        drawn_move = float(np.dot(centres[1] - centres[0], got.normal))
    return args, (got.ratio, got.move_px, drawn_move, got.d_model), time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="simulated sessions per camera")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    cmd = " ".join(["benchmarks/twins.py", *(argv if argv is not None else sys.argv[1:])])
    print(
        f"# Two shots at one angle under the correction fitted on four ({os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.1f} at start; `{cmd}`)"
    )
    print()
    jobs = [(s, f, c) for _, f, c in CONFIGS for s in range(args.seeds)]
    got: dict[tuple[int, float, float], tuple[float, float, float, float]] = {}
    with ProcessPoolExecutor(max(1, args.workers)) as pool:
        for key, row, dt in pool.map(_job, jobs):
            got[key] = row
            print(
                f"# seed {key[0]} field {key[1]:g} centre {key[2]:g}: ratio {row[0]:.3f} move {row[1]:.2f} px "
                f"(drawn {row[2]:.2f}) d {row[3]:.4f} ({dt:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    print(
        "| camera | twins' ratio, median [range] | "
        + " | ".join(f"ratio below {lim:g}" for lim in LIMITS)
        + " | drawn move across the strings, median \\|px\\| | read move - drawn, RMS [max \\|\\|] px"
        + " | read move beyond 1 px |"
    )
    print("|---|---|" + "---|" * len(LIMITS) + "---|---|---|")
    for label, f, c in CONFIGS:
        a = np.array([got[(s, f, c)] for s in range(args.seeds)])
        ok = a[np.isfinite(a[:, 0])]
        ratio = ok[:, 0]
        cells = [f"{np.median(ratio):.3f} [{ratio.min():.3f}, {ratio.max():.3f}]"]
        cells += [f"{int(np.sum(ratio < lim))} of {len(ratio)}" for lim in LIMITS]
        cells.append(f"{np.median(np.abs(ok[:, 2])):.2f}")
        err = ok[:, 1] - ok[:, 2]
        cells.append(f"{np.sqrt(np.mean(err**2)):.2f} [{np.abs(err).max():.2f}]")
        cells.append(f"{int(np.sum(np.abs(ok[:, 1]) > 1.0))} of {len(ok)}")
        print(f"| {label} | " + " | ".join(cells) + " |")
    print()
    print(f"({time.perf_counter() - t0:.0f} s; load average {os.getloadavg()[0]:.1f} at end)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
