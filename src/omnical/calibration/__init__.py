"""Calibration: geometric fits, segmentation, the procedures of seed 000 §3.2 and their analyses."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.calibration.analysis import (
        ProcedureEstimate,
        analyse_procedures,
    )
    from omnical.calibration.analysis_rotation import (
        RotationResult,
        analyse_rotation,
    )
    from omnical.calibration.analysis_tracks import (
        Estimate,
        SlipPrior,
    )
    from omnical.calibration.analysis_translation import (
        TranslationResult,
        analyse_translation,
    )
    from omnical.calibration.campaign import (
        CampaignResult,
        estimate_factors,
        run_campaign,
    )
    from omnical.calibration.export import (
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
    )
    from omnical.calibration.geometry import (
        ArcThroughPoints,
        CircleFit,
        Loss,
        MeanPosition,
        arc_length,
        circle_through_three_points,
        fit_circle,
        heading_from_positions,
        mean_position,
        three_point_arc,
    )
    from omnical.calibration.joint import (
        Alignment,
        JointEstimate,
        JointWarning,
        ObservabilityWarning,
        estimate_joint,
    )
    from omnical.calibration.procedures import (
        hull_margin_m,
        lateral_procedure,
        longitudinal_procedure,
        nominal_path,
        rotation_procedure,
    )
    from omnical.calibration.segments import (
        Segment,
        SegmentKind,
        segment_commands,
        segment_mask,
        settled,
    )

_EXPORTS: dict[str, str] = {
    "Alignment": "omnical.calibration.joint",
    "ArcThroughPoints": "omnical.calibration.geometry",
    "CampaignResult": "omnical.calibration.campaign",
    "CircleFit": "omnical.calibration.geometry",
    "Estimate": "omnical.calibration.analysis_tracks",
    "FactorsFile": "omnical.calibration.factors_io",
    "JointEstimate": "omnical.calibration.joint",
    "JointWarning": "omnical.calibration.joint",
    "Loss": "omnical.calibration.geometry",
    "MeanPosition": "omnical.calibration.geometry",
    "ObservabilityWarning": "omnical.calibration.joint",
    "ProcedureEstimate": "omnical.calibration.analysis",
    "RotationResult": "omnical.calibration.analysis_rotation",
    "Segment": "omnical.calibration.segments",
    "SegmentKind": "omnical.calibration.segments",
    "SlipPrior": "omnical.calibration.analysis_tracks",
    "TranslationResult": "omnical.calibration.analysis_translation",
    "analyse_procedures": "omnical.calibration.analysis",
    "analyse_rotation": "omnical.calibration.analysis_rotation",
    "analyse_translation": "omnical.calibration.analysis_translation",
    "arc_length": "omnical.calibration.geometry",
    "c_header_text": "omnical.calibration.export",
    "circle_through_three_points": "omnical.calibration.geometry",
    "estimate_factors": "omnical.calibration.campaign",
    "estimate_joint": "omnical.calibration.joint",
    "factors_file_text": "omnical.calibration.factors_io",
    "fit_circle": "omnical.calibration.geometry",
    "heading_from_positions": "omnical.calibration.geometry",
    "hull_margin_m": "omnical.calibration.procedures",
    "lateral_procedure": "omnical.calibration.procedures",
    "longitudinal_procedure": "omnical.calibration.procedures",
    "mean_position": "omnical.calibration.geometry",
    "nominal_path": "omnical.calibration.procedures",
    "parse_factors": "omnical.calibration.factors_io",
    "read_factors": "omnical.calibration.factors_io",
    "rotation_procedure": "omnical.calibration.procedures",
    "run_campaign": "omnical.calibration.campaign",
    "segment_commands": "omnical.calibration.segments",
    "segment_mask": "omnical.calibration.segments",
    "settled": "omnical.calibration.segments",
    "three_point_arc": "omnical.calibration.geometry",
    "wheeltec_params_text": "omnical.calibration.export",
    "wheeltec_scales": "omnical.calibration.export",
    "write_c_header": "omnical.calibration.export",
    "write_factors": "omnical.calibration.factors_io",
    "write_wheeltec_params": "omnical.calibration.export",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "Alignment",
    "ArcThroughPoints",
    "CampaignResult",
    "CircleFit",
    "Estimate",
    "FactorsFile",
    "JointEstimate",
    "JointWarning",
    "Loss",
    "MeanPosition",
    "ObservabilityWarning",
    "ProcedureEstimate",
    "RotationResult",
    "Segment",
    "SegmentKind",
    "SlipPrior",
    "TranslationResult",
    "analyse_procedures",
    "analyse_rotation",
    "analyse_translation",
    "arc_length",
    "c_header_text",
    "circle_through_three_points",
    "estimate_factors",
    "estimate_joint",
    "factors_file_text",
    "fit_circle",
    "heading_from_positions",
    "hull_margin_m",
    "lateral_procedure",
    "longitudinal_procedure",
    "mean_position",
    "nominal_path",
    "parse_factors",
    "read_factors",
    "rotation_procedure",
    "run_campaign",
    "segment_commands",
    "segment_mask",
    "settled",
    "three_point_arc",
    "wheeltec_params_text",
    "wheeltec_scales",
    "write_c_header",
    "write_factors",
    "write_wheeltec_params",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
