"""Which quadratic distortion terms do string orientations determine, and what do the real photographs hold?

Usage::

    .venv/bin/python benchmarks/quadratic_sector.py [--real DIR]

A quadratic distortion field shows on the strings of one orientation only as the bow every one of them
shares (its second derivative along a line does not depend on where the line is), one number per
orientation. Modulo a homography (which keeps every line straight) the quadratic fields are
four-dimensional: the thin-prism terms ``s |z|^2`` (two) and the three-fold term ``t conj(z)^2`` (two;
:class:`pipeline.models.radial.RadialModel`'s ``trefoil``). So two orientations determine the thin-prism
terms of a lens that has nothing else, and four determine both.

Three parts:

1. **Exact lenses** (written here in complex form, independent of the model code): a decentred lens with
   thin-prism terms, and the same with a three-fold term; fitted on 2, 3, 4 and 6 orientations, with and
   without the trefoil term; the largest d of the fitted shots and of four unseen orientations
   (noise-free strings).
2. **The real photographs, all three fitted**: ``radial4+tangential+prism`` and the same with the trefoil
   term, each shot's d and the part of it every string shares (:func:`pipeline.shared_bend.shared_bend`),
   and a probe: on top of the first correction, a least-squares fit of one two-parameter term at a time
   (the trefoil, and three cubic terms no model here has) to the corrected points, to see whether the
   trefoil is special or any two parameters would do as well.
3. **The real photographs, two fitted**: each split, the held-out shot's d with and without the trefoil
   term (two orientations cannot determine it: this is why the choice sets it aside there).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "pipeline"))

from complex_lens import ComplexLens, worst_d
from harp_points import harp_point_sets

from pipeline.fit import fit_distortion
from pipeline.shared_bend import shared_bend
from pipeline.straightness import straightness

REAL = Path(os.environ.get("HARP_REAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "real-harp"))
W, H = 1200, 800


def exact_part() -> None:
    print("## 1. Exact lenses, 1200x800 (noise 0.002 px on fitted points; unseen strings at 20, 70, 110, 160 deg)\n")
    print("| lens | fitted orientations (deg) | spec | largest fitted d px | largest unseen d px |")
    print("|---|---|---|---:|---:|")
    centre = (W / 2 + 40, H / 2 - 25)
    lenses = {
        "decentred, thin prism": ComplexLens(-0.06, 2e-4 - 1e-4j, 0j, centre),
        "same + three-fold 0.22 px": ComplexLens(-0.06, 2e-4 - 1e-4j, 2e-4 + 1e-4j, centre),
    }
    for name, lens in lenses.items():
        unseen = harp_point_sets(lens, W, H, (20, 70, 110, 160), noise=0.0, seed=9)
        for angles in ((90, 45), (90, 45, 0), (0, 45, 90, 135), (0, 30, 60, 90, 120, 150)):
            shots = harp_point_sets(lens, W, H, angles, noise=0.002, seed=1)
            for tref in (False, True):
                r = fit_distortion(shots, W, H, "radial", 4, True, True, trefoil=tref)
                spec = "radial4+tangential+prism" + ("+trefoil" if tref else "")
                fitted = worst_d(r.model, shots) if r else float("nan")
                seen = worst_d(r.model, unseen) if r else float("nan")
                print(f"| {name} | {', '.join(map(str, angles))} | {spec} | {fitted:.4f} | {seen:.4f} |")
    print()


def _basis(q: np.ndarray, centre: np.ndarray, scale: float) -> dict[str, tuple[np.ndarray, ...]]:
    x, y = (q[:, 0] - centre[0]) / scale, (q[:, 1] - centre[1]) / scale
    return {
        "trefoil conj(z)^2": ((x * x - y * y, -2 * x * y), (2 * x * y, x * x - y * y)),
        "conj(z)^3": ((x**3 - 3 * x * y * y, -(3 * x * x * y - y**3)), (3 * x * x * y - y**3, x**3 - 3 * x * y * y)),
        "(x^3, -y^3), (xy^2, -x^2y)": ((x**3, -(y**3)), (x * y * y, -x * x * y)),
        "|z|^2 conj(z)": ((x * (x * x + y * y), -y * (x * x + y * y)), (y * (x * x + y * y), x * (x * x + y * y))),
    }


def probe(sets: list[np.ndarray], name: str, centre: np.ndarray, scale: float) -> list[np.ndarray]:
    """Corrected edges with one two-parameter term fitted on top by linear least squares (each edge's
    line free: offset and turn), the term in px at the half diagonal."""
    blocks_a, blocks_y = [], []
    ne = len(sets)
    for e, q in enumerate(sets):
        m = q.mean(axis=0)
        d = np.linalg.svd(q - m)[2][0]
        n = np.array([-d[1], d[0]])
        cols = _basis(q, centre, scale)[name]
        a = np.zeros((len(q), 2 + 2 * ne))
        for k, (bx, by) in enumerate(cols):
            a[:, k] = scale * (n[0] * bx + n[1] * by)
        a[:, 2 + 2 * e] = -1.0
        a[:, 3 + 2 * e] = (q - m) @ d
        blocks_a.append(a)
        blocks_y.append(-((q - m) @ n))
    sol = np.linalg.lstsq(np.vstack(blocks_a), np.concatenate(blocks_y), rcond=None)[0][:2]
    out = []
    for q in sets:
        cols = _basis(q, centre, scale)[name]
        out.append(q + scale * sum(c * np.c_[bx, by] for c, (bx, by) in zip(sol, cols, strict=True)))
    return out


def real_parts(directory: Path) -> None:
    import cv2

    from pipeline.measure import measure_image

    names = ["IMG_6931.pgm", "IMG_6950.pgm", "IMG_6964.pgm"]
    edges = {}
    for n in names:
        img = cv2.imread(str(directory / n), cv2.IMREAD_UNCHANGED)
        if img is None:
            print(f"(real photographs not found in {directory}: parts 2 and 3 skipped)")
            return
        edges[n] = [ln.points for ln in measure_image(img).lines]
    h, w = img.shape
    print(f"## 2. Real photographs ({', '.join(names)}), {w}x{h}, all three fitted\n")
    print("| spec | shot | d px | shared by every string px | each edge's own px |")
    print("|---|---|---:|---:|---:|")
    fits = {}
    for tref in (False, True):
        r = fit_distortion([edges[n] for n in names], w, h, "radial", 4, True, True, trefoil=tref)
        fits[tref] = r
        for n in names:
            c = [r.model.undistort_points(p) for p in edges[n]]
            sb = shared_bend(c)
            spec = "radial4+tangential+prism" + ("+trefoil" if tref else "")
            print(
                f"| {spec} | {n} | {straightness(c).d:.4f} | {sb.shared_px if sb else float('nan'):.4f} | "
                f"{sb.own_px if sb else float('nan'):.4f} |"
            )
    m = fits[True].model
    t = complex(*m.trefoil)
    print(
        f"\nthe fitted three-fold term: |t| x half diagonal = {abs(t) * m.scale:.3f} px at the corners "
        f"(t1, t2 = {m.trefoil[0]:.3g}, {m.trefoil[1]:.3g}); three orientations leave one combination of the "
        "thin-prism and three-fold terms free, so this is one of a line of fits as good, not a measurement "
        "of the term\n"
    )
    base = fits[False].model
    centre, scale = np.asarray(base.center), base.scale
    print("Probe: one two-parameter term fitted on top of radial4+tangential+prism (linear least squares):\n")
    print("| term added | " + " | ".join(f"{n} d px" for n in names) + " |")
    print("|---|" + "---:|" * len(names))
    corrected = {n: [base.undistort_points(p) for p in edges[n]] for n in names}
    print("| none | " + " | ".join(f"{straightness(corrected[n]).d:.4f}" for n in names) + " |")
    for name in _basis(np.zeros((1, 2)), centre, scale):
        allsets = [q for n in names for q in corrected[n]]
        moved = probe(allsets, name, centre, scale)
        out, i = [], 0
        for n in names:
            k = len(corrected[n])
            out.append(straightness(moved[i : i + k]).d)
            i += k
        print(f"| {name} | " + " | ".join(f"{v:.4f}" for v in out) + " |")
    print("\n## 3. Real photographs, two fitted, the third held out\n")
    print("| held out | radial4+tangential+prism held-out d px | + trefoil held-out d px |")
    print("|---|---:|---:|")
    for held in names:
        train = [edges[n] for n in names if n != held]
        row = []
        for tref in (False, True):
            r = fit_distortion(train, w, h, "radial", 4, True, True, trefoil=tref)
            row.append(straightness([r.model.undistort_points(p) for p in edges[held]]).d if r else float("nan"))
        print(f"| {held} | {row[0]:.4f} | {row[1]:.4f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--real", type=Path, default=REAL, help="directory of the real photographs")
    args = ap.parse_args()
    t0 = time.time()
    print(
        f"# Quadratic distortion terms and string orientations (2 CPUs, load average {os.getloadavg()[0]:.1f} "
        f"at start; `benchmarks/quadratic_sector.py`)\n"
    )
    exact_part()
    real_parts(args.real)
    print(f"\n({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
