"""Options of the commands that drive a real robot (run, navigate, calibrate campaign).

Declared once so that they read the same everywhere; defaults stay at the use site
(``baud: Baud = 115200``). :class:`LiveOptions` carries them from the command to the rig.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, TypeAlias

import typer

if TYPE_CHECKING:
    from omnical.drivers.safety import Area
    from omnical.ips.beacons import BeaconMap

__all__ = [
    "MAX_HOST_WATCHDOG_S",
    "AreaOption",
    "Baud",
    "HedgeBaud",
    "HostWatchdog",
    "LiveOptions",
    "MapBeacons",
    "Margin",
    "Model",
    "RobotOption",
    "StartYaw",
    "TimeScale",
    "Yes",
]

RobotOption: TypeAlias = Annotated[
    str,
    typer.Option(
        help="'twin' (in-process), 'serial:PORT' (vehicle controller), 'ros2' (the robot's "
        "ROS 2 topics), or a preset / robot YAML (that robot's in-process twin)."
    ),
]
Model: TypeAlias = Annotated[
    str | None,
    typer.Option(
        help="Robot preset (rosy-mecanum, omni-x) or robot YAML, with --robot twin, "
        "serial:PORT or ros2 (default rosy-mecanum)."
    ),
]
MapBeacons: TypeAlias = Annotated[
    str | None,
    typer.Option(help="Beacon map YAML or 'default' (a real robot: else the streamed map)."),
]
Baud: TypeAlias = Annotated[int, typer.Option(help="Vehicle controller baud rate (serial).")]
HedgeBaud: TypeAlias = Annotated[int, typer.Option(help="Hedgehog baud rate (serial).")]
Margin: TypeAlias = Annotated[
    float,
    typer.Option(
        help="Required margin inside the beacon coverage / --area, m (a live robot; negative: "
        "allowed that far outside)."
    ),
]
AreaOption: TypeAlias = Annotated[
    str | None, typer.Option(help="Allowed area 'x0,y0,x1,y1' in the map, m (serial).")
]


def map_beacons(beacons: str | None) -> BeaconMap | None:
    """``--beacons``: the map of a YAML file, seed 000's for 'default', None when not given."""
    from omnical.ips.beacons import default_beacon_map, load_beacon_map

    if beacons is None:
        return None
    return default_beacon_map() if beacons == "default" else load_beacon_map(beacons)


def parse_area(area: str | None) -> Area | None:
    """``--area x0,y0,x1,y1`` as an :class:`~omnical.drivers.safety.Area` (None: not given).

    Raises:
        ConfigError: not four numbers.
    """
    import math

    from omnical.drivers.safety import Area
    from omnical.errors import ConfigError

    if area is None:
        return None
    try:
        x0, y0, x1, y1 = (float(v) for v in area.split(","))
    except ValueError:
        msg = f"--area {area!r}: give x0,y0,x1,y1 in metres"
        raise ConfigError(msg) from None
    if not all(math.isfinite(v) for v in (x0, y0, x1, y1)) or x0 == x1 or y0 == y1:
        msg = f"--area {area!r}: give the corners of a rectangle, four finite numbers in metres"
        raise ConfigError(msg)
    return Area(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))


def _parse_yaw(text: str | float) -> float:
    """A heading: radians within ±2π, or degrees with a suffix (``90deg``)."""
    import math

    raw = str(text).strip()
    degrees = raw.lower().endswith("deg")
    try:
        value = float(raw[: -len("deg")] if degrees else raw)
    except ValueError:
        msg = f"{raw!r}: give radians (e.g. 1.571) or degrees with a suffix (90deg)"
        raise typer.BadParameter(msg) from None
    if not math.isfinite(value):
        msg = f"{raw!r} is not a heading"
        raise typer.BadParameter(msg)
    if degrees:
        return math.radians(value)
    if abs(value) > 2.0 * math.pi:
        msg = (
            f"{value:g} rad is more than a full turn: give radians "
            f"(e.g. {math.radians(value):.4g}) or degrees with a suffix ({value:g}deg)"
        )
        raise typer.BadParameter(msg)
    return value


StartYaw: TypeAlias = Annotated[
    float,
    typer.Option(
        help="Robot heading in the map at start: rad, or degrees as 90deg (serial).",
        parser=_parse_yaw,
        metavar="YAW",
    ),
]
HostWatchdog: TypeAlias = Annotated[
    float,
    typer.Option(help="Zero the command if this process stalls this long, s (a live robot; ≤ 10)."),
]
Yes: TypeAlias = Annotated[bool, typer.Option("--yes", "-y", help="Do not ask before moving.")]
TimeScale: TypeAlias = Annotated[
    float,
    typer.Option(
        hidden=True,
        help="Tests only: the host clock against 'twin serve' / 'ros2 twin' --time-scale.",
    ),
]


MAX_HOST_WATCHDOG_S = 10.0
"""The longest ``--host-watchdog``: a host stalled that long leaves the robot on its command."""


@dataclass(frozen=True)
class LiveOptions:
    """The options above as one command gave them (the defaults: none given); only a real
    robot takes them, :meth:`refuse_on_twin` says which the twin refuses."""

    baud: int = 115200
    hedge_baud: int = 115200
    margin_m: float = 0.3
    area: str | None = None
    start_yaw_rad: float = 0.0
    host_watchdog_s: float = 0.5
    yes: bool = False
    time_scale: float = 1.0
    twist_stamped: bool = False

    def __post_init__(self) -> None:
        """Refuse values that would switch a guard off: a NaN ``--margin`` passed every path,
        a NaN ``--host-watchdog`` never tripped (ConfigError naming the option). A negative
        margin is the user's: it allows the path that far outside the coverage."""
        import math

        from omnical.errors import ConfigError

        if not math.isfinite(self.margin_m):
            msg = (
                f"--margin {self.margin_m:g}: give a distance in metres (how far inside the "
                "coverage and --area the path must stay; negative: how far outside it may go)"
            )
            raise ConfigError(msg)
        if not 0.0 < self.host_watchdog_s <= MAX_HOST_WATCHDOG_S:
            msg = (
                f"--host-watchdog {self.host_watchdog_s:g}: give seconds above 0 and at most "
                f"{MAX_HOST_WATCHDOG_S:g} (the robot drives on its last command that long)"
            )
            raise ConfigError(msg)

    @property
    def allowed(self) -> Area | None:
        """``--area`` parsed (ConfigError: not a rectangle)."""
        return parse_area(self.area)

    def refuse_on_twin(self, twin: str = "the twin") -> None:
        """Refuse ``--area`` and ``--time-scale``, which guard or pace a real robot only
        (``twin``: how the message names the twin).

        Raises:
            ConfigError: either was given.
        """
        from omnical.errors import ConfigError

        if self.time_scale != 1.0:
            msg = (
                "--time-scale applies to a live robot only (tests: against 'omnical twin serve' "
                "or 'omnical ros2 twin')"
            )
            raise ConfigError(msg)
        if self.area is not None:
            msg = f"--area guards a real robot's motion: it does not apply to {twin}"
            raise ConfigError(msg)


def check_can_confirm(yes: bool) -> None:
    """Refuse before any work when the first motion would need a confirmation nobody can give.

    Raises:
        ConfigError: no ``--yes`` and standard input is not a terminal.
    """
    import sys

    from omnical.errors import ConfigError

    if not yes and not sys.stdin.isatty():
        msg = "no terminal to confirm the first motion on: add --yes to run unattended"
        raise ConfigError(msg)


ABORT_KEYS_TEXT = "Ctrl-C, space, q or Esc stops it"
"""What the confirmation prompts say stops a run (services.hil.ABORT_KEYS and Ctrl-C)."""


def confirm_first_motion(question: str, yes: bool) -> bool:
    """Ask ``question`` before a robot's first motion (``--yes``: do not ask); False, with a
    line saying the robot did not move, when the answer is no."""
    from omnical.cli.output import say

    check_can_confirm(yes)
    if yes or typer.confirm(question):
        return True
    say("not run: the robot did not move")
    return False
