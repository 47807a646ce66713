"""Files of the navigation commands and the demo's navigation chapter.

:func:`write_map_outputs` (``omnical map``: YAML + PGM, TUM, PNG), :func:`write_navigation_figure`,
:func:`write_plan_figure` and :func:`navigation_chapter_section` (the demo's chapter).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from omnical.bags.export import tum_lines
from omnical.errors import OutputError
from omnical.estimation.se2 import compose_poses
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import InflatedMap
from omnical.navigation.map_io import save_map
from omnical.navigation.prm import PlanResult, Roadmap
from omnical.navigation.slam import scan_points_sensor
from omnical.reports.figures.navigation import plot_mapping, plot_navigation, plot_plan
from omnical.reports.markdown import FigureLink, MarkdownTable, Section
from omnical.services.navigation import MappingRun, NavigationChapter, NavigationRun, RecordedMap

__all__ = [
    "figure_scans",
    "map_output_paths",
    "navigation_chapter_section",
    "plan_output_paths",
    "scan_hits_world",
    "write_map_outputs",
    "write_navigation_figure",
    "write_plan_figure",
]

_FIGURE_SCANS = 60
"""Scans drawn in a mapping figure (evenly spread over the run)."""


def map_output_paths(yaml_path: str | Path) -> dict[str, Path]:
    """The files ``omnical map --out MAP.yaml`` writes: yaml, pgm, tum, png."""
    y = Path(yaml_path)
    return {
        "yaml": y,
        "pgm": y.with_suffix(".pgm"),
        "tum": y.with_suffix(".tum"),
        "png": y.with_suffix(".png"),
    }


def figure_scans(m: int, count: int = _FIGURE_SCANS) -> NDArray[np.int64]:
    """Indices of the ``count`` scans (of ``m``) a mapping figure draws, spread over the run."""
    picks: NDArray[np.int64] = np.unique(
        np.linspace(0, m - 1, min(count, m)).round().astype(np.int64)
    )
    return picks


def scan_hits_world(
    poses: NDArray[np.float64],
    ranges_m: NDArray[np.float64],
    angles_rad: NDArray[np.float64],
    mount_pose: tuple[float, float, float],
    max_range_m: float,
    count: int = _FIGURE_SCANS,
) -> list[NDArray[np.float64]]:
    """The hit points of the scans :func:`figure_scans` picks, in the map frame."""
    picks = figure_scans(poses.shape[0], count)
    sensors = compose_poses(poses[picks], np.asarray(mount_pose, dtype=np.float64))
    out = []
    for sensor, k in zip(sensors, picks, strict=True):
        pts, hit = scan_points_sensor(ranges_m[k], angles_rad, max_range_m)
        p = pts[hit]
        c, s = math.cos(sensor[2]), math.sin(sensor[2])
        out.append(
            np.column_stack(
                [sensor[0] + c * p[:, 0] - s * p[:, 1], sensor[1] + s * p[:, 0] + c * p[:, 1]]
            )
        )
    return out


def _write_tum(path: Path, t_ns: NDArray[np.int64], poses: NDArray[np.float64]) -> None:
    quaternions = [(math.sin(yaw / 2), math.cos(yaw / 2)) for yaw in poses[:, 2].tolist()]
    rows = np.column_stack(
        [poses[:, :2], np.zeros((len(poses), 3)), np.reshape(quaternions, (-1, 2))]
    )
    header = "# omnical map: SLAM trajectory, timestamp tx ty tz qx qy qz qw\n"
    try:
        path.write_text(header + tum_lines(t_ns, rows), encoding="utf-8")
    except OSError as err:
        msg = f"{path}: cannot write: {err.strerror or err}"
        raise OutputError(msg) from None


def _since_first(t_s: NDArray[np.float64], m: int) -> NDArray[np.float64]:
    """The times of the scans a mapping figure draws, s since the first scan."""
    picked: NDArray[np.float64] = t_s[figure_scans(m)] - t_s[0]
    return picked


def write_map_outputs(
    recorded: RecordedMap, yaml_path: str | Path, *, source: str = ""
) -> dict[str, Path]:
    """Write the map (YAML + PGM), the trajectory (TUM) and the figure of ``recorded``.

    Check the paths first (:func:`omnical.reports.outputs.claim_files` on
    :func:`map_output_paths`); this writes over them.

    Raises:
        OutputError: a file cannot be written.
    """
    paths = map_output_paths(yaml_path)
    comment = f"omnical map {source}".strip()
    save_map(recorded.slam.grid, paths["yaml"], comment=comment)
    _write_tum(paths["tum"], recorded.scan_t_ns, recorded.slam.poses)
    slam = recorded.slam
    hits = scan_hits_world(
        slam.poses, recorded.ranges_m, recorded.angles_rad, recorded.mount_pose, 6.0
    )
    rmse = (
        f"; RMSE vs /ground_truth {recorded.trajectory_rmse_m * 100:.1f} cm, "
        f"yaw {math.degrees(recorded.yaw_rmse_rad):.2f}°"
        if math.isfinite(recorded.trajectory_rmse_m)
        else ""
    )
    plot_mapping(
        paths["png"],
        grid=slam.grid,
        poses=slam.poses,
        scan_points_world=hits,
        odometry=slam.odometry_poses,
        truth=recorded.truth,
        keyframes=slam.keyframes,
        loop_pairs=slam.loop_closures,
        scan_t_s=_since_first(recorded.scan_t_ns.astype(np.float64) * 1e-9, len(slam.poses)),
        title=(
            f"SLAM on {source or 'the recording'}: {len(slam.poses)} scans, "
            f"{len(slam.keyframes)} keyframes, {len(slam.loop_closures)} loop closures{rmse}"
        ),
    )
    return paths


def write_mapping_figure(run: MappingRun, path: Path, title: str) -> Path:
    """Seed 001 Fig. 12 for a mapping tour on the twin (truth drawn)."""
    slam = run.slam
    lp = run.scans.params
    hits = scan_hits_world(slam.poses, run.scans.ranges_m, lp.angles_rad, lp.mount_pose, 6.0)
    return plot_mapping(
        path,
        grid=slam.grid,
        poses=slam.poses,
        scan_points_world=hits,
        odometry=slam.odometry_poses,
        truth=run.scans.true_pose,
        keyframes=slam.keyframes,
        loop_pairs=slam.loop_closures,
        scan_t_s=_since_first(np.asarray(run.scans.t_s, dtype=np.float64), len(slam.poses)),
        title=title,
    )


def write_navigation_figure(
    run: NavigationRun,
    map_grid: OccupancyGrid,
    path: Path,
    title: str = "",
) -> Path:
    """Seed 001 Fig. 13 for ``run`` on ``map_grid``."""
    planned = [leg.plan.path_m for leg in run.legs if leg.plan.status == "ok"]
    rm = run.roadmap
    return plot_navigation(
        path,
        grid=map_grid,
        blocked=run.inflated.blocked,
        start=run.start,
        goals=np.array([leg.goal_m for leg in run.legs], dtype=np.float64).reshape(-1, 2),
        planned=planned,
        driven=run.twin_log.ground_truth_pose[:, :2],
        roadmap_nodes=None if rm is None else rm.nodes_m,
        roadmap_edges=None if rm is None else rm.edges,
        estimated=run.estimates[:, 1:3] if run.estimates.size else None,
        title=title,
    )


def plan_output_paths(csv_path: str | Path) -> dict[str, Path]:
    """The files ``omnical plan --out PATH.csv`` writes: the way-points and the figure
    ``PATH.png`` beside them."""
    csv = Path(csv_path)
    return {"csv": csv, "png": csv.with_suffix(".png")}


def write_plan_figure(
    path: Path,
    *,
    inflated: InflatedMap,
    start: NDArray[np.float64],
    goal: NDArray[np.float64],
    result: PlanResult,
    roadmap: Roadmap | None,
    title: str,
) -> Path:
    """The figure of ``omnical plan``: the path on the map it was planned on."""
    return plot_plan(
        path,
        grid=inflated.grid,
        blocked=inflated.blocked,
        start=start,
        goal=goal,
        planned=result.path_m,
        raw=None if np.array_equal(result.raw_path_m, result.path_m) else result.raw_path_m,
        roadmap_nodes=None if roadmap is None else roadmap.nodes_m,
        roadmap_edges=None if roadmap is None else roadmap.edges,
        title=title,
    )


def _cm(value: float) -> str:
    return "–" if not math.isfinite(value) else f"{value * 100:.1f}"


def navigation_chapter_section(chapter: NavigationChapter, fig_dir: Path) -> Section:
    """Draw the chapter's figures into ``fig_dir`` and return its Markdown section.

    Figure links are absolute; :func:`omnical.reports.markdown.write_markdown_report` makes them
    relative to the report.
    """
    mapping, nav = chapter.mapping, chapter.navigation
    score = mapping.score
    fig_dir.mkdir(parents=True, exist_ok=True)
    map_png = write_mapping_figure(
        mapping,
        fig_dir / "navigation-mapping.png",
        f"{chapter.world_name}: mapping tour, SLAM map (uncalibrated odometry)",
    )
    nav_png = write_navigation_figure(
        nav,
        mapping.slam.grid,
        fig_dir / "navigation-goals.png",
        f"{chapter.world_name}: navigating to {len(chapter.goals)} goals on the SLAM map",
    )
    duration = float(mapping.scans.t_s[-1] - mapping.scans.t_s[0])
    targets = MarkdownTable(
        ("measure", "value", "target (omnical's, on the twin)"),
        (
            ("occupied precision", f"{score.occupied_precision:.4f}", "≥ 0.95"),
            ("recall of the surfaces seen", f"{score.recall_seen:.4f}", "≥ 0.90"),
            ("free but occupied", f"{score.free_but_occupied * 100:.2f} %", "≤ 1 %"),
            ("SLAM trajectory RMSE", f"{_cm(mapping.trajectory_rmse_m)} cm", "≤ 2 cm (lab)"),
            ("SLAM yaw RMSE", f"{math.degrees(mapping.yaw_rmse_rad):.2f}°", "≤ 0.5°"),
            ("raw odometry RMSE", f"{_cm(mapping.odometry_rmse_m)} cm", "–"),
            (
                "mapping speed",
                f"{duration / max(mapping.slam_time_s, 1e-9):.1f}× real time",
                "≥ 5×",
            ),
        ),
        caption=f"Mapping tour on {chapter.world_name} ({duration:.0f} s of robot time)",
        note=(
            "Target: what omnical requires of its SLAM on this tour of the twin (its tests "
            "check the map and trajectory bounds); the map is scored against the world's floor "
            "plan, the trajectory against the twin's ground truth."
        ),
        align=("l", "r", "r"),
    )
    legs = MarkdownTable(
        ("leg", "goal (m)", "controller", "plan", "end", "goal error (cm)"),
        tuple(
            (
                str(k),
                f"({leg.goal_m[0]:.1f}, {leg.goal_m[1]:.1f})",
                leg.controller,
                f"{leg.plan.status} ({leg.plan.method or leg.plan.reason})",
                leg.control.reason if leg.control is not None else "–",
                _cm(leg.goal_error_m),
            )
            for k, leg in enumerate(nav.legs, 1)
        ),
        caption="Navigating between points on the SLAM map",
        note=(
            f"Collision: {nav.collision or 'none'}; smallest clearance of the footprint to the "
            f"floor plan {_cm(nav.min_clearance_m)} cm (ground truth); scan-to-map matches "
            f"accepted {nav.localisation_accepted * 100:.0f} %."
        ),
        align=("r", "l", "l", "l", "l", "r"),
    )
    intro = (
        "Seed 001 §4.2.3 on the twin: the default (uncalibrated) rosy-mecanum twin drives a tour "
        f"of {chapter.world_name} with a 2D LiDAR (360 beams, 12 m, ≈ 1 cm noise, 10 Hz); SLAM "
        "(scan matching with the odometry as prior, keyframes, loop closures, a gtsam pose "
        "graph, a log-odds map at 2 cm) builds the map, obstacles are inflated by the "
        "footprint's circumscribed radius, a PRM plans each leg and the robot follows it, "
        "localised by scan-to-map matching (beyond the paper, whose odometry error "
        "'confuses the robot about its current position')."
    )
    return Section(
        "Navigation (seed 001 §4.2.3, Figures 12–13)",
        (
            intro,
            targets,
            FigureLink(map_png, "Scans and tracked poses; the map built (seed 001 Fig. 12)"),
            legs,
            FigureLink(
                nav_png,
                "Inflated obstacles, roadmap, planned and driven paths (seed 001 Fig. 13)",
            ),
        ),
    )
