"""The lensfun databases lensfun loads on this machine, for the export's name check.

Lensfun (0.3.x, and lensfunpy, which bundles its own copy) reads every ``*.xml``
of these directories and merges their lenses on (maker, model, crop factor):

- the system database, ``/usr/share/lensfun/version_1`` (Debian's
  ``liblensfun-data``; also ``/usr/local/share/...`` and the unversioned
  directories of older releases);
- the updates ``lensfun-update-data`` fetches, ``/var/lib/lensfun-updates/version_1``;
- the user's own, ``$XDG_DATA_HOME/lensfun`` (``~/.local/share/lensfun``) and
  its ``updates/version_1``;
- lensfunpy's bundled ``db_files`` (found without importing lensfunpy).

``HARP_LENSFUN_DIRS`` (``:``-separated) replaces the list, e.g. for a
machine whose lensfun was built with another prefix.

References
----------
.. [1] Lensfun manual, "Database search order", https://lensfun.github.io/manual/latest/dbsearch.html
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

MAX_DATABASE_BYTES = 32 * 1024 * 1024
"""A file larger than this is not a lensfun database (lensfun's largest is ~1 MB): skipped."""


def lensfun_directories() -> list[Path]:
    """Where lensfun looks for databases (see the module docstring), existing or not."""
    env = os.environ.get("HARP_LENSFUN_DIRS")
    if env is not None:
        return [Path(p) for p in env.split(os.pathsep) if p]
    data_home = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    dirs = [Path(prefix) / "share" / "lensfun" / sub for prefix in ("/usr", "/usr/local") for sub in ("version_1", "")]
    dirs += [Path("/var/lib/lensfun-updates/version_1"), data_home / "lensfun", data_home / "lensfun/updates/version_1"]
    spec = importlib.util.find_spec("lensfunpy")
    if spec is not None and spec.origin:
        dirs.append(Path(spec.origin).parent / "db_files")
    return dirs


_TEXTS: dict[tuple[str, int, int], str] = {}
"""File texts read so far, by (path, mtime, size): a long-running server reads a database again only when it changed."""


def _read(dirs: list[Path]) -> tuple[tuple[str, str], ...]:
    found: list[tuple[str, str]] = []
    for d in dirs:
        try:
            files = sorted(p for p in d.glob("*.xml") if p.is_file())
        except OSError:
            continue
        for p in files:
            try:
                st = p.stat()
                if st.st_size > MAX_DATABASE_BYTES:
                    continue
                key = (str(p), st.st_mtime_ns, st.st_size)
                if key not in _TEXTS:
                    _TEXTS[key] = p.read_text(encoding="utf-8", errors="replace")
                found.append((str(p), _TEXTS[key]))
            except OSError:
                continue
    return tuple(found)


def installed_databases(exclude: str | os.PathLike[str] | None = None) -> tuple[tuple[str, str], ...]:
    """``(path, XML text)`` of every lensfun database lensfun would load, without ``exclude``
    (the file being written: adding to one's own database is not a clash)."""
    found = _read(lensfun_directories())
    if exclude is None:
        return found
    target = Path(exclude).resolve()
    return tuple((name, text) for name, text in found if Path(name).resolve() != target)
