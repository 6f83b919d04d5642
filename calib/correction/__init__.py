"""A guarded residual correction, the loop's last stage after geometry and physical effects:
kernel ridge regression (a Gaussian process's mean) of what they leave over the poses'
features, cross-validated, applied only inside the calibrated region."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "correction": (
            "CorrectionFileError",
            "ResidualCorrection",
            "feature_names",
            "pose_features",
        ),
        "held": (
            "correction_in",
            "correction_in_file",
            "corrected_targets",
            "held_dataset",
        ),
        "offer": ("Offer", "fit_and_judge", "stats"),
        "stages": ("save_stages_png", "stage_table", "table_lines"),
    },
)
