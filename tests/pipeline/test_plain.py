"""The one finite-or-None and the one plain-data converter (pipeline.plain)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from pipeline.plain import finite_or_none, json_default, plain


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (1.5, 1.5),
        (3, 3.0),
        (np.float64(0.25), 0.25),
        (np.float32(0.5), 0.5),
        (np.int64(7), 7.0),
        (-0.0, 0.0),
    ],
)
def test_finite_numbers_are_floats(value, expected):
    out = finite_or_none(value)
    assert type(out) is float and out == expected


@pytest.mark.parametrize(
    "value", [None, math.nan, math.inf, -math.inf, np.float64("nan"), True, False, np.bool_(True), "1.0", [1.0], {}]
)
def test_what_is_no_finite_number_is_none(value):
    assert finite_or_none(value) is None


def test_plain_gives_json_types_and_null_for_non_finite():
    doc = {
        1: (np.float64(1.5), np.int32(2), math.nan),
        "a": np.array([[1.0, np.inf], [3.0, 4.0]]),
        "p": Path("/x/y"),
        "b": np.bool_(False),
        "s": "text",
        "n": None,
    }
    out = plain(doc)
    assert out == {"1": [1.5, 2, None], "a": [[1.0, None], [3.0, 4.0]], "p": "/x/y", "b": False, "s": "text", "n": None}
    assert type(out["1"][0]) is float and type(out["1"][1]) is int and type(out["b"]) is bool
    json.dumps(out, allow_nan=False)  # nothing left that JSON cannot hold


def test_plain_can_keep_non_finite_floats():
    out = plain({"k": [np.float64("nan"), math.inf, np.array([-math.inf])]}, nonfinite_as_none=False)
    assert math.isnan(out["k"][0]) and out["k"][1] == math.inf and out["k"][2] == [-math.inf]


def test_json_default_converts_numpy_and_paths_and_refuses_the_rest():
    text = json.dumps({"a": np.arange(3), "f": np.float32(0.5), "p": Path("q")}, default=json_default)
    assert json.loads(text) == {"a": [0, 1, 2], "f": 0.5, "p": "q"}
    with pytest.raises(TypeError, match="not JSON serialisable: object"):
        json.dumps(object(), default=json_default)
