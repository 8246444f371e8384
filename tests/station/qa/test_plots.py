"""The QA report's figures and their labels (``station.qa.plots``)."""

from __future__ import annotations


def test_a_shots_group_label_tells_the_twin_and_the_stage_position():
    # the residual plot labels each shot's edges; the twin shares its angle with another shot, so it says so
    import numpy as np

    from station.qa.plots import Shot

    img = np.zeros((2, 2))
    assert Shot(45.0, img, None).group == "45°"
    assert Shot(45.0, img, None, twin=True).group == "45° twin"
    assert Shot(22.5, img, None, shift_mm=10.0).group == "22.5° 10 mm"
    assert Shot(45.0, img, None).place == "stage 45 deg"
