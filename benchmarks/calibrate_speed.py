"""Wall time of ``harp calibrate`` (default automatic model choice) as a whole process.

Usage::

    .venv/bin/python benchmarks/calibrate_speed.py [--repeat 3]

``harp calibrate SHOTS... --out MODEL --json`` started with ``subprocess`` (interpreter
start-up, imports, reading and measuring every shot once, the cross-validated choice of the
model over the default candidates, the final fit, writing the model file), median of
``--repeat`` runs after one warm-up run, with the CPU time (user + system) of the process and
its worker processes (``resource.getrusage`` of the children), on

* the three shared real photographs (1761x1174 PGM);
* six synthetic shots of 1761x1174 (PGM) at orientations 0, 30, ... 150 degrees through a
  decentred barrel lens with decentering terms, 3 px strings 60 px apart, noise 1.5.

It also prints the model chosen, its cross-validated d and its fit d (8 significant digits), to
show that the figures stay those of the cross-validation from scratch. Targets (issue 8): <= 3 s on the three photos,
<= 6 s on six shots of 1761x1174, on the 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.models.radial import RadialModel  # noqa: E402
from pipeline.render import HarpScene, render_harp  # noqa: E402

REAL = ROOT.parent / "shared" / "data" / "real-harp"
HARP = [sys.executable, "-m", "station.cli"]


def run(paths: list[Path], out: Path, repeat: int) -> tuple[float, float, dict]:
    walls, cpus, rep = [], [], {}
    for _ in range(repeat + 1):  # the first run warms the file cache, not counted
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(
            [*HARP, "calibrate", *map(str, paths), "--out", str(out), "--json"],
            check=True,
            capture_output=True,
            text=True,
            cwd=ROOT,
        )
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
        rep = json.loads(done.stdout)
    return float(np.median(walls[1:])), float(np.median(cpus[1:])), rep


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="harp-cal-bench-"))
    cases = []
    real = sorted(REAL.glob("*.pgm"))
    if real:
        cases.append(("3 real photos 1761x1174", real))
    w, h = 1761, 1174
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.02, 0.0, 0.003), center=(900.0, 570.0), tangential=(5e-4, -3e-4))
    six = []
    for i, ang in enumerate(range(0, 180, 30)):
        r = render_harp(w, h, HarpScene(angle_deg=float(ang), spacing_px=60.0, phase_px=9.0 * i), lens=lens, seed=i)
        p = tmp / f"shot{ang:03d}.pgm"
        cv2.imwrite(str(p), r.image)
        six.append(p)
    cases.append(("6 synthetic shots 1761x1174", six))
    print(
        f"harp calibrate speed (default --model auto), {os.cpu_count()} cores (load average "
        f"{os.getloadavg()[0]:.1f} when started), median of {args.repeat} runs"
    )
    print()
    print("| shots | `harp calibrate` whole process wall s | CPU s (with workers) | choice | CV d px | fit d px |")
    print("|---|---|---|---|---|---|")
    try:
        for name, paths in cases:
            wall, cpu, rep = run(paths, tmp / "lens.yaml", args.repeat)
            ch = rep["choice"]
            cv = next(r["cv_d"] for r in ch["table"] if r["label"] == ch["label"])
            print(f"| {name} | {wall:.2f} | {cpu:.2f} | {ch['label']} | {cv:.8g} | {rep['fit']['d']:.8g} |", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print()
    print(f"load average at end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
