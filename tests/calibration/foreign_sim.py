"""A "foreign" simulator, independent of omnical.twin: recordings made by a simulator not ours.

A pure kinematic integrator with the seven-factor truth written out from the definitions
(docs/CONVENTIONS.md), a hedgehog offset and a simple Marvelmind-like IPS (range noise, NLOS
outliers, latency), producing a :class:`Recording` with only the documented topics: /cmd_vel,
/odom (pose + body twist, yaw wrapped like a real bag), /beacon_raw_distance bursts,
/beacons_pos_a and /hedge_pos_ang. It shares no code with omnical's twin or kinematics: only the
RecordingBuilder is used, to write the result. Its rates, beacon map, addresses and time base
differ from the twin's on purpose.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.recording.recording import Recording, RecordingBuilder

Twist = Callable[[float], tuple[float, float, float]]

BEACONS = {1: (0.0, 0.0, 1.8), 2: (7.2, 0.0, 1.9), 7: (7.0, 6.1, 1.7), 8: (0.1, 6.0, 1.8)}


@dataclass(frozen=True)
class ForeignTruth:
    """Truth of a foreign run. Scales (long, lat, rot); cross-talks (fwd, rev, left, right) rad/m."""

    scales: tuple[float, float, float] = (0.985, 1.06, 1.03)
    crosstalks: tuple[float, float, float, float] = (-0.006, 0.004, 0.025, -0.018)
    installed_scales: tuple[float, float, float] = (1.0, 1.0, 1.0)
    installed_crosstalks: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    hedge_offset_m: tuple[float, float] = (-0.06, 0.05)
    hedge_z_m: float = 0.35
    start_map: tuple[float, float, float] = (3.4, 2.9, 0.7)
    start_odom: tuple[float, float, float] = (12.0, -4.0, 2.5)  # odom did not start at zero
    latency_s: float = 0.07
    ips_rate_hz: float = 16.0
    range_sigma_m: float = 0.02
    outlier_probability: float = 0.05
    slip_sigma: float = 0.0  # relative σ of the real twist's slip (Ornstein–Uhlenbeck), 0: none
    slip_correlation_s: float = 0.5


def _yaw_from(c: tuple[float, ...], vx: float, vy: float) -> float:
    return c[0] * max(vx, 0) + c[1] * max(-vx, 0) + c[2] * max(vy, 0) + c[3] * max(-vy, 0)


def _step(p: list[float], v: tuple[float, float, float], dt: float) -> None:
    mid = p[2] + 0.5 * v[2] * dt
    p[0] += (v[0] * math.cos(mid) - v[1] * math.sin(mid)) * dt
    p[1] += (v[0] * math.sin(mid) + v[1] * math.cos(mid)) * dt
    p[2] += v[2] * dt


def simulate(
    twist: Twist, duration_s: float, truth: ForeignTruth, seed: int, *, ground_truth: bool = False
) -> Recording:
    """Run ``twist(t)`` (desired body twist) open loop for ``duration_s`` and record it.

    ``ground_truth``: also record the real pose of base_link in the map as ``/ground_truth``
    (at the odometry's 20 Hz), for evaluations against the truth (no user recording has it).
    """
    rng = np.random.default_rng(seed)
    dt, t0_ns = 0.005, 1_700_000_000_123_456_789
    ks, kc = truth.installed_scales, truth.installed_crosstalks
    real, odom = list(truth.start_map), list(truth.start_odom)
    out = RecordingBuilder()
    hedge: list[tuple[float, float, float]] = []
    slip = [0.0, 0.0, 0.0]
    for i in range(round(duration_s / dt) + 1):
        t = i * dt
        cx, cy, cw = twist(t)
        # firmware: inject cross-talk, then scale (the wheels then do exactly this)
        w = (cx * ks[0], cy * ks[1], (cw - _yaw_from(kc, cx, cy)) * ks[2])
        vx, vy = w[0] / truth.scales[0], w[1] / truth.scales[1]
        v_real = (vx, vy, w[2] / truth.scales[2] + _yaw_from(truth.crosstalks, vx, vy))
        if truth.slip_sigma > 0.0:  # the wheels slip: the body moves a little off the plant
            a = math.exp(-dt / truth.slip_correlation_s)
            slip = [a * e + math.sqrt(1.0 - a * a) * truth.slip_sigma * rng.normal() for e in slip]
            v_real = (
                v_real[0] * (1 + slip[0]),
                v_real[1] * (1 + slip[1]),
                v_real[2] * (1 + slip[2]),
            )
        ox, oy = w[0] / ks[0], w[1] / ks[1]
        v_odom = (ox, oy, w[2] / ks[2] + _yaw_from(kc, ox, oy))
        stamp = t0_ns + round(t * 1e9)
        if i % 10 == 0:  # 20 Hz, as the Wheeltec node publishes
            out.add("/cmd_vel", stamp, vx_mps=cx, vy_mps=cy, wz_radps=cw)
            yaw = math.atan2(math.sin(odom[2]), math.cos(odom[2]))
            out.add(
                "/odom",
                stamp,
                x_m=odom[0],
                y_m=odom[1],
                yaw_rad=yaw,
                vx_mps=v_odom[0],
                vy_mps=v_odom[1],
                wz_radps=v_odom[2],
            )
            if ground_truth:
                out.add(
                    "/ground_truth",
                    stamp,
                    x_m=real[0],
                    y_m=real[1],
                    yaw_rad=math.atan2(math.sin(real[2]), math.cos(real[2])),
                    vx_mps=v_real[0],
                    vy_mps=v_real[1],
                    wz_radps=v_real[2],
                )
        c, s = math.cos(real[2]), math.sin(real[2])
        ho = truth.hedge_offset_m
        hedge.append((t, real[0] + c * ho[0] - s * ho[1], real[1] + s * ho[0] + c * ho[1]))
        _step(real, v_real, dt)
        _step(odom, v_odom, dt)
    _ips(out, np.array(hedge), truth, rng, t0_ns)
    return out.build()


def _ips(
    out: RecordingBuilder,
    hedge: NDArray[np.float64],
    truth: ForeignTruth,
    rng: np.random.Generator,
    t0_ns: int,
) -> None:
    for k, t_b in enumerate(np.arange(0.0, hedge[-1, 0], 10.0)):
        for j, (addr, pos) in enumerate(BEACONS.items()):
            out.add(
                "/beacons_pos_a",
                t0_ns + round((t_b + 0.002 * j + 1e-4 * k) * 1e9),
                address=addr,
                x_m=pos[0],
                y_m=pos[1],
                z_m=pos[2],
            )
    for t_e in np.arange(0.3, hedge[-1, 0] - 0.3, 1.0 / truth.ips_rate_hz):
        x = float(np.interp(t_e, hedge[:, 0], hedge[:, 1]))
        y = float(np.interp(t_e, hedge[:, 0], hedge[:, 2]))
        t_pub = t_e + truth.latency_s
        out.add(
            "/hedge_pos_ang",
            t0_ns + round(t_pub * 1e9),
            address=12,
            timestamp_ms=round(t_e * 1e3),
            x_m=x + rng.normal(0, 0.01),
            y_m=y + rng.normal(0, 0.01),
            z_m=truth.hedge_z_m,
            flags=0,
            angle_deg=0.0,
        )
        for j, (addr, (bx, by, bz)) in enumerate(BEACONS.items()):
            d = math.sqrt((x - bx) ** 2 + (y - by) ** 2 + (truth.hedge_z_m - bz) ** 2)
            d += rng.normal(0.0, truth.range_sigma_m)
            if rng.random() < truth.outlier_probability:
                d += rng.uniform(0.2, 1.0)
            out.add(
                "/beacon_raw_distance",
                t0_ns + round((t_pub + 0.001 * (j + 1)) * 1e9),
                address_hedge=12,
                address_beacon=addr,
                distance_m=round(d, 3),
            )


def lissajous(t: float) -> tuple[float, float, float]:
    """A Lissajous-like body twist: every direction, both turning senses, ≤ 0.35 m/s."""
    ramp = min(1.0, t / 2.0)
    return (
        ramp * 0.30 * math.sin(2 * math.pi * t / 23.0),
        ramp * 0.25 * math.sin(2 * math.pi * t / 17.0 + 0.6),
        ramp * 0.45 * math.sin(2 * math.pi * t / 29.0 + 1.1),
    )


def piecewise(segments: list[tuple[float, float, float, float]], ramp_s: float = 1.0) -> Twist:
    """Body twist from (duration s, vx, vy, wz) segments, each ramped up and down linearly."""
    starts = np.cumsum([0.0] + [d for d, *_ in segments])

    def twist(t: float) -> tuple[float, float, float]:
        i = int(np.searchsorted(starts, t, side="right")) - 1
        if i < 0 or i >= len(segments):
            return (0.0, 0.0, 0.0)
        d, vx, vy, wz = segments[i]
        f = min(1.0, (t - starts[i]) / ramp_s, (starts[i] + d - t) / ramp_s)
        return (f * vx, f * vy, f * wz)

    return twist


def square_dance() -> tuple[Twist, float]:
    """Every direction of the seven factors, twice, with turns between (≈ 150 s)."""
    v, h = 0.3, (1.5, 0.0, 0.0, 0.0)
    loop = [(11.0, v, 0, 0), h, (9.0, 0, v, 0), h, (11.0, -v, 0, 0), h, (9.0, 0, -v, 0), h]
    turn = [(9.0, 0, 0, 0.8), h]
    diag = [(10.0, 0.2, 0.2, 0), h, (10.0, -0.2, -0.2, 0), h, (10.0, 0.2, -0.2, 0), h]
    diag += [(10.0, -0.2, 0.2, 0), h]
    segments = [(2.0, 0.0, 0.0, 0.0), *loop, *turn, *diag, *turn, *loop]
    return piecewise(segments), sum(d for d, *_ in segments) + 1.0
