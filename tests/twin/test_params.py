"""Twin files: the factor sections overlay the default twin through the one factors.yaml parser."""

from __future__ import annotations

import pytest

from omnical.errors import ConfigError
from omnical.robot import load_robot
from omnical.twin.params import ROSY_TRUTH, parse_twin

ROSY = load_robot("rosy-mecanum")


def test_partial_factor_sections_overlay_the_default_truth() -> None:
    p = parse_twin(
        {
            "true_factors": {"scale": {"lateral": 1.05}},
            "installed_factors": {"crosstalk_rad_per_m": {"left": 0.01}},
        },
        ROSY,
        "t.yaml",
    )
    assert p.true_factors == ROSY_TRUTH.with_values(scale_lateral=1.05)
    assert p.installed_factors.crosstalk_left_rad_per_m == 0.01
    assert p.installed_factors.scale_longitudinal == 1.0


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (
            {"true_factors": {"scale": {"sideways": 1.0}}},
            r"t\.yaml: field 'true_factors\.scale\.sideways': unknown key",
        ),
        (
            {"true_factors": {"scale": {"lateral": 5}}},
            r"field 'true_factors\.scale\.lateral': 5\.0 is not a plausible",
        ),
        (
            {"installed_factors": {"crosstalk_rad_per_m": {"left": 3}}},
            r"installed_factors\.crosstalk_rad_per_m\.left",
        ),
    ],
)
def test_bad_factor_sections_name_the_field(data: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_twin(data, ROSY, "t.yaml")
