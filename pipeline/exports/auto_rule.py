"""When a pin-hole export is not enough and the fisheye model is fitted too.

:data:`AUTO` is the export that writes OpenCV's pin-hole or fisheye model, whichever its consumer
finds closer; :func:`fisheye_reason` is the one rule every format with a choice of the two uses to
try the fisheye (a wide-angle calibration, or a pin-hole less exact than :func:`auto_limit`), and
:func:`consumer_max_px` the error a consumer of an export sees with its own default point solver.
"""

from __future__ import annotations

import math

from pipeline.exports.conversion_error import ConversionError
from pipeline.exports.source import Export, ExportSource

AUTO = "auto"
"""The name :func:`write_export` takes for "OpenCV, pin-hole or fisheye, whichever is closer"."""


AUTO_BAR_PX = 0.01
"""Without a holdout ``d``, the RMS (modulo homography) within which :data:`AUTO` takes the
pin-hole export without trying the fisheye one (the station's precision bar)."""


AUTO_MAX_FACTOR = 5.0
"""... and its max must be within this many times that RMS limit (issue 10's targets for the
default OpenCV export: 0.01 px RMS, 0.05 px max)."""


def consumer_max_px(ex: Export) -> float:
    """The max error (px) a consumer of ``ex`` sees, judged with its own default solver: the worst of
    the closed-form maps (the conversion error, modulo homography) and the default point solver."""
    assert ex.error is not None
    worst = ex.error.max_mod_h_px
    if ex.solver is not None:
        worst = max(worst, ex.solver.consumer_max_px)
    return float(worst)


def auto_limit(src: ExportSource) -> tuple[float, str]:
    """The limit a pin-hole export is held to before the fisheye model is tried, and what it is."""
    if src.holdout_d is not None and math.isfinite(src.holdout_d):
        return float(src.holdout_d), "the holdout d"
    return AUTO_BAR_PX, f"the {AUTO_BAR_PX:g} px bar"


def fisheye_reason(src: ExportSource, err: ConversionError, pin_max: float) -> str | None:
    """Why the fisheye model is fitted too (None: the pin-hole export suffices).

    A wide-angle calibration, or a pin-hole export less exact than the calibration: RMS or
    residual ``d`` above the limit (:func:`auto_limit`), or ``pin_max`` (its max as its consumer
    sees it) above :data:`AUTO_MAX_FACTOR` times the limit.
    """
    limit, _ = auto_limit(src)
    worst = max(err.rms_mod_h_px, err.d_px if math.isfinite(err.d_px) else 0.0)
    if src.wide_angle:
        return "the calibration chose a wide-angle model"
    if worst <= limit and pin_max <= AUTO_MAX_FACTOR * limit:
        return None
    return f"the pin-hole is less exact than {limit:.4f} px RMS / {AUTO_MAX_FACTOR * limit:.4f} px max"
