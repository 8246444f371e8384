"""A session's colour (station.session.colour): which frames are colour, and what is kept when the shots
cannot give the TCA or the vignetting (the measurement against the truth: tests/station/cli/test_session_colour.py)."""

from __future__ import annotations

import numpy as np

from pipeline.render import HarpScene
from pipeline.render_colour import render_mosaic
from station.session.colour import colour_summary, focus_colour, frames_cfa
from station.session.records import FrameSaved
from tests.pipeline.colour_lenses import GAINS, colour_lens


def _frame(meta):
    return FrameSaved(0, 0, 0, 0, "frames/f0_o0_a0_i0.png", "0" * 64, meta)


def test_a_grey_camera_has_no_colour():
    assert frames_cfa([_frame({"extra": {"sim": {}}}), _frame({})]) is None
    assert frames_cfa([_frame({"extra": {"sim": {}, "cfa": "GRBG"}})]) == "GRBG"
    assert colour_summary(None) == {}


def test_one_orientation_is_kept_as_its_reasons():
    """One shot cannot separate a channel's field from the harp, nor the back-light from the lens: both
    measurements are kept as one-line reasons (the distortion profile is stored all the same)."""
    w, h = 200, 150
    lens = colour_lens(w, h)["lenses"]
    scene = HarpScene(angle_deg=5.0, spacing_px=20.0, string_width_px=5.0, blur_px=1.0)
    mosaic = render_mosaic(w, h, scene, lens, "RGGB", gains=GAINS, seed=3).image.astype(np.float64)
    doc = focus_colour([mosaic], "RGGB", [0.0], ["frames/f0_o0_a0_i0.png"], lens["G"], 30, 65535.0)
    assert set(doc) == {"tca", "vignetting"}
    for what in ("tca", "vignetting"):
        assert set(doc[what]) == {"failure"} and "\n" not in doc[what]["failure"], doc
    assert "two or more" in doc["vignetting"]["failure"]
    cells = colour_summary(doc)
    assert cells["TCA"].startswith("none: ") and cells["vignetting"].startswith("none: ")
    # a clipped sheet: the vignetting refused, said with the shot's name
    clipped = focus_colour([mosaic, mosaic], "RGGB", [0.0, 90.0], ["a", "b"], lens["G"], 30, float(mosaic.min()))
    assert clipped["vignetting"]["failure"].startswith("a: ") and "saturated" in clipped["vignetting"]["failure"]
