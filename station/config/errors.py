"""The one error of a station configuration: :class:`ConfigError`, one line naming file and field."""

from __future__ import annotations

import os

from station.errors import HarpError


class ConfigError(HarpError, ValueError):
    """A configuration problem; ``str()`` is one line naming file and field."""

    def __init__(self, file: str | os.PathLike, field_path: str, expected: str):
        self.file = str(file)
        self.field = field_path
        self.expected = expected
        super().__init__(f"{self.file}: {field_path}: {expected}")
