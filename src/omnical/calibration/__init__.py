"""Calibration: geometric fits, segmentation, the procedures of seed 000 §3.2 and their analyses."""
