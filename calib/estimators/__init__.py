"""Linear estimators of the fine step (OLS, Liu and its variants, ridge, PCR) by name
(registry), and the Levenberg-Marquardt solver of every nonlinear fit."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "levenberg_marquardt": (
            "JacobianFn",
            "LMOptions",
            "ResidualFn",
            "ReweightedResult",
            "reweighted_levenberg_marquardt",
        ),
        "linear": (
            "DrawEstimator",
            "LinearEstimate",
            "draws",
        ),
        "liu": ("Liu",),
        "liu_paper_units": ("LiuPaperUnits",),
        "ols": ("OLS",),
        "registry": (
            "ESTIMATORS",
            "make_estimator",
        ),
    },
)
