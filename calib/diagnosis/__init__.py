"""Residual diagnosis after the geometric fit: more than noise? which physical candidate
explains it, judged on held-out poses only (diagnose), and its figure."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "context": (
            "actuator_offsets",
            "extra_parameters",
        ),
        "core": (
            "Diagnosis",
            "TestSet",
            "default_candidates",
            "diagnose",
            "effect_offsets",
            "effect_target_shifts",
        ),
        "figure": ("save_diagnosis_png",),
    },
)
