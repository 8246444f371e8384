"""Whole simulated sessions, one turntable-axis place against two: the field error of the stored lens.

Usage::

    .venv/bin/python benchmarks/two_place_sessions.py [--seeds 0,1,2,3] [--size 1000x750] [--workers 2]

``benchmarks/axis_positions.py --stored`` emulates what a session stores from shots about two places (the same
choice and joint fit on rendered shots). This runs the sessions themselves: ``harp session run`` on the simulated
station of ``configs/demo.yaml`` with the realistic camera (``realism_seed``: bent and kinked strings, field blur,
back-light, vignetting, noise, Bayer; one frame per orientation), a unit of the demo lens drawn from each serial
(``simulation.lens_spread: 1``), the automatic model choice (``pipeline.model: auto``, plain folds; and, in
the last two columns, radial4+tangential+prism fixed) and the strings' bends and kinks separated (the default),
at one focus setting (0.5). Plans:

* **one place**: twelve turntable angles 0..165 by 15 about one axis;
* **two places**: six angles 0..150 by 30 at each of two linear-stage positions (``capture.shift_positions_mm``
  [0, 40] on a Zaber axis 3; the stage moves the axis by 40 mm x the scene's pitch over the harp's spacing,
  6 px/mm, i.e. 240 px along ``shift_direction_deg`` 26.57 degrees, the (2, 1) direction).

The table gives, per seed (realism seed and lens serial ``TWO-<seed>``), the model each session stored and its
field error against the exact lens of that unit at that focus (``pipeline.compare.compare_models``, modulo
homography, 20 px grid), and each session's wall time (a whole process, the machine's other load aside).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from drivers.sim.lens import lens_field, lens_for_focus, lens_unit, with_field  # noqa: E402
from pipeline.compare import compare_models  # noqa: E402
from pipeline.fit import correction_scale  # noqa: E402
from station.store import ProfileStore  # noqa: E402

FOCUS = 0.5
DIRECTION_DEG = math.degrees(math.atan2(1.0, 2.0))
ONE = {"orientations_deg": [float(a) for a in range(0, 180, 15)]}
TWO = {"orientations_deg": [float(a) for a in range(0, 180, 30)], "shift_positions_mm": [0.0, 40.0]}
FIXED = "radial4+tangential+prism"
PLANS: dict[str, tuple[dict[str, Any], str]] = {
    "one place": (ONE, "auto"),
    "two places": (TWO, "auto"),
    f"one place, {FIXED}": (ONE, FIXED),
    f"two places, {FIXED}": (TWO, FIXED),
}


def config(
    root: Path,
    seed: int,
    capture: dict[str, Any],
    pipeline: dict[str, Any],
    w: int,
    h: int,
    *,
    serial: str,
    lens_field_px: float = 0.0,
    defaults: bool = False,
) -> Path:
    """The configuration of one session: ``configs/demo.yaml`` with the realistic camera (``realism_seed`` =
    ``seed``), the unit of the demo lens of ``serial`` (spread 1) with a residual field of ``lens_field_px``, the
    ``capture`` and ``pipeline`` keys given, one frame per orientation, focus :data:`FOCUS`. ``defaults``: the
    demo's pipeline keys dropped first, so what is not given is the session's default."""
    d = yaml.safe_load((REPO / "configs" / "demo.yaml").read_text())
    d["station"]["camera"].update(width=w, height=h, realism_seed=seed)
    d["simulation"].update(lens_spread=1.0, lens_field_px=float(lens_field_px))
    d["lens"]["serial"] = serial
    d["focus"]["settings"] = [FOCUS]
    d["capture"].update(frames_per_orientation=1, **capture)
    if "shift_positions_mm" in capture:
        d["station"]["turntable"]["shift_axis"] = 3
        d["station"]["harp"]["shift_direction_deg"] = DIRECTION_DEG
        d["simulation"]["shift_direction_deg"] = DIRECTION_DEG
    if defaults:
        d["pipeline"] = {"t": d["pipeline"]["t"]}
    d["pipeline"].update(bootstrap=0, workers=1, **pipeline)
    d["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    p = root / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def run_session(
    seed: int,
    capture: dict[str, Any],
    pipeline: dict[str, Any],
    w: int,
    h: int,
    *,
    serial: str,
    lens_field_px: float = 0.0,
    defaults: bool = False,
    harp: Sequence[str] = (str(REPO / ".venv" / "bin" / "harp"),),
) -> dict[str, Any]:
    """``harp session run`` of :func:`config` in a temporary directory (``harp``: the command that is ``harp``,
    e.g. one that changes the simulator first, ``benchmarks/session_ablation.py``): its wall time and exit code,
    and, when it stored a profile, the profile's model, its field error against the exact lens of the unit at
    :data:`FOCUS` (``pipeline.compare.compare_models``, modulo homography, 20 px grid), whether the strings were
    separated, the places of the turntable axis found, the residual field the session's field stage chose (None:
    none) and by how many paired standard errors it was ahead of the model in the folds (``lead``, from the
    choice's reason), the names of the QA checks its focus setting failed (``failed``), and the stored
    correction's linear scale over the image against the exact lens's (``pipeline.fit.correction_scale``: a
    correction that shrinks the image straightens every edge, and the field error, modulo homography, does not
    see a uniform scale)."""
    with tempfile.TemporaryDirectory(prefix="sessions-") as tmp:
        root = Path(tmp)
        cfg = config(root, seed, capture, pipeline, w, h, serial=serial, lens_field_px=lens_field_px, defaults=defaults)
        t0 = time.perf_counter()
        done = subprocess.run(
            [*harp, "session", "run", str(cfg), "--quiet", "--no-report"],
            capture_output=True, text=True, cwd=root, start_new_session=True, check=False,
        )  # fmt: skip
        wall = time.perf_counter() - t0
        out: dict[str, Any] = {"seed": seed, "wall": wall, "code": done.returncode}
        if done.returncode not in (0, 1):  # 1: the session finished with a QA failure, its profile stored
            out["error"] = (done.stderr.strip().splitlines() or ["?"])[-1]
            return out
        with ProfileStore(root / "profiles.sqlite") as st:
            (p,) = st.profiles()
        (results,) = root.glob("sessions/*/results.json")
        checks = json.loads(results.read_text())["focus"][0].get("checks", [])
        out["failed"] = [c["name"] for c in checks if not c.get("passed", True)]
        truth = with_field(lens_for_focus(FOCUS, w, h, lens_unit(serial, 1.0)), lens_field(serial, lens_field_px), w, h)
        out["field"] = float(compare_models(p.model, truth, w, h, step=20).rms)
        out["scale"] = correction_scale(p.model, w, h) / correction_scale(truth, w, h)
        out["model"] = p.spec.label if p.spec is not None else "?"
        out["grid"] = p.spec.field if p.spec is not None else None
        out["separated"] = bool(p.details.get("strings", {}).get("separated"))
        out["places"] = len((p.details.get("harp_health", {}).get("axes") or {}).get("places", [])) or 1
        lead = re.search(r"ahead of \S+ by (-?[0-9.]+) paired standard errors", str(p.selection.get("reason", "")))
        out["lead"] = float(lead.group(1)) if lead and out["grid"] is not None else None
        return out


def cell(r: dict[str, Any]) -> str:
    """A table cell of :func:`run_session`'s result: the stored model, its field error and the wall time (and
    whether the strings were not separated, how many places were found, a field's lead in the folds, the QA
    checks the session failed), or why the session failed."""
    if "error" in r:
        return f"failed (exit {r['code']}): {r['error']}"
    sep = "" if r["separated"] else ", strings not separated"
    sep += f", {r['places']} places found" if r["places"] > 1 else ""
    sep += f", {r['lead']:+.1f} SE" if r.get("lead") is not None else ""
    sep += f", QA fails {'+'.join(r['failed'])}" if r.get("failed") else ""
    return f"{r['model']} {r['field']:.4f}{sep} ({r['wall']:.0f})"


def run(job: tuple[int, str, int, int]) -> dict[str, Any]:
    seed, plan, w, h = job
    capture, model = PLANS[plan]
    return {**run_session(seed, capture, {"model": model}, w, h, serial=f"TWO-{seed}"), "plan": plan}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3")
    ap.add_argument("--size", default="1000x750")
    ap.add_argument("--workers", type=int, default=2, help="sessions run at once")
    ap.add_argument("--plans", default=";".join(PLANS), help="the plans to run, by name, separated by ;")
    args = ap.parse_args(argv)
    plans = [p for p in PLANS if p in args.plans.split(";")]
    if not plans:
        ap.error(f"--plans: none of {args.plans!r} is a plan ({', '.join(PLANS)})")
    w, h = (int(v) for v in args.size.split("x"))
    seeds = [int(s) for s in args.seeds.split(",")]
    print(
        f"# Whole simulated sessions, one place against two: field error of the stored lens, {w}x{h}, focus {FOCUS} "
        f"({os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
        f"`benchmarks/two_place_sessions.py {' '.join(argv if argv is not None else sys.argv[1:])}`)"
    )
    print()
    jobs = [(s, plan, w, h) for s in seeds for plan in plans]
    with ThreadPoolExecutor(max(1, args.workers)) as pool:
        results = list(pool.map(run, jobs))
    print("| seed | " + " | ".join(f"{plan}: stored model, field px (wall s)" for plan in plans) + " |")
    print("|---:|" + "---|" * len(plans))
    by = {(r["seed"], r["plan"]): r for r in results}
    for s in seeds:
        print(f"| {s} | " + " | ".join(cell(by[(s, plan)]) for plan in plans) + " |", flush=True)
    print()
    fields = {plan: np.array([by[(s, plan)].get("field", np.nan) for s in seeds]) for plan in plans}
    for plan, f in fields.items():
        print(
            f"{plan}: at or below 0.005 px {int(np.sum(f <= 0.005))} of {len(f)}, median {np.nanmedian(f):.4f} px, "
            f"worst {np.nanmax(f):.4f} px"
        )
    print(f"(load average at end {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
