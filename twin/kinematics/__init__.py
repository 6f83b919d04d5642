"""Kinematics of any MJCF machine. One engine per job: forward_batch (many poses) runs the compiled
kernels (numba) where they cover the machine, else the numpy path (tree, reduced, adjoint); the
single-pose Newton (single_pose: forward, inverse) is the reference the tests hold both to, and
pinocchio_model an independent cross-check; sensitivity* give the identification Jacobian."""

from common.face import face

__all__, __getattr__, __dir__ = face(
    __name__,
    {
        "batch": ("forward_batch",),
        "closure": (
            "closure_jacobian",
            "update_kinematics",
        ),
        "inverse_batch": (
            "actuator_joint_parameters",
            "actuator_twist_jacobians",
            "commands_near",
            "inverse_near",
        ),
        "sensitivity": ("target_jacobian",),
        "sensitivity_batch": (
            "JacobianPlan",
            "target_jacobian_batch",
            "tool_twist_jacobian_batch",
        ),
        "single_pose": (
            "check_commands",
            "forward",
            "inverse",
            "pose_to_frame",
        ),
        "structure": (
            "on_one_blas_thread",
            "one_blas_thread",
        ),
    },
)
