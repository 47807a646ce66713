"""Twin files: the factor sections overlay the default twin through the one factors.yaml parser."""

from __future__ import annotations

import pytest

from omnical.errors import ConfigError
from omnical.robot.loader import load_robot
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
        # the IPS section's own checks, the field named whole (a new user saw "field
        # 'nlos_probability: a probability ...", the quote unclosed)
        (
            {"ips": {"nlos_probability": 2}},
            r"^t\.yaml: field 'ips\.nlos_probability': a probability must be in \[0, 1\], got 2",
        ),
        ({"ips": {"sideways": 1}}, r"^t\.yaml: field 'ips': unknown key 'sideways'$"),
    ],
)
def test_bad_factor_sections_name_the_field(data: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_twin(data, ROSY, "t.yaml")


def test_motor_imperfections_from_a_twin_file() -> None:
    p = parse_twin(
        {
            "base": "ideal",
            "motor_gain_errors": [-0.01, -0.02, 0.0, 0.01],
            "motor_time_constant_error": 0.2,
            "coulomb_friction_radps": 1.0,
            "viscous_droop": 0.05,
        },
        ROSY,
        "t.yaml",
    )
    motors = p.wheel_motors(ROSY.drive_train, 4)
    assert [m.gain for m in motors] == pytest.approx([0.99, 0.98, 1.0, 1.01])
    assert motors[0].time_constant_s == pytest.approx(1.2 * ROSY.drive_train.motor_time_constant_s)
    assert (motors[0].coulomb_friction_radps, motors[0].viscous_droop) == (1.0, 0.05)
    assert parse_twin({"base": "ideal"}, ROSY).coulomb_friction_radps == 0.0


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"motor_gain_errors": [0.0, 0.0]}, r"'motor_gain_errors': 2 values for 4 wheels"),
        ({"motor_gain_errors": [0.0, 0.0, -0.95, 0.0]}, r"'motor_gain_errors\.2'"),
        ({"coulomb_friction_radps": -1.0}, r"'coulomb_friction_radps'"),
        ({"viscous_droop": -0.1}, r"'viscous_droop'"),
        ({"motor_time_constant_error": -1.0}, r"'motor_time_constant_error'"),
    ],
)
def test_bad_motor_imperfections_name_the_field(data: dict[str, object], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_twin(data, ROSY, "t.yaml")


def test_a_start_yaw_in_degrees_is_refused_with_the_radians_meant() -> None:
    """Issue 29 (degrees where radians are asked): ``start_pose_map: [1.5, 1.2, 90]`` started
    the twin at 90 rad (a heading of 116.6°) without a word."""
    robot = load_robot("rosy-mecanum")
    with pytest.raises(ConfigError, match=r"t\.yaml: field 'start_pose_map\.2': a yaw of 90 rad"):
        parse_twin({"start_pose_map": [1.5, 1.2, 90]}, robot, "t.yaml")
    assert (
        parse_twin({"start_pose_map": [1.5, 1.2, -3.1]}, robot, "t.yaml").start_pose_map[2] == -3.1
    )


def test_a_true_hedgehog_off_the_robot_is_refused() -> None:
    """Issue 29 (sizes checked): a twin's hedge_offset_m in centimetres was taken (±1000 m)."""
    robot = load_robot("rosy-mecanum")
    with pytest.raises(ConfigError, match=r"t\.yaml: field 'hedge_offset_m': the hedgehog"):
        parse_twin({"hedge_offset_m": [4, -3, 40]}, robot, "t.yaml")
    ok = parse_twin({"hedge_offset_m": [0.05, -0.02, 0.4]}, robot, "t.yaml")
    assert ok.hedge_offset_m == (0.05, -0.02, 0.4)


@pytest.mark.parametrize(
    ("ips", "match"),
    [
        ({"latency_s": 1e9}, r"'ips\.latency_s': must be at most 10 s .*got 1e\+09$"),
        ({"latency_s": 1e18}, r"'ips\.latency_s': must be at most 10 s"),
        ({"latency_periods": 50}, r"'ips\.latency_periods': must be at most 10 "),
        ({"timing_jitter_s": 5.0}, r"'ips\.timing_jitter_s': must be at most 1 s"),
        ({"burst_gap_s": [0.001, 1e6]}, r"'ips\.burst_gap_s': must be at most 1 s"),
        ({"device_uptime_at_start_s": 1e18}, r"'ips\.device_uptime_at_start_s': must be at most"),
        ({"beacon_repeat_period_s": 1e9}, r"'ips\.beacon_repeat_period_s': must be at most 3600"),
        ({"beacon_first_s": 1e9}, r"'ips\.beacon_first_s': must be at most 3600 s"),
        ({"rate_min_hz": 1e-9}, r"'ips\.rate_min_hz': must be at least 0\.5 Hz"),
    ],
)
def test_ips_times_beyond_a_physical_bound_are_refused(ips: dict[str, object], match: str) -> None:
    """A twin's ips.latency_s of 1e9 ran a 1e9-s simulation (1e18: a negative bag time)."""
    with pytest.raises(ConfigError, match=r"^t\.yaml: field " + match):
        parse_twin({"ips": ips}, ROSY, "t.yaml")
    edge = {"latency_s": 10.0, "latency_periods": 10.0, "beacon_first_s": 3600.0}
    assert parse_twin({"ips": edge}, ROSY, "t.yaml").ips.latency_s == 10.0


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"true_factors": {"scale": {"lateral": True}}}, "true_factors.scale"),
        (
            {"installed_factors": {"crosstalk_rad_per_m": {"left": False}}},
            "installed_factors.crosstalk_rad_per_m",
        ),
        ({"slip_sigma": True}, "slip_sigma"),
        ({"wheel_radius_errors": [0.01, True, 0.0, 0.0]}, "wheel_radius_errors"),
    ],
)
def test_a_boolean_is_not_a_number_in_a_twin_file(data: dict[str, object], field: str) -> None:
    """Found by a new user: ``true_factors.scale.lateral: true`` was taken for 1.0 and
    ``slip_sigma: true`` said "less than or equal to 0.5"; robot files refused booleans."""
    with pytest.raises(ConfigError) as info:
        parse_twin(data, ROSY, "t.yaml")
    assert str(info.value) == f"t.yaml: field '{field}': expected a number, got a boolean"
