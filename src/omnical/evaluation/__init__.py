"""Evaluation: association, alignment and error measures of trajectories."""

from omnical.evaluation.odometry import OdometryErrors, odometry_vs_ground_truth

__all__ = ["OdometryErrors", "odometry_vs_ground_truth"]
