"""The live warnings against the session's limits (station.live.checks)."""

from __future__ import annotations

import numpy as np

from drivers.sim.camera import SimulatedCamera
from pipeline.assess import assess_frame
from station.config import CheckConfig
from station.live.checks import live_warnings


def test_exposure_warning_appears_exactly_when_the_frame_saturates():
    """Exposure swept through the simulator's clipping point (scale 255/200 = 1.275 at the centre
    of the lit sheet): the over-exposure warning is on exactly for the frames whose saturated
    fraction exceeds the session's limit, counted here on the frame itself."""
    checks = CheckConfig()
    cam = SimulatedCamera(width=320, height=240, seed=2)
    first = None
    with cam:
        for scale in np.arange(1.0, 1.40001, 0.0125):
            cam.set_exposure(10_000.0 * scale)
            img = cam.capture().image
            warned = any(w.startswith("over-exposed") for w in live_warnings(assess_frame(img), checks))
            saturated = float(np.mean(img == 255))
            assert warned == (saturated > checks.max_saturated_fraction), (scale, saturated)
            if scale <= 1.25:  # 200 x 1.25 = 250 grey levels: 3 sigma of noise below the top
                assert not warned
            if scale >= 1.30:
                assert warned
            if warned and first is None:
                first = scale
    assert first is not None and 1.2625 <= first <= 1.2875, first
