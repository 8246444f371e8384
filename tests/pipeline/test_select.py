import numpy as np
import pytest

from pipeline.cross_validation import FALLBACK
from pipeline.fitspec import FitSpec
from pipeline.models import RadialModel
from pipeline.select import select_model
from tests.pipeline.harp_points import harp_point_sets
from tests.pipeline.rendered_shots import real_shots

W, H = 1000, 750
DECENTRED = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02, 0.0, 0.003), center=(530, 355), tangential=(0.001, -0.0007))
CANDS = (FitSpec("radial", 2), FitSpec("radial", 4, True), FitSpec("radial", 4, True, True), FitSpec("poly", 5))


def test_cv_picks_the_simplest_model_that_generalises():
    shots = harp_point_sets(DECENTRED, W, H, (0, 45, 90, 135), noise=0.005, seed=5)
    sel = select_model(shots, W, H, candidates=CANDS, stop_factor=None)  # every fold of every candidate
    assert sel.folds == "images"
    assert sel.choice == FitSpec("radial", 4, True)
    rows = {r.candidate.label: r for r in sel.table}
    assert len(rows) == 4 and all(len(r.fold_d) == 4 for r in rows.values())
    assert rows["radial4+tangential"].cv_d < 0.006  # holdout d at the point noise (0.005)
    assert rows["radial2"].cv_d > 2 * rows["radial4+tangential"].cv_d  # too simple
    # richer models fit as well but do not beat it by more than the tolerance: not chosen
    assert rows["radial4+tangential+prism"].n_params > rows["radial4+tangential"].n_params
    assert "radial4+tangential" in sel.reason and "leave-one-shot-out" in sel.reason
    d = sel.to_dict()
    assert d["label"] == "radial4+tangential" and len(d["table"]) == 4


def test_two_shots_fall_back_to_alternate_edge_folds():
    shots = harp_point_sets(DECENTRED, W, H, (0, 90), noise=0.005, seed=5)
    sel = select_model(shots, W, H, candidates=CANDS[:2])
    assert sel.folds == "edges" and "alternate-edge" in sel.reason
    assert sel.choice == FitSpec("radial", 4, True)


def test_no_candidate_possible_gives_the_fallback_and_says_why():
    shots = harp_point_sets(DECENTRED, W, H, (30, 31, 32), noise=0.005, seed=5)
    sel = select_model(shots, W, H, candidates=CANDS[:2])
    assert sel.choice == FALLBACK and sel.folds == "none"
    assert "orientation" in sel.reason
    assert all(r.failure and not np.isfinite(r.cv_d) for r in sel.table)


def test_real_photos_radial_generalises_polynomial_does_not(real_harp_dir):
    """Issue 3 item 3: leave-one-shot-out over the 3 real shots prefers the physical model."""
    real = real_shots(str(real_harp_dir))
    w, h, _ = real[0]
    cands = (FitSpec("radial", 4, True, True), FitSpec("poly", 5))
    sel = select_model([s for _, _, s in real], w, h, candidates=cands, stop_factor=None)
    rows = {r.candidate.label: r for r in sel.table}
    print({k: (round(r.cv_d, 4), [round(v, 4) for v in r.fold_d]) for k, r in rows.items()})
    assert sel.choice == cands[0]
    assert max(rows["radial4+tangential+prism"].fold_d) <= 0.1
    assert rows["poly5"].cv_d > 10 * rows["radial4+tangential+prism"].cv_d


def test_edge_folds_hold_out_whole_strings_not_one_side_of_each():
    # measure() lists a string's two edges next to each other (lines 2k, 2k+1: one string).
    # Holding out one edge while fitting its twin 3 px away leaks the held-out string into the fit.
    from pipeline.cross_validation import cv_folds

    lines = [[np.full((6, 2), 10.0 * i + j) for j in range(8)] for i in range(2)]
    for train, held in cv_folds(lines, "edges"):
        held_ids = {float(p[0, 0]) for p in held}
        train_ids = {float(p[0, 0]) for s in train for p in s}
        assert held_ids and train_ids and not held_ids & train_ids
        held_strings = {(int(v) // 10, int(v) % 10 // 2) for v in held_ids}
        train_strings = {(int(v) // 10, int(v) % 10 // 2) for v in train_ids}
        assert not held_strings & train_strings


def test_a_non_finite_held_out_edge_does_not_void_the_cross_validation():
    # the fit rejects an edge with non-finite points; the held-out measure must skip it too
    shots = harp_point_sets(DECENTRED, W, H, (0, 45, 90, 135), noise=0.005, seed=5)
    shots[1] = list(shots[1]) + [np.array([[1.0, np.nan]] * 10)]
    sel = select_model(shots, W, H, candidates=CANDS[:2])
    assert sel.folds == "images" and all(np.isfinite(r.cv_d) for r in sel.table)
    assert sel.choice == FitSpec("radial", 4, True)


def test_a_simpler_model_measurably_worse_is_not_chosen():
    """One standard error, paired over the held-out edges (pipeline.select): a lens with thin-prism
    terms gets them although the CV d of the model without is only 1.8 % higher (inside the old
    5 % + 0.001 px tolerance, which chose it); without prism terms in the lens, the simpler wins."""
    cands = (FitSpec("radial", 4), FitSpec("radial", 4, True, True))
    for prism, expected in ((8e-4, cands[1]), (0.0, cands[0])):
        lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02), prism=(prism, 0.0, -prism, 0.0) if prism else None)
        shots = harp_point_sets(lens, W, H, (0, 30, 60, 90, 120, 150), noise=0.005, seed=7)
        sel = select_model(shots, W, H, candidates=cands)
        cv = {r.candidate: r.cv_d for r in sel.table}
        assert sel.choice == expected, (prism, cv)
        if prism:
            assert cv[cands[0]] < 1.05 * cv[cands[1]] + 0.001  # what the tolerance rule could not see
            assert "one standard error" in sel.reason


def test_warm_started_folds_and_stopped_candidates_keep_the_choice_and_figures():
    """Item 6 of issue 8: folds warm-started from the fit on all shots, hopeless candidates stopped;
    the choice is the same as from scratch, the CV d of the good candidates within 0.1 % (a poor model
    within 5 %: its outlier edges, set by the fit on all shots, differ a little from each fold's)."""
    shots = harp_point_sets(DECENTRED, W, H, (0, 45, 90, 135), noise=0.005, seed=5)
    cold = select_model(shots, W, H, candidates=CANDS, warm_start=False, stop_factor=None)
    fast = select_model(shots, W, H, candidates=CANDS)
    assert fast.choice == cold.choice
    for a, b in zip(fast.table, cold.table):
        assert a.candidate == b.candidate
        if a.failure is None:
            good = b.cv_d < 2 * cold.table[1].cv_d
            assert a.cv_d == pytest.approx(b.cv_d, rel=0.001 if good else 0.05)
            assert a.full_fit is not None and a.full_fit.model is not None
        else:  # stopped: far worse than the best, and says so
            assert a.failure.startswith("stopped") and b.cv_d > 2 * cold.table[1].cv_d
    assert any(r.failure for r in fast.table)  # radial2 is stopped (its fit on all shots is 2.5x too bent)


def test_the_choice_is_made_with_every_orientation_in_the_fit():
    """Issue 19 item 2: tier 1 (leave one shot out) only sets aside what fails on an unseen
    orientation; the choice among the rest is the lowest CV d on alternate strings, every shot in
    every fit (pipeline.select.TIER2_RULE), and its correction is as near the exact lens as the best
    candidate's (a richer model taken on a tie costs nothing; truth: the lens map, modulo homography)."""
    from pipeline.compare import compare_models
    from pipeline.cross_validation import cv_folds
    from pipeline.select import ORIENTATION_TOLERANCE

    shots = harp_point_sets(DECENTRED, W, H, (0, 60, 120), noise=0.005, seed=3)
    sel = select_model(shots, W, H, candidates=CANDS, stop_factor=None)
    loso = {r.candidate: r for r in sel.table}
    best = min(r.cv_d for r in sel.table if np.isfinite(r.cv_d))
    tier2 = {r.candidate for r in sel.strings_table}
    assert FitSpec("poly", 5) not in tier2 and loso[FitSpec("poly", 5)].cv_d > 10 * best  # fails a new orientation
    assert all(loso[c].cv_d <= (1 + ORIENTATION_TOLERANCE) * best or c == sel.choice for c in tier2)
    assert sel.choice == min(sel.strings_table, key=lambda r: r.cv_d).candidate
    assert FitSpec("radial", 2) not in tier2  # too simple: set aside on the unseen orientations
    err = {r.candidate: compare_models(r.full_fit.model, DECENTRED, W, H, step=25).rms for r in sel.table}
    assert err[sel.choice] < 1.2 * min(err[c] for c in tier2) and err[sel.choice] < 0.003
    for train, held in cv_folds(shots, "edges"):  # the tier-2 folds: every shot in every fit
        assert all(len(s) >= len(shots[i]) // 2 - 1 for i, s in enumerate(train)) and held
    assert "every orientation in the fit" in sel.reason and "unseen orientation" in sel.reason
    assert [r["label"] for r in sel.to_dict()["strings_table"]] == [r.candidate.label for r in sel.strings_table]


def test_a_centre_prior_that_bends_the_fit_loses_with_every_orientation():
    """A lens decentred by 17 px: with every orientation in the fit the prior's pull on the centre
    shows (alternate-string CV d above the free centre's) and the free centre is chosen; its field
    is closer to the exact lens than the prior's (truth: the lens map, modulo homography)."""
    from pipeline.compare import compare_models

    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(514.5, 365.5), tangential=(0.001, -7e-4))
    cands = (FitSpec("radial", 4, True), FitSpec("radial", 4, True, center_prior=True))
    shots = harp_point_sets(lens, W, H, (15, 75, 135), noise=0.01, seed=2)
    sel = select_model(shots, W, H, candidates=cands)
    strings = {r.candidate: r.cv_d for r in sel.strings_table}
    assert strings[cands[1]] > 1.05 * strings[cands[0]]
    assert sel.choice == cands[0]
    err = {r.candidate: compare_models(r.full_fit.model, lens, W, H, step=25).rms for r in sel.table}
    assert err[cands[0]] < 0.5 * err[cands[1]]


def _own_fields(shots, seed: int, rms: float):
    """Each shot moved by a smooth field of its own (quadratic and cubic terms, ``rms`` px each): an orientation's
    own measurement bias, which leave-one-shot-out folds cannot tell from the lens."""
    rng = np.random.default_rng(seed)
    out = []
    for lines in shots:
        f = rng.normal(0, rms, (2, 6))
        moved = []
        for p in lines:
            xn, yn = (p[:, 0] - W / 2) / (W / 2), (p[:, 1] - H / 2) / (H / 2)
            basis = np.stack([xn * xn, xn * yn, yn * yn, xn**3, xn * yn * yn, yn**3])
            moved.append(p + np.column_stack([f[0] @ basis, f[1] @ basis]))
        out.append(moved)
    return out


def test_a_free_centre_is_judged_with_every_orientation_when_its_centre_prior_twin_generalises():
    """Three shots: the leave-one-shot-out folds fit two orientations, which leave a free centre nearly
    undetermined, so the centre prior wins them by far (here beyond tier 1's tolerance) without the lens's
    centre being where the prior pulls it. The free twin is then judged with every orientation in the fit
    (tier 2) with its prior twin, and chosen where it wins there; its correction is nearer the exact lens than the
    prior's (truth: the lens map, modulo homography; before, the prior was the choice)."""
    from pipeline.compare import compare_models

    lens = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(520.5, 360.5), tangential=(0.001, -7e-4))
    free, prior = FitSpec("radial", 4, True, True), FitSpec("radial", 4, True, True, center_prior=True)
    shots = _own_fields(harp_point_sets(lens, W, H, (15, 75, 135), noise=0.01, seed=6), 6, 0.04)
    sel = select_model(shots, W, H, candidates=(free, prior), orientation_tolerance=0.2)
    loso = {r.candidate: r.cv_d for r in sel.table}
    assert loso[free] > 1.2 * loso[prior]  # the free centre fails the folds' tolerance on its own
    assert {r.candidate for r in sel.strings_table} == {free, prior}
    assert sel.choice == free == min(sel.strings_table, key=lambda r: r.cv_d).candidate
    assert f"as its twin {prior.label} does" in sel.reason
    err = {r.candidate: compare_models(r.full_fit.model, lens, W, H, step=25).rms for r in sel.table}
    assert err[free] < err[prior]


def test_too_few_orientations_for_the_choice_are_said():
    from pipeline.orientations import distinct_orientations, required_orientations, shot_orientation, support_problem

    shots = harp_point_sets(DECENTRED, W, H, (0, 90), noise=0.005, seed=5)
    assert [round(shot_orientation(s)) % 180 for s in shots] == [0, 90]
    assert distinct_orientations([1.0, 179.0, 45.0, 50.0, 90.0]) == 3  # 1 and 179 are 2 deg apart
    assert distinct_orientations([0.0, 8.0, 16.0]) == 2  # 0 and 16 are distinct, 8 is near both
    assert distinct_orientations(5.0 * i for i in range(36)) == 18  # a sweep 5 deg apart: 0, 10, ..., 170
    # every angle of a turntable in 0.0036 deg steps: 10 deg is no whole number of steps, so no 18 directions lie
    # pairwise 10 deg apart (their 18 gaps would each be exactly 10); 17 do
    assert distinct_orientations(0.0036 * i for i in range(100000)) == 17
    assert distinct_orientations([30.0, 30.0, 210.0]) == 1 and distinct_orientations([]) == 0
    assert required_orientations(FitSpec("radial", 4, True, True)) == 3
    assert required_orientations(FitSpec("radial", 4)) == 2
    sel = select_model(shots, W, H, candidates=(FitSpec("radial", 4, True),))
    assert sel.support and "needs >= 3 distinct string orientations" in sel.support and sel.support in sel.reason
    assert "not checked" in sel.reason
    assert support_problem(FitSpec("radial", 4), shots) is None
    three = harp_point_sets(DECENTRED, W, H, (0, 60, 120), noise=0.005, seed=5)
    assert support_problem(FitSpec("poly", 5), three) and support_problem(FitSpec("radial", 4, True), three) is None


def test_a_flexible_model_needs_a_clear_lead_over_the_radial_ones():
    """A lens with real non-radial structure: the polynomial is far ahead of every radial model on
    unseen orientations and is chosen; asked for a lead it does not have, the choice is radial and
    the reason says by how much the polynomial won the folds."""
    from tests.pipeline.rendered_shots import nonradial_lens

    lens = nonradial_lens()
    shots = harp_point_sets(lens, W, H, (0, 36, 72, 108, 144), noise=0.005, seed=4)
    sel = select_model(shots, W, H, candidates=CANDS, stop_factor=None)
    assert sel.choice == FitSpec("poly", 5)
    assert "paired standard errors ahead of every radial model" in sel.reason
    lead = float(sel.reason.split("px, ")[-1].split(" paired")[0])
    assert lead > 2.0
    strict = select_model(shots, W, H, candidates=CANDS, stop_factor=None, flexible_margin_se=lead + 1)
    assert strict.choice.kind == "radial"
    assert f"won the folds by only {lead:.1f} paired standard errors" in strict.reason
