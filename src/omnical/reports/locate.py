"""``omnical locate``'s work on one recording, for the command and ``fleet locate``: its three
topics read, the fixes solved and checked (:func:`locate_bag`), their figure (:class:`Located`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final

from omnical.bags.bag import read_bag
from omnical.errors import RecordingError
from omnical.ips import from_recording
from omnical.ips.beacons import BeaconMap, load_beacon_map
from omnical.ips.plausibility import implausible_fixes, implausible_height
from omnical.ips.solve.fixes import Fixes
from omnical.recording.topics import BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG
from omnical.services.voice import SILENT, Voice

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from omnical.choices import LocateMethod

__all__ = ["POOR_BELOW", "Located", "locate_bag"]

POOR_BELOW: Final = 0.5
"""Fixes of which a smaller fraction is usable (ok or degraded) are poor: ``omnical locate``
exits 3 unless ``--allow-poor``; ``fleet locate``'s row is an error."""


@dataclass(frozen=True)
class Located:
    """A recording located as ``omnical locate`` locates it.

    Attributes:
        fixes: one per burst; beacons: the map they are in.
        usable_fraction: the fraction of the fixes that are ok or degraded (0 without fixes).
        not_plausible: why the fixes are not plausible, as ``omnical locate`` says it ("" if
            they are: :func:`~omnical.ips.plausibility.implausible_fixes`).
        title: the figure's; vendor_xy: the vendor's positions drawn beside the fixes (None
            unless asked for).
    """

    fixes: Fixes
    beacons: BeaconMap
    usable_fraction: float
    not_plausible: str
    title: str
    vendor_xy: NDArray[np.float64] | None

    @property
    def poor(self) -> bool:
        """Whether fewer than :data:`POOR_BELOW` of the fixes are usable."""
        return self.usable_fraction < POOR_BELOW

    def plot(self, path: Path) -> None:
        """Draw the fixes over the beacon map, the vendor's beside them, into ``path`` (PNG)."""
        from omnical.reports.figures.ips import plot_fixes

        plot_fixes(self.fixes, self.beacons, path, vendor_xy=self.vendor_xy, title=self.title)


def locate_bag(
    bag: Path,
    *,
    method: LocateMethod,
    beacons: Path | None,
    hedge_z_m: float | None,
    sigma_m: float | None,
    self_calibrate: bool,
    vendor: bool = False,
    voice: Voice = SILENT,
) -> Located:
    """Read what locate needs of ``bag``, solve it with ``method`` and check the fixes against
    ``hedge_z_m`` and ``sigma_m`` (the options of ``omnical locate``; ``beacons``: a beacon
    map YAML, None for the recording's); ``vendor``: keep the vendor's positions for the
    figure; ``voice``: the spinner while solving.

    Raises:
        RecordingError, ConfigError: as :func:`~omnical.ips.from_recording.locate`.
    """
    # Ranges, the beacon map and the vendor positions (hedgehog height, plot): nothing else.
    loaded = [read_bag(bag, (BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG))]
    if not loaded[0].has(BEACON_RAW_DISTANCE) or not len(loaded[0].topic(BEACON_RAW_DISTANCE)):
        dropped = [n for n in loaded[0].notes if n.startswith(f"{BEACON_RAW_DISTANCE}:")]
        if dropped:  # every one of them unusable: not "no messages"
            raise RecordingError(f"{bag.name}: nothing to multilaterate: {dropped[0]}")
        raise RecordingError(f"{bag.name}: {from_recording.no_ranges_error()}")
    for note in loaded[0].notes:  # rows dropped as unusable, said as evaluate and export do
        voice.warn(note)
    vendor_xy = None
    if vendor:
        from omnical.reports.figures.ips import vendor_positions

        vendor_xy = vendor_positions(loaded[0])
    bmap = load_beacon_map(beacons) if beacons is not None else None
    height = implausible_height(loaded[0], bmap, hedge_z_m) if hedge_z_m is not None else []
    with voice.status(f"multilaterating ({method})"):
        # The recording is handed over, not kept: its raw-distance columns are freed once
        # the fixes are grouped, before the solving (the peak of a long run).
        fixes, used_map = from_recording.locate(
            loaded.pop(),
            beacons=bmap,
            method=method,
            hedge_z_m=hedge_z_m,
            range_sigma_m=sigma_m,
            self_calibrate=self_calibrate,
        )
    implausible = implausible_fixes(fixes, used_map, hedge_z_m, sigma_m, height)
    not_plausible = f"the fixes are not plausible: {'; '.join(implausible)}" if implausible else ""
    usable = from_recording.status_summary(fixes)[1]
    title = f"{bag.name}: {method} multilateration"
    return Located(fixes, used_map, usable, not_plausible, title, vendor_xy)
