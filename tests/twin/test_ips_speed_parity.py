"""The compiled vendor solve and track filter (numba) against the numpy reference: same bits.

The simulated IPS runs its vendor solve per measurement in :mod:`omnical.twin._ips_kernel`; the
numpy code vectorised over measurements stays as the reference (``engine="python"``). These
tests pin that the two give bit-identical fixes, hence bit-identical recordings for a seed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.experiment.runner import run_script
from omnical.experiment.script import load_script
from omnical.ips.beacons import default_beacon_map
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.robot.loader import load_robot
from omnical.twin.clock import TwinClock
from omnical.twin.ips_messages import IpsMeasurements
from omnical.twin.ips_model import simulate_ips
from omnical.twin.ips_params import IpsParams, NlosZone
from omnical.twin.ips_vendor import VendorSolution, jump_filter, solve_vendor_2d
from omnical.twin.params import default_twin
from omnical.twin.record import twin_recording
from omnical.twin.simulator import DigitalTwin

HEIGHT_M = 0.3


def _problem(rng: np.random.Generator, m: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M measurements of K slots: noisy, mm-rounded distances, reflections, missing slots, and
    a few degenerate cases (coincident or collinear beacons, no distance, beacon overhead)."""
    beacons = rng.uniform(-1.0, 8.0, (m, k, 3))
    beacons[..., 2] = rng.uniform(0.2, 2.5, (m, k))
    hedge = np.column_stack([rng.uniform(-1.0, 8.0, (m, 2)), np.full(m, HEIGHT_M)])
    d = np.linalg.norm(hedge[:, None, :] - beacons, axis=-1)
    d += rng.normal(0.0, 0.01, (m, k)) + (rng.random((m, k)) < 0.1) * rng.uniform(0.05, 1.5, (m, k))
    d = np.round(np.maximum(d, 0.0) * 1000.0) / 1000.0
    used = rng.random((m, k)) < 0.85
    n = m // 20
    beacons[:n, :, :2] = beacons[:n, :1, :2]  # all beacons at one spot
    line = rng.uniform(0.0, 1.0, (n, k, 1))
    beacons[n : 2 * n, :, :2] = line * [[[5.0, 3.0]]]  # collinear
    used[2 * n : 3 * n] = False
    beacons[3 * n : 4 * n, 0, :2] = hedge[3 * n : 4 * n, :2]  # right below a beacon
    d[4 * n : 5 * n] = 0.0
    return beacons, d, used


def _assert_same_solution(a: VendorSolution, b: VendorSolution) -> None:
    for name in ("xy_m", "ok", "n_used", "rms_residual_m", "hdop"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        # bitwise (signed zeros and NaN payload aside, which no caller can see)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name


@pytest.mark.parametrize("k", [1, 2, 3, 4])
@pytest.mark.parametrize("outlier_rms_m", [None, 0.03, 0.0])
@pytest.mark.parametrize("min_beacons", [1, 3])
def test_vendor_solve_is_the_same_on_both_engines(
    k: int, outlier_rms_m: float | None, min_beacons: int
) -> None:
    rng = np.random.default_rng([k, min_beacons, 0 if outlier_rms_m is None else 1])
    beacons, d, used = _problem(rng, 4000, k)
    solutions = [
        solve_vendor_2d(beacons, d, used, HEIGHT_M, min_beacons, outlier_rms_m, engine=engine)
        for engine in ("python", "compiled")
    ]
    _assert_same_solution(*solutions)
    if k >= 3 and outlier_rms_m != 0.0:  # fewer beacons, or a zero threshold: no fix at all
        assert 0 < solutions[1].ok.sum() < len(d)


def test_vendor_solve_takes_any_layout() -> None:
    """Non-contiguous and float32 inputs give what the reference gives."""
    beacons, d, used = _problem(np.random.default_rng(5), 300, 4)
    wide = np.zeros((300, 8, 3))
    wide[:, ::2] = beacons
    args = (wide[:, ::2], d.astype(np.float32), used[:, ::-1][:, ::-1])
    a = solve_vendor_2d(*args, HEIGHT_M, 3, 0.03, engine="python")  # type: ignore[arg-type]
    b = solve_vendor_2d(*args, HEIGHT_M, 3, 0.03, engine="compiled")  # type: ignore[arg-type]
    _assert_same_solution(a, b)


def test_jump_filter_is_the_same_on_both_engines() -> None:
    rng = np.random.default_rng(11)
    steps = rng.normal(0.0, 0.08, (20000, 2))
    steps[rng.random(20000) < 0.02] *= 10.0  # jumps
    xy = np.cumsum(steps, axis=0)
    ok = rng.random(20000) < 0.9
    xy[~ok] = np.nan
    for patience in (0, 1, 3):
        a = jump_filter(xy, ok, 0.2, patience, engine="python")
        b = jump_filter(xy, ok, 0.2, patience, engine="compiled")
        assert a.dtype == b.dtype == np.bool_
        np.testing.assert_array_equal(a, b)
        assert (a.sum() < ok.sum()) == (patience > 0)


def test_unknown_engine_is_refused() -> None:
    beacons, d, used = _problem(np.random.default_rng(0), 10, 4)
    with pytest.raises(ConfigError, match="unknown vendor engine"):
        solve_vendor_2d(beacons, d, used, HEIGHT_M, engine="fast")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="unknown vendor engine"):
        jump_filter(beacons[:, 0, :2], used[:, 0], 0.2, engine="fast")  # type: ignore[arg-type]


def _assert_same_measurements(a: IpsMeasurements, b: IpsMeasurements) -> None:
    for topic in ("positions", "distances", "quality", "beacons", "truth"):
        x, y = getattr(a, topic), getattr(b, topic)
        for name, value in vars(x).items():
            other = vars(y)[name]
            assert value.dtype == other.dtype, f"{topic}.{name}"
            assert np.array_equal(value, other, equal_nan=value.dtype.kind == "f"), (
                f"{topic}.{name}"
            )


SIX_BEACONS = np.array(
    [[0, 0, 2.0], [6, 0, 2.1], [0, 5, 1.9], [6, 5, 2.0], [12, 0, 2.2], [12, 5, 2.0]], dtype=float
)


@pytest.mark.parametrize(
    "params",
    [
        IpsParams(),
        IpsParams.ideal(),
        IpsParams(vendor_outlier_rms_m=None, vendor_averaging_fixes=1),
        IpsParams(
            nlos_probability=0.2,
            distance_drop_probability=0.2,
            max_beacons=3,
            nlos_zones=(NlosZone(4, "circle", (6.0, 2.5, 2.0)),),
        ),
    ],
    ids=["default", "ideal", "unfiltered", "harsh-submaps"],
)
def test_simulate_ips_is_the_same_on_both_engines(params: IpsParams) -> None:
    t = np.arange(0.0, 120.0, 0.02)
    phase = 2.0 * np.pi * t / 40.0
    poses = np.stack([6.0 + 5.0 * np.cos(phase), 2.5 + 2.0 * np.sin(2 * phase), 0.3 * t], 1)
    addresses = np.arange(1, 7)
    runs = [
        simulate_ips(t, poses, addresses, SIX_BEACONS, params, np.random.default_rng(4), engine=e)
        for e in ("python", "compiled")
    ]
    _assert_same_measurements(*runs)
    assert len(runs[0].positions.t_s) > 1000


def _assert_same_recording(a: Recording, b: Recording) -> None:
    assert a.tables.keys() == b.tables.keys()
    for topic, table in a.tables.items():
        other = b.tables[topic]
        np.testing.assert_array_equal(table.t_ns, other.t_ns, err_msg=topic)
        for name in table.names:
            assert table[name].dtype == other[name].dtype, f"{topic}.{name}"
            assert np.array_equal(table[name], other[name]), f"{topic}.{name}"


def test_recording_is_the_same_with_the_reference_vendor() -> None:
    """One twin log recorded twice, the IPS's vendor by numba and by numpy: the same bag."""
    robot = load_robot("rosy-mecanum")
    params = default_twin(robot)
    twin = DigitalTwin(robot, params, seed=5)
    twin.advance_to(1.0)
    run_script(load_script("tour", robot.limits), twin, TwinClock(twin))
    twin.advance_to(twin.t_s + 1.0)
    log = twin.log()
    recordings = []
    for engine in ("python", "compiled"):
        builder = RecordingBuilder()
        ips = replace(params, engine=engine)  # the log is made: only the IPS sees the engine
        twin_recording(builder, log, robot, ips, seed=5, beacons=default_beacon_map())
        recordings.append(builder.build())
    _assert_same_recording(*recordings)
    assert recordings[0].topic("/hedge_pos_ang").t_ns.size > 100
