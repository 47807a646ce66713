"""Real UWB recordings as a user would have them: Marvelmind-topic recordings built from CSVs.

Two public datasets (not ours; provenance and licences in their READMEs):

- CUHK-SZ planar (``uwb_planar_cuhksz``, MIT): 8 anchors, tags on a trolley, motion capture.
  Each CSV row becomes one burst of 8 ``/beacon_raw_distance`` messages 1 ms apart; the anchor
  map goes to ``/beacons_pos_a``; there are no vendor positions (no hedgehog height).
- TU Chemnitz labyrinth (``uwb_labyrinth_tuc``, CC BY-SA 4.0): 4 anchors, **one range per
  message**, round robin, ≈ 7.8 Hz, 2D anchors (z = 0).

The shared extracts (``../shared/datasets``) are used when present (the full CUHK-SZ run,
2 695 rows), else the small copies in ``tests/data`` (every 5th CUHK-SZ row; the whole TU
Chemnitz run). Truth is returned beside each recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from omnical.recording.recording import Recording, RecordingBuilder

TESTS = Path(__file__).resolve().parents[1]
SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "datasets"
TAG_HEIGHT_M = 0.965
YAW_CORRECTION_DEG = 7.0
HEDGE_ADDRESS = 10
ANCHOR_ADDRESS_OFFSET = 1
"""CUHK-SZ anchor j is Marvelmind beacon address j + 1 (addresses are 1–255)."""

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class RealRun:
    """A recording built from a real dataset and the truth of its hedgehog."""

    recording: Recording
    t_ns: NDArray[np.int64]
    """Times of the truth samples, bag ns."""
    truth_xy_m: F64
    """True hedgehog (tag) position at each time, (n, 2), m."""
    source: Path


def cuhksz_dir() -> tuple[Path, str]:
    """The CUHK-SZ folder and its dynamic-run CSV (the shared full run if present)."""
    if (SHARED / "uwb_planar_cuhksz" / "dynamic_fast.csv").is_file():
        return SHARED / "uwb_planar_cuhksz", "dynamic_fast.csv"
    return TESTS / "data" / "uwb_planar_cuhksz", "dynamic_fast_every5.csv"


def tuc_dir() -> Path:
    """The TU Chemnitz folder (the shared one if present, else the test copy)."""
    shared = SHARED / "uwb_labyrinth_tuc"
    return shared if (shared / "ranges.csv").is_file() else TESTS / "data" / "uwb_labyrinth_tuc"


def _csv(path: Path) -> tuple[list[str], F64]:
    names = path.read_text(encoding="utf-8").splitlines()[0].split(",")
    table: F64 = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return names, table


def _ns(t_s: F64) -> NDArray[np.int64]:
    return np.round(np.asarray(t_s) * 1e9).astype(np.int64)


def _beacon_rows(
    builder: RecordingBuilder, t0_ns: int, addresses: NDArray[np.int64], positions: F64
) -> None:
    n = addresses.size
    builder.add_many(
        "/beacons_pos_a",
        t0_ns + np.arange(n, dtype=np.int64) * 1_000_000,
        address=addresses,
        x_m=positions[:, 0],
        y_m=positions[:, 1],
        z_m=positions[:, 2],
    )


def cuhksz_run(tag: int = 0, *, calibrated: bool = True) -> RealRun:
    """The CUHK-SZ dynamic run of one tag as a Marvelmind recording.

    ``calibrated``: the authors' per-link calibration ``(r − bias)/(1 + slope)`` applied, the
    ranges projected to the horizontal plane at the tag height and the anchors written at the
    tag height (the bag of issue 11). Otherwise the raw ranges and the anchors at their
    surveyed heights (≈ 1.044 m; the tag is at ≈ 0.965 m, which the recording does not say).
    """
    folder, name = cuhksz_dir()
    names, rows = _csv(folder / name)
    _, anchors = _csv(folder / "anchors.csv")
    ranges = rows[:, [names.index(f"r_t{tag}_a{j}_m") for j in range(8)]]
    positions = anchors[:, 1:4].copy()
    if calibrated:
        _, calibration = _csv(folder / "range_calibration.csv")
        link = calibration[calibration[:, 0] == tag]
        ranges = (ranges - link[:, 2]) / (1.0 + link[:, 3])
        dz = positions[:, 2] - TAG_HEIGHT_M
        ranges = np.sqrt(np.maximum(ranges * ranges - dz * dz, 0.0))
        positions[:, 2] = TAG_HEIGHT_M
    _, body = _csv(folder / "tags_body_frame.csv")
    yaw = np.deg2rad(rows[:, names.index("gt_yaw_deg")] + YAW_CORRECTION_DEG)
    bx, by = body[tag, 1], body[tag, 2]
    x = rows[:, names.index("gt_x_m")] + np.cos(yaw) * bx - np.sin(yaw) * by
    y = rows[:, names.index("gt_y_m")] + np.sin(yaw) * bx + np.cos(yaw) * by

    t0_ns = 1_000_000_000
    t_ns = t0_ns + 100_000_000 + _ns(rows[:, 0])
    addresses = anchors[:, 0].astype(np.int64) + ANCHOR_ADDRESS_OFFSET
    builder = RecordingBuilder()
    _beacon_rows(builder, t0_ns, addresses, positions)
    n, m = ranges.shape
    builder.add_many(
        "/beacon_raw_distance",
        (t_ns[:, None] + np.arange(m, dtype=np.int64)[None, :] * 1_000_000).reshape(-1),
        address_hedge=np.full(n * m, HEDGE_ADDRESS),
        address_beacon=np.tile(addresses, n),
        distance_m=ranges.reshape(-1),
    )
    return RealRun(builder.build(), t_ns, np.column_stack([x, y]), folder)


def tuc_run() -> RealRun:
    """The TU Chemnitz labyrinth run: one range per message, anchors at z = 0."""
    folder = tuc_dir()
    names, ranges = _csv(folder / "ranges.csv")
    _, anchors = _csv(folder / "anchors.csv")
    _, truth = _csv(folder / "ground_truth.csv")
    t0_ns = 1_000_000_000
    t_ns = t0_ns + _ns(ranges[:, names.index("t_s")])
    addresses = anchors[:, 0].astype(np.int64)
    positions = np.column_stack([anchors[:, 1:3], np.zeros(len(anchors))])
    builder = RecordingBuilder()
    _beacon_rows(builder, t0_ns - 50_000_000, addresses, positions)
    builder.add_many(
        "/beacon_raw_distance",
        t_ns,
        address_hedge=np.full(t_ns.size, HEDGE_ADDRESS),
        address_beacon=ranges[:, names.index("anchor_id")].astype(np.int64),
        distance_m=ranges[:, names.index("range_m")],
    )
    return RealRun(builder.build(), t0_ns + _ns(truth[:, 0]), truth[:, 1:3], folder)


def truth_at(run: RealRun, t_ns: NDArray[np.int64]) -> F64:
    """The true position at the given times (linear interpolation), (n, 2)."""
    t = (t_ns - run.t_ns[0]).astype(np.float64)
    tt = (run.t_ns - run.t_ns[0]).astype(np.float64)
    return np.column_stack([np.interp(t, tt, run.truth_xy_m[:, k]) for k in range(2)])


def main(argv: list[str]) -> None:
    """``python tests/ips/uwb_bags.py OUT``: each dataset as a bag (``cuhksz.mcap``,
    ``tuc.mcap``) and its truth as a TUM file beside it (seconds from the bag's start), for ``omnical locate`` and
    ``omnical evaluate --reference-file`` (README, Accuracy)."""
    from omnical.bags.bag import write_bag

    out = Path(argv[0]) if argv else Path()
    out.mkdir(parents=True, exist_ok=True)
    for name, run in (("cuhksz", cuhksz_run()), ("tuc", tuc_run())):
        bag = write_bag(run.recording, out / f"{name}.mcap")
        rows = [
            f"{(t - run.recording.start_ns) / 1e9:.9f} {x:.4f} {y:.4f} 0 0 0 0 1"
            for t, (x, y) in zip(run.t_ns.tolist(), run.truth_xy_m.tolist(), strict=True)
        ]
        (out / f"{name}.tum").write_text("\n".join(rows) + "\n", encoding="utf-8")
        print(f"{bag} and {out / f'{name}.tum'} from {run.source}")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
