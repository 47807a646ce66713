"""A* on an 8-connected grid (numba): the PRM's fallback for narrow passages and its reference.

No corner cutting; the octile heuristic makes the path optimal on the grid, and ties broken by
push order make it the same every time.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["astar_grid", "path_length"]


@numba.njit(cache=True)
def _push(keys: NDArray[np.float64], vals: NDArray[np.int64], size: int, k: float, v: int) -> int:
    i = size
    keys[i] = k
    vals[i] = v
    while i > 0:
        parent = (i - 1) // 2
        if keys[parent] <= keys[i]:
            break
        keys[parent], keys[i] = keys[i], keys[parent]
        vals[parent], vals[i] = vals[i], vals[parent]
        i = parent
    return size + 1


@numba.njit(cache=True)
def _pop(keys: NDArray[np.float64], vals: NDArray[np.int64], size: int) -> tuple[int, int]:
    top = vals[0]
    size -= 1
    keys[0] = keys[size]
    vals[0] = vals[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        child = left
        if left + 1 < size and keys[left + 1] < keys[left]:
            child = left + 1
        if keys[i] <= keys[child]:
            break
        keys[child], keys[i] = keys[i], keys[child]
        vals[child], vals[i] = vals[i], vals[child]
        i = child
    return top, size


@numba.njit(cache=True)
def _astar(blocked: NDArray[np.bool_], sr: int, sc: int, gr: int, gc: int) -> NDArray[np.int64]:
    rows, cols = blocked.shape
    n = rows * cols
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    cap = 8 * n + 8
    keys = np.empty(min(cap, 1 << 24))
    vals = np.empty(keys.shape[0], dtype=np.int64)
    start = sr * cols + sc
    goal = gr * cols + gc
    g[start] = 0.0
    size = _push(keys, vals, 0, 0.0, start)
    dr = np.array([1, -1, 0, 0, 1, 1, -1, -1])
    dc = np.array([0, 0, 1, -1, 1, -1, 1, -1])
    sqrt2 = math.sqrt(2.0)
    found = False
    while size > 0:
        cur, size = _pop(keys, vals, size)
        if closed[cur]:
            continue
        closed[cur] = True
        if cur == goal:
            found = True
            break
        r = cur // cols
        c = cur - r * cols
        for k in range(8):
            nr = r + dr[k]
            nc = c + dc[k]
            if nr < 0 or nc < 0 or nr >= rows or nc >= cols or blocked[nr, nc]:
                continue
            if k >= 4:
                if blocked[r, nc] or blocked[nr, c]:
                    continue
                step = sqrt2
            else:
                step = 1.0
            nxt = nr * cols + nc
            if closed[nxt]:
                continue
            cost = g[cur] + step
            if cost < g[nxt]:
                g[nxt] = cost
                parent[nxt] = cur
                ar = abs(nr - gr)
                ac = abs(nc - gc)
                h = max(ar, ac) + (sqrt2 - 1.0) * min(ar, ac)
                if size >= keys.shape[0]:
                    grown_k = np.empty(2 * keys.shape[0])
                    grown_v = np.empty(2 * keys.shape[0], dtype=np.int64)
                    grown_k[:size] = keys[:size]
                    grown_v[:size] = vals[:size]
                    keys = grown_k
                    vals = grown_v
                size = _push(keys, vals, size, cost + h * (1.0 + 1e-9), nxt)
    if not found:
        return np.empty((0, 2), dtype=np.int64)
    count = 0
    cur = goal
    while cur != -1:
        count += 1
        cur = parent[cur]
    out = np.empty((count, 2), dtype=np.int64)
    cur = goal
    for i in range(count - 1, -1, -1):
        out[i, 0] = cur // cols
        out[i, 1] = cur - (cur // cols) * cols
        cur = parent[cur]
    return out


def astar_grid(
    blocked: NDArray[np.bool_], start_rc: tuple[int, int], goal_rc: tuple[int, int]
) -> NDArray[np.int64]:
    """The optimal 8-connected path of cells (K, 2) (row, col) from start to goal; (0, 2) if none.

    Start and goal must be free cells inside the grid (else no path).
    """
    b = np.ascontiguousarray(blocked, dtype=np.bool_)
    rows, cols = b.shape
    for r, c in (start_rc, goal_rc):
        if not (0 <= r < rows and 0 <= c < cols) or b[r, c]:
            return np.empty((0, 2), dtype=np.int64)
    return np.asarray(
        _astar(b, int(start_rc[0]), int(start_rc[1]), int(goal_rc[0]), int(goal_rc[1]))
    )


def path_length(points: NDArray[np.float64]) -> float:
    """Length of a polyline (K, 2); 0 for fewer than two points."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[0] < 2:
        return 0.0
    return float(np.hypot(*np.diff(p, axis=0).T).sum())
