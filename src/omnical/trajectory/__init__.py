"""Trajectories: timing profiles, the seeds' reference paths and open-loop feed-forward commands."""

from omnical.trajectory.profiles import (
    ProfileTiming,
    phase_profile,
    profile_duration,
    profile_timing,
)
from omnical.trajectory.references import (
    SEED001_SQUARE_M,
    SEED003_SQUARE_M,
    SEED003_TRIANGLE_M,
    Reference,
    circle,
    lissajous,
    polygon,
    waypoints,
)
from omnical.trajectory.scripts import (
    TwistLimits,
    body_twists_between,
    check_twist_limits,
    feedforward_commands,
    integrate_body_twists,
)

__all__ = [
    "SEED001_SQUARE_M",
    "SEED003_SQUARE_M",
    "SEED003_TRIANGLE_M",
    "ProfileTiming",
    "Reference",
    "TwistLimits",
    "body_twists_between",
    "check_twist_limits",
    "circle",
    "feedforward_commands",
    "integrate_body_twists",
    "lissajous",
    "phase_profile",
    "polygon",
    "profile_duration",
    "profile_timing",
    "waypoints",
]
