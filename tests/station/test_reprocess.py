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
    frame = sorted((copy / "frames").glob("f1_o2_*.pgm"))[0]
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
