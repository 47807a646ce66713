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
from omnical.cli.output import say

if TYPE_CHECKING:
    from omnical.ips.solve.noise_model import NoiseModel
    from omnical.reports.locate import Located

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
        located = _locate_and_write(
            run, out, chosen, plot, beacons, hedge_z, sigma_m, not no_self_calibration, overwrite
        )
    if located.not_plausible:
        typer.echo(f"omnical: {located.not_plausible}", err=True)
        raise typer.Exit(EXIT_NO_RESULT)
    if located.poor:
        typer.echo(
            f"omnical: warning: only {100.0 * located.usable_fraction:.1f} % of the fixes are "
            "usable (ok or degraded); see the reason column of the CSV",
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
) -> Located:
    """Locate ``run`` (:func:`~omnical.reports.locate.locate_bag`), write the CSV (and the
    figure); the fixes, checked."""
    from omnical.cli.output import voice
    from omnical.ips.from_recording import FIXES_CSV_HEADER, status_summary, write_fixes_csv
    from omnical.reports.locate import locate_bag
    from omnical.reports.outputs import claim_files, csv_with_header

    (target,) = claim_files([out], overwrite=overwrite, recognise=csv_with_header(FIXES_CSV_HEADER))
    if plot is not None:
        claim_files([plot], overwrite=overwrite)
    located = locate_bag(
        run,
        method=method,
        beacons=beacons,
        hedge_z_m=hedge_z,
        sigma_m=sigma_m,
        self_calibrate=self_calibrate,
        vendor=plot is not None,
        voice=voice(),
    )
    _say_learnt(located.fixes.notes, located.fixes.noise)
    # Written to a file beside ``out`` that replaces it once complete (an interrupted run
    # leaves ``out`` as it was).
    with _replacing(out, target) as partial:
        write_fixes_csv(located.fixes, partial)
    say(f"wrote {out}: {status_summary(located.fixes)[0]}")
    if plot is not None:
        located.plot(plot)
        say(f"wrote {plot}")
    return located


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
