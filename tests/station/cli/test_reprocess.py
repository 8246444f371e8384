"""``harp reprocess`` on a real archived session: on a local process pool and on a real Dask cluster
(``LocalCluster`` with two worker processes), into a real SQLite file and a real PostgreSQL server.

The archive is one real session of the small demo station (tests/station/archive.py). The pipeline
has not changed since it was recorded, so its re-processed profiles must be the profiles the
session itself stored — the executor's fit is the independent reference — and the same on both
runners. A copy of the session with one damaged frame must be reported (one line, exit 2) while
the good session is re-processed and stored.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import shutil
import uuid

import numpy as np
import pytest

from station import __version__
from station.cli import main
from station.store import ProfileStore


def _main(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def _damage_frames(session):
    """One pixel changed in the first frame of each focus setting: the manifest's SHA-256 no longer
    matches (each job fails at its first frame)."""
    frames = [sorted((session / "frames").glob(f"f{f}_o0_*.png"))[0] for f in (0, 1)]
    for frame in frames:
        data = bytearray(frame.read_bytes())
        data[-100] ^= 0x55
        frame.write_bytes(bytes(data))
    return frames


@pytest.fixture(scope="module")
def runs(factory_archive, tmp_path_factory, postgres):
    """The same archive re-processed twice: on the local pool (into the archive's SQLite store, a
    damaged copy of the session beside it) and on a Dask LocalCluster (into a PostgreSQL database)."""
    from dask.distributed import LocalCluster

    root = tmp_path_factory.mktemp("reprocess") / "archive"
    shutil.copytree(factory_archive.root, root, symlinks=True)
    good, sqlite_store = root / "sessions" / "s1", root / "profiles.sqlite"
    bad = root / "sessions" / "s1-damaged"
    shutil.copytree(good, bad)
    damaged = _damage_frames(bad)
    with ProfileStore(sqlite_store, create=False) as st:
        before = {p.id: p for p in st.profiles()}
    local = _main(["reprocess", good, bad, "--workers", "2", "--store", sqlite_store])

    pg = postgres.create_database(f"reprocess_{uuid.uuid4().hex[:12]}")
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", host="127.0.0.1"
    ) as cluster:
        dask = _main(["reprocess", good, "--scheduler", cluster.scheduler_address, "--store", pg, "--json"])
    return {
        "good": good,
        "bad": bad,
        "damaged": damaged,
        "before": before,
        "sqlite": sqlite_store,
        "pg": pg,
        "local": local,
        "dask": dask,
    }


def _reprocessed(store_where):
    with ProfileStore(store_where, create=False) as st:
        return {p.focus: p for p in st.profiles() if "#reprocess-" in (p.provenance.session_dir or "")}


def _field(p, n=9):
    """The profile's correction at an n x n grid over its image (px), from its stored model."""
    xs, ys = np.meshgrid(np.linspace(0, p.width - 1, n), np.linspace(0, p.height - 1, n))
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1)
    return np.asarray(p.model.undistort_points(pts))


def test_local_pool_reports_the_damaged_session_and_stores_the_good_one(runs):
    code, out, err = runs["local"]
    assert code == 2
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("harp reprocess: ") and "checksum does not match" in lines[0]
    assert all(str(frame) in lines[0] for frame in runs["damaged"])
    assert "Traceback" not in out + err
    new = _reprocessed(runs["sqlite"])
    assert sorted(new) == [0.0, 1.0]  # both focus settings of the good session, none of the damaged one
    for p in new.values():
        assert p.provenance.extra["reprocess"]["session"] == str(runs["good"])
    assert "1 session(s) re-processed, 1 failed" in out


def test_reprocessed_profiles_are_the_sessions_own_and_keep_the_old_ones(runs):
    before = runs["before"]
    with ProfileStore(runs["sqlite"], create=False) as st:
        after = {p.id: p for p in st.profiles()}
    assert set(before) <= set(after)  # nothing replaced: the old profiles stay
    for p in before.values():
        assert after[p.id].model.to_dict() == p.model.to_dict()
    new = _reprocessed(runs["sqlite"])
    old_by_focus = {p.focus: p for p in before.values()}
    for f, p in new.items():
        old = old_by_focus[f]
        # the same frames through the same pipeline: the executor's fit, to rounding
        assert np.abs(_field(p) - _field(old)).max() < 1e-9
        assert p.merit.holdout.d == pytest.approx(old.merit.holdout.d, abs=1e-9)
        assert p.qa.verdict == old.qa.verdict == "PASS"


def test_provenance_names_the_session_the_old_profile_and_the_versions(runs):
    import numpy
    import scipy

    before = {p.focus: p for p in runs["before"].values()}
    for f, p in _reprocessed(runs["sqlite"]).items():
        r = p.provenance.extra["reprocess"]
        old = before[f]
        assert r["session"] == str(runs["good"])
        assert r["old_profile_id"] == old.id
        assert r["old_verdict"] == "PASS"
        assert r["old_software"] == old.provenance.software
        assert r["versions"]["harp-station"] == __version__
        assert r["versions"]["numpy"] == numpy.__version__ and r["versions"]["scipy"] == scipy.__version__
        assert p.provenance.session_dir == f"{old.provenance.session_dir}#reprocess-{__version__}"
        assert p.provenance.command == "harp reprocess"


def test_old_and_new_figures_are_printed(runs):
    # off a terminal: tab-separated, an old and a new column per figure, the sessions' whole paths
    _code, out, _err = runs["local"]
    header, *lines = out.split("\n\n")[0].splitlines()
    cols = header.split("\t")
    rows = [dict(zip(cols, l.split("\t"))) for l in lines]
    assert all(len(l.split("\t")) == len(cols) for l in lines)
    assert "holdout d old (px)" in cols and "verdict new" in cols and "│" not in out
    good = [r for r in rows if r["session"] == str(runs["good"])]
    assert len(good) == 2, out  # the good session's two focus settings ...
    assert any(r["session"].endswith("s1-damaged") and r["verdict new"] == "failed" for r in rows)  # ... the damaged
    new = _reprocessed(runs["sqlite"])
    for old in runs["before"].values():
        row = next(r for r in good if r["focus"] == f"{old.focus:g}")
        assert (row["profile old"], row["profile new"]) == (f"#{old.id}", f"#{new[old.focus].id}")
        assert row["holdout d old (px)"] == f"{old.merit.holdout.d:.4f}"
        assert row["holdout d new (px)"] == f"{new[old.focus].merit.holdout.d:.4f}"
        assert (row["verdict old"], row["verdict new"]) == ("PASS", "PASS")


def test_dask_cluster_gives_the_same_profiles_as_the_local_pool(runs):
    code, out, err = runs["dask"]
    assert code == 0, err
    doc = json.loads(out)
    assert doc["reprocessed"] == 1 and doc["failed"] == 0
    # the jobs ran on the cluster's worker processes, not here
    ran_on = {e["worker"] for s in doc["sessions"] for e in s["focus"]}
    assert ran_on and all(
        w.split(":")[-1].isdigit() and int(w.split(":")[-1]) != __import__("os").getpid() for w in ran_on
    )
    local, dask = _reprocessed(runs["sqlite"]), _reprocessed(runs["pg"])
    assert sorted(dask) == sorted(local) == [0.0, 1.0]
    for f in local:
        a, b = local[f], dask[f]
        assert a.model.to_dict() == b.model.to_dict()  # identical, not merely close
        assert a.merit.to_dict() == b.merit.to_dict()
        assert a.qa.to_dict() == b.qa.to_dict()
        # the PostgreSQL store does not hold the session's old profile: named by the session only
        assert b.provenance.extra["reprocess"]["old_profile_id"] is None
        assert b.provenance.extra["reprocess"]["session"] == str(runs["good"])
    for s in doc["sessions"]:
        for e in s["focus"]:
            assert e["new"]["profile_id"] == dask[e["focus"]].id
            assert e["new"]["holdout_d_px"] == dask[e["focus"]].merit.holdout.d


# ------------------------------------------------------------------ faults (no re-processing)
@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--workers", "0"], "--workers must be at least 1"),
        (["--model", "nonsense"], "--model nonsense"),
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:9"], "--workers is for the local pool"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_2(factory_archive, argv, needle):
    code, out, err = _main(["reprocess", factory_archive.session, *argv])
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and needle in err


def test_what_is_not_a_session_is_reported_and_nothing_is_stored(tmp_path):
    (tmp_path / "empty").mkdir()
    code, out, err = _main(["reprocess", tmp_path / "empty", "--store", tmp_path / "st.sqlite"])
    assert code == 2
    assert "not a session directory" in err and str(tmp_path / "empty") in err and err.count("\n") == 1
    assert not (tmp_path / "st.sqlite").exists()
    code, _out, err = _main(["reprocess", tmp_path / "missing"])
    assert code == 2 and "no such session directory" in err
    (tmp_path / "a.png").write_bytes(b"")  # was "no such session directory" of a file that is there
    code, _out, err = _main(["reprocess", tmp_path / "a.png"])
    assert code == 2 and err == f"harp reprocess: {tmp_path / 'a.png'}: a file, not a session directory\n"


def test_a_session_whose_manifest_is_lost_is_named_so_and_nothing_is_stored(factory_archive, tmp_path):
    # was "the session stored no profile (nothing to re-process)" of a session holding three profiles
    s = tmp_path / "s"
    shutil.copytree(factory_archive.session, s)
    (s / "manifest.jsonl").unlink()
    code, out, err = _main(["reprocess", s, "--store", tmp_path / "st.sqlite", "--workers", "1"])
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"harp reprocess: {s / 'manifest.jsonl'}: missing, but the session holds what it recorded")
    assert "restore manifest.jsonl from a backup" in err and not (tmp_path / "st.sqlite").exists()


@pytest.mark.parametrize(
    ("address", "needle"),
    [
        ("tcp://127.0.0.1:9", "cannot reach the Dask scheduler at tcp://127.0.0.1:9"),
        ("127.0.0.1:8786", "give the Dask scheduler's address as tcp://HOST:PORT"),
    ],
)
def test_a_scheduler_that_cannot_be_used_is_one_line_and_creates_no_store(factory_archive, tmp_path, address, needle):
    store = tmp_path / "new.sqlite"
    code, out, err = _main(["reprocess", factory_archive.session, "--scheduler", address, "--store", store])
    assert code == 2 and out == ""
    assert err.startswith("harp reprocess: ") and needle in err and err.count("\n") == 1
    assert not store.exists()


def _stored_profiles(store) -> int:
    """Profiles in the SQLite store as another process writes it (0 while it cannot be read)."""
    import sqlite3

    try:
        with contextlib.closing(sqlite3.connect(f"file:{store}?mode=ro", uri=True, timeout=0.1)) as con:
            return int(con.execute("SELECT count(*) FROM profiles").fetchone()[0])
    except sqlite3.Error:
        return 0


@pytest.mark.parametrize("moment", ["pool start", "after the first stored session"])
def test_ctrl_c_is_one_line_exit_130_and_what_was_stored_is_whole(factory_archive, tmp_path, moment):
    """Ctrl-C at the terminal (SIGINT to the whole process group: the command and its pool) while
    the sessions are re-processed: one line, exit 130, and every session in the store complete.
    The moment is chosen by what the store shows, not by a delay (a fast machine once finished the
    whole run before a fixed delay ran out): as soon as the store exists (the jobs are planned and
    the pool starts), or as soon as it holds a first session's profiles, with six left to do."""
    import os
    import signal
    import subprocess
    import sys
    import time

    sessions = []
    for k in range(8):
        shutil.copytree(factory_archive.session, tmp_path / f"s{k}")
        sessions.append(tmp_path / f"s{k}")
    store = tmp_path / "st.sqlite"
    cmd = [
        sys.executable,
        "-m",
        "station.cli",
        "reprocess",
        *map(str, sessions),
        "--workers",
        "2",
        "--store",
        str(store),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.time() + 120
    while not store.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.02)  # the store is opened once the jobs are planned, just before they start
    if moment != "pool start":
        while _stored_profiles(store) < 2 and time.time() < deadline and proc.poll() is None:
            time.sleep(0.02)  # a session is stored with both its focus settings at once
    assert proc.poll() is None, "the re-processing ended before Ctrl-C could be sent"
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (out, err)
    assert "Traceback" not in err and err.count("\n") == 1, err
    m = re.match(r"harp reprocess: interrupted: (\d+) session\(s\) re-processed and stored before Ctrl-C", err)
    assert m, err
    done = int(m.group(1))
    assert _stored_profiles(store) == 2 * done  # both focus settings of each session said stored, no more
    if moment != "pool start":
        assert 1 <= done < len(sessions)
        with ProfileStore(store, create=False) as st:  # what was stored reads back whole
            assert len(st.profiles()) == 2 * done
    else:  # interrupted while the store was made, or just after: running it again stores everything
        again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert again.returncode == 0, again.stderr
        assert _stored_profiles(store) == 2 * (done + len(sessions))


def test_field_sets_the_sessions_pipeline_field(factory_archive, tmp_path):
    """``--field auto`` runs the residual-field stage the session's configuration (``pipeline.field: none``) did
    not: each new profile's choice says what it made of a field, where the session's profiles say nothing of one."""
    root = tmp_path / "archive"
    shutil.copytree(factory_archive.root, root, symlinks=True)
    good, store = root / "sessions" / "s1", root / "profiles.sqlite"
    with ProfileStore(store, create=False) as st:
        old = list(st.profiles())
    assert old and all("residual field" not in p.selection.get("reason", "") for p in old)
    code, out, err = _main(["reprocess", good, "--field", "auto", "--workers", "1", "--store", store, "--json"])
    assert code == 0 and err == "", err
    new = _reprocessed(store)
    assert sorted(new) == sorted(p.focus for p in old)
    for p in new.values():
        assert "residual field: " in p.selection["reason"], p.selection


# ------------------------------------------------------------------ --dry-run: the store only read
def _archive_copy(factory_archive, tmp_path):
    root = tmp_path / "archive"
    shutil.copytree(factory_archive.root, root, symlinks=True)
    return root / "sessions" / "s1", root / "profiles.sqlite"


def test_dry_run_names_the_stored_profile_each_result_would_replace_and_writes_nothing(factory_archive, tmp_path):
    # was: the dry run never opened the store, and its "profile old" column was empty
    good, store = _archive_copy(factory_archive, tmp_path)
    with ProfileStore(store, create=False) as st:
        before = {p.focus: p for p in st.profiles()}
    data = store.read_bytes()
    code, out, err = _main(["reprocess", good, "--dry-run", "--workers", "1", "--store", store])
    assert code == 0 and err == "", err
    header, *lines = out.split("\n\n")[0].splitlines()
    rows = [dict(zip(header.split("\t"), l.split("\t"))) for l in lines]
    assert sorted(r["focus"] for r in rows) == ["0", "1"]
    for r in rows:
        assert (r["profile old"], r["profile new"]) == (f"#{before[float(r['focus'])].id}", "")
    assert "new profiles not stored (--dry-run)" in out
    assert store.read_bytes() == data  # nothing written, nothing upgraded
    with ProfileStore(store, create=False) as st:
        assert {p.id for p in st.profiles()} == {p.id for p in before.values()}


def test_dry_run_without_a_store_or_with_an_older_one_says_so_and_neither_creates_nor_upgrades_it(
    factory_archive, tmp_path
):
    import sqlite3

    good, store = _archive_copy(factory_archive, tmp_path)
    missing = tmp_path / "none" / "store.sqlite"
    code, out, err = _main(["reprocess", good, "--dry-run", "--workers", "1", "--store", missing, "--json"])
    assert code == 0, err
    assert err == (
        f"harp reprocess: warning: {missing}: no profile store here; name one with --store or --config "
        "(--dry-run: the old profiles' store ids are not shown)\n"
    )
    assert not missing.parent.exists()  # neither the file nor its directory made
    doc = json.loads(out)
    assert doc["store"] is None and doc["stored"] is False and doc["reprocessed"] == 1
    assert [e["old"]["profile_id"] for s in doc["sessions"] for e in s["focus"]] == [None, None]

    with contextlib.closing(sqlite3.connect(store)) as con, con:  # as a store an older harp wrote looks
        con.execute("UPDATE alembic_version SET version_num = '0005'")
    code, out, err = _main(["reprocess", good, "--dry-run", "--workers", "1", "--store", store, "--json"])
    assert code == 0, err
    assert err.startswith(f"harp reprocess: warning: {store}: written by older software (revision 0005; ")
    assert err.endswith("(--dry-run: the old profiles' store ids are not shown)\n") and err.count("\n") == 1
    with contextlib.closing(sqlite3.connect(store)) as con:
        assert con.execute("SELECT version_num FROM alembic_version").fetchone() == ("0005",)  # not upgraded
    assert json.loads(out)["store"] is None
