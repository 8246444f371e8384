"""The profile store: every lens profile, its QA verdict and its history, in SQLite or PostgreSQL.

Rooms:

* :mod:`station.store.location` — a store named by a path or URL (``sqlite:///…``,
  ``postgresql://user@host:port/db``; which store a command uses, ``--store``, ``--config``,
  ``$HARP_STORE`` or the default, is the command line's: :mod:`station.cli.store_options`);
* :mod:`station.store.database` — :class:`ProfileStore`: opening (for reading or writing,
  integrity checked before writing), one transaction per write with retries, the queries;
* :mod:`station.store.dashboard` — read queries for the factory QA dashboard;
* :mod:`station.store.schema` — the tables (SQLAlchemy Core), :mod:`station.store.migrate` and
  ``migrations/`` — Alembic revisions that build and upgrade them in place;
* :mod:`station.store.engine` — connections, retries, database errors as one-line messages;
* :mod:`station.store.errors` — :class:`StoreError`.

Importing this package is cheap: SQLAlchemy is imported only when a store is opened
(``ProfileStore`` is loaded on first use), so a command that never opens one pays nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from station.store.errors import StoreError
from station.store.location import DEFAULT_STORE, StoreLocation, default_store, default_store_path, parse_store

if TYPE_CHECKING:
    from station.store.database import ProfileStore

__all__ = [
    "DEFAULT_STORE",
    "ProfileStore",
    "StoreError",
    "StoreLocation",
    "default_store",
    "default_store_path",
    "parse_store",
]


def __getattr__(name: str) -> Any:
    if name == "ProfileStore":
        from station.store.database import ProfileStore  # defers sqlalchemy

        return ProfileStore
    raise AttributeError(f"module 'station.store' has no attribute {name!r}")
