"""The harp checks itself (issue 19 item 4): strings' own bends fitted with the lens, on shots of a
turning harp whose strings are bent by known amounts (truth: the generator's exact geometry,
``tests.pipeline.harp_points.turning_harp_point_sets``, and the exact lens map)."""

import numpy as np
import pytest

from pipeline.compare import compare_models
from pipeline.edgeset import FitResult
from pipeline.fit import correction_scale, fit_distortion
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import (
    BEND_LIMIT_PX,
    STRING_RIDGE,
    StringShape,
    fit_harp_shape,
    legendre,
    own_bends,
    seen_twice,
)
from pipeline.lens_population import lens_population
from pipeline.models.base import DistortionModel
from pipeline.models.radial_field import RadialFieldParametrisation
from tests.pipeline.harp_points import kinked_harp_point_sets, turning_harp_point_sets
from tests.pipeline.harp_support import LENS, H, W, drawn_corrected

SPEC = FitSpec("radial", 4, True, True)
TURNS = (0, 30, 60, 90, 120, 150)


def _true_bend(coef, span):
    u = np.linspace(span[0], span[1], 401)
    return float(np.max(np.abs(np.asarray(coef) @ legendre(u, (2, 3, 4)))))


def _fits(bends, turns=TURNS, given=None, **kw):
    shots, _ = turning_harp_point_sets(LENS, W, H, turns, bends, axis=(497, 378), seed=4, **kw)
    plain = fit_distortion(shots, W, H, **SPEC.fit_arguments())
    return plain, fit_harp_shape(shots, turns if given is None else given, W, H, SPEC, plain=plain)


def test_bent_strings_are_found_and_the_lens_is_freed_of_them():
    bends = np.zeros((11, 3))
    bends[4] = (0.05, 0.0, 0.0)  # a bow of 0.05 px (P2)
    bends[6] = (0.0, 0.04, -0.02)  # an S and a W
    plain, fit = _fits(bends)
    assert fit, fit
    assert fit.frame.sign == 1 and fit.frame.angle0_deg == pytest.approx(20.0, abs=0.2)
    assert np.hypot(fit.frame.centre[0] - 497, fit.frame.centre[1] - 378) < 2.0
    found = {s.index: s for s in fit.strings}
    assert sorted(found) == list(range(11)) and all(s.shots == len(TURNS) for s in fit.strings)
    for k in (4, 6):  # recovered within 20 %
        assert found[k].bend_px == pytest.approx(_true_bend(bends[k], found[k].span), rel=0.2)
    assert all(found[k].bend_px < 0.006 for k in found if k not in (4, 6))
    assert {s.index for s in fit.bent_strings(BEND_LIMIT_PX)} == {4, 6}
    # the lens no longer bends itself to the strings: closer to the exact lens, and the lines straighter
    plain_err = compare_models(plain.model, LENS, W, H, step=25).rms
    joint_err = compare_models(fit.model, LENS, W, H, step=25).rms
    assert joint_err < 0.5 * plain_err
    assert fit.d_after < 0.7 * plain.d_after
    d = fit.to_dict()
    assert d["strings"][4]["bend_px"] == pytest.approx(found[4].bend_px) and d["frame"]["sign"] == 1


def test_a_straight_harp_shows_no_bend_and_costs_the_lens_nothing():
    plain, fit = _fits(np.zeros((11, 3)))
    assert fit and max(s.bend_px for s in fit.strings) < 0.004 and not fit.bent_strings()
    assert (
        compare_models(fit.model, LENS, W, H, step=25).rms
        < 1.1 * compare_models(plain.model, LENS, W, H, step=25).rms + 2e-4
    )


def test_strings_the_plain_fit_rejects_in_every_shot_are_still_checked_and_the_lens_is_fitted_without_them():
    # Edges this clean make the plain fit's outlier rule (5x the median edge RMS) reject the bent strings' edges,
    # in most shots or all: without them the check would pass a harp with two strings bent beyond the limit.
    bends = np.zeros((11, 3))
    bends[4] = (0.03, 0.0, 0.0)
    bends[6] = (0.0, 0.03, 0.0)
    shots, _ = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=(497, 378), seed=4, noise=3e-4)
    plain = fit_distortion(shots, W, H, **SPEC.fit_arguments())
    assert len(plain.rejected) >= 16
    blind = fit_harp_shape(shots, TURNS, W, H, SPEC, plain=plain, readmit=False)
    assert blind and len(blind.strings) < 11  # a string rejected in every shot is not even counted
    fit = fit_harp_shape(shots, TURNS, W, H, SPEC, plain=plain)
    assert fit, fit
    found = {s.index: s for s in fit.strings}
    assert sorted(found) == list(range(11)) and all(s.shots == len(TURNS) for s in fit.strings)
    for k in (4, 6):  # measured 1.00 and 0.99 of the drawn bend
        assert found[k].bend_px == pytest.approx(_true_bend(bends[k], found[k].span), rel=0.05)
    assert {s.index for s in fit.bent_strings(BEND_LIMIT_PX)} == {4, 6} and not fit.rejected
    # the lens is the joint fit of the plain fit's edges, with or without the edges given back to the check
    assert fit.model.to_dict() == blind.model.to_dict()


def test_an_edge_given_back_that_its_string_does_not_explain_is_left_out_and_one_on_no_string_stays_out():
    bends = np.zeros((11, 3))
    bends[5] = (0.04, 0.0, 0.0)
    shots, offsets = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=(497, 378), seed=4)
    shots = [list(s) for s in shots]
    rng = np.random.default_rng(7)
    # shot 2: a copy of one of its edges wiggling by 0.3 px (lies on a string, its string cannot follow it)
    wiggly = shots[2][8].copy()
    t = np.linspace(0.0, 1.0, len(wiggly))
    d = wiggly[-1] - wiggly[0]
    wiggly += 0.3 * np.sin(6 * np.pi * t)[:, None] * np.array([-d[1], d[0]]) / np.hypot(*d)
    shots[2].append(wiggly)
    # shot 3: a curved edge half way between two strings (no string there: a frame's or a shadow's)
    stray = shots[3][8] + 30.0 * np.array([-1.0, 1.0]) / np.sqrt(2.0)
    stray = stray + 0.5 * ((np.linspace(-1, 1, len(stray)) ** 2)[:, None]) + rng.normal(0, 0.003, stray.shape)
    shots[3].append(stray)
    plain = fit_distortion(shots, W, H, **SPEC.fit_arguments())
    out = {(r.image, r.line) for r in plain.rejected}
    assert (2, len(shots[2]) - 1) in out and (3, len(shots[3]) - 1) in out
    fit = fit_harp_shape(shots, TURNS, W, H, SPEC, plain=plain)
    assert fit, fit
    assert [(r.image, r.line) for r in fit.rejected] == [(2, len(shots[2]) - 1)]
    assert "outlier of the strings' fit" in fit.rejected[0].reason
    assert len(fit.strings) == 11 and {s.index for s in fit.bent_strings()} == {5}


def test_the_bends_reported_are_not_shrunk_by_the_ridge_that_steadies_the_lens():
    # the joint fit's own coefficients, under its ridge, carried 0.85 and 0.92 of these bends; each string's terms
    # fitted again with the lens held and no ridge carry 0.96-0.97 (noise of 0.003 px: no edge is rejected)
    bends = np.zeros((11, 3))
    bends[4] = (0.03, 0.0, 0.0)
    bends[6] = (0.0, 0.02, 0.0)
    plain, fit = _fits(bends, noise=0.003)
    assert fit and not plain.rejected
    for k in (4, 6):
        s = next(s for s in fit.strings if s.index == k)
        assert s.bend_px == pytest.approx(_true_bend(bends[k], s.span), rel=0.07)
        assert abs(s.bend_px - _true_bend(bends[k], s.span)) < 2 * s.bend_se_px


def test_a_turntable_seen_turning_the_other_way():
    bends = np.zeros((11, 3))
    bends[5] = (0.04, 0.0, 0.0)
    turns = tuple(-t for t in TURNS)
    _, fit = _fits(bends, turns=turns, given=TURNS)  # the harp turns clockwise in the image
    assert fit and fit.frame.sign == -1
    assert {s.index for s in fit.bent_strings()} == {5}


def test_angles_that_do_not_match_the_shots_are_refused():
    _, fit = _fits(np.zeros((11, 3)), given=(0, 90, 30, 150, 60, 120))
    assert not fit and "do not follow the turntable angles" in fit.reason
    _, fit = _fits(np.zeros((11, 3)), given=(0, 30))
    assert not fit and "6 shots but 2 turntable angles" in fit.reason


def test_a_harp_moved_between_two_turntable_axes_frees_the_lens_of_what_one_axis_cannot():
    # Bows growing with the string's distance from the axis: about one axis at the distortion centre a radial
    # correction imitates them exactly (module docstring), so one axis gives them to the lens; the same harp
    # seen about two axes 170 px either side (its turntable moved, the shift not given) tells them apart.
    n = 23
    q = (np.arange(n) - (n - 1) / 2) * 60.0
    bends = np.zeros((n, 3))
    bends[:, 0] = 0.05 * q / 600.0
    bends[8, 1] = 0.04  # and one string with an S of its own
    centre, shift = np.array(LENS.center), np.array([150.0, 75.0])
    one_turn = tuple(range(0, 180, 15))
    one, _ = turning_harp_point_sets(LENS, W, H, one_turn, bends, axis=centre, step=40, seed=4)
    left, _ = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=centre - shift, step=40, seed=5)
    right, _ = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=centre + shift, step=40, seed=6)
    plain = fit_distortion(one, W, H, **SPEC.fit_arguments())
    fit = fit_harp_shape(one, one_turn, W, H, SPEC, plain=plain)
    err_one = compare_models(fit.model, LENS, W, H, step=25).rms
    shots, groups = left + right, ["left"] * 6 + ["right"] * 6
    plain = fit_distortion(shots, W, H, **SPEC.fit_arguments())
    # the default ridge keeps about half of what only two axes see (pipeline.harp_shape: chosen on realistic
    # renders); a ridge ten times weaker lets the shots decide
    default = fit_harp_shape(shots, TURNS + TURNS, W, H, SPEC, plain=plain, axis_groups=groups)
    fit = fit_harp_shape(shots, TURNS + TURNS, W, H, SPEC, plain=plain, axis_groups=groups, ridge=0.1 * STRING_RIDGE)
    assert default and fit, (default, fit)
    assert err_one > 0.005 and err_one > 1.5 * compare_models(default.model, LENS, W, H, step=25).rms
    assert err_one > 2.0 * compare_models(fit.model, LENS, W, H, step=25).rms
    axes = dict(fit.axis_groups)
    assert np.hypot(*(np.array(axes["left"].centre) - (centre - shift))) < 2.0
    assert np.hypot(*(np.array(axes["right"].centre) - (centre + shift))) < 2.0
    checked = 0
    for s in fit.strings:  # each string's drawn bend, over the stretch the fit saw, recovered within 20 %
        k = int(round(s.offset_px / 60.0 + (n - 1) / 2))
        true = _true_bend(bends[k], s.span)
        if s.shots >= 6 and true > 0.01:
            assert s.bend_px == pytest.approx(true, rel=0.2), k
            checked += 1
    assert checked >= 12
    assert set(fit.to_dict()["axis_groups"]) == {"left", "right"}


def test_axis_groups_that_do_not_match_the_shots_are_refused():
    shots, _ = turning_harp_point_sets(LENS, W, H, TURNS, np.zeros((11, 3)), axis=(497, 378), seed=4)
    fit = fit_harp_shape(shots, TURNS, W, H, SPEC, axis_groups=[0, 0, 1])
    assert not fit and "6 shots but 3 axis groups" in fit.reason
    fit = fit_harp_shape(shots, TURNS, W, H, SPEC, axis_groups=[0, 0, 0, 1, 1, 1], axis_shifts={0: (0.0, 0.0)})
    assert not fit and "no axis shift for axis group 1" in fit.reason


# ------------------------------------------------------------------ the harp's frame in the joint fit
def test_four_shots_45_degrees_apart_number_every_string_and_find_its_kinks():
    # the geometry in which the frame was once put a half pitch off (benchmarks/RESULTS-strings.md, "half-pitch
    # ambiguity"): 9 strings 60 px apart, 0/45/90/135; each string now one string in all four shots, its kink
    # found where it was drawn with its area (2 h lambda) within 30 %
    turns = (0, 45, 90, 135)
    drawn = {2: (120.0, 0.3, 10.0), 4: (-200.0, 0.3, 10.0), 6: (-80.0, -0.25, 8.0)}
    shots, offsets = kinked_harp_point_sets(LENS, W, H, turns, 9, drawn, axis=(497, 378), seed=4, noise=0.008)
    fit = fit_harp_shape(
        shots, turns, W, H, SPEC, plain=fit_distortion(shots, W, H, **SPEC.fit_arguments()), kinks=True
    )
    assert fit, fit
    assert np.hypot(fit.frame.centre[0] - 497, fit.frame.centre[1] - 378) < 2.0
    assert [(s.shots, s.edges) for s in fit.strings] == [(4, 8)] * 9
    assert np.allclose([s.offset_px for s in fit.strings], offsets, atol=2.0)  # the outer ones seen in corners
    found = {k.string: k for k in fit.kinks}
    assert sorted(found) == sorted(drawn)
    for s, (at, h, lam) in drawn.items():
        assert abs(found[s].at_px - at) < 4.0 and found[s].area_px2 == pytest.approx(2 * h * lam, rel=0.3)


def test_a_frame_the_turntable_angles_cannot_place_refuses_the_fit_with_the_reason():
    # three shots of a harp wider than the image (tests/pipeline/test_harp_frame.py): harp_frame refuses the frame,
    # and the joint fit says why instead of numbering the strings wrongly
    turns = (0, 60, 120)
    corrected, _, _ = drawn_corrected(turns, 29, 50.0, (0.7, 0.4), seed=2)
    shots = [[LENS.distort_points(e) for e in s] for s in corrected]
    fit = fit_harp_shape(shots, turns, W, H, SPEC, plain=fit_distortion(shots, W, H, **SPEC.fit_arguments()))
    assert not fit and "add angles spread over the half turn" in fit.reason


def _weak_field_shots() -> tuple[DistortionModel, list[list[np.ndarray]], tuple[int, ...], FitSpec, FitResult]:
    """A lens with a 0.03 px field, strings bowed a few hundredths, noisy edges, one turntable axis: the shots,
    angles, a spec with a weakly penalised field and its plain fit, on which the joint fit without the axis gauge
    shrinks the image."""
    lens = lens_population(3, 1, W, H, field=True, field_rms_px=(0.03, 0.03))[0].model
    bends = np.random.default_rng(3).normal(0.0, 0.03, (13, 3))
    turns = (0, 30, 60, 90, 150)
    shots, _ = turning_harp_point_sets(lens, W, H, turns, bends, axis=(497, 378), step=60.0, seed=3, noise=0.03)
    spec = FitSpec("radial", 4, True, True, field=(8, 6), field_penalty=1e-4)
    plain = fit_distortion(shots, W, H, **spec.fit_arguments())
    assert plain, plain
    return lens, shots, turns, spec, plain


def test_a_joint_fit_with_a_weak_field_keeps_the_images_scale():
    """With a weakly penalised field the free distortion centre could slide far out while the correction shrank
    the image (straighter in corrected pixels): on these shots the joint fit shrank the image to 0.16 of its size,
    0.32 px off the lens, and was made again with the centre held. The field's part that turns with the harp about
    its axis is now held off the field (``axis_basis``; a shrink about the axis is such a part), and the fit keeps
    the lens's scale by itself. Truth: the exact lens map. (``tests/pipeline/test_fit.py`` tests the collapse's
    measure.)"""
    lens, shots, turns, spec, plain = _weak_field_shots()
    fit = fit_harp_shape(shots, turns, W, H, spec, plain=plain)
    assert fit, fit
    assert abs(correction_scale(fit.model, W, H) - correction_scale(lens, W, H)) < 0.01
    err_plain = compare_models(plain.model, lens, W, H, step=25).rms
    assert compare_models(fit.model, lens, W, H, step=25).rms < err_plain
    assert not any("centre held" in w for w in fit.warnings), fit.warnings


def test_a_joint_fit_that_collapses_the_image_is_made_again_with_the_centre_held(monkeypatch):
    """What the axis gauge does not cover (a collapse of another kind) falls back on the re-fit with the centre
    held (``_solve_joint``). Without the gauge these shots collapse the free-centre fit; the fit kept
    is the held one, says so, keeps the lens's scale and is nearer the exact lens map than the plain fit."""
    lens, shots, turns, spec, plain = _weak_field_shots()
    monkeypatch.setattr(RadialFieldParametrisation, "with_axis_gauge", lambda self, *centres: self)
    fit = fit_harp_shape(shots, turns, W, H, spec, plain=plain)
    assert fit, fit
    assert any("centre held" in w for w in fit.warnings), fit.warnings
    assert abs(correction_scale(fit.model, W, H) - correction_scale(lens, W, H)) < 0.01
    err_plain = compare_models(plain.model, lens, W, H, step=25).rms
    assert compare_models(fit.model, lens, W, H, step=25).rms < err_plain


def test_a_joint_fit_about_two_axes_holds_the_field_off_what_turns_about_either():
    """About one axis a field's part that turns with the harp is a set of string bends and is held off the field;
    about two axes each axis's part is such a set in that axis's shots, and a realistic session about two places
    let a field take bends through it (``benchmarks/RESULTS-residual-field.md``). The field a two-axis joint fit
    stores has no part that turns about either drawn axis (truth: ``axis_basis`` about the drawn axes, distorted
    through the exact lens, not the axes the fit found), and the lens is nearer the exact lens map than the plain
    fit's."""
    from pipeline.models.radial_field import RadialFieldModel, axis_basis

    n = 23
    q = (np.arange(n) - (n - 1) / 2) * 60.0
    bends = np.random.default_rng(7).normal(0.0, 0.03, (n, 3))
    bends[:, 0] += 0.05 * (q / 600.0) ** 2
    centre, shift = np.array(LENS.center), np.array([120.0, 60.0])
    axes = (centre - shift, centre + shift)
    left, _ = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=axes[0], step=40, seed=5, noise=0.03)
    right, _ = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=axes[1], step=40, seed=6, noise=0.03)
    spec = FitSpec("radial", 4, True, True, field=(8, 6), field_penalty=1e-4)
    shots = left + right
    plain = fit_distortion(shots, W, H, **spec.fit_arguments())
    fit = fit_harp_shape(shots, TURNS + TURNS, W, H, spec, plain=plain, axis_groups=["L"] * 6 + ["R"] * 6)
    assert fit and isinstance(fit.model, RadialFieldModel), fit
    m = fit.model
    c = np.concatenate([m.cx.ravel(), m.cy.ravel()])
    for axis in axes:
        turning = axis_basis(tuple(LENS.distort_points(np.asarray([axis]))[0]), m.bounds, m.shape)
        assert np.linalg.norm(turning.T @ c) < 0.01, axis  # px of coefficients (1.2 gauged about one axis, 5.6-5.8 not)
    assert compare_models(m, LENS, W, H, step=25).rms < 0.6 * compare_models(plain.model, LENS, W, H, step=25).rms


def _p4(u):
    """Legendre P4 written out by hand (not through ``legendre``)."""
    return (35 * u**4 - 30 * u**2 + 3) / 8


def _string(k, p4=0.0, span=(-1.3, 1.3), twice=(-1.3, 1.3)):
    return StringShape(k, 60.0 * k, (2, 3, 4), (0.0, 0.0, p4), (1e-3,) * 3, span, 6, 6, 600, 0.0, 1e-3, twice)


def test_the_stretch_two_shots_see_is_the_hull_of_the_overlaps_of_the_shots_stretches():
    u = np.concatenate([np.linspace(-1.3, 0.2, 50), np.linspace(-0.5, 0.8, 50), np.linspace(0.6, 1.4, 50)])
    shot = np.repeat([4, 7, 9], 50)
    # shots 4 and 7 overlap on [-0.5, 0.2], 7 and 9 on [0.6, 0.8]
    assert seen_twice(u, shot) == pytest.approx((-0.5, 0.8))
    assert np.isnan(seen_twice(u[:100], np.zeros(100, np.intp))).all()  # one shot: nothing seen twice
    assert np.isnan(seen_twice(np.r_[u[:50], u[100:]], np.repeat([4, 9], 50))).all()  # two shots apart


def test_a_string_is_judged_within_half_the_diagonal_and_beyond_it_only_where_two_shots_see_it():
    """Three strings with the same P4 term of 0.005 px (0.005 px at u = +-1, 0.0327 px at u = +-1.3: truth from
    the polynomial written by hand), among five straight ones: seen by two shots out to u = +-1.3 its own bend is
    the end's; seen twice only over [-0.9, 0.9], or by no two shots, the ends beyond u = +-1 that one shot sees are
    not judged and the bend is the one at u = +-1; a straight string has none."""
    a = 0.005
    strings = [_string(k) for k in range(5)] + [
        _string(5, a),
        _string(6, a, twice=(-0.9, 0.9)),
        _string(7, a, twice=(float("nan"), float("nan"))),
    ]
    own = own_bends(strings)
    assert own[5] == pytest.approx(a * _p4(1.3), rel=1e-9)
    assert own[6] == pytest.approx(a * _p4(1.0), rel=1e-3) and own[7] == pytest.approx(a * _p4(1.0), rel=1e-3)
    assert max(own[k] for k in range(5)) == 0.0


def _waved(shots, which, amp, period, seed):
    """``shots`` with a slow wave across every edge of the shots ``which`` (``amp`` px, ``period`` px along the
    edge, a random phase per edge): the phase error of edges that run along the pixel grid."""
    rng = np.random.default_rng(seed)
    out = []
    for i, lines in enumerate(shots):
        new = []
        for p in lines:
            d = (p[-1] - p[0]) / np.hypot(*(p[-1] - p[0]))
            s = (p - p[0]) @ d
            wave = amp * np.sin(2 * np.pi * s / period + rng.uniform(0, 2 * np.pi)) if i in which else 0.0 * s
            new.append(p + wave[:, None] * np.array([-d[1], d[0]]))
        out.append(new)
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_shots_measured_far_worse_than_the_others_are_weighed_by_their_variance_in_the_harp_check(seed):
    """Two of six shots carry a wave of 0.05 px and 300 px along every edge (edges along the pixel grid, whose
    sub-pixel phase drifts slowly, are measured so: ``SHOT_NOISE_FACTOR``), over noise of 0.01 px. Unweighed, the
    waves bent straight strings beyond the limit (0.025-0.031 px on these seeds); weighed, only the string bowed on
    purpose is bent, within 20 % of its drawn bow (truth: P2 written by hand), and the two shots are named."""
    bends = np.zeros((11, 3))
    bends[4] = (0.03, 0.0, 0.0)
    shots, _ = turning_harp_point_sets(LENS, W, H, TURNS, bends, axis=(497, 378), seed=seed, step=10, noise=0.01)
    shots = _waved(shots, {1, 4}, 0.05, 300.0, seed)
    fit = fit_harp_shape(shots, TURNS, W, H, SPEC, plain=fit_distortion(shots, W, H, **SPEC.fit_arguments()))
    assert fit, fit
    assert [i for i, _ in fit.noisy_shots] == [1, 4] and all(r > 3 for _, r in fit.noisy_shots)
    assert {s.index for s in fit.bent_strings()} == {4}
    bow = next(s for s in fit.strings if s.index == 4)
    u = np.linspace(*bow.span, 401)
    assert bow.bend_px == pytest.approx(float(np.max(np.abs(0.03 * 0.5 * (3 * u**2 - 1)))), rel=0.2)
    assert fit.to_dict()["noisy_shots"].keys() == {"1", "4"}
