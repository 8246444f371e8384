"""Every export format on the real-photo model, through the commands a user runs.

Run:  .venv/bin/python benchmarks/export_formats.py [--real DIR] [--keep DIR]
Prints a table (commit it as benchmarks/RESULTS-exports.md). Steps, each a ``harp`` process:

1. ``harp calibrate IMG_6931 IMG_6950 --holdout IMG_6964 --model radial --out lens.yaml``
   (radial k1..k4 + tangential + thin prism, free centre: the recommended model);
2. for each format, ``harp export lens.yaml --format F -o FILE --json`` with the lens and camera
   given on the command line (illustrative: the photos do not say which camera took them; the
   values make the camera matrix nominal and give lensfun a crop factor) — the conversion error
   it states (RMS / max modulo homography over the whole image, borders included), the residual d
   it states on a noise-free full-field harp and on the two fitting shots (measured again from
   the model file's provenance), whether it warned, and the whole-process time;
3. ``harp evaluate FILE IMG_6964 --json``: the residual d that the file, read back by harp
   evaluate, leaves on the held-out photo, beside the model's own holdout d as ``harp calibrate``
   states it; the first row is ``harp evaluate lens.yaml IMG_6964`` (harp evaluate normalises by
   the 4 corrected corners, ``harp calibrate`` does not, hence the small difference).

The real consumers' reading of these files is in ``pytest tests/pipeline/test_export_consumers.py -s``;
the second table (:func:`benchmarks.export_consumers.table`) is every format x lens (this model, the demo
lens, a 93 and a 115 degree lens) in its consumer, over the image and out to 1.3x the corner radius.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REAL = Path(os.environ.get("HARP_REAL_DATA", REPO.parent / "shared" / "data" / "real-harp"))
LENS = [
    *("--lens-maker", "Canon", "--lens-model", "EF 50mm f/1.8 II", "--camera-maker", "Canon"),
    *("--camera-model", "EOS 40D", "--focal-mm", "50", "--pixel-pitch-um", "11.4", "--crop", "1.611"),
    *("--mount", "Canon EF"),
]
EXPORTS = [  # (label, format, extra options, file name)
    ("opencv (default: 12, rational + thin prism)", "opencv", [], "lens.yml"),
    ("opencv --coeffs 14 (+ tilt)", "opencv", ["--coeffs", "14"], "lens14.yml"),
    ("opencv --coeffs 8 (rational)", "opencv", ["--coeffs", "8"], "lens8.yml"),
    ("opencv --coeffs 5 (plumb_bob)", "opencv", ["--coeffs", "5"], "lens5.yml"),
    ("opencv-fisheye (Kannala-Brandt)", "opencv-fisheye", [], "fisheye.yml"),
    ("ros (default: rational_polynomial, 8)", "ros", [], "ros.yaml"),
    ("ros --coeffs 5 (plumb_bob)", "ros", ["--coeffs", "5"], "ros5.yaml"),
    ("ros-equidistant", "ros-equidistant", [], "ros-eq.yaml"),
    ("mrcal (default: LENSMODEL_OPENCV12)", "mrcal", [], "lens.cameramodel"),
    ("mrcal --coeffs 8", "mrcal", ["--coeffs", "8"], "lens8.cameramodel"),
    ("lensfun (ptlens, crop factor 1.611)", "lensfun", [], "lensfun.xml"),
    ("colmap (OPENCV, FULL_OPENCV, OPENCV_FISHEYE or THIN_PRISM_FISHEYE)", "colmap", [], "cameras.txt"),
    ("kalibr (pinhole-radtan or pinhole-equi)", "kalibr", [], "camchain.yaml"),
    ("basalt (kb4)", "basalt", [], "calib.json"),
    ("metashape (frame or fisheye)", "metashape", [], "calibration.xml"),
    ("maps (.npz, cv2.remap)", "maps", [], "maps.npz"),
    ("stmap (.exr)", "stmap", [], "stmap.exr"),
    ("auto", "auto", [], "auto.yml"),
]


def chosen_model(fmt: str, fig: dict) -> str:
    """`` → MODEL`` of a format that chooses among models (its first note: ``"colmap: FULL_OPENCV, ..."``)."""
    note = next((n for n in fig.get("notes", []) if n.startswith(f"{fmt}: ")), None)
    return "" if note is None else " → " + note[len(fmt) + 2 :].split()[0].rstrip(",:")


def harp(*args: str) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "station.cli", *args], capture_output=True, text=True, cwd=REPO)
    return out, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--real", type=Path, default=REAL, help="the real harp photographs")
    ap.add_argument("--keep", type=Path, default=None, help="write the files here (default: a temporary directory)")
    args = ap.parse_args()
    work = args.keep or Path(tempfile.mkdtemp(prefix="harp-exports-"))
    work.mkdir(parents=True, exist_ok=True)
    shots = [str(args.real / f"IMG_{n}.pgm") for n in (6931, 6950, 6964)]
    model = work / "lens.yaml"
    cal, t_cal = harp("calibrate", shots[0], shots[1], "--holdout", shots[2], "--model", "radial", "--out", str(model))
    if cal.returncode != 0:
        print(cal.stderr, file=sys.stderr)
        return 1
    print(f"# harp export on the real-photo model — {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    print()
    print(
        f"Model: `harp calibrate IMG_6931.pgm IMG_6950.pgm --holdout IMG_6964.pgm --model radial --out lens.yaml` "
        f"({t_cal:.0f} s)"
    )
    print()
    print(
        "| export | conversion RMS / max mod H (px) | residual d full-field harp (px) | residual d fitting shots "
        "(px; model's) | harp evaluate on IMG_6964: d (px; model's holdout d) | warning | time (s) |"
    )
    print("|---|---|---|---|---|---|---|")
    ev, _ = harp("evaluate", str(model), shots[2], "--json")
    own = json.loads(ev.stdout)["after"]["d"]
    print(f"| the harp model file itself (no conversion) | - | - | - | {own:.4f} | - | - |")
    model_holdout = None
    for label, fmt, extra, name in EXPORTS:
        path = work / name
        ex, t = harp("export", str(model), "--format", fmt, *extra, *LENS, "-o", str(path), "--json")
        if ex.returncode != 0:
            print(f"| {label} | failed: {ex.stderr.strip()} | | | | | |")
            continue
        fig = json.loads(ex.stdout)
        c = fig["conversion"]
        model_holdout = fig["holdout_d"]
        ev, _ = harp("evaluate", str(path), shots[2], "--json")
        held = json.loads(ev.stdout)["after"]["d"] if ev.returncode == 0 else None
        chosen = f" → {fig['format']}" if fmt == "auto" else chosen_model(fmt, fig)
        print(
            f"| {label}{chosen} | {c['rms_mod_h_px']:.4f} / {c['max_mod_h_px']:.4f} | {c['d_px']:.4f} | "
            f"{c['shots_d_px']:.4f} ({c['model_shots_d_px']:.4f}) | "
            f"{'-' if held is None else f'{held:.4f}'} ({model_holdout:.4f}) | "
            f"{'yes' if fig['warnings'] else 'no'} | {t:.1f} |"
        )
    print()
    print(f"files in {work}")
    print()
    print("## Every export x lens in its consumer, over the image and out to 1.3x the corner radius")
    print()
    print("(`benchmarks/export_consumers.py`: the consumers, their inverse and the figures are described there.)")
    print()
    sys.path.insert(0, str(REPO))
    from benchmarks.export_consumers import table  # defers cv2, pycolmap, lensfunpy

    table(model)
    return 0


if __name__ == "__main__":
    sys.exit(main())
