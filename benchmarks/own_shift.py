"""How much of a held-out shot's error is a term of its own? The real photographs against the realistic simulator.

Usage::

    .venv/bin/python benchmarks/own_shift.py [--seeds 20] [--shots 3] [--workers 2] [--real DIR]

Every 2 + 1 split of three shots (with ``--shots N``, every shot of N held out in turn): radial4+tangential+prism
fitted on the others (``pipeline.fit.fit_distortion``), the held-out shot's d with that correction as it is, and
with two parameters of the held-out shot's own fitted on it (the correction is otherwise held):

* **own axis shift** (:func:`pipeline.own_shift.own_axis_shift`): the whole correction moved by a vector ``t``
  (``U'(p) = U(p - t) + t``), which is what a lens whose distortion centre moved between shots does (an image
  stabiliser that re-centres, a focus or zoom group with play; :func:`pipeline.lens_population.shot_to_shot`). On
  one shot's parallel strings it shows mostly as a bow every string shares (the radial term's gradient across the
  strings), so it also stands for a bow the whole harp shares in that shot, or a lens term that bends each
  orientation its own way (a three-fold term, ``benchmarks/quadratic_sector.py``): one shot per orientation cannot
  tell these apart;
* **own k1, k2** (control): the radial terms changed for the held-out shot, which a refocus would do; it bends
  every orientation alike.

The ratio ``with its own term / as it is`` says how much of the held-out error a two-parameter term of that shot
alone takes away. The same is computed on simulated sessions built like ``benchmarks/realism.py``'s (three shots at
the photographs' string angles, 1761x1174, every effect drawn from its documented range; its
:func:`realism.simulated_measurements`), with a stable lens (non-parametric field up to 0.04 px RMS, the default,
and up to 0.1 px) and with a lens whose distortion centre moves between shots by N(0, 6 px), or whose decentering
terms p1, p2 do by N(0, 5e-5) or N(0, 1e-4) (``benchmarks/realism.py --shot-decentre``).
The first two splits (near-vertical and diagonal strings held out) and the third (near-horizontal, whose strings
span the long side) are summarised apart.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from pipeline.edgeset import held_out_residuals
from pipeline.fit import fit_distortion
from pipeline.fitspec import parse
from pipeline.models.base import DistortionModel
from pipeline.own_shift import own_axis_shift
from station.moving_lens import OWN_SHIFT_RATIO

SPEC = "radial4+tangential+prism"
CONFIGS = (  # (label, largest lens-field RMS px, distortion-centre SD px, p1/p2 SD between shots)
    ("stable lens, field <= 0.04 px", 0.04, 0.0, 0.0),
    ("stable lens, field <= 0.1 px", 0.1, 0.0, 0.0),
    ("centre moving N(0, 6 px)", 0.04, 6.0, 0.0),
    ("decentering p1, p2 moving N(0, 5e-5)", 0.04, 0.0, 5e-5),
    ("decentering p1, p2 moving N(0, 1e-4)", 0.04, 0.0, 1e-4),
)
TERMS = ("axis shift", "k1, k2")


def own_k_d(model: DistortionModel, lines: Sequence[np.ndarray], width: int, height: int) -> float:
    """Held-out d of ``lines`` under ``model`` with the shot's own k1, k2 change fitted on them (the control): the
    correction applied to ``p + s q (a r^2 + b r^4)``, ``q`` the offset from the image centre over ``s``, half the
    diagonal."""
    from scipy.optimize import least_squares

    scale = 0.5 * float(np.hypot(width, height))
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])

    class _Model:
        def __init__(self, z: np.ndarray) -> None:
            self.z = z

        def undistort_points(self, xy: np.ndarray) -> np.ndarray:
            p = np.asarray(xy, dtype=np.float64)
            q = (p - centre) / scale
            r2 = np.sum(q * q, axis=1, keepdims=True)
            return model.undistort_points(p + scale * q * (self.z[0] * r2 + self.z[1] * r2 * r2))

    sol = least_squares(
        lambda z: held_out_residuals(_Model(z), lines),  # type: ignore[arg-type]
        np.zeros(2),
        x_scale=1e-3,
        diff_step=1e-4,
    )
    return float(np.sqrt(np.mean(sol.fun**2)))


def splits(shots: Sequence[Sequence[np.ndarray]], width: int, height: int) -> list[tuple[float, ...] | None]:
    """Per 2 + 1 split (the shot held out in order): fit d, held-out d, and held-out d with each of :data:`TERMS`
    of its own; None where the fit fails."""
    spec = parse(SPEC)
    out: list[tuple[float, ...] | None] = []
    for h in range(len(shots)):
        res = fit_distortion([shots[i] for i in range(len(shots)) if i != h], width, height, **spec.fit_arguments())
        if not res:
            out.append(None)
            continue
        own = own_axis_shift(res.model, shots[h])
        out.append((res.d_after, own.d_held, own.d_own, own_k_d(res.model, shots[h], width, height)))
    return out


def shot_angles(n: int) -> tuple[float, ...]:
    """The shots' string angles: the photographs' for three, else ``n`` spread over the half turn from 10 deg (never
    within 2 deg of the pixel grid)."""
    from realism import REAL_ANGLES

    return tuple(REAL_ANGLES) if n == 3 else tuple(10.0 + 180.0 * i / n for i in range(n))


def _job(
    args: tuple[int, float, float, float, int],
) -> tuple[tuple[int, float, float, float, int], list[tuple[float, ...] | None], float]:
    import threadpoolctl
    from realism import H, W, simulated_measurements

    t0 = time.perf_counter()
    seed, field_max, centre_sd, tangential_sd, n = args
    with threadpoolctl.threadpool_limits(1):
        ms, _ = simulated_measurements(
            seed,
            field_max=field_max,
            shot_decentre=tangential_sd,
            centre_sd_px=centre_sd,
            string_angles=shot_angles(n),
        )
        got = splits([[ln.points for ln in m.lines] for m in ms], W, H)
    return args, got, time.perf_counter() - t0


def _fmt_split(row: tuple[float, ...] | None) -> str:
    if row is None:
        return "fit failed"
    fit, held, *own = row
    return f"{fit:.4f} / {held:.4f} / " + " / ".join(f"{o:.4f} ({o / held:.2f})" for o in own)


def _summary(rows: list[tuple[float, ...]], real_worst: float | None) -> str:
    if not rows:
        return "- | - | - | -"
    held = np.array([r[1] for r in rows])
    ratio = np.array([[r[2 + i] / r[1] for i in range(len(TERMS))] for r in rows])
    cells = [f"{np.median(held):.4f} [{held.min():.4f}, {held.max():.4f}]"]
    for i in range(len(TERMS)):
        cells.append(f"{np.median(ratio[:, i]):.2f} [{ratio[:, i].min():.2f}, {ratio[:, i].max():.2f}]")
    if real_worst is not None:
        cells.append(f"{int(np.sum(ratio[:, 0] <= real_worst))} of {len(rows)}")
    return " | ".join(cells)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="simulated sessions per configuration (3 shots each)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--shots",
        type=int,
        default=3,
        help="shots per simulated session: 3 at the photographs' angles, or more spread over the half turn "
        "(each held out in turn)",
    )
    ap.add_argument(
        "--real",
        default=os.environ.get("HARP_REAL_DATA", str(Path(__file__).resolve().parents[2] / "shared/data/real-harp")),
    )
    args = ap.parse_args(argv)
    from realism import REAL, H, W

    from pipeline.measure import measure_image
    from station.imageio import read_grey

    t0 = time.perf_counter()
    cmd = " ".join(["benchmarks/own_shift.py", *(argv if argv is not None else sys.argv[1:])])
    print(
        f"# A held-out shot's own two-parameter term: real photographs and realistic sessions "
        f"({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; `{cmd}`)"
    )
    print()
    print(f"## Real photographs ({', '.join(REAL)}), {W}x{H}, {SPEC}")
    print()
    print("| held out | fit d / held-out d / with its own axis shift (ratio) / with its own k1, k2 (ratio), px |")
    print("|---|---|")
    real = splits(
        [[ln.points for ln in measure_image(read_grey(Path(args.real) / f"{n}.pgm"), t=30).lines] for n in REAL], W, H
    )
    for name, row in zip(REAL, real):
        print(f"| {name} | {_fmt_split(row)} |")
    first = [r for r in real[:2] if r is not None]
    real_worst = max(r[2] / r[1] for r in first) if first else None
    print()
    jobs = [(s, f, c, p, args.shots) for _, f, c, p in CONFIGS for s in range(args.seeds)]
    got: dict[tuple[int, float, float, float, int], list[tuple[float, ...] | None]] = {}
    with ProcessPoolExecutor(args.workers) as pool:
        for key, rows, _ in pool.map(_job, jobs):
            got[key] = rows
    angles = ", ".join(f"{a:g}" for a in shot_angles(args.shots))
    print(
        f"## Realistic sessions, seeds 0..{args.seeds - 1} per configuration ({args.shots} shots each, strings at "
        f"{angles} deg +- 3; each held out in turn)"
    )
    print()
    print(
        "| configuration | splits | held-out d px, median [range] | own axis shift / as is, median [range] "
        "| own k1, k2 / as is | axis-shift ratio at or below the real photographs' largest of splits 1-2 |"
    )
    print("|---|---|---|---|---|---|")
    for label, f, c, p in CONFIGS:
        by = [got[(s, f, c, p, args.shots)] for s in range(args.seeds)]
        if args.shots == 3:
            a = [r for rows in by for r in rows[:2] if r is not None]
            b = [r[2] for r in by if r[2] is not None]
            print(f"| {label} | 1-2 | {_summary(a, real_worst)} |")
            print(f"| {label} | 3 | {_summary(b, real_worst)} |")
        else:
            every = [r for rows in by for r in rows if r is not None]
            print(f"| {label} | all {args.shots} | {_summary(every, real_worst)} |")
            med = [float(np.median([r[2] / r[1] for r in rows if r is not None])) for rows in by]
            below = sum(m < OWN_SHIFT_RATIO for m in med)
            print(
                f"| {label} | median per session | {min(med):.2f} .. {max(med):.2f} | below the station's "
                f"{OWN_SHIFT_RATIO:g}: {below} of {len(med)} sessions | | |"
            )
    print()
    print(
        f"({time.perf_counter() - t0:.0f} s; real photographs' largest axis-shift ratio of splits 1-2: "
        f"{real_worst if real_worst is None else f'{real_worst:.2f}'})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
