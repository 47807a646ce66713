"""``omnical locate``: multilaterate the raw distances of a recording, one fix per burst."""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import LocateMethod, parse_choice
from omnical.cli.errors import EXIT_NO_RESULT, handled_errors
from omnical.cli.options import (
    HedgeZ,
    LocateMethodOption,
    NoSelfCalibration,
    Overwrite,
    SigmaM,
)
from omnical.cli.output import console, say

if TYPE_CHECKING:
    from omnical.ips.solve.noise_model import NoiseModel

__all__ = ["EXIT_POOR_FIXES", "locate"]

EXIT_POOR_FIXES = EXIT_NO_RESULT
"""Exit status when fewer than half the fixes are usable (without ``--allow-poor``)."""


def locate(
    run: Annotated[
        Path, typer.Argument(metavar="BAG", help="Recording with /beacon_raw_distance.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Fixes CSV to write.")],
    method: LocateMethodOption = LocateMethod.ROBUST.value,
    plot: Annotated[Path | None, typer.Option(help="PNG of the fixes over the beacon map.")] = None,
    beacons: Annotated[
        Path | None, typer.Option(help="Beacon map YAML (default: the recording's).")
    ] = None,
    hedge_z: HedgeZ = None,
    sigma_m: SigmaM = None,
    no_self_calibration: NoSelfCalibration = False,
    allow_poor: Annotated[
        bool,
        typer.Option("--allow-poor", help="Exit 0 even when fewer than half the fixes are usable."),
    ] = False,
    overwrite: Overwrite = False,
) -> None:
    """Multilaterate every raw-distance burst of a recording, with a confidence for each fix.

    Exit status 3 (after writing the fixes) when fewer than half the fixes are usable (ok or
    degraded), unless --allow-poor, and when the ranges contradict --hedge-z or --sigma-m.
    """
    with handled_errors():
        chosen = parse_choice(LocateMethod, method, "--method")
        if plot is not None and plot.suffix.lower() != ".png":
            from omnical.errors import ConfigError

            msg = f"--plot {plot}: the figure is a PNG; give a file name ending in .png"
            raise ConfigError(msg)
        usable, implausible = _locate_and_write(
            run, out, chosen, plot, beacons, hedge_z, sigma_m, not no_self_calibration, overwrite
        )
    if implausible:
        typer.echo(f"omnical: the fixes are not plausible: {'; '.join(implausible)}", err=True)
        raise typer.Exit(EXIT_NO_RESULT)
    if usable < 0.5:
        typer.echo(
            f"omnical: warning: only {100.0 * usable:.1f} % of the fixes are usable (ok or "
            "degraded); see the reason column of the CSV",
            err=True,
        )
        if not allow_poor:
            raise typer.Exit(EXIT_POOR_FIXES)


def _locate_and_write(
    run: Path,
    out: Path,
    method: LocateMethod,
    plot: Path | None,
    beacons: Path | None,
    hedge_z: float | None,
    sigma_m: float | None,
    self_calibrate: bool,
    overwrite: bool,
) -> tuple[float, list[str]]:
    """Read what locate needs of ``run``, solve it, write the CSV (and the figure); the
    usable fraction of the fixes and why they are not plausible
    (:func:`~omnical.ips.plausibility.implausible_fixes`)."""
    from omnical.bags.bag import read_bag
    from omnical.ips.beacons import load_beacon_map
    from omnical.ips.from_recording import FIXES_CSV_HEADER, status_summary, write_fixes_csv
    from omnical.ips.from_recording import locate as locate_fixes
    from omnical.ips.plausibility import implausible_fixes, implausible_height
    from omnical.recording.topics import BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG
    from omnical.reports.outputs import claim_files, csv_with_header

    (target,) = claim_files([out], overwrite=overwrite, recognise=csv_with_header(FIXES_CSV_HEADER))
    if plot is not None:
        claim_files([plot], overwrite=overwrite)
    # Ranges, the beacon map and the vendor positions (hedgehog height, plot): nothing else.
    loaded = [read_bag(run, (BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG))]
    vendor = None
    if plot is not None:
        from omnical.reports.figures.ips import vendor_positions

        vendor = vendor_positions(loaded[0])
    bmap = load_beacon_map(beacons) if beacons is not None else None
    height = implausible_height(loaded[0], bmap, hedge_z) if hedge_z is not None else []
    with console().status(f"multilaterating ({method})"):
        # The recording is handed over, not kept: its raw-distance columns are freed once
        # the fixes are grouped, before the solving (the peak of a long run).
        fixes, used_map = locate_fixes(
            loaded.pop(),
            beacons=bmap,
            method=method,
            hedge_z_m=hedge_z,
            range_sigma_m=sigma_m,
            self_calibrate=self_calibrate,
        )
    _say_learnt(fixes.notes, fixes.noise)
    # Written to a file beside ``out`` that replaces it once complete (an interrupted run
    # leaves ``out`` as it was).
    with _replacing(out, target) as partial:
        write_fixes_csv(fixes, partial)
    summary, usable = status_summary(fixes)
    say(f"wrote {out}: {summary}")
    if plot is not None:
        from omnical.reports.figures.ips import plot_fixes

        plot_fixes(
            fixes, used_map, plot, vendor_xy=vendor, title=f"{run.name}: {method} multilateration"
        )
        say(f"wrote {plot}")
    return usable, implausible_fixes(fixes, used_map, hedge_z, sigma_m, height)


@contextmanager
def _replacing(out: Path, target: Path) -> Iterator[Path]:
    """A new file beside ``target`` (``out``, or the file a link ``out`` points to, as
    :func:`~omnical.reports.outputs.claim_files` returns it) that replaces it when the block
    ends without an error. A write that fails is reported as the output's.

    Raises:
        OutputError: the file cannot be written or put in place (the disk full, ...).
    """
    from omnical.errors import OmnicalError, OutputError

    partial = target.with_name(f".{target.name}.{os.getpid()}.partial")
    try:
        yield partial
        partial.replace(target)
    except OSError as err:
        if isinstance(err, OmnicalError) or err.filename not in (None, str(partial), str(target)):
            raise  # said already, or another file's (named there)
        msg = f"{out}: cannot write: {err.strerror or err}"
        raise OutputError(msg) from None
    finally:
        partial.unlink(missing_ok=True)


def _say_learnt(notes: Sequence[str], noise: Sequence[NoiseModel]) -> None:
    """Print the locate notes and each hedgehog's learnt noise model: in full for up to
    :data:`_DETAILED_MODELS` hedgehogs, else its summary line only (a hundred hedgehogs'
    links were five hundred lines)."""
    for note in notes:
        say(f"note: {note}")
    detailed = len(noise) <= _DETAILED_MODELS
    for model in noise:
        lines = model.describe()
        for line in lines if detailed else lines[:1]:
            say(line)
    if not detailed:
        say(f"(each link's σ, bias and scale left out for {len(noise)} hedgehogs)")


_DETAILED_MODELS = 8
"""Most hedgehogs whose noise models ``omnical locate`` prints link by link."""
