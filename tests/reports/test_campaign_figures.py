"""The campaign's procedure figures show the factors the run measured (issue 29)."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.text import Text

from omnical.calibration.campaign import FactorEstimate, Iteration, Validation
from omnical.calibration.procedures.tracks import ProcedureTracks
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import FACTORS
from omnical.reports.campaign import procedure_measured
from omnical.reports.figures._common import save_figure
from omnical.reports.figures.calibration import plot_procedure

_SIGMA = {f.field: 1e-4 for f in FACTORS}


def _estimate(installed: CorrectionFactors, factors: CorrectionFactors) -> FactorEstimate:
    return FactorEstimate(factors, _SIGMA, installed, "procedures")


def _result() -> SimpleNamespace:
    start = CorrectionFactors()
    rot = start.with_values(scale_rotational=1.02382)
    total = rot.with_values(scale_lateral=1.12966, crosstalk_left_rad_per_m=0.03924)
    iteration = Iteration(
        index=1,
        installed=start,
        rotation=_estimate(start, rot),
        translation=FactorEstimate(
            total, _SIGMA, rot, "procedures", held={"crosstalk_right_rad_per_m": "not observable"}
        ),
        factors=total,
        sigma=_SIGMA,
        change={f.field: 0.0 for f in FACTORS},
        converged=False,
        recordings=("iter1-rotation", "iter1-longitudinal", "iter1-lateral"),
    )
    final = total.with_values(scale_rotational=1.02382 * 1.0005)
    validation = Validation(_estimate(total, final), ("validation-rotation",))
    return SimpleNamespace(iterations=(iteration,), validation=validation)


def test_each_procedure_says_the_factors_it_measured() -> None:
    result = _result()
    title, lines = procedure_measured(result, "iter1-rotation")  # type: ignore[arg-type]
    assert title == "measured: k rot 1.02382 ± 0.00010"
    assert any("installed 1.00000: +2.382 %" in line for line in lines)
    title, lines = procedure_measured(result, "iter1-lateral")  # type: ignore[arg-type]
    assert "k lat 1.12966 ± 0.00010" in title and "c left +39.24 ± 0.10 mrad/m" in title
    assert "c right not estimated" in title
    assert any("not observable" in line for line in lines)
    assert "k lon" not in title and "k rot" not in title
    title, lines = procedure_measured(result, "validation-rotation")  # type: ignore[arg-type]
    assert title.startswith("residual: k rot +0.050 ± 0.010 %")
    assert any("(+5.1 σ)" in line for line in lines)  # 0.05 % over 1e-4 / 1.02382
    assert procedure_measured(result, "iter7-rotation") == ("", ())  # type: ignore[arg-type]


def test_the_measured_factors_are_framed_above_the_legend(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    drawn: list[Figure] = []

    def keep(fig: Figure, path: Path, **kwargs: object) -> Path:
        drawn.append(fig)
        return save_figure(fig, path, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("omnical.reports.figures.calibration.save_figure", keep)
    t = np.linspace(0.0, 10.0, 50)
    tracks = ProcedureTracks(
        t0_ns=0,
        segments=(),
        stills={},
        fix_t_s=t,
        fix_xy_m=np.column_stack([1.0 + 0.2 * t, np.full_like(t, 2.0)]),
        odom_t_s=t,
        odom_pose=np.column_stack([0.2 * t, np.zeros_like(t), np.zeros_like(t)]),
        settle_s=1.0,
    )
    measured = ("measured (totals to install, ± 1σ):", "", "k rot   1.02382 ± 0.00010")
    plot_procedure(tracks, [], tmp_path / "p.png", measured=measured)
    side = drawn[0].axes[1]
    (box,) = [t for t in side.texts if isinstance(t, Text) and "k rot" in t.get_text()]
    legend = side.get_legend()
    assert isinstance(legend, Legend)
    renderer = FigureCanvasAgg(drawn[0]).get_renderer()  # type: ignore[no-untyped-call]
    patch = box.get_bbox_patch()
    assert patch is not None
    frame = patch.get_window_extent(renderer)
    assert frame.y0 > legend.get_window_extent(renderer).y1
    assert math.isclose(box.get_position()[1], 1.0)
