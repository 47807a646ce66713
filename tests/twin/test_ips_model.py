"""Tests of the simulated Marvelmind IPS (non-inverse architecture)."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.twin.ips_messages import (
    FLAG_COORDINATES_UNAVAILABLE,
    FLAG_TIMESTAMP_MS,
    IpsMeasurements,
)
from omnical.twin.ips_model import (
    hedge_positions_map,
    measurement_rate_hz,
    select_submap,
    simulate_ips,
)
from omnical.twin.ips_params import IpsParams, NlosZone

# Seed 000 Table 3: stationary beacons 3, 4, 5, 6 (z = 0.4 m), hedgehog 10 at z = 0.4 m.
ADDRESSES = np.array([3, 4, 5, 6])
BEACONS_M = np.array([[0.0, 0.0, 0.4], [5.767, 0.0, 0.4], [0.485, 4.809, 0.4], [5.445, 4.813, 0.4]])
HEDGE_Z_M = 0.4


def circle_trajectory(
    duration_s: float = 60.0, rate_hz: float = 50.0
) -> tuple[np.ndarray, np.ndarray]:
    """A 1.5 m circle in the middle of the Table 3 map, turning slowly."""
    t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    phase = 2.0 * np.pi * t / 30.0
    poses = np.stack([2.9 + 1.5 * np.cos(phase), 2.4 + 1.5 * np.sin(phase), 0.2 * t], axis=1)
    return t, poses


def run(params: IpsParams, seed: int = 0, duration_s: float = 60.0) -> IpsMeasurements:
    t, poses = circle_trajectory(duration_s)
    return simulate_ips(t, poses, ADDRESSES, BEACONS_M, params, np.random.default_rng(seed))


def vendor_errors_m(meas: IpsMeasurements) -> np.ndarray:
    """Horizontal error of each vendor fix (flags bit 0 clear) against the truth."""
    pos = meas.positions
    ok = (pos.flags & FLAG_COORDINATES_UNAVAILABLE) == 0
    truth = meas.truth.hedge_map_m[pos.measurement_index[ok]]
    return np.asarray(np.hypot(pos.x_m[ok] - truth[:, 0], pos.y_m[ok] - truth[:, 1]))


def test_ideal_reproduces_exact_3d_distances_and_positions() -> None:
    t, poses = circle_trajectory()
    meas = simulate_ips(t, poses, ADDRESSES, BEACONS_M, IpsParams.ideal(), np.random.default_rng(3))
    d = meas.distances
    # Independent truth: interpolate the trajectory at the emission times.
    t_emit = meas.truth.t_emit_s[d.measurement_index]
    x = np.interp(t_emit, t, poses[:, 0])
    y = np.interp(t_emit, t, poses[:, 1])
    beacon = BEACONS_M[np.searchsorted(ADDRESSES, d.address_beacon)]
    expected = np.sqrt((x - beacon[:, 0]) ** 2 + (y - beacon[:, 1]) ** 2 + (HEDGE_Z_M - 0.4) ** 2)
    assert len(d.distance_m) == 4 * len(meas.truth.t_emit_s)
    np.testing.assert_allclose(d.distance_m, expected, rtol=0, atol=1e-12)
    assert not d.is_outlier.any()
    assert set(d.address_hedge.tolist()) == {10}
    pos = meas.positions
    assert np.all(pos.flags == FLAG_TIMESTAMP_MS)
    assert np.all(pos.address == 10) and np.all(pos.angle_deg == 0.0)
    assert np.max(vendor_errors_m(meas)) < 1e-9
    np.testing.assert_allclose(pos.z_m, HEDGE_Z_M)
    assert np.all(meas.quality.quality_percent == 100)


def test_same_seed_same_output_and_other_seed_differs() -> None:
    a, b, c = run(IpsParams(), seed=7), run(IpsParams(), seed=7), run(IpsParams(), seed=8)
    for topic in ("positions", "distances", "quality", "beacons", "truth"):
        rec_a, rec_b = getattr(a, topic), getattr(b, topic)
        for f in fields(rec_a):
            np.testing.assert_array_equal(getattr(rec_a, f.name), getattr(rec_b, f.name))
    n = min(len(a.distances.distance_m), len(c.distances.distance_m))
    assert not np.array_equal(a.distances.distance_m[:n], c.distances.distance_m[:n])


def test_results_are_read_only() -> None:
    meas = run(IpsParams.ideal(), duration_s=2.0)
    with pytest.raises(ValueError, match="read-only"):
        meas.positions.x_m[0] = 1.0


def test_outlier_fraction_and_bias_range_as_configured() -> None:
    params = IpsParams.ideal(nlos_probability=0.2, nlos_bias_range_m=[0.1, 1.0])
    meas = run(params, seed=11, duration_s=200.0)
    d = meas.distances
    n = len(d.distance_m)
    assert n == 4 * 25 * 200
    fraction = d.is_outlier.mean()
    assert abs(fraction - 0.2) < 4.0 * np.sqrt(0.2 * 0.8 / n)
    bias = d.distance_m - d.true_distance_m
    assert np.all(bias[~d.is_outlier] == 0.0)
    assert bias[d.is_outlier].min() >= 0.1 and bias[d.is_outlier].max() <= 1.0
    assert abs(bias[d.is_outlier].mean() - 0.55) < 0.02


def test_nlos_zone_biases_named_beacon_only_inside_zone() -> None:
    zone = NlosZone.rectangle(4, 3.5, 0.0, 6.0, 3.0, bias_m=0.4)
    meas = run(IpsParams.ideal(nlos_zones=(zone,)), seed=2)
    d = meas.distances
    hedge = meas.truth.hedge_map_m[d.measurement_index]
    inside = zone.contains(hedge[:, 0], hedge[:, 1])
    target = (d.address_beacon == 4) & inside
    assert target.sum() > 50 and (inside & (d.address_beacon != 4)).sum() > 50
    bias = d.distance_m - d.true_distance_m
    np.testing.assert_allclose(bias[target], 0.4, atol=1e-12)
    np.testing.assert_allclose(bias[~target], 0.0, atol=1e-12)
    np.testing.assert_array_equal(d.is_outlier, target)


def test_nlos_zone_circle_and_mapping() -> None:
    zone = NlosZone.from_mapping({"beacon": 5, "circle": [2.9, 3.9, 0.5], "bias_m": 0.3})
    assert zone == NlosZone.circle(5, 2.9, 3.9, 0.5, bias_m=0.3)
    inside = zone.contains(np.array([2.9, 3.3, 2.9]), np.array([3.9, 3.9, 3.3]))
    np.testing.assert_array_equal(inside, [True, True, False])
    with pytest.raises(ConfigError, match="radius"):
        NlosZone.from_mapping({"beacon": 5, "circle": [0.0, 0.0, -1.0]})
    with pytest.raises(ConfigError, match="exactly one"):
        NlosZone.from_mapping({"beacon": 5})
    with pytest.raises(ConfigError, match="colour"):
        NlosZone.from_mapping({"beacon": 5, "circle": [0, 0, 1], "colour": "red"})


def test_rate_is_25_hz_for_table3_map_and_lower_when_spread_out() -> None:
    meas = run(IpsParams.ideal(), duration_s=60.0)
    rate = len(meas.truth.t_emit_s) / 60.0
    assert rate == pytest.approx(25.0, abs=0.05)
    np.testing.assert_allclose(np.diff(meas.truth.t_emit_s), 0.04, atol=1e-9)

    spread = BEACONS_M * np.array([2.5, 2.5, 1.0])  # 14.4 m × 12 m, diagonal 18.5 m
    t = np.linspace(0.0, 60.0, 601)
    poses = np.tile([7.0, 6.0, 0.0], (len(t), 1))
    far = simulate_ips(t, poses, ADDRESSES, spread, IpsParams.ideal(), np.random.default_rng(0))
    far_rate = len(far.truth.t_emit_s) / 60.0
    spacing = np.linalg.norm(spread[0] - spread[3])
    assert far_rate < 12.0
    assert far_rate == pytest.approx(float(measurement_rate_hz(spacing, IpsParams())), abs=0.05)


def test_rate_law_knots_and_tdma_share() -> None:
    params = IpsParams()
    rates = measurement_rate_hz(np.array([2.0, 7.5, 11.0, 30.0]), params)
    np.testing.assert_allclose(rates, [25.0, 25.0, 10.0, 7.0])
    assert 10.0 < float(measurement_rate_hz(9.0, params)) < 25.0
    assert float(measurement_rate_hz(50.0, params)) < 7.0
    two = IpsParams(hedgehog_count=2)
    assert float(measurement_rate_hz(3.0, two)) == pytest.approx(12.5)
    floor = IpsParams(rate_knots=((1.0, 25.0), (2.0, 1.0)), rate_min_hz=0.5)
    assert float(measurement_rate_hz(100.0, floor)) == pytest.approx(0.5)


def test_latency_shifts_bag_times_only() -> None:
    base = IpsParams(latency_s=0.01, latency_periods=1.0)
    late = IpsParams(latency_s=0.21, latency_periods=1.0)
    a, b = run(base, seed=5), run(late, seed=5)
    np.testing.assert_array_equal(a.truth.t_emit_s, b.truth.t_emit_s)
    np.testing.assert_allclose(b.positions.t_s - a.positions.t_s, 0.2, atol=1e-9)
    np.testing.assert_allclose(b.distances.t_s - a.distances.t_s, 0.2, atol=1e-9)
    np.testing.assert_allclose(b.quality.t_s - a.quality.t_s, 0.2, atol=1e-9)
    np.testing.assert_array_equal(b.positions.timestamp_ms, a.positions.timestamp_ms)
    np.testing.assert_array_equal(b.positions.x_m, a.positions.x_m)
    # Default latency: 10 ms + one 40 ms period after emission.
    delay = a.positions.t_s - a.truth.t_emit_s[a.positions.measurement_index]
    np.testing.assert_allclose(delay, 0.05, atol=1e-9)


def test_burst_order_and_device_timestamp() -> None:
    meas = run(IpsParams(device_uptime_at_start_s=12.5), seed=4)
    pos, d, q = meas.positions, meas.distances, meas.quality
    for times in (pos.t_s, d.t_s, q.t_s):
        assert np.all(np.diff(times) > 0.0)
    t_pos = dict(zip(pos.measurement_index.tolist(), pos.t_s.tolist(), strict=True))
    t_q = dict(zip(q.measurement_index.tolist(), q.t_s.tolist(), strict=True))
    lag = d.t_s - np.array([t_pos[i] for i in d.measurement_index.tolist()])
    assert lag.min() >= 0.001 - 1e-12 and lag.max() <= 4 * 0.003 + 1e-12
    assert all(
        t_q[i] > t for i, t in zip(d.measurement_index.tolist(), d.t_s.tolist(), strict=True)
    )
    t_emit = meas.truth.t_emit_s[pos.measurement_index]
    np.testing.assert_array_equal(pos.timestamp_ms, np.floor((12.5 + t_emit) * 1000.0))
    wrapped = run(IpsParams(device_uptime_at_start_s=2**32 / 1000.0 - 1.0), duration_s=3.0)
    ts = wrapped.positions.timestamp_ms
    assert ts.max() < 2**32 and ts.min() < 3000 and ts[0] > 2**32 - 1000


def test_beacon_positions_repeat_every_10_s() -> None:
    meas = run(IpsParams(), duration_s=35.0)
    b = meas.beacons
    assert len(b.t_s) == 4 * 4
    np.testing.assert_array_equal(b.address, np.tile(ADDRESSES, 4))
    np.testing.assert_allclose(b.t_s[::4], [0.0, 10.0, 20.0, 30.0])
    np.testing.assert_allclose(b.x_m, np.tile(BEACONS_M[:, 0], 4))
    np.testing.assert_allclose(b.z_m, 0.4)


def test_measurement_drops_reduce_counts() -> None:
    meas = run(IpsParams.ideal(measurement_drop_probability=0.2), seed=9, duration_s=100.0)
    m = len(meas.truth.t_emit_s)
    kept = len(meas.positions.t_s) / m
    assert abs(kept - 0.8) < 4.0 * np.sqrt(0.2 * 0.8 / m)
    assert len(meas.quality.t_s) == len(meas.positions.t_s)
    assert len(meas.distances.t_s) == 4 * len(meas.positions.t_s)
    np.testing.assert_array_equal(
        np.flatnonzero(~meas.truth.dropped), meas.positions.measurement_index
    )


def test_distance_drops_flag_unavailable_and_repeat_last_position() -> None:
    meas = run(IpsParams.ideal(distance_drop_probability=0.3), seed=6, duration_s=100.0)
    pos, d = meas.positions, meas.distances
    per_measurement = np.bincount(d.measurement_index, minlength=len(meas.truth.t_emit_s))
    n_rx = per_measurement[pos.measurement_index]
    assert abs(len(d.t_s) / (4 * len(pos.t_s)) - 0.7) < 0.02
    unavailable = (pos.flags & FLAG_COORDINATES_UNAVAILABLE) != 0
    np.testing.assert_array_equal(unavailable, n_rx < 3)
    assert unavailable.sum() > 100
    assert np.all(pos.flags & FLAG_TIMESTAMP_MS)
    last_xy = (0.0, 0.0)
    for i in range(len(pos.t_s)):
        if unavailable[i]:
            assert (pos.x_m[i], pos.y_m[i]) == last_xy
        else:
            last_xy = (pos.x_m[i], pos.y_m[i])
    assert np.all(meas.quality.quality_percent[unavailable] == 0)
    assert np.all(meas.quality.quality_percent[n_rx == 3] == 75)


def test_vendor_error_grows_with_nlos() -> None:
    """Without its filtering the vendor fit is corrupted by reflections (seed 000 §2.4)."""
    unfiltered = IpsParams(vendor_outlier_rms_m=None, vendor_averaging_fixes=1)
    clean = replace(unfiltered, nlos_probability=0.0, measurement_drop_probability=0.0)
    dirty = replace(unfiltered, nlos_probability=0.15, measurement_drop_probability=0.0)
    err_clean = vendor_errors_m(run(clean, seed=1))
    err_dirty = vendor_errors_m(run(dirty, seed=1))
    assert np.mean(err_clean) < 0.03
    assert np.mean(err_dirty) > 3.0 * np.mean(err_clean)
    zone = NlosZone.rectangle(3, 0.0, 0.0, 6.0, 5.0, bias_m=0.5)
    err_zone = vendor_errors_m(run(IpsParams.ideal(nlos_zones=(zone,)), seed=1))
    assert np.min(err_zone) > 0.05


def test_default_vendor_filters_its_outliers() -> None:
    """The default vendor (outlier filter, track filter, 3-fix averaging) keeps 15 % NLOS
    from corrupting its fixes: the RMS error at emission stays near the clean one and far
    below the unfiltered fit's (issue 11: the real system filters its own outliers)."""
    dirty = IpsParams(nlos_probability=0.15, measurement_drop_probability=0.0)
    clean = replace(dirty, nlos_probability=0.0)
    raw = replace(dirty, vendor_outlier_rms_m=None, vendor_averaging_fixes=1)
    rms = {
        name: float(np.sqrt(np.mean(vendor_errors_m(run(p, seed=1)) ** 2)))
        for name, p in (("clean", clean), ("dirty", dirty), ("raw", raw))
    }
    assert rms["dirty"] < 1.5 * rms["clean"], rms
    assert rms["dirty"] < 0.2 * rms["raw"], rms


def test_quality_lower_with_outliers_and_drops() -> None:
    base = {
        "nlos_probability": 0.0,
        "measurement_drop_probability": 0.0,
        "distance_drop_probability": 0.0,
    }
    q_clean = run(IpsParams.from_mapping(base), seed=2).quality.quality_percent
    q_nlos = run(IpsParams.from_mapping({**base, "nlos_probability": 0.2}), seed=2)
    q_drop = run(IpsParams.from_mapping({**base, "distance_drop_probability": 0.2}), seed=2)
    assert np.mean(q_clean) > 90.0
    assert np.mean(q_nlos.quality.quality_percent) < np.mean(q_clean) - 20.0
    assert np.mean(q_drop.quality.quality_percent) < np.mean(q_clean) - 10.0
    outlier_rows = np.unique(q_nlos.distances.measurement_index[q_nlos.distances.is_outlier])
    has_outlier = np.isin(q_nlos.quality.measurement_index, outlier_rows)
    q = q_nlos.quality.quality_percent
    assert np.mean(q[has_outlier]) < np.mean(q[~has_outlier]) - 40.0


def test_hedge_offset_rotates_with_yaw() -> None:
    np.testing.assert_allclose(
        hedge_positions_map([[1.0, 2.0, np.pi / 2]], [0.2, 0.1, 0.4]), [[0.9, 2.2, 0.4]], atol=1e-12
    )
    t = np.linspace(0.0, 10.0, 101)
    poses = np.stack([np.full_like(t, 2.0), np.full_like(t, 2.5), np.linspace(0.0, np.pi, 101)], 1)
    params = IpsParams.ideal(hedge_offset_base_m=[0.3, 0.0, 0.4])
    meas = simulate_ips(t, poses, ADDRESSES, BEACONS_M, params, np.random.default_rng(0))
    yaw = np.interp(meas.truth.t_emit_s, t, poses[:, 2])
    expected = np.stack([2.0 + 0.3 * np.cos(yaw), 2.5 + 0.3 * np.sin(yaw)], axis=1)
    np.testing.assert_allclose(meas.truth.hedge_map_m[:, :2], expected, atol=1e-12)
    idx = meas.positions.measurement_index
    np.testing.assert_allclose(meas.positions.x_m, expected[idx, 0], atol=1e-9)
    np.testing.assert_allclose(meas.positions.y_m, expected[idx, 1], atol=1e-9)


def test_temperature_error_scales_distances() -> None:
    meas = run(IpsParams.ideal(temperature_error_c=10.0), duration_s=5.0)
    d = meas.distances
    np.testing.assert_allclose(d.distance_m, d.true_distance_m * 1.017, rtol=1e-12)


def test_submap_is_nearest_four_sorted_by_address() -> None:
    addresses = np.array([9, 3, 4, 5, 6, 8])
    beacons = np.vstack([BEACONS_M, [[11.0, 0.0, 0.4], [11.0, 4.8, 0.4]]])[[5, 0, 1, 2, 3, 4]]
    sel, spacing = select_submap([[1.0, 1.0, 0.4], [10.0, 2.0, 0.4]], addresses, beacons, 4)
    np.testing.assert_array_equal(addresses[sel], [[3, 4, 5, 6], [4, 6, 8, 9]])
    assert spacing[0] == pytest.approx(np.hypot(5.445, 4.813))
    t = np.linspace(0.0, 20.0, 201)
    poses = np.stack([np.linspace(1.0, 10.0, 201), np.full_like(t, 2.4), np.zeros_like(t)], 1)
    meas = simulate_ips(t, poses, addresses, beacons, IpsParams.ideal(), np.random.default_rng(1))
    sub = meas.truth.submap_addresses
    assert {tuple(r) for r in sub.tolist()} >= {(3, 4, 5, 6), (4, 6, 8, 9)}
    for i, a in zip(meas.distances.measurement_index, meas.distances.address_beacon, strict=True):
        assert a in sub[i]


def test_out_of_range_beacons_give_no_distance() -> None:
    meas = run(IpsParams.ideal(max_range_m=4.0), seed=0)
    d = meas.distances
    assert len(d.t_s) < 4 * len(meas.positions.t_s)
    assert d.true_distance_m.max() <= 4.0


def test_quantized_to_millimetres_by_default() -> None:
    meas = run(IpsParams(), duration_s=5.0)
    for values in (meas.distances.distance_m, meas.positions.x_m, meas.beacons.x_m):
        np.testing.assert_allclose(values * 1000.0, np.round(values * 1000.0), atol=1e-6)


def test_from_mapping_overrides_and_rejects_unknown_keys() -> None:
    params = IpsParams.from_mapping(
        {
            "hedge_offset_base_m": [0.1, 0.0, 0.35],
            "nlos_probability": 0.1,
            "rate_knots": [[5.0, 25], [11.0, 10.0]],
            "nlos_zones": [{"beacon": 4, "rectangle": [0, 0, 1, 1]}],
            "quantize_mm": False,
        }
    )
    assert params.hedge_offset_base_m == (0.1, 0.0, 0.35)
    assert params.rate_knots == ((5.0, 25.0), (11.0, 10.0))
    assert params.nlos_zones == (NlosZone.rectangle(4, 0.0, 0.0, 1.0, 1.0),)
    assert params.distance_noise_m == IpsParams().distance_noise_m
    with pytest.raises(ConfigError, match="nlos_probabilty"):
        IpsParams.from_mapping({"nlos_probabilty": 0.1})
    with pytest.raises(ConfigError, match="nlos_probability"):
        IpsParams.from_mapping({"nlos_probability": 1.5})
    with pytest.raises(ConfigError, match="max_beacons"):
        IpsParams.from_mapping({"max_beacons": 5})
    with pytest.raises(ConfigError, match="quantize_mm"):
        IpsParams.from_mapping({"quantize_mm": "yes"})
    with pytest.raises(ConfigError, match="rate_knots"):
        IpsParams.from_mapping({"rate_knots": [[5.0, 10.0], [11.0, 25.0]]})
    with pytest.raises(ConfigError, match="timing_jitter_s"):
        IpsParams(timing_jitter_s=0.05)


def test_bad_inputs_raise_config_error() -> None:
    t, poses = circle_trajectory(5.0)
    rng = np.random.default_rng(0)
    with pytest.raises(ConfigError, match="beacon 7"):
        zone = NlosZone.rectangle(7, 0.0, 0.0, 1.0, 1.0)
        simulate_ips(t, poses, ADDRESSES, BEACONS_M, IpsParams(nlos_zones=(zone,)), rng)
    with pytest.raises(ConfigError, match="increasing"):
        simulate_ips(t[::-1], poses, ADDRESSES, BEACONS_M, IpsParams(), rng)
    with pytest.raises(ConfigError, match="distinct"):
        simulate_ips(t, poses, np.array([3, 3, 5, 6]), BEACONS_M, IpsParams(), rng)
    with pytest.raises(ConfigError, match=r"\(B, 3\)"):
        simulate_ips(t, poses, ADDRESSES, BEACONS_M[:, :2], IpsParams(), rng)


def test_submap_of_all_beacons_is_the_same_everywhere() -> None:
    order = np.array([2, 0, 3, 1])  # addresses out of order in the map
    addresses, beacons = ADDRESSES[order], BEACONS_M[order]
    hedge = np.column_stack(
        [np.linspace(-3.0, 9.0, 50), np.linspace(8.0, -2.0, 50), np.full(50, 0.4)]
    )
    for max_beacons in (4, 9):  # every beacon serves: the short cut
        sel, spacing = select_submap(hedge, addresses, beacons, max_beacons)
        assert sel.dtype == np.int64
        np.testing.assert_array_equal(addresses[sel], np.tile([3, 4, 5, 6], (50, 1)))
        pair = np.linalg.norm(beacons[:, None] - beacons[None, :], axis=-1)
        np.testing.assert_array_equal(spacing, np.full(50, pair.max()))
    sel3, spacing3 = select_submap(hedge, addresses, beacons, 3)  # the nearest three
    assert sel3.shape == (50, 3)
    assert np.all(spacing3 <= spacing)
