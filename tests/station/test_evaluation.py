"""Correction files read for ``harp evaluate`` (:mod:`station.evaluation`): a harp model file read back
as the model written, and every problem one line naming the file."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.compare import compare_models
from station.evaluation import EvaluateError, evaluate, load_correction
from station.files import write_profile
from tests.station.store.test_database import profile


def test_a_harp_model_file_reads_back_as_its_model(tmp_path):
    p = profile()
    write_profile(tmp_path / "lens.yaml", p)
    model, kind = load_correction(tmp_path / "lens.yaml", 640, 480)
    assert kind == "harp:radial" and compare_models(model, p.model, 640, 480).max < 1e-9


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("none", None, "correction file not found ('none' means no correction only with --already-corrected)"),
        ("missing.yml", None, "correction file not found"),
        ("dir", "DIR", "is a directory, not a correction file"),
    ],
)
def test_bad_correction_files_are_one_line(tmp_path, name, content, message):
    path = tmp_path / name
    if content == "DIR":
        path.mkdir()
    with pytest.raises(EvaluateError) as exc:
        load_correction(path if name != "none" else "none", 640, 480)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_shots_without_strings_are_named_and_nothing_is_left_to_evaluate(tmp_path):
    import cv2

    shot = tmp_path / "flat.png"
    cv2.imwrite(str(shot), np.full((60, 80), 100, np.uint8))
    with pytest.raises(EvaluateError) as exc:
        evaluate("none", [shot], already_corrected=True)
    assert str(exc.value) == "no string edge found in any image"  # the shot's own line is in the report's errors
    other = tmp_path / "small.png"
    cv2.imwrite(str(other), np.full((30, 40), 100, np.uint8))
    with pytest.raises(EvaluateError, match="no string edge found in any image; .*all shots must have the same size"):
        evaluate("none", [shot, other], already_corrected=True)
