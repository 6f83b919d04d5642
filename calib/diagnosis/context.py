"""What the diagnosis knows about each pose: commands, time, sensitivities, loads, features.

Everything here comes from the calibration model (the nominal mechanism with the identified
geometric values injected) and from the dataset: commands, measurement order or time. Nothing
of the truth twin, nothing of its effects.

* ``j_act``: d(targets)/d(actuator offsets), the columns through which any actuator-level
  effect (gain, screw lead, encoder eccentricity, backlash, drift, compliance) shows;
* ``extra``: identification columns of geometry the user's error model left out (reflector
  offsets on the tool, joint-axis direction errors), from a richer parameter set;
* ``gravity``: the static actuator loads of the nominal model's own masses and of a unit
  payload at the tool (calib.diagnosis.gravity);
* ``tool_rotation``: the tool frame per pose, to test the residual against orientation.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.diagnosis.gravity import GravityLoads, gravity_loads
from calib.fit.model import CalibrationModel
from common.worker_processes import map_chunks
from twin.kinematics.closure import update_kinematics
from twin.kinematics.sensitivity import target_jacobian
from twin.kinematics.sensitivity_batch import target_jacobian_batch
from twin.parameters import Parameter, ParameterSet
from twin.rotations import matrix_from_quat

SITE_POS = 2
BODY_ROT = 1
# Up to this many poses each pose's Jacobian on its own (twin.kinematics.sensitivity), as every
# diagnosis before; beyond, all poses at once by the batched adjoint
# (twin.kinematics.sensitivity_batch, the same derivatives to 1e-12 relative, tested): 9,000
# arm poses 0.03 s instead of 1.3 s, 9,000 hexapod poses 0.3 s instead of 5 s (one core)
PER_POSE_MAX = 1500


@dataclass(frozen=True)
class ExtraGeometry:
    """Named columns of geometry outside the error model, grouped by candidate."""

    groups: dict[str, tuple[str, ...]]  # candidate name -> parameter names
    columns: dict[str, np.ndarray]  # candidate name -> (N, R, k)


@dataclass(frozen=True)
class Context:
    """One set of poses as the candidates see it (SI units throughout)."""

    commands: np.ndarray  # (N, A)
    time: np.ndarray  # (N,) measurement order or seconds, from the calibration's first pose
    previous: np.ndarray  # (A,) the command before the first pose of this set
    is_slide: np.ndarray  # (A,) bool
    actuator_names: tuple[str, ...]
    time_unit: str  # "pose" or "s"
    j_act: np.ndarray | None = None  # (N, R, A)
    extra: ExtraGeometry | None = None
    gravity: GravityLoads | None = None
    targets: np.ndarray | None = None  # (N, T, 3) predicted at the geometric estimate
    tool_rotation: np.ndarray | None = None  # (N, 3, 3)
    head: np.ndarray | None = None  # tracker head in the base frame (3,)
    rows: np.ndarray | None = None  # (N, R) bool: kept residual rows

    @property
    def n_poses(self) -> int:
        return len(self.commands)


def approach_direction(commands: np.ndarray, time: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Sign of each actuator's last move before each pose, in measurement order (N, A)."""
    seq = np.argsort(time, kind="stable")
    prev = np.vstack([previous, commands[seq][:-1]])
    direction = np.zeros_like(commands, dtype=float)
    direction[seq] = np.sign(commands[seq] - prev)
    return direction


def actuator_offsets(model: CalibrationModel) -> ParameterSet:
    """One encoder-offset parameter per actuator (an actuator offset as a joint zero)."""
    mech = model.nominal
    return ParameterSet(
        [
            Parameter(f"offset.{n}", "joint_zero", mech.model.joint(int(j)).name)
            for n, j in zip(mech.actuator_names, mech.actuator_joints, strict=True)
        ],
        mech.model,
    )


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    """Two unit vectors perpendicular to ``axis`` (2, 3), chosen deterministically."""
    a = axis / np.linalg.norm(axis)
    ref = np.eye(3)[int(np.argmin(np.abs(a)))]
    e1 = np.cross(a, ref)
    e1 /= np.linalg.norm(e1)
    return np.array([e1, np.cross(a, e1)])


def _new_directions(existing: list[np.ndarray], proposed: np.ndarray) -> list[np.ndarray]:
    """The proposed unit vectors not already in the span of ``existing`` (Gram-Schmidt)."""
    basis = [e / np.linalg.norm(e) for e in existing]
    out = []
    for v in proposed:
        w = v.copy()
        for b in basis:
            w -= (w @ b) * b
        if np.linalg.norm(w) > 1e-6:
            basis.append(w / np.linalg.norm(w))
            out.append(v)
    return out


def extra_parameters(model: CalibrationModel) -> dict[str, list[Parameter]]:
    """Geometry beyond the user's error model: reflector offsets (every target site along
    its body's axes) and joint-axis direction errors (two tilts of each joint's body about
    axes perpendicular to the joint axis), minus what the error model already holds."""
    m = model.nominal.model
    params = model.params
    have: dict[tuple[int, int], list[np.ndarray]] = {}
    for k in range(len(params)):
        key = (int(params.kind[k]), int(params.element[k]))
        have.setdefault(key, []).append(params.axis[k])
    reflector = []
    for s in model.nominal.target_sites:
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, int(s))
        for axis in _new_directions(have.get((SITE_POS, int(s)), []), np.eye(3)):
            tag = "xyz"[int(np.argmax(np.abs(axis)))]
            reflector.append(Parameter(f"{name}.d{tag}", "site_pos", name, tuple(axis)))
    tilts = []
    proposed: dict[int, list[tuple[str, np.ndarray]]] = {}
    for j in range(m.njnt):
        if int(m.jnt_type[j]) not in (
            int(mujoco.mjtJoint.mjJNT_HINGE),
            int(mujoco.mjtJoint.mjJNT_SLIDE),
        ):
            continue
        b = int(m.jnt_bodyid[j])
        axis = matrix_from_quat(m.body_quat[b]) @ m.jnt_axis[j]
        jname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
        proposed.setdefault(b, []).extend((jname, e) for e in _perpendicular(axis))
    for b, items in proposed.items():
        bname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        kept = _new_directions(have.get((BODY_ROT, b), []), np.array([e for _, e in items]))
        for i, axis in enumerate(kept):
            jname = next(n for n, e in items if e is axis or np.allclose(e, axis))
            axis = np.where(np.abs(axis) < 1e-12, 0.0, axis)
            tilts.append(Parameter(f"{bname}.tilt{i + 1}({jname})", "body_rot", bname, tuple(axis)))
    return {"reflector_offsets": reflector, "joint_axis_errors": tilts}


def sensitivities(
    model: CalibrationModel, values: np.ndarray, qpos: np.ndarray, with_extra: bool = True
) -> tuple[np.ndarray, ExtraGeometry | None]:
    """Actuator-offset columns (N, R, A) and the extra geometric columns, one Jacobian per
    pose over one parameter set."""
    offsets = actuator_offsets(model)
    groups = extra_parameters(model) if with_extra else {}
    plist = list(offsets.parameters) + [p for g in groups.values() for p in g]
    mech = model.mechanism(values)
    pset = ParameterSet(plist, mech.model)
    zero = np.zeros(len(pset))
    if len(qpos) > PER_POSE_MAX:  # a long campaign: all poses at once, the batched adjoint
        flat = target_jacobian_batch(mech, pset, zero, qpos)
        jac = flat.reshape(len(qpos), -1, len(pset))
    else:
        # the poses in chunks, side by side in worker processes on a long run (each pose's
        # Jacobian is that of one process, bit for bit: common.worker_processes)
        def chunk(poses: np.ndarray) -> list[np.ndarray]:
            return [target_jacobian(mech, pset, zero, qpos[i]) for i in poses]

        rows = 3 * len(model.nominal.target_names) * len(qpos)
        jac = np.array([j for part in map_chunks(chunk, len(qpos), rows) for j in part])
    a = len(offsets)
    j_act = jac[:, :, :a]
    if not with_extra:
        return j_act, None
    cols, names, start = {}, {}, a
    for g, ps in groups.items():
        if ps:
            cols[g] = jac[:, :, start : start + len(ps)]
            names[g] = tuple(p.name for p in ps)
        start += len(ps)
    return j_act, ExtraGeometry(names, cols)


def tool_rotations(model: CalibrationModel, values: np.ndarray, qpos: np.ndarray) -> np.ndarray:
    """The tool frame at each closed configuration (N, 3, 3)."""
    mech = model.mechanism(values)
    out = np.empty((len(qpos), 3, 3))
    for k, q in enumerate(qpos):
        update_kinematics(mech, q)
        out[k] = mech.data.site_xmat[mech.tool_site].reshape(3, 3)
    return out


def build_context(
    model: CalibrationModel,
    values: np.ndarray,
    commands: np.ndarray,
    time: np.ndarray,
    time_unit: str,
    qpos: np.ndarray | None = None,
    targets: np.ndarray | None = None,
    previous: np.ndarray | None = None,
    head: np.ndarray | None = None,
    rows: np.ndarray | None = None,
    full: bool = True,
    gravity: bool = True,
) -> Context:
    """The context of one pose set; ``full`` adds the Jacobians and features (the fitting
    needs them), without it only what actuator offsets need (commands, time, loads)."""
    nominal = model.nominal
    commands = np.asarray(commands, dtype=float)
    if previous is None:
        previous = nominal.home_qpos[nominal.actuator_qpos]
    if (qpos is None or targets is None) and (full or gravity):
        pred = model.predict(values, commands)
        qpos, targets = pred.qpos, pred.targets
    loads = None
    if gravity:
        loads = gravity_loads(model.mechanism(values), qpos, nominal.masses_defaulted)
    j_act, extra, rot = None, None, None
    if full:
        j_act, extra = sensitivities(model, values, qpos)
        rot = tool_rotations(model, values, qpos)
    return Context(
        commands=commands,
        time=np.asarray(time, dtype=float),
        previous=np.asarray(previous, dtype=float),
        is_slide=np.asarray(nominal.actuator_is_slide, dtype=bool),
        actuator_names=nominal.actuator_names,
        time_unit=time_unit,
        j_act=j_act,
        extra=extra,
        gravity=loads,
        targets=targets,
        tool_rotation=rot,
        head=None if head is None else np.asarray(head, dtype=float),
        rows=rows,
    )


def reflector_span(model: CalibrationModel) -> dict[str, np.ndarray]:
    """``{"reflector_offsets": (k, 6)}``: what a small rigid motion (translation, rotation
    about the body's origin) of the reflector set does to each extra reflector parameter
    (its axis times the motion of its site), for :func:`calib.diagnosis.verdict.effect_parameters`;
    empty when the extra reflector parameters are not all on one body."""
    params = extra_parameters(model)["reflector_offsets"]
    m = model.nominal.model
    if not params:
        return {}
    sites = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, p.element) for p in params]
    if len({int(m.site_bodyid[s]) for s in sites}) != 1:
        return {}
    rows = []
    for p, s in zip(params, sites, strict=True):
        pos = np.asarray(m.site_pos[s], dtype=float)
        axis = np.asarray(p.axis, dtype=float)
        rows.append(np.concatenate([axis, np.cross(pos, axis)]))  # a.(v + w x p)
    return {"reflector_offsets": np.array(rows)}
