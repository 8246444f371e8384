"""``harp profile`` and ``harp qa`` find their store one way (--store PATH|URL, --config CONFIG),
on both backends, from any directory; reading never creates a store; damage is one line, exit 2."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from station.cli import main
from station.store import ProfileStore
from station.store.location import parse_store
from tests.station.store.conftest import tamper
from tests.station.store.test_database import THRESHOLDS, profile, put

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs" / "demo.yaml"


def config_naming(dirpath: Path, store_url: str, **qa) -> Path:
    """A station configuration in ``dirpath`` whose store is ``store_url`` (a file named relative to it),
    with ``qa`` thresholds over the demo's."""
    d = yaml.safe_load(DEMO.read_text())
    d["qa"].update(qa)
    loc = parse_store(store_url)
    d["store"] = (
        {"path": str(Path("..") / loc.path.parent.name / loc.path.name)}
        if loc.backend == "sqlite"
        else {"url": store_url}
    )
    dirpath.mkdir(parents=True, exist_ok=True)
    p = dirpath / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_profile_and_qa_find_the_store_by_url_or_config(store_url, tmp_path, monkeypatch, capsys):
    from station.qa.verdicts import qa_verdict

    with ProfileStore(store_url) as st:
        for focus in (0.0, 0.5, 1.0):  # judged as a session does, under a 10 px distortion limit
            p = profile(focus=focus)
            st.put_profile(p.with_(qa=qa_verdict(p, {**THRESHOLDS, "max_distortion_px": 10.0})))
    cfg = config_naming(tmp_path / "cfg", store_url, max_distortion_px=5.0)
    other = tmp_path / "elsewhere"
    other.mkdir()
    monkeypatch.chdir(other)  # relative paths in the config are relative to the config, not here
    monkeypatch.delenv("HARP_STORE", raising=False)
    for opts in (["--store", store_url], ["--config", str(cfg)]):
        capsys.readouterr()
        assert main(["profile", "list", *opts]) == 0, capsys.readouterr().err
        assert "S1" in capsys.readouterr().out
        assert main(["profile", *opts, "show", "S1", "--focus", "0.5"]) == 0
        capsys.readouterr()
        # --store: judged under the thresholds it was calibrated with (10 px: PASS); --config brings its
        # own thresholds (max_distortion_px 5 fails this 5.9 px lens)
        code = main(["qa", "S1", *opts, "--json"])
        out = json.loads(capsys.readouterr().out)
        assert len(out["profiles"]) == 3
        if opts[0] == "--store":
            assert code == 0 and out["verdict"] == "PASS"
        else:
            assert code == 1 and out["verdict"] == "FAIL" and "distortion" in out["profiles"][0]["reasons"][0]
    with ProfileStore(store_url, create=False) as st:
        rows = list(st.qa_results())
        assert sum(r["origin"] == "command" for r in rows) == 6 and sum(r["origin"] == "session" for r in rows) == 3
        assert all(r["checks"] for r in rows)  # every run of harp qa kept its checks
    assert sorted(p.name for p in other.iterdir()) == []  # nothing created where the command ran


def test_reading_a_store_that_is_not_there_creates_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("HARP_STORE", raising=False)
    for argv in (
        ["profile", "list"],
        ["profile", "show", "S1", "--store", "nowhere/p.sqlite"],
        ["qa", "S1", "--store", "nowhere/p.sqlite"],
        ["profile", "list", "--config", str(config_naming(tmp_path / "cfg", str(tmp_path / "db" / "p.sqlite")))],
    ):
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "no profile store here" in err, (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg"]  # no store, no profiles/ directory


def test_bad_store_names_and_servers_are_one_line(tmp_path, capsys):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    for store, says in (
        ("mysql://x@h/db", "unknown store URL scheme"),
        (f"postgresql://harp@127.0.0.1:{port}/harp", "cannot connect"),
    ):
        capsys.readouterr()
        assert main(["profile", "list", "--store", store]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err and "Traceback" not in err


def test_profile_list_shows_the_readable_rows_and_reports_the_damaged(store_url, raw, capsys):
    with ProfileStore(store_url) as st:
        bad = put(st, session="a")
        put(st, session="b", lens=("B", "b", "GOOD-1"))
    tamper(raw, f"UPDATE profiles SET model_json = '{{broken' WHERE id = {bad}")
    assert main(["profile", "list", "--store", store_url]) == 2
    out, err = capsys.readouterr()
    assert "GOOD-1" in out
    assert err.count("\n") == 1 and f"profile #{bad}" in err and "cannot be read" in err


def test_damaged_sqlite_store_is_one_line_for_every_reading_command(tmp_path, capsys):
    store = tmp_path / "p.sqlite"
    with ProfileStore(store) as st:
        for i in range(40):
            put(st, session=f"s{i}", details={"pad": "x" * 600})
    data = bytearray(store.read_bytes())
    data[3 * 4096 : 3 * 4096 + 400] = b"\x33" * 400
    store.write_bytes(bytes(data))
    for argv in (
        ["profile", "list"],
        ["profile", "show", "S1"],
        ["profile", "export", "S1", "--focus", "0.5", "--format", "json"],
        ["qa", "S1"],
    ):
        capsys.readouterr()
        assert main([*argv, "--store", str(store)]) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(store) in err and "Traceback" not in err, (argv, err)


def test_commands_that_do_not_use_the_store_do_not_import_sqlalchemy():
    code = (
        "import sys\nfrom station.cli import main\n"
        "try:\n    main(['measure', '--help'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('sqlalchemy', 'alembic', 'psycopg') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_a_station_that_cannot_open_creates_no_store(tmp_path, capsys):
    from tests.station.cli.test_session import small_config

    cfg = small_config(tmp_path)
    d = yaml.safe_load(cfg.read_text())
    d["station"]["camera"]["width"] = 8  # the simulated camera refuses it when opened
    cfg.write_text(yaml.safe_dump(d))
    for extra in ([], ["--store", str(tmp_path / "other.sqlite")]):
        assert main(["session", "run", str(cfg), "--quiet", *extra]) == 2
        assert capsys.readouterr().err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["station.yaml"]  # no store, no sessions


def test_session_run_into_the_store_named_on_the_command_line(postgres, tmp_path):
    from tests.station.store.stations import station_config

    url = postgres.create_database("cli_session")
    cfg = station_config(tmp_path, str(tmp_path / "config-store.sqlite"), "CLI-1", seed=3)
    assert main(["session", "run", str(cfg), "--quiet", "--no-report", "--store", url]) == 0
    with ProfileStore(url, create=False) as st:
        (p,) = st.profiles()
        assert p.lens.serial == "CLI-1" and p.qa is not None
        assert [r["origin"] for r in st.qa_results()] == ["session"]
    assert not (tmp_path / "config-store.sqlite").exists()


def test_a_stored_model_with_a_nan_parameter_is_a_damaged_row_for_every_reading_command(tmp_path, capsys):
    # was shown (profile show --id, exit 0), judged and, on export, "our correction is undefined over much of the image"
    store = tmp_path / "p.sqlite"
    with ProfileStore(store) as st:
        bad = put(st, session="a")
        put(st, session="b", lens=("B", "b", "GOOD-1"))
        doc = json.loads(
            st.engine.connect().exec_driver_sql(f"SELECT model_json FROM profiles WHERE id = {bad}").scalar()
        )
        doc["k"][-1] = float("nan")
        tamper(st.engine, f"UPDATE profiles SET model_json = '{json.dumps(doc)}' WHERE id = {bad}")
    for argv in (["profile", "show", "--id", str(bad)], ["profile", "export", "--id", str(bad), "--format", "json"]):
        assert main([*argv, "--store", str(store)]) == 2, argv
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1, err
        assert f"profile #{bad} (lens S1, focus 0.5) cannot be read (model.k[{len(doc['k']) - 1}] is nan)" in err
    assert main(["profile", "list", "--store", str(store)]) == 2
    out, err = capsys.readouterr()
    assert "GOOD-1" in out and err.count("\n") == 1 and f"profile #{bad}" in err


_PASSWORD = "s3cret-pw"


@pytest.mark.parametrize(
    "store",
    [
        f"postgresql://harp:{_PASSWORD}@127.0.0.1:99999/harp",  # bad port
        f"postgresql://harp:{_PASSWORD}@127.0.0.1:5432/",  # no database
        f"postgresql://harp:{_PASSWORD}@:5432/harp",  # no host
        f"mysql://harp:{_PASSWORD}@127.0.0.1/harp",  # another scheme
    ],
)
def test_a_store_url_the_command_refuses_is_named_without_its_password(store, capsys):
    for argv in (["profile", "list", "--store", store], ["qa", "DEMO-0001", "--store", store]):
        capsys.readouterr()
        assert main(argv) == 2
        out, err = capsys.readouterr()
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert "harp:***@" in err and _PASSWORD not in err + out, err


@pytest.mark.parametrize("pid", [2**31, 2**63, 10**20, -(2**63) - 1])
def test_a_profile_id_no_row_can_have_is_not_found(store_url, pid, capsys):
    """An id beyond the id column's integer (SQLite 64-bit, PostgreSQL 32-bit): `no profile #N in STORE`, exit 2, as
    any id not in the store; before: `internal error: OverflowError: Python int too large to convert to SQLite
    INTEGER` (PostgreSQL: `integer out of range`)."""
    with ProfileStore(store_url) as st:
        put(st)
        where = str(st.location)
    for args in (["profile", "--store", store_url, "show", "--id", str(pid)],
                 ["profile", "--store", store_url, "export", "--id", str(pid), "--format", "opencv"]):  # fmt: skip
        capsys.readouterr()
        assert main(args) == 2
        out, err = capsys.readouterr()
        assert out == "" and err == f"harp profile: no profile #{pid} in {where}\n", err
