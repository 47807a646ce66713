"""``omnical sweep``: Monte-Carlo calibration campaigns on the twin over the distributions of a
spec (true factors, IPS noise and NLOS, room size, iterations, slip), one row per run in
``DIR/sweep.csv``; run i's parameters and seed from ``SeedSequence(S).spawn(N)[i]``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from omnical.errors import ConfigError, OmnicalError
from omnical.fleet.executors import ExecutorSpec
from omnical.fleet.runner import claim_out_dir, run_chunk, run_into_table, shared_path
from omnical.fleet.table import INDEX, REASON, STATUS, failure

if TYPE_CHECKING:
    from omnical.ips.beacons import BeaconMap
    from omnical.robot.description import RobotDescription
    from omnical.twin.params import TwinParams

__all__ = [
    "PARAMETERS",
    "SWEEP_TABLE",
    "SweepJob",
    "SweepRun",
    "SweepSpec",
    "load_sweep_spec",
    "parse_sweep_spec",
    "run_sweep",
    "run_sweep_chunk",
    "sample_run",
    "sweep_header",
]

SWEEP_TABLE: Final = "sweep.csv"

_SCALES: Final = ("longitudinal", "lateral", "rotational")
_CROSSTALKS: Final = ("forward", "reverse", "left", "right")

PARAMETERS: Final = (
    *(f"true_factors.scale.{s}" for s in _SCALES),
    *(f"true_factors.crosstalk.{c}" for c in _CROSSTALKS),
    "ips.distance_noise_m",
    "ips.nlos_probability",
    "ips.latency_s",
    "room_scale",
    "iterations",
    "slip_sigma",
    "procedure.rotation.distance_m",
    "procedure.rotation.turns",
    "procedure.longitudinal.distance_m",
    "procedure.longitudinal.repeats",
    "procedure.lateral.distance_m",
    "procedure.lateral.repeats",
)
"""What a sweep can vary: the twin's true factors, its IPS's range noise (m), NLOS probability
and latency (s), the room (× seed 000's 5.8 m × 4.8 m beacon map, the start pose scaled with
it), the campaign's most iterations, the wheel slip σ, and the procedures' sizes (seed 000's:
rotation 2.5 m and 3 turns, longitudinal 3.5 m twice, lateral 3 m twice)."""

_INTEGER: Final = frozenset(
    {
        "iterations",
        "procedure.rotation.turns",
        "procedure.longitudinal.repeats",
        "procedure.lateral.repeats",
    }
)


class _Distribution(BaseModel):
    """One parameter: a number, or exactly one of the distributions."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    uniform: tuple[float, float] | None = None
    loguniform: tuple[float, float] | None = None
    normal: tuple[float, float] | None = None
    choice: tuple[float, ...] | None = Field(default=None, min_length=1, max_length=1000)

    @model_validator(mode="after")
    def _one(self) -> _Distribution:
        given = [k for k in ("uniform", "loguniform", "normal", "choice") if getattr(self, k)]
        if len(given) != 1:
            msg = "give exactly one of uniform, loguniform, normal, choice"
            raise ValueError(msg)
        for name in ("uniform", "loguniform"):
            pair = getattr(self, name)
            if pair is not None and not (
                math.isfinite(pair[0]) and math.isfinite(pair[1]) and pair[0] <= pair[1]
            ):
                raise ValueError(f"{name}: [low, high] with low ≤ high")
        if self.loguniform is not None and self.loguniform[0] <= 0.0:
            raise ValueError("loguniform: low must be > 0")
        if self.normal is not None and not self.normal[1] >= 0.0:
            raise ValueError("normal: [mean, sd] with sd ≥ 0")
        return self

    def draw(self, rng: np.random.Generator) -> float:
        if self.uniform is not None:
            return float(rng.uniform(*self.uniform))
        if self.loguniform is not None:
            low, high = np.log(self.loguniform)
            return float(np.exp(rng.uniform(low, high)))
        if self.normal is not None:
            return float(rng.normal(*self.normal))
        assert self.choice is not None
        return float(self.choice[int(rng.integers(len(self.choice)))])


class _SpecModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    robot: str = "rosy-mecanum"
    twin: Literal["default", "ideal"] | dict[str, Any] = "default"
    method: Literal["procedures", "joint"] = "procedures"
    iterations: int = Field(default=1, ge=1, le=10)
    validate_runs: bool = Field(default=False, alias="validate")
    target: float = Field(default=0.001, gt=0.0, le=1.0)
    parameters: dict[str, Any] = {}


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep spec (picklable: it travels with every job).

    Attributes:
        robot: robot preset or YAML path.
        twin: the twin mapping the runs start from (``omnical`` twin YAML format).
        method: the campaign's estimation method.
        iterations: most iterations of a campaign (unless ``iterations`` is varied).
        validate: run the validation procedures too.
        target: the relative scale error the report counts runs within (0.001 = 0.1 %).
        parameters: name → a number or a distribution (sorted by name).
        text: the spec as given (for the report).
        source: where it came from (its file), for messages.
    """

    robot: str
    twin: Mapping[str, Any]
    method: str
    iterations: int
    validate: bool
    target: float
    parameters: tuple[tuple[str, float | _Distribution], ...]
    text: str = ""
    source: str = "sweep spec"

    @property
    def varied(self) -> tuple[str, ...]:
        """The parameters drawn from a distribution (the report's axes)."""
        return tuple(n for n, d in self.parameters if isinstance(d, _Distribution))


def parse_sweep_spec(data: Any, source: str, text: str = "") -> SweepSpec:
    """A sweep spec (parsed YAML), validated.

    Raises:
        ConfigError: names the file, the field and the reason.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a sweep spec is a mapping (robot, twin, parameters, ...)")
    try:
        m = _SpecModel.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "(top level)"
        raise ConfigError(f"{source}: field '{where}': {first['msg']}") from None
    parameters: dict[str, float | _Distribution] = {}
    for name, value in m.parameters.items():
        where = f"{source}: field 'parameters.{name}'"
        if name not in PARAMETERS:
            raise ConfigError(f"{where}: unknown; one of {', '.join(PARAMETERS)}")
        if isinstance(value, int | float) and not isinstance(value, bool):
            if not math.isfinite(value):
                raise ConfigError(f"{where}: not a finite number")
            parameters[name] = float(value)
            continue
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: a number or one of uniform, loguniform, normal, choice")
        try:
            parameters[name] = _Distribution.model_validate(value)
        except ValidationError as err:
            first = err.errors()[0]
            inner = "".join(f".{p}" for p in first["loc"])
            why = str(first["msg"]).removeprefix("Value error, ")
            raise ConfigError(f"{source}: field 'parameters.{name}{inner}': {why}") from None
    twin = {"base": m.twin} if isinstance(m.twin, str) else dict(m.twin)
    robot = m.robot
    if robot.endswith((".yaml", ".yml")):  # a file: the same for workers in another directory
        robot = str(Path(robot).resolve())
    return SweepSpec(
        robot,
        twin,
        m.method,
        m.iterations,
        m.validate_runs,
        m.target,
        tuple(sorted(parameters.items())),
        text,
        source,
    )


def load_sweep_spec(path: Path) -> SweepSpec:
    """Read and validate ``path`` through the guarded YAML loader.

    Raises:
        ConfigError: a bad spec (file, field, reason); RecordingError: an unreadable file.
    """
    from omnical.userfiles import parse_yaml, read_text_file

    text = read_text_file(path, "sweep spec")
    return parse_sweep_spec(parse_yaml(text, str(path), "sweep spec"), str(path), text)


@dataclass(frozen=True)
class SweepJob:
    """Run ``index`` of a sweep seeded with ``seed`` (its parameters are drawn in the worker)."""

    index: int
    seed: int
    spec: SweepSpec


def sample_run(spec: SweepSpec, seed: int, index: int) -> tuple[dict[str, float], int]:
    """Run ``index``'s parameters and campaign seed: ``SeedSequence(seed).spawn(N)[index]``
    (the same whatever N and wherever it is drawn), spawned once more into the draws' and
    the campaign's streams."""
    child = np.random.SeedSequence(seed, spawn_key=(index,))
    draws, campaign = child.spawn(2)
    rng = np.random.default_rng(draws)
    values = {}
    for name, dist in spec.parameters:
        value = dist.draw(rng) if isinstance(dist, _Distribution) else float(dist)
        values[name] = float(round(value)) if name in _INTEGER else value
    return values, int(campaign.generate_state(1, np.uint64)[0] >> np.uint64(1))


def _merged(base: Mapping[str, Any], path: Sequence[str], value: float) -> dict[str, Any]:
    out = dict(base)
    if len(path) == 1:
        out[path[0]] = value
        return out
    inner = out.get(path[0])
    out[path[0]] = _merged(inner if isinstance(inner, Mapping) else {}, path[1:], value)
    return out


def _twin_and_beacons(
    spec: SweepSpec, values: Mapping[str, float], robot: RobotDescription
) -> tuple[TwinParams, BeaconMap | None]:
    """The twin of one run (spec's twin with the drawn values, validated as a twin file) and
    its beacon map (seed 000's scaled by ``room_scale``, None when the room is not varied)."""
    from dataclasses import replace

    from omnical.ips.beacons import BeaconMap, default_beacon_map
    from omnical.twin.params import parse_twin

    data: dict[str, Any] = dict(spec.twin)
    for name, value in values.items():
        if name.startswith("true_factors.scale."):
            data = _merged(data, ("true_factors", "scale", name.rsplit(".", 1)[1]), value)
        elif name.startswith("true_factors.crosstalk."):
            key = name.rsplit(".", 1)[1]
            data = _merged(data, ("true_factors", "crosstalk_rad_per_m", key), value)
        elif name.startswith("ips."):
            data = _merged(data, ("ips", name.split(".", 1)[1]), value)
        elif name == "slip_sigma":
            data = _merged(data, ("slip_sigma",), value)
    twin = parse_twin(data, robot, f"{spec.source}: twin")
    scale = values.get("room_scale")
    if scale is None:
        return twin, None
    if not (math.isfinite(scale) and 0.1 <= scale <= 20.0):
        raise ConfigError(f"room_scale {scale:g}: outside 0.1 to 20")
    seed000 = default_beacon_map()
    positions = seed000.positions_m.copy()
    positions[:, :2] *= scale
    beacons = BeaconMap(seed000.addresses, positions, seed000.hedge_addresses, seed000.hedge_z_m)
    x, y, yaw = twin.start_pose_map
    return replace(twin, start_pose_map=(x * scale, y * scale, yaw)), beacons


def _factor_fields() -> tuple[str, ...]:
    from omnical.kinematics.factors import FACTORS

    return tuple(f.field for f in FACTORS)


def sweep_header(spec: SweepSpec) -> list[str]:
    """The columns of ``DIR/sweep.csv``: index, campaign seed, status, reason, the parameters,
    the campaign's outcome, then per factor the truth, the estimate, its error and its 1σ."""
    per_factor = [c for f in _factor_fields() for c in (f"{f}_true", f, f"{f}_error", f"{f}_sigma")]
    return [
        INDEX,
        "seed",
        STATUS,
        REASON,
        *(name for name, _ in spec.parameters),
        "iterations_run",
        "converged",
        "robot_time_s",
        "max_scale_error",
        "max_crosstalk_error_rad_per_m",
        *per_factor,
    ]


def run_sweep_job(job: SweepJob) -> dict[str, str]:
    """One campaign on the twin (an error is the row's reason)."""
    import warnings

    from omnical.robot.loader import load_robot
    from omnical.twin.bench import run_twin_campaign

    values, seed = sample_run(job.spec, job.seed, job.index)
    row = {
        INDEX: str(job.index),
        "seed": str(seed),
        **{name: repr(value) for name, value in values.items()},
    }
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            robot = load_robot(job.spec.robot)
            twin, beacons = _twin_and_beacons(job.spec, values, robot)
            iterations = int(values.get("iterations", job.spec.iterations))
            if iterations < 1:
                raise ConfigError(f"iterations {iterations}: at least 1")
            procedures: dict[str, dict[str, Any]] = {}
            for name, value in values.items():
                if name.startswith("procedure."):
                    _, kind, option = name.split(".")
                    procedures.setdefault(kind, {})[option] = (
                        int(value) if name in _INTEGER else value
                    )
            result = run_twin_campaign(
                robot,
                twin,
                seed=seed,
                max_iterations=iterations,
                method=job.spec.method,  # type: ignore[arg-type]
                beacons=beacons,
                validate=job.spec.validate,
                measure=False,
                procedures=procedures,
            )
    except Exception as err:  # an error is a row, never an abort
        return {**row, STATUS: "error", REASON: failure(err)}
    from omnical.kinematics.factors import FACTORS

    row.update(
        {
            STATUS: "ok",
            REASON: "",
            "iterations_run": str(len(result.iterations)),
            "converged": str(result.converged).lower(),
            "robot_time_s": repr(float(result.robot_time_s)),
        }
    )
    scale_errors: list[float] = []
    crosstalk_errors: list[float] = []
    for f in FACTORS:
        truth = float(getattr(twin.true_factors, f.field))
        value = float(getattr(result.factors, f.field))
        error = value / truth - 1.0 if f.is_scale else value - truth
        (scale_errors if f.is_scale else crosstalk_errors).append(abs(error))
        row[f"{f.field}_true"] = repr(truth)
        row[f.field] = repr(value)
        row[f"{f.field}_error"] = repr(error)
        row[f"{f.field}_sigma"] = repr(float(result.sigma[f.field]))
    row["max_scale_error"] = repr(max(scale_errors))
    row["max_crosstalk_error_rad_per_m"] = repr(max(crosstalk_errors))
    return row


run_sweep_chunk = partial(run_chunk, run_sweep_job)
"""The rows of a chunk of runs (:func:`~omnical.fleet.runner.run_chunk`)."""


def _failed(job: SweepJob, reason: str) -> dict[str, str]:
    return {INDEX: str(job.index), "seed": "", STATUS: "error", REASON: reason}


@dataclass(frozen=True)
class SweepRun:
    """What a sweep left: the table, the report, the rows and those a resume found done."""

    table: Path
    report: Path
    rows: tuple[dict[str, str], ...]
    done_before: int


def run_sweep(
    spec: SweepSpec,
    runs: int,
    seed: int,
    executor: ExecutorSpec,
    out: Path,
    *,
    chunk: int = 0,
    resume: bool = False,
    overwrite: bool = False,
    on_start: Callable[[int, int], None] | None = None,
    on_rows: Callable[[int], None] | None = None,
    on_stop: Callable[[Path, int, str], None] | None = None,
    notify: Callable[[str], None] | None = None,
) -> SweepRun:
    """``runs`` campaigns of ``spec`` seeded from ``seed`` on ``executor``; ``DIR/sweep.csv``
    and ``DIR/report.md``. ``on_start``, ``on_rows``, ``on_stop``, ``notify``: as
    :func:`~omnical.fleet.recordings.run_fleet`'s (an earlier output replaced only once the
    run is complete).

    Raises:
        ConfigError: the robot of the spec, or its twin, is bad (checked before any run).
        OutputError: ``out`` cannot take the run.
    """
    from omnical.reports.fleet import write_sweep_report
    from omnical.robot.loader import load_robot

    if runs < 1:
        raise ConfigError(f"--runs {runs}: at least 1")
    from omnical.twin.params import check_nlos_beacons, parse_twin

    try:
        robot = load_robot(spec.robot)
    except OmnicalError as err:  # one line naming the spec: "SPEC.yaml: robot: ..."
        raise ConfigError(f"{spec.source}: robot: {err}") from None
    twin = parse_twin(dict(spec.twin), robot, f"{spec.source}: twin")  # a bad twin: one error
    check_nlos_beacons(twin, None, f"{spec.source}: twin")  # the runs' maps: seed 000's
    out = shared_path(out)
    settings = {
        "spec": spec.text,
        "runs": runs,
        "seed": seed,
    }
    claim = claim_out_dir(
        out, settings, SWEEP_TABLE, resume=resume, overwrite=overwrite, notify=notify
    )  # refused before an executor starts
    jobs = [SweepJob(i, seed, spec) for i in range(runs)]

    def report(place: Path, rows: list[dict[str, str]]) -> Path:
        return write_sweep_report(
            place,
            rows,
            spec.varied,
            error="max_scale_error",
            error_label="largest relative scale error",
            target=spec.target,
            spec_text=spec.text,
        )

    rows, done_before, written = run_into_table(
        executor, run_sweep_chunk, lambda _: jobs, sweep_header(spec), claim=claim, chunk=chunk,
        failed=_failed, report=report, on_start=on_start, on_rows=on_rows, on_stop=on_stop,
    )  # fmt: skip
    return SweepRun(out / SWEEP_TABLE, out / written.name, tuple(rows), done_before)
