"""The first paper's screw-theory error model of the hybrid polisher (Eqs. 1-9, Appendix A).

Implemented on its own, as the paper derives it, to cross-check the twin's identification
Jacobian (implicit-function form over the closed chain). Only nominal frames come from the
MJCF (joint positions and axes at the measured configuration); the error propagation is the
paper's:

* every source error of joint frame {R_j,i} is a twist at the head point P,
  ``A_j,i dEta_j,i`` with A the adjoint of Eq. (A-1): (R dt + r x R dtheta; R dtheta),
  r = A_j,i - P (frames are those fixed to the preceding link, z along the joint axis);
* the platform twist solves Eq. (5): the three actuation wrenches of the UPS limbs (forces
  along w_3,i through A_6,i) and the three constraint wrenches of the UP limb (forces along
  w_2,4 and w_2,4 x w_3,4 through A_0, a couple along w_2,4 x w_1,4) applied to it give the
  encoder offsets and the projected structural-error twists (Eqs. 3-4);
* the wrist adds its joint twists (Eq. 6), and the target position errors follow Eq. (9):
  dp_j = dp_P + dtheta x (p_j - P).
Twists are (linear velocity of the point at P; angular velocity), world (= {R}) axes.
"""

from __future__ import annotations

import mujoco
import numpy as np

from twin.kinematics.closure import update_kinematics
from twin.mechanism import Mechanism
from twin.parameters import ParameterSet
from twin.rotations import matrix_from_quat

UPS_LIMBS = (1, 2, 3)
COMPONENT_AXIS = {"dx": 0, "dy": 1, "dz": 2, "dalpha": 0, "dbeta": 1, "dgamma": 2}


def _limb_of(body_name: str) -> tuple[int, int]:
    """(limb, joint index) from body names ``limb<i>_frame0`` / ``limb<i>_j<j>``."""
    limb_part, joint_part = body_name.split("_", 1)
    limb = int(limb_part.removeprefix("limb"))
    joint = 0 if joint_part == "frame0" else int(joint_part.removeprefix("j"))
    return limb, joint


def _reciprocal(wrench: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Reciprocal product of wrenches (force; moment about P) with twists (v_P; omega)."""
    return wrench[..., :3] @ twist[:3] + wrench[..., 3:] @ twist[3:]


class PolisherScrewModel:
    """Linear map B (Eq. 7) from source errors to the head's pose error twist, per pose."""

    def __init__(self, mech: Mechanism, params: ParameterSet) -> None:
        self.mech = mech
        self.params = params
        m = mech.model
        self.body_of_param = []
        for k, p in enumerate(params.parameters):
            if p.kind in ("body_pos", "body_rot"):
                b = int(params.element[k])
            elif p.kind == "joint_zero":
                b = int(m.jnt_bodyid[params.element[k]])
            else:
                raise ValueError(f"parameter '{p.name}': the screw model has no {p.kind} errors")
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
            self.body_of_param.append((b, *_limb_of(name)))

    def _frame(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """Pre-joint frame of a body (fixed to the preceding link): rotation and origin."""
        m, d = self.mech.model, self.mech.data
        par = m.body_parentid[body]
        r_par = d.xmat[par].reshape(3, 3)
        return r_par @ matrix_from_quat(m.body_quat[body]), d.xpos[par] + r_par @ m.body_pos[body]

    def _point(self, name: str) -> np.ndarray:
        return self.mech.data.site_xpos[self.mech.site_id(name)].copy()

    def _axis(self, joint: str) -> np.ndarray:
        j = mujoco.mj_name2id(self.mech.model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        return self.mech.data.xaxis[j].copy()

    def pose_error_matrix(self, qpos: np.ndarray) -> np.ndarray:
        """B (6, n): the head's pose error twist at P per unit source error (Eq. 7)."""
        update_kinematics(self.mech, qpos)
        d = self.mech.data
        p = self._point("tool")
        # actuation wrenches of the UPS limbs: unit force along the limb through A_6,i
        wa = []
        for i in UPS_LIMBS:
            w = self._axis(f"limb{i}_j3")
            a6 = self._point(f"platform_S{i}")
            wa.append(np.concatenate([w, np.cross(a6 - p, w)]))
        # constraint wrenches of the UP limb
        w1, w2, w3 = (self._axis(f"limb4_j{j}") for j in (1, 2, 3))
        a0 = d.xanchor[mujoco.mj_name2id(self.mech.model, mujoco.mjtObj.mjOBJ_JOINT, "limb4_j1")]
        n1 = np.cross(w2, w3)
        n3 = np.cross(w2, w1)
        wc = [
            np.concatenate([w2, np.cross(a0 - p, w2)]),
            np.concatenate([n1, np.cross(a0 - p, n1)]),
            np.concatenate([np.zeros(3), n3]),
        ]
        jp = np.array(wa + wc)  # (6, 6): J_P of Eq. (5), rows are wrenches
        n = len(self.params)
        rhs = np.zeros((6, n))  # right-hand side of Eq. (5) per parameter
        wrist = np.zeros((6, n))  # $_S,t of Eq. (6) per parameter
        for k, (b, limb, joint) in enumerate(self.body_of_param):
            kind = self.params.parameters[k].kind
            r_frame, origin = self._frame(b)
            component = self.params.names[k].rsplit(".", 1)[-1]
            # the error's own axis: x, y or z of the joint frame {R_j,i} (Appendix A)
            axis_world = (
                r_frame[:, COMPONENT_AXIS[component]] if component in COMPONENT_AXIS else None
            )
            if kind == "joint_zero":
                if limb in UPS_LIMBS:
                    rhs[limb - 1, k] = 1.0  # Delta q_i in Eq. (3)
                    continue
                w = d.xaxis[self.params.element[k]]
                twist = np.concatenate([np.cross(w, p - d.xanchor[self.params.element[k]]), w])
            elif kind == "body_pos":
                twist = np.concatenate([axis_world, np.zeros(3)])
            else:
                twist = np.concatenate([np.cross(axis_world, p - origin), axis_world])
            if limb in UPS_LIMBS:
                rhs[limb - 1, k] = _reciprocal(wa[limb - 1], twist)
            elif joint <= 3:
                rhs[3:, k] = _reciprocal(np.array(wc), twist)
            else:
                wrist[:, k] = twist
        platform = np.linalg.solve(jp, rhs)
        return platform + wrist

    def target_matrix(self, qpos: np.ndarray) -> np.ndarray:
        """H rows of one pose (T*3, n): Eq. (9) applied to Eq. (7)."""
        b = self.pose_error_matrix(qpos)
        p = self._point("tool")
        rows = []
        for s in self.mech.target_sites:
            pj = self.mech.data.site_xpos[s]
            rows.append(b[:3] + np.cross(b[3:].T, pj - p).T)
        return np.vstack(rows)
