"""Beacon map: the stationary beacons of an indoor positioning system, in the ``map`` frame.

Use :func:`load_beacon_map` / :func:`save_beacon_map` (YAML), :func:`beacon_map_from_rows`
(``/beacons_pos_a``) or :func:`default_beacon_map` (seed 000); layout in docs/locate.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.userfiles import read_yaml

if TYPE_CHECKING:
    from pydantic import BaseModel

__all__ = [
    "ADDRESS_RANGE",
    "MAX_HEDGE_Z_M",
    "BeaconMap",
    "beacon_map_from_rows",
    "default_beacon_map",
    "load_beacon_map",
    "save_beacon_map",
]


ADDRESS_RANGE: Final = (1, 255)
"""Addresses of Marvelmind devices: one byte on the wire, 0 marking an empty slot."""
MAX_HEDGE_Z_M: Final = 100.0
"""Largest |height| of a hedgehog, m: a beacon map's ``hedges`` and ``--hedge-z``."""


def _readonly(array: NDArray[Any]) -> NDArray[Any]:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class BeaconMap:
    """Stationary beacons (addresses and positions) and known hedgehog heights.

    Attributes:
        addresses: Beacon addresses, shape (n,), int64, unique. The column order of every
            distance matrix built against this map.
        positions_m: Beacon positions in the ``map`` frame, shape (n, 3), metres.
        hedge_addresses: Addresses of mobile beacons whose height is known, shape (k,).
        hedge_z_m: Height of each of those mobile beacons in the ``map`` frame, shape (k,), m.
    """

    addresses: NDArray[np.int64]
    positions_m: NDArray[np.float64]
    hedge_addresses: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    hedge_z_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0, dtype=np.float64))

    def __post_init__(self) -> None:
        addresses = np.array(self.addresses, dtype=np.int64).reshape(-1)
        positions = np.array(self.positions_m, dtype=np.float64)
        if positions.ndim != 2 or positions.shape != (addresses.size, 3):
            msg = (
                f"BeaconMap: positions_m must have shape ({addresses.size}, 3) to match "
                f"{addresses.size} addresses, got {positions.shape}"
            )
            raise ConfigError(msg)
        _check_unique("addresses", addresses)
        if not np.all(np.isfinite(positions)):
            bad = addresses[~np.all(np.isfinite(positions), axis=1)].tolist()
            msg = f"BeaconMap: positions_m of beacons {bad} are not finite"
            raise ConfigError(msg)
        hedges = np.array(self.hedge_addresses, dtype=np.int64).reshape(-1)
        hedge_z = np.array(self.hedge_z_m, dtype=np.float64).reshape(-1)
        if hedges.shape != hedge_z.shape:
            msg = f"BeaconMap: {hedges.size} hedge_addresses but {hedge_z.size} hedge_z_m values"
            raise ConfigError(msg)
        _check_unique("hedge_addresses", hedges)
        if not np.all(np.isfinite(hedge_z)):
            msg = f"BeaconMap: hedge_z_m must be finite, got {hedge_z.tolist()}"
            raise ConfigError(msg)
        object.__setattr__(self, "addresses", _readonly(addresses))
        object.__setattr__(self, "positions_m", _readonly(positions))
        object.__setattr__(self, "hedge_addresses", _readonly(hedges))
        object.__setattr__(self, "hedge_z_m", _readonly(hedge_z))

    def __len__(self) -> int:
        """Return the number of stationary beacons."""
        return int(self.addresses.size)

    def __eq__(self, other: object) -> bool:
        """Compare addresses, positions and hedge heights exactly."""
        if not isinstance(other, BeaconMap):
            return NotImplemented
        return (
            np.array_equal(self.addresses, other.addresses)
            and np.array_equal(self.positions_m, other.positions_m)
            and np.array_equal(self.hedge_addresses, other.hedge_addresses)
            and np.array_equal(self.hedge_z_m, other.hedge_z_m)
        )

    __hash__ = None  # type: ignore[assignment]

    def index_of(self, addresses: ArrayLike) -> NDArray[np.intp]:
        """Return the column index of each address, or -1 where the address is not in the map.

        Args:
            addresses: Beacon addresses, any shape.

        Returns:
            Indices into :attr:`addresses`, same shape as the input, -1 for unknown addresses.
        """
        query = np.asarray(addresses, dtype=np.int64)
        if self.addresses.size == 0:
            return np.full(query.shape, -1, dtype=np.intp)
        order = np.argsort(self.addresses, kind="stable")
        sorted_addresses = self.addresses[order]
        slot = np.clip(np.searchsorted(sorted_addresses, query), 0, sorted_addresses.size - 1)
        found = sorted_addresses[slot] == query
        return np.where(found, order[slot], -1).astype(np.intp)

    def hedge_height_m(self, address: int) -> float | None:
        """Return the known height of a mobile beacon in metres, or None if it is not known."""
        hit = np.flatnonzero(self.hedge_addresses == address)
        return float(self.hedge_z_m[hit[0]]) if hit.size else None


def _check_unique(name: str, addresses: NDArray[np.int64]) -> None:
    values, counts = np.unique(addresses, return_counts=True)
    if np.any(counts > 1):
        msg = f"BeaconMap: {name} must be unique, repeated: {values[counts > 1].tolist()}"
        raise ConfigError(msg)


def default_beacon_map() -> BeaconMap:
    """Return the beacon map of seed 000, Table 3.

    Stationary beacons 3, 4, 5, 6 at (0, 0), (5.767, 0), (0.485, 4.809), (5.445, 4.813) m,
    all at z = 0.4 m; hedgehog 10 at z = 0.4 m.
    """
    return BeaconMap(
        addresses=np.array([3, 4, 5, 6], dtype=np.int64),
        positions_m=np.array(
            [
                [0.000, 0.000, 0.400],
                [5.767, 0.000, 0.400],
                [0.485, 4.809, 0.400],
                [5.445, 4.813, 0.400],
            ],
        ),
        hedge_addresses=np.array([10], dtype=np.int64),
        hedge_z_m=np.array([0.400]),
    )


def beacon_map_from_rows(
    address: ArrayLike,
    x_m: ArrayLike,
    y_m: ArrayLike,
    z_m: ArrayLike,
    *,
    t_ns: ArrayLike | None = None,
    hedges: BeaconMap | None = None,
) -> BeaconMap:
    """Build a map from ``/beacons_pos_a`` rows, keeping the latest row of each address.

    Args:
        address: Beacon address of each row, shape (r,).
        x_m: x of each row, shape (r,), metres (``map`` frame).
        y_m: y of each row, shape (r,), metres.
        z_m: z of each row, shape (r,), metres.
        t_ns: Optional receive time of each row, shape (r,), ns. Without it the rows are taken
            to be in time order and the last row of an address wins.
        hedges: Optional map whose hedgehog heights are carried over.

    Returns:
        A map with one beacon per distinct address, sorted by address.

    Raises:
        ConfigError: If the arrays differ in length or a kept position is not finite.
    """
    columns = [np.asarray(a).reshape(-1) for a in (address, x_m, y_m, z_m)]
    if t_ns is not None:
        columns.append(np.asarray(t_ns).reshape(-1))
    lengths = {c.size for c in columns}
    if len(lengths) != 1:
        msg = f"beacon_map_from_rows: arrays differ in length: {[c.size for c in columns]}"
        raise ConfigError(msg)
    addresses = columns[0].astype(np.int64)
    order = (
        np.argsort(columns[4].astype(np.int64), kind="stable")
        if t_ns is not None
        else np.arange(addresses.size)
    )
    # Walk the rows newest first: np.unique returns the first hit, i.e. the latest row.
    newest_first = order[::-1]
    kept_addresses, first = np.unique(addresses[newest_first], return_index=True)
    rows = newest_first[first]
    positions = np.stack([c[rows].astype(np.float64) for c in columns[1:4]], axis=1)
    return BeaconMap(
        addresses=kept_addresses,
        positions_m=positions,
        hedge_addresses=hedges.hedge_addresses if hedges else np.zeros(0, dtype=np.int64),
        hedge_z_m=hedges.hedge_z_m if hedges else np.zeros(0),
    )


@lru_cache(maxsize=1)
def _map_file_model() -> type[BaseModel]:
    """The pydantic model of a beacon map file, defined on first use (pydantic is slow to load)."""
    from pydantic import BaseModel, ConfigDict, Field, field_validator
    from pydantic_core import PydanticCustomError

    def marvelmind_address(value: int) -> int:
        if not ADDRESS_RANGE[0] <= value <= ADDRESS_RANGE[1]:
            lo, hi = ADDRESS_RANGE
            reason = f"a Marvelmind address is {lo} to {hi} (0 marks an empty slot), got {value}"
            raise PydanticCustomError("address_range", reason)
        return value

    class _BeaconEntry(BaseModel):
        model_config = ConfigDict(extra="forbid", strict=False)
        address: int
        position_m: list[float]

        _address = field_validator("address")(marvelmind_address)

        @field_validator("position_m")
        @classmethod
        def _three_finite(cls, value: list[float]) -> list[float]:
            if len(value) != 3:
                msg = f"expected 3 numbers [x, y, z] in metres, got {len(value)}"
                raise ValueError(msg)
            if not all(np.isfinite(value)):
                msg = f"must be finite, got {value}"
                raise ValueError(msg)
            return value

    class _HedgeEntry(BaseModel):
        model_config = ConfigDict(extra="forbid")
        address: int
        z_m: float = Field(allow_inf_nan=False)

        _address = field_validator("address")(marvelmind_address)

        @field_validator("z_m")
        @classmethod
        def _height(cls, value: float) -> float:
            if abs(value) > MAX_HEDGE_Z_M:
                reason = (
                    f"the hedgehog's height must lie within ±{MAX_HEDGE_Z_M:g} m "
                    f"(as --hedge-z), got {value:g}"
                )
                raise PydanticCustomError("hedge_height", reason)
            return value

    class _BeaconMapFile(BaseModel):
        model_config = ConfigDict(extra="forbid")
        beacons: list[_BeaconEntry] = Field(min_length=1)
        hedges: list[_HedgeEntry] = Field(default_factory=list)

    return _BeaconMapFile


def _field_path(location: Sequence[int | str]) -> str:
    path = ""
    for part in location:
        path += f"[{part}]" if isinstance(part, int) else (f".{part}" if path else str(part))
    return path or "<top level>"


def load_beacon_map(path: str | Path) -> BeaconMap:
    """Load and validate a beacon map from a YAML file.

    Args:
        path: YAML file with a ``beacons`` list (``address``, ``position_m``) and an optional
            ``hedges`` list (``address``, ``z_m``); see the module docstring.

    Returns:
        The beacon map, beacons in file order.

    Raises:
        ConfigError: If the file cannot be read or parsed, or a field is missing or invalid;
            the message names the file, the field and the reason.
    """
    file = Path(path)
    document = read_yaml(file, "beacon map")
    from pydantic import ValidationError

    try:
        parsed: Any = _map_file_model().model_validate(document)
    except ValidationError as err:
        first = err.errors()[0]
        msg = f"{file}: {_field_path(first['loc'])}: {first['msg']}"
        if err.error_count() > 1:
            msg += f" (and {err.error_count() - 1} more problems)"
        raise ConfigError(msg) from None
    try:
        return BeaconMap(
            addresses=np.array([b.address for b in parsed.beacons], dtype=np.int64),
            positions_m=np.array([b.position_m for b in parsed.beacons], dtype=np.float64),
            hedge_addresses=np.array([h.address for h in parsed.hedges], dtype=np.int64),
            hedge_z_m=np.array([h.z_m for h in parsed.hedges], dtype=np.float64),
        )
    except ConfigError as err:
        msg = f"{file}: {err}"
        raise ConfigError(msg) from None


def save_beacon_map(beacons: BeaconMap, path: str | Path) -> None:
    """Write a beacon map as YAML in the layout :func:`load_beacon_map` reads."""
    document = {
        "beacons": [
            {"address": int(a), "position_m": [float(v) for v in p]}
            for a, p in zip(beacons.addresses, beacons.positions_m, strict=True)
        ],
        "hedges": [
            {"address": int(a), "z_m": float(z)}
            for a, z in zip(beacons.hedge_addresses, beacons.hedge_z_m, strict=True)
        ],
    }
    Path(path).write_text(yaml.safe_dump(document, sort_keys=False), encoding="utf-8")
