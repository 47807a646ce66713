from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.navigation.grid import OccupancyGrid
from omnical.navigation.inflation import Footprint
from omnical.twin.lidar import Lidar, LidarParams, scan_points, simulate_scans
from omnical.twin.world import World


def _box() -> OccupancyGrid:
    occ = np.zeros((200, 300), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return OccupancyGrid.from_occupied(occ, 0.02)


def test_ideal_ranges_hit_the_walls() -> None:
    lid = Lidar(_box(), LidarParams.ideal(beams=4, angle_min_rad=0.0))
    r = lid.scan(np.array([3.0, 2.0, 0.0]))
    # walls' inner faces: x = 0.02 and 5.98, y = 0.02 and 3.98
    np.testing.assert_allclose(r, [2.98, 1.98, 2.98, 1.98], atol=1e-9)


def test_mount_pose_and_points() -> None:
    params = LidarParams.ideal(beams=4, angle_min_rad=0.0, mount_pose=(0.1, 0.0, math.pi / 2))
    lid = Lidar(_box(), params)
    r = lid.scan(np.array([3.0, 2.0, 0.0]))
    assert r[0] == pytest.approx(1.98)  # first beam looks along +y of the world
    pts = scan_points(r, params)
    np.testing.assert_allclose(pts[0], [0.1, 1.98], atol=1e-9)


def test_noise_dropouts_and_rate() -> None:
    t = np.linspace(0.0, 2.0, 101)
    poses = np.column_stack([3.0 + 0.1 * t, 2.0 + 0 * t, 0.2 * t])
    scans = simulate_scans(t, poses, _box(), LidarParams(rate_hz=5.5, dropout_probability=0.05))
    assert len(scans) == 12 and scans.ranges_m.shape == (12, 360)
    assert 0.03 < np.isnan(scans.ranges_m).mean() < 0.07
    ideal = Lidar(_box(), LidarParams.ideal()).true_ranges(scans.true_pose)
    ok = np.isfinite(scans.ranges_m)
    assert np.std(scans.ranges_m[ok] - ideal[ok]) == pytest.approx(0.01, rel=0.15)
    again = simulate_scans(t, poses, _box(), LidarParams(rate_hz=5.5, dropout_probability=0.05))
    np.testing.assert_array_equal(scans.ranges_m, again.ranges_m)


def test_no_return_is_inf() -> None:
    lid = Lidar(_box(), LidarParams.ideal(range_max_m=1.0))
    assert np.isinf(lid.scan(np.array([3.0, 2.0, 0.0]))).all()


def test_bad_params() -> None:
    with pytest.raises(ConfigError, match="dropout"):
        LidarParams(dropout_probability=1.5)
    with pytest.raises(ConfigError, match="range"):
        LidarParams(range_min_m=5.0, range_max_m=1.0)


def test_world_collision() -> None:
    world = World(_box(), Footprint(0.6, 0.4), "box")
    assert not world.collides((3.0, 2.0, 0.0))
    assert world.collides((0.3, 2.0, 0.0))  # front/back half-length 0.3 reaches the wall cell
    assert not world.collides((0.35, 2.0, 0.0))
    assert world.collides((0.35, 2.0, math.pi / 4))  # turning swings the corners into the wall
    assert "collision" in world.collision_message((0.3, 2.0, 0.0))
    assert world.min_clearance_m(np.array([[3.0, 2.0, 0.0]])) == pytest.approx(1.78, abs=0.015)
