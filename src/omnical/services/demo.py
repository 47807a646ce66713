"""The demo: the whole story of seed 000 on the ``rosy-mecanum`` twin, as one result.

:func:`run_demo` runs its chapters (Lissajous, campaign, Table 4, seed 001's paths, seed 003,
navigation) and writes nothing: :func:`omnical.reports.demo.write_demo` writes its files.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from omnical.calibration.campaign import CampaignResult
from omnical.control.waypoint import WaypointController, seed001_circle_waypoints
from omnical.estimation.smoother import SmootherParams
from omnical.evaluation.metrics import (
    GROUND_TRUTH_KEY,
    SMOOTHED_KEY,
    Tracked,
    TrackingMetrics,
    track_recording,
)
from omnical.experiment.script import TwistSequence
from omnical.recording.recording import Recording
from omnical.robot.description import RobotDescription
from omnical.robot.loader import load_robot
from omnical.services.navigation import NavigationChapter, demo_chapter
from omnical.services.seed003 import Seed003Result, run_seed003
from omnical.trajectory.references import SEED001_SQUARE_M, Reference, lissajous
from omnical.trajectory.scripts import feedforward_commands
from omnical.twin.bench import run_twin_campaign
from omnical.twin.closed_loop import ClosedLoopRun, closed_loop_run
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run

__all__ = [
    "DemoResult",
    "LissajousRun",
    "PathRun",
    "lissajous_run",
    "lissajous_smoother",
    "run_demo",
]

LEAD_IN_S = 1.0
"""simulate_run stands the robot still for this long before the commands start."""

LISSAJOUS_CENTRE_MAP_M = (2.9, 2.4)
"""Centre of the Lissajous curve in seed 000's beacon map (Table 3), metres."""

Progress = Callable[[str], None]


@dataclass(frozen=True)
class LissajousRun:
    """One open-loop Lissajous run and its evaluation.

    Attributes:
        label: ``uncalibrated`` or ``calibrated``.
        recording: the run (twin topics, simulated IPS).
        tracked: estimate name → association, alignment and metrics against the reference.
    """

    label: str
    recording: Recording
    tracked: dict[str, Tracked]

    @property
    def metrics(self) -> dict[str, TrackingMetrics]:
        """Estimate name → Table 4 measures."""
        return {name: t.metrics for name, t in self.tracked.items()}


@dataclass(frozen=True)
class PathRun:
    """One closed-loop path of seeds 001/003.

    Attributes:
        slug: short name for files.
        name: what it is, for the report.
        outline_xy_m: (K, 2) the way-points from the start, path frame.
        run: the closed-loop run.
    """

    slug: str
    name: str
    outline_xy_m: NDArray[np.float64]
    run: ClosedLoopRun

    @property
    def final_vs_odometry_m(self) -> float:
        """Final distance to the last way-point by the odometry the loop closed on."""
        return self.run.final_error_m(_xy(self.outline_xy_m[-1]), "odometry")

    @property
    def final_vs_ground_truth_m(self) -> float:
        """Final distance to the last way-point, truly."""
        return self.run.final_error_m(_xy(self.outline_xy_m[-1]), "ground_truth")

    @property
    def duration_s(self) -> float:
        """How long the loop ran."""
        t = self.run.control.t_s
        return float(t[-1] - t[0])


def _xy(row: NDArray[np.float64]) -> tuple[float, float]:
    return float(row[0]), float(row[1])


@dataclass(frozen=True)
class DemoResult:
    """What the demo ran and measured."""

    robot: RobotDescription
    seed: int
    uncalibrated: LissajousRun
    calibrated: LissajousRun
    campaign: CampaignResult
    paths: tuple[PathRun, ...]
    seed003: Seed003Result
    navigation: NavigationChapter | None

    @property
    def before(self) -> dict[str, TrackingMetrics]:
        """Lissajous measures with uncalibrated kinematics."""
        return self.uncalibrated.metrics

    @property
    def after(self) -> dict[str, TrackingMetrics]:
        """Lissajous measures with calibrated kinematics."""
        return self.calibrated.metrics

    @property
    def improvement(self) -> float:
        """Ground-truth RMSE of the open-loop Lissajous, uncalibrated / calibrated."""
        return self.before[GROUND_TRUTH_KEY].rmse_m / self.after[GROUND_TRUTH_KEY].rmse_m

    @property
    def measured_improvement(self) -> float | None:
        """The same ratio as the sensors measure it (the smoothed IPS + odometry estimate), or
        None when the smoother could not run: what a user without ground truth would publish."""
        if SMOOTHED_KEY not in self.before or SMOOTHED_KEY not in self.after:
            return None
        return self.before[SMOOTHED_KEY].rmse_m / self.after[SMOOTHED_KEY].rmse_m


def lissajous_run(
    robot: RobotDescription,
    params: TwinParams,
    ref: Reference,
    seed: int,
    label: str,
    smoother: SmootherParams | None = None,
) -> LissajousRun:
    """The open-loop Lissajous of seed 000 §4 on the twin, measured as Table 4 does and by the
    smoother (``smoother``; default :func:`lissajous_smoother`)."""
    t, twists = feedforward_commands(ref, 50.0, limits=robot.limits)
    commands = TwistSequence.from_arrays("lissajous", t, twists, rate_hz=50.0)
    start = (float(ref.poses[0, 0]), float(ref.poses[0, 1]), float(ref.poses[0, 2]))
    recording = simulate_run(commands, robot, replace(params, start_pose_map=start), seed=seed)
    # the reference is placed in the map frame where the robot starts: no alignment for the
    # map-frame estimates; the odometry starts at the reference's start (origin alignment)
    tracked = track_recording(
        recording,
        (ref.t_s + LEAD_IN_S, ref.poses),
        align="none",
        odometry_align="origin",
        hedge_offset_m=robot.hedge_offset_m,
        smoother=smoother or lissajous_smoother(robot),
    )
    return LissajousRun(label, recording, tracked)


def lissajous_smoother(
    robot: RobotDescription, before: LissajousRun | None = None
) -> SmootherParams:
    """What the smoother is told on the demo's Lissajous runs.

    The odometry's stamping delay of one control period (``odometry_delay_s``), and after
    calibration the latency found before (``before``) as the prior.
    """
    told = SmootherParams(odometry_delay_s=1.0 / robot.drive_train.control_rate_hz)
    found = before.tracked[SMOOTHED_KEY].smoothing if before is not None else None
    if found is None:
        return told
    return replace(
        told, latency_s=found.latency_s, latency_prior_sigma_s=max(found.latency_sigma_s, 1e-4)
    )


def _closed_loop(
    controller: WaypointController, robot: RobotDescription, params: TwinParams, seed: int
) -> ClosedLoopRun:
    return closed_loop_run(controller, robot, params, seed=seed, pose_source="odometry")


def _closed_loop_paths(
    robot: RobotDescription, params: TwinParams, seed: int
) -> tuple[PathRun, ...]:
    circle = seed001_circle_waypoints()
    cases: list[tuple[str, str, WaypointController, tuple[tuple[float, float], ...]]] = [
        (
            "seed001-circle",
            "seed 001 circle, 1 m radius (waypoint controller)",
            WaypointController(circle),
            ((0.0, 0.0), *circle),
        ),
        (
            "seed001-square",
            "seed 001 square, 1 m (waypoint controller)",
            WaypointController((*SEED001_SQUARE_M[1:], SEED001_SQUARE_M[0])),
            (*SEED001_SQUARE_M, SEED001_SQUARE_M[0]),
        ),
    ]
    start = replace(params, start_pose_map=(2.0, 2.0, 0.0))
    return tuple(
        PathRun(
            slug,
            name,
            np.array(outline, dtype=np.float64),
            _closed_loop(controller, robot, start, seed + i),
        )
        for i, (slug, name, controller, outline) in enumerate(cases)
    )


def run_demo(
    *, seed: int = 0, progress: Progress | None = None, with_navigation: bool = True
) -> DemoResult:
    """Run the whole story (module docstring); ``progress`` receives one line per chapter.

    ``with_navigation=False`` leaves out the navigation chapter.
    """
    say = progress or (lambda _msg: None)
    robot = load_robot("rosy-mecanum")
    params = default_twin(robot)
    ref = lissajous(origin_m=LISSAJOUS_CENTRE_MAP_M)

    say("Lissajous, uncalibrated")
    before = lissajous_run(robot, params, ref, seed, "uncalibrated")

    say("calibration campaign")
    campaign = run_twin_campaign(robot, params, seed=seed)

    say("Lissajous, calibrated")
    calibrated = params.with_installed(campaign.factors)
    after = lissajous_run(
        robot, calibrated, ref, seed + 1, "calibrated", lissajous_smoother(robot, before)
    )

    say("closed-loop paths")
    paths = _closed_loop_paths(robot, calibrated, seed)

    say("seed 003 on the omni-X twin")
    seed003 = run_seed003(seed=seed)

    navigation = None
    if with_navigation:
        say("navigation on lab-8x6")
        navigation = demo_chapter(seed)
    return DemoResult(robot, seed, before, after, campaign, paths, seed003, navigation)
