"""``harp qa`` through station.cli.main: exit codes 0 PASS / 1 FAIL / 2 error."""

import json
import shutil
import sys
import textwrap

import pytest

from drivers.sim.lens import lens_for_focus
from station.cli import main
from station.config import Identity
from station.files import write_model_file
from station.profile import Holdout, Merit, Profile, Provenance
from station.qa.verdicts import session_profiles
from station.store import ProfileStore
from tests.station.processes import run_process
from tests.station.qa_session import H, W, build_session


def stored(p, lens, focus, session_dir):
    """A profile as a store keeps it: of ``lens`` at ``focus``, from ``session_dir``, station "t"."""
    return p.with_(
        lens=Identity(*lens),
        camera=Identity("c", "m", "s"),
        focus=focus,
        merit=Merit(holdout=Holdout(p.merit.holdout_d)),
        provenance=Provenance(station="t", session_dir=session_dir, software="harp-station 0"),
    )


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return build_session(tmp_path_factory.mktemp("qa"))


def qa(capsys, *args):
    code = main(["qa", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def qa_json(capsys, *args):
    code, out, err = qa(capsys, *args, "--json")
    return code, (json.loads(out) if out.strip() else None), err


def test_session_passes_and_is_recorded(session, capsys):
    code, out, err = qa_json(capsys, session)
    assert code == 0, err
    assert out["verdict"] == "PASS" and [p["focus"] for p in out["profiles"]] == [0.0, 0.5, 1.0]
    for p in out["profiles"]:
        assert p["passed"] and p["figures"]["holdout_d_px"] < 0.05 and p["figures"]["distortion_max_px"] < 5
    (loo,) = out["interpolation"]
    assert loo["focus"] == 0.5 and 0 < loo["rms_px"] < 0.05
    with ProfileStore(session.parent.parent / "profiles.sqlite") as st:
        rows = list(st.qa_results())
    assert [r["verdict"] for r in rows[-3:]] == ["PASS"] * 3
    assert rows[-1]["session_dir"] == str(session.resolve())


def test_fail_on_threshold_is_exit_1(session, capsys):
    code, out, _ = qa_json(capsys, session, "--max-holdout-d", "1e-6", "--no-record")
    assert code == 1 and out["verdict"] == "FAIL"
    assert all("holdout d" in p["reasons"][0] for p in out["profiles"])
    code, out, _ = qa_json(capsys, session, "--max-distortion", "0.01", "--no-record")
    assert code == 1 and all(p["reasons"][0].startswith("distortion") for p in out["profiles"])
    code, text, err = qa(capsys, session, "--max-distortion", "0.01", "--no-record")
    assert code == 1 and err.rstrip().endswith("QA: FAIL")


def test_reference_model_file(session, tmp_path, capsys):
    ref = tmp_path / "golden.yaml"
    write_model_file(ref, lens_for_focus(0.0, W, H), width=W, height=H)
    code, out, _ = qa_json(capsys, session, "--reference", ref, "--max-reference-deviation", "0.05", "--no-record")
    assert code == 1
    f0, f05, f1 = out["profiles"]
    # the fit at focus 0 matches the golden lens (focus 0); focus 1 is another lens state
    assert f0["passed"] and f0["figures"]["reference_max_px"] < 0.05
    assert not f1["passed"] and "deviates from the reference" in f1["reasons"][0]
    assert f1["figures"]["reference_max_px"] > f05["figures"]["reference_max_px"] > f0["figures"]["reference_max_px"]


def test_lens_in_store_with_reference_lens(session, tmp_path, capsys):
    store = tmp_path / "p.sqlite"
    with ProfileStore(store) as st:
        for _f, p in session_profiles(session):
            st.put_profile(stored(p, ("Sim", "SIM-12mm", "UNIT-7"), p.focus, str(session)))
        # the golden lens: the true demo lens, calibrated at focus 0 and 1 only
        for focus in (0.0, 1.0):
            golden = Profile(lens_for_focus(focus, W, H), W, H, merit=Merit(holdout=Holdout(0.0)))
            st.put_profile(stored(golden, ("Sim", "SIM-12mm", "GOLDEN"), focus, "golden"))
    code, out, err = qa_json(
        capsys, "UNIT-7", "--store", store, "--reference", "GOLDEN", "--max-reference-deviation", "0.05"
    )
    assert code == 0, err
    # focus 0.5 was judged against the golden lens interpolated between 0 and 1
    assert [p["profile_id"] is not None for p in out["profiles"]] == [True] * 3
    assert all(p["figures"]["reference_max_px"] < 0.05 for p in out["profiles"])
    with ProfileStore(store) as st:
        assert len(list(st.qa_results())) == 3


@pytest.mark.parametrize(
    "args, message",
    [
        (["no-such-lens", "--store", "{store}"], "no lens matching"),
        (["{tmp}"], "not a session directory"),
        # issue 21 item 4: a path that does not exist is a missing path, not a lens the store lacks
        (["{tmp}/sessions/nothere", "--store", "{store}"], "no such session directory"),
        (["./nothere", "--store", "{store}"], "no such session directory"),
        # a file given for the session: was "no lens matching '.../other-size.yaml'" (or, without a store, "no
        # profile store here")
        (["{ref}", "--store", "{store}"], "other-size.yaml: a file, not a session directory (give a session"),
        (["{ref}", "--store", "{tmp}/none.sqlite"], "other-size.yaml: a file, not a session directory"),
        (["SIM 50mm f/1.8", "--store", "{store}"], "no lens matching"),
        (["{session}", "--reference", "{ref}"], "--reference needs a threshold"),
        (["{session}", "--reference", "{ref}", "--max-reference-deviation", "1"], "is for 640x480 images"),
        (["{session}", "--reference", "{tmp}/missing.yaml", "--max-reference-deviation", "1"], "no such model file"),
        (["{session}", "--reference", "#99", "--max-reference-deviation", "1", "--store", "{store}"], "no profile #99"),
    ],
)
def test_errors_are_one_line_exit_2(session, tmp_path, capsys, args, message):
    store = tmp_path / "p.sqlite"
    ProfileStore(store).close()
    ref = tmp_path / "other-size.yaml"
    write_model_file(ref, lens_for_focus(0.0, 640, 480), width=640, height=480)
    fill = {"store": store, "tmp": tmp_path, "session": session, "ref": ref}
    code, out, err = qa(capsys, *[a.format(**fill) for a in args], "--no-record")
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err


def test_session_without_profiles_and_bad_threshold(session, tmp_path, capsys):
    empty = tmp_path / "s"
    shutil.copytree(session, empty)
    for p in (empty / "profiles").iterdir():
        p.unlink()
    code, _, err = qa(capsys, empty, "--no-record")
    assert code == 2 and "the session is not finished (focus 0 has no profile" in err and "focus 1 has no" in err
    code, _, err = qa(capsys, empty, "--no-record", "--partial")
    assert code == 2 and "no fitted profile" in err
    with pytest.raises(SystemExit) as exc:
        main(["qa", str(session), "--max-holdout-d", "-3"])
    assert exc.value.code == 2


def test_unwritable_report_dir_is_one_line_naming_it(session, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    code, out, err = qa(capsys, session, "--report", blocker / "report", "--no-record")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        f"harp qa: {blocker / 'report'}: cannot write the report (Not a directory: {blocker / 'report'})"
    ], err


def test_corrupt_reference_file_is_named_once(session, tmp_path, capsys):
    ref = tmp_path / "golden.yaml"
    ref.write_text("format: harp-distortion-model\nformat_version: 1\nmodel: [\n")
    code, out, err = qa(capsys, session, "--reference", ref, "--max-reference-deviation", "1", "--no-record")
    assert code == 2 and err.startswith(f"harp qa: reference {ref}: not a valid YAML model file")
    assert err.count(str(ref)) == 1 and err.count("\n") == 1, err


@pytest.fixture
def cut_first_qa_commit(monkeypatch):
    """The first commit of a ``harp qa`` history row is written, and then its connection is lost before the
    command hears so (the server or the network gone at that moment): the store says it may or may not
    have been written. Returns the list of what happened ("cut" once it did)."""
    import sqlite3

    import sqlalchemy as sa

    happened = []
    armed = []
    commit = sa.engine.default.DefaultDialect.do_commit
    put = ProfileStore.put_qa_result

    def do_commit(self, dbapi_connection):
        commit(self, dbapi_connection)
        if armed and not happened:
            happened.append("cut")
            if self.name == "sqlite":  # what the driver then finds: a closed connection
                dbapi_connection.close()
                raise sqlite3.ProgrammingError("Cannot operate on a closed database.")
            # the server ends the connection (as an administrator's pg_terminate_backend or a restart would)
            dbapi_connection.execute("SELECT pg_terminate_backend(pg_backend_pid())")

    def put_qa_result(self, **kw):
        armed.append(1)
        try:
            return put(self, **kw)
        finally:
            armed.pop()

    monkeypatch.setattr(sa.engine.default.DefaultDialect, "do_commit", do_commit)
    monkeypatch.setattr(ProfileStore, "put_qa_result", put_qa_result)
    return happened


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_qa_run_again_after_a_commit_that_may_not_be_written_records_each_row_once(
    backend, session, tmp_path, capsys, request, cut_first_qa_commit
):
    if backend == "sqlite":
        store = str(tmp_path / "store.sqlite")
    else:
        store = request.getfixturevalue("postgres").create_database(f"qa_{tmp_path.name[-20:].lower()}")

    def command_rows():
        with ProfileStore(store, create=False) as st:
            return [(r["focus"], r["verdict"]) for r in st.qa_results() if r["origin"] == "command"]

    code, _, err = qa(capsys, session, "--store", store)
    assert cut_first_qa_commit == ["cut"]
    warned = [line for line in err.splitlines() if "result not recorded" in line]
    assert len(warned) == 1 and "may or may not have been written" in warned[0], err
    assert f"run harp qa {session} again to record it" in warned[0]
    assert command_rows() == [(0.0, "PASS")]  # the first row was written after all

    assert qa(capsys, session, "--store", store)[0] == code  # run again, as the warning says
    assert command_rows() == [(0.0, "PASS"), (0.5, "PASS"), (1.0, "PASS")]  # each focus once

    # a later run, and a run under other thresholds, are QA runs of their own: rows of their own
    assert qa(capsys, session, "--store", store)[0] == code
    assert qa(capsys, session, "--store", store, "--max-distortion", "0.01")[0] == 1
    rows = command_rows()
    assert len(rows) == 9 and rows[3:6] == rows[:3] and [v for _f, v in rows[6:]] == ["FAIL"] * 3


KILLED_AFTER_COMMIT = textwrap.dedent(
    """
    import os, signal, sys
    from station.cli import main
    from station.store import ProfileStore

    after = int(sys.argv[1])  # killed (SIGKILL: no handler, no finally) once this many rows are committed
    put = ProfileStore.put_qa_result
    done = []

    def put_qa_result(self, **kw):
        got = put(self, **kw)  # its transaction committed
        done.append(1)
        if len(done) == after:
            os.kill(os.getpid(), signal.SIGKILL)
        return got

    ProfileStore.put_qa_result = put_qa_result
    sys.exit(main(sys.argv[2:]))
    """
)


@pytest.mark.parametrize("after", [1, 3])
def test_qa_killed_right_after_a_commit_then_run_again_records_each_row_once(after, session, tmp_path, capsys):
    """``harp qa`` killed by SIGKILL (or a power cut) right after the commit of its first row, or of its last one
    (before it could say so): nothing of it ran after the commit. Run again with the same results, each focus
    setting's row is in the QA history once; a later run adds rows of its own."""
    store = str(tmp_path / "store.sqlite")
    code = qa(capsys, session, "--store", store, "--no-record")[0]  # the verdict, nothing recorded
    done = run_process(
        [sys.executable, "-c", KILLED_AFTER_COMMIT, str(after), "qa", str(session), "--store", store], timeout=240
    )
    assert done.returncode == -9, done.stderr

    def command_rows():
        with ProfileStore(store, create=False) as st:
            return [(r["focus"], r["verdict"]) for r in st.qa_results() if r["origin"] == "command"]

    assert command_rows() == [(0.0, "PASS"), (0.5, "PASS"), (1.0, "PASS")][:after]  # what the commits wrote
    assert qa(capsys, session, "--store", store)[0] == code  # run again
    assert command_rows() == [(0.0, "PASS"), (0.5, "PASS"), (1.0, "PASS")]  # each focus once
    assert qa(capsys, session, "--store", store)[0] == code  # a later run: rows of its own
    assert len(command_rows()) == 6


def _tree(root):
    """Every file under ``root`` (hidden ones too) with its bytes, by relative path."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_qa_of_a_session_writes_nothing_into_it(session, tmp_path, capsys):
    """``harp qa DIR`` judges a session: before, it opened it as a resume does, cutting a torn last manifest
    line, removing temporaries and holding the disk reserve in it."""
    copy = tmp_path / "s1"
    shutil.copytree(session, copy)
    (copy / "manifest.jsonl").open("a").write('{"kind": "fra')  # a torn last line, as a kill leaves it
    (copy / "frames" / ".f0_o0_a0_i0.png.tmp1").write_bytes(b"partial")  # a write a kill interrupted
    (copy / ".reserve").unlink()
    before = _tree(copy)
    code, out, err = qa_json(capsys, copy, "--no-record")
    assert code == 0 and out["verdict"] == "PASS", err
    assert _tree(copy) == before


def test_two_harp_qa_of_one_session_at_once_both_judge_it(session, tmp_path, capsys):
    """Another reader holding the session (a second ``harp qa`` of it) does not refuse this one; a session
    running in it (its exclusive lock) still does, saying what to do. Before, the second ``harp qa`` was
    refused with `session is in use by another process`, exit 2."""
    import fcntl

    from station.session.directory import SessionDir, SessionError

    with open(session / ".lock", "rb") as reader:  # another harp qa, judging it: its shared lock
        fcntl.flock(reader, fcntl.LOCK_SH | fcntl.LOCK_NB)
        code, out, err = qa_json(capsys, session, "--no-record")
        assert code == 0 and out["verdict"] == "PASS", err
    with SessionDir.open(session, read_only=True):
        with pytest.raises(SessionError, match="in use by another process"):
            SessionDir.open(session)  # a resume waits for the readers
    with open(session / ".lock", "a+") as held:  # a session running in it
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        code, out, err = qa(capsys, session, "--no-record")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        f"harp qa: {session}: session is in use by another process (a session running in it, or another harp "
        "command using it); wait until it ends, then run again"
    ], err


@pytest.fixture
def read_only_copy(session, tmp_path):
    """The session under a read-only bind mount (an archive, a share this user cannot write; root only)."""
    import os
    import subprocess

    if os.geteuid() != 0:
        pytest.skip("a read-only bind mount needs root (CI runs as root)")
    mnt = tmp_path / "archive"
    mnt.mkdir()
    if subprocess.run(["mount", "--bind", str(session.parent), str(mnt)], capture_output=True).returncode != 0:
        pytest.skip("no bind mount here (a container without CAP_SYS_ADMIN); the writes-nothing test still runs")
    try:
        subprocess.run(["mount", "-o", "remount,bind,ro", str(mnt)], check=True)
        yield mnt / session.name
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_qa_of_a_session_on_a_read_only_file_system(session, read_only_copy, capsys):
    """Before: `harp qa: [Errno 30] Read-only file system: '…/.lock'`, exit 2 — a session in a read-only
    archive could not be judged again."""
    with pytest.raises(OSError):
        (read_only_copy / "probe").write_text("")  # really read-only
    code, out, err = qa_json(capsys, read_only_copy, "--no-record")
    assert code == 0, err
    code_rw, out_rw, err_rw = qa_json(capsys, session, "--no-record")
    assert code_rw == 0, err_rw
    assert [(p["focus"], p["verdict"], p["figures"]) for p in out["profiles"]] == [
        (p["focus"], p["verdict"], p["figures"]) for p in out_rw["profiles"]
    ]


def test_a_damaged_kept_measurement_is_named_with_what_to_do(tmp_path, capsys):
    """A measurement file the session kept, damaged since: ``harp qa DIR`` judges the stored figures and says which
    file and ``harp session repair``; before, it said `the session kept no measurements for this focus setting`."""
    from tests.station.cli.test_session import small_config

    cfg = small_config(tmp_path, focus=(0.0,))
    assert main(["session", "run", str(cfg), "--name", "s", "--quiet", "--no-report"]) == 0
    capsys.readouterr()
    sdir = tmp_path / "sessions" / "s"
    kept = [json.loads(line) for line in (sdir / "manifest.jsonl").read_text().splitlines()]
    (measured,) = [r["file"] for r in kept if r["kind"] == "measure" and r.get("orientation_idx") == 1]
    code, out, err = qa_json(capsys, sdir, "--no-record")
    assert code == 0 and out["profiles"][0]["measurements"] is not None, err  # recomputed while whole
    data = bytearray((sdir / measured).read_bytes())
    data[len(data) // 2] ^= 0xFF
    (sdir / measured).write_bytes(bytes(data))
    code, out, err = qa_json(capsys, sdir, "--no-record")
    assert code == 0 and out["profiles"][0]["measurements"] is None, err
    (note,) = out["profiles"][0]["notes"]
    assert note.startswith(f"{sdir / measured}: checksum does not match the manifest: stored figures judged"), note
    assert note.endswith(f"run: harp session repair {sdir} (it fits the focus setting again from its frames)"), note
    # the lens judged from the store: the session its profile names is at hand, its measurement damaged
    code, out, err = qa_json(capsys, "DEMO-0001", "--store", tmp_path / "profiles.sqlite", "--no-record")
    assert code == 0 and out["profiles"][0]["measurements"] is None, err
    assert any(
        n.startswith(f"{sdir / measured}: checksum does not match the manifest") for n in out["profiles"][0]["notes"]
    )


def test_qa_of_an_unfinished_session_gives_no_verdict_unless_partial(tmp_path, capsys):
    """A session whose plan has three focus settings, stopped after two: ``harp qa DIR`` says which focus setting
    has no profile and what to do, exit 2, nothing recorded; ``--partial`` judges the two (PASS) and names the
    third. Then the third's fit recorded as failed: the line gives its reason. Before, the two were judged and
    the session passed, exit 0, as if the lens had been calibrated at every focus setting of its plan."""
    from station.session.directory import SessionDir
    from station.session.records import FitFailed

    sdir = build_session(tmp_path, fitted=2)  # the plan's focus settings: 0, 0.5, 1
    code, out, err = qa(capsys, sdir)
    assert (code, out) == (2, "")
    assert err.strip().splitlines() == [
        f"harp qa: {sdir}: the session is not finished (focus 1 has no profile: not fitted and stored yet): run harp "
        f"session resume {sdir} to finish it, then harp qa again (--partial judges the profiles it has)"
    ], err
    assert not (tmp_path / "profiles.sqlite").exists()  # no QA history row of a verdict not given

    code, out, err = qa_json(capsys, sdir, "--partial", "--no-record")
    assert code == 0 and out["verdict"] == "PASS", err
    assert [p["focus"] for p in out["profiles"]] == [0.0, 0.5]
    assert out["unfinished"] == ["focus 1 has no profile: not fitted and stored yet"]
    assert "harp qa: focus 1 has no profile: not fitted and stored yet: not judged (--partial)" in err.splitlines()

    with SessionDir.open(sdir) as s:
        s.append(FitFailed(2, "too few edges in two directions"))
    code, out, err = qa(capsys, sdir, "--no-record")
    assert code == 2 and "(focus 1 has no profile: its fit failed (too few edges in two directions))" in err, err
