"""FitSpec (pipeline/fitspec.py): labels, parsing and bounds of the division (rational) radial term."""

import pytest

from pipeline.fitspec import DIVISION_BOUNDS, FitSpec, parse, spec_problem


@pytest.mark.parametrize(
    "label",
    ["radial2+division1", "radial4+tangential+prism+division1", "radial2+tangential+division2+centre-prior"],
)
def test_division_label_round_trip(label):
    spec = parse(label)
    assert spec.label == label and spec.division >= 1
    assert FitSpec.from_dict(spec.to_dict()) == spec
    assert spec.fit_arguments()["division"] == spec.division


def test_no_division_keeps_the_old_labels_and_dicts():
    spec = parse("radial4+tangential+prism")
    assert spec.division == 0 and "division" not in spec.to_dict() and "division" not in spec.fit_arguments()
    assert FitSpec.from_dict({"model": "radial", "degree": 4}).division == 0


def test_division_bounds_and_kinds():
    lo, hi = DIVISION_BOUNDS
    with pytest.raises(ValueError, match="division terms must be within"):
        FitSpec("radial", 2, division=hi + 1)
    with pytest.raises(ValueError, match="division terms apply to the radial model only"):
        FitSpec("poly", 5, division=1)
    with pytest.raises(ValueError, match="unknown term"):
        parse("radial2+divisionx")
    assert spec_problem("radial", 2, division=1.5) is not None
    assert spec_problem("radial", 2, division=lo) is None
