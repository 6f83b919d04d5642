"""The identification Jacobian on the compiled kernel
(twin.kinematics.kernels.jacobian_batch): the parameters' screws as the arrays the
kernel reads, and the poses in chunks side by side on the kept pool.

The kernel does per configuration what twin.kinematics.sensitivity_batch does with arrays over poses
(frames, screws, explicit term, the outputs' motion, the adjoint solve and its contraction),
so no (poses x sites x parameters) array is formed in between. It covers serial chains and
square closure systems; twin.kinematics.sensitivity_batch keeps the numpy path for the others and as
the reference the tests compare against.
"""

from __future__ import annotations

import mujoco
import numpy as np

from twin.kinematics.compiled import (
    CompiledPlan,
    compiled_numbers,
    int_array,
    own_copy,
    parallel_min,
    pose_chunks,
    processors,
    run_chunks,
)
from twin.kinematics.structure import FastKinematics
from twin.parameters import ParameterSet, left_jacobian_so3

# the kernel's screw kinds (twin.kinematics.kernels.screws)
SHIFT, TURN, HINGE, SLIDE = 0, 1, 2, 3
PARALLEL_MIN = 64  # fewer poses than this: one thread


def screw_arrays(
    params: ParameterSet, model: mujoco.MjModel, values: np.ndarray
) -> tuple[np.ndarray, ...]:
    """(kind, element, body, vec, pivot) of every parameter for the kernel's ``screws``, as
    :meth:`~twin.parameters.ParameterSet.screws_soa` reads them: a body or site offset
    shifts along its axis in the parent's (the site's body's) frame, a body rotation turns
    about ``J_l(rotvec) axis`` in the parent's frame about the body's origin (``pivot``,
    ``model``'s offset with ``values`` injected), a joint's zero turns about (slides along)
    the joint's axis."""
    n = len(params)
    kind, el, axis = params.kind, params.element, params.axis
    code = np.empty(n, dtype=np.int64)
    body = np.full(n, -1, dtype=np.int64)
    vec = np.zeros((n, 3))
    pivot = np.zeros((n, 3))
    shifted = np.flatnonzero(kind == 0)
    code[shifted], body[shifted] = SHIFT, model.body_parentid[el[shifted]]
    vec[shifted] = axis[shifted]
    turned = np.flatnonzero(kind == 1)
    if turned.size:
        rotvecs = params.rotation_vectors(np.asarray(values, dtype=float))
        # one left Jacobian per rotated body (a body's rotations share its rotation vector)
        left = {b: left_jacobian_so3(w) for b, w in rotvecs.items()}
        code[turned], body[turned] = TURN, model.body_parentid[el[turned]]
        for k in turned:
            vec[k] = left[int(el[k])] @ axis[k]
        pivot[turned] = model.body_pos[el[turned]]
    sited = np.flatnonzero(kind == 2)
    code[sited], body[sited] = SHIFT, model.site_bodyid[el[sited]]
    vec[sited] = axis[sited]
    zeros = np.flatnonzero(kind == 3)
    code[zeros] = np.where(np.asarray(params.is_angle)[zeros], HINGE, SLIDE)
    other = np.flatnonzero(~params.is_geometric)  # no motion (callers refuse them before)
    code[other], body[other] = SHIFT, 0
    return code, int_array(el), body, vec, pivot


def jacobian_compiled(
    fk: FastKinematics,
    plan: CompiledPlan,
    params: ParameterSet,
    values: np.ndarray,
    qpos: np.ndarray,
    sites: np.ndarray,
    moves: np.ndarray,
    angular: bool,
) -> np.ndarray:
    """d(outputs)/d(parameters) (N, O*rows, n) at the closed configurations ``qpos``
    (N, nq) of ``fk``'s machine (with ``values`` injected): the outputs are the sites
    ``sites`` (O,), their positions (rows x, y, z) and with ``angular`` their rotations
    (3 more rows), ``moves`` (O, n_free) says which free dof moves which of them."""
    from twin.kinematics.kernels import jacobian_batch  # compiles on first use

    model = fk.model
    cs = fk.closure
    closure_sites = cs.sites if cs is not None else np.zeros(0, dtype=int)
    nc = len(closure_sites) // 2
    affected = params.site_affected(model, np.concatenate([closure_sites, sites]).astype(int))
    pairs = (*np.nonzero(affected[: 2 * nc]), *np.nonzero(affected[2 * nc :]))
    pairs = tuple(int_array(p) for p in pairs)
    outputs = (int_array(sites), np.ascontiguousarray(moves, dtype=np.uint8), bool(angular))
    parameters = screw_arrays(params, model, values)
    numbers = compiled_numbers(fk)
    qs = np.ascontiguousarray(qpos, dtype=float)
    n_pose, m_rows, n_par = len(qs), len(sites) * (6 if angular else 3), len(params)
    out = np.empty((n_pose, m_rows, n_par))
    chunks = pose_chunks(n_pose, 1 if n_pose < parallel_min(fk, PARALLEL_MIN) else processors())

    def work(sl: slice) -> None:  # arrays of its own (see kinematics_compiled.solve_compiled)
        part = np.empty((sl.stop - sl.start, m_rows, n_par))
        jacobian_batch(
            qs[sl].copy(),
            own_copy(plan.structure),
            own_copy(numbers),
            own_copy(plan.closure),
            own_copy(plan.dofs),
            own_copy(outputs),
            own_copy(parameters),
            own_copy(pairs),
            part,
        )
        out[sl] = part

    run_chunks(work, chunks)
    return out
