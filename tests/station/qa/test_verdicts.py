"""QA verdicts on corrections with exact answers: truthful checks, and the stored model itself judged."""

import dataclasses
import math

import numpy as np
import pytest

from drivers.sim.lens import lens_for_focus
from pipeline.fitspec import FitSpec
from pipeline.models.base import IdentityModel
from pipeline.models.radial import RadialModel
from station.calibration import calibrate_shots
from station.config import QAConfig
from station.profile import Holdout, Merit, Profile, Provenance
from station.qa.verdicts import (
    Measurements,
    combine,
    distortion_magnitude,
    evaluate,
    qa_verdict,
    round_trip_error,
)
from tests.pipeline.harp_points import harp_point_sets

W, H = 400, 300
ANGLES = (0.0, 45.0, 90.0, 135.0)
SPEC = FitSpec("radial", 4, tangential=True)


def by_name(v):
    return {c.name: c for c in v.checks}


def tampered(model, k1=5.0):
    """The model with its first-order radial coefficient replaced (issue 14's tampered profile)."""
    return dataclasses.replace(model, k=(model.k[0], k1, *model.k[2:]))


@pytest.fixture(scope="module")
def calibrated():
    """The demo lens at 400x300 calibrated from exact edge points (tiny noise), its edges, and the truth."""
    truth = lens_for_focus(0.5, W, H)
    shots = harp_point_sets(truth, W, H, ANGLES, spacing=30.0, step=12.0, noise=0.003, seed=4)
    cal = calibrate_shots(shots, W, H, SPEC, holdout="orientations")
    assert cal.failure is None, cal.failure
    return cal.profile(W, H, provenance=Provenance()), Measurements(shots, "exact points"), truth


def test_identity_has_no_distortion():
    rms, mx = distortion_magnitude(IdentityModel(), W, H)
    assert rms < 1e-9 and mx < 1e-9
    assert round_trip_error(IdentityModel(), W, H) == 0.0


def test_thresholds():
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01))
    _rms, mx = distortion_magnitude(lens, W, H)
    assert 0.1 < mx < 3.0  # 0.01 * s at the corners, less modulo homography
    ok = evaluate(lens, W, H, 0.01, QAConfig(max_holdout_d_px=0.02, max_distortion_px=mx + 0.01))
    assert ok.passed and ok.reasons == ()
    assert [c.name for c in ok.checks] == ["holdout_d", "defined", "distortion_max"]
    assert all(c.passed for c in ok.checks)
    bad = evaluate(lens, W, H, 0.03, QAConfig(max_holdout_d_px=0.02, max_distortion_px=mx - 0.01))
    assert bad.verdict == "FAIL" and len(bad.reasons) == 2
    assert bad.reasons[0].startswith("holdout d 0.0300 px > 0.02 px")
    assert math.isclose(bad.metrics["distortion_max_px"], mx)


def test_every_check_says_truthfully_what_happened():
    # issue 9: "Checks: holdout d 0.0012 px <= 0.001 px" was written above "Reasons for FAIL: ... > 0.001 px"
    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01))
    _rms, mx = distortion_magnitude(lens, W, H)
    failed = by_name(evaluate(lens, W, H, 0.0012, QAConfig(max_holdout_d_px=0.001, max_distortion_px=mx / 2)))
    c = failed["holdout_d"]
    assert (c.value, c.comparison, c.limit, c.passed) == (0.0012, "<=", 0.001, False)
    assert c.text == "holdout d 0.0012 px > 0.001 px: FAIL"
    d = failed["distortion_max"]
    assert d.passed is False and d.text == f"distortion max (modulo homography) {mx:.3f} px > {mx / 2:g} px: FAIL"
    held = by_name(evaluate(lens, W, H, 0.0012, QAConfig(max_holdout_d_px=0.05)))
    assert held["holdout_d"].passed is True and held["holdout_d"].text == "holdout d 0.0012 px <= 0.05 px: PASS"
    shown = held["distortion_max"]  # no threshold: reported, not judged
    assert shown.passed is None and shown.limit is None and shown.text.endswith("reported, no threshold")
    assert shown.value == pytest.approx(mx)
    # the typed check survives its JSON form
    from station.profile import Check

    assert Check.from_dict(c.to_dict()) == c


def test_reference_deviation_and_missing_holdout():
    a = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.01))
    b = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02))
    q = QAConfig(max_holdout_d_px=1.0, max_reference_deviation_px=0.01)
    assert evaluate(a, W, H, 0.01, q, reference=a).passed
    v = evaluate(a, W, H, 0.01, q, reference=b)
    assert not v.passed and "deviation from the reference" in v.reasons[0]
    assert by_name(v)["reference_deviation_max"].text.endswith("> 0.01 px: FAIL")
    v = evaluate(a, W, H, None, q)
    assert not v.passed and "no cross-validated" in v.reasons[0]
    assert by_name(v)["holdout_d"].text == "holdout d: none recorded: FAIL"
    assert "not checked, no reference given" in v.checks[-1].text and v.checks[-1].passed is None
    assert combine([]) == "FAIL" and combine([evaluate(a, W, H, 0.0, q)]) == "PASS"


def test_a_correction_not_defined_at_the_corners_fails():
    # issue 14: a coefficient written into a stored profile. k1 = -5 folds the radial map at a tenth
    # of the half diagonal (rho (1 - 5 rho ...) stops increasing there), so the corners have no
    # inverse. (k1 = +5, issue 14's 259 px, is monotonic and has an exact inverse since the shared
    # safeguarded inverse, issue 20 item 9: the recorded figures catch it, tests below.)
    good = lens_for_focus(0.5, 1280, 960)
    bad = tampered(good, k1=-5.0)
    # truth independent of the check: the correction maps the corners where no inverse brings them back
    corners = np.array([[0.0, 0.0], [1279.0, 0.0], [1279.0, 959.0], [0.0, 959.0]])
    assert not np.allclose(bad.distort_points(bad.undistort_points(corners)), corners, atol=1.0, equal_nan=False)
    v = qa_verdict(Profile(bad, 1280, 960, merit=Merit(holdout=Holdout(0.001))))  # default thresholds
    assert not v.passed
    c = by_name(v)["defined"]
    assert c.passed is False and "corners" in c.text and c.text.endswith("FAIL")
    assert any("not defined over the whole image" in r for r in v.reasons)
    assert by_name(qa_verdict(Profile(good, 1280, 960, merit=Merit(holdout=Holdout(0.001)))))["defined"].passed


def test_the_stored_model_is_judged_on_its_measurements(calibrated):
    profile, measured, truth = calibrated
    v = qa_verdict(profile, measurements=measured)
    c = by_name(v)["corrected_d"]
    assert v.passed and c.passed and c.value < 0.01
    # the edges chosen as the fit chose them: the fit's own d on its shots, recomputed from the stored model
    assert c.value == pytest.approx(profile.merit.fit.d, rel=1e-9)
    # a model changed after calibration no longer straightens the edges it was fitted on
    # (a mild change here, still defined everywhere, so only this check can see it)
    changed = profile.with_(model=tampered(profile.model, k1=0.02))
    assert round_trip_error(changed.model, W, H) < 1e-6
    v = qa_verdict(changed, measurements=measured)
    c = by_name(v)["corrected_d"]
    assert not v.passed and c.passed is False and c.value > 0.05
    assert any("does not straighten the shots it was fitted on" in r for r in v.reasons)


def test_a_model_changed_after_its_verdict_fails_without_measurements(calibrated):
    profile, _measured, _truth = calibrated
    judged = profile.with_(qa=qa_verdict(profile))
    again = qa_verdict(judged)
    assert again.passed and by_name(again)["distortion_recorded"].passed
    changed = judged.with_(model=tampered(profile.model, k1=0.02))
    v = qa_verdict(changed)
    c = by_name(v)["distortion_recorded"]
    assert not v.passed and c.passed is False and "when judged at calibration" in c.text


def test_holdout_recomputed_from_the_measurements(calibrated):
    profile, measured, _truth = calibrated
    v = qa_verdict(profile, measurements=measured, recompute=True)
    checks = by_name(v)
    assert v.passed and checks["holdout_d_stored"].passed
    assert checks["holdout_d"].value == pytest.approx(profile.merit.holdout_d, abs=1e-9)
    assert "recomputed" in checks["holdout_d"].text
    # a stored holdout d that does not belong to the measurements: the recomputed one is judged
    lied = profile.with_(merit=dataclasses.replace(profile.merit, holdout=Holdout(1e-6, None, None, ())))
    v = qa_verdict(lied, QAConfig(max_holdout_d_px=0.05), measurements=measured, recompute=True)
    checks = by_name(v)
    assert checks["holdout_d"].value == pytest.approx(profile.merit.holdout_d, abs=1e-9)
    assert not v.passed and checks["holdout_d_stored"].passed is False
    assert v.metrics["holdout_d_stored_px"] == 1e-6


def test_a_turntable_axis_found_away_from_where_the_stage_put_it_fails_the_profile():
    """Two-axis capture: each place's axis as the joint fit found it against the stage's travel
    (:func:`station.axis_places.axis_record`: 10 px per mm along 0 degrees, places 0 and 10 mm, pitch 40 px);
    within half a pitch it passes, beyond it the strings were misnumbered there and QA says so."""
    from pipeline.harp_frame import HarpFrame
    from pipeline.harp_shape import HarpShapeFit
    from station.axis_places import Axes, AxisPlaces, axis_record

    places = AxisPlaces((0.0, 0.0, 10.0, 10.0), (0.0, 0.0, 10.0, 10.0), 0.0, 4.0)
    axes = Axes(places, ("0 mm", "0 mm", "10 mm", "10 mm"), {"0 mm": (-50.0, 0.0), "10 mm": (50.0, 0.0)}, 40.0, 10.0)

    def judged(second_x):
        frames = [HarpFrame(20.0, 1, (c, 150.0), 250.0, 37.0) for c in (150.0, second_x)]
        fit = HarpShapeFit(
            None, None, frames[0], (), 0.0, 0.0, 0, axis_groups=(("0 mm", frames[0]), ("10 mm", frames[1]))
        )
        rec = axis_record(axes, fit)
        return rec, by_name(evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health={"axes": rec}))

    rec, ok = judged(252.0)  # 102 px for 100: 2 px off, split between the two places
    assert rec["worst_off_px"] == pytest.approx(1.0) and rec["limit_px"] == 20.0 and rec["misplaced"] == []
    assert (
        ok["axis_places"].passed is True and "0 mm at (150.0, 150.0), 10 mm at (252.0, 150.0)" in ok["axis_places"].text
    )
    rec, bad = judged(300.0)  # 150 px for 100: 25 px off at each place, beyond half a pitch
    assert rec["misplaced"] == [0.0, 10.0] and bad["axis_places"].passed is False
    v = evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health={"axes": rec})
    assert not v.passed and any("strings were numbered wrongly" in r for r in v.reasons)


def _health(strings, typical, **kw):
    """A harp self-check record as ``station.harp_health.harp_health`` writes it (the QA's input)."""
    own = {s["index"]: s["own_bend_px"] for s in strings}
    worst = max(own, key=lambda k: own[k])
    se = {s["index"]: s["bend_se_px"] for s in strings}
    return {
        "limit_px": 0.02, "worst_string": worst, "worst_bend_px": own[worst], "worst_bend_se_px": se[worst],
        "typical_bend_px": typical, "strings": strings, "significance": 2.0, "outlier_factor": 3.0,
    } | kw  # fmt: skip


def _string(k, own, se):
    return {"index": k, "bend_px": own, "own_bend_px": own, "bend_se_px": se, "shots": 6, "span": [-0.8, 0.8]}


def test_the_harp_check_names_the_most_bent_string_and_says_why_a_bend_beyond_the_limit_passes():
    strings = [_string(k, 0.003, 0.002) for k in range(10)]
    strings[3], strings[7] = _string(3, 0.025, 0.002), _string(7, 0.04, 0.003)
    v = evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health=_health(strings, 0.003, bent_strings=[3, 7]))
    check = by_name(v)["string_bend_max"]
    assert check.passed is False and "(string 7) 0.0400 px > 0.02 px" in check.text
    assert any("string 7 of the harp is bent by 0.0400 px" in r for r in v.reasons)
    # beyond the limit, but no more than two standard errors from none: not a finding, and the text says so
    strings = [_string(k, 0.003, 0.002) for k in range(10)]
    strings[5] = _string(5, 0.0207, 0.0188)
    v = evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health=_health(strings, 0.003, uncertain_strings=[5]))
    check = by_name(v)["string_bend_max"]
    assert check.passed is True and v.passed
    assert "(string 5) 0.0207 px > 0.02 px, but within 2 standard errors (0.0188 px) of a straight string" in check.text
    # beyond the limit, but many strings bend alike (below three times the median string's)
    strings = [_string(k, 0.009, 0.001) for k in range(10)]
    strings[2] = _string(2, 0.024, 0.001)
    check = by_name(evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health=_health(strings, 0.009)))[
        "string_bend_max"
    ]
    assert (
        check.passed is True and "(string 2) 0.0240 px > 0.02 px, but below 3x the median string's 0.0090" in check.text
    )
    # within the limit
    strings = [_string(k, 0.003, 0.002) for k in range(10)]
    check = by_name(evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health=_health(strings, 0.003)))[
        "string_bend_max"
    ]
    assert check.passed is True and "0.0030 px <= 0.02 px" in check.text
    assert "weighed" not in check.text
    # shots the check weighed by their noise: named by turntable angle, with what to do
    noisy = [
        {"shot": 2, "turntable_deg": 60.0, "noise_ratio": 3.4},
        {"shot": 5, "turntable_deg": 150.0, "noise_ratio": 3.6},
    ]
    health = _health(strings, 0.003, noisy_shots=noisy)
    check = by_name(evaluate(IdentityModel(), W, H, 0.01, QAConfig(), harp_health=health))["string_bend_max"]
    assert check.passed is True and "shots at 60, 150 deg measured up to 3.6x worse than the others" in check.text
    assert "turn the harp on its mount" in check.text


def test_twins_fail_the_profile_when_the_lens_moved_between_them_beyond_the_records_limit(calibrated):
    """``twin_move``: of the pairs of twins a profile records (``harp calibrate``'s, without a twin d; a session's,
    with one), the one whose lens moved most is judged against its record's limit; a profile without twins has no
    such check. The records are written by hand here: what is judged is the verdict, not the twin reading."""
    profile, m, _ = calibrated
    pair = {"paths": ["a.pgm", "b.pgm"], "angle_deg": 3.0, "limit_px": 1.0, "moved": False}
    still, moved = {**pair, "move_px": -0.2}, {**pair, "paths": ["a.pgm", "c.pgm"], "move_px": -1.6, "moved": True}
    assert "twin_move" not in by_name(qa_verdict(profile, QAConfig(), measurements=m))
    v = qa_verdict(profile.with_(details={"twins": [still, moved]}), QAConfig(), measurements=m)
    c = by_name(v)["twin_move"]
    assert not v.passed and c.passed is False and c.value == pytest.approx(1.6) and c.limit == 1.0
    assert c.text.startswith("twins a.pgm and c.pgm: the lens moved 1.60 px") and c.text.endswith("> 1 px: FAIL")
    assert any("the lens moved between two shots at one angle" in r for r in v.reasons)
    session = {**still, "paths": ["orientation 1 (30 deg)", "orientation 6 (30 deg, the twin)"], "twin_d_px": 0.004}
    v = qa_verdict(profile.with_(details={"twins": [session]}), QAConfig(), measurements=m)
    c = by_name(v)["twin_move"]
    assert v.passed and c.passed and "(the twin, not fitted: d 0.0040 px) <= 1 px: PASS" in c.text
    assert v.metrics["twin_move_px"] == pytest.approx(0.2) and v.metrics["twin_d_px"] == 0.004
