"""Estimation: planar poses, odometry + IPS fusion, and seed 003's dead-wheel odometry."""
