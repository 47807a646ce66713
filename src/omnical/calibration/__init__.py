"""Calibration: geometric fits, segmentation, the procedures of seed 000 §3.2 and their analyses."""

from omnical.calibration.analysis import ProcedureEstimate, analyse_procedures
from omnical.calibration.analysis_rotation import RotationResult, analyse_rotation
from omnical.calibration.analysis_tracks import Estimate, SlipPrior
from omnical.calibration.analysis_translation import TranslationResult, analyse_translation
from omnical.calibration.campaign import CampaignResult, estimate_factors, run_campaign
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
