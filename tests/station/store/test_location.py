"""Naming a store (path or URL) and choosing it (--store, --config, $HARP_STORE, default)."""

import argparse
from pathlib import Path

import pytest
import yaml

from station.cli.store_options import add_store_options, location_from_args, store_location
from station.config import ConfigError, load_config
from station.store import StoreError
from station.store.location import POSTGRESQL, SQLITE, parse_store

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs" / "demo.yaml"


@pytest.mark.parametrize(
    "text, path",
    [
        ("p.sqlite", "/base/p.sqlite"),
        ("sub/../p.sqlite", "/base/p.sqlite"),
        ("/abs/p.sqlite", "/abs/p.sqlite"),
        ("sqlite:///rel/p.sqlite", "/base/rel/p.sqlite"),
        ("sqlite:////abs/p.sqlite", "/abs/p.sqlite"),
    ],
)
def test_sqlite_names(text, path):
    loc = parse_store(text, Path("/base"))
    assert loc.backend == SQLITE and loc.path == Path(path) and loc.sqlalchemy_url == f"sqlite:///{path}"
    assert str(loc) == path


@pytest.mark.parametrize("scheme", ["postgresql", "postgres", "postgresql+psycopg"])
def test_postgresql_names(scheme):
    loc = parse_store(f"{scheme}://harp:secret@db.example:5433/profiles")
    assert loc.backend == POSTGRESQL
    assert loc.sqlalchemy_url == "postgresql+psycopg://harp:secret@db.example:5433/profiles"
    assert str(loc) == "postgresql://harp@db.example:5433/profiles"  # messages never show the password


@pytest.mark.parametrize(
    "text, says",
    [
        ("mysql://x@h/db", "unknown store URL scheme"),
        ("postgresql://harp@host", "needs a database"),
        ("postgresql:///db", "needs a host"),
        ("postgresql://h:notaport/db", "bad port"),
        ("sqlite://", "sqlite:///relative/path"),
        ("sqlite:///:memory:", "must be a file"),
        ("  ", "empty store name"),
    ],
)
def test_bad_names_are_one_line(text, says):
    with pytest.raises(StoreError, match=says) as exc:
        parse_store(text)
    assert "\n" not in str(exc.value)


def write_config(dirpath: Path, store: dict) -> Path:
    d = yaml.safe_load(DEMO.read_text())
    d["store"] = store
    dirpath.mkdir(parents=True, exist_ok=True)
    p = dirpath / "station.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_config_store_path_or_url_relative_to_the_config(tmp_path):
    sub = tmp_path / "cfg"
    assert load_config(write_config(sub, {"path": "db/p.sqlite"})).store.path == sub / "db" / "p.sqlite"
    assert load_config(write_config(sub, {"url": "sqlite:///db/q.sqlite"})).store.path == sub / "db" / "q.sqlite"
    cfg = load_config(write_config(sub, {"url": "postgresql://harp@127.0.0.1:5432/harp"}))
    assert cfg.store.backend == POSTGRESQL and cfg.store_path is None
    for store, says in (
        ({"path": "a", "url": "sqlite:///b"}, "one of store.path .* not both"),
        ({"url": "ftp://x/y"}, "store.url"),
    ):
        with pytest.raises(ConfigError, match=says) as exc:
            load_config(write_config(sub, store))
        assert "\n" not in str(exc.value)


def test_which_store_a_command_uses(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("HARP_STORE", raising=False)
    cfg = write_config(tmp_path / "cfg", {"path": "../stores/line.sqlite"})
    parser = argparse.ArgumentParser()
    add_store_options(parser)

    def where(*argv):
        return location_from_args(parser.parse_args(list(argv)))

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    user = tmp_path / "data" / "harp-station" / "harp-profiles.sqlite"  # the XDG base directory specification
    assert where().path == user
    assert load_config(write_config(tmp_path / "bare", {"sessions_dir": "s"})).store.path == user
    monkeypatch.chdir(tmp_path / "cfg")
    assert where().path == user  # wherever the command runs
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert where().path == tmp_path / "home" / ".local" / "share" / "harp-station" / "harp-profiles.sqlite"
    monkeypatch.setenv("HARP_CONFIG", str(cfg))  # a station's configuration, set once for its commands
    assert where().path == tmp_path / "stores" / "line.sqlite"
    monkeypatch.setenv("HARP_STORE", "postgresql://harp@h:1/db")
    assert where().backend == POSTGRESQL
    assert where("--config", str(cfg)).path == tmp_path / "stores" / "line.sqlite"  # the config's, not the env's
    assert where("--config", str(cfg), "--store", "x.sqlite").path == tmp_path / "x.sqlite"  # --store first
    assert store_location(config=load_config(cfg)).path == tmp_path / "stores" / "line.sqlite"
    with pytest.raises(ConfigError):
        where("--config", str(tmp_path / "missing.yaml"))
