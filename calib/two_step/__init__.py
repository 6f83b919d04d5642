"""The first paper's two-step procedure: coarse (encoder offsets by OLS) then fine
(the identifiable errors by a linear estimator of calib.estimators)."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "coarse": (
            "CoarseResult",
            "coarse_calibration",
        ),
        "fine": (
            "FineProblem",
            "estimate",
            "fine_problem",
        ),
        "nominal": ("nominal_targets",),
    },
)
