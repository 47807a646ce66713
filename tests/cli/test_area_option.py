"""``--area``: four finite numbers making a rectangle, or a one-line refusal."""

from __future__ import annotations

import pytest

from omnical.cli.serial_options import parse_area
from omnical.errors import ConfigError


def test_an_area_is_its_corners_in_either_order() -> None:
    area = parse_area("3,2,0.5,0")
    assert area is not None
    assert (area.x_min, area.y_min, area.x_max, area.y_max) == (0.5, 0.0, 3.0, 2.0)
    assert parse_area(None) is None


@pytest.mark.parametrize("text", ["nan,0,5,5", "0,0,inf,5", "0,0,0,5", "1,2,3", "a,b,c,d"])
def test_an_area_that_guards_nothing_is_refused(text: str) -> None:
    with pytest.raises(ConfigError, match="--area"):
        parse_area(text)
