"""Issue 3 acceptance on the twin: robust vs plain least squares, and honest confidence ellipses.

The twin drives the standard tour; the simulated IPS measures it with 5 % and 10 % of distances
hit by non-line-of-sight outliers; each fix is compared with the true hedgehog position at the
emission of its measurement.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from ips_synthetic import locate_recording

from omnical.experiment.runner import run_script
from omnical.experiment.script import load_script
from omnical.ips.beacons import default_beacon_map
from omnical.ips.solve.fixes import CHI2_2DOF_95, FixStatus, mahalanobis_sq
from omnical.ips.solve.noise_model import NoiseModel
from omnical.robot.loader import load_robot
from omnical.twin.clock import TwinClock
from omnical.twin.ips_messages import IpsMeasurements
from omnical.twin.ips_model import simulate_ips
from omnical.twin.ips_params import IpsParams
from omnical.twin.params import default_twin
from omnical.twin.simulator import DigitalTwin


@cache
def _tour_truth(seed: int) -> tuple[np.ndarray, np.ndarray]:
    robot = load_robot("rosy-mecanum")
    twin = DigitalTwin(robot, default_twin(robot), seed=seed)
    run_script(load_script("tour", robot.limits), twin, TwinClock(twin))
    gt = twin.log().ground_truth
    return gt[:, 0], gt[:, 1:4]


def _measure(seed: int, nlos: float) -> IpsMeasurements:
    t, poses = _tour_truth(seed)
    bmap = default_beacon_map()
    params = replace(IpsParams(), nlos_probability=nlos, hedge_offset_base_m=(0.04, -0.03, 0.4))
    return simulate_ips(
        t, poses, bmap.addresses, bmap.positions_m, params, np.random.default_rng(seed)
    )


def _errors(ips: IpsMeasurements, method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = ips.distances
    t_ns = np.round(d.t_s * 1e9).astype(np.int64)
    fixes = locate_recording(
        t_ns,
        d.address_hedge,
        d.address_beacon,
        d.distance_m,
        default_beacon_map(),
        method=method,  # type: ignore[arg-type]
    )
    assert fixes.t_ns is not None
    first = np.searchsorted(t_ns, fixes.t_ns)
    truth = ips.truth.hedge_map_m[d.measurement_index[first], :2]
    delta = fixes.positions_map_m[:, :2] - truth
    return (
        np.hypot(delta[:, 0], delta[:, 1]),
        mahalanobis_sq(fixes.covariance_xy_m2, delta),
        fixes.status,
    )


@pytest.mark.parametrize("nlos", [0.05, 0.10])
@pytest.mark.parametrize("seed", [1, 2])
def test_robust_p95_at_most_half_of_lsq(seed: int, nlos: float) -> None:
    """The robust fixes it does not flag as rejected beat every least-squares fix.

    With 10 % of ranges biased, about 6 % of 4-beacon fixes carry two NLOS ranges; no per-fix
    method can recover those, and the robust solver flags them ``rejected`` rather than return
    them as usable. Counting those too, its 95th percentile is still lower than least squares'.
    """
    ips = _measure(seed, nlos)
    err_lsq, _, st_lsq = _errors(ips, "lsq")
    err_rob, _, st_rob = _errors(ips, "robust")
    solvable = (st_lsq != FixStatus.DEGENERATE) & (st_rob != FixStatus.DEGENERATE)
    usable = solvable & (st_rob <= FixStatus.DEGRADED)
    p95_lsq = np.percentile(err_lsq[solvable], 95)
    assert np.percentile(err_rob[usable], 95) <= 0.5 * p95_lsq
    assert np.percentile(err_rob[solvable], 95) < p95_lsq
    assert np.mean(st_rob[solvable] == FixStatus.REJECTED) < 0.1


@pytest.mark.parametrize("nlos", [0.05, 0.10])
@pytest.mark.parametrize("seed", [1, 2])
def test_confidence_ellipses_of_ok_fixes_are_honest(seed: int, nlos: float) -> None:
    ips = _measure(seed, nlos)
    _, m2, status = _errors(ips, "robust")
    ok = status == FixStatus.OK
    assert ok.sum() > 1000
    coverage = float(np.mean(m2[ok] <= CHI2_2DOF_95))
    assert 0.90 <= coverage <= 0.98, coverage


@pytest.mark.parametrize("seed", [1, 2])
def test_issue_11_targets_on_the_twin(seed: int) -> None:
    """5 % NLOS, learned noise model: measured ok|≥3 clean 0.950 / 0.962, RMSE 2.43 / 2.49 cm,
    p95 4.3 / 4.3 cm, coverage 0.950 / 0.959 (seeds 1 / 2)."""
    ips = _measure(seed, 0.05)
    d = ips.distances
    err, m2, status = _errors(ips, "robust")
    t_ns = np.round(d.t_s * 1e9).astype(np.int64)
    fixes_t = np.unique(t_ns[np.r_[True, np.diff(d.measurement_index) != 0]])
    index = d.measurement_index[np.searchsorted(t_ns, fixes_t)]
    clean = np.bincount(d.measurement_index, weights=~d.is_outlier)[index]
    ok = status == FixStatus.OK
    assert ok.size == clean.size
    assert np.mean(ok[clean >= 3]) >= 0.94
    assert np.sqrt(np.mean(err[ok] ** 2)) <= 0.025
    assert np.percentile(err[ok], 95) <= 0.05
    assert 0.90 <= np.mean(m2[ok] <= CHI2_2DOF_95) <= 0.98


def _locate(
    ips: IpsMeasurements, distance_m: np.ndarray
) -> tuple[np.ndarray, NoiseModel, np.ndarray]:
    d = ips.distances
    t_ns = np.round(d.t_s * 1e9).astype(np.int64)
    fixes = locate_recording(
        t_ns, d.address_hedge, d.address_beacon, distance_m, default_beacon_map()
    )
    assert fixes.t_ns is not None
    truth = ips.truth.hedge_map_m[d.measurement_index[np.searchsorted(t_ns, fixes.t_ns)], :2]
    return fixes.positions_map_m[:, :2] - truth, fixes.noise[0], fixes.status == FixStatus.OK


@pytest.mark.parametrize("seed", [1, 2])
def test_no_bias_is_learned_where_there_is_none(seed: int) -> None:
    """The twin's ranges have no per-link bias or scale: the self-calibration must not invent
    one from the one-sided NLOS outliers (it did: biases of 5–15 mm, scales +0.1–0.3 %, a mean
    fix error of several mm, which the calibration procedures read as a 0.2 % scale error)."""
    ips = _measure(seed, 0.05)
    delta, model, ok = _locate(ips, ips.distances.distance_m)
    bias, sd = model.bias_m, model.bias_sd_m
    assert np.all((np.abs(bias) < 0.002) | (np.abs(bias) <= 3.0 * np.nan_to_num(sd, nan=np.inf)))
    scale_error, scale_sd = np.abs(model.scale - 1.0), np.nan_to_num(model.scale_sd, nan=np.inf)
    assert np.all((scale_error < 5e-4) | (scale_error <= 3.0 * scale_sd))
    assert np.all(np.abs(np.mean(delta[ok], axis=0)) < 0.002)


def test_a_real_bias_and_scale_are_still_learned() -> None:
    """A link biased by +6 cm and another with a 1 % scale error: both found, fixes unbiased."""
    ips = _measure(1, 0.05)
    d = ips.distances
    beacons = default_beacon_map().addresses
    distance = d.distance_m.copy()
    distance[d.address_beacon == beacons[0]] += 0.06
    distance[d.address_beacon == beacons[2]] *= 1.01
    delta, model, ok = _locate(ips, distance)
    assert model.bias_m[0] == pytest.approx(0.06, abs=0.01)
    assert model.scale[2] == pytest.approx(1.01, abs=0.003) or (
        model.bias_m[2]
        == pytest.approx(0.01 * 4.0, abs=0.03)  # a bias can stand in on a short spread
    )
    assert np.all(np.abs(np.mean(delta[ok], axis=0)) < 0.003)
