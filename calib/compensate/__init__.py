"""The identified machine put to use: commands that reach desired poses (compensation)
and the calibrated model as files for a controller or simulator (export)."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "before": ("nominal_commands_error",),
        "compensation": (
            "TwistCompensation",
            "reachable_compensated_commands",
        ),
        "identified_machine": (
            "IdentifiedMachine",
            "load_identified_machine",
        ),
        "model_export": (
            "FK_TOLERANCE_M",
            "export_model",
            "gains_text",
            "kinematics_difference",
        ),
        "sidecar": (
            "missing_line",
            "sidecar_path",
        ),
        "poses": (
            "Compensation",
            "compensate",
            "shown_residual",
            "solve_each",
        ),
        "residual": ("with_residual_correction",),
        "program_state": (
            "RunStateError",
            "run_state",
        ),
        "program": (
            "NominalTargets",
            "compensate_program",
            "nearest_targets",
            "nominal_targets",
        ),
    },
)
