"""Issue 20's target beyond the image: every pin-hole and fisheye export family has no pole and no fold
out to 1.3x the corner radius, in its consumer (``cv2``), on the real camera and a wide lens.

``test_export_poles.py`` holds the 12- and 8-coefficient files (OpenCV, ROS, mrcal) to 1.5x; here the
families it does not: the 4- and 5-coefficient pin-hole fits (Kalibr's radtan; ROS / OpenCV plumb_bob and
the LCP PerspectiveModel) and the fisheye fits with 4 coefficients (opencv-fisheye, ros-equidistant,
Kalibr equi, COLMAP OPENCV_FISHEYE, Basalt-like kb4) and 2 (the LCP FisheyeModel), each fitted as its
export fits it (the nominal focal). In OpenCV: ``cv2.projectPoints`` / ``cv2.fisheye.projectPoints`` of
rays out to 1.3x the corner radius (the ideal radius ``tan theta`` of the farthest corner, found by
OpenCV's own converged inverse) are finite and move outwards with the radius along every ray, and
OpenCV's converged inverse (``cv2.undistortPointsIter`` / ``cv2.fisheye.undistortPoints`` with criteria)
takes those pixels back to their rays (no second preimage). A family that cannot hold a lens that way is
refused by its fit (pin-hole: :mod:`pipeline.exports.pole_free`), which is a pass here.
"""

import cv2
import numpy as np
import pytest

from pipeline.exports.fit import fit_fisheye, fit_opencv
from tests.pipeline.export_support import real_model, wide_radial

EXTRA = 1.3
ANGLES = np.radians(np.arange(0.0, 360.0, 30.0) + 7.0)
CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)


def _lenses(real_harp_dir):
    rm = real_model(1, str(real_harp_dir))
    f115 = 400 / (2 * np.sin(np.radians(115 / 4)))  # the equisolid focal of a 115 degree 640 x 480 lens
    return {
        "real": (rm.model, rm.width, rm.height, 50.0 / 11.4e-3),  # the photographs' camera, nominal focal
        "wide115": (wide_radial(115.0, 640, 480), 640, 480, f115),
    }


FAMILIES = ("pinhole4", "pinhole5", "fisheye4", "fisheye2")
CASES = [("real", f) for f in FAMILIES] + [("wide115", "fisheye4"), ("wide115", "fisheye2")]
"""The wide lens in the fisheye families its exports use (its 12- and 8-coefficient pin-hole files are in
``test_export_poles.py``; a 4-coefficient fit of it runs LM to its evaluation limit, minutes: not here)."""


@pytest.fixture(scope="module")
def fits(real_harp_dir):
    """``{(lens, family): (K, D) or the fit's refusal (str)}``."""
    out = {}
    lenses = _lenses(real_harp_dir)
    for name, fam in CASES:
        model, w, h, f = lenses[name]
        try:
            if fam.startswith("pinhole"):
                m, _ = fit_opencv(model, w, h, n_coeffs=int(fam[-1]), focal=f)
            else:
                m, _ = fit_fisheye(model, w, h, focal=f, n_coeffs=int(fam[-1]))
        except ValueError as exc:
            out[(name, fam)] = str(exc)
            continue
        out[(name, fam)] = (m.camera_matrix, m.dist_coeffs, w, h)
    return out


def _inverse(k, d, q, fisheye):
    q = np.asarray(q, dtype=np.float64).reshape(-1, 1, 2)
    if fisheye:
        return cv2.fisheye.undistortPoints(q, k, d, criteria=CRIT).reshape(-1, 2)
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
        return cv2.undistortPointsIter(q, k, d, None, None, CRIT).reshape(-1, 2)
    return cv2.undistortPoints(q, k, d, R=None, P=None, criteria=CRIT).reshape(-1, 2)  # OpenCV 5


def _project(k, d, v, fisheye):
    v = np.ascontiguousarray(v.reshape(-1, 1, 3))
    if fisheye:
        p, _ = cv2.fisheye.projectPoints(v, np.zeros(3), np.zeros(3), k, d)
    else:
        p, _ = cv2.projectPoints(v, np.zeros(3), np.zeros(3), k, d)
    return p.reshape(-1, 2)


@pytest.mark.parametrize("lens, family", CASES, ids=[f"{n}-{f}" for n, f in CASES])
def test_no_pole_no_fold_out_to_1_3x_the_corner_radius_in_opencv(fits, lens, family):
    got = fits[(lens, family)]
    if isinstance(got, str):  # refused by the fit (a pole or fold it cannot avoid): nothing exported
        assert "pole or fold" in got or "cannot represent" in got, got
        print(f"\n{lens} {family}: refused by the fit ({got[:90]}...)")
        return
    k, d, w, h = got
    fisheye = family.startswith("fisheye")
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=np.float64)
    n = _inverse(k, d, corners, fisheye)
    back = _project(k, d, np.column_stack([n, np.ones(4)]), fisheye)
    assert np.abs(back - corners).max() < 1e-6  # OpenCV's inverse converged at the corners
    rc = float(np.hypot(n[:, 0], n[:, 1]).max())
    r = np.linspace(0.0, EXTRA * rc, 400)
    v = np.stack([np.cos(ANGLES)[:, None] * r, np.sin(ANGLES)[:, None] * r, np.ones((len(ANGLES), len(r)))], -1)
    p = _project(k, d, v, fisheye).reshape(len(ANGLES), len(r), 2)
    assert np.all(np.isfinite(p)), f"{lens} {family}: non-finite projection"
    rad = np.hypot(p[..., 0] - k[0, 2], p[..., 1] - k[1, 2])
    step = np.diff(rad, axis=1).min()
    # and back: OpenCV's converged inverse finds the same rays (one preimage), beyond the image too
    rays = _inverse(k, d, p.reshape(-1, 2), fisheye).reshape(len(ANGLES), len(r), 2)
    miss = float(np.abs(rays - v[..., :2]).max() / (EXTRA * rc))
    print(
        f"\n{lens} {family}: corner radius {rc:.4f}, at {EXTRA}x: projected radius up to {rad.max():.1f} px, "
        f"smallest step {step:.3g} px, inverse off by {miss:.1e} (relative)"
    )
    assert step > 0, f"{lens} {family}: the projected radius decreases (a fold or a pole)"
    assert miss < 1e-6, f"{lens} {family}: OpenCV's inverse does not return the rays ({miss:.2g})"
