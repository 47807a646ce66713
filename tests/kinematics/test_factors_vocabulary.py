"""The factor vocabulary agrees with CorrectionFactors and the factors.yaml layout."""

from dataclasses import fields

import pytest

from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import CROSSTALKS, FACTORS, SCALES, Factor, FactorKind
from omnical.kinematics.factors_layout import CROSSTALK_KEYS, SCALE_KEYS


def test_fields_in_correction_factors_order() -> None:
    assert [f.field for f in FACTORS] == [f.name for f in fields(CorrectionFactors)]


def test_kinds_units_and_neutral_values() -> None:
    assert [f.yaml_key for f in SCALES] == list(SCALE_KEYS)
    assert [f.yaml_key for f in CROSSTALKS] == list(CROSSTALK_KEYS)
    identity = CorrectionFactors.identity()
    for f in FACTORS:
        assert getattr(identity, f.field) == f.neutral
        assert f.unit == ("" if f.kind is FactorKind.SCALE else "rad/m")
    assert Factor.CROSSTALK_LEFT.key == "crosstalk.left"
    assert Factor.SCALE_ROTATIONAL.yaml_section == "scale"


@pytest.mark.parametrize(
    ("factor", "old", "new", "expected"),
    [
        (Factor.SCALE_LATERAL, 1.10, 1.21, 0.10),
        (Factor.CROSSTALK_RIGHT, 0.010, 0.013, 0.003),
    ],
)
def test_change_is_relative_for_scales_and_a_difference_for_crosstalks(
    factor: Factor, old: float, new: float, expected: float
) -> None:
    assert factor.change(old, new) == pytest.approx(expected)


def test_from_field_rejects_unknown_names() -> None:
    assert Factor.from_field("scale_lateral") is Factor.SCALE_LATERAL
    with pytest.raises(ValueError, match="not a valid Factor"):
        Factor.from_field("scale_diagonal")
