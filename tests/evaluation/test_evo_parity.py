"""evo_ape on omnical's TUM exports gives omnical's RMSE (runs when evo is installed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from omnical.bags.bag import write_bag
from omnical.bags.export import export_bag_tum, tum_lines
from omnical.evaluation.association import Association
from omnical.evaluation.metrics import estimates_of, reference_of, track
from omnical.recording.recording import Recording

evo_metrics: Any = pytest.importorskip("evo.core.metrics")
evo_sync: Any = pytest.importorskip("evo.core.sync")
file_interface: Any = pytest.importorskip("evo.tools.file_interface")


def write_tum_pair(
    association: Association,
    estimate_path: Path,
    reference_path: Path,
    *,
    estimate_xy_m: np.ndarray | None = None,
) -> tuple[Path, Path]:
    """The associated estimate (or ``estimate_xy_m``) and the interpolated reference as two
    TUM files with the same stamps: evo_ape then compares exactly the pairs omnical compares."""
    t_ns = np.round(association.t_s * 1e9).astype(np.int64)
    xy = association.estimate_xy_m if estimate_xy_m is None else estimate_xy_m
    pairs = (
        (estimate_path, xy, association.estimate_yaw_rad),
        (reference_path, association.reference_xy_m, association.reference_yaw_rad),
    )
    for path, positions, yaw in pairs:
        half = np.zeros(len(t_ns)) if yaw is None else 0.5 * yaw
        rows = np.zeros((len(t_ns), 7))
        rows[:, :2], rows[:, 5], rows[:, 6] = positions, np.sin(half), np.cos(half)
        path.write_text(tum_lines(t_ns, rows), encoding="utf-8")
    return estimate_path, reference_path


def _evo_ape_rmse(ref_path: Path, est_path: Path, align: str) -> float:
    traj_ref = file_interface.read_tum_trajectory_file(str(ref_path))
    traj_est = file_interface.read_tum_trajectory_file(str(est_path))
    traj_ref, traj_est = evo_sync.associate_trajectories(traj_ref, traj_est, max_diff=1e-6)
    if align == "se2":
        traj_est.align(traj_ref, correct_scale=False)
    elif align == "origin":
        traj_est.align_origin(traj_ref)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((traj_ref, traj_est))
    return float(ape.get_statistic(evo_metrics.StatisticsType.rmse))


@pytest.mark.parametrize("align", ["origin", "se2", "none"])
def test_recording_tum_export_odometry(default_tour: Recording, tmp_path: Path, align: str) -> None:
    # /odom and /ground_truth share their time stamps on the twin: evo's time matching pairs
    # exactly the samples omnical interpolates at (interpolation at a sample is the sample)
    bag = write_bag(default_tour, tmp_path / "tour")
    files = {p.name: p for p in export_bag_tum(bag, tmp_path / "tum").written}
    ours = track(
        estimates_of(default_tour, names=("odometry",))["odometry"],
        reference_of(default_tour),
        align_mode=align,  # type: ignore[arg-type]
    ).metrics
    theirs = _evo_ape_rmse(files["ground_truth.tum"], files["odom.tum"], align)
    assert ours.rmse_m > 0.1  # uncalibrated: a real comparison, not 0 = 0
    assert theirs == pytest.approx(ours.rmse_m, abs=1e-6)


@pytest.mark.parametrize("align", ["se2", "none"])
def test_associated_pair_ips(default_tour: Recording, tmp_path: Path, align: str) -> None:
    # vendor IPS at its own times: the reference interpolated at those times is written beside
    # it, so evo matches the same pairs
    tracked = track(
        estimates_of(default_tour, names=("ips",))["ips"],
        reference_of(default_tour),
        align_mode=align,  # type: ignore[arg-type]
    )
    est_path, ref_path = write_tum_pair(
        tracked.association, tmp_path / "ips.tum", tmp_path / "ref.tum"
    )
    theirs = _evo_ape_rmse(ref_path, est_path, align)
    assert theirs == pytest.approx(tracked.metrics.rmse_m, abs=1e-6)
    # already aligned by omnical, no alignment in evo: the same number again
    est_aligned, _ = write_tum_pair(
        tracked.association,
        tmp_path / "ips-aligned.tum",
        tmp_path / "ref2.tum",
        estimate_xy_m=tracked.alignment.xy_m,
    )
    assert _evo_ape_rmse(ref_path, est_aligned, "none") == pytest.approx(
        tracked.metrics.rmse_m, abs=1e-6
    )
