"""factors.yaml reading/writing and the exports (C header, Wheeltec ROS parameters)."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from omnical.calibration.export import (
    HEADER_MACROS,
    c_header_text,
    wheeltec_params_text,
    wheeltec_scales,
    write_c_header,
    write_wheeltec_params,
)
from omnical.calibration.factors_io import (
    FactorsFile,
    factors_file_text,
    parse_factors,
    read_factors,
    write_factors,
    yaml_number,
)
from omnical.errors import ConfigError
from omnical.kinematics.correction import CorrectionFactors

TRUTH = CorrectionFactors(1.02, 1.13, 1.0236, 0.0072, -0.00009, 0.0389, -0.0277)
SIGMA = CorrectionFactors(0.0004, 0.0006, 0.0012, 0.0005, float("nan"), 0.00061, 0.000613)

EXAMPLE = """\
scale: {longitudinal: 1.02, lateral: 1.13, rotational: 1.0236}
crosstalk_rad_per_m: {forward: 0.0072, reverse: 0.00009, left: 0.0389, right: 0.0277}
uncertainty:
  scale: {longitudinal: 0.001, lateral: 0.002, rotational: 0.003}
  crosstalk_rad_per_m: {forward: 0.0004, reverse: 0.0005, left: 0.0006, right: 0.0007}
"""


def test_reads_the_documented_example(tmp_path: Path) -> None:
    path = tmp_path / "factors.yaml"
    path.write_text(EXAMPLE, encoding="utf-8")
    f = read_factors(path)
    assert f.factors == CorrectionFactors.seed000_table2()
    assert f.uncertainty == CorrectionFactors(0.001, 0.002, 0.003, 0.0004, 0.0005, 0.0006, 0.0007)


def test_write_read_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        factors = CorrectionFactors(
            *rng.uniform(0.8, 1.2, 3), *(rng.normal(0, 0.02, 4) * 10.0 ** rng.integers(-4, 0, 4))
        )
        path = write_factors(tmp_path / "sub" / "factors.yaml", factors, SIGMA)
        back = read_factors(path)
        assert back.factors == factors
        assert back.uncertainty is not None
        u = back.uncertainty.as_vector()
        np.testing.assert_array_equal(np.isnan(u), np.isnan(SIGMA.as_vector()))
        np.testing.assert_array_equal(u[~np.isnan(u)], SIGMA.as_vector()[~np.isnan(u)])
    assert read_factors(write_factors(tmp_path / "plain.yaml", TRUTH)) == FactorsFile(TRUTH, None)


def test_file_layout_is_the_documented_one() -> None:
    text = factors_file_text(TRUTH, SIGMA, comment="run 3\nseed 000")
    lines = text.splitlines()
    assert lines[:2] == ["# run 3", "# seed 000"]
    assert lines[2] == "scale: {longitudinal: 1.02, lateral: 1.13, rotational: 1.0236}"
    assert lines[3] == (
        "crosstalk_rad_per_m: {forward: 0.0072, reverse: -0.00009, left: 0.0389, right: -0.0277}"
    )
    assert lines[4] == "uncertainty:"
    assert lines[5] == "  scale: {longitudinal: 0.0004, lateral: 0.0006, rotational: 0.0012}"
    assert lines[6].startswith("  crosstalk_rad_per_m: {forward: 0.0005, reverse: .nan,")
    assert "e-" not in text
    assert yaml_number(1.0) == "1.0"
    assert yaml_number(9e-05) == "0.00009"
    assert yaml_number(float("inf")) == ".inf"


@pytest.mark.parametrize(
    ("text", "field", "reason"),
    [
        ("[1, 2]", None, "must be a mapping"),
        (EXAMPLE.replace("lateral: 1.13, ", ""), "scale.lateral", "missing"),
        (
            EXAMPLE.replace("forward: 0.0072", "fwd: 0.0072"),
            "crosstalk_rad_per_m.fwd",
            "unknown key",
        ),
        (EXAMPLE.replace("1.0236", "fast"), "scale.rotational", "expected a number"),
        (EXAMPLE.replace("1.0236", "true"), "scale.rotational", "expected a number"),
        (EXAMPLE.replace("1.13", "3.0"), "scale.lateral", "not a plausible scaling"),
        (EXAMPLE.replace("1.13", ".nan"), "scale.lateral", "not a plausible scaling"),
        (
            EXAMPLE.replace("0.0389", "1.5"),
            "crosstalk_rad_per_m.left",
            "not a plausible cross-talk",
        ),
        (EXAMPLE.replace("lateral: 0.002", "lateral: -0.002"), "uncertainty.scale.lateral", ">= 0"),
        (
            EXAMPLE.replace("right: 0.0007", "right: .inf"),
            "uncertainty.crosstalk_rad_per_m.right",
            ">= 0",
        ),
        (
            EXAMPLE.replace(
                "  scale: {longitudinal: 0.001, lateral: 0.002, rotational: 0.003}\n", ""
            ),
            "uncertainty.scale",
            "missing",
        ),
        ("scale: {longitudinal: 1, lateral: 1, rotational: 1}\n", "crosstalk_rad_per_m", "missing"),
        (EXAMPLE + "extra: 1\n", "extra", "unknown key"),
        (
            EXAMPLE.replace("scale: {", "scale: [", 1).replace("1.0236}", "1.0236]", 1),
            "scale",
            "expected a mapping",
        ),
        ("scale: {longitudinal: 1.0\n", None, "invalid YAML at line"),
    ],
)
def test_invalid_files_give_one_line_errors_naming_file_and_field(
    tmp_path: Path, text: str, field: str | None, reason: str
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        read_factors(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    assert reason in message
    if field is not None:
        assert f"field '{field}'" in message


def test_missing_file_and_unwritable_path(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        read_factors(tmp_path / "absent.yaml")
    blocker = tmp_path / "file"
    blocker.write_text("x", encoding="utf-8")
    with pytest.raises(ConfigError, match="cannot write"):
        write_factors(blocker / "factors.yaml", TRUTH)


def test_parse_accepts_integers_and_numeric_strings() -> None:
    data = yaml.safe_load(
        EXAMPLE.replace("longitudinal: 1.02,", "longitudinal: 1,").replace("0.00009", "9e-05")
    )
    f = parse_factors(data, "inline")
    assert f.factors.scale_longitudinal == 1.0
    assert f.factors.crosstalk_reverse_rad_per_m == 9e-05


# --------------------------------------------------------------------------- exports


def _defines(text: str) -> dict[str, float]:
    found = re.findall(r"#define (OMNICAL_\w+) \(?(-?[0-9.]+)f\)?", text)
    return {name: float(value) for name, value in found}


def test_c_header_has_the_seven_constants_and_the_conventions(tmp_path: Path) -> None:
    path = write_c_header(tmp_path / "omnical_factors.h", TRUTH, SIGMA)
    text = path.read_text(encoding="utf-8")
    assert "#ifndef OMNICAL_FACTORS_H\n#define OMNICAL_FACTORS_H" in text
    assert text.rstrip().endswith("#endif /* OMNICAL_FACTORS_H */")
    assert "#define OMNICAL_SCALE_LONGITUDINAL 1.020000f" in text
    assert "#define OMNICAL_CROSSTALK_RIGHT_RAD_PER_M (-0.027700f)" in text
    values = _defines(text)
    assert list(values) == list(HEADER_MACROS)
    np.testing.assert_allclose(list(values.values()), TRUTH.as_vector(), atol=5e-7)
    assert "counter-clockwise positive" in text
    assert "first inject the cross-talk, then scale" in text
    assert "not estimated" in text  # the NaN uncertainty of the reverse cross-talk


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_c_header_compiles(tmp_path: Path) -> None:
    write_c_header(tmp_path / "omnical_factors.h", TRUTH, SIGMA)
    source = tmp_path / "use.c"
    source.write_text(
        '#include "omnical_factors.h"\n#include "omnical_factors.h"\n'
        "float compensate_wz(float vx, float vy, float wz) {\n"
        "  wz -= OMNICAL_CROSSTALK_FORWARD_RAD_PER_M * (vx > 0 ? vx : 0)\n"
        "      + OMNICAL_CROSSTALK_REVERSE_RAD_PER_M * (vx < 0 ? -vx : 0)\n"
        "      + OMNICAL_CROSSTALK_LEFT_RAD_PER_M * (vy > 0 ? vy : 0)\n"
        "      + OMNICAL_CROSSTALK_RIGHT_RAD_PER_M * (vy < 0 ? -vy : 0);\n"
        "  return wz * OMNICAL_SCALE_ROTATIONAL * OMNICAL_SCALE_LONGITUDINAL\n"
        "      / OMNICAL_SCALE_LATERAL -OMNICAL_CROSSTALK_RIGHT_RAD_PER_M;\n"
        "}\n",
        encoding="utf-8",
    )
    result = subprocess.run(
        [
            "cc",
            "-fsyntax-only",
            "-std=c99",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            str(source),
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr


def test_c_header_refuses_unusable_factors() -> None:
    with pytest.raises(ConfigError, match="scale_lateral"):
        c_header_text(TRUTH.with_values(scale_lateral=float("nan")))
    with pytest.raises(ConfigError, match="positive"):
        c_header_text(TRUTH.with_values(scale_rotational=0.0))


def test_wheeltec_parameters_are_the_reciprocal_scales(tmp_path: Path) -> None:
    path = write_wheeltec_params(tmp_path / "wheeltec.yaml", TRUTH, SIGMA)
    text = path.read_text(encoding="utf-8")
    data = yaml.safe_load(text)
    params = data["wheeltec_robot"]["ros__parameters"]
    assert set(params) == {
        "odom_x_scale",
        "odom_y_scale",
        "odom_z_scale_positive",
        "odom_z_scale_negative",
    }
    assert params["odom_x_scale"] == pytest.approx(1 / 1.02, rel=1e-15)
    assert params["odom_y_scale"] == pytest.approx(1 / 1.13, rel=1e-15)
    assert params["odom_z_scale_positive"] == params["odom_z_scale_negative"]
    assert params["odom_z_scale_positive"] == pytest.approx(1 / 1.0236, rel=1e-15)
    assert all(isinstance(v, float) for v in params.values())
    assert wheeltec_scales(TRUTH) == params
    # a reported 1.02 m becomes the 1 m really travelled
    assert 1.02 * params["odom_x_scale"] == pytest.approx(1.0)
    ours = data["omnical"]["ros__parameters"]
    assert ours["scale"] == {"longitudinal": 1.02, "lateral": 1.13, "rotational": 1.0236}
    assert ours["crosstalk_rad_per_m"]["reverse"] == -0.00009
    assert ours["crosstalk_rad_per_m"]["right"] == -0.0277
    assert "reverse" not in ours["uncertainty"]["crosstalk_rad_per_m"]  # NaN: not estimated
    assert ours["uncertainty"]["scale"]["rotational"] == 0.0012
    comments = "\n".join(line for line in text.splitlines() if line.startswith("#"))
    assert "cannot hold" in comments
    assert "cross-talk" in comments
    assert "opposite signs" in comments
    assert not math.isnan(params["odom_x_scale"])


def test_wheeltec_parameters_without_uncertainty() -> None:
    data = yaml.safe_load(wheeltec_params_text(CorrectionFactors()))
    assert data["wheeltec_robot"]["ros__parameters"]["odom_x_scale"] == 1.0
    assert "uncertainty" not in data["omnical"]["ros__parameters"]


HELD = {
    "crosstalk_reverse_rad_per_m": 'not separable: "reverse" with forward, held at a guess */',
    "scale_rotational": "not observable: only 0° of rotation",
}


def test_held_factors_round_trip_and_are_marked_in_the_exports(tmp_path: Path) -> None:
    sigma = CorrectionFactors(0.0004, 0.0006, float("nan"), 0.0005, float("nan"), 0.0006, 0.0006)
    path = write_factors(tmp_path / "f.yaml", TRUTH, sigma, held=HELD)
    text = path.read_text(encoding="utf-8")
    assert "held:" in text
    back = read_factors(path)
    assert back.factors == TRUTH
    assert dict(back.held) == {  # field order
        "scale_rotational": HELD["scale_rotational"],
        "crosstalk_reverse_rad_per_m": HELD["crosstalk_reverse_rad_per_m"],
    }
    # without reasons the NaN uncertainties are the held factors
    plain = read_factors(write_factors(tmp_path / "g.yaml", TRUTH, sigma))
    assert dict(plain.held) == {
        "scale_rotational": "not estimated",
        "crosstalk_reverse_rad_per_m": "not estimated",
    }
    assert read_factors(write_factors(tmp_path / "h.yaml", TRUTH, SIGMA)).held == {
        "crosstalk_reverse_rad_per_m": "not estimated"
    }
    header = c_header_text(TRUTH, sigma, held=HELD)
    assert "HELD" in header
    assert re.search(r"#define OMNICAL_SCALE_ROTATIONAL .*HELD", header)
    assert re.search(r"OMNICAL_CROSSTALK_REVERSE_RAD_PER_M: not separable", header)
    body = header.split("*/", 2)  # the reason's "*/" cannot close the comment early
    assert "held at a guess * /" in header and len(body) == 3
    assert re.search(r"#define OMNICAL_SCALE_LONGITUDINAL .*1 sigma", header)
    params = wheeltec_params_text(TRUTH, sigma, held=HELD)
    assert "# HELD" in params
    data = yaml.safe_load(params)
    held = data["omnical"]["ros__parameters"]["held"]
    assert held["crosstalk_rad_per_m"]["reverse"] == HELD["crosstalk_reverse_rad_per_m"]
    assert held["scale"]["rotational"] == HELD["scale_rotational"]
    assert "HELD" not in c_header_text(TRUTH, None)


@pytest.mark.parametrize(
    ("section", "reason"),
    [
        ("held: [1]\n", "field 'held': expected a mapping"),
        ("held: {speed: {x: a}}\n", "field 'held.speed': unknown key"),
        ("held: {scale: {sideways: a}}\n", "field 'held.scale.sideways': unknown key"),
        ("held: {scale: {lateral: 3}}\n", "field 'held.scale.lateral': expected a reason"),
        ("held: {scale: [lateral]}\n", "field 'held.scale': expected a mapping"),
    ],
)
def test_bad_held_sections_are_one_line_errors(tmp_path: Path, section: str, reason: str) -> None:
    path = tmp_path / "f.yaml"
    path.write_text(EXAMPLE + section, encoding="utf-8")
    with pytest.raises(ConfigError, match=re.escape(reason)) as err:
        read_factors(path)
    assert "\n" not in str(err.value)
