"""The live view of a Bayer camera (issue 24 item 4): each red and blue string edge against green's,
per ring of the image, on the page.

Truth: a raw mosaic rendered through exact per-channel lens maps (``tests/pipeline/colour_lenses.py``:
red magnified, blue shrunk, decentred, with a lateral shift); the shift across each measured edge
is the closed-form TCA there.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from drivers.protocols import CameraIdentity, Frame
from pipeline.render import HarpScene
from pipeline.render_colour import render_mosaic
from pipeline.tca import ChannelOffsets, channel_offsets
from station.live.runner import LiveStation
from tests.pipeline.colour_lenses import GAINS, colour_lens
from tests.station.live.support import wait_for

W, H = 480, 360
PATTERN = "BGGR"


@pytest.fixture(scope="module")
def mosaic():
    lens = colour_lens(W, H, strength=2.0)
    scene = HarpScene(angle_deg=20.0, spacing_px=36.0, string_width_px=8.0, blur_px=1.0)
    return render_mosaic(W, H, scene, lens["lenses"], PATTERN, gains=GAINS, seed=7).image, lens["tca"]


def _frame(image, pattern: str, counter: int = 1) -> Frame:
    ident = CameraIdentity("test", "bayer", "0")
    return Frame(image, time.time(), 1000.0, 0.0, None, ident, counter, {"cfa": pattern})


def _shown(st: LiveStation) -> dict:
    return wait_for(lambda: st.state()["channels"], what="the colour figures")


def test_a_bayer_frame_shows_each_channel_against_green(mosaic):
    image, truth = mosaic
    with LiveStation(None) as st:
        st.show_frame(_frame(image, PATTERN), stage_deg=0.0)
        col = _shown(st)
        wait_for(lambda: st.frames_assessed >= 1, what="the frame's assessment")
        s = st.state()
    assert col["pattern"] == PATTERN and col["frame"] == 1
    # the assessment runs on the mosaic's luma: the strings are found, the Bayer checkerboard is not an edge
    assert s["figures"]["strings_found"] >= 8, s["figures"]
    from pipeline.cfa import measure_mosaic

    offsets = channel_offsets(measure_mosaic(image, PATTERN))
    for shown in col["channels"]:
        got = offsets[shown["channel"]]
        exact = ChannelOffsets(
            got.channel,
            W,
            H,
            got.points,
            got.normal,
            np.einsum("ij,ij->i", got.normal, truth[got.channel].displacement(got.points)),
        ).summary()
        print(
            f"\n{shown['channel']}: rings {[z['median_outward_px'] for z in shown['zones']]}, exact {[z['median_outward_px'] for z in exact['zones']]}"
        )
        assert shown["points"] == exact["points"] > 300
        for z, zt in zip(shown["zones"], exact["zones"]):
            assert abs(z["median_outward_px"] - zt["median_outward_px"]) < 0.03, (shown["channel"], z, zt)
        outer = shown["zones"][-1]["median_outward_px"]
        assert outer > 0.3 if shown["channel"] == "R" else outer < -0.3


def test_a_pattern_that_is_not_bayer_is_one_line(mosaic):
    image, _ = mosaic
    with LiveStation(None) as st:
        st.show_frame(_frame(image, "RGBX", counter=5), stage_deg=0.0)
        err = wait_for(lambda: [e for e in st.state()["errors"] if e["device"] == "camera"], what="the camera line")
        assert st.state()["channels"] is None
    assert err[0]["message"].startswith("frame 5: unknown CFA pattern 'RGBX'") and "\n" not in err[0]["message"]


def test_the_page_shows_the_colour_panel(page, mosaic):
    from station.live.web import live_app
    from station.web import start

    image, _ = mosaic
    with LiveStation(None) as st:
        st.show_frame(_frame(image, PATTERN), stage_deg=0.0)
        col = _shown(st)
        with start(live_app(st)) as srv:
            page.goto(srv.url)
            page.wait_for_selector("#channels-table tr[data-channel='R']", timeout=30_000)
            assert page.is_visible("#colour-panel")
            for shown in col["channels"]:
                cells = page.locator(f"#channels-table tr[data-channel='{shown['channel']}'] td").all_inner_texts()
                assert cells[0] == {"R": "red", "B": "blue"}[shown["channel"]]
                assert cells[4] == f"{shown['zones'][-1]['median_outward_px']:.3f}", cells
            assert f"{PATTERN} mosaic" in page.inner_text("#colour-info")
