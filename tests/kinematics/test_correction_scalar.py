"""The twin's scalar fast paths of the correction model equal the vectorised functions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.kinematics.correction import (
    CorrectionFactors,
    compensate_twist,
    compensate_twist_scalar,
    counter_compensate_twist,
    counter_compensate_twist_scalar,
    crosstalk_yaw_rate,
    crosstalk_yaw_rate_scalar,
)

_speed = st.floats(-2.0, 2.0, allow_nan=False)
_scale = st.floats(0.5, 2.0, allow_nan=False)
_cross = st.floats(-0.5, 0.5, allow_nan=False)
_factors = st.builds(CorrectionFactors, _scale, _scale, _scale, _cross, _cross, _cross, _cross)
_twist = st.tuples(_speed, _speed, st.floats(-5.0, 5.0, allow_nan=False))


@settings(max_examples=300, deadline=None)
@given(_factors, _twist)
def test_scalar_paths_equal_the_vectorised_functions(
    factors: CorrectionFactors, twist: tuple[float, float, float]
) -> None:
    vx, vy, wz = twist
    assert crosstalk_yaw_rate_scalar(factors, vx, vy) == pytest.approx(
        float(crosstalk_yaw_rate(factors, vx, vy)), rel=0.0, abs=1e-12
    )
    np.testing.assert_allclose(
        compensate_twist_scalar(vx, vy, wz, factors),
        compensate_twist(twist, factors),
        rtol=0.0,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        counter_compensate_twist_scalar(vx, vy, wz, factors),
        counter_compensate_twist(twist, factors),
        rtol=0.0,
        atol=1e-12,
    )


@settings(max_examples=100, deadline=None)
@given(_factors, _twist)
def test_scalar_counter_compensation_undoes_scalar_compensation(
    factors: CorrectionFactors, twist: tuple[float, float, float]
) -> None:
    back = counter_compensate_twist_scalar(*compensate_twist_scalar(*twist, factors), factors)
    np.testing.assert_allclose(back, twist, rtol=0.0, atol=1e-12)


def test_scalar_crosstalk_picks_the_direction_of_travel() -> None:
    f = CorrectionFactors(1.0, 1.0, 1.0, 0.1, 0.2, 0.3, 0.4)
    assert crosstalk_yaw_rate_scalar(f, 1.0, 0.0) == pytest.approx(0.1)
    assert crosstalk_yaw_rate_scalar(f, -1.0, 0.0) == pytest.approx(0.2)
    assert crosstalk_yaw_rate_scalar(f, 0.0, 1.0) == pytest.approx(0.3)
    assert crosstalk_yaw_rate_scalar(f, 0.0, -1.0) == pytest.approx(0.4)
    # the truth of the twin: the robot falls short by 1/k and turns by c per metre
    assert counter_compensate_twist_scalar(
        1.0, 0.0, 0.0, f.with_values(scale_longitudinal=2.0)
    ) == (
        pytest.approx(0.5),
        pytest.approx(0.0),
        pytest.approx(0.05),
    )
