"""The closed choices omnical takes (methods, modes, formats) and the one way to parse them.

Each a :class:`~enum.StrEnum` (plain strings work too); :func:`parse_choice` raises a one-line
:class:`~omnical.errors.ChoiceError`. Standard library only: the CLI imports it first.
"""

from __future__ import annotations

from enum import StrEnum
from typing import TypeVar

from omnical.errors import ChoiceError

__all__ = [
    "AlignMode",
    "ChoiceError",
    "EstimationMethod",
    "ExportFormat",
    "LocateMethod",
    "OdometrySource",
    "choice_list",
    "parse_choice",
]


class LocateMethod(StrEnum):
    """Multilateration method (:func:`omnical.ips.solve.solve_fixes`)."""

    ROBUST = "robust"
    """Least squares plus leave-one-out rejection of NLOS ranges."""
    LSQ = "lsq"
    """Gauss–Newton least squares from a closed-form start."""
    GRID = "grid"
    """Seed 000's 1 mm search minimising its Eq. 4 (2D only)."""


class AlignMode(StrEnum):
    """How an estimated trajectory is aligned to its reference before errors are taken."""

    NONE = "none"
    """As recorded (estimates already in the map frame)."""
    ORIGIN = "origin"
    """Start poses made to coincide (odometry)."""
    SE2 = "se2"
    """Least-squares rotation and translation in the plane."""


class EstimationMethod(StrEnum):
    """How the correction factors are estimated from recordings."""

    PROCEDURES = "procedures"
    """Seed 000's procedures, one factor group per manoeuvre."""
    JOINT = "joint"
    """One least squares over all seven factors and the hedgehog offset."""


class OdometrySource(StrEnum):
    """Which odometry a recording is evaluated or calibrated with
    (:mod:`omnical.estimation.odometry_sources` computes each)."""

    ODOM = "odom"
    """The recording's ``/odom`` (the vehicle controller's own wheel odometry)."""
    WHEELS = "wheels"
    """From the driven wheels' encoders (a JointState topic) through the robot's kinematics."""
    SEED003 = "seed003"
    """Seed 003's dead-wheel + IMU + magnetometer estimate."""


class ExportFormat(StrEnum):
    """File format of ``omnical export``."""

    CSV = "csv"
    """One CSV file per topic."""
    TUM = "tum"
    """TUM trajectory files (``t x y z qx qy qz qw``)."""


_Choice = TypeVar("_Choice", bound=StrEnum)


def choice_list(enum_type: type[StrEnum]) -> str:
    """The values of ``enum_type`` as prose: ``robust, lsq or grid``."""
    values = [member.value for member in enum_type]
    if len(values) == 1:
        return values[0]
    return f"{', '.join(values[:-1])} or {values[-1]}"


def parse_choice(enum_type: type[_Choice], text: str, option_name: str) -> _Choice:
    """The member of ``enum_type`` spelt ``text`` (a member is returned as it is).

    Args:
        enum_type: The closed set of choices.
        text: What the user or the caller gave.
        option_name: Where it was given (``--method``, ``solve_fixes: method``), for the message.

    Raises:
        ChoiceError: ``text`` is not one of the values, e.g.
            ``--method: unknown value 'foo'; choose robust, lsq or grid``.
    """
    try:
        return enum_type(text)
    except ValueError:
        msg = f"{option_name}: unknown value {text!r}; choose {choice_list(enum_type)}"
        raise ChoiceError(msg) from None
