"""Provenance of a profile: when, by which software, from which images (with their SHA-256).

:func:`make_provenance` makes the :class:`station.profile.Provenance` record; the
software version comes from here (:data:`station.SOFTWARE`, read from the installed
distribution), never from :mod:`pipeline` — the pure model-file code stores the
record as plain data.
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Iterable, Sequence
from typing import Any

from station import SOFTWARE
from station.files import sha256_file
from station.profile import Provenance


def make_provenance(
    images: Iterable[str | os.PathLike] = (),
    *,
    t: int | None = None,
    command: str | Sequence[str] | None = None,
    station: str | None = None,
    session_dir: str | None = None,
    **extra: Any,
) -> Provenance:
    """Provenance record: UTC time now, this software, the input images with their sha256,
    ``t``, the command line, the station id, the session directory and any ``extra``."""
    return Provenance(
        created_utc=_dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        software=SOFTWARE,
        command=None if command is None else command if isinstance(command, str) else " ".join(map(str, command)),
        t=t,
        images=tuple((str(p), sha256_file(p)) for p in images),
        station=station,
        session_dir=session_dir,
        extra=extra,
    )
