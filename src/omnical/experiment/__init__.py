"""Experiments: the Robot/Clock ports, motion scripts and the Runner."""
