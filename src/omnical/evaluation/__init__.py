"""Evaluation: association, alignment and error measures of trajectories.

``association`` (the reference at the estimate's times), ``alignment`` (none, origin, SE(2)),
``metrics`` (seed 000 Table 4, on arrays or a recording; the odometry against ground truth).
"""
