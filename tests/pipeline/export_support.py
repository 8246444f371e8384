"""Shared truth and helpers of the export tests: an exact wide-angle lens, the real-photo models,
consumer comparisons modulo homography, and running Debian's own consumers under /usr/bin/python3."""

from __future__ import annotations

import json
import os
import subprocess
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from pipeline.compare import fit_homography
from pipeline.edgeset import FitResult, corrected_straightness
from pipeline.fit import fit_distortion
from pipeline.models.base import DistortionModel
from tests.pipeline.rendered_shots import REAL, real_shots

SYSTEM_PYTHON = "/usr/bin/python3"


@dataclass(frozen=True)
class EquisolidLens(DistortionModel):
    r"""Exact wide-angle lens (test truth, independent of the export code): equisolid projection.

    A ray at angle :math:`\theta` is recorded at radius :math:`r_d = 2f\sin(\theta/2)` from
    ``(cx, cy)``; its pin-hole image is at :math:`r_u = f\tan\theta`. So the correction is
    :math:`r_u(r_d) = f\tan(2\arcsin(r_d / 2f))`, in closed form both ways.
    """

    f: float
    cx: float
    cy: float
    name: str = field(default="equisolid_test", init=False, repr=False)

    def undistort_points(self, xy):
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        d = xy - [self.cx, self.cy]
        rd = np.hypot(d[:, 0], d[:, 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            theta = 2 * np.arcsin(rd / (2 * self.f))
            s = np.where(rd > 1e-12, self.f * np.tan(theta) / rd, 1.0)
        return np.array([self.cx, self.cy]) + d * s[:, None]

    def distort_points(self, xy, max_iter=50):
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        d = xy - [self.cx, self.cy]
        ru = np.hypot(d[:, 0], d[:, 1])
        theta = np.arctan(ru / self.f)
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(ru > 1e-12, 2 * self.f * np.sin(theta / 2) / ru, 1.0)
        return np.array([self.cx, self.cy]) + d * s[:, None]

    def to_dict(self):
        return {"model": self.name, "f": self.f, "cx": self.cx, "cy": self.cy}

    @classmethod
    def from_dict(cls, d):
        return cls(d["f"], d["cx"], d["cy"])


#: 640 x 480, 74 degrees from the axis at the corners (149 degrees diagonal field), slightly decentred
WIDE_W, WIDE_H = 640, 480
WIDE = EquisolidLens(f=330.0, cx=322.0, cy=236.5)


@dataclass(frozen=True)
class RealModel:
    """A model fitted on two real photos, with the third held out."""

    model: DistortionModel
    width: int
    height: int
    train: tuple[str, str]
    held: str
    holdout_d: float
    edges: tuple[np.ndarray, ...]


def wide_radial(fov_deg: float, width: int, height: int, centre_offset: tuple[float, float] = (3.0, -2.0)):
    """A harp RadialModel of an equisolid lens whose diagonal field of view is ``fov_deg``.

    The correction ratio :math:`r_u / r_d` of :class:`EquisolidLens` (f set so that the half
    diagonal is at half the field of view) sampled at 200 radii and fitted by a degree-6
    polynomial in :math:`\\rho` (lens construction, not a result of the code under test).
    """
    from pipeline.models import RadialModel

    half = 0.5 * float(np.hypot(width - 1, height - 1))
    f = half / (2 * np.sin(np.radians(fov_deg / 2) / 2))
    rho = np.linspace(0.0, 1.0, 200)
    rd = rho * half
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(rho > 0, f * np.tan(2 * np.arcsin(rd / (2 * f))) / np.maximum(rd, 1e-9), 1.0)
    k = np.linalg.lstsq(np.stack([rho**i for i in range(7)], axis=1), ratio, rcond=None)[0]
    c = ((width - 1) / 2.0 + centre_offset[0], (height - 1) / 2.0 + centre_offset[1])
    return RadialModel.for_image(width, height, k=tuple(float(v) for v in k), center=c)


@cache
def real_model(held: int, directory: str) -> RealModel:
    """radial4 + tangential + prism (free centre, the recommended model), fit on the two other photos."""
    shots = real_shots(directory)
    w, h, _ = shots[0]
    train = [s for i, (_, _, s) in enumerate(shots) if i != held]
    r = fit_distortion(train, w, h, model="radial", degree=4, tangential=True, prism=True)
    assert isinstance(r, FitResult), getattr(r, "reason", "")
    d, _ = corrected_straightness(r.model, shots[held][2])
    names = tuple(n for i, n in enumerate(REAL) if i != held)
    edges = tuple(p for s in train for p in s)
    return RealModel(r.model, w, h, (names[0], names[1]), REAL[held], float(d), edges)


def mod_h(ideal_theirs: np.ndarray, ideal_ours: np.ndarray) -> tuple[float, float]:
    """RMS and max of ``|H(theirs) - ours|`` after the best homography (pixels)."""
    _, res = fit_homography(ideal_theirs, ideal_ours)
    e = np.hypot(res[:, 0], res[:, 1])
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def ideal_grid(width: int, height: int, step: int) -> np.ndarray:
    """Integer pixel grid every ``step`` px with the last row/column."""
    xs = np.unique(np.append(np.arange(0, width, step), width - 1))
    ys = np.unique(np.append(np.arange(0, height, step), height - 1))
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1).astype(np.int64)


def compare_map(
    model: DistortionModel, map_x: np.ndarray, map_y: np.ndarray, step: int = 8
) -> tuple[float, float, int]:
    """A consumer's map (ideal pixel -> distorted source) against our correction, modulo homography.

    At ideal pixels ``p`` of the grid, ``q = map(p)`` is where the consumer reads the distorted
    image; our correction of ``q`` must be ``p`` up to a homography. Points whose ``q`` falls outside
    the image are not compared (they are not in the picture). Returns ``(rms, max, n)``.
    """
    h, w = map_x.shape[:2]
    p = ideal_grid(w, h, step)
    q = np.stack([map_x.reshape(h, w)[p[:, 1], p[:, 0]], map_y.reshape(h, w)[p[:, 1], p[:, 0]]], axis=1)
    q = q.astype(np.float64)
    ok = (q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1)
    rms, mx = mod_h(p[ok].astype(np.float64), model.undistort_points(q[ok]))
    return rms, mx, int(ok.sum())


def system_python(script: str, payload: dict) -> dict:
    """Run ``script`` with Debian's /usr/bin/python3 (its own packages), JSON in on stdin, JSON out on stdout."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    out = subprocess.run(
        [SYSTEM_PYTHON, "-c", script],
        input=json.dumps(payload),
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


# ------------------------------------------------------ the real consumers
ROS_SCRIPT = r"""
import json, sys
import numpy as np
import camera_calibration_parsers, image_geometry
req = json.load(sys.stdin)
name, ci = camera_calibration_parsers.readCalibration(req["path"])
out = {"camera_name": name, "model": ci.distortion_model, "D": list(ci.D), "K": list(ci.K),
       "width": ci.width, "height": ci.height}
if req.get("rectify"):
    m = image_geometry.PinholeCameraModel()
    m.fromCameraInfo(ci)
    raw = np.zeros((ci.height, ci.width), np.uint8)
    m.rectifyImage(raw, raw.copy())
    np.save(req["rectify"], np.stack([m.mapx.reshape(ci.height, ci.width), m.mapy.reshape(ci.height, ci.width)]))
print(json.dumps(out))
"""
"""Debian's ``camera_calibration_parsers`` reads a camera_info YAML; with ``rectify`` (an ``.npy``
path) ``image_geometry.PinholeCameraModel`` builds its rectification maps and they are saved there."""

MRCAL_SCRIPT = r"""
import json, sys
import numpy as np
import mrcal
req = json.load(sys.stdin)
m = mrcal.cameramodel(req["path"])
lensmodel, intr = m.intrinsics()
q = np.array(req["q"], dtype=float)
v = mrcal.unproject(q, lensmodel, intr)
p = np.stack([intr[0] * v[:, 0] / v[:, 2] + intr[2], intr[1] * v[:, 1] / v[:, 2] + intr[3]], axis=1)
print(json.dumps({"lensmodel": lensmodel, "imagersize": [int(x) for x in m.imagersize()], "p": p.tolist()}))
"""
"""Debian's ``mrcal`` reads a ``.cameramodel`` and unprojects pixels ``q`` to pin-hole pixels."""


def ros_in_consumer(path, rectify: bool = False) -> dict:
    """The camera_info at ``path`` as Debian's ROS parser reads it; with ``rectify`` also
    ``mapx``, ``mapy``: image_geometry's rectification maps (ideal pixel -> distorted source)."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        npy = os.path.join(d, "maps.npy")
        got = system_python(ROS_SCRIPT, {"path": str(path), "rectify": npy if rectify else None})
        if rectify:
            got["mapx"], got["mapy"] = np.load(npy)
    return got


def opencv_maps(path, width: int, height: int) -> tuple[np.ndarray, np.ndarray, str, np.ndarray]:
    """cv2.FileStorage reads an OpenCV export and OpenCV builds its undistortion maps
    (``cv2.initUndistortRectifyMap``, or ``cv2.fisheye``'s for ``distortion_model: fisheye``):
    ``(map_x, map_y, distortion_model, camera_matrix)``."""
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    k, d = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    kind = fs.getNode("distortion_model").string()
    fs.release()
    if kind == "fisheye":
        mx, my = cv2.fisheye.initUndistortRectifyMap(k, d, np.eye(3), k, (width, height), cv2.CV_32FC1)
    else:
        mx, my = cv2.initUndistortRectifyMap(k, d, None, k, (width, height), cv2.CV_32FC1)
    return mx, my, kind, k


def fisheye_maps_of_ros(got: dict, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """cv::fisheye maps of a parsed ``equidistant`` camera_info (what ROS 2's image_proc does)."""
    import cv2

    k = np.array(got["K"]).reshape(3, 3)
    return cv2.fisheye.initUndistortRectifyMap(k, np.array(got["D"]), np.eye(3), k, (width, height), cv2.CV_32FC1)


def mrcal_in_consumer(
    path, width: int, height: int, nx: int = 60, ny: int = 40
) -> tuple[str, list, np.ndarray, np.ndarray]:
    """mrcal's reading of a ``.cameramodel`` at pixels of a grid: ``(lensmodel, imagersize, q, p)``
    with ``p`` the pin-hole pixels mrcal unprojects ``q`` to."""
    xs, ys = np.linspace(0, width - 1, nx), np.linspace(0, height - 1, ny)
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    got = system_python(MRCAL_SCRIPT, {"path": str(path), "q": q.tolist()})
    return got["lensmodel"], got["imagersize"], q, np.array(got["p"])


def lensfun_in_consumer(
    xml: str, camera: tuple[str, str], lens: tuple[str, str], focal: float, width: int, height: int, n: int = 40
) -> tuple[object, object, np.ndarray, np.ndarray]:
    """lensfun (lensfunpy) finds ``camera`` (maker, model) and ``lens`` (maker, model) in a database
    and corrects the pixels of a grid at ``focal`` and the camera's crop factor:
    ``(camera, lens, p, q)`` with ``q`` where lensfun reads the distorted image for ideal ``p``."""
    import lensfunpy

    db = lensfunpy.Database(xml=xml, load_common=False, load_bundled=False)
    (cam,) = db.find_cameras(*camera)
    (lf_lens,) = db.find_lenses(cam, *lens)
    mod = lensfunpy.Modifier(lf_lens, cam.crop_factor, width, height)
    mod.initialize(focal, 2.8, 1000.0, scale=1.0, flags=lensfunpy.ModifyFlags.DISTORTION)
    xs, ys = np.linspace(0, width - 1, n), np.linspace(0, height - 1, max(2, n * height // width))
    p = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    q = np.array([mod.apply_geometry_distortion(float(x), float(y), 1, 1)[0, 0] for x, y in p], dtype=np.float64)
    return cam, lf_lens, p, q


def compare_points(
    model: DistortionModel, p: np.ndarray, q: np.ndarray, width: int, height: int
) -> tuple[float, float]:
    """A consumer's ideal pixels ``p`` and the distorted ``q`` it reads them from, against our correction
    (modulo homography; points whose ``q`` is outside the image are not compared)."""
    ok = (q[:, 0] >= 0) & (q[:, 0] <= width - 1) & (q[:, 1] >= 0) & (q[:, 1] <= height - 1)
    return mod_h(p[ok], model.undistort_points(q[ok]))
