"""Which profile store a command uses — the one place that decides it.

Every command that reads or writes profiles (``harp session``, ``harp profile``, ``harp qa``, and
any later one) finds its store with :func:`store_location` / :func:`open_store`, and the commands
that take a store on the command line add the same two options with :func:`add_store_options`:

* ``--store PATH|URL`` — a SQLite file or a ``postgresql://`` URL (:mod:`station.store.location`);
* ``--config CONFIG`` — the store named in that station configuration (``store.path`` or
  ``store.url``; a relative path there is relative to the configuration file).

First match wins: ``--store``, then ``--config`` (or the configuration the command already has,
e.g. a session's), then ``$HARP_STORE``, then the configuration ``$HARP_CONFIG`` names (a station
sets it once for every command run on it), then the per-user default store
``~/.local/share/harp-station/harp-profiles.sqlite`` (:data:`~station.store.location.DEFAULT_STORE`).
None of them depends on the working directory (a relative path in a configuration is relative to
that file). Opening for reading never creates a store: a command that only reads fails with one
line naming the store it looked for. A write that waits for other writers (another station, another
``harp`` storing into the same file) says so on stderr after a moment, once (:func:`waiting_note`).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from station.cli.say import say
from station.errors import HarpError
from station.store.errors import StoreError
from station.store.location import DEFAULT_STORE, SQLITE, StoreLocation, default_store, parse_store, user_store_path

if TYPE_CHECKING:
    from station.config import Config
    from station.store.database import ProfileStore

STORE_HELP = (
    "profile store: a SQLite file or postgresql://user@host:port/db "
    f"(default: $HARP_STORE, else $HARP_CONFIG's store, else {DEFAULT_STORE})"
)
CONFIG_HELP = "station configuration whose store to use (its store.path or store.url)"
CONFIGURED_STORE_HELP = (
    "profile store: a SQLite file or postgresql://user@host:port/db instead of {whose} store (default: its "
    f"store.path or store.url, else {DEFAULT_STORE}; $HARP_STORE is not used)"
)
"""``--store`` of a command that has a station configuration (``harp session run CONFIG``, a session's
own for ``resume`` and ``repair``): :func:`store_location` takes that configuration's store before
``$HARP_STORE``, and a configuration that names none has the per-user default."""


def add_store_options(
    parser: argparse.ArgumentParser, *, suppress: bool = False, config: bool = True, store_help: str = STORE_HELP
) -> None:
    """Add ``--store PATH|URL`` (and ``--config CONFIG``) to a parser. ``suppress=True`` leaves the
    attributes unset when not given (for an option repeated on a sub-command); ``store_help``: the
    ``--store`` help (:data:`CONFIGURED_STORE_HELP` for a command that has a configuration)."""
    default = argparse.SUPPRESS if suppress else None
    parser.add_argument("--store", metavar="PATH|URL", default=default, help=store_help)
    if config:
        parser.add_argument("--config", metavar="CONFIG", type=Path, default=default, help=CONFIG_HELP)


def store_location(
    store: str | os.PathLike[str] | None = None,
    config: Config | None = None,
    config_path: str | os.PathLike[str] | None = None,
) -> StoreLocation:
    """The store to use: ``store`` (``--store``), else the store of ``config`` (a loaded
    configuration) or of the configuration file ``config_path``, else ``$HARP_STORE``, else the
    store of the configuration ``$HARP_CONFIG`` names, else the per-user default. Raises StoreError
    (a bad store name) or ConfigError (a bad configuration)."""
    if store is not None:
        return parse_store(store)
    if config is None and config_path is None and not os.environ.get("HARP_STORE") and os.environ.get("HARP_CONFIG"):
        config = load_env_config("--store or --config")
    if config is None and config_path is not None:
        from station.config import load_config  # defers numpy, yaml

        config = load_config(config_path)
    if config is not None:
        return config.store
    return default_store()


def load_env_config(instead: str) -> Config:
    """The configuration ``$HARP_CONFIG`` names, loaded; one that cannot be is a HarpError whose line says
    where the file came from (the user gave no path) and what to do: correct it, unset the variable or give
    ``instead`` (the command's own options)."""
    from station.config import ConfigError, load_config  # defers numpy, yaml

    try:
        return load_config(os.environ["HARP_CONFIG"])
    except ConfigError as exc:
        raise HarpError(
            f"{exc} (the configuration $HARP_CONFIG names: correct it, unset HARP_CONFIG or give {instead})"
        ) from None


def location_from_args(args: argparse.Namespace, config: Config | None = None) -> StoreLocation:
    """:func:`store_location` from the ``--store`` / ``--config`` options of ``args`` (either may be
    absent); ``config`` is a configuration the command already has (used when neither is given)."""
    store = getattr(args, "store", None)
    config_path = getattr(args, "config", None)
    if store is None and config_path is not None:
        return store_location(config_path=config_path)
    return store_location(store, config)


def waiting_note(prog: str) -> Callable[[str], None]:
    """What ``prog`` (``harp qa``, ...) says when its store makes a write wait for other writers
    (:func:`station.store.engine.write`): ``PROG: waiting for the store …`` on stderr, at once (never on
    stdout: ``--json`` stays clean; with ``--quiet`` too — it is why the command seems to hang)."""
    return lambda text: say(prog, text, flush=True)


def open_store(
    where: StoreLocation | argparse.Namespace | Any, *, write: bool = False, prog: str = "harp", upgrade: bool = True
) -> ProfileStore:
    """Open the store at ``where`` (a location, or parsed arguments with ``--store`` / ``--config``):
    for reading by default (it must exist), for writing with ``write=True`` (created, migrated and
    checked before anything is written). ``prog`` names the command in the line a waiting write says
    (:func:`waiting_note`); ``upgrade=False``: an older store is refused (``kind="older"``), not upgraded
    (:class:`~station.store.database.ProfileStore`)."""
    from station.store.database import ProfileStore  # defers sqlalchemy

    loc = where if isinstance(where, StoreLocation) else location_from_args(where)
    try:
        return ProfileStore(loc, create=write, on_wait=waiting_note(prog), upgrade=upgrade)
    except StoreError as exc:
        env = os.environ.get("HARP_STORE")
        if exc.kind == "missing" and env and _given(where) is None and parse_store(env) == loc:
            raise StoreError(  # the user typed no path: say where it came from
                f"{exc} (this store is named by $HARP_STORE: correct it or unset it)", "missing"
            ) from None
        old = Path("profiles") / "harp-profiles.sqlite"  # where stores were found before the per-user default
        if exc.kind != "missing" or loc.backend != SQLITE or loc.path != user_store_path() or not old.is_file():
            raise
        raise StoreError(
            f"{loc.path}: no profile store here (the per-user default); there is one at {old}: "
            f"--store {old}, or set HARP_STORE",
            "missing",
        ) from None


def _given(where: StoreLocation | argparse.Namespace | Any) -> str | None:
    """The ``--store`` or ``--config`` a command was given (None for a location, or neither option)."""
    if isinstance(where, StoreLocation):
        return None
    return getattr(where, "store", None) or getattr(where, "config", None)
