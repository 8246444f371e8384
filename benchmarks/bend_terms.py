"""How many Legendre terms a string's own bend needs: the lens and the harp check against the drawn strings.

Usage::

    .venv/bin/python benchmarks/bend_terms.py [--seeds 0,2,3,4,5,6,7] [--tops 4,5,6,8] [--cache DIR]

:func:`pipeline.harp_shape.fit_harp_shape` fits each string's deviation from its line as Legendre P2..P4 along
the string (:data:`pipeline.harp_shape.DEVIATION_TERMS`). A braided string's twist moves its centre line with a
period of 570-880 px in the harp (``pipeline.harp_scene``: ``offcentre_px``, ``twist_period_px``), one to two
periods along a string in a 1000x750 image, which three terms cannot follow. Per lens of
``benchmarks/lens_limits.py``'s realistic population without a field (twelve shots at 0..165 degrees, the edges
of ``benchmarks/field_leads.py``: ``--cache`` is the same cache), ``radial4+tangential+prism`` fitted with the
strings' bends and kinks separated and the deviation in P2..P\\ *n* for each ``n`` of ``--tops``:

* the field error of the lens against the exact lens (``compare_models``, modulo homography, 20 px grid);
* the harp check against the drawn strings: each fitted string matched to the drawn string at its offset from
  the axis, the drawn centre line (``StringShape.deviation``: sag, bows, kink, twist) less its straight line over
  the string's fitted span; the RMS difference (median and worst over the strings) and, over the strings whose
  drawn bend exceeds 0.01 px, the fitted bend (``bend_px``) over the drawn one (range, and how many within 20 %).
  A kink is fitted by its own term, not in the deviation, and a bend every string shares (sag) goes to the lens's
  thin-prism terms: strings with those compare low.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from field_leads import ANGLES, H, W, measured
from lens_limits import seed_lens

from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import fit_harp_shape

SPEC = FitSpec("radial", 4, True, True)


def against_drawn(fit, ses) -> tuple[list[float], list[float]]:  # type: ignore[no-untyped-def]
    """Per fitted string, the RMS difference from the drawn centre line, and fitted / drawn bend for strings whose
    drawn bend exceeds 0.01 px (the harp's numbering and direction matched once for the whole harp)."""
    drawn = ses.harp.strings
    pos = np.array([s.position_px for s in drawn])
    g = math.cos(math.radians(ses.mount.gravity_deg))
    bent = [s for s in fit.strings if s.coefficients]
    sign = min((1, -1), key=lambda sg: float(np.mean([np.min(np.abs(pos - sg * s.offset_px)) for s in bent])))
    per: dict[tuple[int, int], list[tuple[float, float, float]]] = {(a, b): [] for a in (1, -1) for b in (1, -1)}
    for s in bent:
        k = int(np.argmin(np.abs(pos - sign * s.offset_px)))
        u = np.linspace(s.span[0], s.span[1], 201)
        line = np.vstack([np.ones_like(u), u]).T
        for along in (1, -1):
            d = drawn[k].deviation(along * u * fit.frame.scale_px, g)
            d = d - line @ np.linalg.lstsq(line, d, rcond=None)[0]
            for side in (1, -1):
                diff = float(np.sqrt(np.mean((side * s.deviation(u) - d) ** 2)))
                per[(along, side)].append((diff, float(np.abs(d).max()), float(s.bend_px)))
    best = min(per, key=lambda key: sum(r[0] ** 2 for r in per[key]))
    rows = per[best]
    return [r[0] for r in rows], [r[2] / r[1] for r in rows if r[1] > 0.01]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,2,3,4,5,6,7")
    ap.add_argument("--tops", default="4,5,6,8", help="highest Legendre degree of each fit")
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args(argv)
    tops = [int(t) for t in args.tops.split(",")]
    print(
        f"# A string's bend in Legendre P2..Pn: lens field error and the harp check against the drawn strings, "
        f"{W}x{H}, twelve angles ({os.cpu_count()} CPUs; `benchmarks/bend_terms.py "
        f"{' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    print(
        "| seed | strings | "
        + " | ".join(f"P2..P{t}: lens px; bend diff median / worst px; fitted/drawn (within 20 %)" for t in tops)
        + " |"
    )
    print("|---:|---|" + "---|" * len(tops), flush=True)
    for seed in (int(s) for s in args.seeds.split(",")):
        lens, ses, _ = seed_lens(seed, W, H, False)
        lines = measured(seed, "without", args.cache)
        plain = fit_distortion(lines, W, H, **SPEC.fit_arguments())
        cells = []
        for top in tops:
            fit = fit_harp_shape(lines, list(ANGLES), W, H, SPEC, plain=plain, kinks=True, degrees=range(2, top + 1))
            if not fit:
                cells.append(f"failed: {fit.reason}")
                continue
            err = compare_models(fit.model, lens, W, H, step=20).rms
            diff, ratio = against_drawn(fit, ses)
            r = np.array(ratio)
            span = f"{r.min():.2f}-{r.max():.2f} ({int(np.sum(np.abs(r - 1) <= 0.2))}/{len(r)})" if len(r) else "-"
            cells.append(f"{err:.4f}; {np.median(diff):.4f} / {np.max(diff):.4f}; {span}")
        print(f"| {seed} | {ses.harp.material} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
