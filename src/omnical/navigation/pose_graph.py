"""A 2D pose graph optimised with gtsam (Levenberg–Marquardt; robust Huber loop closures)."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam  # type: ignore[import-untyped, unused-ignore]
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PoseEdge", "optimize_pose_graph"]


@dataclass(frozen=True)
class PoseEdge:
    """A relative pose constraint ``between(pose_i, pose_j) = relative`` with σ (x, y, yaw).

    ``robust`` edges (loop closures) get a Huber loss.
    """

    i: int
    j: int
    relative: tuple[float, float, float]
    sigmas: tuple[float, float, float]
    robust: bool = False


def optimize_pose_graph(
    initial: ArrayLike,
    edges: list[PoseEdge],
    prior_sigmas: tuple[float, float, float] = (1e-3, 1e-3, 1e-4),
) -> NDArray[np.float64]:
    """Optimise the poses (N, 3) under the edges, with node 0 anchored at its initial value."""
    poses = np.asarray(initial, dtype=np.float64).reshape(-1, 3)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for k, (x, y, th) in enumerate(poses):
        values.insert(k, gtsam.Pose2(float(x), float(y), float(th)))
    if poses.shape[0] == 0:
        return poses.copy()
    graph.add(
        gtsam.PriorFactorPose2(
            0,
            gtsam.Pose2(*(float(v) for v in poses[0])),
            gtsam.noiseModel.Diagonal.Sigmas(np.array(prior_sigmas)),
        )
    )
    for e in edges:
        diagonal = gtsam.noiseModel.Diagonal.Sigmas(np.array(e.sigmas, dtype=np.float64))
        if e.robust:
            robust = gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Huber.Create(1.345), diagonal
            )
            graph.add(gtsam.BetweenFactorPose2(e.i, e.j, gtsam.Pose2(*e.relative), robust))
        else:
            graph.add(gtsam.BetweenFactorPose2(e.i, e.j, gtsam.Pose2(*e.relative), diagonal))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(50)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    out = np.empty_like(poses)
    for k in range(poses.shape[0]):
        p = result.atPose2(k)
        out[k] = (p.x(), p.y(), p.theta())
    return out
