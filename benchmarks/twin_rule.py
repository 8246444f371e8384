"""Does the twin rule change what a session chooses? The plain two-tier choice with and without it.

Usage::

    .venv/bin/python benchmarks/twin_rule.py [--seeds 0:60] [--workers 2] [--cache DIR]

On ``benchmarks/lens_limits.py``'s realistic population (1000x750, six shots 30 degrees apart, measured as
``harp measure`` does: :func:`lens_limits.realistic_measured`), the choice of :func:`pipeline.select.select_model`
on the six shots (plain folds: what a session with ``pipeline.model: auto`` and ``pipeline.choice_folds: plain``
chooses) with the rule (``pipeline.select._with_free_twins``: a free-centre candidate whose centre-prior twin
generalises to an unseen orientation goes to tier 2 with it) and without it (tier 1's candidates alone). Where
the two choices are the same, the population's figures of ``benchmarks/choice_realistic.py`` stand.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

W, H = 1000, 750


def one(seed: int, cache: Path | None) -> tuple[int, str, str, float]:
    import lens_limits

    import pipeline.select as select

    t0 = time.perf_counter()
    fitted = lens_limits.realistic_measured(seed, W, H, cache)[0]
    with_rule = select.select_model(fitted, W, H)
    rule = select._with_free_twins
    select._with_free_twins = lambda general, rows: list(general)  # tier 1's candidates alone
    try:
        without = select.select_model(fitted, W, H)
    finally:
        select._with_free_twins = rule
    return seed, without.choice.label, with_rule.choice.label, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0:60", help="FIRST:END")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None, help="keep the measured renders here")
    args = ap.parse_args(argv)
    first, end = (int(v) for v in args.seeds.split(":"))
    t0 = time.perf_counter()
    load = os.getloadavg()[0]
    print(
        f"# The plain two-tier choice with and without the twin rule, realistic population, 1000x750, six shots "
        f"(seeds {first}..{end - 1}; {os.cpu_count()} CPUs, load average {load:.1f} at start; "
        f"`benchmarks/twin_rule.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    print("| seed | without the rule | with it | same |")
    print("|---:|---|---|---|")
    same = 0
    with ProcessPoolExecutor(args.workers) as ex:
        for seed, a, b, _s in ex.map(one, range(first, end), [args.cache] * (end - first)):
            same += a == b
            print(f"| {seed} | {a} | {b} | {'yes' if a == b else '**no**'} |", flush=True)
    print()
    print(f"same choice: {same} of {end - first} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
