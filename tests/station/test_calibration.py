"""station.calibration: what keeps a set of shots from being calibrated, and the held-out warning."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.fitspec import parse
from station.calibration import holdout_warning, noisy_shot_warnings, shot_count_problem, size_problem


def test_shots_of_different_sizes_are_named():
    assert size_problem([("a.png", 640, 480), ("b.png", 640, 480)]) is None
    msg = size_problem([("a.png", 640, 480), ("b.png", 800, 600)])
    assert msg == "images of different sizes (a.png 640x480, b.png 800x600): one model fits one image size"


def test_a_model_choice_needs_two_shots_a_given_model_one():
    assert "at least 2 shots" in (shot_count_problem(1, None) or "")
    assert shot_count_problem(2, None) is None
    assert shot_count_problem(1, parse("radial4")) is None


def test_holdout_warning_when_the_correction_bends_the_held_out_edges():
    x = np.linspace(0.0, 100.0, 51)
    bent = [np.stack([x, 0.01 * (x - 50.0) ** 2 / 25.0], 1), np.stack([x, 20.0 + 0.0 * x], 1)]
    # d of these edges, uncorrected, computed independently: RMS distance to each edge's own line
    d0 = np.sqrt(np.mean(np.concatenate([_line_residuals(p) for p in bent]) ** 2))
    assert holdout_warning(bent, d0 * 0.5) is None  # straighter after correction
    warning = holdout_warning(bent, d0 * 2.0)
    assert warning is not None and "less straight than uncorrected" in warning and f"{d0:.4f} px before" in warning
    assert holdout_warning(bent, None) is None


def _line_residuals(p: np.ndarray) -> np.ndarray:
    c = p - p.mean(0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return c @ vt[1]


def test_a_session_fit_checks_the_harp_and_qa_fails_a_bent_string():
    """Issue 19 item 4 in the station: a focus setting fitted with its turntable angles carries the
    harp's self-check, and QA fails when a string is bent beyond the limit, naming the string; a
    straight harp passes that check. Truth: the generator's exact bends (a 0.05 px bow of string 4)."""
    from pipeline.fitspec import FitSpec
    from pipeline.harp_shape import BEND_LIMIT_PX
    from pipeline.models import RadialModel
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig, QAConfig
    from station.qa.verdicts import evaluate
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4))
    turns = (0, 30, 60, 90, 120, 150)
    spec = FitSpec("radial", 4, True, True)
    results = {}
    for name, bow in (("bent", 0.05), ("straight", 0.0)):
        bends = np.zeros((11, 3))
        bends[4] = (bow, 0.0, 0.0)
        shots, _ = turning_harp_point_sets(lens, w, h, turns, bends, axis=(497, 378), seed=4)
        cal = calibrate_focus(shots, w, h, PipelineConfig(field="none"), 0, spec, turntable_deg=turns)
        health = cal.details["harp_health"]
        verdict = evaluate(cal.fit.model, w, h, 0.001, QAConfig(), harp_health=health)
        results[name] = (health, verdict)
    health, verdict = results["bent"]
    assert health["worst_string"] == 4 and health["bent_strings"] == [4] and health["limit_px"] == BEND_LIMIT_PX
    u = np.linspace(*health["strings"][4]["span"], 401)  # where the string was seen (half diagonals)
    lo, hi = health["strings"][4]["seen_twice"]  # where two shots or more saw it: within that
    assert u[0] <= lo < hi <= u[-1]
    assert health["noisy_shots"] == []  # every shot drawn with the same noise: none weighed
    truth = float(np.max(np.abs(0.05 * 0.5 * (3 * u**2 - 1))))  # the bow's largest |delta| there
    assert health["worst_bend_px"] == pytest.approx(truth, rel=0.2)  # recovered within 20 %
    assert verdict.verdict == "FAIL" and any("string 4 of the harp is bent" in r for r in verdict.reasons)
    check = next(c for c in verdict.checks if c.name == "string_bend_max")
    assert check.passed is False and check.value == health["worst_bend_px"]
    health, verdict = results["straight"]
    assert health["bent_strings"] == [] and health["worst_bend_px"] < 0.01
    assert next(c for c in verdict.checks if c.name == "string_bend_max").passed is True
    assert verdict.verdict == "PASS"
    # no angles (photographs): no self-check, nothing judged
    shots, _ = turning_harp_point_sets(lens, w, h, turns[:3], np.zeros((11, 3)), seed=4)
    assert "harp_health" not in calibrate_focus(shots, w, h, PipelineConfig(), 0, spec).details


def test_a_session_stores_the_lens_with_the_strings_separated():
    """Issue 19 items 4-5 in the station: with turntable angles, the profile's lens is fitted with every
    string's own bend separated, and it is closer to the exact lens than the lens fitted alone (which takes
    the bends the strings share into the correction); its figures are its own (fit and the
    leave-one-orientation-out hold-out re-made); ``pipeline.strings: ignore`` keeps the lens fitted alone.
    Truth: the generator's exact lens (field error modulo homography over the whole image)."""
    from pipeline.compare import compare_models
    from pipeline.fitspec import FitSpec
    from pipeline.models import RadialModel
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4))
    turns = (0, 30, 60, 90, 120, 150)
    spec = FitSpec("radial", 4, True, True)
    bends = np.random.default_rng(19).normal(0.0, 0.02, (11, 3))  # every string bowed, as real strings are
    bends[:, 0] += 0.03  # and a bow all of them share (what a lens fitted alone takes for distortion)
    shots, _ = turning_harp_point_sets(lens, w, h, turns, bends, axis=(497, 378), seed=7)
    # no residual field (pipeline.field): the lens alone would take the strings' shared bow for one
    sep = calibrate_focus(shots, w, h, PipelineConfig(field="none"), 0, spec, turntable_deg=turns)
    alone = calibrate_focus(shots, w, h, PipelineConfig(strings="ignore", field="none"), 0, spec, turntable_deg=turns)
    assert sep.failure is None and alone.failure is None
    rec = sep.details["strings"]
    assert rec["separated"] is True and "strings" not in alone.details
    err_sep = compare_models(sep.fit.model, lens, w, h, step=20).rms
    err_alone = compare_models(alone.fit.model, lens, w, h, step=20).rms
    assert err_sep < 0.5 * err_alone, (err_sep, err_alone)
    # the figures are the stored lens's: the fit's d is of the points corrected by it alone
    assert sep.fit.model is not alone.fit.model
    assert rec["fit_d_lens_alone_px"] == pytest.approx(alone.merit.fit.d)
    assert rec["holdout_d_lens_alone_px"] == pytest.approx(alone.merit.holdout.d)
    assert sep.merit.holdout.scheme == alone.merit.holdout.scheme and len(sep.merit.holdout.per_orientation_d) == 6
    assert sep.merit.holdout.d != alone.merit.holdout.d
    # the bootstrap, when asked for, is the separated lens's (every replicate fitted with the strings separated)
    boot = calibrate_focus(shots, w, h, PipelineConfig(bootstrap=2, field="none"), 0, spec, turntable_deg=turns)
    assert boot.uncertainty is not None and boot.uncertainty.model is boot.fit.model and boot.uncertainty.n_boot == 2
    assert boot.details["bootstrap_replicates"] == 2 and boot.details["strings"]["field_uncertainty_lens_alone_px"] > 0
    assert boot.merit.field_uncertainty.rms == pytest.approx(boot.uncertainty.rms)
    # the model file says so, and reads back
    from pipeline.model_file import parse_model_text
    from station.profile import Profile, Provenance

    mf = sep.profile(w, h, provenance=Provenance()).to_model_file()
    back = Profile.from_model_file(parse_model_text(mf.text(), "p.yaml"))
    assert back.details["strings"]["separated"] is True
    assert back.details["strings"]["fit_d_lens_alone_px"] == pytest.approx(alone.merit.fit.d)
    # too few orientations to separate: the lens fitted alone, and the reason
    close = (0, 4, 60, 64)  # two orientations 10 deg apart or more
    shots, _ = turning_harp_point_sets(lens, w, h, close, bends, axis=(497, 378), seed=7)
    few = calibrate_focus(shots, w, h, PipelineConfig(), 0, spec, turntable_deg=close)
    assert few.failure is None, few.failure
    assert few.details["strings"]["separated"] is False and "turntable angles" in few.details["strings"]["reason"]


def test_an_automatic_choice_with_turntable_angles_can_separate_the_strings():
    """``calibrate_shots(turntable_deg=...)`` (a session's ``pipeline.choice_folds: strings-separated``) chooses
    by folds fitted with the strings separated, and says so in the record a profile keeps; bent strings (0.04 px
    terms) had the plain folds choose radial2 for a lens with a rho^4 term (tests/pipeline/test_separated_cv.py)."""
    from pipeline.fitspec import CHOICE_FOLDS, CHOICE_FOLDS_PLAIN, FitSpec
    from pipeline.models import RadialModel
    from pipeline.select import SEPARATED_FOLDS
    from station.calibration import calibrate_shots, selection_record
    from station.config import PipelineConfig
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.002), center=(512, 366))
    turns = (0, 36, 72, 108, 144)
    bends = np.random.default_rng(1).normal(0.0, 0.04, (9, 3))
    shots, _ = turning_harp_point_sets(lens, w, h, turns, bends, axis=(497, 378), seed=4, step=60.0)
    cands = [FitSpec("radial", 2), FitSpec("radial", 4)]
    cal = calibrate_shots(shots, w, h, candidates=cands, turntable_deg=turns)
    assert cal.failure is None and cal.spec == cands[1]
    rec = selection_record(cal.selection)
    assert rec["folds"] == SEPARATED_FOLDS and "strings separated, turntable angles known" in rec["reason"]
    assert cal.fit.model is cal.selection.table[1].full_fit.model  # the fold's start: no second fit
    assert PipelineConfig().choice_folds == CHOICE_FOLDS_PLAIN and set(CHOICE_FOLDS) == {"plain", "strings-separated"}


def _kinked_harp():
    """A turning harp whose strings carry three cusps drawn at known places, through an exact radial lens
    (``tests.pipeline.harp_points.kinked_harp_point_sets``): ``(w, h, lens, turns, spec, drawn, shots)``."""
    from pipeline.fitspec import FitSpec
    from pipeline.models import RadialModel
    from tests.pipeline.harp_points import kinked_harp_point_sets

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4))
    turns = (0, 30, 60, 90, 120, 150)
    spec = FitSpec("radial", 4, True, True)
    drawn = {2: (120.0, 0.3, 10.0), 4: (-200.0, 0.3, 10.0), 6: (-80.0, -0.25, 8.0)}
    shots, _ = kinked_harp_point_sets(lens, w, h, turns, 11, drawn, axis=(497, 378), seed=4, noise=0.008)
    return w, h, lens, turns, spec, drawn, shots


def test_a_session_can_model_the_strings_kinks():
    """``pipeline.strings: separate-kinks``: the stored lens is fitted with each string's kinks found and modelled
    (``pipeline.harp_kinks``), the record lists them where they were drawn, and the lens is closer to the exact
    lens than with the bends alone separated. Truth: the drawn cusps and the exact lens map."""
    from pipeline.compare import compare_models
    from pipeline.harp_shape import fit_harp_shape
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig

    w, h, lens, turns, spec, drawn, shots = _kinked_harp()
    kinked = calibrate_focus(
        shots, w, h, PipelineConfig(strings="separate-kinks", field="none"), 0, spec, turntable_deg=turns
    )
    assert kinked.failure is None and kinked.details["strings"]["separated"] is True
    found = kinked.details["strings"]["kinks"]
    assert sorted(k["string"] for k in found) == sorted(drawn)
    for k in found:
        assert abs(k["at_px"] - drawn[k["string"]][0]) < 4.0
    bends = fit_harp_shape(shots, turns, w, h, spec)  # what pipeline.strings: separate stores
    err = [compare_models(m, lens, w, h, step=20).rms for m in (kinked.fit.model, bends.model)]
    assert err[0] < 0.5 * err[1], err


def test_a_sessions_field_stage_judges_its_folds_with_the_kinks_modelled():
    """With ``pipeline.strings: separate-kinks`` the field stage's folds find and model each string's kinks as the
    stored lens is fitted, and remove them from the held-out shot (``kink_t``): the model's CV d there is about the
    generator's noise, not the bends-only folds' (in which a field took the kinks' bumps near the turntable axis,
    ``benchmarks/RESULTS-residual-field.md``). Truth: the noise drawn."""
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig

    w, h, _, turns, spec, _, shots = _kinked_harp()
    cfg = PipelineConfig(strings="separate-kinks", field="auto")
    cal = calibrate_focus(shots, w, h, cfg, 0, spec, turntable_deg=turns)
    assert cal.failure is None and "residual field: " in cal.selection.reason
    row = next(r for r in cal.selection.table if r.candidate == spec)
    assert row.cv_d < 1.2 * 0.008, row.cv_d  # the bends-only folds: 0.0132 px (checked once)


def test_kinks_are_the_default_and_a_kink_free_harp_stores_what_separate_stores():
    """``pipeline.strings`` defaults to ``separate-kinks``; on strings with no kink it finds none and stores exactly
    what ``separate`` stores: lens, hold-out and field uncertainty (no false kink moves them). Truth: a harp drawn
    with no kink (``kinked_harp_point_sets`` with none). (The hold-out's folds and the bootstrap's replicates then
    do not scan at all, a matter of time: ``benchmarks/RESULTS-strings.md``.)"""
    from pipeline.fitspec import STRINGS_KINKS, FitSpec
    from pipeline.models import RadialModel
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig
    from tests.pipeline.harp_points import kinked_harp_point_sets

    assert PipelineConfig().strings == STRINGS_KINKS
    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4))
    turns = (0, 30, 60, 90, 120, 150)
    spec = FitSpec("radial", 4, True, True)
    shots, _ = kinked_harp_point_sets(lens, w, h, turns, 11, {}, axis=(497, 378), seed=4, noise=0.008)
    cals = [
        calibrate_focus(shots, w, h, PipelineConfig(strings=s, bootstrap=4, field="none"), 0, spec, turntable_deg=turns)
        for s in ("separate-kinks", "separate")
    ]
    kinked, bends = cals
    assert kinked.failure is None and kinked.details["strings"]["separated"] is True
    assert kinked.details["strings"]["kinks"] == [] and "kinks" not in bends.details["strings"]
    assert kinked.merit.holdout == bends.merit.holdout and kinked.merit.holdout is not None
    assert kinked.merit.field_uncertainty == bends.merit.field_uncertainty
    assert kinked.merit.field_uncertainty is not None and kinked.details["bootstrap_replicates"] == 4
    grid = np.mgrid[0:w:50, 0:h:50].reshape(2, -1).T.astype(float)
    assert np.array_equal(kinked.fit.model.undistort_points(grid), bends.fit.model.undistort_points(grid))


def test_a_two_axis_capture_hands_the_joint_fit_each_place_of_the_turntable_axis():
    """Issue 19 item 4/5, the station's side: shots about two turntable-axis places (the turntable carried sideways
    by a linear stage) are fitted with each shot's place (``axis_places``: its axis group, and the rough image shift
    of the stage's travel through the harp's pitch). Bows growing with the strings' distance from the axis are what
    a radial correction imitates about one axis; about two the shots tell them apart, so the stored lens is far
    closer to the exact lens than the lens alone (the joint fit refuses the shots when it is not told the places: no
    one axis makes them one harp). Truth: the
    generator's exact lens map and the axes it was drawn about. One place: the profile is the one made without
    places, byte for byte."""
    from pipeline.compare import compare_models
    from pipeline.fit import fit_distortion
    from pipeline.fitspec import FitSpec
    from pipeline.harp_shape import fit_harp_shape
    from pipeline.models import RadialModel
    from station.axis_places import AxisPlaces
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig
    from station.profile import Provenance
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 640, 480
    lens = RadialModel.for_image(
        w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(328, 234), tangential=(8e-4, -5e-4), prism=(4e-4, 0, -3e-4, 0)
    )
    spec = FitSpec("radial", 4, True, True)
    n = 23
    bends = np.zeros((n, 3))
    bends[:, 0] = 0.05 * (np.arange(n) - (n - 1) / 2) * 40.0 / 400.0  # bows growing with the distance from the axis
    turns = (0, 45, 90, 135)  # four angles: the same at each place, which alone cannot place its axis with three
    centre, shift = np.array(lens.center), np.array([100.0, 50.0])  # the axis 112 px either side of the middle
    left, _ = turning_harp_point_sets(lens, w, h, turns, bends, axis=centre - shift, spacing=40.0, step=40, seed=5)
    right, _ = turning_harp_point_sets(lens, w, h, turns, bends, axis=centre + shift, spacing=40.0, step=40, seed=6)
    shots, angles = left + right, turns + turns
    # the harp's strings 6 mm apart, 40 px in the image: 6.67 px per mm; the stage sent to -/+16.77 mm and read
    # back a little off, moving the axis 26.57 deg below +x in the image (given as 26.5)
    travel = float(np.hypot(*shift)) / (40.0 / 6.0)
    places = AxisPlaces((-travel,) * 4 + (travel,) * 4, (-travel + 0.01,) * 4 + (travel - 0.02,) * 4, 26.5, 6.0)
    cfg = PipelineConfig(strings="separate", field="none")
    two = calibrate_focus(shots, w, h, cfg, 0, spec, turntable_deg=angles, axis_places=places)
    assert two.failure is None and two.details["strings"]["separated"] is True, two.details.get("strings")
    # the same shots, the places not told: no one axis makes them one harp, and the joint fit says so (the lens
    # alone is what is left)
    one = fit_harp_shape(shots, angles, w, h, spec)
    assert not one and "do not agree about any one turntable axis" in one.reason, one
    err_two = compare_models(two.fit.model, lens, w, h, step=20).rms
    err_one = compare_models(fit_distortion(shots, w, h, **spec.fit_arguments()).model, lens, w, h, step=20).rms
    assert err_two < 0.6 * err_one, (err_two, err_one)
    axes = two.details["harp_health"]["axes"]
    # the scale from the pitch of the edges as measured (the lens's local scale in it: 1.2 % here)
    assert axes["shift_given"] is True and axes["px_per_mm"] == pytest.approx(40.0 / 6.0, rel=0.03)
    assert [p["position_mm"] for p in axes["places"]] == [-travel, travel]
    for p, drawn in zip(axes["places"], (centre - shift, centre + shift), strict=True):  # each place's axis found
        assert np.hypot(*(np.array(p["centre_px"]) - drawn)) < 2.0 and p["shots"] == 4
    assert axes["worst_off_px"] < 2.0 and axes["misplaced"] == [] and axes["limit_px"] == pytest.approx(20, rel=0.03)
    # one place: nothing changes (the profile's model file byte for byte; the harp's self-check made, the lens
    # fitted alone to keep the test short)
    same, cfg = AxisPlaces((5.0,) * 4, (5.0,) * 4, 26.5, 6.0), PipelineConfig(strings="ignore", field="none")
    at_one = calibrate_focus(left, w, h, cfg, 0, spec, turntable_deg=turns, axis_places=same)
    plain = calibrate_focus(left, w, h, cfg, 0, spec, turntable_deg=turns)
    text = [c.profile(w, h, provenance=Provenance()).to_model_file().text() for c in (at_one, plain)]
    assert text[0] == text[1] and "axes" not in at_one.details["harp_health"]


def test_a_session_whose_angles_cannot_place_the_harps_axis_says_so():
    """Issue 19 item 4: three turntable angles and a harp wider than the image cannot place the turntable axis
    (the strings' distances agree about a lattice of places, ``pipeline.harp_frame.harp_frame``): the session keeps
    the lens alone and records why, in the harp's self-check and in QA's check, rather than numbering the
    strings wrongly. Truth: the generator's uniform harp (27 strings 50 px apart about a known axis)."""
    from pipeline.fitspec import FitSpec
    from pipeline.models import RadialModel
    from station.calibration import calibrate_focus
    from station.config import PipelineConfig, QAConfig
    from station.qa.verdicts import evaluate
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366), tangential=(8e-4, -5e-4))
    turns, spec = (0, 60, 120), FitSpec("radial", 4, True, True)
    shots, _ = turning_harp_point_sets(lens, w, h, turns, np.zeros((27, 3)), axis=(530, 395), spacing=50.0, step=40)
    cal = calibrate_focus(shots, w, h, PipelineConfig(strings="separate", field="none"), 0, spec, turntable_deg=turns)
    assert cal.failure is None
    why, health = "the harp's axis is ambiguous with these turntable angles", cal.details["harp_health"]
    assert why in health["failure"] and "add angles spread over the half turn" in health["failure"]
    assert cal.details["strings"]["separated"] is False and why in cal.details["strings"]["reason"]
    checks = evaluate(cal.fit.model, w, h, 0.001, QAConfig(), harp_health=health).checks
    check = next(c for c in checks if c.name == "string_bend_max")
    assert check.passed is None and why in check.text  # reported with the verdict, not judged


def test_pipeline_field_auto_stores_a_residual_field_where_the_lens_has_one():
    """``pipeline.field: auto`` (the default): the session's model (given here, then chosen) gets a residual field when it holds
    on unseen orientations, judged with the strings separated (:func:`pipeline.select.select_field`); the stored
    lens, fitted with the strings separated, is then closer to the exact lens (a 0.03 px field behind 0.03 px
    string bows), the record says why, and the model file reads back with the field. ``none`` stores the radial
    model. Truth: the exact lens (field error modulo homography over the whole image)."""
    from dataclasses import replace

    from pipeline.compare import compare_models
    from pipeline.fitspec import FIELD_AUTO, FIELD_CHOICES, FIELD_NONE, FitSpec
    from pipeline.lens_population import lens_population
    from pipeline.model_file import parse_model_text
    from station.calibration import calibrate_focus, selection_record
    from station.config import PipelineConfig
    from station.profile import Profile, Provenance
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 1000, 750
    lens = lens_population(2, 1, w, h, field=True, field_rms_px=(0.03, 0.03))[0].model
    turns = (0, 30, 60, 90, 120, 150)
    bends = np.random.default_rng(2).normal(0.0, 0.03, (13, 3))
    shots, _ = turning_harp_point_sets(lens, w, h, turns, bends, axis=(497, 378), step=60.0, seed=2)
    spec = FitSpec("radial", 4, True, True)
    assert PipelineConfig().field == FIELD_AUTO and set(FIELD_CHOICES) == {"none", "auto"}
    cfg = PipelineConfig(strings="separate")  # the bends only: no kink scan, which this harp has no use for
    plain = calibrate_focus(shots, w, h, replace(cfg, field=FIELD_NONE), 0, spec, turntable_deg=turns)
    auto = calibrate_focus(shots, w, h, cfg, 0, spec, turntable_deg=turns)
    assert plain.failure is None and auto.failure is None, auto.failure
    assert plain.spec == spec and plain.selection is None
    assert auto.spec.field is not None and auto.spec.label.startswith("radial4+tangential+prism+field")
    assert auto.details["strings"]["separated"] is True
    err_plain = compare_models(plain.fit.model, lens, w, h, step=20).rms
    err_auto = compare_models(auto.fit.model, lens, w, h, step=20).rms
    assert err_auto < 0.6 * err_plain, (err_auto, err_plain)
    rec = selection_record(auto.selection)
    assert (
        rec["reason"].startswith("radial4+tangential+prism given; residual field: ")
        and "strings separated" in rec["reason"]
    )
    back = Profile.from_model_file(
        parse_model_text(auto.profile(w, h, provenance=Provenance()).to_model_file().text(), "p.yaml")
    )
    assert back.spec == auto.spec
    p = np.random.default_rng(0).uniform([0, 0], [w - 1, h - 1], (50, 2))
    assert np.allclose(back.model.undistort_points(p), auto.fit.model.undistort_points(p), atol=1e-9)
    # an automatic choice first, then the field on top of it
    few = [FitSpec("radial", 2), spec]
    from station.calibration import calibrate_shots

    chosen = calibrate_shots(shots, w, h, candidates=few, field=FIELD_AUTO, field_turntable_deg=turns)
    assert chosen.failure is None and chosen.spec.field is not None and chosen.spec.degree == 4
    assert "; residual field: " in chosen.selection.reason and chosen.selection.choice == chosen.spec
    with pytest.raises(ValueError, match="unknown field choice"):
        calibrate_shots(shots, w, h, spec, field="always")


def test_noisy_shot_warnings_name_the_shots_the_correction_leaves_far_less_straight():
    """Two of six shots carry a 0.05 px wave across every edge over 0.01 px noise (truth: which shots were waved,
    ``tests.pipeline.test_harp_shape._waved``): both named; the same shots without the wave, or two shots only, none."""
    from pipeline.fit import fit_distortion
    from pipeline.models import RadialModel
    from tests.pipeline.harp_points import turning_harp_point_sets
    from tests.pipeline.test_harp_shape import _waved

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366))
    turns = (0, 30, 60, 90, 120, 150)
    shots, _ = turning_harp_point_sets(lens, w, h, turns, np.zeros((11, 3)), step=10, noise=0.01, seed=3)
    names = [f"shot{i}.pgm" for i in range(6)]
    waved = _waved(shots, {2, 5}, 0.05, 300.0, 3)
    found = noisy_shot_warnings(fit_distortion(waved, w, h, model="radial", degree=4), names)
    assert [x.split(":")[0] for x in found] == ["shot2.pgm", "shot5.pgm"] and "turn the harp" in found[0]
    assert noisy_shot_warnings(fit_distortion(shots, w, h, model="radial", degree=4), names) == []
    assert noisy_shot_warnings(fit_distortion(waved[1:3], w, h, model="radial", degree=4), names[1:3]) == []


def _turning_lens_shots(moves_px):
    """Six shots of a straight harp turning 0..150 deg, each through the same lens with its distortion centre moved
    by ``moves_px[i]`` (hand-chosen; all zero: a stable lens)."""
    from pipeline.models import RadialModel
    from tests.pipeline.harp_points import turning_harp_point_sets

    w, h = 1000, 750
    shots = []
    for i, (turn, (mx, my)) in enumerate(zip((0, 30, 60, 90, 120, 150), moves_px)):
        lens = RadialModel.for_image(
            w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512 + mx, 366 + my), tangential=(8e-4, -5e-4)
        )
        shots += turning_harp_point_sets(lens, w, h, (turn,), np.zeros((11, 3)), axis=(497, 378), seed=10 + i)[0]
    return shots, w, h


def test_a_lens_whose_centre_moves_between_shots_is_told_from_a_stable_one():
    """The held-out orientations' own axis shift (pipeline.own_shift) in a session's hold-out: a lens whose distortion
    centre moves by 5-7 px between shots (by hand) leaves each held-out orientation bent by its own move, which moving
    the fold's correction takes back to the noise: ``moving``, and the QA text says what to do; the same lens held
    still: nothing of its own (median ratio near 1), no advice."""
    from station.calibration import calibrate_shots
    from station.config import QAConfig
    from station.moving_lens import OWN_SHIFT_RATIO
    from station.qa.verdicts import evaluate

    spec = parse("radial4+tangential+prism")
    got = {}
    for name, moves in (
        ("moving", [(0, 0), (6, -4), (-5, 3), (4, 5), (-6, -2), (3, -6)]),
        ("stable", [(0, 0)] * 6),
    ):
        shots, w, h = _turning_lens_shots(moves)
        cal = calibrate_shots(shots, w, h, spec, holdout="orientations")
        own = cal.details["own_shift"]
        v = evaluate(cal.fit.model, w, h, cal.merit.holdout.d, QAConfig(), own_shift=own)
        got[name] = (own, next(c for c in v.checks if c.name == "holdout_own_shift"), cal)
    own, check, cal = got["moving"]
    assert own["judged"] and own["moving"] and own["ratio_median"] < 0.3 and own["limit"] == OWN_SHIFT_RATIO
    held = [o["d_held_px"] for o in own["per_orientation"]]
    assert len(held) == 6 and min(held) > 0.01  # every moved shot bent beyond its 0.003 px noise, held out
    assert all(o["d_own_px"] < 0.008 for o in own["per_orientation"])
    assert check.passed is None and "switch stabilisation off" in check.text and check.value == own["ratio_median"]
    # the model file keeps it, and QA judging the file reports it the same
    from pipeline.model_file import parse_model_text
    from station.profile import Profile, Provenance
    from station.qa.verdicts import qa_verdict

    back = Profile.from_model_file(
        parse_model_text(cal.profile(w, h, provenance=Provenance()).to_model_file().text(), "p.yaml")
    )
    assert back.details["own_shift"] == own
    assert next(c for c in qa_verdict(back).checks if c.name == "holdout_own_shift").text == check.text
    own, check, _ = got["stable"]
    assert own["judged"] and not own["moving"] and own["ratio_median"] > 0.95
    assert check.passed is None and "stabilisation" not in check.text
