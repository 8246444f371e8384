"""A zoom session: the simulated zoom lens calibrated over 3 focal lengths x 2 focus settings; the store
holds it per (focal, focus); profile show interpolates in both, never extrapolates; the lensfun export
has one calibration per focal length, read by lensfun itself; the Adobe LCP export one per (focal, focus).

Truth: the simulated zoom lens's closed form (:func:`drivers.sim.lens.zoom_lens`), compared modulo
homography (what a harp measures)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from drivers.sim.lens import zoom_lens
from pipeline.compare import compare_models
from pipeline.models import model_from_dict
from station.cli import main
from station.store import ProfileStore

REPO = Path(__file__).resolve().parents[3]
W, H = 320, 240
FOCALS = (12.0, 24.0, 36.0)


@pytest.fixture(scope="module")
def zoom_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("zoom")
    doc = yaml.safe_load((REPO / "configs" / "demo-zoom.yaml").read_text())
    doc["station"]["camera"].update(width=W, height=H, spacing_px=20.0, string_width_px=4.0)
    doc["camera_body"]["pixel_pitch_um"] = 15.0
    doc["capture"]["orientations_deg"] = [0, 45, 90, 135]
    doc["pipeline"]["workers"] = 1
    doc["report"] = {"overlays": "none"}
    doc["store"] = {"path": "profiles.sqlite", "sessions_dir": "sessions"}
    cfg = d / "zoom.yaml"
    cfg.write_text(yaml.safe_dump(doc))
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["session", "run", str(cfg), "--quiet", "--json", "--name", "z"])
    return d, code, json.loads(out.getvalue())


def test_every_setting_is_stored_with_its_focal_length_and_close_to_the_lens(zoom_run):
    d, code, results = zoom_run
    assert code == 0
    assert [(p["name"], p["exit_code"], p["verdict"]) for p in results["parts"]] == [
        (f"focal-{z:g}mm", 0, "PASS") for z in FOCALS
    ]
    assert sorted((s["focal"], s["focus"]) for s in results["settings"]) == [(z, f) for z in FOCALS for f in (0.0, 1.0)]
    with ProfileStore(d / "profiles.sqlite", create=False) as st:
        ((lens_id, *_),) = st.lenses()
        current = st.latest_by_focus(lens_id)
    assert len(current) == 6
    for p in current:
        c = compare_models(p.model, zoom_lens(p.focal, p.focus, W, H), W, H, step=10.0)
        assert c.rms < 0.03, (p.focal, p.focus, c.rms)
    # barrel at the wide end, pincushion at the long end: the measured corrections say so too
    for z, sign in ((12.0, 1.0), (36.0, -1.0)):
        p = next(q for q in current if q.focal == z and q.focus == 0.0)
        corner = p.model.undistort_points([[0.0, 0.0]])[0]
        assert sign * (-corner[0] - corner[1]) > 0  # moved away from the centre: barrel
    assert [(e["axis"], e["focal"]) for e in results["leave_one_out"]] == [("focal", 24.0), ("focal", 24.0)]
    assert (d / "sessions" / "z" / "zoom-results.json").is_file()


def test_profile_show_interpolates_in_both_and_never_extrapolates(zoom_run, capsys):
    d, _, _ = zoom_run
    store = ["--store", str(d / "profiles.sqlite")]
    capsys.readouterr()
    assert main(["profile", "show", "ZOOM-0001", "--zoom-mm", "18", "--focus", "0.5", "--json", *store]) == 0
    doc = json.loads(capsys.readouterr().out)
    model = model_from_dict(doc["interpolated"]["model"])
    c = compare_models(model, zoom_lens(18.0, 0.5, W, H), W, H, step=10.0)
    print(f"interpolated at 18 mm, focus 0.5 against the lens: RMS {c.rms:.4f} px, max {c.max:.4f} px")
    assert c.rms < 0.1
    assert {r["axis"] for r in doc["interpolated"]["leave_one_out"]} == {"focal"}
    assert main(["profile", "show", "ZOOM-0001", "--zoom-mm", "40", "--focus", "0.5", *store]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "focal 40 is outside the calibrated range [12, 36]: extrapolation refused" in err[0]
    assert main(["profile", "show", "ZOOM-0001", "--focus", "0.5", *store]) == 2
    assert "is a zoom lens: give --zoom-mm MM with --focus" in capsys.readouterr().err
    assert main(["profile", "show", "ZOOM-0001", "--zoom-mm", "24", "--focus", "1", *store]) == 0
    assert capsys.readouterr().out.splitlines()[0].startswith("focal (mm)\tfocus\tid")


def test_lensfun_export_one_calibration_per_focal_read_by_lensfun(zoom_run, tmp_path, capsys):
    from tests.pipeline.export_support import compare_points, lensfun_in_consumer

    d, _, _ = zoom_run
    xml = tmp_path / "zoom.xml"
    args = ["profile", "export", "ZOOM-0001", "--focus", "0", "--format", "lensfun", "-o", str(xml)]
    store = ["--store", str(d / "profiles.sqlite")]
    # the decentred lens's fitted centres differ per focal: lensfun holds one per lens, refused whole
    assert main([*args, *store]) == 2 and not xml.exists()
    assert "--lensfun-no-center" in capsys.readouterr().err
    assert main([*args, "--lensfun-no-center", *store]) == 0
    text = xml.read_text()
    assert text.count("<distortion ") == 3 and all(f'focal="{z}"' in text for z in FOCALS)
    for z in FOCALS:
        cam, lens, p, q = lensfun_in_consumer(
            text, ("harp station", "SimulatedCamera"), ("Simulated Optics", "SIM-ZOOM-12-36mm"), z, W, H
        )
        rms, mx = compare_points(zoom_lens(z, 0.0, W, H), p, q, W, H)
        print(f"lensfun at {z:g} mm against the lens: RMS {rms:.4f} px, max {mx:.4f} px")
        assert rms < 0.15
    # lensfun has no focus axis for distortion: no focus given is refused in one line, nothing written ...
    capsys.readouterr()
    none = tmp_path / "none.xml"
    assert main(["profile", "export", "ZOOM-0001", "--format", "lensfun", "-o", str(none), *store]) == 2
    err = capsys.readouterr().err.strip()
    assert "name LENS and --focus F" in err and "\n" not in err and not none.exists()
    # ... and the other focus setting exported into the same file replaces each focal's, said so
    assert main([*args[:4], "1", *args[5:], "--lensfun-no-center", *store]) == 0
    err = capsys.readouterr().err
    assert err.count("no focus axis") == 3 and err.count("focus 1 calibration replaced the focus 0 one") == 3
    text = xml.read_text()
    assert text.count("<distortion ") == 3 and "focus setting 0 (" not in text
    _, _, p, q = lensfun_in_consumer(
        text, ("harp station", "SimulatedCamera"), ("Simulated Optics", "SIM-ZOOM-12-36mm"), 36.0, W, H
    )
    assert compare_points(zoom_lens(36.0, 1.0, W, H), p, q, W, H)[0] < 0.15  # the long end at focus 1


def test_lcp_export_one_profile_per_focal_and_focus_applied_by_rawtherapees_equations(zoom_run, tmp_path, capsys):
    """``--format lcp`` at one focus writes a profile per calibrated focal length, filed under the focus
    distance given (another focus setting exported into the same file adds its own: one entry per (focal,
    focus distance); ``tests/station/cli/test_export_lcp.py``)."""
    import numpy as np

    from tests.pipeline.export_support import compare_points
    from tests.pipeline.lcp_equations import correct_distortion, mapper, read_profiles

    d, _, _ = zoom_run
    out = tmp_path / "zoom.lcp"
    store = ["--store", str(d / "profiles.sqlite")]
    stated = {}
    for focus, metres in (("0", 0.5),):
        args = ["profile", "export", "ZOOM-0001", "--focus", focus, "--format", "lcp", "-o", str(out), "--json"]
        assert main([*args, "--distance", str(metres), *store]) == 0
        lines = capsys.readouterr().out.strip().splitlines()
        assert lines[-1] == f"lcp: 3 calibrations (focal 12 mm, 24 mm, 36 mm) at focus {focus} in {out}"
        stated.update({(z, metres): json.loads(ln)["conversion"] for z, ln in zip(FOCALS, lines[:-1], strict=True)})
    prof = read_profiles(out.read_bytes())
    assert [(m["focal"], m["focus"]) for m in prof["models"]] == [(z, 0.5) for z in FOCALS]
    assert not prof["fisheye"]
    p = np.stack(np.meshgrid(np.linspace(0, W - 1, 32), np.linspace(0, H - 1, 24)), axis=-1).reshape(-1, 2)
    for m in prof["models"]:
        q = correct_distortion(mapper(m, W, H, m["focal"]), p, prof["fisheye"])
        rms, mx = compare_points(zoom_lens(m["focal"], 0.0, W, H), p, q, W, H)
        c = stated[(m["focal"], m["focus"])]
        print(
            f"lcp at {m['focal']:g} mm, {m['focus']:g} m against the lens: RMS {rms:.4f} px, max {mx:.4f} px "
            f"(stated against the profile: RMS {c['rms_mod_h_px']:.4f}, max {c['max_mod_h_px']:.4f} px)"
        )
        # the profile is within 0.03 px RMS of the lens (first test); the file within its stated error of it
        assert rms <= 1.3 * c["rms_mod_h_px"] + 0.03


def test_resume_of_a_finished_zoom_session_does_nothing_again(zoom_run, capsys):
    d, _, _ = zoom_run
    capsys.readouterr()
    assert main(["session", "resume", str(d / "sessions" / "z"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("already finished (QA verdict PASS), nothing to do") == 3
