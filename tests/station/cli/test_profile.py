"""``harp profile``: a profile that failed QA is never current (issue 9 item 1); ids can be named
(item 4); ``--json`` and tab-separated tables off a terminal (item 3).

The store is a real SQLite file written through the store's API; each verdict is the one QA gives
the profile (:func:`station.qa.verdicts.qa_verdict`), failing on its holdout d against a 0.001 px
limit. Truth for the interpolated export: between two identical corrections the interpolated
field is that correction.
"""

from __future__ import annotations

import json

import pytest

from pipeline.compare import compare_models
from station.cli import main
from station.qa.verdicts import qa_verdict
from station.store import ProfileStore
from tests.station.store.test_database import MODEL, THRESHOLDS, profile

PASSING = {**THRESHOLDS, "max_distortion_px": 10.0}
FAILING = {**PASSING, "max_holdout_d_px": 0.001, "max_distortion_px": 20.0}  # holdout d is 0.012 px
FAILED_CHECK = "holdout d 0.0120 px > 0.001 px"


OTHER = {**MODEL, "k": [1.0, 0.03]}  # the failed profile's correction: 3x the distortion
"""Were a failed profile used by the interpolation, the result would be far from MODEL."""


def judged(session: str, focus: float, thresholds, lens=("Acme", "50mm", "S1"), model=MODEL):
    from pipeline.models import model_from_dict

    p = profile(session=session, focus=focus, lens=lens).with_(model=model_from_dict(model))
    return p.with_(qa=qa_verdict(p, thresholds))


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """S1: focus 0 and 1 pass; at 0.5 an older session passed and the newest failed.
    S2: focus 0 and 1 failed, 0.5 passed."""
    path = tmp_path_factory.mktemp("profiles") / "p.sqlite"
    ids = {}
    with ProfileStore(path) as st:
        ids["old 0.5"] = st.put_profile(judged("old", 0.5, PASSING))
        for f in (0.0, 1.0):
            ids[f] = st.put_profile(judged("new", f, PASSING))
        ids["failed 0.5"] = st.put_profile(judged("new", 0.5, FAILING, model=OTHER))
        for f, t in ((0.0, FAILING), (0.5, PASSING), (1.0, FAILING)):
            ids[f"S2 {f}"] = st.put_profile(judged("s2", f, t, lens=("Acme", "35mm", "S2")))
    return str(path), ids


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_show_uses_current_profiles_only(store, capsys):
    path, ids = store
    code, out, err = run(capsys, "profile", "show", "S1", "--store", path, "--json")
    doc = json.loads(out)
    assert code == 0 and [p["focus"] for p in doc["profiles"]] == [0.0, 1.0]  # the older pass does not stand in
    assert [p["id"] for p in doc["left_out"]] == [ids["failed 0.5"]]
    assert f"focus 0.5: profile #{ids['failed 0.5']} failed QA ({FAILED_CHECK}): not current" in err
    # --allow-failed: the newest of every focus setting, each failed one said on stderr
    code, out, err = run(capsys, "profile", "show", "S1", "--store", path, "--json", "--allow-failed")
    doc = json.loads(out)
    assert code == 0 and [p["id"] for p in doc["profiles"]] == [ids[0.0], ids["failed 0.5"], ids[1.0]]
    assert doc["profiles"][1]["verdict"] == "FAIL" and doc["profiles"][1]["qa"]["checks"][0]["passed"] is False
    assert err.startswith("harp profile: warning: lens Acme 50mm serial S1, focus 0.5") and err.count("\n") == 1
    # one focus setting whose newest profile failed: exit 1, one line naming lens, focus and check
    code, out, err = run(capsys, "profile", "show", "S1", "--focus", "0.5", "--store", path)
    assert code == 1 and out == "" and err.count("\n") == 1
    assert f"lens Acme 50mm serial S1, focus 0.5: profile #{ids['failed 0.5']} failed QA ({FAILED_CHECK})" in err
    # a profile named by its id is shown whatever its verdict, and said not current
    code, out, err = run(capsys, "profile", "show", "--id", ids["failed 0.5"], "--store", path, "--json")
    (shown,) = json.loads(out)["profiles"]
    assert code == 0 and shown["id"] == ids["failed 0.5"] and shown["verdict"] == "FAIL"
    assert "it is not a current profile" in err
    assert shown["model_parameters"] == OTHER
    code, _, err = run(capsys, "profile", "show", "--id", 9999, "--store", path)
    assert code == 2 and "no profile #9999" in err


def test_list_says_verdict_and_current(store, capsys):
    path, ids = store
    code, out, _ = run(capsys, "profile", "list", "--store", path, "--json")
    rows = {p["id"]: p for p in json.loads(out)["profiles"]}
    assert code == 0 and len(rows) == 7
    current = {i for i, p in rows.items() if p["current"]}
    assert current == {ids[0.0], ids[1.0], ids["S2 0.5"]}
    assert rows[ids["failed 0.5"]]["verdict"] == "FAIL" and rows[ids["old 0.5"]]["verdict"] == "PASS"
    # off a terminal: tab-separated, one header line with units, one line per profile
    code, out, _ = run(capsys, "profile", "list", "--store", path)
    header, *lines = out.splitlines()
    cols = header.split("\t")
    assert code == 0 and "holdout d (px)" in cols and "verdict" in cols and "current" in cols
    assert len(lines) == 7 and all(len(line.split("\t")) == len(cols) for line in lines)
    by_id = {line.split("\t")[0]: dict(zip(cols, line.split("\t"))) for line in lines}
    assert by_id[f"#{ids['failed 0.5']}"]["current"] == "no" and by_id[f"#{ids[0.0]}"]["current"] == "yes"
    assert float(by_id[f"#{ids[0.0]}"]["holdout d (px)"]) == pytest.approx(0.012)


def test_export_refuses_a_failed_profile(store, capsys, tmp_path):
    path, ids = store
    argv = ("profile", "export", "S1", "--focus", "0.5", "--format", "json", "--store", path)
    code, out, err = run(capsys, *argv)
    assert code == 1 and out == "" and err.count("\n") == 1
    assert err == (
        f"harp profile: lens Acme 50mm serial S1, focus 0.5: profile #{ids['failed 0.5']} failed QA "
        f"({FAILED_CHECK}); not exported (--allow-failed exports it anyway)\n"
    )
    code, out, err = run(capsys, *argv, "--allow-failed")
    assert code == 0 and json.loads(out)["model"] == OTHER
    assert err.startswith("harp profile: warning: lens Acme 50mm serial S1, focus 0.5") and "--allow-failed" in err
    # the file says so (issue 21 item 1: the same stamp as the dashboard's)
    assert json.loads(out)["stamp"] == [
        f"FAILED QA: profile #{ids['failed 0.5']} at focus 0.5 was judged FAIL ({FAILED_CHECK}); "
        "exported anyway: do not use it as a calibration that passed"
    ]
    # by id: the same rule
    code, out, err = run(capsys, "profile", "export", "--id", ids["failed 0.5"], "--format", "json", "--store", path)
    assert code == 1 and out == "" and "not exported" in err
    code, out, _ = run(capsys, "profile", "export", "--id", ids[1.0], "--format", "json", "--store", path)
    assert code == 0 and json.loads(out)["model"] == MODEL and "stamp" not in json.loads(out)
    code, _, err = run(capsys, "profile", "export", "S1", "--format", "json", "--store", path)
    assert code == 2 and "--focus" in err and err.count("\n") == 1


def test_interpolation_leaves_failed_profiles_out(store, capsys):
    from pipeline.models import model_from_dict

    path, ids = store
    code, out, err = run(capsys, "profile", "export", "S1", "--focus", "0.25", "--format", "json", "--store", path)
    assert code == 0, err
    assert f"profile #{ids['failed 0.5']} failed QA ({FAILED_CHECK}): not current, left out" in err
    got = model_from_dict(json.loads(out)["model"])
    # between two identical corrections: that correction (to the interpolator's grid, 32 px here)
    assert compare_models(got, model_from_dict(MODEL), 640, 480).rms < 0.002
    assert compare_models(got, model_from_dict(OTHER), 640, 480).rms > 0.5  # the failed one was not used
    # S2: only 0.5 is current; 0.25 lies between failed settings: refused, naming them
    code, out, err = run(capsys, "profile", "export", "S2", "--focus", "0.25", "--format", "json", "--store", path)
    assert code == 1 and out == "" and err.count("\n") == 1
    assert f"focus 0: profile #{ids['S2 0.0']} failed QA" in err and f"focus 1: profile #{ids['S2 1.0']}" in err
    code, out, err = run(
        capsys, "profile", "export", "S2", "--focus", "0.25", "--format", "json", "--store", path, "--allow-failed"
    )
    assert code == 0 and err.count("warning") == 2  # the newest of each setting used, two of them failed
    stamp = json.loads(out)["stamp"]  # the file names the failed profiles it was interpolated from
    assert [line.split(" was judged")[0] for line in stamp] == [
        f"FAILED QA: profile #{ids['S2 0.0']} at focus 0",
        f"FAILED QA: profile #{ids['S2 1.0']} at focus 1",
    ]
