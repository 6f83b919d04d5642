"""Identification and its judgement: the calibration model, identify (robust, with prior and
tracker registration), the verdict, verify, and the measured-data workflow that chains them."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "identification": (
            "IdentificationResult",
            "identify",
        ),
        "model": (
            "CalibrationModel",
            "ColumnJacobian",
            "Prediction",
        ),
        "observations": (
            "Observations",
            "bind_dataset",
            "model_from_files",
        ),
        "position_error": (
            "error_norms",
            "stats_mm",
        ),
        "prior": (
            "DETERMINED_Z",
            "PriorSpec",
            "correlation_matrix",
        ),
        "registration": (
            "Registration",
            "RegistrationError",
            "initial_registration",
            "rigid_motion_span",
        ),
        "verdict": (
            "ASSUMED_SIGMA_MM",
            "Accuracy",
            "DEFAULT_MAX_RATIO",
            "EXIT_BAD_INPUT",
            "EXIT_OK",
            "EXIT_POOR_FIT",
            "EXIT_UNREACHABLE",
            "EXIT_WORKER_LOST",
            "MAX_SIGMA_MM",
            "Verdict",
            "implausible_estimates",
            "noise_rule",
        ),
        "verify": (
            "Side",
            "Verification",
            "score_side",
        ),
        "verify_register": (
            "STATION_RATIO",
            "StationCheck",
            "station_check",
            "verify_registered",
        ),
        "workflow": (
            "CalibrationRun",
            "FitFailed",
            "calibrate",
            "nominal_registration",
            "verify_result",
        ),
        "run_content": (
            "probe_summary",
            "regularisation_text",
            "rejected_rows",
            "result_content",
        ),
    },
)
