"""station.reprocess without re-fitting: the jobs of an archive and the failures that are values.

(The whole re-processing, local and on a Dask cluster, is tests/station/cli/test_reprocess.py.)
"""

from __future__ import annotations

import json
import shutil

import pytest

from station.reprocess import FocusJob, ReprocessError, plan_jobs, probe_scheduler, reprocess_focus, run_jobs


@pytest.fixture
def copy(factory_archive, tmp_path):
    dst = tmp_path / "s1"
    shutil.copytree(factory_archive.session, dst)
    return dst


def test_one_job_per_focus_setting_the_session_stored(factory_archive, tmp_path):
    stored = [
        json.loads(l)["focus_idx"]
        for l in (factory_archive.session / "manifest.jsonl").read_text().splitlines()
        if json.loads(l).get("kind") == "stored"
    ]
    (tmp_path / "not-a-session").mkdir()
    jobs, failed = plan_jobs([factory_archive.session, tmp_path / "not-a-session"], spec="auto")
    assert [j.focus_idx for j in jobs] == sorted(stored) == [0, 1]
    assert all(j.session_dir == str(factory_archive.session.resolve()) and j.spec == "auto" for j in jobs)
    assert list(failed) == [str((tmp_path / "not-a-session").resolve())]
    assert "not a session directory (no session.json)" in failed[str((tmp_path / "not-a-session").resolve())]


def test_a_missing_frame_is_the_jobs_failure_not_an_exception(copy):
    frame = sorted((copy / "frames").glob("f1_o2_*.png"))[0]
    frame.unlink()
    r = run_jobs([FocusJob(str(copy), 1)], workers=1)[0]
    assert r.profile is None and r.focus is None
    assert r.failure == f"{frame}: cannot read (No such file or directory)"


def test_a_damaged_manifest_fails_the_job_in_one_line(copy):
    (copy / "session.json").write_text("{not json")
    r = reprocess_focus(FocusJob(str(copy), 0))
    assert r.profile is None
    assert r.failure.startswith(f"{copy / 'session.json'}: cannot read") and "\n" not in r.failure


def test_scheduler_address_is_checked_before_dask_is_asked():
    with pytest.raises(ReprocessError, match="tcp://HOST:PORT"):
        probe_scheduler("localhost:8786")
    with pytest.raises(ReprocessError, match="cannot reach the Dask scheduler at tcp://127.0.0.1:9"):
        probe_scheduler("tcp://127.0.0.1:9")


def test_a_session_is_finished_and_stored_when_its_last_focus_result_arrives(tmp_path):
    from station.reprocess import FocusResult, OldProfile, SessionCollector, reprocess_key
    from station.store import ProfileStore
    from tests.station.store.test_database import profile

    old = OldProfile(None, None, "PASS", "harp-station 0.0.1")
    ok = lambda d, f: FocusResult(FocusJob(d, f), 0.5 * f, profile(focus=0.5 * f, session=d), old)  # noqa: E731
    jobs = [FocusJob("/a", 0), FocusJob("/a", 1), FocusJob("/b", 0)]
    told = []
    with ProfileStore(tmp_path / "p.sqlite") as store:
        collect = SessionCollector(jobs, store, on_outcome=told.append)
        collect(ok("/a", 1))  # any order: /a is finished only with both of its focus settings
        collect(FocusResult(FocusJob("/b", 0), 0.0, None, None, failure="frame damaged"))
        assert [o.session_dir for o in told] == ["/b"] and not told[0].ok and told[0].failure == "frame damaged"
        collect(ok("/a", 0))
        a = collect.outcomes["/a"]
        assert a.ok and [r.job.focus_idx for r in a.results] == [0, 1] and len(a.new_ids) == 2
        stored = [store.profile(i) for i in a.new_ids]
    assert [p.focus for p in stored] == [0.0, 0.5] and {p.provenance.session_dir for p in stored} == {
        reprocess_key("/a")
    }
    assert stored[0].provenance.extra["reprocess"]["old_software"] == "harp-station 0.0.1"
    dry = SessionCollector(jobs[:1])  # no store: finished, nothing stored
    dry(ok("/a", 0))
    assert dry.outcomes["/a"].ok and dry.outcomes["/a"].new_ids == [] and len(dry.outcomes["/a"].profiles) == 1


def test_reprocessing_a_session_rebuilds_the_profile_it_stored(factory_archive):
    """Issue 22 item 1: the session and ``harp reprocess`` build a focus setting's profile by the
    same builder (station.calibration.calibrate_focus / focus_profile): re-processing the frames
    with the session's configuration gives the model, spec, selection and verdict it stored."""
    import numpy as np

    for f in (0, 1):
        r = reprocess_focus(FocusJob(str(factory_archive.session), f))
        assert r.failure is None, r.failure
        old = r.old.profile
        assert old is not None and r.profile is not None
        assert r.profile.spec == old.spec and r.profile.selection == old.selection
        a, b = r.profile.model.to_dict(), old.model.to_dict()
        assert a.keys() == b.keys()
        for k in a:
            if isinstance(a[k], (int, float, list)):
                np.testing.assert_allclose(np.asarray(a[k], float), np.asarray(b[k], float), rtol=1e-9, atol=1e-12)
            else:
                assert a[k] == b[k], k
        assert r.profile.qa is not None and old.qa is not None
        assert r.profile.qa.verdict == old.qa.verdict == r.old.verdict
        assert [c.split(":")[0] for c in r.profile.qa.reasons] == [c.split(":")[0] for c in old.qa.reasons]


def test_the_selection_reasons_are_written_in_one_place():
    """Issue 22 item 1: the reason a given spec is recorded with is written once
    (station.calibration), the session, ``harp calibrate`` and ``harp reprocess`` import it."""
    from pathlib import Path

    from station.calibration import GIVEN_BY_CONFIG, GIVEN_ON_COMMAND_LINE

    root = Path(__file__).resolve().parents[2] / "station"
    for text in (GIVEN_BY_CONFIG, GIVEN_ON_COMMAND_LINE):
        holders = [p.relative_to(root).as_posix() for p in root.rglob("*.py") if text in p.read_text()]
        assert holders == ["calibration.py"], (text, holders)
