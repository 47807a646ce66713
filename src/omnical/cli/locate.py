"""``omnical locate``: multilaterate the raw distances of a recording, one fix per burst."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import LocateMethod, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import choice_metavar
from omnical.cli.output import console, say

if TYPE_CHECKING:
    from omnical.ips.beacons import BeaconMap
    from omnical.ips.solve import Fixes
    from omnical.recording.recording import Recording

__all__ = ["locate"]


def locate(
    run: Annotated[Path, typer.Argument(help="Recording with /beacon_raw_distance.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Fixes CSV to write.")],
    method: Annotated[
        str,
        typer.Option(
            metavar=choice_metavar(LocateMethod),
            help="robust (least squares, NLOS ranges rejected), lsq (plain least squares) "
            "or grid (seed 000's 1 mm search).",
        ),
    ] = LocateMethod.ROBUST.value,
    plot: Annotated[Path | None, typer.Option(help="PNG of the fixes over the beacon map.")] = None,
    beacons: Annotated[
        Path | None, typer.Option(help="Beacon map YAML (default: the recording's).")
    ] = None,
    hedge_z: Annotated[
        float | None, typer.Option(help="Hedgehog height, m (default: map or vendor).")
    ] = None,
) -> None:
    """Multilaterate every raw-distance burst of a recording, with a confidence for each fix."""
    with handled_errors():
        chosen = parse_choice(LocateMethod, method, "--method")
        _locate_and_write(run, out, chosen, plot, beacons, hedge_z)


def _locate_and_write(
    run: Path,
    out: Path,
    method: LocateMethod,
    plot: Path | None,
    beacons: Path | None,
    hedge_z: float | None,
) -> None:
    from omnical.ips.beacons import load_beacon_map
    from omnical.ips.from_recording import locate as locate_fixes
    from omnical.ips.from_recording import write_fixes_csv
    from omnical.ips.solve import FixStatus
    from omnical.recording.bag import read_bag
    from omnical.recording.topics import BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG

    # Ranges, the beacon map and the vendor positions (hedgehog height, plot): nothing else.
    recording = read_bag(run, (BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG))
    bmap = load_beacon_map(beacons) if beacons is not None else None
    with console().status(f"multilaterating ({method})"):
        fixes, used_map = locate_fixes(recording, beacons=bmap, method=method, hedge_z_m=hedge_z)
    write_fixes_csv(fixes, out)
    counts = {s.name.lower(): int((fixes.status == s).sum()) for s in FixStatus}
    say(f"wrote {out}: {len(fixes)} fixes " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if plot is not None:
        _plot_fixes(recording, fixes, used_map, plot, f"{run.name}: {method} multilateration")
        say(f"wrote {plot}")


def _plot_fixes(
    recording: Recording, fixes: Fixes, beacons: BeaconMap, png: Path, title: str
) -> None:
    """The one call into :mod:`omnical.reports.figures` of ``omnical locate``."""
    import numpy as np

    from omnical.reports.figures.ips import plot_fixes

    vendor = None
    if recording.has("/hedge_pos_ang"):
        pos = recording.topic("/hedge_pos_ang")
        ok = (pos["flags"] & 1) == 0
        vendor = np.column_stack([pos["x_m"][ok], pos["y_m"][ok]])
    plot_fixes(fixes, beacons, png, vendor_xy=vendor, title=title)
