"""The multilateration figure (seed 000 Figure 15): fixes with confidence ellipses over the beacon map."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import EllipseCollection
from numpy.typing import NDArray

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve import CHI2_2DOF_95, Fixes, FixStatus, ellipses_from_covariances

__all__ = ["plot_fixes"]

_STATUS_STYLE = {
    FixStatus.OK: ("tab:green", "ok"),
    FixStatus.DEGRADED: ("tab:orange", "degraded"),
    FixStatus.REJECTED: ("tab:red", "rejected"),
    FixStatus.DEGENERATE: ("tab:gray", "degenerate"),
}


def plot_fixes(
    fixes: Fixes,
    beacons: BeaconMap,
    path: Path,
    *,
    vendor_xy: NDArray[np.float64] | None = None,
    truth_xy: NDArray[np.float64] | None = None,
    title: str = "multilateration",
    max_ellipses: int = 400,
) -> Path:
    """Draw fixes coloured by status with 95 % confidence ellipses, the vendor's positions beside.

    Args:
        fixes: the multilateration result.
        beacons: the stationary beacons (drawn as labelled triangles).
        path: PNG to write.
        vendor_xy: (N, 2) the vendor's position solution, drawn in blue.
        truth_xy: (N, 2) ground truth (twin only), drawn as a thin black line.
        title: figure title.
        max_ellipses: at most this many ellipses (evenly subsampled) to keep the figure readable.
    """
    fig, ax = plt.subplots(figsize=(9, 7.5))
    b = beacons.positions_m
    ax.scatter(b[:, 0], b[:, 1], marker="^", s=120, c="black", zorder=5, label="stationary beacons")
    for addr, (x, y, _) in zip(beacons.addresses, b, strict=True):
        ax.annotate(str(addr), (x, y), textcoords="offset points", xytext=(6, 6), fontsize=10)
    if truth_xy is not None and len(truth_xy):
        ax.plot(truth_xy[:, 0], truth_xy[:, 1], "-", color="black", lw=0.8, label="ground truth")
    if vendor_xy is not None and len(vendor_xy):
        ax.plot(
            vendor_xy[:, 0],
            vendor_xy[:, 1],
            ".",
            color="tab:blue",
            ms=2.5,
            alpha=0.6,
            label="vendor (Marvelmind)",
        )
    p = fixes.positions_map_m
    finite = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    for status, (color, label) in _STATUS_STYLE.items():
        sel = finite & (fixes.status == status)
        if np.any(sel):
            ax.plot(
                p[sel, 0],
                p[sel, 1],
                ".",
                color=color,
                ms=3,
                label=f"fixes {label} ({int(sel.sum())})",
            )
    usable = finite & (fixes.status <= FixStatus.DEGRADED)
    idx = np.flatnonzero(usable)
    if idx.size:
        idx = idx[:: max(1, idx.size // max_ellipses)]
        ell = ellipses_from_covariances(fixes.covariance_xy_m2[idx], scale=CHI2_2DOF_95)
        coll = EllipseCollection(
            2 * ell.semi_major_m,
            2 * ell.semi_minor_m,
            np.degrees(ell.angle_rad),
            units="xy",
            offsets=p[idx, :2],
            offset_transform=ax.transData,
            facecolors="none",
            edgecolors="tab:green",
            linewidths=0.6,
            alpha=0.7,
        )
        ax.add_collection(coll)
        ax.plot([], [], color="tab:green", lw=0.6, label="95 % confidence ellipses")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x (m, map)")
    ax.set_ylabel("y (m, map)")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8, markerscale=1.5, framealpha=0.9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path
