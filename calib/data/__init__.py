"""Data in and out of the calibration: the Dataset (a user's readings: CSV + sidecar) and its
I/O, set selection, hints at wrong units or columns, result files, desired poses, programs."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "dataset": (
            "Dataset",
            "DatasetError",
            "sidecar_path",
        ),
        "dataset_io": (
            "read_dataset",
            "require_model",
            "write_dataset",
        ),
        "desired_poses": (
            "DesiredPoses",
            "DesiredPosesError",
            "read_desired_poses",
        ),
        "hints": (
            "UNIT_SCALES",
            "likely_causes",
        ),
        "program": (
            "Program",
            "ProgramError",
            "parse_seed",
            "read_program",
        ),
        "result_file": (
            "CalibrationResult",
            "ResultFileError",
            "correlation_pairs",
            "load_result",
            "result_from_content",
            "result_text",
            "unusable_values",
        ),
        "select": (
            "CALIBRATION",
            "select_set",
            "subset",
        ),
    },
)
