"""The zoom demo end to end: ``harp session run configs/demo-zoom.yaml`` (3 focal lengths x 2 focus
settings), its time on this machine against the 60 s target, and its accuracy against the simulated
zoom lens.

Usage::

    .venv/bin/python benchmarks/zoom_demo.py [--runs 3]

Each run is the whole process (start-up, emulator, capture, fits, QA, reports, store) on a copy of the
configuration whose store and sessions live in a temporary directory; wall and CPU time (process and
children) and the load average are printed per run. Then every stored profile is compared with the
simulated lens at its setting (:func:`drivers.sim.lens.zoom_lens`, modulo homography,
:func:`pipeline.compare.compare_models`), and the correction interpolated at settings between them
(18 and 30 mm, focus 0.5) likewise; and the leave-one-out error per axis the session printed.
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
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()

    from drivers.sim.lens import zoom_lens
    from pipeline.compare import compare_models
    from pipeline.zoom import ZoomInterpolator
    from station.store import ProfileStore

    rows, last = [], None
    for run in range(args.runs):
        tmp = tempfile.mkdtemp(prefix="zoom-demo-")
        d = yaml.safe_load((REPO / "configs" / "demo-zoom.yaml").read_text())
        d["store"] = {"path": str(Path(tmp) / "profiles.sqlite"), "sessions_dir": str(Path(tmp) / "s")}
        cfg = Path(tmp) / "config.yaml"
        cfg.write_text(yaml.safe_dump(d))
        load0 = os.getloadavg()[0]
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "station.cli", "session", "run", str(cfg), "--quiet", "--json", "--name", "z"],
            cwd=REPO,
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - t0
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
        rows.append((run + 1, wall, cpu, proc.returncode, load0))
        if proc.returncode != 0:
            print(proc.stderr[-2000:], file=sys.stderr)
        last = (tmp, json.loads(proc.stdout) if proc.returncode == 0 else None)
    print("# Zoom demo: configs/demo-zoom.yaml (3 focal lengths x 2 focus settings, 640x480, 5 orientations)\n")
    print("| run | wall (s) | CPU, process + children (s) | exit | load average at start |")
    print("| ---: | ---: | ---: | ---: | ---: |")
    for r in rows:
        print(f"| {r[0]} | {r[1]:.1f} | {r[2]:.1f} | {r[3]} | {r[4]:.2f} |")
    walls = sorted(r[1] for r in rows)
    print(f"\nwall: median {walls[len(walls) // 2]:.1f} s, max {walls[-1]:.1f} s (target <= 60 s on 2 cores)\n")
    assert last is not None and last[1] is not None
    tmp, results = last
    with ProfileStore(Path(tmp) / "profiles.sqlite", create=False) as st:
        ((lens_id, *_),) = st.lenses()
        current = st.latest_by_focus(lens_id)
    w, h = current[0].width, current[0].height
    print("| focal (mm) | focus | holdout d (px) | against the lens, RMS / max (px) |")
    print("| ---: | ---: | ---: | --- |")
    for p in current:
        c = compare_models(p.model, zoom_lens(p.focal, p.focus, w, h), w, h, step=10.0)
        print(f"| {p.focal:g} | {p.focus:g} | {p.merit.holdout_d:.4f} | {c.rms:.4f} / {c.max:.4f} |")
    zi = ZoomInterpolator({(p.focal, p.focus): p.model for p in current}, w, h)
    print("\n| interpolated at focal (mm) | focus | against the lens, RMS / max (px) |")
    print("| ---: | ---: | --- |")
    for z, f in ((18.0, 0.5), (30.0, 0.5), (24.0, 0.5)):
        c = compare_models(zi.at(z, f), zoom_lens(z, f, w, h), w, h, step=10.0)
        print(f"| {z:g} | {f:g} | {c.rms:.4f} / {c.max:.4f} |")
    print("\nleave-one-out, as the session printed it:")
    for e in results["leave_one_out"]:
        print(
            f"- along the {e['axis']}, focal {e['focal']:g} mm, focus {e['focus']:g} left out: "
            f"RMS {e['rms_px']:.4f} px, max {e['max_px']:.4f} px"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
