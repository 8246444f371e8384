"""The demo session end to end: accuracy against the simulator's true lens, and time.

Usage::

    .venv/bin/python benchmarks/station_demo.py [--config configs/demo.yaml]

Runs ``harp session run`` on the configuration (a copy whose profile store
and sessions live in a temporary directory), then compares every stored
profile with the simulated camera's true lens at that focus
(:func:`drivers.sim.lens.lens_for_focus`) modulo the best homography
(:func:`pipeline.compare.compare_models`, 10 px grid), and prints a
Markdown table: focus, holdout d, bootstrap field uncertainty, field error
against the truth (RMS, max), the exit code and QA verdict, plus wall and CPU time of the
whole session beside the duration ``harp session plan`` estimated for it
(process and its children), how long the session report at its end took
(from the manifest's timestamps), and the machine's load average, since
other work on the machine slows a session down.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=REPO / "configs" / "demo.yaml")
    args = ap.parse_args()

    from drivers.sim.lens import lens_for_focus
    from pipeline.compare import compare_models
    from station.store import ProfileStore

    with tempfile.TemporaryDirectory() as tmp:
        d = yaml.safe_load(args.config.read_text())
        d["store"] = {"path": str(Path(tmp) / "profiles.sqlite"), "sessions_dir": str(Path(tmp) / "s")}
        cfg = Path(tmp) / "config.yaml"
        cfg.write_text(yaml.safe_dump(d))
        load0 = os.getloadavg()[0]
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "station.cli", "session", "run", str(cfg), "--quiet", "--name", "demo"],
            cwd=REPO,
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - t0
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        load1 = os.getloadavg()[0]
        if proc.returncode not in (0, 1):  # 1: finished, QA verdict FAIL (reported below)
            print(proc.stderr, file=sys.stderr)
            return 1
        cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
        with ProfileStore(Path(tmp) / "profiles.sqlite") as st:
            profiles = st.profiles()
        w, h = profiles[0].width, profiles[0].height
        print(
            f"## `harp session run {args.config.relative_to(REPO)}` "
            f"({w}x{h}, {len(d['focus']['settings'])} focus x {len(d['capture']['orientations_deg'])} "
            f"orientations x {d['capture']['frames_per_orientation']} frames)\n"
        )
        print("| focus | holdout d (px) | field unc. RMS / max (px) | error vs true lens RMS (px) | max (px) |")
        print("|---:|---:|---:|---:|---:|")
        for p in profiles:
            c = compare_models(p.model, lens_for_focus(p.focus, w, h), w, h, step=10.0)
            fu = p.merit.field_uncertainty
            unc = "-" if fu is None else f"{fu.rms:.4f} / {fu.max:.4f}"
            print(f"| {p.focus:g} | {p.merit.holdout.d:.4f} | {unc} | {c.rms:.4f} | {c.max:.4f} |")
        recs = [json.loads(line) for line in (Path(tmp) / "s" / "demo" / "manifest.jsonl").open()]
        t_of = {r["kind"]: r["t"] for r in recs}
        report = f"{t_of['report'] - t_of['qa_session']:.1f} s" if "report" in t_of else "not written"
        from station.config import load_config
        from station.session.estimate import estimate_plan

        estimate = estimate_plan(load_config(cfg)).seconds
        verdict = json.loads((Path(tmp) / "s" / "demo" / "results.json").read_text())["verdict"]
        print(f"\nexit code {proc.returncode}, QA verdict {verdict} (results.json)")
        print(
            f"\nwall {wall:.1f} s (`harp session plan` estimated {estimate:.0f} s), CPU {cpu:.1f} s "
            f"(session and its worker processes), "
            f"of which the session report (Markdown + HTML, {len(list((Path(tmp) / 's' / 'demo' / 'report').glob('*.png')))} PNGs) "
            f"{report}; load average {load0:.1f} -> {load1:.1f} on {os.cpu_count()} cores"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
