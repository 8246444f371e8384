"""The profile record: every typed field survives the model file and the store row; older
files and rows are read for what they hold."""

import json
import sqlite3

import pytest

from pipeline.fitspec import FitSpec
from pipeline.intrinsics import Intrinsics, distortion_digest
from pipeline.model_file import parse_model_text
from pipeline.models import RadialModel
from station.config import Identity, Optics
from station.profile import (
    HOLDOUT_LEAVE_ONE_ORIENTATION_OUT,
    Check,
    Figures,
    Holdout,
    Merit,
    Profile,
    Provenance,
    UncertaintySummary,
    Verdict,
)
from station.store import ProfileStore
from tests.station.store.legacy import legacy_schema

W, H = 640, 480
MODEL = RadialModel.for_image(W, H, k=(1.0, 0.0, 0.02, 0.0, -0.003), center=(321.5, 240.25), tangential=(1e-4, -2e-4))

FULL = Profile(
    model=MODEL,
    width=W,
    height=H,
    spec=FitSpec("radial", 4, tangential=True),
    selection={"reason": "radial4+tangential: leave-one-shot-out CV d 0.0012 px", "folds": "images"},
    merit=Merit(
        fit=Figures(0.0012, 0.0047),
        holdout=Holdout(0.0013, 0.005, HOLDOUT_LEAVE_ONE_ORIENTATION_OUT, (0.0012, 0.0014, 0.0013)),
        before=Figures(1.25, 4.5),
        field_uncertainty=UncertaintySummary(0.0006, 0.0034, 12),
        extra={"rejected_edges": [{"line": 3, "reason": "outlier"}]},
    ),
    qa=Verdict(
        "FAIL",
        ("holdout d 0.0013 px > 0.001 px: ...",),
        {"holdout_d_px": 0.0013, "distortion_max_px": 1.3},
        (
            Check("holdout_d", 0.0013, "<=", 0.001, False, "holdout d 0.0013 px <= 0.001 px"),
            Check("distortion_max", 1.3, "<=", 5.0, True, "distortion max 1.300 px <= 5 px"),
        ),
        {"max_holdout_d_px": 0.001, "max_distortion_px": 5.0, "max_reference_deviation_px": None},
    ),
    lens=Identity("Acme", "12mm", "L-1"),
    camera=Identity("Cam", "Body", "C-1"),
    focus=0.5,
    focal=12.0,
    optics=Optics(focal_mm=12.0, mount="C", pixel_pitch_um=3.45, crop_factor=5.6),
    provenance=Provenance(
        created_utc="2026-12-01T18:11:21Z",
        software="harp-station 0.1.0",
        command="harp session",
        t=30,
        images=(("frames/a.pgm", "ab" * 32), ("frames/b.pgm", "cd" * 32)),
        station="st-1",
        session_dir="/data/sessions/s1",
        extra={"holdout": [{"path": "x.pgm"}]},
    ),
    details={"n_points": 1234, "warnings": []},
    intrinsics=Intrinsics(
        fx=812.5,
        fy=811.25,
        cx=321.0,
        cy=239.5,
        skew=0.0,
        sd=(0.25, 0.5, 0.125, 0.0625, 0.0),
        covariance=tuple(tuple(float(i == j) / (i + 2) for j in range(5)) for i in range(5)),
        width=W,
        height=H,
        rms_px=0.031,
        holdout_rms_px=0.034,
        n_views=6,
        n_points=144,
        source="harp intrinsics: 6 ChArUco views",
        distortion=distortion_digest(MODEL),
        holdout_per_view=(0.03, 0.032, 0.04, 0.031, 0.033, 0.035),
        views=tuple(f"b{i}.png" for i in range(6)),
        warnings=("fy known to 1.5 % only",),
    ),
)


def test_model_file_round_trip_keeps_every_typed_field():
    mf = FULL.to_model_file()
    back = Profile.from_model_file(parse_model_text(mf.text(), "p.yaml"))
    assert back == FULL.with_(details={})  # fit diagnostics live in the store, not in the file
    doc = mf.merit
    assert doc["holdout"]["scheme"] == HOLDOUT_LEAVE_ONE_ORIENTATION_OUT  # the layout model files had
    assert doc["field_uncertainty"] == {"rms": 0.0006, "max": 0.0034, "replicates": 12}
    assert doc["choice"]["label"] == "radial4+tangential" and mf.provenance["focus"] == 0.5
    assert mf.provenance["optics"] == {"focal_mm": 12.0, "mount": "C", "pixel_pitch_um": 3.45, "crop_factor": 5.6}


def test_lens_info_is_what_an_export_needs_of_the_profile():
    info = FULL.lens_info()
    assert (info.lens_maker, info.lens_model, info.lens_serial) == ("Acme", "12mm", "L-1")
    assert (info.camera_maker, info.camera_model, info.focus) == ("Cam", "Body", 0.5)
    assert info.nominal_focal_px(W) == pytest.approx(12.0 / 3.45e-3)  # f / pitch
    assert (info.mount, info.crop_factor, info.sensor_width_mm) == ("C", 5.6, None)
    assert Profile(MODEL, W, H).lens_info() == type(info)()  # nothing known: every field empty


def test_store_row_round_trip_keeps_every_typed_field(tmp_path):
    with ProfileStore(tmp_path / "p.sqlite") as st:
        pid = st.put_profile(FULL)
        back = st.profile(pid)
    assert back.stored_at is not None
    assert back == FULL.with_(id=pid, stored_at=back.stored_at)


def test_a_profile_without_its_identity_cannot_be_stored(tmp_path):
    from station.store import StoreError

    with ProfileStore(tmp_path / "p.sqlite") as st, pytest.raises(StoreError, match="lens, camera, focus"):
        st.put_profile(Profile(MODEL, W, H))


def test_an_older_model_file_gives_what_it_holds():
    text = (
        "format: harp-distortion-model\nformat_version: 1\n"
        f"model: {json.dumps(MODEL.to_dict())}\nimage: {{width: {W}, height: {H}}}\n"
        "merit: {fit: {d: 0.01, d_max: 0.04}, holdout: {d: 0.02, d_max: 0.05}}\n"
        "provenance: {focus: 0.25}\n"
    )
    p = Profile.from_model_file(parse_model_text(text, "old.yaml"))
    assert p.spec is None and p.qa is None and p.lens is None and p.focus == 0.25
    assert p.merit.fit == Figures(0.01, 0.04) and p.merit.holdout == Holdout(0.02, 0.05)
    assert p.merit.field_uncertainty is None


def test_a_schema_2_row_is_migrated_and_read_from_its_figures_and_details(tmp_path):
    path = tmp_path / "old.sqlite"
    db = sqlite3.connect(path)
    legacy_schema(db, 2)
    db.execute("INSERT INTO lenses (maker, model, serial) VALUES ('Acme', '12mm', 'L-1')")
    db.execute("INSERT INTO cameras (maker, model, serial) VALUES ('Cam', 'Body', 'C-1')")
    details = {
        "d_before": 1.25,
        "d_max_before": 4.5,
        "holdout_per_orientation": [0.0012, 0.0014],
        "bootstrap_replicates": 12,
        "fit": {"model": "radial", "degree": 4, "tangential": True, "prism": False},
    }
    db.execute(
        "INSERT INTO profiles (lens_id, camera_id, focus, model_name, model_json, width, height, fit_d, fit_d_max,"
        " holdout_d, holdout_d_max, field_uncertainty_rms, field_uncertainty_max, session_dir, station_id,"
        " software_version, created_at, details_json) VALUES (1, 1, 0.5, 'radial', ?, ?, ?, 0.0012, 0.0047,"
        " 0.0013, 0.005, 0.0006, 0.0034, '/s1', 'st-1', '0.1.0', '2026-12-01T18:11:21+00:00', ?)",
        (json.dumps(MODEL.to_dict()), W, H, json.dumps(details)),
    )
    db.commit()
    db.close()
    with ProfileStore(path) as st:
        (p,) = st.profiles()
    assert p.model == MODEL and (p.width, p.height) == (W, H) and p.focus == 0.5
    assert p.lens == Identity("Acme", "12mm", "L-1") and p.camera == Identity("Cam", "Body", "C-1")
    assert p.spec == FitSpec("radial", 4, tangential=True)
    assert p.merit.fit == Figures(0.0012, 0.0047) and p.merit.before == Figures(1.25, 4.5)
    assert p.merit.holdout == Holdout(0.0013, 0.005, HOLDOUT_LEAVE_ONE_ORIENTATION_OUT, (0.0012, 0.0014))
    assert p.merit.field_uncertainty == UncertaintySummary(0.0006, 0.0034, 12)
    assert p.provenance.software == "harp-station 0.1.0" and p.provenance.station == "st-1"
    assert p.provenance.session_dir == "/s1" and p.stored_at == "2026-12-01T18:11:21+00:00" and p.qa is None


def test_a_verdict_is_kept_with_its_profile(tmp_path):
    with ProfileStore(tmp_path / "p.sqlite") as st:
        pid = st.put_profile(FULL.with_(qa=None))
        assert st.profile(pid).qa is None
        st.record_verdict(pid, FULL.qa)
        assert st.profile(pid).qa == FULL.qa
        with st.engine.connect() as conn:
            got = conn.exec_driver_sql("SELECT verdict FROM profiles WHERE id = ?", (pid,)).scalar()
        assert got == "FAIL"
