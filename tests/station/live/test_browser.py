"""The live page in a real browser (Debian's Chromium, headless, under Playwright) on the
simulated station: the strings and the focus score appear and update, "next orientation"
moves the turntable, a camera fault is one line that clears.

``HARP_LIVE_SCREENSHOT=docs/live-view.png pytest tests/station/test_live_browser.py`` also
saves the README's screenshot.
"""

from __future__ import annotations

import os

import pytest

from station.live.web import live_app
from station.web import start
from tests.station.live.support import live_config, running_live, wait_for


@pytest.fixture(scope="module")
def live_page_server(tmp_path_factory):
    # the harp's dark frame and two dust shadows in view: groups the grouping rejects, with reasons
    cfg = live_config(tmp_path_factory.mktemp("live"), width=640, height=480, frame=True, dust=2)
    with running_live(cfg, reconnect_s=0.1) as (st, cam, sim):
        with start(live_app(st)) as srv:
            yield st, cam, srv


def _text(page, sel):
    return page.inner_text(sel).strip()


def _set_focus(page, value):
    page.evaluate(
        "(v) => { const s = document.getElementById('focus-slider'); s.value = v; s.dispatchEvent(new Event('change')); }",
        value,
    )


def test_live_page_shows_strings_focus_and_moves_the_turntable(page, live_page_server):
    st, cam, srv = live_page_server
    page.goto(srv.url)
    page.wait_for_function("() => Number(document.querySelector('#strings-found').dataset.count) >= 4", timeout=30_000)
    assert page.locator("#strings-table tbody tr").count() >= 4
    # the overlay draws the edges found over the frame once that frame has loaded (the figures arrive
    # first: reading the canvas once, right after them, found it still blank on a fast machine)
    page.wait_for_function(
        """() => { const c = document.getElementById('overlay'); if (!c.width || !c.height) return false;
                   const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
                   let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n > 1000; }""",
        timeout=30_000,
    )
    # one orientation covers no cell (a cell needs edges in two directions): the frame stays visible,
    # not tinted all over (the overlay draws the edges and labels only, a small part of the picture)
    page.wait_for_function("() => document.querySelector('#coverage-fraction').dataset.fraction !== ''", timeout=30_000)
    assert float(page.evaluate("() => document.querySelector('#coverage-fraction').dataset.fraction")) == 0.0
    page.evaluate("() => window.harpLive.redraw()")  # the overlay as drawn with this coverage
    drawn = page.evaluate(
        """() => { const c = document.getElementById('overlay');
                   const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
                   let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n / (d.length / 4); }"""
    )
    assert drawn < 0.5, drawn
    # labels stay whole inside the picture: pushed in from the right, top and bottom borders
    at = "(a) => window.harpLive.labelAt(...a)"
    assert page.evaluate(at, [630, 5, 40, 640, 480, 1]) == [598, 13]
    assert page.evaluate(at, [-5, 500, 10, 640, 480, 1]) == [2, 478]
    assert page.evaluate(at, [100, 200, 10, 640, 480, 1]) == [100, 200]
    # the frame is a separate image request, replaced at every refresh (naturalWidth is 0 while the next
    # one loads): wait for a loaded frame of the downscaled width, 640 px
    page.wait_for_function("() => document.getElementById('frame').naturalWidth === 640", timeout=30_000)
    sharp = float(_text(page, "#focus-score"))
    assert sharp > 0.45  # at the best focus, 0.37
    # turn the focus away: the score drops, frame after frame
    _set_focus(page, 0.25)
    page.wait_for_function(
        f"() => Number(document.querySelector('#focus-score').textContent) < {0.8 * sharp}", timeout=30_000
    )
    assert cam.get_focus() == pytest.approx(0.25)
    shot = os.environ.get("HARP_LIVE_SCREENSHOT")
    if shot:  # a through-focus sweep for the picture
        for f in (0.29, 0.33, 0.41, 0.45, 0.49):
            n = st.frames_assessed
            _set_focus(page, f)
            wait_for(lambda: st.frames_assessed >= n + 3, what="frames at the focus setting")
    _set_focus(page, 0.37)
    page.wait_for_function(
        f"() => Number(document.querySelector('#focus-score').textContent) > {0.95 * sharp}", timeout=30_000
    )
    page.wait_for_function("() => document.querySelector('#peak').dataset.focus !== ''", timeout=10_000)
    assert page.locator("#rejected").inner_text().startswith("rejected: ")
    assert _text(page, "#corners") == "corners missing: top left, top right, bottom left, bottom right"
    if shot:
        page.set_viewport_size({"width": 1400, "height": 1000})
        page.wait_for_timeout(1500)
        page.screenshot(path=shot, full_page=True)
    # next orientation: the turntable moves to the plan's 45 degrees and the page says so
    assert float(page.locator("#tt-angle").get_attribute("data-deg")) == pytest.approx(0.0, abs=1e-3)
    page.click("#next-orientation")
    page.wait_for_function(
        "() => Math.abs(Number(document.querySelector('#tt-angle').dataset.deg) - 45) < 0.01", timeout=30_000
    )
    assert "orientation 2 of 4" in _text(page, "#tt-orientation")
    page.wait_for_function(
        "() => document.querySelector('#orientations-seen').textContent.includes('45.0')", timeout=30_000
    )
    assert _text(page, "#verdict") == "would pass the session's checks"
    assert page.locator("#device-errors li").count() == 0


def test_live_page_shows_a_camera_fault_as_one_line_and_carries_on(page, live_page_server):
    st, cam, srv = live_page_server
    page.goto(srv.url)
    page.wait_for_function("() => Number(document.querySelector('#frame-info').dataset.frameId) > 0", timeout=30_000)
    cam.fail_next(25, "timeout")  # ~1.5 s without frames
    line = page.locator("#device-errors li").first
    line.wait_for(timeout=10_000)
    text = line.inner_text()
    assert text.startswith("sim camera SIM-0001: no frame within") and "\n" not in text
    page.wait_for_selector("#device-errors li.recovered", timeout=30_000)
    assert "working again since" in page.locator("#device-errors li").first.inner_text()
    before = int(page.locator("#frame-info").get_attribute("data-frame-id"))
    page.wait_for_function(
        f"() => Number(document.querySelector('#frame-info').dataset.frameId) > {before}", timeout=30_000
    )
