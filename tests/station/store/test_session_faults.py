"""A session meets a bad store (issue 14): a damaged store stops ``harp session run`` with exit 2
before anything is captured; a store whose disk fills up (a real size-limited tmpfs mounted by the
test, as root) stops the session at the store step with one line and exit 2, the frames and fits
kept, and the session resumes once space is freed, each profile stored exactly once."""

import contextlib
import os
import subprocess
from pathlib import Path

import pytest

from station.cli import main
from station.session.directory import SessionDir
from station.session.executor import EXIT_ABORTED, EXIT_OK
from station.session.records import Aborted, FrameSaved
from station.session_run import run_session
from station.store import ProfileStore
from tests.station.fakes import FakeCamera, FakeStage
from tests.station.session.test_executor import make_config


@contextlib.contextmanager
def small_filesystem(where: Path, size_kib: int):
    """A tmpfs of ``size_kib`` KiB mounted at ``where`` (needs root, as CI and the developers' machines run)."""
    where.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size_kib}k,mode=0755", "tmpfs", str(where)],
        capture_output=True,
        text=True,
    )
    if r.returncode != 0:
        pytest.fail(f"cannot mount a tmpfs at {where} ({r.stderr.strip()}): these tests run as root")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)


def fill(directory: Path) -> Path:
    """Fill the filesystem of ``directory`` to the last byte; return the filler file."""
    filler = directory / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        for size in (65536, 4096, 1):
            with contextlib.suppress(OSError):
                while os.write(fd, b"\0" * size) == size:
                    pass
    finally:
        os.close(fd)
    assert os.statvfs(directory).f_bavail == 0
    return filler


def test_damaged_store_stops_the_session_before_capture(tmp_path, capsys):
    from tests.station.cli.test_session import small_config

    cfg = small_config(tmp_path)
    store = tmp_path / "profiles.sqlite"
    with ProfileStore(store) as st:
        from tests.station.store.test_database import put

        for i in range(40):
            put(st, session=f"s{i}", details={"pad": "x" * 600})
    data = bytearray(store.read_bytes())
    data[4 * 4096 : 4 * 4096 + 300] = b"\x5a" * 300
    store.write_bytes(bytes(data))
    assert main(["session", "run", str(cfg), "--quiet", "--no-report"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(store) in err and "damaged" in err and ".recover" in err
    assert not (tmp_path / "sessions").exists()  # stopped before a session directory was made


def test_full_disk_at_the_store_step_stops_with_exit_2_and_resumes(tmp_path, capsys):
    with small_filesystem(tmp_path / "small", 1024) as small:
        store_path = small / "profiles.sqlite"
        cfg = _with_store(make_config(tmp_path, focus=(0.0, 1.0)), store_path)
        ProfileStore(store_path).close()  # an existing store on a disk about to be full
        stage = FakeStage(offset_deg=5.0)
        with ProfileStore(store_path) as store, SessionDir.create(tmp_path / "sessions", cfg, name="s") as s:
            filler = fill(small)
            result = run_session(s, FakeCamera(stage), stage, store=store, sleep=lambda _s: None, report=False)
            assert result.exit_code == EXIT_ABORTED
            msg = result.message
            assert "\n" not in msg and str(store_path) in msg and "no space left" in msg
            assert f"harp session resume {s.path}" in msg
            aborted = list(s.of_type(Aborted))
            assert len(aborted) == 1 and "no space left" in aborted[0].reason
            assert len(list(s.of_type(FrameSaved))) == 4  # every frame of focus 0 kept (stopped at its store step)
        with ProfileStore(store_path) as store:
            assert store.profiles() == []  # nothing half-written
        filler.unlink()  # space freed: resume through the command
        capsys.readouterr()
        assert main(["session", "resume", str(tmp_path / "sessions" / "s"), "--quiet", "--no-report"]) == EXIT_OK
        with ProfileStore(store_path, create=False) as store:
            profiles = store.profiles()
            assert sorted(p.focus for p in profiles) == [0.0, 1.0]
            rows = list(store.qa_results())
            assert sorted(r["profile_id"] for r in rows) == sorted(p.id for p in profiles)  # once each
            assert all(p.qa is not None for p in profiles)


def _with_store(cfg, store_path: Path):
    """The configuration with its store on ``store_path``."""
    import yaml

    from station.config import load_config

    d = yaml.safe_load(cfg.path.read_text())
    d["store"]["path"] = str(store_path)
    cfg.path.write_text(yaml.safe_dump(d))
    return load_config(cfg.path)


def test_a_session_repaired_into_another_store_never_judges_that_stores_profiles(tmp_path, capsys):
    """A session whose manifest records the store ids of its profiles (#1, #2 in its store), repaired with
    ``--store`` naming another station's store, where #1 and #2 are another lens's failed profiles: before, its QA
    recorded its PASS as those profiles' verdicts (the other lens's failed profile #2 became PASS, current and
    exportable; its session row pointed at this session), exit 0. Now it is refused before anything is fitted or
    stored, with one line naming the store and what to do, and the other store is as it was (no row changed or
    added); QA checks the same when it records a verdict."""
    import json
    import sqlite3

    import yaml

    from tests.station.cli.test_session import small_config

    mine = small_config(tmp_path / "mine")
    assert main(["session", "run", str(mine), "--name", "a", "--quiet", "--no-report"]) == 0
    theirs = small_config(tmp_path / "theirs")
    d = yaml.safe_load(theirs.read_text())
    d["lens"]["serial"] = "OTHER-9"
    d["qa"]["max_holdout_d_px"] = 0.0001  # every profile of this lens fails
    theirs.write_text(yaml.safe_dump(d))
    assert main(["session", "run", str(theirs), "--name", "b", "--quiet", "--no-report"]) == 1
    capsys.readouterr()
    other = tmp_path / "theirs" / "profiles.sqlite"

    def rows():
        with contextlib.closing(sqlite3.connect(other)) as db:
            return (
                db.execute("SELECT id, lens_id, verdict, qa_json, session_dir FROM profiles ORDER BY id").fetchall(),
                db.execute("SELECT * FROM qa_results ORDER BY id").fetchall(),
            )

    before = rows()
    assert [r[2] for r in before[0]] == ["FAIL", "FAIL"]
    session = tmp_path / "mine" / "sessions" / "a"
    kept = [json.loads(line) for line in (session / "manifest.jsonl").read_text().splitlines()]
    assert sorted(r["profile_id"] for r in kept if r["kind"] == "stored") == [1, 2]  # the ids of its own store
    measured = next(r["file"] for r in kept if r["kind"] == "measure" and r["focus_idx"] == 0)
    (session / measured).write_bytes(b"damaged")  # repair fits focus setting 0 again, then judges both

    code = main(["session", "repair", str(session), "--store", str(other)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.strip().splitlines()[-1] == (
        f"harp session: {other}: profile #1 is the profile of session {tmp_path / 'theirs' / 'sessions' / 'b'} at "
        f"focus 0, not of {session} at focus 0; nothing was captured, fitted or stored (the session stored its "
        "profiles in another store: give that one with --store, or leave --store out for its configuration's)"
    ), err
    assert rows() == before  # the other lens's profiles, verdicts and session rows untouched, and nothing added
    # the same refusal when the session's verdicts are recorded (QA), for a store whose ids are checked only then
    from station.qa.judge import judge_session
    from station.store.errors import StoreError

    with SessionDir.open(session) as s, ProfileStore(str(other)) as store, pytest.raises(StoreError, match=" is the "):
        judge_session(s, store=store)
    assert rows() == before
    # its own store: repaired, QA PASS
    assert main(["session", "repair", str(session)]) == 0, capsys.readouterr().err
