"""The range noise model of a recording: per beacon link σ, and a bias and scale when observable.

A range is ``d = bias + scale · ρ + e``, ``ρ`` the true distance, ``e`` zero-mean noise (σ per
link, or a link covariance); :class:`NoiseModel` holds what was learned and corrects distances.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["NoiseModel", "NoiseSource"]


class NoiseSource(enum.Enum):
    """Where the σ of a noise model comes from."""

    PRIOR = "prior"
    """The default prior (``SolverOptions.range_sigma_m``): nothing was learned."""
    GIVEN = "given"
    """Fixed by the user (``--sigma-m`` / ``range_sigma_m``)."""
    LEARNED = "learned"
    """Estimated from the recording's own residuals (robust statistics over the whole run)."""


def _frozen(values: ArrayLike, dtype: type) -> NDArray[np.generic]:
    array: NDArray[np.generic] = np.array(values, dtype=dtype).reshape(-1)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class NoiseModel:
    """Per-link range model ``d = bias + scale · ρ + e``, ``e ~ N(0, σ²)``, for m beacons.

    Attributes:
        beacon_addresses: Beacon of each link, shape (m,), the map's column order.
        sigma_m: Range noise σ per link, metres (after the bias/scale correction).
        bias_m: Range bias per link, metres (0 where not estimated).
        scale: Range scale per link (1 where not estimated).
        bias_sd_m: Standard deviation of each bias estimate, metres (NaN if not estimated).
        scale_sd: Standard deviation of each scale estimate (NaN if not estimated).
        n_residuals: Residuals each link's σ was learned from (0 if not learned).
        source: Where σ comes from (:class:`NoiseSource`).
        hedge_address: The hedgehog these links belong to, when known.
        link_covariance_m2: Covariance of the link errors (m, m), m², when the run's residuals
            show them correlated (:func:`omnical.ips.solve.linkcov.learn_link_covariance`);
            None: independent, σ².
        widening: Average widening of the fix covariances by the learned link covariance,
            ``tr(C_indep⁻¹ C_Σ) / dims`` (NaN if not measured).
        widening_sd: Jackknife standard error of :attr:`widening` (NaN if not measured).
        link_covariance_z: Standard errors by which the learned link covariance predicts
            held-out blocks of the run better than independent errors (NaN if not measured).
        calibration_covariance: Covariance (2m, 2m) of the errors of the bias (m, first m
            entries) and of the scale (relative, last m) per link, a block jackknife over the
            run; None where not measured.
        calibration_widening: Average ``tr(C_indep⁻¹ C_Γ) / dims`` the calibration's
            uncertainty adds to the fix covariances (NaN if not measured).
    """

    beacon_addresses: NDArray[np.int64]
    sigma_m: NDArray[np.float64]
    bias_m: NDArray[np.float64]
    scale: NDArray[np.float64]
    bias_sd_m: NDArray[np.float64]
    scale_sd: NDArray[np.float64]
    n_residuals: NDArray[np.int64]
    source: NoiseSource = NoiseSource.PRIOR
    hedge_address: int | None = None
    link_covariance_m2: NDArray[np.float64] | None = None
    widening: float = float("nan")
    widening_sd: float = float("nan")
    link_covariance_z: float = float("nan")
    calibration_covariance: NDArray[np.float64] | None = None
    calibration_widening: float = float("nan")

    def __post_init__(self) -> None:
        for name, dtype in (
            ("beacon_addresses", np.int64),
            ("sigma_m", np.float64),
            ("bias_m", np.float64),
            ("scale", np.float64),
            ("bias_sd_m", np.float64),
            ("scale_sd", np.float64),
            ("n_residuals", np.int64),
        ):
            object.__setattr__(self, name, _frozen(getattr(self, name), dtype))
        m = self.beacon_addresses.size
        for name in ("sigma_m", "bias_m", "scale", "bias_sd_m", "scale_sd", "n_residuals"):
            if getattr(self, name).size != m:
                msg = f"NoiseModel: {name} must have {m} entries, got {getattr(self, name).size}"
                raise ValueError(msg)
        for name, size in (("link_covariance_m2", m), ("calibration_covariance", 2 * m)):
            if getattr(self, name) is None:
                continue
            covariance = np.array(getattr(self, name), dtype=np.float64)
            if covariance.shape != (size, size):
                msg = f"NoiseModel: {name} must have shape ({size}, {size}), got {covariance.shape}"
                raise ValueError(msg)
            covariance.setflags(write=False)
            object.__setattr__(self, name, covariance)

    @classmethod
    def uniform(
        cls,
        beacon_addresses: ArrayLike,
        sigma_m: float | ArrayLike,
        source: NoiseSource = NoiseSource.PRIOR,
        hedge_address: int | None = None,
    ) -> NoiseModel:
        """A model with no bias, unit scale and the given σ (scalar or per link)."""
        addresses = np.asarray(beacon_addresses, dtype=np.int64).reshape(-1)
        m = addresses.size
        nan = np.full(m, np.nan)
        return cls(
            addresses,
            np.broadcast_to(np.asarray(sigma_m, dtype=np.float64), (m,)).copy(),
            np.zeros(m),
            np.ones(m),
            nan,
            nan.copy(),
            np.zeros(m, dtype=np.int64),
            source,
            hedge_address,
        )

    @property
    def bias_estimated(self) -> NDArray[np.bool_]:
        """Links whose bias was estimated, shape (m,)."""
        mask: NDArray[np.bool_] = np.isfinite(self.bias_sd_m)
        return mask

    @property
    def scale_estimated(self) -> NDArray[np.bool_]:
        """Links whose scale was estimated, shape (m,)."""
        mask: NDArray[np.bool_] = np.isfinite(self.scale_sd)
        return mask

    @property
    def calibrated(self) -> bool:
        """Whether any bias or scale was estimated."""
        return bool(np.any(self.bias_estimated) or np.any(self.scale_estimated))

    def correct(self, distances_m: ArrayLike) -> NDArray[np.float64]:
        """Return ``(d − bias) / scale`` for distances (n, m) in the model's column order."""
        d = np.asarray(distances_m, dtype=np.float64)
        corrected: NDArray[np.float64] = (d - self.bias_m) / self.scale
        return corrected

    def describe(self) -> list[str]:
        """Human-readable lines: one summary line, then one line per link."""
        hedge = f"hedgehog {self.hedge_address}: " if self.hedge_address is not None else ""
        sigma = self.sigma_m
        if self.source is NoiseSource.LEARNED:
            what = f"range noise learned from the recording, σ {_span(sigma * 100)} cm"
        elif self.source is NoiseSource.GIVEN:
            what = f"range noise fixed at σ {_span(sigma * 100)} cm"
        else:
            what = f"range noise prior σ {_span(sigma * 100)} cm (not learned)"
        if self.calibrated:
            what += (
                f"; self-calibrated bias on {int(self.bias_estimated.sum())} and scale on "
                f"{int(self.scale_estimated.sum())} of {sigma.size} links"
            )
        lines = [hedge + what]
        if self.link_covariance_m2 is not None:
            lines.append(
                "  the link errors are correlated (the run's residuals show it, in standard "
                f"errors: widening {(self.widening - 1.0) / self.widening_sd:.1f}, held-out fit "
                f"{self.link_covariance_z:.1f}): position variances × {self.widening:.2f} ± "
                f"{self.widening_sd:.2f} on average (ellipse axes × {np.sqrt(self.widening):.2f})"
            )
        if self.calibration_covariance is not None:
            lines.append(
                "  the run determines each link's bias and scale only so well (jackknife over "
                f"the run): position variances + {self.calibration_widening:.2f} × the range "
                "noise's on average"
            )
        if self.source is NoiseSource.LEARNED or self.calibrated:
            for k, address in enumerate(self.beacon_addresses):
                bias = (
                    f"bias {self.bias_m[k] * 100:+.1f} ± {self.bias_sd_m[k] * 100:.1f} cm"
                    if self.bias_estimated[k]
                    else "bias not estimated"
                )
                scale = (
                    f"scale {self.scale[k]:.4f} ± {self.scale_sd[k]:.4f}"
                    if self.scale_estimated[k]
                    else "scale not estimated"
                )
                lines.append(
                    f"  beacon {int(address)}: σ {sigma[k] * 100:.1f} cm "
                    f"({int(self.n_residuals[k])} residuals), {bias}, {scale}"
                )
        return lines


def _span(values_cm: NDArray[np.float64]) -> str:
    lo, hi = float(np.min(values_cm)), float(np.max(values_cm))
    return f"{lo:.1f}" if abs(hi - lo) < 0.05 else f"{lo:.1f}–{hi:.1f}"
