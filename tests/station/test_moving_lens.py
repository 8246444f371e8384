"""A lens that moves between shots: the own-shift record (``station.moving_lens``)."""

from __future__ import annotations

import pytest


def test_the_own_shift_record_judges_only_with_four_orientations_or_more():
    from pipeline.models import RadialModel
    from pipeline.own_shift import OwnShift
    from station.config import QAConfig
    from station.moving_lens import MIN_OWN_SHIFT_ORIENTATIONS, own_shift_record
    from station.qa.verdicts import evaluate

    low = [OwnShift(0.04, 0.01, (3.0, 4.0), 100)]  # ratio 0.25
    rec = own_shift_record(low * (MIN_OWN_SHIFT_ORIENTATIONS - 1))
    assert rec["ratio_median"] == pytest.approx(0.25) and not rec["judged"] and not rec["moving"]
    rec = own_shift_record(low * MIN_OWN_SHIFT_ORIENTATIONS + [OwnShift(0.02, 0.02, (0.0, 0.0), 100)])
    assert rec["judged"] and rec["moving"] and rec["per_orientation"][0]["shift_px"] == [3.0, 4.0]
    v = evaluate(RadialModel.for_image(640, 480), 640, 480, 0.01, QAConfig(), own_shift=rec)
    check = next(c for c in v.checks if c.name == "holdout_own_shift")
    assert "by up to 5.0 px" in check.text and v.verdict == "PASS"  # reported, not judged
    assert not any(
        c.name == "holdout_own_shift"
        for c in evaluate(
            RadialModel.for_image(640, 480), 640, 480, 0.01, QAConfig(), own_shift=own_shift_record(low)
        ).checks
    )


def test_the_own_shift_advice_points_at_the_twin_when_the_session_took_one():
    # a session with a twin read is told to look at its check, not to take one (capture.twin_deg)
    from pipeline.models import RadialModel
    from pipeline.own_shift import OwnShift
    from station.config import QAConfig
    from station.moving_lens import MIN_OWN_SHIFT_ORIENTATIONS, own_shift_record
    from station.qa.verdicts import evaluate

    rec = own_shift_record([OwnShift(0.04, 0.01, (3.0, 4.0), 100)] * MIN_OWN_SHIFT_ORIENTATIONS)
    twin = {"paths": ["a", "b"], "angle_deg": 30.0, "move_px": 0.2, "limit_px": 1.0, "moved": False}

    def text(twins):
        v = evaluate(RadialModel.for_image(640, 480), 640, 480, 0.01, QAConfig(), own_shift=rec, twins=twins)
        return next(c for c in v.checks if c.name == "holdout_own_shift").text

    assert "capture.twin_deg" in text(None) and "check twin_move" not in text(None)
    assert "capture.twin_deg" not in text([twin]) and "the twin (check twin_move) tells it" in text([twin])
