"""Parameters of the simulated Marvelmind IPS (non-inverse architecture) and its NLOS zones.

*assumption* marks a number the vendor does not publish; the sources of the defaults are in
docs/DESIGN-NOTES.md. Override them from YAML with :meth:`IpsParams.from_mapping`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from itertools import pairwise
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError

__all__ = ["IpsParams", "NlosZone"]

ZoneShape = Literal["rectangle", "circle"]


@dataclass(frozen=True)
class NlosZone:
    """A map-frame area where one beacon hears only a wall reflection of the hedgehog.

    Seed 000 §2.4. Inside the zone every distance to ``beacon_address`` is the true distance
    plus ``bias_m``, plus the usual noise.

    Attributes:
        beacon_address: address of the stationary beacon that loses line of sight.
        shape: ``"rectangle"`` or ``"circle"``.
        bounds_m: rectangle ``(x_min, y_min, x_max, y_max)`` or circle ``(x_c, y_c, radius)``,
            m in the map frame; tested against the hedgehog's x, y.
        bias_m: extra path length of the reflection, m ≥ 0 (*assumption*).
    """

    beacon_address: int
    shape: ZoneShape
    bounds_m: tuple[float, ...]
    bias_m: float = 0.45

    def __post_init__(self) -> None:
        _check_address("nlos_zones.beacon", self.beacon_address)
        if self.shape == "rectangle":
            if len(self.bounds_m) != 4:
                msg = "nlos_zones.rectangle: needs 4 numbers (x_min, y_min, x_max, y_max)"
                raise ConfigError(msg)
            x0, y0, x1, y1 = self.bounds_m
            if not (x0 < x1 and y0 < y1):
                msg = (
                    "nlos_zones.rectangle: needs x_min < x_max and y_min < y_max, "
                    f"got {self.bounds_m}"
                )
                raise ConfigError(msg)
        elif self.shape == "circle":
            if len(self.bounds_m) != 3:
                msg = "nlos_zones.circle: needs 3 numbers (x_c, y_c, radius)"
                raise ConfigError(msg)
            if not self.bounds_m[2] > 0.0:
                msg = f"nlos_zones.circle: radius must be > 0, got {self.bounds_m[2]}"
                raise ConfigError(msg)
        else:
            msg = f"nlos_zones.shape: must be 'rectangle' or 'circle', got {self.shape!r}"
            raise ConfigError(msg)
        if not all(math.isfinite(v) for v in self.bounds_m):
            msg = f"nlos_zones.{self.shape}: bounds must be finite, got {self.bounds_m}"
            raise ConfigError(msg)
        if not (math.isfinite(self.bias_m) and self.bias_m >= 0.0):
            msg = f"nlos_zones.bias_m: must be a finite bias >= 0 m, got {self.bias_m}"
            raise ConfigError(msg)

    @classmethod
    def rectangle(
        cls,
        beacon_address: int,
        x_min: float,
        y_min: float,
        x_max: float,
        y_max: float,
        bias_m: float = 0.45,
    ) -> NlosZone:
        """An axis-aligned rectangle in the map frame (metres)."""
        return cls(beacon_address, "rectangle", (x_min, y_min, x_max, y_max), bias_m)

    @classmethod
    def circle(
        cls, beacon_address: int, x_c: float, y_c: float, radius: float, bias_m: float = 0.45
    ) -> NlosZone:
        """A disc in the map frame (metres)."""
        return cls(beacon_address, "circle", (x_c, y_c, radius), bias_m)

    @classmethod
    def from_mapping(cls, data: Mapping[str, object]) -> NlosZone:
        """Build from ``{beacon: 4, rectangle: [x0, y0, x1, y1], bias_m: 0.4}`` (or ``circle``).

        A circle is given as ``circle: [x_c, y_c, radius]``.

        Raises:
            ConfigError: unknown key, missing or double shape, or a bad value.
        """
        allowed = {"beacon", "rectangle", "circle", "bias_m"}
        for key in data:
            if key not in allowed:
                msg = f"nlos_zones: unknown key {key!r} (allowed: {', '.join(sorted(allowed))})"
                raise ConfigError(msg)
        if "beacon" not in data:
            msg = "nlos_zones: missing key 'beacon'"
            raise ConfigError(msg)
        shapes = [s for s in ("rectangle", "circle") if s in data]
        if len(shapes) != 1:
            msg = "nlos_zones: give exactly one of 'rectangle' or 'circle'"
            raise ConfigError(msg)
        shape: ZoneShape = "rectangle" if shapes[0] == "rectangle" else "circle"
        bounds = _float_tuple(f"nlos_zones.{shape}", data[shape], None)
        bias = _as_float("nlos_zones.bias_m", data.get("bias_m", 0.45))
        return cls(_as_int("nlos_zones.beacon", data["beacon"]), shape, bounds, bias)

    def contains(self, x_m: ArrayLike, y_m: ArrayLike) -> NDArray[np.bool_]:
        """Whether map points lie in the zone (boundary included).

        Args:
            x_m: (M,) x in the map frame, m.
            y_m: (M,) y in the map frame, m.

        Returns:
            (M,) boolean mask.
        """
        x = np.asarray(x_m, dtype=np.float64)
        y = np.asarray(y_m, dtype=np.float64)
        if self.shape == "rectangle":
            x0, y0, x1, y1 = self.bounds_m
            return np.asarray((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1), dtype=np.bool_)
        xc, yc, r = self.bounds_m
        return np.asarray((x - xc) ** 2 + (y - yc) ** 2 <= r * r, dtype=np.bool_)


@dataclass(frozen=True)
class IpsParams:
    """How the simulated Marvelmind system measures, fails and reports.

    Geometry and protocol:
        hedge_address: address of the mobile beacon (hedgehog); 10 as in seed 000 Table 3.
        hedge_offset_base_m: hedgehog (x, y, z) in base_link, m; z its height above the floor
            (seed 000 Table 3: 0.4 m).
        max_beacons: beacons of the serving submap (nearest ones), 1–4 [MAN p.28; IF p.22].
        max_range_m: ultrasound range, m; farther beacons return no distance [MAN p.5–6].
        min_beacons_for_fix: distances needed for a fix; fewer gives a position packet with
            flags bit 0 set [IF p.15].

    Update rate and timing (the law: ``ips_model.measurement_rate_hz``):
        rate_knots: (largest beacon spacing m, rate Hz) pairs, spacing increasing, rate not
            increasing [seed 000 §2.1; MAN p.6, p.36; manual §9.4].
        rate_min_hz: lowest rate, Hz, at least 0.5 [IF p.48].
        hedgehog_count: mobiles sharing the ultrasound by TDMA, each at 1/count of the rate
            [MAN p.6].
        timing_jitter_s: half-width of the uniform jitter of emission times, s, ≤ 1
            (*assumption*).
        latency_s, latency_periods: the position packet's bag time is emission time +
            ``latency_s`` + ``latency_periods`` / rate [manual §9.4]; ≤ 10 s and ≤ 10 periods.
        burst_gap_s: (min, max) gap between consecutive messages of a burst and between
            beacon-position messages, s, ≤ 1 (*assumption*).
        device_uptime_at_start_s: time since the hedgehog woke up at the first trajectory
            sample, s, ≤ 2³² ms; ``timestamp_ms`` counts from wake-up [IF p.16] (*assumption*).
        beacon_repeat_period_s: period of the stationary beacon positions, s, ≤ 3600 [IF p.18].
        beacon_first_s: first beacon-position burst after the first trajectory sample, s,
            ≤ 3600.

    Distances (time of flight):
        distance_noise_m: constant part of the standard deviation, m [MAN p.5: ±2 cm].
        distance_noise_fraction: part of the standard deviation proportional to distance,
            dimensionless (*assumption*).
        temperature_error_c: assumed minus true air temperature, °C; distances scale by
            1 + ``sound_speed_fraction_per_c`` × this.
        sound_speed_fraction_per_c: per °C [manual §11.10: 0.17 % per °C].
        nlos_probability: chance that a single distance is a reflection (*assumption*).
        nlos_bias_range_m: (min, max) of the uniform positive bias of a reflection, m
            (*assumption*).
        nlos_zones: persistent reflection areas, see :class:`NlosZone`.
        measurement_drop_probability: chance that a whole measurement is lost by radio
            (*assumption*; MAN p.27).
        distance_drop_probability: chance that one beacon misses the pulse (*assumption*).
        quantize_mm: round distances and positions to whole mm, as the wire format
            [IF p.16, p.22].

    Vendor solution and quality:
        vendor_jitter_m: σ of extra Gaussian jitter per axis on the vendor position, m
            (*assumption*; seed 000 §2.4).
        vendor_outlier_rms_m: RMS range residual above which the vendor filters a fix (leaves
            out the beacon whose omission makes it consistent, else no fix), m; it also turns
            on the track filter (jumps > 0.2 m dropped). None: no filter.
        vendor_averaging_fixes: each reported fix is the causal mean of the last n fixes;
            1 for none (*assumption*).
        quality_residual_scale_m: residual RMS at which the quality's residual factor is
            e^-1, m (*assumption*).
        quality_hdop_good: HDOP at and below which geometry does not lower the quality
            (*assumption*).
    """

    hedge_address: int = 10
    hedge_offset_base_m: tuple[float, float, float] = (0.0, 0.0, 0.4)
    max_beacons: int = 4
    max_range_m: float = 30.0
    min_beacons_for_fix: int = 3
    rate_knots: tuple[tuple[float, float], ...] = ((7.5, 25.0), (11.0, 10.0), (30.0, 7.0))
    rate_min_hz: float = 0.5
    hedgehog_count: int = 1
    timing_jitter_s: float = 0.002
    latency_s: float = 0.010
    latency_periods: float = 1.0
    burst_gap_s: tuple[float, float] = (0.001, 0.003)
    device_uptime_at_start_s: float = 30.0
    beacon_repeat_period_s: float = 10.0
    beacon_first_s: float = 0.0
    distance_noise_m: float = 0.015
    distance_noise_fraction: float = 0.002
    temperature_error_c: float = 0.0
    sound_speed_fraction_per_c: float = 0.0017
    nlos_probability: float = 0.05
    nlos_bias_range_m: tuple[float, float] = (0.1, 1.0)
    nlos_zones: tuple[NlosZone, ...] = ()
    measurement_drop_probability: float = 0.01
    distance_drop_probability: float = 0.02
    quantize_mm: bool = True
    vendor_jitter_m: float = 0.005
    vendor_outlier_rms_m: float | None = 0.03
    vendor_averaging_fixes: int = 3
    quality_residual_scale_m: float = 0.1
    quality_hdop_good: float = 1.5

    def __post_init__(self) -> None:
        _check_address("hedge_address", self.hedge_address)
        _check_int_range("max_beacons", self.max_beacons, 1, 4)
        _check_int_range("min_beacons_for_fix", self.min_beacons_for_fix, 3, 4)
        _check_int_range("hedgehog_count", self.hedgehog_count, 1, 250)
        _check_int_range("vendor_averaging_fixes", self.vendor_averaging_fixes, 1, 100)
        if len(self.hedge_offset_base_m) != 3 or not all(
            math.isfinite(v) for v in self.hedge_offset_base_m
        ):
            msg = f"hedge_offset_base_m: needs 3 finite numbers, got {self.hedge_offset_base_m}"
            raise ConfigError(msg)
        for name in (
            "max_range_m",
            "rate_min_hz",
            "beacon_repeat_period_s",
            "quality_residual_scale_m",
            "quality_hdop_good",
        ):
            _check_number(name, getattr(self, name), positive=True)
        for name in (
            "timing_jitter_s",
            "latency_s",
            "latency_periods",
            "device_uptime_at_start_s",
            "beacon_first_s",
            "distance_noise_m",
            "distance_noise_fraction",
            "sound_speed_fraction_per_c",
            "vendor_jitter_m",
        ):
            _check_number(name, getattr(self, name), positive=False)
        _check_number("temperature_error_c", self.temperature_error_c, positive=False, signed=True)
        for name, most, why in _TIME_BOUNDS:
            _check_at_most(name, getattr(self, name), most, why)
        if self.rate_min_hz < _RATE_MIN_FLOOR_HZ:
            msg = (
                f"rate_min_hz: must be at least {_RATE_MIN_FLOOR_HZ} Hz (Marvelmind's slowest "
                f"update rate), got {self.rate_min_hz}"
            )
            raise ConfigError(msg)
        if self.vendor_outlier_rms_m is not None:
            _check_number("vendor_outlier_rms_m", self.vendor_outlier_rms_m, positive=True)
        for name in (
            "nlos_probability",
            "measurement_drop_probability",
            "distance_drop_probability",
        ):
            value = getattr(self, name)
            _check_number(name, value, positive=False)
            if value > 1.0:
                msg = f"{name}: a probability must be in [0, 1], got {value}"
                raise ConfigError(msg)
        for name in ("burst_gap_s", "nlos_bias_range_m"):
            lo, hi = getattr(self, name)
            _check_number(name, lo, positive=False)
            _check_number(name, hi, positive=False)
            if lo > hi:
                msg = f"{name}: needs min <= max, got ({lo}, {hi})"
                raise ConfigError(msg)
        _check_at_most("burst_gap_s", self.burst_gap_s[1], _BURST_GAP_MAX_S, "s")
        _check_rate_knots(self.rate_knots)
        if self.rate_min_hz > self.rate_max_hz:
            msg = f"rate_min_hz: {self.rate_min_hz} Hz exceeds the fastest rate knot"
            raise ConfigError(msg)
        if 2.0 * self.timing_jitter_s >= 1.0 / self.rate_max_hz:
            msg = (
                f"timing_jitter_s: {self.timing_jitter_s} s could reorder measurements; keep "
                f"it under half the shortest period ({0.5 / self.rate_max_hz} s)"
            )
            raise ConfigError(msg)
        for zone in self.nlos_zones:
            if not isinstance(zone, NlosZone):
                msg = f"nlos_zones: expected NlosZone entries, got {type(zone).__name__}"
                raise ConfigError(msg)

    @property
    def rate_max_hz(self) -> float:
        """Fastest measurement rate of one hedgehog alone (the first rate knot), Hz."""
        return self.rate_knots[0][1]

    @classmethod
    def ideal(cls, **overrides: object) -> IpsParams:
        """No noise, no outliers, no drops, no quantisation, no vendor filtering; timing and
        latency kept.

        Keyword overrides are applied on top (checked like :meth:`from_mapping`).
        """
        base = cls(
            timing_jitter_s=0.0,
            distance_noise_m=0.0,
            distance_noise_fraction=0.0,
            temperature_error_c=0.0,
            nlos_probability=0.0,
            nlos_zones=(),
            measurement_drop_probability=0.0,
            distance_drop_probability=0.0,
            quantize_mm=False,
            vendor_jitter_m=0.0,
            vendor_outlier_rms_m=None,
            vendor_averaging_fixes=1,
        )
        return base.with_overrides(overrides) if overrides else base

    @classmethod
    def from_mapping(cls, data: Mapping[str, object]) -> IpsParams:
        """Defaults overridden by a mapping (e.g. the ``ips:`` section of a twin YAML).

        Lists become tuples; ``nlos_zones`` is a list of :meth:`NlosZone.from_mapping` entries.

        Raises:
            ConfigError: an unknown key (named in the message) or a bad value.
        """
        return cls().with_overrides(data)

    def with_overrides(self, data: Mapping[str, object]) -> IpsParams:
        """A copy with the fields named in ``data`` replaced, checked as in :meth:`from_mapping`."""
        known = {f.name: getattr(self, f.name) for f in fields(self)}
        changes: dict[str, object] = {}
        for key, value in data.items():
            if key not in known:
                msg = f"ips: unknown key {key!r}"
                raise ConfigError(msg)
            changes[key] = _coerce(key, value, known[key])
        return replace(self, **changes)  # type: ignore[arg-type]


def _coerce(name: str, value: object, default: object) -> object:
    """Convert a YAML value to the type of the field's default, or raise ConfigError."""
    if name == "nlos_zones":
        if isinstance(value, Sequence) and not isinstance(value, str | bytes):
            zones = []
            for item in value:
                if isinstance(item, NlosZone):
                    zones.append(item)
                elif isinstance(item, Mapping):
                    zones.append(NlosZone.from_mapping(item))
                else:
                    msg = f"nlos_zones: each entry must be a mapping, got {type(item).__name__}"
                    raise ConfigError(msg)
            return tuple(zones)
        msg = f"nlos_zones: expected a list, got {type(value).__name__}"
        raise ConfigError(msg)
    if name == "vendor_outlier_rms_m" and value is None:
        return None  # no vendor filter
    if name == "rate_knots":
        if isinstance(value, Sequence) and not isinstance(value, str | bytes):
            return tuple(_float_tuple(name, pair, 2) for pair in value)
        msg = f"rate_knots: expected a list of [spacing_m, rate_hz] pairs, got {value!r}"
        raise ConfigError(msg)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            msg = f"{name}: expected true or false, got {value!r}"
            raise ConfigError(msg)
        return value
    if isinstance(default, int):
        return _as_int(name, value)
    if isinstance(default, float):
        return _as_float(name, value)
    if isinstance(default, tuple):
        return _float_tuple(name, value, len(default))
    msg = f"{name}: cannot be set from a mapping"  # pragma: no cover - every field is handled
    raise ConfigError(msg)


def _as_int(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        msg = f"{name}: expected an integer, got {value!r}"
        raise ConfigError(msg)
    return int(value)


def _as_float(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        msg = f"{name}: expected a number, got {value!r}"
        raise ConfigError(msg)
    return float(value)


def _float_tuple(name: str, value: object, length: int | None) -> tuple[float, ...]:
    if not isinstance(value, Sequence) or isinstance(value, str | bytes):
        msg = f"{name}: expected a list of numbers, got {value!r}"
        raise ConfigError(msg)
    if length is not None and len(value) != length:
        msg = f"{name}: expected {length} numbers, got {len(value)}"
        raise ConfigError(msg)
    return tuple(_as_float(name, v) for v in value)


_RATE_MIN_FLOOR_HZ = 0.5
"""Lowest ``rate_min_hz``: Marvelmind's slowest update-rate setting [IF p.48]; slower would
stretch ``latency_periods`` periods into minutes."""

_BURST_GAP_MAX_S = 1.0
"""Longest gap between the messages of a burst, s (they are ms apart)."""

_TIME_BOUNDS: tuple[tuple[str, float, str], ...] = (
    ("timing_jitter_s", 1.0, "s"),
    ("latency_s", 10.0, "s (Marvelmind's latency is about 0.1-0.5 s)"),
    ("latency_periods", 10.0, "measurement periods"),
    (
        "device_uptime_at_start_s",
        2**32 / 1000.0,
        "s (the uint32 millisecond timestamp wraps there)",
    ),
    ("beacon_repeat_period_s", 3600.0, "s"),
    ("beacon_first_s", 3600.0, "s"),
)
"""Upper bounds of the time-like fields: (name, largest value, unit and reason)."""


def _check_at_most(name: str, value: float, most: float, why: str) -> None:
    if value > most:
        msg = f"{name}: must be at most {most:g} {why}, got {value:g}"
        raise ConfigError(msg)


def _check_rate_knots(knots: tuple[tuple[float, float], ...]) -> None:
    if len(knots) == 0 or any(len(k) != 2 for k in knots):
        msg = "rate_knots: needs at least one (spacing_m, rate_hz) pair"
        raise ConfigError(msg)
    for spacing_m, rate_hz in knots:
        _check_number("rate_knots spacing", spacing_m, positive=False)
        _check_number("rate_knots rate", rate_hz, positive=True)
    for (s0, r0), (s1, r1) in pairwise(knots):
        if not (s1 > s0 and r1 <= r0):
            msg = f"rate_knots: spacing must increase and rate not increase, got {knots}"
            raise ConfigError(msg)


def _check_address(name: str, value: int) -> None:
    _check_int_range(name, value, 1, 255)


def _check_int_range(name: str, value: int, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        msg = f"{name}: must be an integer in [{lo}, {hi}], got {value!r}"
        raise ConfigError(msg)


def _check_number(name: str, value: float, *, positive: bool, signed: bool = False) -> None:
    if not math.isfinite(value):
        msg = f"{name}: must be finite, got {value}"
        raise ConfigError(msg)
    if positive and value <= 0.0:
        msg = f"{name}: must be > 0, got {value}"
        raise ConfigError(msg)
    if not signed and value < 0.0:
        msg = f"{name}: must be >= 0, got {value}"
        raise ConfigError(msg)
