"""A residual field added when it holds on unseen orientations (``pipeline.field: auto``, issue 19 items 3 and 5).

Truth: the exact lens maps of :mod:`pipeline.lens_population` (a radial + tangential + prism lens, with or without
the smooth non-parametric field a real lens adds), a turning harp whose strings are bent by known Legendre terms
(``tests.pipeline.harp_points.turning_harp_point_sets``, independent of the fit), and the field error modulo a
homography against the exact lens (:func:`pipeline.compare.compare_models`) of the lens fitted with the strings
separated, as a session stores it."""

import numpy as np
import pytest
import threadpoolctl

from pipeline.compare import compare_models
from pipeline.fitspec import FitSpec
from pipeline.harp_shape import fit_harp_shape
from pipeline.lens_population import lens_population
from pipeline.select import SEPARATED_FOLDS, select_field
from tests.pipeline.harp_points import turning_harp_point_sets

W, H = 1000, 750
SPEC = FitSpec("radial", 4, True, True)
TURNS = (0, 30, 60, 90, 120, 150)
GRIDS, PENALTIES = ((8, 6),), (1e-4, 1e-3)


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with threadpoolctl.threadpool_limits(1):
        yield


def _shots(seed: int, field: bool, turns=TURNS):
    lens = lens_population(seed, 1, W, H, field=field, field_rms_px=(0.03, 0.03))[0].model
    bends = np.random.default_rng(seed).normal(0.0, 0.03, (13, 3))  # every string bowed a few hundredths
    shots, _ = turning_harp_point_sets(lens, W, H, turns, bends, axis=(497, 378), step=40.0, seed=seed)
    return lens, shots


def _stored_error(sel, shots, lens) -> dict[FitSpec, float]:
    """Each candidate's lens fitted with the strings separated (what a session stores), against the exact lens."""
    out = {}
    for r in sel.table:
        joint = fit_harp_shape(shots, TURNS, W, H, r.candidate, plain=r.full_fit)
        assert joint, joint
        out[r.candidate] = compare_models(joint.model, lens, W, H, step=25).rms
    return out


def test_with_the_turntable_angles_a_lens_with_a_field_gets_one_the_plain_folds_miss():
    """A lens with a 0.03 px field behind 0.03 px string bows: judged with each held-out shot's strings' bends
    removed, the field wins and the stored lens's field error halves; the plain folds, where the strings'
    bends are most of a held-out shot's bend, keep the radial model."""
    lens, shots = _shots(2, True)
    sel = select_field(shots, W, H, SPEC, grids=GRIDS, penalties=PENALTIES, turntable_deg=TURNS)
    assert sel.choice.field == (8, 6) and sel.folds == SEPARATED_FOLDS, sel.reason
    assert sel.reason.startswith("residual field: ") and "strings separated" in sel.reason
    assert f"ahead of {SPEC.label} by " in sel.reason  # how clearly the field won, in paired standard errors
    err = _stored_error(sel, shots, lens)
    assert err[SPEC] > 0.012 and err[sel.choice] < 0.6 * err[SPEC], err
    plain = select_field(shots, W, H, SPEC, grids=GRIDS, penalties=PENALTIES)
    assert plain.choice == SPEC and plain.folds == "images", plain.reason


def test_a_lens_without_a_field_keeps_its_model():
    """The same harp and a lens without a field: every field candidate would store a worse lens, and none is
    taken."""
    lens, shots = _shots(0, False)
    sel = select_field(shots, W, H, SPEC, grids=GRIDS, penalties=PENALTIES, turntable_deg=TURNS)
    assert sel.choice == SPEC, sel.reason
    err = _stored_error(sel, shots, lens)
    assert err[SPEC] < 0.003 and all(e > err[SPEC] for c, e in err.items() if c != SPEC), err


def test_too_few_orientations_or_a_model_that_cannot_carry_a_field_keep_the_model_and_say_why():
    lens, shots = _shots(1, True, turns=(0, 60, 120))
    sel = select_field(shots, W, H, SPEC, turntable_deg=(0, 60, 120))
    assert sel.choice == SPEC and sel.table == () and sel.folds == "none"
    assert "a field needs >= 4 distinct string orientations, the shots have 3" in sel.reason
    poly = FitSpec("poly", 5)
    assert select_field(shots, W, H, poly).choice == poly
    assert "the radial model only" in select_field(shots, W, H, poly).reason
    has = FitSpec("radial", 4, True, True, field=(8, 6), field_penalty=1e-3)
    assert select_field(shots, W, H, has).choice == has and "it has one" in select_field(shots, W, H, has).reason


def test_a_polynomial_choice_is_weighed_against_the_best_radial_model_with_a_field():
    """The choice took a free polynomial (it follows a lens's field better than any radial candidate alone); with
    the strings separated its folds weigh it against the best radial candidate with each field, and the lowest CV d
    is stored: here the radial model with a field, closer to the exact lens than the polynomial. Without the
    turntable angles the polynomial stays, and the reason says why."""
    lens, shots = _shots(2, True)
    poly = FitSpec("poly", 7)
    sel = select_field(shots, W, H, poly, grids=GRIDS, penalties=PENALTIES, turntable_deg=TURNS, radial=SPEC)
    assert [r.candidate for r in sel.table][:2] == [poly, SPEC] and sel.folds == SEPARATED_FOLDS
    assert sel.choice.kind == "radial" and sel.choice.field == (8, 6), sel.reason
    err = _stored_error(sel, shots, lens)
    assert err[sel.choice] < 0.8 * err[poly], err
    plain = select_field(shots, W, H, poly, radial=SPEC)
    assert plain.choice == poly and "a field applies to the radial model only" in plain.reason
