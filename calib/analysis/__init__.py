"""What a pose set can tell: identifiability, observability, the first paper's
reconstructions and screw model, orientation reach, pose selection, rank structure, scoring,
ISO 9283 pose accuracy and repeatability."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "identifiability": (
            "IdentifiabilityReport",
            "RANK_RTOL",
            "analyse",
            "scaled_jacobian",
            "zero_columns",
        ),
        "iso9283": (
            "ORIENTATION_KEYS",
            "POSITION_KEYS",
            "STANDARD",
            "IsoSide",
            "characteristics",
            "group_commands",
            "iso_side",
        ),
        "observability_indices": ("observability",),
        "orientation": ("orientation_reach",),
        "pose_selection": (
            "exchange",
            "paper_selection",
            "stopping_count",
        ),
        "rank_structure": (
            "describe",
            "pose_probes",
            "rank_correlations",
        ),
        "reconstruction": (
            "correlation_reconstruction",
            "spectral_reconstruction",
        ),
        "scoring": (
            "PoseErrors",
            "error_stats",
            "max_mean_stats",
            "pose_errors",
            "pose_errors_between",
        ),
        "screw_polisher": ("PolisherScrewModel",),
    },
)
