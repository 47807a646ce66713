"""Plane geometry for calibration from IPS tracks (seed 000 §3.2.3): arcs, circles, lengths.

Nearly straight arcs are parametrised by a point, the heading there and the signed curvature κ
(smooth through κ = 0), fitted from Pratt's fit by least squares, optionally robust.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import GeometryError
from omnical.estimation.se2 import rotate_xy, wrap_angle

__all__ = [
    "LOSSES",
    "CircleFit",
    "Loss",
    "MeanPosition",
    "arc_length",
    "fit_circle",
    "mean_position",
    "robust_loss",
]

Loss = Literal["linear", "soft_l1", "huber", "cauchy", "arctan"]
"""Loss functions of :func:`fit_circle` (those of ``scipy.optimize.least_squares``)."""

LOSSES: tuple[Loss, ...] = ("linear", "soft_l1", "huber", "cauchy", "arctan")
_Array = NDArray[np.float64]
_HUBER_K = 1.345  # 95 % efficiency at the normal distribution
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class CircleFit:
    """A circle (or straight line) fitted to a track, in the frame of the points.

    Attributes:
        curvature_per_m: signed curvature κ in rad/m; + when the points, in the order given,
            turn counter-clockwise. 0 is a straight line.
        curvature_std_per_m: 1σ uncertainty of κ (from the Jacobian and the residual variance).
        radius_m: 1/|κ|; ``inf`` for a straight line.
        radius_std_m: 1σ uncertainty of the radius, σ_κ/κ² (``inf`` for κ = 0).
        centre_xy_m: (2,) centre of the circle; None when κ is exactly 0.
        point_xy_m: (2,) point of the arc closest to the centroid of the points.
        heading_rad: direction of traversal at ``point_xy_m``, in [−π, π].
        covariance: (3, 3) covariance of (normal offset of the arc at ``point_xy_m`` in m,
            heading in rad, curvature in rad/m).
        residuals_m: (N,) signed orthogonal distance of each point, + left of the traversal.
        rms_m: root-mean-square of ``residuals_m`` over the points of positive weight
            (unweighted, outliers included).
        n_points: number of points with positive weight.
    """

    curvature_per_m: float
    curvature_std_per_m: float
    radius_m: float
    radius_std_m: float
    centre_xy_m: _Array | None
    point_xy_m: _Array
    heading_rad: float
    covariance: _Array
    residuals_m: _Array
    rms_m: float
    n_points: int


@dataclass(frozen=True)
class MeanPosition:
    """A stand-still position averaged over many fixes.

    Attributes:
        mean_xy_m: (D,) the (robust) mean position.
        std_error_m: (D,) 1σ standard error of the mean, per axis (``inf`` for a single fix).
        n_points: number of fixes averaged.
    """

    mean_xy_m: _Array
    std_error_m: _Array
    n_points: int


# ---------------------------------------------------------------------------------------------
# input checks


def _check_points(
    points: ArrayLike, name: str, *, min_points: int, dims: tuple[int, ...] = (2,)
) -> _Array:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in dims:
        shapes = " or ".join(f"(N, {k})" for k in dims)
        msg = f"{name} must have shape {shapes}, got {p.shape}"
        raise GeometryError(msg)
    if p.shape[0] < min_points:
        msg = f"{name} needs at least {min_points} points, got {p.shape[0]}"
        raise GeometryError(msg)
    if not np.all(np.isfinite(p)):
        msg = f"{name} contains non-finite values"
        raise GeometryError(msg)
    return p


def _check_point(point: ArrayLike, name: str) -> _Array:
    p = np.asarray(point, dtype=np.float64)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        msg = f"{name} must be a finite (2,) point, got {p!r}"
        raise GeometryError(msg)
    return p


# ---------------------------------------------------------------------------------------------
# circle fit


def _pratt(xy: _Array, w: _Array) -> tuple[float, float, float, float]:
    """Pratt's algebraic fit A(x² + y²) + Bx + Cy + D = 0, B² + C² − 4AD = 1 (centred data)."""
    scale = float(np.sqrt(np.average(np.sum(xy**2, axis=1), weights=w)))
    s = xy / scale
    design = np.column_stack([np.sum(s**2, axis=1), s[:, 0], s[:, 1], np.ones(len(s))])
    design *= np.sqrt(w)[:, None]
    m = design.T @ design
    constraint = np.array(
        [[0.0, 0.0, 0.0, -2.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [-2.0, 0.0, 0.0, 0.0]]
    )
    _, vectors = np.linalg.eig(np.linalg.solve(constraint, m))
    best: tuple[float, _Array] | None = None
    for a in np.real(vectors).T:
        q = float(a @ constraint @ a)
        if q <= 0.0:
            continue
        score = float(a @ m @ a) / q
        if best is None or score < best[0]:
            best = (score, a / np.sqrt(q))
    if best is None:  # pragma: no cover - M is positive semi-definite, one root always qualifies
        msg = "the algebraic circle fit found no admissible solution"
        raise GeometryError(msg)
    a_, b_, c_, d_ = best[1]
    return float(a_ / scale), float(b_), float(c_), float(d_ * scale)


def _initial_arc(xy: _Array, w: _Array) -> tuple[_Array, float, float]:
    """Start of the geometric fit: (point on the arc, heading, curvature), xy centred."""
    a, b, c, d = _pratt(xy, w)
    # orient the circle along the traversal: the tangent is the gradient of P turned by −90°
    grad = 2.0 * a * xy + np.array([b, c])
    tangent = np.column_stack([grad[:, 1], -grad[:, 0]])
    if np.sum(np.diff(xy, axis=0) * tangent[:-1]) < 0.0:
        a, b, c, d = -a, -b, -c, -d
    bc = float(np.hypot(b, c))
    if bc > 1e-9:  # the closest point of the circle to the centroid (the origin)
        normal = np.array([b, c]) / bc
        p0 = -2.0 * d / (1.0 + bc) * normal
    else:  # the centroid is the centre: start from the point of the circle nearest xy[0]
        centre = -np.array([b, c]) / (2.0 * a)
        radial = xy[0] - centre
        p0 = centre + radial / np.linalg.norm(radial) / (2.0 * abs(a))
        grad0 = 2.0 * a * p0 + np.array([b, c])
        normal = grad0 / np.linalg.norm(grad0)
    heading = float(np.arctan2(-normal[0], normal[1]))
    return p0, heading, -2.0 * a


def _arc_residuals(params: _Array, s: _Array) -> tuple[_Array, _Array]:
    """Signed distances e (N,) and their Jacobian (N, 3) with respect to (d, θ, κ)."""
    d, theta, kappa = params
    ct, st = np.cos(theta), np.sin(theta)
    u = s[:, 0] * ct + s[:, 1] * st
    v = -s[:, 0] * st + s[:, 1] * ct - d
    a2 = u * u + v * v
    g = 2.0 * v - kappa * a2
    root = np.sqrt(np.maximum(1.0 - 2.0 * kappa * v + kappa * kappa * a2, 1e-24))
    den = 1.0 + root
    e = g / den

    def partial(g_x: _Array, h_x: _Array) -> _Array:
        return np.asarray((g_x * den - g * h_x / (2.0 * root)) / (den * den), dtype=np.float64)

    e_u = partial(-2.0 * kappa * u, 2.0 * kappa * kappa * u)
    e_v = partial(2.0 - 2.0 * kappa * v, -2.0 * kappa + 2.0 * kappa * kappa * v)
    e_k = partial(-a2, -2.0 * v + 2.0 * kappa * a2)
    jac = np.column_stack([-e_v, e_u * (v + d) - e_v * u, e_k])
    return e, jac


def _psi(r: _Array, f_scale: float, loss: Loss) -> tuple[_Array, _Array]:
    """ψ(r) and ψ'(r) of a scipy loss for residuals r; cost = f² ρ((r/f)²), ψ = ½ d cost / dr."""
    z = (r / f_scale) ** 2
    _, d1, d2 = robust_loss(z, loss)
    return r * d1, d1 + 2.0 * z * d2


def robust_loss(z: _Array, loss: str) -> tuple[_Array, _Array, _Array]:
    """ρ, ρ', ρ'' of a loss of ``scipy.optimize.least_squares`` (:data:`LOSSES`) at z = (r / f)²."""
    if loss == "soft_l1":
        t = 1.0 + z
        return 2.0 * (np.sqrt(t) - 1.0), 1.0 / np.sqrt(t), -0.5 * t**-1.5
    if loss == "cauchy":
        t = 1.0 + z
        return np.log1p(z), 1.0 / t, -1.0 / t**2
    if loss == "huber":
        inside = z <= 1.0
        zs = np.where(inside, 1.0, z)
        return (
            np.where(inside, z, 2.0 * np.sqrt(zs) - 1.0),
            np.where(inside, 1.0, 1.0 / np.sqrt(zs)),
            np.where(inside, 0.0, -0.5 * zs**-1.5),
        )
    if loss == "arctan":
        t = 1.0 + z * z
        return np.arctan(z), 1.0 / t, -2.0 * z / t**2
    return z, np.ones_like(z), np.zeros_like(z)


def fit_circle(
    points_xy: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    loss: Loss = "linear",
    f_scale_m: float = 0.05,
) -> CircleFit:
    """Fit a circle or a straight line to a track by geometric (orthogonal) least squares.

    Pratt's algebraic fit gives the start, then the orthogonal distances are minimised over
    (offset, heading, curvature): a straight track gives κ ≈ 0 with a finite σ_κ.

    Args:
        points_xy: (N, 2) positions in m, in the order of traversal (N ≥ 3).
        weights: (N,) relative weights ≥ 0 (e.g. 1/σ² of each fix); the absolute scale of the
            uncertainties always comes from the residual variance. Default: all 1.
        loss: ``"linear"``, or a robust loss of ``scipy.optimize.least_squares``
            (``"soft_l1"``, ``"huber"``, ``"cauchy"``, ``"arctan"``) against NLOS outliers.
        f_scale_m: residual in m (at weight 1) beyond which a robust loss discounts a point.

    Returns:
        The fit, with the 1σ uncertainty of curvature and radius. With N = 3 the fit is exact
        and the uncertainties are ``inf``.

    Raises:
        GeometryError: fewer than 3 points (of positive weight), non-finite or coincident
            points, negative weights, an unknown loss or a non-positive ``f_scale_m``, no
            convergence.
    """
    from scipy.optimize import least_squares  # 0.35 s to import: only fits need it

    xy = _check_points(points_xy, "points_xy", min_points=3)
    n_all = len(xy)
    w = np.ones(n_all) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (n_all,) or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        msg = f"weights must be ({n_all},) finite and ≥ 0"
        raise GeometryError(msg)
    if loss not in LOSSES:
        msg = f"loss must be one of {', '.join(LOSSES)}, got {loss!r}"
        raise GeometryError(msg)
    if not f_scale_m > 0.0:
        msg = f"f_scale_m must be > 0, got {f_scale_m}"
        raise GeometryError(msg)
    used = w > 0.0
    n = int(np.count_nonzero(used))
    if n < 3:
        msg = f"a circle fit needs at least 3 points of positive weight, got {n}"
        raise GeometryError(msg)
    centroid = np.average(xy, axis=0, weights=w)
    centred = xy - centroid
    spread = float(np.sqrt(np.average(np.sum(centred**2, axis=1), weights=w)))
    if spread <= 1e-12 * max(1.0, float(np.max(np.abs(xy)))):
        msg = "all points of the circle fit coincide"
        raise GeometryError(msg)

    p0, heading0, kappa0 = _initial_arc(centred[used], w[used])
    ref = centroid + p0
    s = xy - ref
    sw = np.sqrt(w)

    def fun(params: _Array) -> _Array:
        return np.asarray(sw * _arc_residuals(params, s)[0], dtype=np.float64)

    def jac(params: _Array) -> _Array:
        return np.asarray(sw[:, None] * _arc_residuals(params, s)[1], dtype=np.float64)

    result = least_squares(
        fun,
        np.array([0.0, heading0, kappa0]),
        jac=jac,
        loss=loss,
        f_scale=f_scale_m,
        x_scale="jac",
        ftol=1e-14,
        xtol=1e-14,
        gtol=1e-14,
        max_nfev=200,
    )
    if result.status <= 0:  # pragma: no cover - converges in < 20 evaluations on test tracks
        msg = f"the circle fit did not converge: {result.message}"
        raise GeometryError(msg)
    d, theta, kappa = (float(x) for x in result.x)
    e, j = _arc_residuals(result.x, s)
    # Huber's covariance of an M-estimator: Σψ²/(n − 3) / mean(ψ')² (JᵀJ)⁻¹, on the weighted
    # residuals; for the linear loss this is σ̂² (JᵀWJ)⁻¹.
    r, js = sw[used] * e[used], sw[used, None] * j[used]
    psi, dpsi = _psi(r, f_scale_m, loss)
    mean_dpsi = float(np.mean(dpsi))
    dof = n - 3
    if dof > 0 and mean_dpsi > 0.0:
        sigma2 = float(np.sum(psi * psi)) / dof / mean_dpsi**2
        try:
            cov = np.asarray(sigma2 * np.linalg.inv(js.T @ js), dtype=np.float64)
        except np.linalg.LinAlgError as err:  # pragma: no cover - excluded by the checks
            msg = "the circle fit is degenerate (singular normal matrix)"
            raise GeometryError(msg) from err
    else:
        cov = np.full((3, 3), np.inf)
    return _circle_fit(d, theta, kappa, ref, cov, e, used)


def _circle_fit(
    d: float,
    theta: float,
    kappa: float,
    ref: _Array,
    cov: _Array,
    e: _Array,
    used: NDArray[np.bool_],
) -> CircleFit:
    heading = wrap_angle(theta)
    normal = np.array([-np.sin(heading), np.cos(heading)])
    point = ref + d * normal
    kappa_std = float(np.sqrt(cov[2, 2])) if np.isfinite(cov[2, 2]) else np.inf
    if kappa == 0.0:
        radius, radius_std, centre = np.inf, np.inf, None
    else:
        radius = 1.0 / abs(kappa)
        radius_std = kappa_std / kappa**2
        centre = point + normal / kappa
    return CircleFit(
        curvature_per_m=kappa,
        curvature_std_per_m=kappa_std,
        radius_m=radius,
        radius_std_m=radius_std,
        centre_xy_m=centre,
        point_xy_m=point,
        heading_rad=heading,
        covariance=cov,
        residuals_m=e,
        rms_m=float(np.sqrt(np.mean(e[used] ** 2))),
        n_points=int(np.count_nonzero(used)),
    )


def _arc_coordinate(fit: CircleFit, q: _Array) -> float:
    """Signed length along the fitted arc from ``fit.point_xy_m`` to the projection of q."""
    u, v = (float(c) for c in rotate_xy(-fit.heading_rad, q - fit.point_xy_m))
    kappa = fit.curvature_per_m
    if kappa == 0.0:
        return u
    return float(np.arctan2(kappa * u, 1.0 - kappa * v)) / kappa


def arc_length(fit: CircleFit, start_xy: ArrayLike, end_xy: ArrayLike) -> float:
    """Length along the fitted arc between the projections of two points.

    Each point is projected onto the arc (radially for a circle, orthogonally for a line),
    measured from ``fit.point_xy_m`` up to half a turn either way.

    Args:
        fit: a fit from :func:`fit_circle`.
        start_xy: (2,) start position in m.
        end_xy: (2,) end position in m.

    Returns:
        Signed arc length in m: positive when ``end_xy`` follows ``start_xy`` in the direction
        of traversal of the fit.

    Raises:
        GeometryError: a point is not a finite (2,) vector.
    """
    start = _check_point(start_xy, "start_xy")
    end = _check_point(end_xy, "end_xy")
    return _arc_coordinate(fit, end) - _arc_coordinate(fit, start)


# ---------------------------------------------------------------------------------------------
# stand-still averages


def _huber_location(x: _Array) -> tuple[float, float]:
    """Huber M-estimate of location (MAD scale) and its asymptotic standard error."""
    n = len(x)
    med = float(np.median(x))
    scale = _MAD_TO_SIGMA * float(np.median(np.abs(x - med)))
    if scale == 0.0:  # more than half the fixes identical (quantised positions)
        scale = float(np.std(x, ddof=1))
    if scale == 0.0:
        return med, 0.0
    mu = med
    for _ in range(100):
        r = (x - mu) / scale
        w = np.minimum(1.0, _HUBER_K / np.maximum(np.abs(r), 1e-300))
        new = float(np.sum(w * x) / np.sum(w))
        done = abs(new - mu) <= 1e-12 * scale
        mu = new
        if done:
            break
    r = (x - mu) / scale
    psi = np.clip(r, -_HUBER_K, _HUBER_K)
    dpsi = float(np.mean(np.abs(r) <= _HUBER_K))
    if dpsi == 0.0:  # pragma: no cover - at least the median is inside the corner
        return mu, np.inf
    return mu, scale * float(np.sqrt(np.mean(psi * psi))) / dpsi / np.sqrt(n)


def mean_position(points: ArrayLike, *, robust: bool = True) -> MeanPosition:
    """Average the IPS fixes of a stand-still, with the standard error of the average.

    Args:
        points: (N, D) positions in m (D = 2 or 3).
        robust: a Huber M-estimate per axis (scale from the MAD, k = 1.345); otherwise the
            arithmetic mean and s/√N.

    Returns:
        The mean, its per-axis standard error (asymptotic for the Huber estimate; ``inf`` for a
        single fix) and N.

    Raises:
        GeometryError: no points, wrong shape or non-finite values.
    """
    p = _check_points(points, "points", min_points=1, dims=(2, 3))
    n = len(p)
    if n == 1:
        return MeanPosition(p[0].copy(), np.full(p.shape[1], np.inf), 1)
    if not robust:
        return MeanPosition(p.mean(axis=0), p.std(axis=0, ddof=1) / np.sqrt(n), n)
    located = [_huber_location(p[:, k]) for k in range(p.shape[1])]
    return MeanPosition(np.array([m for m, _ in located]), np.array([e for _, e in located]), n)
