"""The multilateration figure (seed 000 Figure 15): fixes with confidence ellipses over the beacon map."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import EllipseCollection
from matplotlib.lines import Line2D
from numpy.typing import NDArray

from omnical.ips.beacons import BeaconMap
from omnical.ips.solve.fixes import CHI2_2DOF_95, Fixes, FixStatus, ellipses_from_covariances
from omnical.recording.recording import Recording
from omnical.recording.topics import HEDGE_POS_ANG
from omnical.reports.figures._common import save_figure, wrap_title

__all__ = ["FixesView", "fixes_view", "plot_fixes", "vendor_positions"]

FloatArray = NDArray[np.float64]

_STATUS_STYLE = {
    FixStatus.OK: ("tab:green", "ok"),
    FixStatus.DEGRADED: ("tab:orange", "degraded"),
    FixStatus.REJECTED: ("tab:red", "rejected"),
    FixStatus.DEGENERATE: ("tab:gray", "degenerate"),
}

_OK_ZORDER = 2.0
"""The ok fixes, dense along the path: at matplotlib's default for lines."""
_VENDOR_ZORDER = 2.5
"""The vendor's positions, mostly on the same spots: over the ok fixes (which hid them)."""
_FLAGGED_ZORDER = 3.0
"""Degraded, rejected fixes: few, and what the figure is read for: over the vendor's."""

_MARGIN = 0.04
"""Free border around everything in view, as a fraction of the larger side."""


@dataclass(frozen=True)
class FixesView:
    """The axis limits of the fixes figure and what lies outside them.

    Attributes:
        x_m: (low, high) of the x axis.
        y_m: (low, high) of the y axis.
        outside: number of scattered points (rejected fixes, vendor positions) outside the
            view: they lie further than the map's own size from the beacons and the usable fixes.
    """

    x_m: tuple[float, float]
    y_m: tuple[float, float]
    outside: int


def _bounds(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    ok = np.all(np.isfinite(points), axis=1)
    return points[ok].min(axis=0), points[ok].max(axis=0)


def fixes_view(
    anchors_xy_m: FloatArray,
    halo_lo_m: FloatArray,
    halo_hi_m: FloatArray,
    scattered_xy_m: FloatArray,
) -> FixesView:
    """Limits that hold the beacons, the usable fixes with their ellipses, and the scattered points.

    Args:
        anchors_xy_m: (N, 2) what must be in view: beacons, ground truth, usable fixes.
        halo_lo_m: (M, 2) lower-left corners of the boxes around the ellipses drawn.
        halo_hi_m: (M, 2) their upper-right corners.
        scattered_xy_m: (K, 2) rejected fixes and vendor positions: in view unless further
            than the map's size from the rest (a wild outlier would shrink the map to a dot).
    """
    core = np.concatenate([anchors_xy_m, halo_lo_m, halo_hi_m])
    lo, hi = _bounds(core) if np.any(np.all(np.isfinite(core), axis=1)) else (np.zeros(2),) * 2
    span = max(float(np.max(hi - lo)), 1.0)
    finite = scattered_xy_m[np.all(np.isfinite(scattered_xy_m), axis=1)]
    near = np.all((finite >= lo - span) & (finite <= hi + span), axis=1)
    if np.any(near):
        lo = np.minimum(lo, finite[near].min(axis=0))
        hi = np.maximum(hi, finite[near].max(axis=0))
    pad = _MARGIN * max(float(np.max(hi - lo)), 1e-3)
    return FixesView(
        (float(lo[0] - pad), float(hi[0] + pad)),
        (float(lo[1] - pad), float(hi[1] + pad)),
        int(np.count_nonzero(~near)),
    )


def vendor_positions(recording: Recording) -> FloatArray | None:
    """The vendor's valid positions (x, y) to draw beside the fixes (``vendor_xy``); None
    without ``/hedge_pos_ang``."""
    if not recording.has(HEDGE_POS_ANG):
        return None
    pos = recording.topic(HEDGE_POS_ANG)
    ok = (pos["flags"] & 1) == 0
    return np.column_stack([pos["x_m"][ok], pos["y_m"][ok]])


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

    The legend sits to the right of the map (never over a beacon) and names every status with
    its count, the ones without a position too (degenerate fixes have none). The limits hold
    the beacons, the fixes and their ellipses.

    Args:
        fixes: the multilateration result.
        beacons: the stationary beacons (drawn as labelled triangles).
        path: PNG to write.
        vendor_xy: (N, 2) the vendor's position solution, drawn as blue crosses over the fixes.
        truth_xy: (N, 2) ground truth (twin only), drawn as a thin black line.
        title: figure title.
        max_ellipses: at most this many ellipses (evenly subsampled) to keep the figure readable.
    """
    fig, ax = plt.subplots(figsize=(8, 7.5))
    b = beacons.positions_m
    ax.scatter(b[:, 0], b[:, 1], marker="^", s=120, c="black", zorder=5, label="stationary beacons")
    for addr, (x, y, _) in zip(beacons.addresses, b, strict=True):
        ax.annotate(str(addr), (x, y), textcoords="offset points", xytext=(6, 6), fontsize=10)
    anchors = [b[:, :2]]
    scattered = [np.empty((0, 2))]
    if truth_xy is not None and len(truth_xy):
        ax.plot(truth_xy[:, 0], truth_xy[:, 1], "-", color="black", lw=0.8, label="ground truth")
        anchors.append(truth_xy[:, :2])
    if vendor_xy is not None and len(vendor_xy):
        # thin crosses over the ok fixes, which leave them seen between
        ax.plot(
            vendor_xy[:, 0],
            vendor_xy[:, 1],
            "+",
            color="tab:blue",
            ms=3.5,
            mew=0.5,
            alpha=0.7,
            zorder=_VENDOR_ZORDER,
            label="vendor (Marvelmind)",
        )
        scattered.append(vendor_xy[:, :2])
    p = fixes.positions_map_m
    finite = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    for status, (color, label) in _STATUS_STYLE.items():
        of_status = fixes.status == status
        total = int(of_status.sum())
        if not total:
            continue
        sel = finite & of_status
        missing = total - int(sel.sum())
        text = f"fixes {label} ({total})"
        if missing == total:
            text += ": no position, not drawn"
        elif missing:
            text += f", {missing} without a position (not drawn)"
        zorder = _OK_ZORDER if status == FixStatus.OK else _FLAGGED_ZORDER
        ax.plot(p[sel, 0], p[sel, 1], ".", color=color, ms=3, zorder=zorder, label=text)
        (anchors if status <= FixStatus.DEGRADED else scattered).append(p[sel, :2])
    usable = finite & (fixes.status <= FixStatus.DEGRADED)
    idx = np.flatnonzero(usable)
    halo_lo, halo_hi = np.empty((0, 2)), np.empty((0, 2))
    if idx.size:
        step = max(1, idx.size // max_ellipses)
        idx = idx[::step]
        cov = fixes.covariance_xy_m2[idx]
        ell = ellipses_from_covariances(cov, scale=CHI2_2DOF_95)
        keep = np.isfinite(ell.semi_major_m) & np.isfinite(ell.semi_minor_m)
        idx, cov = idx[keep], cov[keep]
        coll = EllipseCollection(
            2 * ell.semi_major_m[keep],
            2 * ell.semi_minor_m[keep],
            np.degrees(ell.angle_rad[keep]),
            units="xy",
            offsets=p[idx, :2],
            offset_transform=ax.transData,
            facecolors="none",
            edgecolors="tab:green",
            linewidths=0.6,
            alpha=0.7,
        )
        ax.add_collection(coll)
        # the ellipse's half-extent along x and y: sqrt(scale · variance of that axis)
        half = np.sqrt(CHI2_2DOF_95 * np.column_stack([cov[:, 0, 0], cov[:, 1, 1]]))
        halo_lo, halo_hi = p[idx, :2] - half, p[idx, :2] + half
        every = "" if step == 1 else f", every {step}th"
        label = f"95 % confidence ellipses\n(ok and degraded fixes{every})"
        ax.plot([], [], color="tab:green", lw=0.6, label=label)
    view = fixes_view(np.concatenate(anchors), halo_lo, halo_hi, np.concatenate(scattered))
    if view.outside:
        ax.plot([], [], " ", label=f"{view.outside} scattered points outside the view")
    ax.set_xlim(*view.x_m)
    ax.set_ylim(*view.y_m)
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("x (m, map)")
    ax.set_ylabel("y (m, map)")
    ax.set_title(wrap_title(title, 7.0))
    legend = ax.legend(
        loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8, framealpha=0.9
    )
    for handle in legend.legend_handles:
        if isinstance(handle, Line2D) and handle.get_marker() in {".", "+"}:
            handle.set_markersize(8)
    return save_figure(fig, path, dpi=130, tight=False, crop=True)
