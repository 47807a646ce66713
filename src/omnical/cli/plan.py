"""``omnical plan``: plan a path on a map_server map (PRM, A* fallback, shortcutting)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Robot, Seed
from omnical.cli.output import say

if TYPE_CHECKING:
    from omnical.navigation.grid import OccupancyGrid

__all__ = ["check_inside", "check_yaw_rad", "parse_xy", "plan"]

MAX_NODES = 5000
"""``--nodes`` at most (:data:`omnical.navigation.prm.MAX_NUM_NODES`, checked equal in the tests;
written out here so that the CLI's help does not import the planner)."""


def parse_xy(text: str, option: str, count: int = 2) -> tuple[float, ...]:
    """``"X,Y"`` (or ``"X,Y,YAW"`` with ``count=3``) → floats; a ConfigError names the option.

    A yaw is in radians, within ±2π; ``90deg`` gives degrees (a plain 90 is refused: that
    is degrees where radians are asked, a map rotated by 116.6°).
    """
    import math

    from omnical.errors import ConfigError

    parts = [p.strip() for p in text.split(",")]
    yaw_deg = count == 3 and len(parts) == 3 and parts[2].lower().endswith("deg")
    if yaw_deg:
        parts[2] = parts[2][: -len("deg")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        shape = "X,Y" if count == 2 else "X,Y,YAW"
        msg = f"{option}: expected {shape} (finite numbers), got {text!r}"
        raise ConfigError(msg)
    if count == 3:
        values[2] = math.radians(values[2]) if yaw_deg else check_yaw_rad(values[2], option)
    return tuple(values)


def check_yaw_rad(yaw_rad: float, option: str) -> float:
    """``yaw_rad`` if it is within ±2π, else a ConfigError saying it looks like degrees."""
    import math

    from omnical.errors import ConfigError

    if abs(yaw_rad) > 2.0 * math.pi:
        msg = (
            f"{option}: a yaw of {yaw_rad:g} rad is more than a full turn: give radians "
            f"(e.g. {math.radians(yaw_rad):.4g}) or degrees with a suffix ({yaw_rad:g}deg)"
        )
        raise ConfigError(msg)
    return yaw_rad


def check_inside(grid: OccupancyGrid, option: str, xy: tuple[float, ...], map_name: object) -> None:
    """A point of ``option`` lies on the map, else a ConfigError naming the option (exit 2)."""
    import numpy as np

    from omnical.errors import ConfigError

    cell = grid.world_to_cell(np.array(xy[:2], dtype=np.float64).reshape(1, 2))
    if not bool(grid.in_bounds(cell)[0]):
        msg = f"{option} {xy[0]:g},{xy[1]:g}: outside the map {map_name}"
        raise ConfigError(msg)


def plan(
    map_yaml: Annotated[
        Path,
        typer.Argument(
            metavar="MAP", help="map_server map (YAML + PGM), or a shipped world (lab-8x6)."
        ),
    ],
    from_xy: Annotated[str, typer.Option("--from", metavar="X,Y", help="Start, in metres.")],
    to_xy: Annotated[str, typer.Option("--to", metavar="X,Y", help="Goal, in metres.")],
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", help="Path CSV to write (x_m,y_m); the figure goes beside it (PATH.png)."
        ),
    ],
    nodes: Annotated[
        int, typer.Option(help=f"PRM nodes (mobileRobotPRM NumNodes), 0 to {MAX_NODES}.")
    ] = 1000,
    connection_distance: Annotated[
        float, typer.Option(help="PRM ConnectionDistance, m (> 0).")
    ] = 3.0,
    seed: Seed = 0,
    inscribed: Annotated[
        bool,
        typer.Option(
            "--inscribed", help="Inflate by the inscribed radius (default: circumscribed)."
        ),
    ] = False,
    robot: Robot = "rosy-mecanum",
    overwrite: Overwrite = False,
) -> None:
    """Plan a path from --from to --to on a map inflated by the robot's footprint.

    Status ok, start_in_collision, goal_in_collision or no_path (exit 3).
    """
    with handled_errors():
        import numpy as np

        from omnical.cli.errors import EXIT_NO_RESULT
        from omnical.cli.output import tell
        from omnical.cli.robot_target import load_said_robot
        from omnical.errors import ConfigError, OutputError
        from omnical.navigation.inflation import inflate
        from omnical.navigation.map_io import load_map
        from omnical.navigation.prm import PlanParams, PrmParams, build_roadmap
        from omnical.navigation.prm import plan as plan_path
        from omnical.reports.navigation import plan_output_paths, write_plan_figure
        from omnical.reports.outputs import csv_with_header, is_figure, stage_files
        from omnical.services.navigation import resolve_world, robot_footprint

        if not 0 <= nodes <= MAX_NODES:
            msg = f"--nodes: must be 0 to {MAX_NODES}, got {nodes}"
            raise ConfigError(msg)
        if not connection_distance > 0.0:
            msg = f"--connection-distance: must be > 0 m, got {connection_distance}"
            raise ConfigError(msg)
        if out.suffix.lower() == ".png":
            msg = f"--out {out}: give the path's CSV file (PATH.csv; its figure is PATH.png)"
            raise ConfigError(msg)
        paths = plan_output_paths(out)
        csv_file = csv_with_header("x_m,y_m")
        outputs = stage_files(
            [paths["csv"], paths["png"]],
            overwrite=overwrite,
            recognise=lambda p: is_figure(p) if p.name == paths["png"].name else csv_file(p),
            notify=tell,
        )
        start = np.array(parse_xy(from_xy, "--from"))
        goal = np.array(parse_xy(to_xy, "--to"))
        grid = load_map(resolve_world(map_yaml))
        check_inside(grid, "--from", tuple(start), map_yaml)
        check_inside(grid, "--to", tuple(goal), map_yaml)
        description = load_said_robot(robot)
        footprint = robot_footprint(description)
        kind: Literal["inscribed", "circumscribed"] = "inscribed" if inscribed else "circumscribed"
        infl = inflate(grid, footprint=footprint, radius=kind)
        say(
            f"footprint {footprint.length_m:g} m x {footprint.width_m:g} m: obstacles inflated by "
            f"its {kind} radius {infl.radius_m:.3f} m"
        )
        params = PlanParams(PrmParams(nodes, connection_distance, seed))
        # the roadmap the planner would build, built here to be drawn (not when it is not needed)
        roadmap = (
            None
            if infl.blocked_at(np.stack([start, goal])).any()
            else build_roadmap(infl, params.prm)
        )
        result = plan_path(infl, start, goal, params, roadmap=roadmap)
        if result.status != "ok":
            say(f"{result.status}: {result.reason}")
            raise typer.Exit(EXIT_NO_RESULT)
        lines = ["x_m,y_m"] + [f"{float(x)!r},{float(y)!r}" for x, y in result.path_m]
        summary = f"{result.path_m.shape[0]} way-points, {result.length_m:.2f} m"
        with outputs.staged(tell) as (csv_path, png_path):
            try:
                csv_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
            except OSError as err:
                msg = f"{paths['csv']}: cannot write: {err.strerror or err}"
                raise OutputError(msg) from None
            write_plan_figure(
                png_path,
                inflated=infl,
                start=start,
                goal=goal,
                result=result,
                roadmap=roadmap,
                title=(
                    f"plan on {map_yaml.name} for {description.name} (inflated by "
                    f"{infl.radius_m:.2f} m): {result.method}, {summary}"
                ),
            )
        say(f"ok ({result.method}): {summary}; wrote {paths['csv']}, {paths['png']}")
