"""Cross-validation table (pipeline.cross_validation): what a candidate without a fit on all shots gets."""

import numpy as np

from pipeline.cross_validation import cross_validate
from pipeline.edgeset import FitFailure
from pipeline.fitspec import FitSpec
from pipeline.models import RadialModel
from tests.pipeline.harp_points import harp_point_sets

W, H = 1000, 750
LENS = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02, 0.0, 0.003), center=(505, 372), tangential=(0.0008, -0.0005))
CANDS = (FitSpec("radial", 4, True), FitSpec("radial", 4, True, True))


def test_a_candidate_whose_fit_on_all_shots_fails_is_not_cross_validated_and_says_why():
    """A candidate whose fit on all the shots fails (on a realistic lens, radial4+tangential+prism+division1's
    correction folded over inside the image while its folds passed, and the choice took it:
    ``benchmarks/axis_positions.py --stored``, seed 22) has no correction to store: its row fails with that
    reason, without folds, and it cannot be chosen (:func:`pipeline.select.select_model` takes finite CV d only); the other candidates' rows are what they are without it."""
    shots = harp_point_sets(LENS, W, H, (0, 45, 90, 135), noise=0.005, seed=11)
    alone, _ = cross_validate(shots, W, H, CANDS, "images", stop_factor=None)
    failed = FitFailure("the fitted correction folds over inside the image")
    table, _ = cross_validate(shots, W, H, CANDS, "images", stop_factor=None, full_fits={CANDS[1]: failed})
    bad = table[1]
    assert bad.failure == f"its fit on all shots: {failed.reason}" and not np.isfinite(bad.cv_d)
    assert bad.fold_d == () and bad.full_fit is None
    assert table[0].cv_d == alone[0].cv_d and np.isfinite(alone[1].cv_d)  # it had passed its folds
