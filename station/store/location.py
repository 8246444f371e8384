"""Where a profile store is: a SQLite file or a PostgreSQL database, named by a path or a URL.

A store is named the same way everywhere (``store.path`` / ``store.url`` in a
configuration, ``--store`` on the command line, ``$HARP_STORE``):

* a file path (``profiles/harp-profiles.sqlite``) or ``sqlite:///relative/path`` /
  ``sqlite:////absolute/path`` — a SQLite file (the default backend);
* ``postgresql://user[:password]@host[:port]/database`` (also ``postgres://`` and
  ``postgresql+psycopg://``) — a PostgreSQL database, reached with psycopg 3.

A relative file path is relative to ``base`` (the directory of the configuration
that names it, else the working directory). This module only parses names: it
imports no database library, so a command that never opens a store pays nothing.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

from station.store.errors import StoreError

SQLITE = "sqlite"
POSTGRESQL = "postgresql"

STORE_FILE = "harp-profiles.sqlite"
"""The file name of the per-user default store."""

DEFAULT_STORE = "~/.local/share/harp-station/harp-profiles.sqlite"
"""The per-user default store as the documentation and help texts name it (``$XDG_DATA_HOME``, when
set, replaces ``~/.local/share``): where every command looks when nothing names a store, and the
store of a configuration without ``store.path`` / ``store.url`` (``configs/demo.yaml``). The same
file whatever the working directory: see :func:`user_store_path`."""

_PG_SCHEMES = ("postgresql", "postgres", "postgresql+psycopg")


@dataclass(frozen=True)
class StoreLocation:
    """A profile store's place: ``backend`` (:data:`SQLITE` or :data:`POSTGRESQL`) and either
    the absolute ``path`` of the SQLite file or the PostgreSQL ``url``."""

    backend: str
    path: Path | None = None
    url: str | None = None

    @property
    def sqlalchemy_url(self) -> str:
        """The URL SQLAlchemy opens (driver spelled out: ``postgresql+psycopg://``)."""
        if self.backend == SQLITE:
            return f"sqlite:///{self.path}"
        assert self.url is not None
        parts = urlsplit(self.url)
        return urlunsplit(("postgresql+psycopg", *parts[1:]))

    @property
    def has_password(self) -> bool:
        """Whether the URL carries a password (``postgresql://user:password@host/db``)."""
        return self.url is not None and urlsplit(self.url).password is not None

    def __str__(self) -> str:
        """How messages name the store: the file path, or the URL without its password."""
        if self.backend == SQLITE:
            return str(self.path)
        assert self.url is not None
        parts = urlsplit(self.url)
        netloc = parts.netloc
        if "@" in netloc:
            user, host = netloc.rsplit("@", 1)
            netloc = f"{user.split(':', 1)[0]}@{host}"
        return urlunsplit(("postgresql", netloc, parts.path, parts.query, ""))


def parse_store(text: str | os.PathLike[str], base: Path | None = None) -> StoreLocation:
    """The :class:`StoreLocation` named by a path or URL; raises StoreError (one line) when
    the name is not one (an unknown scheme, a PostgreSQL URL without a database)."""
    s = os.fspath(text).strip()
    if not s:
        raise StoreError("empty store name: give a file path or a postgresql:// URL")
    scheme = s.split("://", 1)[0].lower() if "://" in s else ""
    shown = without_password(s)  # how the messages name it
    if scheme in _PG_SCHEMES:
        parts = urlsplit(s)
        if not parts.hostname and "host=" not in parts.query:
            raise StoreError(f"{shown}: a PostgreSQL store URL needs a host: postgresql://user@host:port/database")
        if not parts.path.strip("/"):
            raise StoreError(f"{shown}: a PostgreSQL store URL needs a database: postgresql://user@host:port/database")
        try:
            parts.port  # noqa: B018  (validates the port)
        except ValueError:
            raise StoreError(f"{shown}: bad port in the store URL") from None
        return StoreLocation(POSTGRESQL, url=urlunsplit(("postgresql", *parts[1:])))
    if scheme == "sqlite":
        rest = s[len("sqlite://") :]
        if not rest.startswith("/") or rest == "/":
            raise StoreError(f"{s}: a SQLite store URL is sqlite:///relative/path or sqlite:////absolute/path")
        rest = rest[1:]  # sqlite:///x -> x (relative), sqlite:////x -> /x
        if rest in ("", ":memory:"):
            raise StoreError(f"{s}: a profile store must be a file")
        s = rest
    elif scheme:
        raise StoreError(
            f"{shown}: unknown store URL scheme {scheme!r} (expected a file path, sqlite:/// or postgresql://)"
        )
    path = Path(os.path.expanduser(s))
    if not path.is_absolute():
        path = (base if base is not None else Path.cwd()) / path
    return StoreLocation(SQLITE, path=Path(os.path.normpath(path)))


def without_password(url: str) -> str:
    """``url`` with its password, if it has one, written ``***`` (``postgresql://harp:***@host/db``): a
    message names a store the user gave without printing the password in it."""
    if "://" not in url:
        return url
    scheme, rest = url.split("://", 1)
    end = min((i for i in (rest.find(c) for c in "/?#") if i >= 0), default=len(rest))
    netloc = rest[:end]
    if "@" not in netloc:
        return url
    user, host = netloc.rsplit("@", 1)
    if ":" not in user:
        return url
    return f"{scheme}://{user.split(':', 1)[0]}:***@{host}{rest[end:]}"


def user_store_path() -> Path:
    """The per-user default store: ``$XDG_DATA_HOME/harp-station/harp-profiles.sqlite``, with
    ``~/.local/share`` for an unset ``$XDG_DATA_HOME`` (the XDG base directory specification)."""
    data_home = os.environ.get("XDG_DATA_HOME") or os.path.join("~", ".local", "share")
    return Path(os.path.normpath(os.path.expanduser(data_home))) / "harp-station" / STORE_FILE


def default_store_path() -> Path:
    """``$HARP_STORE`` as a path, else :func:`user_store_path` (kept for callers that want a path;
    :func:`default_store` also understands URLs)."""
    env = os.environ.get("HARP_STORE")
    return Path(env) if env else user_store_path()


def default_store() -> StoreLocation:
    """``$HARP_STORE`` (path or URL), else the per-user default store (:func:`user_store_path`)."""
    env = os.environ.get("HARP_STORE")
    return parse_store(env) if env else StoreLocation(SQLITE, path=user_store_path())
