"""Trajectories: timing profiles, the seeds' reference paths and open-loop feed-forward commands."""
