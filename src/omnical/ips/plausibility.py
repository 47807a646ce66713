"""Whether a recording's fixes are plausible: ``--hedge-z`` against the ranges and the learned
biases, the learned or given range noise. ``omnical locate`` exits 3 on a reason, the fleet
makes it the recording's error row.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from omnical.ips.beacons import BeaconMap
    from omnical.ips.solve.fixes import Fixes
    from omnical.recording.recording import Recording

__all__ = [
    "IMPLAUSIBLE_SIGMA_M",
    "SHORT_RANGES_M",
    "implausible_biases",
    "implausible_fixes",
    "implausible_height",
    "implausible_noise",
]

IMPLAUSIBLE_SIGMA_M = 0.5
"""A learned range σ above this (m) says the ranges do not fit the geometry (height, map, unit)."""


def implausible_height(
    recording: Recording, beacons: BeaconMap | None, hedge_z_m: float
) -> list[str]:
    """``--hedge-z`` against the ranges: a range shorter than the height difference to its
    beacon cannot be (the noise aside); more than 5 % of them say the height is wrong."""
    import numpy as np

    from omnical.ips.from_recording import beacon_map_of
    from omnical.recording.topics import BEACON_RAW_DISTANCE

    if not recording.has(BEACON_RAW_DISTANCE):
        return []
    bmap = beacon_map_of(recording, beacons)
    d = recording.topic(BEACON_RAW_DISTANCE)
    addresses = np.asarray(bmap.addresses)
    index = np.searchsorted(addresses, d["address_beacon"], sorter=np.argsort(addresses))
    order = np.argsort(addresses)
    known = np.isin(d["address_beacon"], addresses)
    beacon_z = np.asarray(bmap.positions_m)[order[np.minimum(index, len(order) - 1)], 2]
    gap = np.abs(hedge_z_m - beacon_z[known])
    short = float(np.mean(np.asarray(d["distance_m"])[known] < gap - 0.1)) if known.any() else 0.0
    if short <= 0.05:
        return []
    lo, hi = float(bmap.positions_m[:, 2].min()), float(bmap.positions_m[:, 2].max())
    why = (
        f"--hedge-z {hedge_z_m:g} m: {short:.0%} of the ranges are shorter than the height "
        f"difference to their beacon (beacons at z {lo:.2f}–{hi:.2f} m)"
    )
    return [why]


SHORT_RANGES_M = 0.05
"""Learned range biases whose median is below minus this (m), most of them negative: the ranges
are shorter than the geometry at the given height predicts, so the height is wrong."""


def implausible_biases(fixes: Fixes, beacons: BeaconMap, hedge_z_m: float) -> list[str]:
    """``--hedge-z`` against the range biases the self-calibration learned with it."""
    import numpy as np

    reasons = []
    for model in fixes.noise:
        bias = np.asarray(model.bias_m)[model.bias_estimated]
        if bias.size < 3:
            continue
        median = float(np.median(bias))
        if median < -SHORT_RANGES_M and np.mean(bias < 0.0) >= 0.75:
            z = np.asarray(beacons.positions_m)[:, 2]
            reasons.append(
                f"--hedge-z {hedge_z_m:g} m: the ranges are shorter than this height predicts "
                f"on {int(np.sum(bias < 0.0))} of {bias.size} links (learned biases "
                f"{100 * bias.min():.1f} to {100 * bias.max():.1f} cm, median "
                f"{100 * median:.1f} cm; a real range is longer, not shorter): the hedgehog is "
                f"nearer the beacons' heights (z {z.min():.2f}–{z.max():.2f} m) than that"
            )
    return reasons


def implausible_noise(fixes: Fixes, sigma_m: float | None) -> list[str]:
    """A learned σ of metres, or a given ``--sigma-m`` far above what the fixes show."""
    import numpy as np

    reasons = []
    worst = max((float(np.max(m.sigma_m)) for m in fixes.noise if len(m.sigma_m)), default=0.0)
    if sigma_m is None and worst > IMPLAUSIBLE_SIGMA_M:
        reasons.append(
            f"a range noise σ of {worst:.2f} m learned from the recording: the ranges do not "
            "fit the beacon map (a wrong --hedge-z, beacon map or unit)"
        )
    residual = fixes.residual_rms_m[np.isfinite(fixes.residual_rms_m)]
    typical = float(np.median(residual)) if residual.size else 0.0
    if sigma_m is not None and typical > 0.0 and sigma_m >= 0.1 and sigma_m > 5.0 * typical:
        reasons.append(
            f"--sigma-m {sigma_m:g} m is {sigma_m / typical:.0f}× the ranges' median residual "
            f"{typical * 100:.1f} cm: every outlier passes as ok (σ is in metres: 2 cm is 0.02)"
        )
    return reasons


def implausible_fixes(
    fixes: Fixes,
    beacons: BeaconMap,
    hedge_z_m: float | None,
    sigma_m: float | None,
    height: Sequence[str] = (),
) -> list[str]:
    """Every reason the fixes are not plausible, in ``omnical locate``'s order: ``height``
    (:func:`implausible_height`, checked on the recording before it was solved), the noise,
    then, with ``--hedge-z``, the learned biases; empty when they are."""
    reasons = list(height) + implausible_noise(fixes, sigma_m)
    if hedge_z_m is not None:
        reasons += implausible_biases(fixes, beacons, hedge_z_m)
    return reasons
