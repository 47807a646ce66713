"""``omnical plan``: plan a path on a map_server map (PRM, A* fallback, shortcutting)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite
from omnical.cli.output import say

__all__ = ["parse_xy", "plan"]


def parse_xy(text: str, option: str, count: int = 2) -> tuple[float, ...]:
    """``"X,Y"`` (or ``"X,Y,YAW"`` with ``count=3``) → floats; a ConfigError names the option."""
    import math

    from omnical.errors import ConfigError

    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        shape = "X,Y" if count == 2 else "X,Y,YAW"
        msg = f"{option}: expected {shape} (finite numbers), got {text!r}"
        raise ConfigError(msg)
    return values


def plan(
    map_yaml: Annotated[
        Path, typer.Argument(help="map_server map (YAML + PGM), or a shipped world (lab-8x6).")
    ],
    from_xy: Annotated[str, typer.Option("--from", help="Start X,Y in metres.")],
    to_xy: Annotated[str, typer.Option("--to", help="Goal X,Y in metres.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Path CSV to write (x_m,y_m).")],
    nodes: Annotated[int, typer.Option(help="PRM nodes (mobileRobotPRM NumNodes).")] = 1000,
    connection_distance: Annotated[float, typer.Option(help="PRM ConnectionDistance, m.")] = 3.0,
    seed: Annotated[int, typer.Option(help="PRM seed.")] = 0,
    inscribed: Annotated[
        bool, typer.Option(help="Inflate by the inscribed radius (default: circumscribed).")
    ] = False,
    overwrite: Overwrite = False,
) -> None:
    """Plan from --from to --to on a map; status ok / start_in_collision / goal_in_collision / no_path."""
    with handled_errors():
        _plan(map_yaml, from_xy, to_xy, out, nodes, connection_distance, seed, inscribed, overwrite)


def _plan(
    map_yaml: Path,
    from_xy: str,
    to_xy: str,
    out: Path,
    nodes: int,
    connection_distance: float,
    seed: int,
    inscribed: bool,
    overwrite: bool,
) -> None:
    import numpy as np

    from omnical.cli.errors import EXIT_NO_RESULT
    from omnical.errors import ConfigError, OutputError
    from omnical.navigation.inflation import inflate
    from omnical.navigation.map_io import load_map
    from omnical.navigation.prm import PlanParams, PrmParams
    from omnical.navigation.prm import plan as plan_path
    from omnical.reports.outputs import claim_files, csv_with_header
    from omnical.services.navigation import resolve_world

    claim_files([out], overwrite=overwrite, recognise=csv_with_header("x_m,y_m"))
    start = np.array(parse_xy(from_xy, "--from"))
    goal = np.array(parse_xy(to_xy, "--to"))
    grid = load_map(resolve_world(map_yaml))
    for option, xy in (("--from", start), ("--to", goal)):
        if not bool(grid.in_bounds(grid.world_to_cell(xy.reshape(1, 2)))[0]):
            msg = f"{option} {xy[0]:g},{xy[1]:g}: outside the map {map_yaml}"
            raise ConfigError(msg)
    infl = inflate(grid, radius="inscribed" if inscribed else "circumscribed")
    result = plan_path(infl, start, goal, PlanParams(PrmParams(nodes, connection_distance, seed)))
    if result.status != "ok":
        say(f"{result.status}: {result.reason}")
        raise typer.Exit(EXIT_NO_RESULT)
    lines = ["x_m,y_m"] + [f"{float(x)!r},{float(y)!r}" for x, y in result.path_m]
    try:
        out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as err:
        msg = f"{out}: cannot write: {err.strerror or err}"
        raise OutputError(msg) from None
    say(
        f"ok ({result.method}): {result.path_m.shape[0]} way-points, {result.length_m:.2f} m; "
        f"wrote {out}"
    )
