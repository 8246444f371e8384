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


def test_a_choice_is_a_label_or_auto():
    """Issue 22 item 2: ``model`` settings and options read by one function: a label, or auto (None)."""
    from pipeline.fitspec import AUTO, parse_choice

    assert parse_choice(AUTO) is None and parse_choice(" Auto ") is None
    assert parse_choice("radial6+prism") == FitSpec("radial", 6, prism=True)
    assert parse_choice("poly") == FitSpec("poly", 5)
    with pytest.raises(ValueError, match="'automatic': unknown model"):
        parse_choice("automatic")


@pytest.mark.parametrize(
    "spec",
    [
        FitSpec("radial", 6, True, False, True),
        FitSpec("radial", 2, division=1),
        FitSpec("radial", 4, True, True, field=(8, 6), field_penalty=0.01),
        FitSpec("poly", 7),
    ],
)
def test_fit_arguments_read_back(spec):
    """The fit's keyword arguments (kept by schema-2 store rows) give back the spec that made them."""
    assert FitSpec.from_fit_arguments(spec.fit_arguments()) == spec
