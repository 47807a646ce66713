"""Shared fixtures: the shipped worlds (skipped when absent) and small synthetic maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omnical.navigation.grid import OccupancyGrid

WORLDS = Path(__file__).parents[2].parent / "shared" / "worlds"


def world_yaml(name: str) -> Path:
    path = WORLDS / f"{name}.yaml"
    if not path.is_file():
        pytest.skip(f"{path} not available")
    return path


def room(rows: int = 60, cols: int = 80, res: float = 0.05) -> OccupancyGrid:
    """A walled room with a block in the middle and a wall with a door."""
    occ = np.zeros((rows, cols), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[20:30, 20:30] = True
    occ[:, 55] = True
    occ[40:48, 55] = False
    return OccupancyGrid.from_occupied(occ, res, (-1.0, -0.5, 0.0))
