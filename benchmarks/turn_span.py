"""Does turning the harp through 360 degrees, not 180, separate the strings' shapes from the lens better?

Usage::

    .venv/bin/python benchmarks/turn_span.py [--seeds 38,26,34,16,0,27,37,39,1,2,3,4]

A shot at ``a + 180`` shows a string's lines in the same direction as at ``a`` but the string on the
other side of the turntable axis and its bend reversed in the image, while the lens's correction stays
on the sensor; so a capture plan of 180-degree pairs might tell the strings' bends from the lens where
half a turn cannot. For each seeded lens of ``benchmarks/lens_limits.py`` (its realistic session:
lens, harp with drawn string shapes, mount), the exact edges (no rendering: the strings' shapes are the
only error) are traced at each plan's angles and radial4+tangential+prism is fitted alone
(``pipeline.fit.fit_distortion``) and with the strings separated (``pipeline.harp_shape.fit_harp_shape``,
the angles given); the table gives the field error against the exact lens (``pipeline.compare``),
"alone / separated", px. Plans with the same number of shots are compared: six (30-degree steps
over half a turn, or 60-degree steps over a whole turn: three line directions twice) and twelve
(15-degree steps, or 30-degree steps over a whole turn: six directions twice).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from lens_limits import SPEC, seed_lens

from pipeline.compare import compare_models
from pipeline.fit import fit_distortion
from pipeline.harp_shape import fit_harp_shape
from pipeline.realism import shot_edges
from pipeline.render import visible_edges

W, H = 1000, 750
PLANS: dict[str, tuple[float, ...]] = {
    "6 shots, 0..150 by 30": tuple(range(0, 180, 30)),
    "6 shots, 0..300 by 60": tuple(range(0, 360, 60)),
    "12 shots, 0..165 by 15": tuple(range(0, 180, 15)),
    "12 shots, 0..330 by 30": tuple(range(0, 360, 30)),
}


def row(seed: int) -> str:
    lens, ses, start = seed_lens(seed, W, H)
    cells = [str(seed), str(start["lens"]), str(start["strings"])]
    for angles in PLANS.values():
        lines = []
        for a in angles:
            edges = shot_edges(lens, ses.harp, ses.mount.pose(float(a)), W, H)
            lines.append([c for _, c in visible_edges(edges, lens, W, H, step=2.0)])
        plain = fit_distortion(lines, W, H, **SPEC.fit_arguments())
        sep = fit_harp_shape(lines, [float(a) for a in angles], W, H, SPEC, plain=plain) if plain else None
        alone = compare_models(plain.model, lens, W, H, step=20).rms if plain else np.nan
        both = compare_models(sep.model, lens, W, H, step=20).rms if sep else np.nan
        cells.append(f"{alone:.4f} / {both:.4f}")
    return "| " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="38,26,34,16,0,27,37,39,1,2,3,4")
    args = ap.parse_args(argv)
    print(
        f"# Half a turn or a whole turn: field error, radial4+tangential+prism alone / strings separated, exact "
        f"edges, {W}x{H} ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/turn_span.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    print("| seed | lens | strings | " + " | ".join(PLANS) + " |")
    print("|---:|---|---|" + "---:|" * len(PLANS))
    t0 = time.perf_counter()
    for s in args.seeds.split(","):
        print(row(int(s)), flush=True)
    print()
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
