"""What ``harp qa`` judges and with what (:mod:`station.qa.targets`): the thresholds' order of
precedence, the golden reference found as a model file, a stored profile or a lens, and a stored
lens judged. Profiles are stored in a real SQLite file; the verdicts they carry are written by
hand (:func:`tests.station.store.test_database.verdict`), never by the code under test.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from pipeline.compare import compare_models
from pipeline.models import model_from_dict
from station.config import QAConfig
from station.files import write_profile
from station.profile import Verdict
from station.qa.targets import (
    QAInputError,
    Target,
    judge_targets,
    lens_context,
    lens_targets,
    reference_model,
    thresholds_for,
)
from station.qa.verdicts import distortion_magnitude
from station.store import ProfileStore
from tests.station.store.test_database import MODEL, profile, verdict

DISTORTION = distortion_magnitude(model_from_dict(MODEL), 640, 480)[1]  # 5.9 px at the corners
CALIBRATED = Verdict(
    "PASS",
    (),
    {"holdout_d_px": 0.012, "distortion_max_px": DISTORTION},
    (),
    {"max_holdout_d_px": 0.05, "max_distortion_px": 10.0, "max_reference_deviation_px": None},
)
"""The verdict the profiles were calibrated with: their holdout d 0.012 px and distortion, under 0.05 / 10 px."""
NO_OVERRIDES = {"max_holdout_d_px": None, "max_distortion_px": None, "max_reference_deviation_px": None}


def target(p) -> Target:
    return Target(p.focus, p, p.id, "test")


def test_thresholds_command_line_over_config_over_session_over_calibration_over_defaults(tmp_path):
    calibrated = target(profile(qa=verdict(0.01, limit=0.02)))  # calibrated under max holdout d 0.02
    config = SimpleNamespace(qa=QAConfig(max_holdout_d_px=0.03), path=tmp_path / "c.yaml")
    session = SimpleNamespace(config=SimpleNamespace(qa=QAConfig(max_holdout_d_px=0.04)))
    assert thresholds_for(calibrated, NO_OVERRIDES).max_holdout_d_px == 0.02
    assert calibrated.thresholds_from == "calibration"
    assert thresholds_for(calibrated, NO_OVERRIDES, session=session).max_holdout_d_px == 0.04
    assert calibrated.thresholds_from == "the session's configuration"
    assert thresholds_for(calibrated, NO_OVERRIDES, config=config, session=session).max_holdout_d_px == 0.03
    assert calibrated.thresholds_from == f"--config {tmp_path / 'c.yaml'}"
    got = thresholds_for(calibrated, {**NO_OVERRIDES, "max_distortion_px": 7.0}, config=config)
    assert (got.max_holdout_d_px, got.max_distortion_px) == (0.03, 7.0)
    assert calibrated.thresholds_from.endswith(" and the command line")
    unjudged = target(profile())
    assert thresholds_for(unjudged, NO_OVERRIDES) == QAConfig()
    assert unjudged.thresholds_from == "defaults (the profile records none)"


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """Lens S1 at focus 0 and 1 (the same correction), passed; the store's path and ids."""
    path = tmp_path_factory.mktemp("targets") / "p.sqlite"
    with ProfileStore(path) as st:
        ids = [st.put_profile(profile(session="s", focus=f, qa=CALIBRATED)) for f in (0.0, 1.0)]
    return path, ids


def same(a, b) -> bool:
    return compare_models(a, b, 640, 480).max < 1e-9


def opener(path):
    return lambda: ProfileStore(path, create=False)


def test_reference_from_a_model_file_a_stored_profile_or_a_lens(stored, tmp_path):
    path, ids = stored
    truth = model_from_dict(MODEL)
    ref_file = tmp_path / "ref.yaml"
    write_profile(ref_file, profile())
    assert same(reference_model(str(ref_file), opener(path), 0.5, 640, 480), truth)
    with pytest.raises(QAInputError, match=r"is for 640x480 images, not 320x240"):
        reference_model(str(ref_file), opener(path), 0.5, 320, 240)
    with pytest.raises(QAInputError, match=r"reference nowhere/ref.yaml: no such model file"):
        reference_model("nowhere/ref.yaml", opener(path), 0.5, 640, 480)
    assert same(reference_model(f"#{ids[1]}", opener(path), 0.5, 640, 480), truth)
    with pytest.raises(QAInputError, match="no profile #999"):
        reference_model("#999", opener(path), 0.5, 640, 480)
    assert same(reference_model("S1", opener(path), 1.0, 640, 480), truth)  # the lens at a calibrated setting
    between = reference_model("S1", opener(path), 0.5, 640, 480)  # interpolated: that correction, to its grid
    assert compare_models(between, truth, 640, 480).rms < 0.002


def test_a_stored_lens_is_judged_without_its_session(stored):
    path, ids = stored
    with ProfileStore(path, create=False) as st:
        targets = lens_targets(st, "S1")
    assert [(t.focus, t.profile_id, t.source) for t in targets] == [
        (0.0, ids[0], f"profile #{ids[0]}"),
        (1.0, ids[1], f"profile #{ids[1]}"),
    ]
    judged = judge_targets(targets, NO_OVERRIDES, opened={})
    assert judged.overall == "PASS" and [v.verdict for v in judged.verdicts] == ["PASS", "PASS"]
    assert [(t.max_holdout_d_px, t.max_distortion_px) for t in judged.thresholds] == [(0.05, 10.0)] * 2  # as calibrated
    assert judged.interpolation == []  # two settings: nothing to leave out
    assert all("is not at hand" in t.notes[0] for t in targets)  # session "s" is no directory here
    strict = judge_targets(lens_targets_of(path), {**NO_OVERRIDES, "max_holdout_d_px": 0.001}, opened={})
    assert strict.overall == "FAIL" and all(v.checks[0].passed is False for v in strict.verdicts)
    with pytest.raises(QAInputError, match="--reference needs a threshold"):
        judge_targets(lens_targets_of(path), NO_OVERRIDES, reference="S1", open_store=opener(path), opened={})
    rows = lens_context(targets)
    assert rows[0][0] == "software (this report)" and rows[1][0] == "focus 0" and "thresholds from" in rows[1][1]


def lens_targets_of(path):
    with ProfileStore(path, create=False) as st:
        return lens_targets(st, "S1")
