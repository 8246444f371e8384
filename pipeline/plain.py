"""Plain data for JSON and YAML: the one finite-or-None and the one plain-data converter.

Nothing here imports numpy: a numpy value can only exist once numpy is loaded, so the
converters look it up in :data:`sys.modules` (the station's light commands import this
module and must not pay for numpy).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any


def _numpy() -> Any:
    """numpy when it is loaded, else None (then no value can be a numpy one)."""
    return sys.modules.get("numpy")


def finite_or_none(v: object) -> float | None:
    """``float(v)`` for a finite number, None otherwise.

    A number is a Python ``int`` or ``float`` (numpy's ``float64`` is one) or a numpy integer or
    floating scalar; ``bool`` is not a number here. None, NaN, infinities and anything else (text,
    lists, a JSON value of the wrong type) give None.
    """
    if isinstance(v, bool) or v is None:
        return None
    if not isinstance(v, (int, float)):
        np = _numpy()
        if np is None or not isinstance(v, (np.integer, np.floating)):
            return None
    f = float(v)  # a number, checked above
    return f if math.isfinite(f) else None


def plain(obj: Any, *, nonfinite_as_none: bool = True) -> Any:
    """Plain data of ``obj``, recursively: mappings as dicts with text keys, tuples, lists and numpy
    arrays as lists, numpy scalars as Python numbers, paths as text; other values as they are.

    ``nonfinite_as_none``: NaN and infinities become None (JSON's ``null``: JSON has neither);
    False keeps them as floats (YAML writes ``.nan``; a hash of the text sees them).
    """
    if isinstance(obj, Mapping):
        return {str(k): plain(v, nonfinite_as_none=nonfinite_as_none) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v, nonfinite_as_none=nonfinite_as_none) for v in obj]
    np = _numpy()
    if np is not None and isinstance(obj, np.ndarray):
        return plain(obj.tolist(), nonfinite_as_none=nonfinite_as_none)
    if np is not None and isinstance(obj, np.generic):
        return plain(obj.item(), nonfinite_as_none=nonfinite_as_none)
    if isinstance(obj, float):
        return None if nonfinite_as_none and not math.isfinite(obj) else float(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def json_default(o: Any) -> Any:
    """The ``default`` of :func:`json.dumps` for numpy scalars and arrays and paths (as
    :func:`plain` converts them, non-finite floats kept); TypeError for anything else."""
    np = _numpy()
    if np is not None and isinstance(o, np.generic):
        return o.item()
    if np is not None and isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
