"""Planning a measurement before measuring: candidate poses, their feasibility (limits,
collisions, the tracker's line of sight), the selection by observability, the program's
order, and the twin's prediction of the accuracy it will give."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "candidates": ("Candidates", "file_candidates", "workspace_candidates"),
        "feasibility": ("Feasibility", "Rules", "check_poses"),
        "figure": ("save_curve_png",),
        "planner": ("CALIBRATION", "TEST", "Plan", "accuracy_curve", "make_plan"),
        "prediction": ("Prediction", "draw_truth", "predict"),
        "program_file": ("file_units", "program_text"),
    },
)
