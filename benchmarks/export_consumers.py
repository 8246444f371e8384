"""Every export format x lens, in its consumer: the stated conversion error beside the consumer's own figure,
over the image and out to 1.3x the corner radius (issue 20's target: no pole, no fold).

Run:  .venv/bin/python benchmarks/export_consumers.py [--model lens.yaml]   (also the second table of
``benchmarks/export_formats.py``, which passes it the real-photo model it calibrates). Lenses:

- **real**: the real-photo model (``harp calibrate IMG_6931 IMG_6950 --holdout IMG_6964 --model radial``;
  with ``--model``, else fitted here on the same photos), the camera given as in ``export_formats.py``;
- **demo**: the demo configuration's simulated lens at focus 0.5 (1280x960, 12 mm at 3.75 um);
- **wide93**, **wide115**: exact equisolid lenses (93 and 115 degree diagonal field, 640x480, decentred;
  :class:`tests.pipeline.export_support.EquisolidLens`, exact both ways beyond the image too).

For each format (``pipeline.exports.registry.write_export``, in process) the file is read by its consumer
and its *forward map* (an ideal pixel of the consumer's own frame -> the photo's pixel it reads) is used
alone: ``cv2.projectPoints`` / ``cv2.fisheye.projectPoints`` with the matrices ``cv2.FileStorage`` (OpenCV),
PyYAML (ROS camera_info, Kalibr), the ``.cameramodel`` dict (mrcal's OPENCV12/8) read; pycolmap's
``img_from_cam`` (COLMAP); lensfunpy's ``apply_geometry_distortion`` (lensfun); RawTherapee's equations
(LCP, ``tests/pipeline/lcp_equations.py``); Kalibr's documented projection
(``tests/pipeline/kalibr_equations.py``). The map is inverted here by a damped Newton iteration on it (not
the export code's inverse). Figures:

- **image**: the photo's pixels on a 48-point grid, their ideal points by the consumer's map inverted, against
  the harp model's correction, modulo the best homography (RMS / max px), as the export states its error;
- **to 1.3x**: rays from the consumer's centre every 15 degrees out to 1.3x the corner radius (the ideal
  radius of the farthest corner): whether the map stays finite and moves outwards along every ray (``ok``,
  else ``POLE/FOLD`` at the first radius it fails), and between 1.0x and 1.3x the distance (RMS / max px)
  between the consumer's ideal points (by the image's homography) and the harp model's own extension there
  (exact for the demo and wide lenses, the real model's polynomial extrapolated).
"""

from __future__ import annotations

import argparse
import ast
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from drivers.sim.lens import lens_for_focus  # noqa: E402
from pipeline.compare import fit_homography  # noqa: E402
from pipeline.exports.lens import LensInfo  # noqa: E402
from pipeline.exports.registry import FORMATS, write_export  # noqa: E402
from pipeline.exports.source import ExportOptions, ExportSource  # noqa: E402
from pipeline.models.homography import apply_homography  # noqa: E402
from tests.pipeline.export_support import EquisolidLens  # noqa: E402

EXTRA = 1.3
Map = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Consumer:
    """A file as its consumer reads it: its ideal frame's scale ``f`` and centre ``c`` (px) and its forward map."""

    name: str
    f: tuple[float, float]
    c: tuple[float, float]
    forward: Map


def _cv2(k: np.ndarray, d: np.ndarray, fisheye: bool, name: str) -> Consumer:
    k = np.asarray(k, dtype=np.float64).reshape(3, 3)
    d = np.asarray(d, dtype=np.float64).ravel()

    def fwd(p: np.ndarray) -> np.ndarray:
        n = np.column_stack([(p[:, 0] - k[0, 2]) / k[0, 0], (p[:, 1] - k[1, 2]) / k[1, 1], np.ones(len(p))])
        n = np.ascontiguousarray(n.reshape(-1, 1, 3))
        if fisheye:
            q, _ = cv2.fisheye.projectPoints(n, np.zeros(3), np.zeros(3), k, d.reshape(1, -1))
        else:
            q, _ = cv2.projectPoints(n, np.zeros(3), np.zeros(3), k, d)
        return np.asarray(q.reshape(-1, 2), dtype=np.float64)

    return Consumer(name, (k[0, 0], k[1, 1]), (k[0, 2], k[1, 2]), fwd)


def read_opencv(data: bytes, w: int, h: int) -> Consumer:
    fs = cv2.FileStorage(data.decode(), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    k, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    fisheye = fs.getNode("distortion_model").string() == "fisheye"
    fs.release()
    return _cv2(k, d, fisheye, "cv2.FileStorage + cv2" + (".fisheye" if fisheye else "") + ".projectPoints")


def read_ros(data: bytes, w: int, h: int) -> Consumer:
    import yaml

    doc = yaml.safe_load(data.decode())
    fisheye = doc["distortion_model"] == "equidistant"
    k, d = np.array(doc["camera_matrix"]["data"]), np.array(doc["distortion_coefficients"]["data"])
    return _cv2(k, d, fisheye, "PyYAML + cv2 (image_geometry's calls)")


def read_mrcal(data: bytes, w: int, h: int) -> Consumer:
    intr = ast.literal_eval(data.decode().strip())["intrinsics"]
    k = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
    return _cv2(k, np.array(intr[4:]), False, "the .cameramodel dict + cv2 (OPENCV12/8)")


def read_colmap(data: bytes, w: int, h: int) -> Consumer:
    import pycolmap

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "cameras.txt").write_bytes(data)
        (Path(d) / "images.txt").write_text("")
        (Path(d) / "points3D.txt").write_text("")
        rec = pycolmap.Reconstruction()
        rec.read_text(d)
    (cam,) = rec.cameras.values()
    fx, fy, cx, cy = (float(v) for v in cam.params[:4])

    def fwd(p: np.ndarray) -> np.ndarray:  # COLMAP's pixel centres at +0.5
        n = np.column_stack([(p[:, 0] + 0.5 - cx) / fx, (p[:, 1] + 0.5 - cy) / fy, np.ones(len(p))])
        return np.asarray(cam.img_from_cam(n), dtype=np.float64) - 0.5

    return Consumer("pycolmap img_from_cam", (fx, fy), (cx - 0.5, cy - 0.5), fwd)


def read_kalibr(data: bytes, w: int, h: int) -> Consumer:
    from tests.pipeline.kalibr_equations import kalibr_camera, project

    p, dm, k, _ = kalibr_camera(data)

    def fwd(q: np.ndarray) -> np.ndarray:
        n = np.column_stack([(q[:, 0] - p[2]) / p[0], (q[:, 1] - p[3]) / p[1]])
        return np.asarray(project(p, dm, k, n), dtype=np.float64)

    return Consumer(f"Kalibr's equations ({dm})", (p[0], p[1]), (p[2], p[3]), fwd)


def read_basalt(data: bytes, w: int, h: int) -> Consumer:
    from tests.pipeline.basalt_equations import basalt_camera, project

    p, _, _ = basalt_camera(data)

    def fwd(q: np.ndarray) -> np.ndarray:
        xyz = np.column_stack([(q[:, 0] - p[2]) / p[0], (q[:, 1] - p[3]) / p[1], np.ones(len(q))])
        return np.asarray(project(p, xyz), dtype=np.float64)

    return Consumer("basalt-headers' kb4 equations", (p[0], p[1]), (p[2], p[3]), fwd)


def read_metashape(data: bytes, w: int, h: int) -> Consumer:
    from tests.pipeline.metashape_equations import metashape_camera, project

    proj, mw, mh, p = metashape_camera(data)
    fx, fy = p["f"] + p["b1"], p["f"]
    cx, cy = mw * 0.5 + p["cx"] - 0.5, mh * 0.5 + p["cy"] - 0.5  # Metashape's pixel centres at +0.5

    def fwd(q: np.ndarray) -> np.ndarray:
        n = np.column_stack([(q[:, 0] - cx) / fx, (q[:, 1] - cy) / fy])
        return np.asarray(project(proj, mw, mh, p, n), dtype=np.float64) - 0.5

    return Consumer(f"Metashape manual's equations ({proj})", (fx, fy), (cx, cy), fwd)


def read_lcp(data: bytes, w: int, h: int) -> Consumer:
    from tests.pipeline.lcp_equations import correct_distortion, mapper, read_profiles

    prof = read_profiles(data)
    (m,) = prof["models"]
    mc = mapper(m, w, h, m["focal"], prof["sensor_format_factor"])
    fisheye = bool(prof["fisheye"])

    def fwd(p: np.ndarray) -> np.ndarray:
        return np.asarray(correct_distortion(mc, p, fisheye), dtype=np.float64)

    return Consumer("RawTherapee's lcp.cc equations", (mc["fx"], mc["fy"]), (mc["x0"], mc["y0"]), fwd)


def read_lensfun(data: bytes, w: int, h: int, lens: LensInfo) -> Consumer:
    import lensfunpy

    db = lensfunpy.Database(xml=data.decode(), load_common=False, load_bundled=False)
    (cam,) = db.cameras
    (lf,) = db.lenses
    mod = lensfunpy.Modifier(lf, cam.crop_factor, w, h)
    flags = lensfunpy.ModifyFlags.DISTORTION | lensfunpy.ModifyFlags.GEOMETRY
    focal = float(lf.min_focal or lens.focal_mm or 50.0)
    mod.initialize(focal, 2.8, 1000.0, scale=1.0, targeom=lensfunpy.LensType.RECTILINEAR, flags=flags)

    def fwd(p: np.ndarray) -> np.ndarray:
        return np.array([mod.apply_geometry_distortion(float(x), float(y), 1, 1)[0, 0] for x, y in p], np.float64)

    return Consumer("lensfunpy (lensfun 0.3.4)", (float(max(w, h)),) * 2, ((w - 1) / 2.0, (h - 1) / 2.0), fwd)


READERS: dict[str, Callable[..., Consumer]] = {
    "opencv": read_opencv,
    "opencv-fisheye": read_opencv,
    "auto": read_opencv,
    "ros": read_ros,
    "ros-equidistant": read_ros,
    "mrcal": read_mrcal,
    "colmap": read_colmap,
    "kalibr": read_kalibr,
    "lcp": read_lcp,
    "basalt": read_basalt,
    "metashape": read_metashape,
}
"""The consumer of each format this table reads (lensfun: :func:`read_lensfun`, it needs the lens)."""

EXPORTS = [  # (label, format, options)
    ("opencv (12)", "opencv", {}),
    ("opencv --coeffs 8", "opencv", {"coeffs": 8}),
    ("opencv --coeffs 5", "opencv", {"coeffs": 5}),
    ("opencv-fisheye", "opencv-fisheye", {}),
    ("ros (8)", "ros", {}),
    ("ros-equidistant", "ros-equidistant", {}),
    ("mrcal (12)", "mrcal", {}),
    ("colmap", "colmap", {}),
    ("kalibr", "kalibr", {}),
    ("lcp", "lcp", {}),
    ("basalt", "basalt", {}),
    ("metashape", "metashape", {}),
    ("lensfun", "lensfun", {}),
    ("auto", "auto", {}),
]


def invert(c: Consumer, q: np.ndarray, iters: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Ideal pixels whose forward map is ``q``: damped Newton with a central-difference Jacobian per point;
    ``(p, residual px)``."""
    p = np.array(q, dtype=np.float64)
    eps = 1e-3
    for _ in range(iters):
        r = c.forward(p) - q
        jx = (c.forward(p + [eps, 0]) - c.forward(p - [eps, 0])) / (2 * eps)
        jy = (c.forward(p + [0, eps]) - c.forward(p - [0, eps])) / (2 * eps)
        j = np.stack([jx, jy], axis=-1)
        step = np.linalg.solve(j, r[..., None])[..., 0]
        lim = 0.2 * np.linalg.norm(p - c.c, axis=1, keepdims=True) + 5.0
        n = np.linalg.norm(step, axis=1, keepdims=True)
        p = p - step * np.minimum(1.0, lim / np.maximum(n, 1e-300))
    return p, np.linalg.norm(c.forward(p) - q, axis=1)


def _stats(e: np.ndarray) -> tuple[float, float]:
    return float(np.sqrt(np.mean(e**2))), float(e.max())


@dataclass(frozen=True)
class Figures:
    image: tuple[float, float]
    beyond: tuple[float, float]
    fault: str


def consumer_figures(model, w: int, h: int, c: Consumer) -> Figures:
    """See the module docstring."""
    xs, ys = np.linspace(0, w - 1, 48), np.linspace(0, h - 1, max(2, round(48 * h / w)))
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    p, res = invert(c, q)
    inv = res < 1e-4
    note = "" if inv.all() else f"; no inverse at {int(np.sum(~inv))} of {len(q)} pixels"
    q, p = q[inv], p[inv]
    ours = model.undistort_points(q)
    hom = fit_homography(p, ours)
    hm = hom[0] if isinstance(hom, tuple) else hom
    image = _stats(np.linalg.norm(apply_homography(hm, p) - ours, axis=1))
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=np.float64)
    pc, _ = invert(c, corners)
    f, ctr = np.array(c.f), np.array(c.c)
    rc = float(np.max(np.hypot(*((pc - ctr) / f).T)))
    angles = np.radians(np.arange(0.0, 360.0, 15.0) + 7.0)
    t = np.linspace(0.0, EXTRA * rc, 300)
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    pr = ctr + (t[None, :, None] * dirs[:, None, :]) * f
    qr = c.forward(pr.reshape(-1, 2)).reshape(pr.shape)
    q0 = c.forward(ctr[None, :])[0]
    rad = np.hypot(*(qr - q0).transpose(2, 0, 1))
    bad = ~np.isfinite(rad[:, 1:]) | (np.diff(rad, axis=1) <= 0)
    fault = "ok"
    if bad.any():
        first = int(np.argmax(bad.any(axis=0))) + 1
        fault = f"POLE/FOLD at {t[first] / rc:.2f}x"
    ring = t >= rc
    pq, qq = pr[:, ring].reshape(-1, 2), qr[:, ring].reshape(-1, 2)
    ok = np.all(np.isfinite(qq), axis=1)
    ours_r = model.undistort_points(qq[ok])
    good = np.all(np.isfinite(ours_r), axis=1)
    e = np.linalg.norm(apply_homography(hm, pq[ok][good]) - ours_r[good], axis=1)
    beyond = _stats(e) if len(e) else (math.nan, math.nan)
    return Figures(image, beyond, fault + note)


def lenses(model_path: Path | None, real_dir: Path) -> dict[str, tuple[object, int, int, LensInfo]]:
    from pipeline.model_file import read_model_file

    real_lens = LensInfo(
        lens_maker="Canon",
        lens_model="EF 50mm f/1.8 II",
        camera_maker="Canon",
        camera_model="EOS 40D",
        focal_mm=50.0,
        pixel_pitch_um=11.4,
        crop_factor=1.611,
        mount="Canon EF",
    )
    if model_path is not None:
        mf = read_model_file(model_path)
        real = (mf.model, mf.width, mf.height)
    else:
        from tests.pipeline.export_support import real_model

        rm = real_model(2, str(real_dir))
        real = (rm.model, rm.width, rm.height)
    out: dict[str, tuple[object, int, int, LensInfo]] = {"real": (*real, real_lens)}
    demo = LensInfo(
        lens_maker="Simulated Optics", lens_model="SIM-12mm", camera_maker="harp station", camera_model="Sim",
        focal_mm=12.0, pixel_pitch_um=3.75,
    )  # fmt: skip
    out["demo"] = (lens_for_focus(0.5, 1280, 960), 1280, 960, demo)
    for fov in (93.0, 115.0):
        f = 0.5 * math.hypot(639, 479) / (2 * math.sin(math.radians(fov / 4)))
        lens = LensInfo(
            lens_maker="Sim", lens_model=f"Wide {fov:g}", camera_maker="Sim", camera_model="Cam",
            focal_mm=round(f * 3e-3, 4), pixel_pitch_um=3.0,
        )  # fmt: skip
        out[f"wide{fov:g}"] = (EquisolidLens(f=f, cx=322.0, cy=236.5), 640, 480, lens)
    return out


def _fmt(v: tuple[float, float]) -> str:
    return " / ".join("-" if not math.isfinite(x) else f"{x:.4f}" for x in v)


def table(model_path: Path | None = None, real_dir: Path | None = None, out=sys.stdout) -> None:
    real_dir = real_dir or Path(os.environ.get("HARP_REAL_DATA", REPO.parent / "shared" / "data" / "real-harp"))
    print("| lens | export | written as | stated RMS / max mod H (px) | consumer over the image RMS / max (px) | "
          "consumer to 1.3x: pole/fold | consumer 1.0-1.3x vs the harp model RMS / max (px) | consumer | time (s) |",
          file=out)  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|", file=out)
    for name, (model, w, h, lens) in lenses(model_path, real_dir).items():
        src = ExportSource(model, w, h, lens=lens)
        for label, fmt, opts in EXPORTS:
            t0 = time.perf_counter()
            try:
                ex = write_export(fmt, src, ExportOptions(**opts))
            except ValueError as exc:
                why = str(exc).split(";")[0]
                print(f"| {name} | {label} | refused: {why} | | | | | | {time.perf_counter() - t0:.1f} |", file=out)
                continue
            dt = time.perf_counter() - t0
            written = ex.format
            note = next((n for n in ex.notes if n.startswith(f"{ex.format}: ")), None)
            if note is not None and fmt not in ("lensfun", "auto"):
                written += " → " + note[len(ex.format) + 2 :].split()[0].rstrip(",:")
            e = ex.error
            stated = _fmt((e.rms_mod_h_px, e.max_mod_h_px)) if e is not None else "-"
            reader = READERS.get(ex.format)
            if ex.format == "lensfun":
                c = read_lensfun(ex.data, w, h, lens)
            elif reader is not None:
                c = reader(ex.data, w, h)
            else:
                print(
                    f"| {name} | {label} | {written} | {stated} | no consumer in this table | | | | {dt:.1f} |",
                    file=out,
                )
                continue
            fig = consumer_figures(model, w, h, c)
            print(
                f"| {name} | {label} | {written} | {stated} | {_fmt(fig.image)} | {fig.fault} | {_fmt(fig.beyond)} | "
                f"{c.name} | {dt:.1f} |",
                file=out,
                flush=True,
            )
    others = [
        f for f in FORMATS if f not in {e[1] for e in EXPORTS} | {"maps", "stmap", "stmap-redistort", "json", "harp"}
    ]
    if others:
        print(f"\nFormats not in this table yet: {', '.join(others)}.", file=out)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", type=Path, default=None, help="the real-photo model file (default: fitted here)")
    args = ap.parse_args()
    print(f"# Every export x lens in its consumer — {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}\n")
    table(args.model)
    return 0


if __name__ == "__main__":
    sys.exit(main())
