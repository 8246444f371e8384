"""Bad input as one line naming the file (:mod:`station.inputs`): photos that cannot be read or hold no string."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from station.errors import InputError
from station.inputs import NO_STRINGS, measure_file, measure_grey, read_image


def test_an_unreadable_photo_is_one_line_naming_it(tmp_path):
    with pytest.raises(InputError, match=str(tmp_path / "nothing.png")):
        read_image(tmp_path / "nothing.png")
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(InputError) as exc:
        measure_file(bad, 30)
    assert str(bad) in str(exc.value) and "\n" not in str(exc.value)


def test_a_photo_without_strings(tmp_path):
    flat = np.full((120, 160), 128, np.uint8)
    with pytest.raises(InputError) as exc:
        measure_grey("flat.png", flat, 30)
    assert str(exc.value) == f"flat.png: {NO_STRINGS}"
    assert measure_grey("flat.png", flat, 30, require_strings=False).n_lines == 0
    path = tmp_path / "flat.png"
    cv2.imwrite(str(path), flat)
    assert read_image(path).shape == (120, 160) and read_image(path, grey=False).dtype == np.uint8
