"""Entry points: solve a distance matrix, or a whole recording of raw distances, at once."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from typing import Literal, TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.choices import LocateMethod, parse_choice
from omnical.errors import ConfigError
from omnical.ips.beacons import BeaconMap
from omnical.ips.bursts import (
    DEFAULT_MAX_GAP_NS,
    Bursts,
    group_bursts,
    is_sequential,
    sliding_windows,
)
from omnical.ips.solve._fit import (
    Solution,
    SolverOptions,
    chi2_quantile,
    chi2_threshold,
)
from omnical.ips.solve._kernels import Array, RangeProblem, inverse_sym, weighted_cost
from omnical.ips.solve.fixes import Fixes, FixReason, FixStatus, mahalanobis_sq
from omnical.ips.solve.grid import solve_grid
from omnical.ips.solve.linkcov import learn_link_covariance, link_covariances
from omnical.ips.solve.lsq import solve_lsq
from omnical.ips.solve.noise_model import NoiseModel, NoiseSource
from omnical.ips.solve.robust import solve_robust
from omnical.ips.solve.selfcal import learn_links, learn_sigma, linearised_usable

__all__ = [
    "LEARNING_ROUNDS",
    "SEQUENTIAL_NOTE",
    "TRACK_NEIGHBOURS",
    "TRACK_SPAN_NS",
    "MergedFixes",
    "Method",
    "group_ranges",
    "locate_bursts",
    "model_for",
    "off_track",
    "solve_fixes",
    "solve_self_calibrated",
]

Method: TypeAlias = LocateMethod | Literal["robust", "lsq", "grid"]
"""A :class:`~omnical.choices.LocateMethod`, or its value as a plain string."""
_Solver = Callable[[RangeProblem, NDArray[np.bool_], SolverOptions], Solution]
_SOLVERS: dict[LocateMethod, _Solver] = {
    LocateMethod.LSQ: solve_lsq,
    LocateMethod.ROBUST: solve_robust,
    LocateMethod.GRID: solve_grid,
}

SEQUENTIAL_NOTE = (
    "the ranges arrive one per message (round robin): one fix per message from a sliding "
    "window of the latest range of each beacon, at most {age_ms:.0f} ms old"
)
"""The note on fixes from sequential ranges (``age_ms``: the oldest range a window keeps)."""

_DEGENERATE = np.uint16(
    FixReason.TOO_FEW_BEACONS | FixReason.SINGULAR_GEOMETRY | FixReason.UNKNOWN_HEDGE_HEIGHT
)
_DEGRADED = np.uint16(FixReason.AMBIGUOUS_OUTLIER | FixReason.HIGH_RESIDUAL | FixReason.OFF_TRACK)
_BLOCK_DISTANCES = 131_072
_NOT_CONVERGED = np.uint16(FixReason.NOT_CONVERGED)
LEARNING_ROUNDS = 4
"""Robust passes of the self-calibration, each after learning from the previous pass."""
TRACK_NEIGHBOURS = 5
"""Usable fixes of a hedgehog on each side a fix's off-track check compares it with."""
TRACK_SPAN_NS = 1_000_000_000
"""Time on each side of a fix its off-track neighbours are taken from, ns."""
_TRACK_ALPHA = 0.001
_TRACK_CHUNK = 8192
"""Fixes :func:`off_track` takes at a time (each depends only on its window)."""


@dataclass(eq=False)
class _Columns:
    """Output arrays of :class:`Fixes` being filled, or a row-slice view of them."""

    positions_map_m: Array
    covariance_xy_m2: Array
    sigma_z_m: Array
    range_sigma_m: Array
    hdop: Array
    residual_rms_m: Array
    error_eq4_m: Array
    used: NDArray[np.bool_]
    status: NDArray[np.uint8]
    reason: NDArray[np.uint16]

    @classmethod
    def allocate(cls, n: int, m: int) -> _Columns:
        """Allocate for n fixes and m beacons."""
        return cls(
            np.empty((n, 3)),
            np.empty((n, 2, 2)),
            np.empty(n),
            np.empty(n),
            np.empty(n),
            np.empty(n),
            np.empty(n),
            np.empty((n, m), dtype=bool),
            np.empty(n, dtype=np.uint8),
            np.empty(n, dtype=np.uint16),
        )

    def rows(self, lo: int, hi: int) -> _Columns:
        """Return a view of rows ``lo:hi``."""
        return _Columns(**{f.name: getattr(self, f.name)[lo:hi] for f in fields(self)})

    def blank(self, rows: NDArray[np.bool_]) -> None:
        """Set the numbers of ``rows`` to NaN and their beacons to unused."""
        for f in fields(self):
            array = getattr(self, f.name)
            if array.dtype.kind == "f":
                array[rows] = np.nan
        self.used[rows] = False


def _summarise(
    problem: RangeProblem,
    solution: Solution,
    reason: NDArray[np.uint16],
    hedge_z_m: Array,
    options: SolverOptions,
    out: _Columns,
) -> None:
    """Write statistics, covariance and status of a solved chunk into ``out`` (row slices)."""
    dims = problem.dims
    used = solution.used
    reason |= solution.reason
    rss = np.maximum(solution.cost, 0.0)  # weighted by the relative precisions, if any
    plain_rss = rss if problem.precision is None else weighted_cost(problem, used, solution.point)
    n_used = used.sum(axis=0)
    dof = n_used - dims
    with np.errstate(divide="ignore", invalid="ignore"):
        variance = np.maximum(rss / dof, options.range_sigma_m**2)
        inverse, _ = inverse_sym(solution.normal)
        high = rss > chi2_threshold(dof, options.alpha) * options.range_sigma_m**2
        np.sqrt(plain_rss / n_used, out=out.residual_rms_m)
        np.divide(np.sqrt(plain_rss), n_used * n_used, out=out.error_eq4_m)
        np.sqrt(variance, out=out.range_sigma_m)
    reason[high] |= np.uint16(FixReason.HIGH_RESIDUAL)
    status = out.status
    status[:] = FixStatus.OK
    status[(reason & _DEGRADED) != 0] = FixStatus.DEGRADED
    status[solution.rejected | ((reason & _NOT_CONVERGED) != 0)] = FixStatus.REJECTED
    degenerate = (reason & _DEGENERATE) != 0
    status[degenerate] = FixStatus.DEGENERATE
    out.reason[:] = reason
    yy = 2 if dims == 2 else 3
    cov = out.covariance_xy_m2
    np.multiply(inverse[0], variance, out=cov[:, 0, 0])
    np.multiply(inverse[1], variance, out=cov[:, 0, 1])
    cov[:, 1, 0] = cov[:, 0, 1]
    np.multiply(inverse[yy], variance, out=cov[:, 1, 1])
    with np.errstate(invalid="ignore"):
        np.sqrt(inverse[0] + inverse[yy], out=out.hdop)
        out.sigma_z_m[:] = np.sqrt(variance * inverse[5]) if dims == 3 else np.nan
    positions = out.positions_map_m
    positions[:, 0] = solution.point[0]
    positions[:, 1] = solution.point[1]
    positions[:, 2] = solution.point[2] if dims == 3 else hedge_z_m
    out.used[:] = used.T
    if np.any(degenerate):
        out.blank(degenerate)


def _solve_chunk(
    distances_m: Array,
    beacons: BeaconMap,
    hedge_z_m: Array,
    precision: Array | None,
    solver: _Solver,
    dims: int,
    options: SolverOptions,
    out: _Columns,
) -> None:
    distance = np.ascontiguousarray(distances_m.T)
    n = distance.shape[1]
    with np.errstate(invalid="ignore"):
        valid = distance >= 0.0  # False for NaN
        valid &= distance != np.inf
    reason = np.zeros(n, dtype=np.uint16)
    missing = ~valid
    if np.any(missing):
        invalid = missing & ~np.isnan(distance)
        reason[np.any(invalid, axis=0)] |= np.uint16(FixReason.INVALID_DISTANCE)
        reason[missing.sum(axis=0) > len(beacons) - dims - 1] |= np.uint16(
            FixReason.TOO_FEW_BEACONS
        )
        distance = np.where(valid, distance, 0.0)
    elif len(beacons) < dims + 1:
        reason[:] |= np.uint16(FixReason.TOO_FEW_BEACONS)
    position = beacons.positions_m
    if dims == 2:
        known = np.isfinite(hedge_z_m)
        heights = hedge_z_m
        if not np.all(known):
            reason[~known] |= np.uint16(FixReason.UNKNOWN_HEDGE_HEIGHT)
            heights = np.where(known, hedge_z_m, 0.0)
        if heights.size and np.all(heights == heights[0]):
            heights = heights[:1]  # one height for the block: offsets broadcast as (m, 1)
        dz = heights - position[:, 2:3]
        axes: tuple[Array, ...] = (position[:, 0:1], position[:, 1:2])
    else:
        dz = np.zeros((len(beacons), 1))
        axes = (position[:, 0:1], position[:, 1:2], position[:, 2:3])
    problem = RangeProblem(axes, distance, dz * dz, precision)
    solution = solver(problem, valid, options)
    _summarise(problem, solution, reason, hedge_z_m, options, out)


def _noise_model(
    options: SolverOptions, range_sigma_m: float | ArrayLike | None, m: int
) -> tuple[SolverOptions, Array | None]:
    """Return options with the reference σ and the relative precisions (None if uniform)."""
    if range_sigma_m is None:
        sigma = np.array(options.range_sigma_m, dtype=np.float64)
    else:
        sigma = np.asarray(range_sigma_m, dtype=np.float64)
    if sigma.ndim not in (0, 1) or (sigma.ndim == 1 and sigma.shape != (m,)):
        msg = f"solve_fixes: range_sigma_m must be a scalar or shape ({m},), got {sigma.shape}"
        raise ConfigError(msg)
    if not np.all(sigma > 0.0) or not np.all(np.isfinite(sigma)):
        msg = f"solve_fixes: range_sigma_m must be positive and finite, got {sigma.tolist()}"
        raise ConfigError(msg)
    if sigma.ndim == 0 or np.all(sigma == sigma[0]):
        return dataclasses.replace(options, range_sigma_m=float(sigma.reshape(-1)[0])), None
    reference = float(np.sqrt(np.mean(sigma * sigma)))
    precision = ((reference / sigma) ** 2).reshape(m, 1)
    return dataclasses.replace(options, range_sigma_m=reference), precision


def _hedge_heights(
    hedge_z_m: float | ArrayLike | None, beacons: BeaconMap, n: int, dims: int
) -> Array:
    if dims == 3:
        return np.full(n, np.nan)
    if hedge_z_m is None:
        if beacons.hedge_z_m.size != 1:
            msg = (
                "solve_fixes: dims=2 needs the hedgehog height: pass hedge_z_m, or use a "
                f"beacon map with exactly one hedge height (it has {beacons.hedge_z_m.size})"
            )
            raise ConfigError(msg)
        return np.full(n, float(beacons.hedge_z_m[0]))
    heights = np.asarray(hedge_z_m, dtype=np.float64)
    if heights.ndim == 0:
        return np.full(n, float(heights))
    if heights.shape != (n,):
        msg = f"solve_fixes: hedge_z_m must be a scalar or shape ({n},), got {heights.shape}"
        raise ConfigError(msg)
    return heights


def solve_fixes(
    distances_m: ArrayLike,
    beacons: BeaconMap,
    *,
    method: Method = "robust",
    dims: int = 2,
    hedge_z_m: float | ArrayLike | None = None,
    range_sigma_m: float | ArrayLike | None = None,
    options: SolverOptions | None = None,
    chunk_size: int | None = None,
    workers: int = 1,
) -> Fixes:
    """Multilaterate every fix of a distance matrix at once (vectorised over fixes).

    Bad input never raises: a fix with NaN/negative distances, too few beacons or singular
    geometry is flagged (status and reason) and the others go on.

    Args:
        distances_m: Measured distances, shape (n, m) in the map's beacon order, metres;
            NaN where a beacon was not heard.
        beacons: Beacon map (m beacons).
        method: A :class:`~omnical.choices.LocateMethod` or its value: ``"lsq"``
            (Gauss–Newton least squares), ``"robust"`` (NLOS outlier rejection, see
            :mod:`omnical.ips.solve.robust`) or ``"grid"`` (seed 000, 1 mm).
        dims: 2 (solve x, y at a known hedgehog height) or 3 (solve x, y, z; needs beacons
            that are not coplanar).
        hedge_z_m: Hedgehog height in the map frame, scalar or shape (n,), metres; NaN marks
            an unknown height. Defaults to the map's hedge height if it has exactly one.
        range_sigma_m: Prior range noise σ in metres (overrides ``options.range_sigma_m``):
            a scalar, or one σ per map beacon, shape (m,), for a weighted fit with weights
            ``1/σ_i²``. The residual test and the covariance then use the weighted residuals;
            :attr:`Fixes.range_sigma_m` reports σ̂ relative to the RMS of the σ_i.
        options: Numerical options; defaults to :class:`SolverOptions()`.
        chunk_size: Fixes solved per vectorised block; default 131,072 distances per block
            (32,768 fixes of 4 beacons).
        workers: Threads solving blocks in parallel (numpy releases the GIL in its loops).

    Returns:
        One result per fix, see :class:`Fixes`.

    Raises:
        ConfigError: If the matrix does not match the map, ``dims`` is unknown, or the
            hedgehog height is needed and unknown (a programming error, not bad data).
        ChoiceError: If ``method`` is unknown (a :class:`ConfigError` too).
    """
    matrix = np.asarray(distances_m, dtype=np.float64)
    if matrix.ndim != 2 or matrix.shape[1] != len(beacons):
        msg = f"solve_fixes: distances_m must have shape (n, {len(beacons)}), got {matrix.shape}"
        raise ConfigError(msg)
    if dims not in (2, 3):
        msg = f"solve_fixes: dims must be 2 or 3, got {dims}"
        raise ConfigError(msg)
    chosen = parse_choice(LocateMethod, method, "solve_fixes: method")
    options, precision = _noise_model(options or SolverOptions(), range_sigma_m, len(beacons))
    n = matrix.shape[0]
    heights = _hedge_heights(hedge_z_m, beacons, n, dims)
    solver = _SOLVERS[chosen]
    block = max(1, chunk_size or _BLOCK_DISTANCES // max(len(beacons), 1))
    bounds = [(s, min(s + block, n)) for s in range(0, n, block)]

    columns = _Columns.allocate(n, len(beacons))

    def run(bound: tuple[int, int]) -> None:
        lo, hi = bound
        _solve_chunk(
            matrix[lo:hi],
            beacons,
            heights[lo:hi],
            precision,
            solver,
            dims,
            options,
            columns.rows(lo, hi),
        )

    if workers > 1 and len(bounds) > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            list(pool.map(run, bounds))
    else:
        for bound in bounds:
            run(bound)
    return Fixes(
        **{f.name: getattr(columns, f.name) for f in fields(columns)},
        beacon_addresses=beacons.addresses.copy(),
        method=chosen.value,
        dims=dims,
    )


def model_for(
    beacons: BeaconMap,
    options: SolverOptions,
    range_sigma_m: float | ArrayLike | None,
    hedge: int | None,
) -> NoiseModel:
    """The starting noise model of hedgehog ``hedge``: σ given (``range_sigma_m``, validated)
    or the options' prior."""
    m = len(beacons)
    if range_sigma_m is None:
        return NoiseModel.uniform(beacons.addresses, options.range_sigma_m, hedge_address=hedge)
    _noise_model(options, range_sigma_m, m)  # validates
    sigma = np.broadcast_to(np.asarray(range_sigma_m, dtype=np.float64), (m,))
    return NoiseModel.uniform(beacons.addresses, sigma, NoiseSource.GIVEN, hedge)


def solve_self_calibrated(
    distances_m: ArrayLike,
    beacons: BeaconMap,
    *,
    method: Method = "robust",
    dims: int = 2,
    hedge_z_m: float | ArrayLike | None = None,
    range_sigma_m: float | ArrayLike | None = None,
    options: SolverOptions | None = None,
    self_calibrate: bool = True,
    hedge_address: int | None = None,
) -> Fixes:
    """Solve the fixes of one hedgehog with a noise model learned from them (whole run).

    Without ``self_calibrate``: :func:`solve_fixes` with σ = ``range_sigma_m`` (or the prior).
    With it: a least-squares pass, then :data:`LEARNING_ROUNDS` robust passes, each after
    learning σ (unless given), a bias (first) or a bias and scale per link where observable
    (:mod:`omnical.ips.solve.selfcal`), the last with ``method``; when σ is learned, then the
    link covariance and the calibration's uncertainty (:mod:`omnical.ips.solve.linkcov`).
    The final model is :attr:`Fixes.noise`.

    Args:
        distances_m: Measured distances (n, m) in the map's beacon order, metres.
        beacons: Beacon map (m beacons).
        method: See :func:`solve_fixes` (the learning passes use ``robust``).
        dims: See :func:`solve_fixes`.
        hedge_z_m: See :func:`solve_fixes`.
        range_sigma_m: σ fixed by the caller (scalar or per beacon); None learns it.
        options: See :func:`solve_fixes`.
        self_calibrate: Learn from the recording (σ, bias, scale); False uses the ranges as
            they are with the given or prior σ.
        hedge_address: The hedgehog (reported in the noise model).

    Returns:
        The fixes, with :attr:`Fixes.noise` holding the model they were solved with.
    """
    matrix = np.asarray(distances_m, dtype=np.float64)
    options = options or SolverOptions()
    model = model_for(beacons, options, range_sigma_m, hedge_address)

    def solve(with_method: Method, current: NoiseModel) -> Fixes:
        return solve_fixes(
            current.correct(matrix),
            beacons,
            method=with_method,
            dims=dims,
            hedge_z_m=hedge_z_m,
            range_sigma_m=current.sigma_m,
            options=options,
        )

    if not self_calibrate:
        return dataclasses.replace(solve(method, model), noise=(model,))
    learn_sigma_too = range_sigma_m is None
    fixes = solve("lsq", model)
    for round_ in range(LEARNING_ROUNDS):
        fixes = _for_learning(fixes)
        corrected = model.correct(matrix)
        lin = linearised_usable(fixes, corrected, beacons)  # shared: it does not use the model
        if learn_sigma_too:
            model = learn_sigma(fixes, corrected, beacons, model, linearised=lin)
        model = learn_links(fixes, corrected, beacons, model, joint=round_ == 0, linearised=lin)
        last = round_ == LEARNING_ROUNDS - 1
        del fixes, corrected, lin  # released before the next pass allocates its own
        fixes = solve(method if last else "robust", model)
    if learn_sigma_too:
        corrected = model.correct(matrix)
        model = learn_link_covariance(fixes, corrected, beacons, model)
        covariance = link_covariances(fixes, corrected, beacons, model)
        fixes = dataclasses.replace(fixes, covariance_xy_m2=covariance)
    return dataclasses.replace(fixes, noise=(model,))


def _for_learning(fixes: Fixes) -> Fixes:
    """``fixes`` with only what the learning reads (positions, beacons used, status, reason);
    covariances and statistics become read-only NaN views of no memory."""
    nan, n = np.float64(np.nan), len(fixes)
    nothing = np.broadcast_to(nan, (n,))
    return dataclasses.replace(
        fixes,
        covariance_xy_m2=np.broadcast_to(nan, (n, 2, 2)),
        sigma_z_m=nothing,
        range_sigma_m=nothing,
        hdop=nothing,
        residual_rms_m=nothing,
        error_eq4_m=nothing,
    )


def off_track(
    xy: Array,
    covariance: Array,
    status: NDArray[np.uint8],
    t_ns: NDArray[np.int64],
) -> NDArray[np.bool_]:
    """Usable fixes far from the median of their usable neighbours in time.

    ``xy`` (k, 2), ``covariance`` (k, 2, 2), ``status`` (k,) and ``t_ns`` (k,) are one
    hedgehog's fixes. The neighbours are the :data:`TRACK_NEIGHBOURS` usable fixes on each
    side within :data:`TRACK_SPAN_NS`; a fix is off track when ``δᵀ(2C)⁻¹δ`` from their
    component-wise median exceeds the χ² quantile at :data:`_TRACK_ALPHA` (``C`` its
    covariance). Fewer than ``2k + 1`` usable fixes: none is checked.
    """
    out = np.zeros(t_ns.size, dtype=bool)
    usable = np.flatnonzero((status <= FixStatus.DEGRADED) & np.all(np.isfinite(xy), axis=1))
    k = TRACK_NEIGHBOURS
    if usable.size < 2 * k + 1:
        return out
    order = usable[np.argsort(t_ns[usable], kind="stable")]
    threshold = chi2_quantile(2, _TRACK_ALPHA)
    for lo in range(0, order.size, _TRACK_CHUNK):
        hi = min(lo + _TRACK_CHUNK, order.size)
        out[order[lo:hi]] = _off_track_chunk(xy, covariance, t_ns, order, lo, hi, threshold)
    return out


def _off_track_chunk(
    xy: Array,
    covariance: Array,
    t_ns: NDArray[np.int64],
    order: NDArray[np.intp],
    lo: int,
    hi: int,
    threshold: float,
) -> NDArray[np.bool_]:
    """:func:`off_track` of the fixes ``order[lo:hi]`` (their windows reach k further)."""
    k = TRACK_NEIGHBOURS
    first, last = max(lo - k, 0), min(hi + k, order.size)
    pad = ((k - (lo - first), k - (last - hi)),)
    span = order[first:last]
    pos = np.pad(xy[span], (*pad, (0, 0)), constant_values=np.nan)
    times = np.pad(t_ns[span].astype(np.float64), pad, constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(pos, 2 * k + 1, axis=0)  # (c, 2, w)
    t_windows = np.lib.stride_tricks.sliding_window_view(times, 2 * k + 1)
    rows = order[lo:hi]
    centre = t_ns[rows].astype(np.float64)[:, None]
    with np.errstate(invalid="ignore"):
        near = np.abs(t_windows - centre) <= TRACK_SPAN_NS
    near[:, k] = False
    neighbours = np.where(near[:, None, :], windows, np.nan)
    enough = near.sum(axis=1) >= k
    median = _nanmedian_last(neighbours)
    delta = xy[rows] - median
    m2 = mahalanobis_sq(2.0 * covariance[rows], delta)
    with np.errstate(invalid="ignore"):
        result: NDArray[np.bool_] = enough & (m2 > threshold)
    return result


def _nanmedian_last(values: Array) -> Array:
    """``np.nanmedian(values, axis=-1)`` of finite values and NaN, without its masked arrays.

    The middle of the sorted finite values (NaN sorts last), or the half-sum of the two
    middle ones; NaN where a row has none.
    """
    ordered = np.sort(values, axis=-1)
    count = np.count_nonzero(~np.isnan(values), axis=-1)
    low = np.maximum(count - 1, 0)[..., None] // 2
    high = (count // 2)[..., None]
    pair = np.take_along_axis(ordered, low, axis=-1) + np.take_along_axis(ordered, high, axis=-1)
    median: Array = np.where(count > 0, pair[..., 0] / 2.0, np.nan)
    return median


class MergedFixes:
    """The fixes of each hedgehog scattered into one result of n fixes as they are solved
    (each released once copied in; one hedgehog owning every row is taken as it is)."""

    def __init__(self, n: int, m: int) -> None:
        self._n, self._m = n, m
        self._columns: _Columns | None = None
        self._whole: Fixes | None = None
        self._meta: tuple[NDArray[np.int64], str, int] | None = None
        self._noise: list[NoiseModel] = []

    def add(self, rows: NDArray[np.intp], part: Fixes) -> None:
        """Put the fixes ``part`` at ``rows``."""
        self._noise.extend(part.noise)
        if self._meta is None:
            self._meta = (part.beacon_addresses, part.method, part.dims)
            if rows.size == self._n:  # rows are sorted: all of them, in order
                self._whole = part
                return
        if self._columns is None:
            self._columns = _Columns.allocate(self._n, self._m)
        for f in fields(self._columns):
            getattr(self._columns, f.name)[rows] = getattr(part, f.name)

    def result(self) -> Fixes:
        """The merged fixes."""
        if self._whole is not None:
            return dataclasses.replace(self._whole, noise=tuple(self._noise))
        assert self._columns is not None and self._meta is not None
        addresses, method, dims = self._meta
        return Fixes(
            **{f.name: getattr(self._columns, f.name) for f in fields(self._columns)},
            beacon_addresses=addresses,
            method=method,
            dims=dims,
            noise=tuple(self._noise),
        )


def group_ranges(
    t_ns: ArrayLike,
    address_hedge: ArrayLike,
    address_beacon: ArrayLike,
    distance_m: ArrayLike,
    beacons: BeaconMap,
    *,
    dims: int = 2,
    max_gap_ns: int = DEFAULT_MAX_GAP_NS,
    sequential: bool | None = None,
) -> tuple[Bursts, tuple[str, ...]]:
    """Group raw-distance messages into the fixes :func:`locate_bursts` solves: bursts (one
    measurement each) or, when the ranges come one per message (round robin, see
    :func:`~omnical.ips.bursts.is_sequential`), a sliding window of the latest range of each
    beacon closed by every message, with a note saying so.

    Args:
        t_ns: Receive time of each ``/beacon_raw_distance`` message, shape (k,), int ns,
            non-decreasing.
        address_hedge, address_beacon, distance_m: Per message, shape (k,); distances to
            beacons not in ``beacons`` are flagged.
        beacons: Beacon map.
        dims: See :func:`solve_fixes`.
        max_gap_ns: Largest gap between two messages of one burst, ns.
        sequential: Force (True) or forbid (False) sliding windows; None decides from the data.

    ``fix_of_message`` and ``n_messages`` are left empty (:func:`locate_bursts` does not use
    them); the raw-distance columns are not needed afterwards.
    """
    bursts = group_bursts(
        t_ns, address_hedge, address_beacon, distance_m, beacons, max_gap_ns=max_gap_ns
    )
    notes: list[str] = []
    if sequential is None:
        sequential = is_sequential(bursts, dims)
    if sequential:
        del bursts
        bursts, age_ns = sliding_windows(t_ns, address_hedge, address_beacon, distance_m, beacons)
        notes.append(SEQUENTIAL_NOTE.format(age_ms=age_ns / 1e6))
    empty = np.zeros(0, dtype=np.int64)
    slim = dataclasses.replace(bursts, n_messages=empty, fix_of_message=empty.astype(np.intp))
    return slim, tuple(notes)


def locate_bursts(
    bursts: Bursts,
    beacons: BeaconMap,
    *,
    notes: tuple[str, ...] = (),
    method: Method = "robust",
    dims: int = 2,
    hedge_z_m: float | None = None,
    range_sigma_m: float | ArrayLike | None = None,
    options: SolverOptions | None = None,
    self_calibrate: bool = True,
) -> Fixes:
    """Solve grouped fixes (:func:`group_ranges`), each hedgehog's by
    :func:`solve_self_calibrated`.

    Uses ``t_ns``, ``address_hedge``, ``distances_m``, ``n_unknown`` and ``n_invalid`` of
    ``bursts``; ``notes`` go to :attr:`Fixes.notes`.
    """
    fallback = np.nan if hedge_z_m is None else float(hedge_z_m)
    heights = np.full(len(bursts), fallback)
    for address, z in zip(beacons.hedge_addresses, beacons.hedge_z_m, strict=True):
        heights[bursts.address_hedge == address] = z
    # The rows of each hedgehog, in order (stable sort: as np.flatnonzero would give them).
    order = np.argsort(bursts.address_hedge, kind="stable")
    hedges, starts = np.unique(bursts.address_hedge[order], return_index=True)
    groups = np.split(order, starts[1:]) if hedges.size else []
    del order
    options = options or SolverOptions()
    merged = MergedFixes(len(bursts), len(beacons))
    for address, rows in zip(hedges, groups, strict=True):
        whole = rows.size == len(bursts)  # one hedgehog: its rows without copying them
        merged.add(
            rows,
            solve_self_calibrated(
                bursts.distances_m if whole else bursts.distances_m[rows],
                beacons,
                method=method,
                dims=dims,
                hedge_z_m=heights if whole else heights[rows],
                range_sigma_m=range_sigma_m,
                options=options,
                self_calibrate=self_calibrate,
                hedge_address=int(address),
            ),
        )
    if hedges.size:
        fixes = merged.result()
    else:
        fixes = solve_fixes(
            bursts.distances_m,
            beacons,
            method=method,
            dims=dims,
            hedge_z_m=heights,
            range_sigma_m=range_sigma_m,
            options=options,
        )
    reason = fixes.reason.copy()
    reason[bursts.n_unknown > 0] |= np.uint16(FixReason.UNKNOWN_BEACON)
    reason[bursts.n_invalid > 0] |= np.uint16(FixReason.INVALID_DISTANCE)
    status = fixes.status.copy()
    xy = fixes.positions_map_m[:, :2]
    for mine in groups:
        if mine.size == len(bursts):  # one hedgehog: no copies of its columns
            track = off_track(xy, fixes.covariance_xy_m2, fixes.status, bursts.t_ns)
        else:
            track = off_track(
                xy[mine], fixes.covariance_xy_m2[mine], fixes.status[mine], bursts.t_ns[mine]
            )
        off = mine[track]
        reason[off] |= np.uint16(FixReason.OFF_TRACK)
        status[off[status[off] == FixStatus.OK]] = FixStatus.DEGRADED
    return dataclasses.replace(
        fixes,
        reason=reason,
        status=status,
        t_ns=bursts.t_ns,
        address_hedge=bursts.address_hedge,
        notes=notes,
    )
