"""The one check every driver's ``from_config`` makes of its configuration keys."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any


def check_config_keys(
    name: str, cfg: Mapping[str, Any], known: Collection[str], required: Mapping[str, str] | None = None
) -> None:
    """Raise ``ValueError`` naming the first unknown key, or a missing required one.

    ``name`` prefixes the message (e.g. ``"zaber turntable"``); ``known`` holds
    every accepted key (``driver`` is always accepted); ``required`` maps each
    required key to a short description of what it should hold.
    """
    known = set(known) | {"driver"}
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise ValueError(f"{name}: unknown config key {unknown[0]!r} (known: {', '.join(sorted(known - {'driver'}))})")
    for key, what in (required or {}).items():
        if not cfg.get(key):
            raise ValueError(f"{name}: missing config key {key!r} ({what})")
