"""Trajectories: timing profiles, the seeds' reference paths and open-loop feed-forward commands."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
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

_EXPORTS: dict[str, str] = {
    "ProfileTiming": "omnical.trajectory.profiles",
    "Reference": "omnical.trajectory.references",
    "SEED001_SQUARE_M": "omnical.trajectory.references",
    "SEED003_SQUARE_M": "omnical.trajectory.references",
    "SEED003_TRIANGLE_M": "omnical.trajectory.references",
    "TwistLimits": "omnical.trajectory.scripts",
    "body_twists_between": "omnical.trajectory.scripts",
    "check_twist_limits": "omnical.trajectory.scripts",
    "circle": "omnical.trajectory.references",
    "feedforward_commands": "omnical.trajectory.scripts",
    "integrate_body_twists": "omnical.trajectory.scripts",
    "lissajous": "omnical.trajectory.references",
    "phase_profile": "omnical.trajectory.profiles",
    "polygon": "omnical.trajectory.references",
    "profile_duration": "omnical.trajectory.profiles",
    "profile_timing": "omnical.trajectory.profiles",
    "waypoints": "omnical.trajectory.references",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

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


__getattr__ = lazy_getattr(__name__, _EXPORTS)
