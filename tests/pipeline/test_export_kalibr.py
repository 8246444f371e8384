"""The Kalibr camchain export read back with PyYAML and evaluated with Kalibr's documented model equations.

No Kalibr installed (it is a ROS/catkin package, not on PyPI): the consumer here is the file parsed by
PyYAML as Kalibr's ``kalibr_common`` parses it, and the equations of Kalibr's aslam_cv written out
below from its documentation and sources (``PinholeProjection``, ``RadialTangentialDistortion``,
``EquidistantDistortion``): the closed-form projection (``distort``, then ``u = fu x + pu``) and
Kalibr's own point undistortion (5 Gauss-Newton steps for radtan, 20 fixed-point steps for
equidistant), besides the same inversions iterated to convergence. Truth: the harp model
(``undistort_points``), independent of the writer; compared modulo homography as every export.
"""

import numpy as np
import pytest
import yaml

from pipeline.compare import fit_homography
from pipeline.exports.kalibr import read_kalibr_text
from pipeline.exports.registry import read_correction, write_export
from pipeline.exports.source import ExportSource
from pipeline.models.homography import apply_homography
from tests.pipeline.export_support import WIDE, WIDE_H, WIDE_W, mod_h, real_model
from tests.pipeline.kalibr_equations import kalibr_camera, project, unproject

STAMP = "FAILED QA: profile #7 at focus 0 was judged FAIL (test stamp)"


# ------------------------------------------------------------------- exports
@pytest.fixture(scope="module")
def real(real_harp_dir):
    rm = real_model(1, str(real_harp_dir))
    src = ExportSource(rm.model, rm.width, rm.height, holdout_d=rm.holdout_d, edges=rm.edges)
    return rm.model, rm.width, rm.height, write_export("kalibr", src)


@pytest.fixture(scope="module")
def wide():
    return WIDE, WIDE_W, WIDE_H, write_export("kalibr", ExportSource(WIDE, WIDE_W, WIDE_H, stamp=(STAMP,)))


def grid(width, height, nx=64):
    ny = int(round(nx * height / width))
    xs, ys = np.linspace(0, width - 1, nx), np.linspace(0, height - 1, ny)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def check_with_kalibr_equations(model, width, height, ex, expected):
    p, dm, k, cam = kalibr_camera(ex.data)
    assert dm == expected and cam["resolution"] == [width, height] and len(k) == 4
    err = ex.error
    q = grid(width, height)
    ours = model.undistort_points(q)
    x = unproject(p, dm, k, q, converged=True)  # converged: the model the file holds
    rms, mx = mod_h(x, ours)
    x5 = unproject(p, dm, k, q)  # Kalibr's own step count
    rms_k, mx_k = mod_h(x5, ours)
    solver = float(np.max(np.hypot(*((x5 - x) * p[:2]).T)))
    # the projection (closed form): our ideal points into the file's camera by the homography, projected
    h, _ = fit_homography(x, ours)
    proj = project(p, dm, k, apply_homography(np.linalg.inv(h), ours))
    e = np.hypot(*(proj - q).T)
    print(
        f"\nkalibr pinhole-{dm} (Kalibr's documented equations, no Kalibr installed): stated RMS "
        f"{err.rms_mod_h_px:.3g} / max {err.max_mod_h_px:.3g} px mod H; unprojection converged RMS {rms:.3g} / "
        f"max {mx:.3g} px; with Kalibr's own step count RMS {rms_k:.3g} / max {mx_k:.3g} px (the steps leave "
        f"{solver:.2g} px); projection RMS {np.sqrt(np.mean(e**2)):.3g} / max {e.max():.3g} px"
    )
    assert rms <= 1.3 * err.rms_mod_h_px + 5e-4 and mx <= 1.3 * err.max_mod_h_px + 5e-4
    assert abs(rms - err.rms_mod_h_px) <= 0.3 * err.rms_mod_h_px + 5e-4
    assert np.sqrt(np.mean(e**2)) <= 1.3 * err.rms_mod_h_px + 5e-4 and e.max() <= 1.3 * err.max_mod_h_px + 5e-4
    return solver


def test_the_real_lens_as_pinhole_radtan_within_the_stated_error(real):
    model, w, h, ex = real
    check_with_kalibr_equations(model, w, h, ex, "radtan")
    assert ex.notes[0].startswith("kalibr: pinhole-radtan, the closer in max")
    # 4 coefficients (no k3, no rational or thin-prism terms) are less exact than this calibration: said
    assert any("less exact than the calibration" in w for w in ex.warnings)


def test_the_wide_lens_as_pinhole_equi_exactly_and_the_stamp_leads(wide):
    model, w, h, ex = wide
    solver = check_with_kalibr_equations(model, w, h, ex, "equidistant")
    assert ex.error.max_mod_h_px < 1e-4 and solver < 1e-3
    comments = [ln for ln in ex.data.decode().splitlines() if ln.startswith("#")]
    assert comments[0].startswith("# Kalibr camera chain") and comments[1] == f"# {STAMP}"
    assert ex.notes[0].startswith("kalibr: pinhole-equi: pinhole-radtan cannot hold this lens (the OpenCV 4-coeff")


@pytest.mark.parametrize("which", ["real", "wide"])
def test_the_export_reads_back_as_the_model_it_holds(which, request):
    model, w, h, ex = request.getfixturevalue(which)
    c = read_correction(ex.data, "camchain.yaml", w, h)
    assert c.kind == "kalibr:pinhole-" + ("radtan" if which == "real" else "equi") and c.size == (w, h)
    q = grid(w, h, 30)
    assert np.allclose(c.model.undistort_points(q), ex.converted.undistort_points(q), atol=1e-9)
    doc = yaml.safe_load(ex.data)
    two = yaml.safe_dump({"cam0": doc["cam0"], "cam1": {**doc["cam0"], "resolution": [100, 80]}})
    assert read_kalibr_text(two, "camchain.yaml", (w, h))[1] == (w, h)
    for bad, why in (
        ("a: 1\n", "no camN with camera_model"),
        (yaml.safe_dump({"cam0": {**doc["cam0"], "camera_model": "omni"}}), "model omni-.* not read"),
        (yaml.safe_dump({"cam0": {**doc["cam0"], "distortion_coeffs": [0.1]}}), "needs 4 distortion_coeffs, got 1"),
        (yaml.safe_dump({"cam0": doc["cam0"], "cam1": doc["cam0"]}), "2 Kalibr cameras, 2 of them"),
    ):
        with pytest.raises(ValueError, match=f"^camchain.yaml: .*{why}"):
            read_kalibr_text(bad, "camchain.yaml", (w, h))
