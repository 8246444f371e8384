"""Time of the residual-field stage (:func:`pipeline.select.select_field`) before and after a change, and whether
its choice and every candidate's CV d stay the same.

Each seed is one realistic six-shot lens of ``benchmarks/lens_limits.py`` with its non-parametric field
(``realistic_measured(seed, lens_field=True)``: strings separated with the turntable angles, kinks modelled,
base ``radial6+tangential+prism``), the stage run as a session runs it (``pipeline.field: auto``). "before" runs
the code of another checkout (``--before``, default ``/work/main``) in a subprocess, "after" this checkout's (or
``--after``'s); the
two run one after the other on each seed, single-threaded BLAS. Columns: the stage's wall time each way, whether
the choice is the same, the largest relative difference of a candidate's CV d, and the largest difference of the
chosen candidate's fit on all shots (corrected points over a 41 x 31 grid of the image, px).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/field_speed.py --seeds 10,11,12,2,4 [--cache DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def one(seed: int, cache: Path) -> dict[str, object]:
    """Run the stage on seed ``seed`` with whatever ``pipeline`` is importable; its figures as a dict."""
    # pipeline first, from PYTHONPATH: the benchmark modules put this checkout's root first on sys.path
    from pipeline.fitspec import parse
    from pipeline.resample import DEFAULT_T
    from pipeline.select import select_field

    sys.path.insert(0, str(HERE))
    from choice_realistic import H, W
    from lens_limits import FITTED, realistic_measured

    fitted = realistic_measured(seed, W, H, cache, True)[0]
    base = parse("radial6+tangential+prism")
    t0 = time.perf_counter()
    sel = select_field(fitted, W, H, base, turntable_deg=FITTED, kink_t=DEFAULT_T)
    seconds = time.perf_counter() - t0
    gx, gy = np.meshgrid(np.linspace(0, W - 1, 41), np.linspace(0, H - 1, 31))
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    chosen = next((r for r in sel.table if r.candidate == sel.choice), None)
    lens = None
    if chosen is not None and chosen.full_fit is not None:
        lens = chosen.full_fit.model.undistort_points(grid).tolist()
    return {
        "seconds": seconds,
        "choice": sel.choice.label,
        "cv_d": {r.candidate.label: r.cv_d for r in sel.table},
        "lens": lens,
        "pipeline": str(Path(sys.modules["pipeline"].__file__ or "").parent),
    }


def run(seed: int, tree: Path, cache: Path) -> dict[str, object]:
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, __file__, "--one", str(seed), "--cache", str(cache)],
        env=env, capture_output=True, text=True, check=True, cwd=str(tree),
    )  # fmt: skip
    result: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(str(result["pipeline"])).resolve() == (tree / "pipeline").resolve(), (result["pipeline"], tree)
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="10,11,12,2,4")
    ap.add_argument("--before", default="/work/main", help="the checkout whose code is 'before'")
    ap.add_argument("--after", default=str(ROOT), help="the checkout whose code is 'after' (default: this one)")
    ap.add_argument("--cache", default="/tmp/field-speed-cache", help="renders kept here (lens_limits)")
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    cache = Path(args.cache)
    if args.one is not None:
        print(json.dumps(one(args.one, cache)))
        return
    print(f"# load average at start {os.getloadavg()[0]:.1f}; before = {args.before}, after = {args.after}")
    print(
        "| seed | before s | after s | speed-up | choice | same choice | max CV d rel. diff | chosen lens max diff px |"
    )
    print("|---:|---:|---:|---:|---|---|---:|---:|")
    totals = [0.0, 0.0]
    for seed in (int(s) for s in args.seeds.split(",")):
        b = run(seed, Path(args.before), cache)
        a = run(seed, Path(args.after), cache)
        cb, ca = b["cv_d"], a["cv_d"]
        assert isinstance(cb, dict) and isinstance(ca, dict)
        rel = max(
            (abs(ca[k] - cb[k]) / abs(cb[k]) if np.isfinite(cb[k]) else float(np.isfinite(ca.get(k, np.nan))))
            for k in cb
        )
        lens_b, lens_a = b["lens"], a["lens"]
        diff = float(np.max(np.abs(np.subtract(lens_a, lens_b)))) if lens_b and lens_a else float("nan")
        sb, sa = float(b["seconds"]), float(a["seconds"])  # type: ignore[arg-type]
        totals[0] += sb
        totals[1] += sa
        same = "yes" if a["choice"] == b["choice"] and set(ca) == set(cb) else "NO"
        print(f"| {seed} | {sb:.1f} | {sa:.1f} | {sb / sa:.2f} | {a['choice']} | {same} | {rel:.1e} | {diff:.1e} |")
        sys.stdout.flush()
    print(f"\ntotal {totals[0]:.1f} s -> {totals[1]:.1f} s ({totals[0] / totals[1]:.2f}x)")
    print(f"# load average at end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
