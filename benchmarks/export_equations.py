"""The COLMAP, Kalibr, Basalt and Metashape exports in their consumers, stated against measured, per lens.

Run:  .venv/bin/python benchmarks/export_equations.py [--real DIR] [--lenses real,wide93,wide115,prism100]
Prints a Markdown table (committed in benchmarks/RESULTS-exports.md). For each lens and format: the model
the export chose, the conversion error it states (RMS / max modulo homography, each point's largest over
the export's own pixels, the harp model's ideal pixels and the 4-corner normalised frame:
``pipeline.exports.conversion_error.worst_frame_mod_h``), and what its consumer finds on a 64-point-wide grid of the
image, in the 4-corner normalised frame harp evaluate compares in (one of the three, so at most the
stated figure up to the grids' difference): pycolmap's ``cam_from_img`` for COLMAP (a text model read by
``Reconstruction.read_text``), and for the formats whose software is not installable here the
documented equations written out in the tests (``tests/pipeline/{kalibr,basalt,metashape}_equations.py``):
the unprojection inverted to convergence and, beside it, with the consumer's own fixed step count
(Kalibr: 5 Gauss-Newton / 20 fixed-point steps; Basalt: 3 Newton steps), and the export time.

Lenses: ``real`` the real-photo model (radial4 + tangential + prism fitted on IMG_6931 and IMG_6950,
holdout d on IMG_6964); ``wide93`` / ``wide115`` equisolid lenses of 93 and 115 degrees diagonal field
as harp radial models (``wide_angle`` set, as a calibration that chose a wide-angle model); ``prism100``
a 100 degree lens with decentering and thin prism, 320 x 240 (the COLMAP test's THIN_PRISM_FISHEYE lens).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.compare import fit_homography  # noqa: E402
from pipeline.exports.registry import write_export  # noqa: E402
from pipeline.exports.source import ExportSource  # noqa: E402
from pipeline.models import RadialModel  # noqa: E402
from tests.pipeline import basalt_equations as be  # noqa: E402
from tests.pipeline import kalibr_equations as ke  # noqa: E402
from tests.pipeline import metashape_equations as me  # noqa: E402
from tests.pipeline.export_support import real_model, wide_radial  # noqa: E402

REAL = Path(os.environ.get("HARP_REAL_DATA", REPO.parent / "shared" / "data" / "real-harp"))
FORMATS = ("colmap", "kalibr", "basalt", "metashape")


def lenses(names: list[str], real_dir: Path) -> dict[str, ExportSource]:
    out = {}
    for n in names:
        if n == "real":
            rm = real_model(1, str(real_dir))
            out[n] = ExportSource(rm.model, rm.width, rm.height, holdout_d=rm.holdout_d, edges=rm.edges)
        elif n == "prism100":  # decentering and thin prism on a 100 degree lens (the COLMAP test's lens)
            k = wide_radial(100, 320, 240).k
            m = RadialModel.for_image(
                320, 240, k=k, center=(161.0, 119.0), tangential=(1e-3, -5e-4), prism=(3e-3, 0, -2e-3, 0)
            )
            out[n] = ExportSource(m, 320, 240, wide_angle=True)
        elif n.startswith("wide"):
            fov = float(n[4:])
            out[n] = ExportSource(wide_radial(fov, 640, 480), 640, 480, wide_angle=True)
        else:
            raise SystemExit(f"unknown lens {n!r}")
    return out


def grid(w: int, h: int, nx: int = 64) -> np.ndarray:
    ny = int(round(nx * h / w))
    return np.stack(np.meshgrid(np.linspace(0, w - 1, nx), np.linspace(0, h - 1, ny)), axis=-1).reshape(-1, 2)


def normalised_truth(src: ExportSource, q: np.ndarray) -> np.ndarray:
    """The harp correction of ``q`` in its 4-corner normalised frame (harp evaluate's)."""
    w, h = src.width, src.height
    c = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float32)
    n4 = cv2.getPerspectiveTransform(src.model.undistort_points(c).astype(np.float32), c)
    u = np.c_[src.model.undistort_points(q), np.ones(len(q))] @ n4.T
    return u[:, :2] / u[:, 2:]


def mod_h(theirs: np.ndarray, ours: np.ndarray) -> tuple[float, float]:
    ok = np.all(np.isfinite(theirs), axis=1) & np.all(np.isfinite(ours), axis=1)
    _, res = fit_homography(theirs[ok], ours[ok])
    e = np.hypot(res[:, 0], res[:, 1])
    if not ok.all():
        e = np.append(e, np.full(int((~ok).sum()), np.inf))
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def consumer(fmt: str, data: bytes, q: np.ndarray, workdir: Path) -> tuple[str, np.ndarray, np.ndarray | None, str]:
    """(model, converged normalised points, the consumer's own fixed-step points or None, consumer)."""
    if fmt == "colmap":
        import pycolmap

        workdir.mkdir(parents=True, exist_ok=True)
        (workdir / "cameras.txt").write_bytes(data)
        (workdir / "images.txt").write_text("")
        (workdir / "points3D.txt").write_text("")
        rec = pycolmap.Reconstruction()
        rec.read_text(str(workdir))
        (cam,) = rec.cameras.values()
        return cam.model_name, np.asarray(cam.cam_from_img(q + 0.5), float), None, "pycolmap cam_from_img"
    if fmt == "kalibr":
        p, dm, k, _ = ke.kalibr_camera(data)
        conv = ke.unproject(p, dm, k, q, converged=True)
        return f"pinhole-{dm}", conv, ke.unproject(p, dm, k, q), "aslam_cv equations"
    if fmt == "basalt":
        p, _, _ = be.basalt_camera(data)
        conv = be.normalised(be.unproject(p, q, steps=50))
        return "kb4", conv, be.normalised(be.unproject(p, q)), "basalt-headers equations"
    proj, w, h, p = me.metashape_camera(data)
    return proj, me.unproject(proj, w, h, p, q + 0.5), None, "Metashape manual's equations"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--real", type=Path, default=REAL)
    ap.add_argument("--lenses", default="real,wide93,wide115,prism100")
    args = ap.parse_args()
    print(
        f"# COLMAP, Kalibr, Basalt, Metashape exports in their consumers — {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    print()
    print(
        "| lens | format → model | stated RMS / max mod H (px) | consumer, converged: RMS / max (px) | "
        "consumer's own step count: RMS / max (px) | consumer | export time (s) |"
    )
    print("|---|---|---|---|---|---|---|")
    work = Path(tempfile.mkdtemp(prefix="harp-equations-"))
    for name, src in lenses(args.lenses.split(","), args.real).items():
        q = grid(src.width, src.height)
        ours = normalised_truth(src, q)
        for fmt in FORMATS:
            t0 = time.perf_counter()
            try:
                ex = write_export(fmt, src)
            except ValueError as exc:
                print(f"| {name} | {fmt} | refused: {exc} | | | | |")
                continue
            t = time.perf_counter() - t0
            assert ex.error is not None
            model, conv, steps, who = consumer(fmt, ex.data, q, work / f"{name}-{fmt}")
            rc, mc = mod_h(conv, ours)
            own = "-" if steps is None else "{:.4f} / {:.4f}".format(*mod_h(steps, ours))
            print(
                f"| {name} | {fmt} → {model} | {ex.error.rms_mod_h_px:.4f} / {ex.error.max_mod_h_px:.4f} | "
                f"{rc:.4f} / {mc:.4f} | {own} | {who} | {t:.1f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
