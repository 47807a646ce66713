"""Navigation (seed 001 §4.2.3): occupancy grids and map_server maps, ray casting, inflation,
PRM and A* planning, scan matching, pose graph SLAM.

Pure numerics (numpy, scipy, numba, gtsam); the only file I/O is :mod:`.map_io`.
"""
