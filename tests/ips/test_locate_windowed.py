"""``locate`` of a recording a window at a time (issue "Scale"): the same fixes as the whole
run, with what is held bounded by the window.

Bit for bit where the windows are as large as the run's solver blocks; with tiny windows the
solver's own batch effects (its vectorised Gauss–Newton rounds the same fix differently in a
different batch, at the last bit) can move a printed last digit, so those compare the text
columns exactly and the numbers to rounding (:func:`_assert_same`)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from omnical.ips import from_recording, windowed
from omnical.ips.beacons import BeaconMap
from omnical.ips.bursts import group_bursts, sliding_windows
from omnical.ips.from_recording import FixesCsv, locate, locate_run, write_fixes_csv
from omnical.ips.solve import Fixes
from omnical.ips.solve.selfcal import MAX_LEARNING_FIXES
from omnical.ips.windowed import RangeRun, Spill, float_keys, key_floats, median_on_disk
from omnical.recording.recording import Recording, RecordingBuilder


def _uwb_bags() -> ModuleType:
    path = Path(__file__).resolve().parent / "uwb_bags.py"
    spec = importlib.util.spec_from_file_location("uwb_bags", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("uwb_bags", module)
    spec.loader.exec_module(module)
    return module


uwb = _uwb_bags()


def _fed(recording: Recording, part: int) -> RangeRun:
    """A RangeRun fed with the recording's topics ``part`` rows at a time."""
    run = RangeRun()
    d = recording.topic("/beacon_raw_distance")
    for lo in range(0, len(d), part):
        s = slice(lo, lo + part)
        run.add_ranges(d.t_ns[s], d["address_hedge"][s], d["address_beacon"][s], d["distance_m"][s])
    if recording.has("/beacons_pos_a"):
        b = recording.topic("/beacons_pos_a")
        for lo in range(0, len(b), 3):
            s = slice(lo, lo + 3)
            run.add_beacons(
                b.t_ns[s], b["address"][s], b["x_m"][s], b["y_m"][s], b["z_m"][s], first=lo == 0
            )
    if recording.has("/hedge_pos_ang"):
        p = recording.topic("/hedge_pos_ang")
        for lo in range(0, len(p), part):
            s = slice(lo, lo + part)
            run.add_vendor(p["z_m"][s], p["flags"][s], first=lo == 0)
    return run


def _csv_of(fixes: list[Fixes], path: Path) -> bytes:
    with FixesCsv(path) as out:
        for part in fixes:
            out.write(part)
    return path.read_bytes()


def _assert_same(windowed: bytes, whole: bytes) -> None:
    """Same rows, times, beacons, statuses and reasons; numbers equal to their last digit."""
    a = [line.split(b",") for line in windowed.splitlines()]
    b = [line.split(b",") for line in whole.splitlines()]
    assert len(a) == len(b) and a[0] == b[0]
    text = [0, 10, 11, 12]  # t_ns, beacons_used, status, reason
    assert [[r[k] for k in text] for r in a] == [[r[k] for k in text] for r in b]
    x = np.array([[float(v) for v in r[1:10]] for r in a[1:]])
    y = np.array([[float(v) for v in r[1:10]] for r in b[1:]])
    assert np.allclose(x, y, rtol=1e-5, atol=2e-4, equal_nan=True)


def _whole_csv(recording: Recording, path: Path, **options: Any) -> tuple[bytes, Fixes]:
    fixes, _ = locate(recording, **options)
    write_fixes_csv(fixes, path)
    return path.read_bytes(), fixes


def _synthetic(
    hedges: int = 3, seconds: float = 60.0, seed: int = 0, nlos: float = 0.05, missing: float = 0.01
) -> Recording:
    """Several hedgehogs on circles, bursts of four ranges at 8 Hz each, 5 % NLOS, a few
    ranges missing, vendor heights with noise."""
    rng = np.random.default_rng(seed)
    beacons = np.array([[0.0, 0.0, 2.0], [6.0, 0.0, 2.1], [6.0, 5.0, 1.9], [0.0, 5.0, 2.0]])
    addresses = np.array([3, 4, 5, 6])
    z = 0.4
    rows: list[tuple[int, int, int, float]] = []
    vendor: list[tuple[int, int, float, int]] = []
    steps = int(seconds * 8)
    for h in range(hedges):
        phase = rng.uniform(0, 2 * np.pi)
        for k in range(steps):
            t0 = int(k * 125_000_000 + h * 37_000_000 + rng.integers(0, 2_000_000))
            angle = phase + 0.3 * k / 8.0
            p = np.array([3.0 + 2.0 * np.cos(angle), 2.5 + 1.8 * np.sin(angle), z])
            for j, (b, a) in enumerate(zip(beacons, addresses, strict=True)):
                if rng.random() < missing:
                    continue  # a range missing
                d = float(np.linalg.norm(p - b) + rng.normal(0.0, 0.02 + 0.005 * j))
                if rng.random() < nlos:
                    d += rng.uniform(0.2, 0.8)
                rows.append((t0 + j * 1_000_000, 10 + h, int(a), d))
            vendor.append((t0 + 5_000_000, 10 + h, z + rng.normal(0.0, 0.01), 0))
    rows.sort()
    vendor.sort()
    builder = RecordingBuilder()
    for t, hedge, beacon, d in rows:
        builder.add(
            "/beacon_raw_distance", t, address_hedge=hedge, address_beacon=beacon, distance_m=d
        )
    for t, hedge, zv, flags in vendor:
        builder.add(
            "/hedge_pos_ang", t, address=hedge, timestamp_ms=t // 1_000_000, x_m=0.0, y_m=0.0,
            z_m=zv, flags=flags, angle_deg=0.0,
        )  # fmt: skip
    for a, b in zip(addresses, beacons, strict=True):
        builder.add("/beacons_pos_a", 0, address=int(a), x_m=b[0], y_m=b[1], z_m=b[2])
    return builder.build()


@pytest.fixture(scope="module")
def synthetic() -> Recording:
    return _synthetic()


@pytest.mark.parametrize("window", [7, 64, windowed.FIX_WINDOW])
def test_windowed_csv_is_the_whole_runs(synthetic: Recording, tmp_path: Path, window: int) -> None:
    whole, fixes = _whole_csv(synthetic, tmp_path / "whole.csv")
    located = locate_run(
        _fed(synthetic, 101),
        window=window,
        message_window=53,
        learning_fixes=MAX_LEARNING_FIXES,
    )
    assert located.windowed
    assert located.notes == fixes.notes
    assert [m.describe() for m in located.noise] == [m.describe() for m in fixes.noise]
    text = _csv_of(list(located.parts), tmp_path / "windowed.csv")
    if window >= 480:  # a hedgehog's fixes in one window: bit for bit
        assert text == whole
    _assert_same(text, whole)


def test_grouping_in_parts_is_grouping_at_once(synthetic: Recording) -> None:
    """Messages grouped a window at a time, cut where a gap starts: the same fixes."""
    d = synthetic.topic("/beacon_raw_distance")
    run = _fed(synthetic, 97)
    bmap = run.beacon_map()
    spill, n_valid = run.group(bmap, window=41)
    got = spill.read(0, spill.rows)
    want = group_bursts(d.t_ns, d["address_hedge"], d["address_beacon"], d["distance_m"], bmap)
    assert np.array_equal(got["t"], want.t_ns)
    assert np.array_equal(got["hedge"], want.address_hedge)
    assert np.array_equal(got["d"], want.distances_m, equal_nan=True)
    assert np.array_equal(n_valid, np.bincount(want.n_valid, minlength=len(bmap) + 1))


def test_two_processes_learn_the_same_models(
    synthetic: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(windowed, "PARALLEL_FIXES", 0)
    one = locate_run(_fed(synthetic, 500), window=64, workers=1)
    two = locate_run(_fed(synthetic, 500), window=64, workers=2)
    assert [m.describe() for m in one.noise] == [m.describe() for m in two.noise]
    assert _csv_of(list(one.parts), tmp_path / "1.csv") == _csv_of(
        list(two.parts), tmp_path / "2.csv"
    )


@pytest.mark.parametrize("calibrated", [True, False])
def test_real_bursts_cuhksz(tmp_path: Path, calibrated: bool) -> None:
    run = uwb.cuhksz_run(0, calibrated=calibrated)
    whole, fixes = _whole_csv(run.recording, tmp_path / "whole.csv")
    located = locate_run(_fed(run.recording, 333), window=50, message_window=211)
    assert located.windowed and located.notes == fixes.notes
    _assert_same(_csv_of(list(located.parts), tmp_path / "windowed.csv"), whole)
    default = _csv_of(list(locate_run(_fed(run.recording, 333)).parts), tmp_path / "d.csv")
    _assert_same(default, whole)
    if calibrated:  # the run as measured (bench_locate.py): bit for bit with the default windows
        assert default == whole


def test_real_round_robin_tuc(tmp_path: Path) -> None:
    """Sequential ranges: sliding windows carried across parts, the median period on disk."""
    run = uwb.tuc_run()
    whole, fixes = _whole_csv(run.recording, tmp_path / "whole.csv")
    located = locate_run(_fed(run.recording, 29), window=17, message_window=41)
    assert located.windowed
    assert located.notes == fixes.notes
    assert any("round robin" in note for note in located.notes)
    _assert_same(_csv_of(list(located.parts), tmp_path / "windowed.csv"), whole)
    sliding, _ = _fed(run.recording, 29).sliding(located.beacons, window=41)
    t = run.recording.topic("/beacon_raw_distance")
    want, _ = sliding_windows(
        t.t_ns, t["address_hedge"], t["address_beacon"], t["distance_m"], located.beacons
    )
    assert np.array_equal(sliding.read(0, sliding.rows)["d"], want.distances_m, equal_nan=True)


def test_options_without_learning(synthetic: Recording, tmp_path: Path) -> None:
    for options in ({"self_calibrate": False}, {"range_sigma_m": 0.03}, {"method": "lsq"}):
        whole, _ = _whole_csv(synthetic, tmp_path / "whole.csv", **options)
        located = locate_run(_fed(synthetic, 77), window=33, **options)  # type: ignore[arg-type]
        _assert_same(_csv_of(list(located.parts), tmp_path / "w.csv"), whole)


def test_window_bounds_what_is_solved_and_held(
    synthetic: Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every solve takes at most a window (its hedgehogs at once); the learning at most a
    hedgehog's sample; the fixes waiting for the off-track check at most a window and 2 s."""
    sizes: list[int] = []
    solve = windowed.solve_streams

    def spy(distances: NDArray[np.float64], beacons: BeaconMap, *a: Any, **kw: Any) -> Fixes:
        sizes.append(len(distances))
        return solve(distances, beacons, *a, **kw)

    learnt: list[int] = []
    learn_sigma = windowed.learn_sigma

    def spy_learning(fixes: Fixes, *args: Any, **kw: Any) -> Any:
        learnt.append(len(fixes))
        return learn_sigma(fixes, *args, **kw)

    monkeypatch.setattr(windowed, "solve_streams", spy)
    monkeypatch.setattr(windowed, "learn_sigma", spy_learning)
    located = locate_run(_fed(synthetic, 100), window=40, learning_fixes=150)
    parts = list(located.parts)
    assert sizes and max(sizes) <= 40 * 3  # a window: 40 fixes per hedgehog, 3 hedgehogs
    assert learnt and max(learnt) <= 150
    # 3 hedgehogs at 8 Hz: 2 s of fixes is 48; a part is what was decided after a window
    assert max(len(p) for p in parts) <= 120 + 48 + 3
    assert sum(len(p) for p in parts) == 3 * 480


def test_bounded_sample_changes_little(synthetic: Recording) -> None:
    """A learning sample of a quarter of the run: the fixes move by a small part of their σ."""
    fixes, _ = locate(synthetic)
    located = locate_run(_fed(synthetic, 100), learning_fixes=120)
    parts = list(located.parts)
    xy = np.concatenate([p.positions_map_m[:, :2] for p in parts])
    moved = np.hypot(*(xy - fixes.positions_map_m[:, :2]).T)
    sigma = np.sqrt(fixes.covariance_xy_m2[:, 0, 0] + fixes.covariance_xy_m2[:, 1, 1])
    ok = np.isfinite(moved) & np.isfinite(sigma)
    assert np.median(moved[ok] / sigma[ok]) < 0.2


def test_interleaved_height_and_beacon_rows() -> None:
    """The map's latest row of each beacon and the vendor's median height, part by part."""
    run = RangeRun()
    t = np.array([5, 1, 9, 9], dtype=np.int64)
    run.add_beacons(t[:2], np.array([1, 2]), np.zeros(2), np.zeros(2), np.array([1.0, 2.0]))
    run.add_beacons(t[2:], np.array([2, 2]), np.zeros(2), np.zeros(2), np.array([3.0, 4.0]))
    bmap = run.beacon_map()
    assert bmap.positions_m[:, 2].tolist() == [1.0, 4.0]
    z = np.array([0.3, 0.1, 0.2, 0.25, np.inf, -0.0, 0.0])
    flags = np.array([0, 0, 0, 0, 1, 0, 0], dtype=np.uint8)
    run.add_vendor(z[:3], flags[:3])
    run.add_vendor(z[3:], flags[3:])
    assert run.hedge_height(bmap, 10) == float(np.median(z[flags == 0]))


@pytest.mark.parametrize("n", [1, 2, 3, 10, 4097])
def test_median_on_disk_is_numpys(n: int) -> None:
    rng = np.random.default_rng(n)
    for values in (rng.integers(-(2**62), 2**62, n), rng.integers(0, 10**11, n)):
        spill = Spill(np.dtype("<i8"))
        spill.append(values[: n // 2])
        spill.append(values[n // 2 :])
        assert median_on_disk(spill, limit=5) == float(np.median(values))
    floats = rng.normal(size=n)
    assert np.array_equal(key_floats(float_keys(floats)), floats)
    assert np.array_equal(np.argsort(float_keys(floats)), np.argsort(floats))


def test_sweep_output_keeps_no_partial_file_on_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The CLI's replacing writer: an existing output survives an error midway."""
    from omnical.cli.locate import _replacing

    out = tmp_path / "fixes.csv"
    out.write_text("old\n")
    with pytest.raises(KeyboardInterrupt), _replacing(out, out) as partial:
        partial.write_text("half")
        raise KeyboardInterrupt
    assert out.read_text() == "old\n"
    assert list(tmp_path.iterdir()) == [out]
    with _replacing(out, out) as partial:
        partial.write_text("new\n")
    assert out.read_text() == "new\n"
    assert from_recording.FIXES_CSV_HEADER.startswith("t_ns")


def test_hedgehogs_recorded_one_after_another_in_two_processes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Windows holding only the other process's hedgehog: each process finishes its own (an
    empty window had failed an assertion in both)."""
    recording = _synthetic(hedges=2)
    d = recording.topic("/beacon_raw_distance")
    t, hedge = d.t_ns, d["address_hedge"]
    first, second = np.unique(hedge)
    half = (int(t.min()) + int(t.max())) // 2
    keep = ((hedge == first) & (t < half)) | ((hedge == second) & (t >= half))

    def fed() -> RangeRun:
        run = RangeRun()
        run.add_ranges(t[keep], hedge[keep], d["address_beacon"][keep], d["distance_m"][keep])
        return run

    monkeypatch.setattr(windowed, "PARALLEL_FIXES", 0)
    results: list[Any] = []
    collect = windowed._collect

    def kept(child: Any) -> Any:
        results.append(collect(child))
        return results[-1]

    monkeypatch.setattr(windowed, "_collect", kept)
    one = locate_run(fed(), window=64, hedge_z_m=0.4, workers=1)
    two = locate_run(fed(), window=64, hedge_z_m=0.4, workers=2)
    want = _csv_of(list(one.parts), tmp_path / "1.csv")
    assert _csv_of(list(two.parts), tmp_path / "2.csv") == want
    assert len(results) == 1 and results[0] is not None  # the child's share came back


def test_a_stray_address_in_two_processes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One hedgehog and a misread address with one range: the forked process gets the stray
    one, absent from every later window (the review's end-to-end case: a bug report)."""
    recording = _synthetic(hedges=1)
    d = recording.topic("/beacon_raw_distance")

    def fed() -> RangeRun:
        run = RangeRun()
        address = d["address_hedge"].copy()
        address[5] = 99
        run.add_ranges(d.t_ns, address, d["address_beacon"], d["distance_m"])
        return run

    monkeypatch.setattr(windowed, "PARALLEL_FIXES", 0)
    one = locate_run(fed(), window=64, hedge_z_m=0.4, workers=1)
    two = locate_run(fed(), window=64, hedge_z_m=0.4, workers=2)
    assert _csv_of(list(two.parts), tmp_path / "2.csv") == _csv_of(
        list(one.parts), tmp_path / "1.csv"
    )


def test_a_failed_learning_process_changes_nothing(
    synthetic: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The child that learns half the hedgehogs dies: its share is learnt here, and the
    off-track check still covers every hedgehog (its counts had been wiped: 21 → 3 flagged)."""
    monkeypatch.setattr(windowed, "PARALLEL_FIXES", 0)
    one = locate_run(_fed(synthetic, 500), window=64, workers=1)
    want = _csv_of(list(one.parts), tmp_path / "1.csv")
    collect = windowed._collect

    def died(child: Any) -> None:
        collect(child)  # the child's pipe drained and reaped as usual, its result lost

    monkeypatch.setattr(windowed, "_collect", died)
    two = locate_run(_fed(synthetic, 500), window=64, workers=2)
    assert _csv_of(list(two.parts), tmp_path / "2.csv") == want


def test_csv_formatted_in_two_processes_is_the_same_text(
    synthetic: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Half of each block of rows formatted by a forked process; if it fails, here."""
    fixes, _ = locate(synthetic)
    want = write_fixes_csv(fixes, tmp_path / "one.csv").read_bytes()
    monkeypatch.setattr(from_recording, "PARALLEL_CSV_ROWS", 10)
    monkeypatch.setattr(from_recording, "_CSV_BLOCK", 333)
    monkeypatch.setattr(from_recording, "_CSV_CHUNK", 50)
    forks: list[object] = []
    fork = from_recording.fork

    def counted(work: Any, **options: Any) -> Any:
        forks.append(work)
        return fork(work, **options)

    monkeypatch.setattr(from_recording, "fork", counted)
    with FixesCsv(tmp_path / "two.csv", workers=2) as out:
        out.write(fixes)
    assert (tmp_path / "two.csv").read_bytes() == want
    assert len(forks) == -(-len(fixes) // 333)
    collect = from_recording.collect

    def died(child: Any) -> None:
        lost = collect(child)  # drained and reaped, its text lost
        lost.close()

    monkeypatch.setattr(from_recording, "collect", died)
    with FixesCsv(tmp_path / "lost.csv", workers=2) as out:
        out.write(fixes)
    assert (tmp_path / "lost.csv").read_bytes() == want


def test_learning_samples_gathered_in_small_groups_are_the_same(
    synthetic: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The samples of a few hedgehogs at a time (one pass over the usable fixes each)."""
    run = {"window": 64, "learning_fixes": 150}
    want = _csv_of(list(locate_run(_fed(synthetic, 500), **run).parts), tmp_path / "a.csv")
    passes: list[int] = []
    gather = windowed.WindowedLocate._gather

    def counted(self: Any, usable: Spill, counts: Any, group: list[int]) -> Any:
        passes.append(len(group))
        return gather(self, usable, counts, group)

    monkeypatch.setattr(windowed.WindowedLocate, "_gather", counted)
    monkeypatch.setattr(windowed, "_SAMPLE_FIXES", 1)
    got = _csv_of(list(locate_run(_fed(synthetic, 500), **run).parts), tmp_path / "b.csv")
    assert got == want
    assert passes and max(passes) == 1  # one hedgehog a pass: each sample alone


def test_grouping_holds_a_burst_not_a_gapless_run() -> None:
    """Bursts back to back, never 15 ms apart (one gap segment for the whole run): each
    window is cut at its last burst once the carry passes a window (it was the whole run)."""
    bmap = BeaconMap(
        addresses=np.array([3, 4, 5, 6]),
        positions_m=np.array([[0, 0, 2.0], [6, 0, 2.0], [6, 5, 2.0], [0, 5, 2.0]]),
        hedge_addresses=np.zeros(0, np.int64),
        hedge_z_m=np.zeros(0),
    )
    bursts, period_ns = 2_000, 12_000_000
    k = np.arange(bursts)
    t = (k[:, None] * period_ns + np.arange(4)[None, :] * 1_000_000).reshape(-1)
    beacon = np.tile([3, 4, 5, 6], bursts)
    run = RangeRun()
    run.add_ranges(t, np.full(t.size, 10), beacon, np.full(t.size, 3.0))
    carried: list[int] = []
    emitted = group_bursts

    def spy(t_ns: Any, *args: Any, **kwargs: Any) -> Any:
        carried.append(len(t_ns))
        return emitted(t_ns, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(windowed, "group_bursts", spy)
        spill, _ = run.group(bmap, window=400)
    assert spill.rows == bursts
    assert max(carried) <= 2 * 400  # a window and at most a window carried into it


def test_a_stray_address_does_not_hold_the_run_without_learning(tmp_path: Path) -> None:
    """Without self-calibration a hedgehog's usable count is known before the output, so one
    lone range of a misread address does not hold every later fix back (it held all 4,800)."""
    recording = _synthetic(hedges=1, seconds=120.0)
    d = recording.topic("/beacon_raw_distance")
    run = RangeRun()
    run.add_ranges(np.array([1]), np.array([99]), np.array([3]), np.array([2.0]))
    run.add_ranges(d.t_ns[1:], d["address_hedge"][1:], d["address_beacon"][1:], d["distance_m"][1:])
    most = 0
    push = windowed._Track.push

    def measured(self: Any, fixes: Fixes | None, *, last: bool) -> Fixes | None:
        nonlocal most
        out = push(self, fixes, last=last)
        held = self.pending.join()
        most = max(most, 0 if held is None else len(held))
        return out

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(windowed._Track, "push", measured)
        parts = list(locate_run(run, self_calibrate=False, window=64).parts)
    assert sum(len(p) for p in parts) > 900
    assert most < 200
