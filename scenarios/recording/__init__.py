"""Rerun recordings of a scenario: the Recorder (session, machine views, charts; pure pieces in
parts and targets), the layout built from what was logged (blueprints), and the loop-closing
views (loop)."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "recorder": ("Recorder",),
    },
)
