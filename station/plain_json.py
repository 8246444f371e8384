"""Plain JSON data from the station's values: what every ``--json`` output and ``results.json`` print."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any


def plain(obj: Any) -> Any:
    """JSON-safe plain data: mappings (keys as text) and sequences recursively, non-finite floats as
    ``null`` (JSON has no NaN or infinity), numpy scalars as numbers, paths as text."""
    if isinstance(obj, Mapping):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalar
        return plain(obj.item())
    return obj
