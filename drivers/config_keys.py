"""The one check every driver's ``from_config`` makes of its configuration keys."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

from drivers.settings import Setting, problem, split_item


def check_config_keys(
    name: str, cfg: Mapping[str, Any], known: Collection[str], required: Mapping[str, str] | None = None
) -> None:
    """Raise ``ValueError`` naming the first unknown key, a missing required one or a value outside
    its declaration.

    ``name`` prefixes the message (e.g. ``"zaber turntable"``); ``known`` holds every accepted key
    (``driver`` is always accepted): a mapping of keys to their :class:`~drivers.settings.Setting`
    (the driver's ``SETTINGS``) also checks each value given (:func:`drivers.settings.problem`);
    ``required`` maps each required key to a short description of what it should hold.
    """
    keys = set(known) | {"driver"}
    unknown = sorted(set(cfg) - keys)
    if unknown:
        raise ValueError(f"{name}: unknown config key {unknown[0]!r} (known: {', '.join(sorted(keys - {'driver'}))})")
    for key, what in (required or {}).items():
        if not cfg.get(key):
            raise ValueError(f"{name}: missing config key {key!r} ({what})")
    if isinstance(known, Mapping):
        for key, value in cfg.items():
            setting = known.get(key)
            if isinstance(setting, Setting):
                text = problem(setting, value)
                if text is not None:
                    item, expected = split_item(text)
                    raise ValueError(f"{name}: config key {key!r}{item}: {expected}")
