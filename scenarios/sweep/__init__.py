"""Sweeps (python -m scenarios sweep): a study once per seed and per swept setting as Ray
tasks (engine), each one run (one_run), their distributions (aggregate) and report."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "draws": ("map_draws",),
        "engine": (
            "ENV_ENGINE",
            "EngineError",
            "engine_env",
        ),
        "runner": (
            "ProgressBar",
            "sweep",
        ),
    },
)
