"""Kinematics: Jacobians from wheel geometry and the seven-factor correction model."""
