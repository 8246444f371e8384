"""The store every command finds without being told, from any directory (issue 21 item 4): the
per-user default (XDG), or the store of the configuration ``$HARP_CONFIG`` names. Whole commands,
run as a user runs them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import yaml

from station.store.database import ProfileStore

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs" / "demo.yaml"


def harp(*args, cwd: Path, env: dict[str, str]) -> tuple[int, str, str]:
    """``harp ARGS`` in its own process group, killed with it on every exit path."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "station.cli", *map(str, args)],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    return proc.returncode, out, err


def _env(tmp_path: Path, **extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("HARP_STORE", "HARP_CONFIG")}
    env["XDG_DATA_HOME"] = str(tmp_path / "data")
    env.update(extra)
    return env


def _station(dirpath: Path) -> Path:
    """The demo station at test size, its store left to the default (as ``configs/demo.yaml`` does)."""
    d = yaml.safe_load(DEMO.read_text())
    assert "path" not in d["store"] and "url" not in d["store"]  # the demo uses the per-user store
    d["station"]["camera"].update(width=400, height=300, spacing_px=28.0)
    d["focus"]["settings"] = [0.0]
    d["capture"]["orientations_deg"] = [0, 45, 90, 135]
    d["capture"]["frames_per_orientation"] = 1
    d["pipeline"].update(bootstrap=0, workers=1)
    d["store"] = {"sessions_dir": "sessions"}
    dirpath.mkdir(parents=True)
    cfg = dirpath / "station.yaml"
    cfg.write_text(yaml.safe_dump(d))
    return cfg


def test_profiles_of_a_session_are_found_from_any_directory(tmp_path):
    cfg = _station(tmp_path / "line")
    env = _env(tmp_path)
    code, _, err = harp("session", "run", cfg, "--name", "s", "--quiet", "--no-report", cwd=tmp_path / "line", env=env)
    assert code == 0, err
    user_store = tmp_path / "data" / "harp-station" / "harp-profiles.sqlite"
    assert user_store.is_file()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    code, out, err = harp("profile", "list", cwd=elsewhere, env=env)
    assert code == 0, err
    serial = yaml.safe_load(DEMO.read_text())["lens"]["serial"]
    assert serial in out
    # a station that sets HARP_CONFIG: its sessions too, from anywhere
    code, out, err = harp("session", "list", cwd=elsewhere, env=_env(tmp_path, HARP_CONFIG=str(cfg)))
    assert code == 0, err
    assert "s" in out.split()
    code, out, err = harp("session", "list", cwd=elsewhere, env=env)  # no configuration: ./sessions, not there
    assert code == 2 and "no such directory" in err and err.count("\n") == 1


def test_a_store_left_in_the_old_default_place_is_named_when_the_per_user_one_is_missing(tmp_path):
    old = tmp_path / "work" / "profiles" / "harp-profiles.sqlite"
    old.parent.mkdir(parents=True)
    ProfileStore(old, create=True).close()
    code, out, err = harp("profile", "list", cwd=tmp_path / "work", env=_env(tmp_path))
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "no profile store here (the per-user default)" in err
    assert "there is one at profiles/harp-profiles.sqlite: --store profiles/harp-profiles.sqlite" in err


def test_a_bad_configuration_named_by_harp_config_says_where_it_came_from(tmp_path):
    # the line named only the file ("/srv/station.yaml: (file): no such file"), which the user never typed
    bad = tmp_path / "station.yaml"
    d = yaml.safe_load(DEMO.read_text())
    d["capture"]["twin_deg"] = "abc"
    bad.write_text(yaml.safe_dump(d))
    for config, problem in ((tmp_path / "missing.yaml", "(file): no such file"), (bad, "capture.twin_deg: expected")):
        env = _env(tmp_path, HARP_CONFIG=str(config))
        for argv, instead in (
            (["profile", "list"], "--store or --config"),
            (["qa", "DEMO-0001"], "--store or --config"),
            (["session", "list"], "a directory or --config"),
        ):
            code, out, err = harp(*argv, cwd=tmp_path, env=env)
            assert code == 2 and out == "" and err.count("\n") == 1, (argv, err)
            assert err.startswith(f"harp {argv[0]}: {config}: {problem}"), err
            assert err.endswith(
                f"(the configuration $HARP_CONFIG names: correct it, unset HARP_CONFIG or give {instead})\n"
            ), err
    assert not (tmp_path / "data").exists()  # no store created


def test_a_missing_store_named_by_harp_store_says_where_it_came_from(tmp_path):
    # the line named a path the user never typed; given with --store, the same path says nothing of the variable
    missing = tmp_path / "nowhere" / "profiles.sqlite"
    env = _env(tmp_path, HARP_STORE=str(missing))
    for argv in (["profile", "list"], ["qa", "DEMO-0001"]):
        code, out, err = harp(*argv, cwd=tmp_path, env=env)
        assert code == 2 and out == "" and err.count("\n") == 1, (argv, err)
        assert err.startswith(f"harp {argv[0]}: {missing}: no profile store here"), err
        assert err.endswith("(this store is named by $HARP_STORE: correct it or unset it)\n"), err
    code, out, err = harp("profile", "list", "--store", str(missing), cwd=tmp_path, env=env)
    assert code == 2 and err.count("\n") == 1 and "HARP_STORE" not in err, err
    assert not missing.parent.exists()  # nothing created
