"""Calibration: geometric fits, segmentation, the procedures of seed 000 §3.2 and their analyses."""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
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
    from omnical.calibration.joint.estimate import (
        Alignment,
        JointEstimate,
        JointWarning,
        ObservabilityWarning,
        estimate_joint,
    )
    from omnical.calibration.procedures.analysis import (
        ProcedureEstimate,
        analyse_procedures,
    )
    from omnical.calibration.procedures.geometry import (
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
    from omnical.calibration.procedures.rotation import (
        RotationResult,
        analyse_rotation,
    )
    from omnical.calibration.procedures.scripts import (
        hull_margin_m,
        lateral_procedure,
        longitudinal_procedure,
        nominal_path,
        rotation_procedure,
    )
    from omnical.calibration.procedures.segments import (
        Segment,
        SegmentKind,
        segment_commands,
        segment_mask,
        settled,
    )
    from omnical.calibration.procedures.tracks import (
        Estimate,
        SlipPrior,
    )
    from omnical.calibration.procedures.translation import (
        TranslationResult,
        analyse_translation,
    )

_EXPORTS: dict[str, str] = {
    "Alignment": "omnical.calibration.joint.estimate",
    "ArcThroughPoints": "omnical.calibration.procedures.geometry",
    "CampaignResult": "omnical.calibration.campaign",
    "CircleFit": "omnical.calibration.procedures.geometry",
    "Estimate": "omnical.calibration.procedures.tracks",
    "FactorsFile": "omnical.calibration.factors_io",
    "JointEstimate": "omnical.calibration.joint.estimate",
    "JointWarning": "omnical.calibration.joint.estimate",
    "Loss": "omnical.calibration.procedures.geometry",
    "MeanPosition": "omnical.calibration.procedures.geometry",
    "ObservabilityWarning": "omnical.calibration.joint.estimate",
    "ProcedureEstimate": "omnical.calibration.procedures.analysis",
    "RotationResult": "omnical.calibration.procedures.rotation",
    "Segment": "omnical.calibration.procedures.segments",
    "SegmentKind": "omnical.calibration.procedures.segments",
    "SlipPrior": "omnical.calibration.procedures.tracks",
    "TranslationResult": "omnical.calibration.procedures.translation",
    "analyse_procedures": "omnical.calibration.procedures.analysis",
    "analyse_rotation": "omnical.calibration.procedures.rotation",
    "analyse_translation": "omnical.calibration.procedures.translation",
    "arc_length": "omnical.calibration.procedures.geometry",
    "c_header_text": "omnical.calibration.export",
    "circle_through_three_points": "omnical.calibration.procedures.geometry",
    "estimate_factors": "omnical.calibration.campaign",
    "estimate_joint": "omnical.calibration.joint.estimate",
    "factors_file_text": "omnical.calibration.factors_io",
    "fit_circle": "omnical.calibration.procedures.geometry",
    "heading_from_positions": "omnical.calibration.procedures.geometry",
    "hull_margin_m": "omnical.calibration.procedures.scripts",
    "lateral_procedure": "omnical.calibration.procedures.scripts",
    "longitudinal_procedure": "omnical.calibration.procedures.scripts",
    "mean_position": "omnical.calibration.procedures.geometry",
    "nominal_path": "omnical.calibration.procedures.scripts",
    "parse_factors": "omnical.calibration.factors_io",
    "read_factors": "omnical.calibration.factors_io",
    "rotation_procedure": "omnical.calibration.procedures.scripts",
    "run_campaign": "omnical.calibration.campaign",
    "segment_commands": "omnical.calibration.procedures.segments",
    "segment_mask": "omnical.calibration.procedures.segments",
    "settled": "omnical.calibration.procedures.segments",
    "three_point_arc": "omnical.calibration.procedures.geometry",
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
