"""The harp's self-check as a profile keeps it (``station.harp_health``)."""

from __future__ import annotations

import numpy as np


def test_the_harp_check_names_a_string_only_when_its_bend_is_beyond_its_standard_errors():
    """``station.harp_health.harp_health`` on a joint fit given (strings made by hand, so the truth is their
    construction): string 4 bows by 0.03 px measured to 0.002 px, string 7 by 0.025 px measured to 0.02 px (seen
    over little of its length); both beyond the limit and the median string's, only string 4 is a finding."""
    from pipeline.harp_frame import HarpFrame
    from pipeline.harp_shape import HarpShapeFit, StringShape, legendre
    from station.harp_health import harp_health

    def string(k, p2, se):
        span = (-0.8, 0.8)
        bend = float(np.max(np.abs(p2 * legendre(np.linspace(*span, 201), (2,))[0])))
        return StringShape(k, 60.0 * (k - 5), (2, 3, 4), (p2, 0.0, 0.0), (se, se, se), span, 6, 12, 400, bend, se)

    strings = tuple(string(k, {4: 0.06, 7: 0.05}.get(k, 0.001 * (-1) ** k), {7: 0.02}.get(k, 0.002)) for k in range(11))
    frame = HarpFrame(0.0, 1, (500.0, 375.0), 625.0, 60.0)
    joint = HarpShapeFit(None, None, frame, strings, 0.01, 0.012, 20)  # type: ignore[arg-type]
    health = harp_health([], (0, 30, 60, 90, 120, 150), 1000, 750, None, joint=joint)  # type: ignore[arg-type]
    assert health["bent_strings"] == [4] and health["uncertain_strings"] == [7]
    assert health["worst_string"] == 4 and health["significance"] == 2.0


def test_the_harp_check_record_names_the_noisy_shots_by_their_turntable_angle():
    """The same two waved shots of six (truth: shots 2 and 5, turned to 60 and 150 deg when drawn): the session's
    harp-check record lists them with those angles and a noise ratio beyond the factor; the unwaved shots, none."""
    from pipeline.fitspec import FitSpec
    from pipeline.harp_shape import SHOT_NOISE_FACTOR
    from pipeline.models import RadialModel
    from station.harp_health import harp_health
    from tests.pipeline.harp_points import turning_harp_point_sets
    from tests.pipeline.test_harp_shape import _waved

    w, h = 1000, 750
    lens = RadialModel.for_image(w, h, k=(1.0, 0.0, 0.03, 0.0, 0.004), center=(512, 366))
    turns = (0, 30, 60, 90, 120, 150)
    shots, _ = turning_harp_point_sets(lens, w, h, turns, np.zeros((11, 3)), step=10, noise=0.01, seed=3)
    spec = FitSpec("radial", 4, True, True)
    noisy = harp_health(_waved(shots, {2, 5}, 0.05, 300.0, 3), turns, w, h, spec)["noisy_shots"]
    assert [(n["shot"], n["turntable_deg"]) for n in noisy] == [(2, 60.0), (5, 150.0)]
    assert all(n["noise_ratio"] > SHOT_NOISE_FACTOR for n in noisy)
    assert harp_health(shots, turns, w, h, spec)["noisy_shots"] == []
