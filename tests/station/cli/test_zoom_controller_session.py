"""A zoom session whose zoom a VISCA lens controller drives (``station.camera.zoom_controller: {port:
emulator}``): each part's zoom position goes over a real pty, in VISCA bytes, to the emulator, which moves
the simulated zoom lens; the store holds a profile per (focal, focus), each close to the lens at that
setting.

Truth: the VISCA packet written out by hand (CAM_Zoom Direct, ``81 01 04 47 0p 0q 0r 0s FF``) and the
simulated zoom lens's closed form (:func:`drivers.sim.lens.zoom_lens`), compared modulo homography."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import yaml

import drivers.sim.visca_emulator as visca_emulator
from drivers.sim.lens import ZOOM_FOCAL_RANGE_MM, zoom_lens
from pipeline.compare import compare_models
from station.cli import main
from station.store import ProfileStore

REPO = Path(__file__).resolve().parents[3]
W, H = 320, 240
FOCALS = ZOOM_FOCAL_RANGE_MM  # the wide and the long end: zoom positions 0 and 0x4000
POSITIONS = (0, 0x4000)


def test_a_zoom_session_through_the_visca_controller(tmp_path, monkeypatch):
    started = []  # every VISCA emulator the simulated station starts (one per part), kept to read afterwards

    def keep(*args, **kw):
        handle = start(*args, **kw)
        started.append(handle)
        return handle

    start = visca_emulator.start_visca_emulator
    monkeypatch.setattr(visca_emulator, "start_visca_emulator", keep)

    doc = yaml.safe_load((REPO / "configs" / "demo-zoom.yaml").read_text())
    doc["station"]["camera"].update(width=W, height=H, spacing_px=20.0, string_width_px=4.0)
    doc["station"]["camera"]["zoom_controller"] = {"port": "emulator"}
    doc["zoom"] = {"settings": list(FOCALS), "positions": list(POSITIONS)}
    doc["camera_body"]["pixel_pitch_um"] = 15.0
    doc["capture"]["orientations_deg"] = [0, 45, 90, 135]
    doc["pipeline"].update(workers=1, strings="ignore")  # the lens alone: fewer shots suffice
    doc["simulation"]["emulator"] = {"speed_deg_s": 720.0, "accel_deg_s2": 7200.0}
    doc["report"] = {"overlays": "none"}
    doc["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    cfg = tmp_path / "zoom.yaml"
    cfg.write_text(yaml.safe_dump(doc))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["session", "run", str(cfg), "--quiet", "--json", "--name", "z"])
    results = json.loads(out.getvalue())
    assert code == 0, results["parts"]
    assert [(p["focal"], p["exit_code"]) for p in results["parts"]] == [(f, 0) for f in FOCALS]

    # the controller was told each part's position, in VISCA's bytes, and the lens went there
    assert len(started) == len(FOCALS)
    for handle, position, focal in zip(started, POSITIONS, FOCALS, strict=True):
        emu = handle.emulator
        nibbles = bytes((position >> s) & 0xF for s in (12, 8, 4, 0))
        assert b"\x81\x01\x04\x47" + nibbles + b"\xff" in emu.received
        assert emu.zoom == position and emu.world.zoom == focal

    # a profile per (focal, focus), each the lens at its setting
    with ProfileStore(tmp_path / "profiles.sqlite", create=False) as st:
        ((lens_id, *_),) = st.lenses()
        current = st.latest_by_focus(lens_id)
    assert sorted((p.focal, p.focus) for p in current) == [(f, d) for f in FOCALS for d in (0.0, 1.0)]
    for p in current:
        c = compare_models(p.model, zoom_lens(p.focal, p.focus, W, H), W, H, step=10.0)
        print(f"focal {p.focal:g} mm, focus {p.focus:g}: RMS {c.rms:.4f} px, max {c.max:.4f} px against the lens")
        assert c.rms < 0.05, (p.focal, p.focus, c.rms)
