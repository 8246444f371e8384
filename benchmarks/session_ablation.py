"""Whole simulated sessions with one effect of the realistic simulator taken out: what limits a session's lens.

Usage::

    .venv/bin/python benchmarks/session_ablation.py [--seed 4] [--lens without] [--field auto,none]
        [--variants "full;straight;no offcentre"] [--workers 2]

``benchmarks/field_sessions.py`` runs whole ``harp session run`` sessions of the realistic camera (its seed's
harp, mount and effects, :func:`pipeline.realism.realistic_session`) and a unit of the demo lens, with and
without a residual field. This runs the same session (one place, twelve angles, the session's defaults, the
same configuration: :func:`benchmarks.two_place_sessions.config`) with one part of the realistic simulator
removed, to find which part a session's stored lens error, or a field its field stage takes, comes from. Each
session is a whole process: this script, run as ``session_ablation.py --as-harp VARIANT ARGS...``, replaces the
realistic session the simulated camera draws (``pipeline.realism.realistic_session``) by the variant and then is
``harp ARGS...``.

Variants (:data:`VARIANTS`): ``full`` (nothing removed); ``straight`` (every string's shape: sag, bows, kink,
twist's ovality and off-centre section, braid pick); one string term at zero (``no sag``, ``no bow``, ``no
kinks``, ``no ovality``, ``no offcentre``, ``no pick``); ``uniform blur``, ``no Bayer``, ``no noise``, ``flat
light`` (:func:`benchmarks.lens_limits.variant`). ``--lens with`` adds the seed's residual field
(:func:`benchmarks.field_sessions.lens_field_px`).

The table gives each session's stored model, its field error against the exact lens, a field's lead in the
field stage's folds, the QA checks the session failed and its wall time
(:func:`benchmarks.two_place_sessions.cell`).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.field_sessions import lens_field_px  # noqa: E402
from benchmarks.lens_limits import STRAIGHT, reshaped, variant  # noqa: E402
from benchmarks.two_place_sessions import ONE, cell, run_session  # noqa: E402

STRING_TERMS = {
    "no sag": {"sag_px": 0.0},
    "no bow": {"bow_px": (0.0, 0.0, 0.0)},
    "no kinks": {"kink_px": 0.0},
    "no ovality": {"ovality_px": 0.0},
    "no offcentre": {"offcentre_px": 0.0},
    "no pick": {"pick_px": 0.0},
    "straight": STRAIGHT,
}
OTHER = ("uniform blur", "no Bayer", "no noise", "flat light")
VARIANTS = ("full", *STRING_TERMS, *OTHER)


def ablated(session: Any, name: str) -> Any:
    """``session`` (a :class:`pipeline.realism.Session`) with variant ``name`` removed."""
    if name == "full":
        return session
    if name in STRING_TERMS:
        return dataclasses.replace(session, harp=reshaped(session.harp, STRING_TERMS[name]))
    harp, effects = variant(session, name)
    return dataclasses.replace(session, harp=harp, effects=effects)


def as_harp(name: str, args: list[str]) -> int:
    """``harp args`` with the simulated camera's realistic session ablated by ``name``."""
    import pipeline.realism as realism

    drawn = realism.realistic_session

    def realistic_session(*a: Any, **k: Any) -> Any:
        return ablated(drawn(*a, **k), name)

    realism.realistic_session = realistic_session  # the camera imports it when it draws its session
    from station.cli import main as harp

    return int(harp(args) or 0)


def run(job: tuple[int, str, str, str]) -> dict[str, Any]:
    seed, lens, name, field = job
    rms = lens_field_px(seed) if lens == "with" else 0.0
    out = run_session(
        seed, ONE, {"field": field}, 1000, 750, serial=f"FIELD-{seed}", lens_field_px=rms, defaults=True,
        harp=(sys.executable, str(Path(__file__).resolve()), "--as-harp", name),
    )  # fmt: skip
    return {**out, "variant": name, "mode": field}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--as-harp"]:
        return as_harp(argv[1], argv[2:])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--lens", choices=("with", "without"), default="without", help="with or without a field")
    ap.add_argument("--field", default="auto,none", help="pipeline.field values, comma separated")
    ap.add_argument("--variants", default="full;straight", help=f"separated by ; (of: {'; '.join(VARIANTS)})")
    ap.add_argument("--workers", type=int, default=2, help="sessions run at once")
    args = ap.parse_args(argv)
    names = args.variants.split(";")
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        ap.error(f"--variants: unknown {', '.join(unknown)} (known: {'; '.join(VARIANTS)})")
    fields = args.field.split(",")
    print(
        f"# Whole simulated sessions with one effect removed: seed {args.seed}, lens {args.lens} a field, 1000x750, "
        f"twelve angles about one place ({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/session_ablation.py {' '.join(argv)}`)"
    )
    print()
    print("| removed | " + " | ".join(f"field {f}: stored model, field px (wall s)" for f in fields) + " |")
    print("|---|" + "---|" * len(fields), flush=True)
    jobs = [(args.seed, args.lens, n, f) for n in names for f in fields]
    with ThreadPoolExecutor(max(1, args.workers)) as pool:
        done = list(pool.map(run, jobs))
    for i, n in enumerate(names):
        print(f"| {n} | " + " | ".join(cell(r) for r in done[i * len(fields) : (i + 1) * len(fields)]) + " |")
    print(f"\n(load average at end {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
