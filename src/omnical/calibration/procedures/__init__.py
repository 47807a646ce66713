"""Seed 000's calibration procedures: their motion scripts, and the analysis of their recordings
(tracks, headings, the translation and rotation procedures, the factors they give)."""
