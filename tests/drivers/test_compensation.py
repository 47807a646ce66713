"""Host-side compensation for stock firmware."""

from __future__ import annotations

import pytest

from omnical.drivers.compensation import CompensatingRobot
from omnical.experiment.ports import RobotState
from omnical.kinematics.correction import CorrectionFactors, compensate_twist_scalar


class _Base:
    def __init__(self) -> None:
        self.sent: list[tuple[float, float, float]] = []

    def send_twist(self, vx: float, vy: float, wz: float) -> None:
        self.sent.append((vx, vy, wz))

    def read_state(self) -> RobotState:
        return RobotState(0.0, (0.0, 0.0, 0.0), self.sent[-1], (), 0.0)

    def stop(self) -> None:
        self.sent.append((0.0, 0.0, 0.0))


def test_compensates_out_and_counter_compensates_in() -> None:
    f = CorrectionFactors(
        scale_longitudinal=1.02,
        scale_lateral=1.13,
        scale_rotational=1.0236,
        crosstalk_forward_rad_per_m=0.0072,
        crosstalk_reverse_rad_per_m=-0.00009,
        crosstalk_left_rad_per_m=0.0389,
        crosstalk_right_rad_per_m=-0.0277,
    )
    base = _Base()
    robot = CompensatingRobot(base, f)
    robot.send_twist(0.2, 0.1, 0.3)
    assert base.sent[-1] == compensate_twist_scalar(0.2, 0.1, 0.3, f)
    # the base reports what it was fed: the odometry gives back the desired twist
    assert robot.read_state().odom_twist == pytest.approx((0.2, 0.1, 0.3))
    assert not robot.pose_compensated
    robot.stop()
    assert base.sent[-1] == (0.0, 0.0, 0.0)
