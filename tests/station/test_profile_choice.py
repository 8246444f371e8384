"""Which profile a command uses at a focus setting, and why (:mod:`station.profile_choice`).

Profiles are stored in a real SQLite file; verdicts are written by hand as QA writes them
(:func:`tests.station.store.test_database.verdict`). Truth for the interpolation: between two
identical corrections the interpolated field is that correction (to the interpolator's grid).
"""

from __future__ import annotations

import pytest

from pipeline.compare import compare_models
from pipeline.models import model_from_dict
from station.profile_choice import (
    ChoiceError,
    FailedQA,
    at_focus,
    current_and_left_out,
    failed_checks,
    failed_line,
    interpolate,
    is_failed,
    lens_label,
    lens_row,
    verdict_text,
)
from station.store import ProfileStore
from tests.station.store.test_database import MODEL, profile, verdict

LENS = (7, "Acme", "50mm", "S1")


def test_words_of_a_verdict():
    passed, failed, unjudged = profile(qa=verdict(0.01)), profile(qa=verdict(0.08)).with_(id=4), profile()
    assert [is_failed(p) for p in (passed, failed, unjudged)] == [False, True, False]
    assert [verdict_text(p) for p in (passed, failed, unjudged)] == ["PASS", "FAIL", ""]
    assert failed_checks(failed) == "holdout d 0.0800 px <= 0.05 px"  # the failed check's text, verdict cut off
    assert failed_checks(unjudged) == "not judged"
    reasons_only = failed.with_(qa=failed.qa.__class__("FAIL", ("no edges",)))
    assert failed_checks(reasons_only) == "no edges"
    assert lens_row(failed) == (None, "Acme", "50mm", "S1") and lens_row(failed.with_(lens=None))[1:] == ("-",) * 3
    assert lens_label(LENS) == "lens Acme 50mm serial S1"
    assert failed_line(LENS, failed) == (
        "lens Acme 50mm serial S1, focus 0.5: profile #4 failed QA (holdout d 0.0800 px <= 0.05 px)"
    )


def test_at_focus_matches_within_the_tolerance_only():
    ps = [profile(focus=0.0), profile(focus=0.5)]
    assert at_focus(ps, 0.5 + 1e-12) is ps[1] and at_focus(ps, 0.25) is None and at_focus([], 0.0) is None


def test_current_and_left_out(tmp_path):
    with ProfileStore(tmp_path / "p.sqlite") as st:
        ids = [
            st.put_profile(profile(session="a", focus=0.0, qa=verdict(0.01))),
            st.put_profile(profile(session="a", focus=0.5, qa=verdict(0.01))),  # older, passed
            st.put_profile(profile(session="b", focus=0.5, qa=verdict(0.08))),  # newest at 0.5, failed
        ]
        lens_id = st.find_lens("S1")[0]
        used, left_out = current_and_left_out(st, lens_id, allow_failed=False)
        assert [p.id for p in used] == [ids[0]] and [p.id for p in left_out] == [ids[2]]  # no stand-in
        used, left_out = current_and_left_out(st, lens_id, allow_failed=True)
        assert [p.id for p in used] == [ids[0], ids[2]] and left_out == []


def test_interpolate_between_identical_corrections_is_that_correction():
    ps = [profile(focus=0.0).with_(id=1), profile(focus=1.0).with_(id=2)]
    got = interpolate(LENS, ps, 0.25)
    assert compare_models(got.model, model_from_dict(MODEL), 640, 480).rms < 0.002  # to the 32 px grid of the field
    assert (got.width, got.height, got.leave_one_out) == (640, 480, ())  # two settings: nothing to leave out
    assert got.note.startswith("focus 0.25 is not calibrated") and got.known() == "0, 1"
    p = got.profile()
    assert p.focus == 0.25 and p.lens == ps[0].lens and p.provenance.extra["from_profiles"] == [1, 2]
    assert p.merit.extra == {"interpolation_leave_one_out": []} and p.provenance.extra["note"] == got.note


def test_interpolate_never_extrapolates_and_names_the_failed_profiles():
    ps = [profile(focus=0.0), profile(focus=0.5)]
    with pytest.raises(ChoiceError, match=r"not between two calibrated focus settings \(0, 0.5\)"):
        interpolate(LENS, ps, 0.75)
    failed = profile(focus=1.0, qa=verdict(0.08)).with_(id=9)
    with pytest.raises(FailedQA, match="left out: lens Acme 50mm serial S1, focus 1: profile #9 failed QA"):
        interpolate(LENS, ps, 0.75, left_out=[failed])
    other_size = profile(focus=1.0).with_(width=320, height=240)
    with pytest.raises(ChoiceError, match="different image sizes"):
        interpolate(LENS, [*ps, other_size], 0.75)
