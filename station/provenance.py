"""Provenance of a profile: when, by which software, from which images (with their SHA-256).

The pure model-file code (:mod:`pipeline.model_file`) stores this record as plain
data; the software version comes from here (:data:`station.SOFTWARE`, read from the
installed distribution), never from :mod:`pipeline`.
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Iterable, Sequence
from typing import Any

from station import SOFTWARE
from station.files import sha256_file


def make_provenance(
    images: Iterable[str | os.PathLike] = (),
    *,
    t: int | None = None,
    command: str | Sequence[str] | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """Provenance record: UTC time, software version, input images with sha256, t, command line."""
    prov: dict[str, Any] = {
        "created_utc": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "software": SOFTWARE,
    }
    if t is not None:
        prov["t"] = t
    if command is not None:
        prov["command"] = command if isinstance(command, str) else " ".join(map(str, command))
    prov["images"] = [{"path": str(p), "sha256": sha256_file(p)} for p in images]
    prov.update(extra)
    return prov
