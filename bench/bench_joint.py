"""Joint-calibration benchmark: time and peak memory against the recording length.

Simulates 1, 10 and 60 minutes of robot time on the default twin (seed 000 Table 2 truth,
slip, NLOS outliers, hedgehog offset): a script of random moves in every direction (forward,
reverse, lateral, diagonal, to random points of seed 000's room) and turns of both senses.
Each estimate (``estimate_joint``, latency estimated, fixes precomputed by ``locate``) runs in a
fresh subprocess, which reports its wall and CPU time and its peak RSS during the estimate
(Linux: the high-water mark reset just before it; the RSS then, with the recording and the fixes
loaded, is printed as the base; elsewhere ``ru_maxrss``, loading included). The
baseline is the former dense path (``solver="dense"``: whole Jacobian, dense SVD, slip chunks
capped at 150; removed in issue 24, so taken from the source of ``--baseline``, a commit that
still had it) measured in the same run on the 1-minute case (and longer with
``--dense-up-to``). Also prints each estimate's error against the twin's truth.
Targets: 60 min ≤ 30 s CPU and ≤ 1 GB peak; 10 min ≤ 5 s.

The CLI path too (issue "Scale": the estimator alone was fast, ``omnical calibrate estimate
--method joint`` on an 80-minute recording did not converge): each simulated bag goes through
``omnical calibrate estimate BAG --method joint`` run by a fresh interpreter, which reports its
own CPU and wall time and its peak RSS (VmHWM from /proc/self/status, bench_bag.py's way: the
whole command, reading the bag and locating the fixes included). The baseline in the same run is
the same command of ``--baseline`` with its dense solver (``estimate_joint(solver="dense")``
patched in as the default) up to ``--dense-up-to`` minutes. The estimates (from the written YAML) are printed
against the twin's truth, with their σ.

Run: ``.venv/bin/python bench/bench_joint.py [--minutes 1 10 60] [--dense-up-to 1] [--no-cli]
[--baseline COMMIT]``

Coverage of the one-sigma uncertainties over robots (``--coverage 20 [--simulator twin|foreign]
[--slip S]``): random true factors per robot, the three procedure recordings, the joint estimate
as the CLI makes it; per factor the share within 1σ and 2σ (honest: 68 % and 95 %), the RMS
error, the median σ and the noise model found. Measured (issue 29, ``docs/joint-calibration.md``):
twin, 84 robots (seeds 1–84), within 1σ 75 / 70 / 74 / 75 / 76 / 60 / 65 % (scales long., lat.,
rot.; cross-talks fwd, rev, left, right; 95–100 % within 2σ), the left and right biased +0.7σ
/ −0.8σ by the twin's motor dynamics; before the noise model and the sandwich covariance 80 /
75 / 80 / 83 / 88 / 75 / 77 %. The independent simulator (84 robots) without slip 69–85 % (the
rotational scale 98 %, its errors nil), with 0.3 % slip 69–80 %, with 1 % slip 55–71 % (the
rotational scale 68 %, was 35 %). 24 robots scatter a share by ±10 %.

Consistency of the one-sigma uncertainties (``--consistency 10 60 [--seeds 12]``): the tour of
forward 2.5 m, left 2 m, a triple turn, reverse and right repeated for that many minutes on the
default twin, one recording per seed, estimated as the CLI does (latency held at the assumed
50 ms) and with the latency estimated; per factor and the hedgehog offset the mean and spread of
z = (estimate − truth) / σ over the seeds, the share of |z| > 2 and the largest |z|. Honest σ:
mean ≈ 0, spread ≤ 1, few |z| > 2. (Before the held latency's error was charged to the σ, the
60-minute runs had the reverse cross-talk at z +2.0 and the offset's y at +2.1 on average.)
10 minutes, 12 seeds (issue 29): latency estimated, mean z −0.42…+0.24, spread 0.81–1.12;
held at 50 ms (the twin's fixes lag 43 ms) the means reach ±1.0 with spreads 0.7–0.9.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import pickle
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

BASELINE = "0dc267689daceb12d82a982270071d9e43d6a01b"
"""A commit with ``estimate_joint(solver="dense")`` (on main, before issue 24 removed it)."""
ROOT = Path(__file__).resolve().parents[1]
NEW = "-"
"""A child's source argument: this checkout (else the baseline's ``src`` directory, dense)."""

ROOM_X_M = (1.0, 4.7)
ROOM_Y_M = (1.0, 3.8)
SPEED_MPS = 0.25
RATE_RADPS = 0.8


def random_steps(rng: np.random.Generator, count: int, state: list[float]) -> list[dict[str, Any]]:
    """``count`` moves: every third a turn (±60…300°, heading kept within ±2π), else a move in
    a random body direction to a random point of the room (commanded dead reckoning)."""
    steps: list[dict[str, Any]] = []
    x, y, yaw = state
    for n in range(count):
        if n % 3 == 2:
            angle = math.radians(float(rng.uniform(60.0, 300.0))) * (
                1 if rng.random() < 0.5 else -1
            )
            if abs(yaw + angle) > 2 * math.pi:
                angle = -angle
            steps.append(
                {
                    "move": {
                        "wz_radps": math.copysign(RATE_RADPS, angle),
                        "angle_deg": abs(math.degrees(angle)),
                    }
                }
            )
            yaw += angle
        else:
            tx, ty = float(rng.uniform(*ROOM_X_M)), float(rng.uniform(*ROOM_Y_M))
            d = math.hypot(tx - x, ty - y)
            if d < 0.3:
                continue
            c, s = math.cos(yaw), math.sin(yaw)
            bx, by = c * (tx - x) + s * (ty - y), -s * (tx - x) + c * (ty - y)
            steps.append(
                {
                    "move": {
                        "vx_mps": SPEED_MPS * bx / d,
                        "vy_mps": SPEED_MPS * by / d,
                        "distance_m": d,
                    }
                }
            )
            x, y = tx, ty
        steps.append({"hold": {"duration_s": 0.5}})
    state[:] = [x, y, yaw]
    return steps


def make_case(minutes: float, directory: Path, seed: int = 1) -> dict[str, Any]:
    """Simulate ``minutes`` of robot time, locate the fixes, save both; return a description."""
    from omnical.bags.bag import write_bag
    from omnical.experiment.script import parse_script
    from omnical.ips.from_recording import locate
    from omnical.robot.loader import load_robot
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    params = default_twin(robot)
    rng = np.random.default_rng(seed)
    state = [1.5, 1.2, 0.0]
    steps: list[dict[str, Any]] = [{"hold": {"duration_s": 2.0}}]
    while True:
        steps += random_steps(rng, 3, state)
        script = parse_script({"name": f"bench-{minutes:g}", "steps": steps}, robot.limits)
        if script.duration_s >= 60.0 * minutes - 2.0:
            break
    t0 = time.perf_counter()
    rec = simulate_run(script, robot, params, seed=seed)
    sim_s = time.perf_counter() - t0
    rec = rec.without("/ground_truth", "/omnical/events")
    t0 = time.perf_counter()
    fixes, _ = locate(rec)
    locate_s = time.perf_counter() - t0
    bag = directory / f"case-{minutes:g}"
    write_bag(rec, bag, overwrite=True)
    (directory / f"case-{minutes:g}.fixes").write_bytes(pickle.dumps(fixes))
    truth = params.true_factors
    return {
        "minutes": minutes,
        "bag": str(bag),
        "fixes": str(directory / f"case-{minutes:g}.fixes"),
        "robot_s": rec.duration_s,
        "n_odom": len(rec.topic("/odom")),
        "n_fixes": len(fixes.status),
        "sim_s": sim_s,
        "locate_s": locate_s,
        "truth": truth.as_vector().tolist(),
    }


def _status_gb(field: str) -> float | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1e6  # kB
    except OSError:
        pass
    return None


def _reset_peak_rss() -> float:
    """Reset the peak RSS to the current RSS (Linux: clear_refs 5); return the current RSS, GB.

    Elsewhere the peak stays the process's (``ru_maxrss``), loading included.
    """
    with contextlib.suppress(OSError):
        Path("/proc/self/clear_refs").write_text("5")
    current = _status_gb("VmRSS")
    return (
        current if current is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    )


def _peak_rss_gb() -> float:
    peak = _status_gb("VmHWM")
    return peak if peak is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def _use_source(src: str) -> dict[str, str]:
    """Import omnical from ``src`` (the baseline's, dense) unless it is :data:`NEW`; the
    keywords that select the dense solver there."""
    if src == NEW:
        return {}
    sys.path.insert(0, src)
    return {"solver": "dense"}


def child(bag: str, fixes_path: str, src: str) -> None:
    """Run one estimate in this (fresh) process and print its measurements as JSON."""
    import warnings

    dense = _use_source(src)

    from omnical.bags.bag import read_bag
    from omnical.calibration.joint.estimate import estimate_joint

    rec = read_bag(bag)
    fixes = pickle.loads(Path(fixes_path).read_bytes())
    base_gb = _reset_peak_rss()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = estimate_joint([rec], fixes=[fixes], estimate_latency=True, **dense)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    peak_gb = _peak_rss_gb()
    out = {
        "wall_s": wall,
        "cpu_s": cpu,
        "base_gb": base_gb,
        "peak_gb": peak_gb,
        "factors": est.factors.as_vector().tolist(),
        "sigma": est.factor_sigma.as_vector().tolist(),
        "offset": list(est.hedge_offset_m),
        "latency_s": est.latency_s,
        "slip": est.n_slip_parameters,
        "warnings": list(est.warnings),
    }
    print(json.dumps(out))


def cli_child(bag: str, src: str) -> None:
    """Run ``omnical calibrate estimate BAG --method joint`` in this (fresh) process."""
    import io
    import warnings

    import yaml

    dense = _use_source(src)
    if dense:  # the former path as the baseline: the dense solver as the default
        from omnical.calibration.joint import estimate as joint

        defaults = dict(joint.estimate_joint.__kwdefaults__ or {})
        defaults.update(dense)
        joint.estimate_joint.__kwdefaults__ = defaults
    from omnical.cli.main import main as cli_main

    out = Path(tempfile.mkdtemp()) / "factors.yaml"
    sys.argv = ["omnical", "calibrate", "estimate", bag, "--method", "joint", "--out", str(out)]
    wall0 = time.perf_counter()
    printed = io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stdout(printed):
        warnings.simplefilter("ignore")
        with contextlib.suppress(SystemExit):
            cli_main()
    wall = time.perf_counter() - wall0
    usage = resource.getrusage(resource.RUSAGE_SELF)
    cpu = usage.ru_utime + usage.ru_stime  # the whole process, imports included
    params = yaml.safe_load(out.read_text())  # the factors file: scale, crosstalk, uncertainty
    unc = params["uncertainty"]
    scales = ("longitudinal", "lateral", "rotational")
    talks = ("forward", "reverse", "left", "right")
    factors = [params["scale"][k] for k in scales] + [
        params["crosstalk_rad_per_m"][k] for k in talks
    ]
    sigma = [unc["scale"][k] for k in scales] + [unc["crosstalk_rad_per_m"][k] for k in talks]
    text = printed.getvalue()
    result = {
        "wall_s": wall,
        "cpu_s": cpu,
        "peak_gb": _peak_rss_gb(),
        "factors": factors,
        "sigma": sigma,
        "converged": "without converging" not in text,
    }
    print(json.dumps(result))


def run_cli_child(case: dict[str, Any], src: str) -> dict[str, Any]:
    """Run :func:`cli_child` in a fresh interpreter (default BLAS threads, as a user would)."""
    proc = subprocess.run(
        [sys.executable, __file__, "--cli-child", case["bag"], src],
        capture_output=True,
        text=True,
        check=True,
    )
    result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def describe_cli(case: dict[str, Any], res: dict[str, Any], solver: str) -> str:
    truth = np.array(case["truth"])
    est, sigma = np.array(res["factors"]), np.array(res["sigma"])
    err = est - truth
    names = ("lon", "lat", "rot")
    scales = "  ".join(
        f"{n} {v:.4f} ± {s:.4f}" for n, v, s in zip(names, est[:3], sigma[:3], strict=True)
    )
    return (
        f"  CLI {solver:6s} wall {res['wall_s']:7.2f} s  CPU {res['cpu_s']:7.2f} s  "
        f"peak RSS {res['peak_gb']:5.2f} GB  {'converged' if res['converged'] else 'NOT converged'}\n"
        f"         {scales}  (truth {truth[0]:.4f} {truth[1]:.4f} {truth[2]:.4f}); "
        f"max |err|/σ {np.nanmax(np.abs(err) / sigma):.2f}"
    )


def run_child(case: dict[str, Any], src: str) -> dict[str, Any]:
    """Run :func:`child` in a fresh interpreter (one BLAS thread: the CPU time is one core's)."""
    env = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    import os

    proc = subprocess.run(
        [sys.executable, __file__, "--child", case["bag"], case["fixes"], src],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, **env},
    )
    result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def describe(case: dict[str, Any], res: dict[str, Any], solver: str) -> str:
    truth = np.array(case["truth"])
    err = np.array(res["factors"]) - truth
    sigma = np.array(res["sigma"])
    scale_err = np.abs(err[:3] / truth[:3]) * 100.0
    offset_err = math.hypot(res["offset"][0] - 0.04, res["offset"][1] + 0.03) * 1000.0
    return (
        f"  {solver:6s} wall {res['wall_s']:7.2f} s  CPU {res['cpu_s']:7.2f} s  "
        f"peak RSS {res['peak_gb']:5.2f} GB (base {res['base_gb']:.2f})  slip params {res['slip']:5d}\n"
        f"         |scale err| max {scale_err.max():.3f} %  |crosstalk err| max "
        f"{np.abs(err[3:]).max() * 1000:.2f} mrad/m  max |err|/σ {np.nanmax(np.abs(err) / sigma):.2f}  "
        f"offset err {offset_err:.1f} mm  latency {res['latency_s'] * 1000:.1f} ms"
        + (f"\n         warnings: {res['warnings']}" if res["warnings"] else "")
    )


TOUR_STEPS: list[dict[str, Any]] = [
    {"hold": {"duration_s": 3.0}},
    {"move": {"vx_mps": 0.25, "distance_m": 2.5}},
    {"hold": {"duration_s": 2.0}},
    {"move": {"vy_mps": 0.2, "distance_m": 2.0}},
    {"hold": {"duration_s": 2.0}},
    {"move": {"wz_radps": 0.8, "angle_deg": 1080}},
    {"hold": {"duration_s": 2.0}},
    {"move": {"vx_mps": -0.25, "distance_m": 2.5}},
    {"hold": {"duration_s": 2.0}},
    {"move": {"vy_mps": -0.2, "distance_m": 2.0}},
    {"hold": {"duration_s": 3.0}},
]
"""One tour (≈ 47 s), repeated for the consistency check (the session-4 long recordings')."""


def consistency(minutes: float, seeds: int) -> None:
    """z of every factor and the offset over ``seeds`` twin recordings of the repeated tour."""
    import warnings

    from omnical.calibration.joint.estimate import FACTOR_NAMES, estimate_joint
    from omnical.experiment.script import parse_script
    from omnical.ips.from_recording import locate
    from omnical.robot.loader import load_robot
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    robot = load_robot("rosy-mecanum")
    params = default_twin(robot)
    offset = robot.hedge_offset_m[:2]
    one = parse_script({"name": "tour", "steps": TOUR_STEPS}, robot.limits)
    tours = max(1, round(60.0 * minutes / one.duration_s))
    script = parse_script({"name": "tours", "steps": TOUR_STEPS * tours}, robot.limits)
    names = [*FACTOR_NAMES, "hedge_offset_x_m", "hedge_offset_y_m"]
    truth = np.concatenate([params.true_factors.as_vector(), offset])
    z: dict[bool, list[np.ndarray]] = {False: [], True: []}
    cpu: dict[bool, float] = {False: 0.0, True: 0.0}
    found: list[float] = []
    for seed in range(1, seeds + 1):
        rec = simulate_run(script, robot, params, seed=seed).without("/ground_truth")
        fixes, _ = locate(rec)
        for free in (False, True):
            cpu0 = time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est = estimate_joint(
                    [rec], fixes=[fixes], hedge_offset_m=offset, estimate_latency=free
                )
            cpu[free] += time.process_time() - cpu0
            value = np.concatenate([est.factors.as_vector(), est.hedge_offset_m])
            sigma = np.array([est.sigma[n] for n in names])
            z[free].append((value - truth) / sigma)
            if free:
                found.append(est.latency_s)
    print(
        f"{minutes:g} min ({tours} tours), {seeds} seeds; latency estimated: "
        f"{np.mean(found) * 1000:.1f} ms (held: 50 ms)"
    )
    for free in (False, True):
        zs = np.array(z[free])
        label = "latency estimated" if free else "latency held (CLI)"
        print(f"  {label}: CPU {cpu[free] / seeds:.2f} s per estimate")
        print("    factor                        mean z  sd z  |z|>2  max|z|")
        for j, name in enumerate(names):
            col = zs[:, j]
            print(
                f"    {name:28s} {col.mean():+6.2f} {col.std(ddof=1) if seeds > 1 else 0.0:5.2f} "
                f"{np.mean(np.abs(col) > 2.0):6.2f} {np.abs(col).max():6.2f}"
            )


def _random_truth(rng: np.random.Generator) -> np.ndarray:
    """Seven true factors of a random robot: scalings within ±6 % (rotational ±4 %),
    cross-talks of either sign up to 35 mrad/m (seed 000's largest is 39)."""
    scales = 1.0 + rng.uniform(-1.0, 1.0, 3) * np.array([0.06, 0.06, 0.04])
    talks = rng.uniform(-0.035, 0.035, 4)
    out: np.ndarray = np.concatenate([scales, talks])
    return out


def _procedure_scripts() -> list[Any]:
    from omnical.calibration.procedures.scripts import (
        lateral_procedure,
        longitudinal_procedure,
        rotation_procedure,
    )
    from omnical.experiment.script import parse_script
    from omnical.robot.loader import load_robot

    limits = load_robot("rosy-mecanum").limits
    procedures = (rotation_procedure(), longitudinal_procedure(), lateral_procedure())
    return [parse_script(p, limits) for p in procedures]


def _foreign_module() -> Any:
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "tests" / "calibration" / "foreign_sim.py"
    spec = importlib.util.spec_from_file_location("foreign_sim", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["foreign_sim"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _procedure_recordings(
    simulator: str, truth: np.ndarray, seed: int, slip: float | None = None
) -> tuple[list[Any], Any]:
    """The three procedure recordings of a robot with the true factors ``truth`` on the twin or
    the tests' independent simulator, and the lever arm the robot description gives. ``slip``:
    the relative σ of the wheels' slip (None: the twin's own 0.3 %, none on the other)."""
    from dataclasses import replace

    from omnical.kinematics.correction import CorrectionFactors
    from omnical.robot.loader import load_robot
    from omnical.twin.params import default_twin
    from omnical.twin.session import simulate_run

    scripts = _procedure_scripts()
    if simulator == "twin":
        robot = load_robot("rosy-mecanum")
        params = replace(default_twin(robot), true_factors=CorrectionFactors.from_vector(truth))
        if slip is not None:
            params = replace(params, slip_sigma=slip)
        recs = [simulate_run(s, robot, params, seed=seed * 10 + i) for i, s in enumerate(scripts)]
        return recs, robot.hedge_offset_m
    fs = _foreign_module()
    base = fs.ForeignTruth(
        scales=tuple(float(v) for v in truth[:3]),
        crosstalks=tuple(float(v) for v in truth[3:]),
        start_map=(1.5, 1.6, 0.0),
        slip_sigma=slip or 0.0,
    )
    recs = [
        fs.simulate(s.twist_at, s.duration_s + 2.0, base, seed=seed * 10 + i)
        for i, s in enumerate(scripts)
    ]
    return recs, (*base.hedge_offset_m, base.hedge_z_m)


_last_noise: dict[str, float] = {}


def _capture_noise() -> None:
    """Keep each joint estimate's noise model in :data:`_last_noise` (the CLI's path hides it)."""
    from omnical.calibration.joint import estimate as joint

    original = joint.estimate_joint

    def wrapped(*args: Any, **kwargs: Any) -> Any:
        est = original(*args, **kwargs)
        _last_noise.clear()
        _last_noise.update(getattr(est, "noise_variance", {}))
        return est

    joint.estimate_joint = wrapped


def joint_coverage(robots: int, simulator: str, first_seed: int, slip: float | None = None) -> None:
    """Per factor, the share of ``robots`` random robots whose estimate lies within its 1σ.

    Each robot: random true factors (:func:`_random_truth`), the three procedure recordings
    (rotation, longitudinal, lateral; ≈ 5.6 min of robot time), estimated as ``omnical
    calibrate estimate --method joint`` does (:func:`~omnical.calibration.campaign.
    estimate_factors`: latency held at 50 ms on recordings this short, the robot's lever arm
    the start). Honest σ: each factor within 1σ 68 % of the time (± 10 % with 20 robots),
    within 2σ 95 %. Also per factor the RMS error (% for the scalings, mrad/m for the
    cross-talks), the median σ, and the median noise model the estimates found.
    """
    from omnical.calibration.campaign import estimate_factors
    from omnical.calibration.joint.estimate import FACTOR_NAMES

    _capture_noise()
    z_rows: list[np.ndarray] = []
    err_rows: list[np.ndarray] = []
    sigma_rows: list[np.ndarray] = []
    noise: list[dict[str, float]] = []
    cpu = 0.0
    for k in range(robots):
        seed = first_seed + k
        truth = _random_truth(np.random.default_rng(seed))
        recs, arm = _procedure_recordings(simulator, truth, seed, slip)
        cpu0 = time.process_time()
        est = estimate_factors(recs, method="joint", hedge_offset_m=arm)
        cpu += time.process_time() - cpu0
        noise.append(dict(_last_noise))
        value = est.factors.as_vector()
        sigma = np.array([est.sigma[n] for n in FACTOR_NAMES])
        z = (value - truth) / sigma
        z_rows.append(z)
        err_rows.append(value - truth)
        sigma_rows.append(sigma)
        print(
            f"  robot {seed:3d}: z " + " ".join(f"{v:+5.2f}" for v in z),
            flush=True,
        )
    zs = np.array(z_rows)
    print(
        f"{simulator}{f' (slip {slip:g})' if slip is not None else ''}: {robots} robots with random true "
        f"factors, three procedure recordings each, joint estimate as the CLI makes it "
        f"({cpu / robots:.1f} s CPU each)"
    )
    errs, sigmas = np.array(err_rows), np.array(sigma_rows)
    print(
        "  factor                  within 1σ  within 2σ  mean z  sd z  max |z|  RMS error  median σ"
    )
    for j, name in enumerate(FACTOR_NAMES):
        col = zs[:, j][np.isfinite(zs[:, j])]
        unit = 100.0 if j < 3 else 1000.0  # % and mrad/m
        print(
            f"  {name:24s} {100 * np.mean(np.abs(col) <= 1):7.0f} %  {100 * np.mean(np.abs(col) <= 2):7.0f} %"
            f"  {col.mean():+6.2f} {col.std(ddof=1):5.2f} {np.abs(col).max():7.2f}"
            f"  {unit * np.sqrt(np.mean(errs[:, j] ** 2)):9.4f}  {unit * np.median(sigmas[:, j]):8.4f}"
        )
    every = zs[np.isfinite(zs)]
    print(
        f"  all factors              {100 * np.mean(np.abs(every) <= 1):7.0f} %  "
        f"{100 * np.mean(np.abs(every) <= 2):7.0f} %  {every.mean():+6.2f} {every.std(ddof=1):5.2f}"
        f" {np.abs(every).max():7.2f}"
    )
    if noise and noise[0]:
        print(
            "  noise model (variance against the given, median): "
            + ", ".join(f"{k} {np.median([n[k] for n in noise if k in n]):.3g}" for k in noise[0])
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument(
        "--dense-up-to", type=float, default=1.0, help="also run the dense path up to this length"
    )
    parser.add_argument("--no-cli", action="store_true", help="skip the CLI path")
    parser.add_argument(
        "--baseline", default=BASELINE, help="commit whose dense solver is the baseline"
    )
    parser.add_argument(
        "--consistency",
        type=float,
        nargs="+",
        metavar="MINUTES",
        help="only the σ consistency check: z over seeds of the repeated tour, these lengths",
    )
    parser.add_argument(
        "--seeds", type=int, default=12, help="recordings per length (--consistency)"
    )
    parser.add_argument(
        "--coverage",
        type=int,
        metavar="ROBOTS",
        help="only the 1σ coverage over this many random robots' procedure recordings",
    )
    parser.add_argument(
        "--simulator",
        choices=("twin", "foreign"),
        default="twin",
        help="the simulator of --coverage: the twin or the tests' independent one",
    )
    parser.add_argument("--first-seed", type=int, default=1, help="first robot's seed (--coverage)")
    parser.add_argument(
        "--slip",
        type=float,
        default=None,
        help="relative σ of the wheels' slip (--coverage; default: the twin's 0.003, none on the other)",
    )
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    parser.add_argument("--cli-child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(*args.child)
        return
    if args.cli_child:
        cli_child(*args.cli_child)
        return
    if args.coverage:
        joint_coverage(args.coverage, args.simulator, args.first_seed, args.slip)
        return
    if args.consistency:
        for minutes in args.consistency:
            consistency(minutes, args.seeds)
        return
    print(
        "joint calibration (estimate_joint, latency estimated, fixes precomputed), one core per estimate"
    )
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "baseline"
        if any(m <= args.dense_up_to for m in args.minutes):
            old.mkdir()
            archive = subprocess.run(
                ["git", "-C", str(ROOT), "archive", args.baseline, "src"],
                capture_output=True,
                check=True,
            )
            subprocess.run(["tar", "-x", "-C", str(old)], input=archive.stdout, check=True)
        dense_src = str(old / "src")
        for minutes in args.minutes:
            case = make_case(minutes, Path(tmp))
            print(
                f"{minutes:g} min: robot time {case['robot_s']:.0f} s, {case['n_odom']} odom samples, "
                f"{case['n_fixes']} fixes (simulate {case['sim_s']:.1f} s, locate {case['locate_s']:.1f} s)"
            )
            sparse = run_child(case, NEW)
            print(describe(case, sparse, "sparse"))
            target = 5.0 if minutes <= 10 else 30.0
            print(
                f"         target CPU ≤ {target:g} s: {'met' if sparse['cpu_s'] <= target else 'NOT met'}; "
                f"peak ≤ 1 GB: {'met' if sparse['peak_gb'] <= 1.0 else 'NOT met'}"
            )
            if minutes <= args.dense_up_to:
                dense = run_child(case, dense_src)
                print(describe(case, dense, "dense"))
                print(
                    f"         dense/sparse: wall {dense['wall_s'] / sparse['wall_s']:.1f}x, "
                    f"CPU {dense['cpu_s'] / sparse['cpu_s']:.1f}x, peak RSS above base "
                    f"{(dense['peak_gb'] - dense['base_gb']) / max(sparse['peak_gb'] - sparse['base_gb'], 1e-3):.1f}x"
                )
            if args.no_cli:
                continue
            cli = run_cli_child(case, NEW)
            print(describe_cli(case, cli, "sparse"))
            print(
                f"         target CPU ≤ {target:g} s (whole command): "
                f"{'met' if cli['cpu_s'] <= target else 'NOT met'}; "
                f"peak ≤ 1 GB: {'met' if cli['peak_gb'] <= 1.0 else 'NOT met'}"
            )
            if minutes <= args.dense_up_to:
                was = run_cli_child(case, dense_src)
                print(describe_cli(case, was, "dense"))
                print(
                    f"         CLI dense/sparse: wall {was['wall_s'] / cli['wall_s']:.1f}x, "
                    f"CPU {was['cpu_s'] / cli['cpu_s']:.1f}x, "
                    f"peak RSS {was['peak_gb'] / cli['peak_gb']:.1f}x"
                )


if __name__ == "__main__":
    main()
