"""station.calibration: what keeps a set of shots from being calibrated, and the held-out warning."""

from __future__ import annotations

import numpy as np

from pipeline.fitspec import parse
from station.calibration import holdout_warning, shot_count_problem, size_problem


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
