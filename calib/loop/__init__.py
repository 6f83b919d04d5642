"""Closing the loop: a diagnosed effect as parameters of the error model (effect kinds),
refit with the geometry, and compensation through the corrected model."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "compensation": ("loop_commands",),
        "effect": (
            "ActuatorCorrection",
            "diagnosed_correction",
        ),
        "effect_kinds": (
            "parameter_entry",
            "EffectFileError",
            "effect_content",
            "effect_block",
            "extended_model",
            "load_effect",
            "model_for_result",
        ),
        "refit": ("fit_with_diagnosis", "with_result_content"),
        "fit": (
            "LoopFit",
            "fit_with_effect",
            "residual_rms_3d",
        ),
    },
)
