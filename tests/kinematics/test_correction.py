"""The seven-factor correction model of seed 000 Table 2."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.kinematics.correction import (
    CorrectionFactors,
    compensate_twist,
    counter_compensate_twist,
    crosstalk_yaw_rate,
)


def test_table2_values() -> None:
    f = CorrectionFactors.seed000_table2()
    np.testing.assert_array_equal(f.scales, [1.02, 1.13, 1.0236])
    np.testing.assert_array_equal(f.crosstalks_rad_per_m, [0.0072, 0.00009, 0.0389, 0.0277])
    assert CorrectionFactors.from_vector(f.as_vector()) == f


def test_crosstalk_is_direction_dependent() -> None:
    f = CorrectionFactors.seed000_table2()
    assert crosstalk_yaw_rate(f, 0.5, 0.0) == pytest.approx(0.5 * 0.0072)
    assert crosstalk_yaw_rate(f, -0.5, 0.0) == pytest.approx(0.5 * 0.00009)
    assert crosstalk_yaw_rate(f, 0.0, 0.2) == pytest.approx(0.2 * 0.0389)
    assert crosstalk_yaw_rate(f, 0.0, -0.2) == pytest.approx(0.2 * 0.0277)


def test_compensation_scales_and_injects() -> None:
    f = CorrectionFactors.seed000_table2()
    out = compensate_twist([0.3, 0.0, 0.0], f)
    # forward 0.3 m/s: yaw −0.0072·0.3 injected, then scaled by the rotational factor
    np.testing.assert_allclose(out, [0.3 * 1.02, 0.0, -0.0072 * 0.3 * 1.0236])


factor_values = st.tuples(
    st.floats(0.8, 1.25),
    st.floats(0.8, 1.25),
    st.floats(0.8, 1.25),
    st.floats(-0.05, 0.05),
    st.floats(-0.05, 0.05),
    st.floats(-0.05, 0.05),
    st.floats(-0.05, 0.05),
)
twists = st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-3.0, 3.0))


@settings(max_examples=300, deadline=None)
@given(values=factor_values, twist=twists)
def test_counter_compensation_undoes_compensation(
    values: tuple[float, ...], twist: tuple[float, float, float]
) -> None:
    f = CorrectionFactors.from_vector(values)
    np.testing.assert_allclose(
        counter_compensate_twist(compensate_twist(twist, f), f), twist, atol=1e-12
    )
    np.testing.assert_allclose(
        compensate_twist(counter_compensate_twist(twist, f), f), twist, atol=1e-12
    )


def test_identity_changes_nothing() -> None:
    tw = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(compensate_twist(tw, CorrectionFactors.identity()), tw)


def test_composition_multiplies_scales_and_adds_crosstalk() -> None:
    a = CorrectionFactors(1.1, 1.0, 1.02, 0.01, 0.0, 0.02, 0.0)
    b = CorrectionFactors(1.01, 1.05, 0.99, 0.001, 0.002, -0.003, 0.004)
    c = a.composed_with(b)
    np.testing.assert_allclose(c.scales, a.scales * b.scales)
    np.testing.assert_allclose(
        c.crosstalks_rad_per_m, a.crosstalks_rad_per_m + b.crosstalks_rad_per_m
    )
