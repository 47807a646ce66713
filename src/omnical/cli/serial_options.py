"""Options of the commands that drive a robot over serial ports (``run``, ``navigate``,
``calibrate campaign``), declared once so that they read the same everywhere.

Defaults stay at the use site (``baud: Baud = 115200``); the wording says what applies only to a
serial robot.
"""

from __future__ import annotations

from typing import Annotated, TypeAlias

import typer

__all__ = [
    "AreaOption",
    "Baud",
    "HedgeBaud",
    "HostWatchdog",
    "Margin",
    "StartYaw",
    "TimeScale",
    "Yes",
]

Baud: TypeAlias = Annotated[int, typer.Option(help="Vehicle controller baud rate (serial).")]
HedgeBaud: TypeAlias = Annotated[int, typer.Option(help="Hedgehog baud rate (serial).")]
Margin: TypeAlias = Annotated[
    float, typer.Option(help="Required margin inside the beacon coverage / --area, m (serial).")
]
AreaOption: TypeAlias = Annotated[
    str | None, typer.Option(help="Allowed area 'x0,y0,x1,y1' in the map, m (serial).")
]
StartYaw: TypeAlias = Annotated[
    float, typer.Option(help="Robot heading in the map at start, rad (serial).")
]
HostWatchdog: TypeAlias = Annotated[
    float, typer.Option(help="Zero the command if this process stalls this long, s (serial).")
]
Yes: TypeAlias = Annotated[bool, typer.Option("--yes", "-y", help="Do not ask before moving.")]
TimeScale: TypeAlias = Annotated[
    float,
    typer.Option(hidden=True, help="Tests only: the host clock against 'twin serve --time-scale'."),
]
