"""ROS map_server maps: an image (PGM, or PNG/BMP through Pillow) and a YAML file.

Read as map_server does, written as map_saver does; the only file I/O of navigation, every fault
one :class:`~omnical.errors.ConfigError`, a map only within physical ranges.
"""

from __future__ import annotations

import io
import math
import stat
import warnings
from pathlib import Path
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError, OutputError
from omnical.navigation.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from omnical.userfiles import MAX_FILE_BYTES, file_kind, read_file_bytes, read_yaml

__all__ = [
    "FREE_THRESH",
    "MAX_MAP_CELLS",
    "MAX_ORIGIN_M",
    "OCCUPIED_THRESH",
    "RESOLUTION_RANGE_M",
    "SHIPPED_WORLDS",
    "load_map",
    "occupancy_from_image",
    "read_pgm",
    "resolve_world",
    "save_map",
    "write_pgm",
]

OCCUPIED_THRESH: Final = 0.65
FREE_THRESH: Final = 0.196
_MODES: Final = ("trinary", "scale", "raw")

RESOLUTION_RANGE_M: Final = (1e-3, 10.0)
"""Cell sides a map may give, m: 1 mm to 10 m (map_server maps are 1–10 cm)."""
MAX_ORIGIN_M: Final = 1e4
"""Largest |x|, |y| of a map's origin, m: 10 km, as a reference position."""
MAX_MAP_CELLS: Final = 4 * MAX_FILE_BYTES
"""Most pixels of a map image (64 Mi: 8192 × 8192), so a map's grids fit in memory."""


def _fail(path: Path, field: str, reason: str) -> ConfigError:
    where = f"{path}: {field}: " if field else f"{path}: "
    return ConfigError(where + reason)


def _number(path: Path, data: dict[str, Any], key: str, default: float | None = None) -> float:
    if key not in data:
        if default is None:
            raise _fail(path, key, "missing (required by map_server)")
        return default
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise _fail(path, key, f"expected a finite number, got {value!r}")
    return float(value)


def _tokens(data: bytes, count: int, path: Path) -> tuple[list[bytes], int]:
    """The first ``count`` whitespace-separated header tokens (comments skipped) and the offset."""
    tokens: list[bytes] = []
    i, n = 0, len(data)
    while len(tokens) < count:
        while i < n and data[i : i + 1].isspace():
            i += 1
        if i < n and data[i : i + 1] == b"#":
            while i < n and data[i : i + 1] not in (b"\n", b"\r"):
                i += 1
            continue
        if i >= n:
            raise _fail(path, "", "truncated PGM header")
        j = i
        while j < n and not data[j : j + 1].isspace() and data[j : j + 1] != b"#":
            j += 1
        tokens.append(data[i:j])
        i = j
    return tokens, i


def read_pgm(path: str | Path) -> NDArray[np.uint8]:
    """The 8-bit grey image of a PGM file (P5 binary or P2 ASCII; 16-bit values scaled to 8 bits).

    Raises:
        ConfigError: missing, unreadable, too large, not a PGM, truncated.
    """
    p = Path(path)
    return _pgm(_read_bytes(p), p)


def _pgm(data: bytes, p: Path) -> NDArray[np.uint8]:
    """The image of PGM bytes (:func:`read_pgm`); ``p`` names the file in messages."""
    if data[:2] not in (b"P5", b"P2"):
        raise _fail(p, "", f"not a PGM image (magic {data[:2]!r}, expected P5 or P2)")
    tokens, offset = _tokens(data, 4, p)
    try:
        width, height, maxval = (int(t) for t in tokens[1:4])
    except ValueError:
        raise _fail(
            p, "", f"bad PGM header {b' '.join(tokens).decode(errors='replace')!r}"
        ) from None
    if width < 1 or height < 1 or not 0 < maxval < 65536:
        raise _fail(p, "", f"bad PGM size {width}x{height} or maxval {maxval}")
    if width * height > MAX_MAP_CELLS:
        raise _fail(p, "", f"{width}x{height} pixels is too large a map (at most {MAX_MAP_CELLS})")
    if tokens[0] == b"P5":
        body = data[offset + 1 :]
        itemsize = 1 if maxval < 256 else 2
        need = width * height * itemsize
        if len(body) < need:
            raise _fail(p, "", f"truncated PGM: {len(body)} of {need} pixel bytes")
        dtype = np.uint8 if itemsize == 1 else np.dtype(">u2")
        values = np.frombuffer(body[:need], dtype=dtype).astype(np.float64)
    else:
        words = data[offset:].split()
        if len(words) < width * height:
            raise _fail(p, "", f"truncated PGM: {len(words)} of {width * height} pixels")
        try:
            values = np.array([int(w) for w in words[: width * height]], dtype=np.float64)
        except ValueError:
            raise _fail(p, "", "non-numeric pixel in an ASCII PGM") from None
    if maxval != 255:
        values = np.round(values * (255.0 / maxval))
    return np.clip(values, 0, 255).astype(np.uint8).reshape(height, width)


def _read_bytes(p: Path) -> bytes:
    """The bytes of a map image: a regular file of at most 4 × MAX_FILE_BYTES, read bounded."""
    return read_file_bytes(p, "map image", 4 * MAX_FILE_BYTES)


def _read_image(p: Path) -> NDArray[np.uint8]:
    data = _read_bytes(p)
    if p.suffix.lower() in (".pgm", ".pnm") or data[:2] in (b"P5", b"P2"):
        return _pgm(data, p)
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError:  # pragma: no cover - Pillow comes with matplotlib
        raise _fail(p, "", "only PGM images can be read without Pillow") from None
    too_large = f"too large a map image (at most {MAX_MAP_CELLS} pixels)"
    try:
        with warnings.catch_warnings():  # Pillow's warning of a decompression bomb: refused
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as img:
                width, height = img.size
                if width * height > MAX_MAP_CELLS:
                    raise _fail(p, "", f"{width}x{height} pixels is {too_large}")
                grey = np.asarray(img.convert("L"), dtype=np.uint8)
    except (Image.DecompressionBombWarning, Image.DecompressionBombError):
        raise _fail(p, "", too_large) from None
    except ConfigError:
        raise
    except UnidentifiedImageError:  # its message names Pillow's BytesIO, not the file
        raise _fail(p, "", "not a PGM or PNG image (nor another format Pillow reads)") from None
    except (OSError, ValueError) as err:
        raise _fail(p, "", f"cannot read the image: {err}") from None
    return grey


def _check_image_file(p: Path, image_path: Path) -> None:
    """The map's ``image`` names a regular file (not a directory, a FIFO, a device)."""
    try:
        mode = image_path.stat().st_mode
    except FileNotFoundError:
        raise _fail(p, "image", f"{image_path} does not exist") from None
    except OSError as err:
        raise _fail(p, "image", f"{image_path}: cannot read: {err.strerror or err}") from None
    if stat.S_ISDIR(mode):
        raise _fail(p, "image", f"{image_path} is a directory, not an image file")
    if not stat.S_ISREG(mode):
        raise _fail(p, "image", f"{image_path} is not a regular file ({file_kind(mode)})")


def occupancy_from_image(
    image: NDArray[np.uint8],
    *,
    negate: bool = False,
    occupied_thresh: float = OCCUPIED_THRESH,
    free_thresh: float = FREE_THRESH,
    mode: str = "trinary",
) -> NDArray[np.int8]:
    """map_server's reading of an image (top row first) → cells (bottom row first)."""
    v = np.asarray(image, dtype=np.float64)
    if mode == "raw":
        raw = 255.0 - v if negate else v
        cells = np.full(v.shape, UNKNOWN, dtype=np.int8)
        cells[raw == 0] = FREE
        cells[raw == 100] = OCCUPIED
        return cells[::-1].copy()
    occ = v / 255.0 if negate else (255.0 - v) / 255.0
    cells = np.full(v.shape, UNKNOWN, dtype=np.int8)
    cells[occ > occupied_thresh] = OCCUPIED
    cells[occ < free_thresh] = FREE
    return cells[::-1].copy()


def load_map(path: str | Path) -> OccupancyGrid:
    """Load a map_server map (YAML + image).

    Raises:
        ConfigError: ``file: field: reason`` for a missing or bad YAML field, a missing or
            unreadable image, or an image that is not a map.
    """
    p = Path(path)
    data = read_yaml(p, "map YAML file")
    if not isinstance(data, dict):
        raise _fail(p, "", f"expected a mapping of map_server fields, got {type(data).__name__}")
    if "image" not in data:
        raise _fail(p, "image", "missing (required by map_server)")
    image = data["image"]
    if not isinstance(image, str) or not image.strip():
        raise _fail(p, "image", f"expected a file name, got {image!r}")
    resolution = _number(p, data, "resolution")
    low, high = RESOLUTION_RANGE_M
    if not low <= resolution <= high:
        raise _fail(p, "resolution", f"must be {low:g} to {high:g} m per cell, got {resolution:g}")
    origin = data.get("origin")
    if (
        not isinstance(origin, list)
        or len(origin) != 3
        or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in origin
        )
    ):
        raise _fail(p, "origin", f"expected [x, y, yaw] (3 finite numbers), got {origin!r}")
    if max(abs(origin[0]), abs(origin[1])) > MAX_ORIGIN_M or abs(origin[2]) > 2.0 * math.pi:
        raise _fail(
            p,
            "origin",
            f"x, y must lie within ±{MAX_ORIGIN_M:g} m and yaw within ±2π rad, got {origin!r}",
        )
    negate = data.get("negate", 0)
    if negate not in (0, 1) or isinstance(negate, float):
        raise _fail(p, "negate", f"expected 0 or 1, got {negate!r}")
    occ_th = _number(p, data, "occupied_thresh")
    free_th = _number(p, data, "free_thresh")
    if not 0.0 <= free_th < occ_th <= 1.0:
        raise _fail(
            p,
            "free_thresh",
            f"need 0 <= free_thresh < occupied_thresh <= 1, got {free_th}, {occ_th}",
        )
    mode = data.get("mode", "trinary")
    if mode not in _MODES:
        raise _fail(p, "mode", f"expected one of {', '.join(_MODES)}, got {mode!r}")
    image_path = Path(image) if Path(image).is_absolute() else p.parent / image
    _check_image_file(p, image_path)
    pixels = _read_image(image_path)
    cells = occupancy_from_image(
        pixels,
        negate=bool(negate),
        occupied_thresh=occ_th,
        free_thresh=free_th,
        mode=str(mode),
    )
    return OccupancyGrid(cells, resolution, (float(origin[0]), float(origin[1]), float(origin[2])))


def write_pgm(path: str | Path, image: NDArray[np.uint8]) -> None:
    """Write an 8-bit grey image (top row first) as a P5 PGM."""
    img = np.asarray(image, dtype=np.uint8)
    header = f"P5\n# omnical\n{img.shape[1]} {img.shape[0]}\n255\n".encode("ascii")
    try:
        Path(path).write_bytes(header + img.tobytes())
    except OSError as err:
        msg = f"{path}: cannot write: {err.strerror or err}"
        raise OutputError(msg) from None


def save_map(grid: OccupancyGrid, yaml_path: str | Path, comment: str = "") -> Path:
    """Write ``grid`` as map_saver does: ``NAME.pgm`` beside ``NAME.yaml``; returns the PGM path.

    Raises:
        OutputError: the files cannot be written.
    """
    yp = Path(yaml_path)
    pgm = yp.with_suffix(".pgm")
    img = np.full(grid.shape, 205, dtype=np.uint8)
    img[grid.cells == FREE] = 254
    img[grid.cells == OCCUPIED] = 0
    write_pgm(pgm, img[::-1])
    ox, oy, oyaw = grid.origin
    lines = [f"# {comment}"] if comment else []
    lines += [
        f"image: {pgm.name}",
        "mode: trinary",
        f"resolution: {grid.resolution_m!r}",
        f"origin: [{ox!r}, {oy!r}, {oyaw!r}]",
        "negate: 0",
        f"occupied_thresh: {OCCUPIED_THRESH}",
        f"free_thresh: {FREE_THRESH}",
    ]
    try:
        yp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as err:
        msg = f"{yp}: cannot write: {err.strerror or err}"
        raise OutputError(msg) from None
    return pgm


SHIPPED_WORLDS = ("lab-8x6", "warehouse-20x20")
"""Floor plans shipped with omnical (``omnical/data/worlds``): ``--world NAME`` finds them."""


def resolve_world(name_or_path: str | Path) -> Path:
    """The map_server YAML of ``name_or_path``: an existing file, else a shipped world's name
    (:data:`SHIPPED_WORLDS`, with or without ``.yaml``).

    Raises:
        ConfigError: neither a file nor a shipped world (the message lists the shipped ones).
    """
    from importlib import resources

    path = Path(name_or_path)
    if path.exists():
        return path
    stem = path.name.removesuffix(".yaml")
    if path.parent == Path() and stem in SHIPPED_WORLDS:
        return Path(str(resources.files("omnical").joinpath("data", "worlds", f"{stem}.yaml")))
    msg = (
        f"{name_or_path}: no such floor plan file, and not a shipped world "
        f"({', '.join(SHIPPED_WORLDS)})"
    )
    raise ConfigError(msg)
