"""The numpy kinematics behind batched forward kinematics and the identification Jacobian.

* the kinematic tree equals MuJoCo's ``mj_kinematics`` (frames of bodies, joints, sites) on
  the three machines and on a model with every joint kind, general and negative axes and
  joint offsets;
* batched forward kinematics, compiled and numpy alike, equals the single-pose MuJoCo Newton
  solve to 1e-9 m (it is ~1e-13) on the hexapod, the polisher, the serial arm and a four-bar
  linkage whose closure has more equations than unknowns (the least-squares path), and
  follows a model edited in place;
* the per-closure elimination and the adjoint solve equal dense LAPACK solves, also where
  the static pivots are refused and Householder takes over.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

import twin.kinematics.reduced as kinematics_reduced
import twin.kinematics.small_systems as small_systems
import twin.kinematics.structure as kinematics_fast
from twin.kinematics.adjoint import adjoint_solve
from twin.kinematics.batch import forward_batch
from twin.kinematics.single_pose import forward
from twin.kinematics.structure import fast_kinematics
from twin.kinematics.tree import TreePlan, tree_frames
from twin.mechanism import Mechanism
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
MACHINES = ("hexapod_rrrprr", "polisher", "arm6r")

EVERY_JOINT = """
<mujoco>
  <compiler boundmass="0.001" boundinertia="1e-6"/>
  <worldbody>
    <body name="a" pos="0.1 0.2 0.3" quat="0.9 0.1 -0.3 0.2">
      <freejoint/>
      <site name="sa" pos="0.05 0 0.1" quat="0.7 0.7 0 0"/>
      <body name="b" pos="0.2 0 0" quat="0.8 0 0.6 0">
        <joint name="h1" type="hinge" axis="0.3 -0.5 0.8" pos="0.01 0.02 -0.03"/>
        <joint name="s1" type="slide" axis="0.6 0.8 0" pos="0.1 0 0"/>
        <site name="sb" pos="0 0.1 0"/>
        <body name="c" pos="0 0 0.3">
          <joint name="b1" type="ball" pos="0 0.05 0"/>
          <body name="d" pos="0.1 0.1 0">
            <joint name="h2" type="hinge" axis="0 0 -1"/>
            <joint name="h3" type="hinge" axis="1 0 0" pos="0 0 0.02"/>
            <site name="sd" pos="0.02 0.03 0.04" quat="0.5 0.5 0.5 0.5"/>
          </body>
        </body>
      </body>
    </body>
    <body name="e" pos="-0.3 0 0">
      <joint name="h4" type="hinge" axis="0 -1 0"/>
      <site name="se" pos="0 0 0.2"/>
    </body>
  </worldbody>
</mujoco>
"""

FOUR_BAR = """
<mujoco model="four_bar">
  <worldbody>
    <site name="anchor" pos="1 0 0"/>
    <body name="crank">
      <joint name="j1" type="hinge" axis="0 0 1" range="-30 30"/>
      <body name="coupler">
        <joint name="j2" type="hinge" axis="0 0 1" pos="0 0.4 0"/>
        <site name="tool" pos="0.4 0.55 0"/>
        <site name="target_1" pos="0.4 0.6 0.1"/>
        <site name="target_2" pos="0.5 0.5 0.1"/>
        <body name="rocker" pos="0.8 0.7 0">
          <joint name="j3" type="hinge" axis="0 0 -1"/>
          <site name="end" pos="0.2 -0.7 0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <equality><connect site1="end" site2="anchor"/></equality>
  <actuator><position name="crank" joint="j1"/></actuator>
</mujoco>
"""


def four_bar_with_errors():
    """The four-bar (a least-squares closure: more equations than free dofs) with one error
    of every kind injected: (the error model, its values, the injected machine, 9 closed
    poses over the crank's stroke)."""
    from twin.parameters import Parameter, ParameterSet

    nominal = Mechanism.from_xml_string(FOUR_BAR)
    params = ParameterSet(
        [
            Parameter("rocker_x", "body_pos", "rocker", (1.0, 0.0, 0.0)),
            Parameter("rocker_y", "body_pos", "rocker", (0.0, 1.0, 0.0)),
            Parameter("coupler_rz", "body_rot", "coupler", (0.0, 0.0, 1.0)),
            Parameter("tool_y", "site_pos", "tool", (0.0, 1.0, 0.0)),
            Parameter("end_y", "site_pos", "end", (0.0, 1.0, 0.0)),
            Parameter("j2_zero", "joint_zero", "j2"),
        ],
        nominal.model,
    )
    values = np.array([1e-3, -2e-3, 3e-3, 2e-3, 1e-3, -2e-3])
    mech = nominal.with_model(params.inject(nominal.model, values))
    qpos = forward_batch(mech, np.linspace(-0.4, 0.4, 9)[:, None]).qpos
    return params, values, mech, qpos


def _mujoco_frames(model: mujoco.MjModel, qpos: np.ndarray) -> list[dict[str, np.ndarray]]:
    data = mujoco.MjData(model)
    out = []
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        out.append(
            {
                f: getattr(data, f).copy()
                for f in ("xpos", "xmat", "xanchor", "xaxis", "site_xpos", "site_xmat")
            }
        )
    return out


def _random_configurations(model: mujoco.MjModel, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = np.tile(model.qpos0, (n, 1)) + rng.normal(0.0, 0.4, (n, model.nq))
    for j in range(model.njnt):  # quaternions of free and ball joints: unit
        adr = model.jnt_qposadr[j]
        start = {int(mujoco.mjtJoint.mjJNT_FREE): 3, int(mujoco.mjtJoint.mjJNT_BALL): 0}
        if int(model.jnt_type[j]) in start:
            a = adr + start[int(model.jnt_type[j])]
            q[:, a : a + 4] /= np.linalg.norm(q[:, a : a + 4], axis=1, keepdims=True)
    return q


def _assert_tree_equals_mujoco(model: mujoco.MjModel, qpos: np.ndarray) -> None:
    frames = tree_frames(TreePlan(model), model, np.ascontiguousarray(qpos.T))
    sites = np.arange(model.nsite)
    spos = frames.site_positions(model, sites)
    srot = frames.site_rotations(model, sites)
    for i, ref in enumerate(_mujoco_frames(model, qpos)):
        got = {
            "xpos": frames.xpos[..., i].T,
            "xmat": np.moveaxis(frames.xmat[..., i], 2, 0).reshape(-1, 9),
            "xanchor": frames.xanchor[..., i].T,
            "xaxis": frames.xaxis[..., i].T,
            "site_xpos": spos[..., i].T,
            "site_xmat": np.moveaxis(srot[..., i], 2, 0).reshape(-1, 9),
        }
        for f, value in got.items():
            np.testing.assert_allclose(value, ref[f], rtol=0, atol=1e-12, err_msg=f)


@pytest.mark.parametrize("name", MACHINES)
def test_tree_equals_mujoco_on_the_machines(name):
    model = Mechanism.from_xml(ROOT / f"models/{name}.xml").model
    _assert_tree_equals_mujoco(model, _random_configurations(model, 12, 1))


def test_tree_equals_mujoco_for_every_joint_kind():
    model = mujoco.MjModel.from_xml_string(EVERY_JOINT)
    plan = TreePlan(model)
    kinds = {g.kind for level in plan.levels for g in level.groups}
    j = mujoco.mjtJoint
    assert kinds == {int(j.mjJNT_HINGE), int(j.mjJNT_SLIDE), int(j.mjJNT_BALL)}
    assert any(level.free_local.size for level in plan.levels)
    _assert_tree_equals_mujoco(model, _random_configurations(model, 12, 2))


def machines_with_commands(n: int, seed: int) -> dict[str, tuple[Mechanism, np.ndarray]]:
    """Each machine of MACHINES with n commands: random reachable poses of a parallel one,
    uniform over 80 % of each range for a serial one."""
    out = {}
    for name in MACHINES:
        mech = Mechanism.from_xml(ROOT / f"models/{name}.xml")
        rng = np.random.default_rng(seed)
        if mech.is_serial:
            lo, hi = mech.actuator_range.T
            commands = rng.uniform(0.8 * lo, 0.8 * hi, (n, mech.n_actuators))
        else:
            commands = random_poses(mech, n, rng)[1]
        out[name] = (mech, commands)
    return out


@pytest.fixture(scope="module")
def machines():
    return machines_with_commands(40, 3)


def _assert_batch_equals_single(mech: Mechanism, commands: np.ndarray, **kwargs) -> None:
    batch = forward_batch(mech, commands, **kwargs)
    for k, c in enumerate(commands):
        single = forward(mech, c, check_stroke=kwargs.get("check_stroke", True))
        np.testing.assert_allclose(batch.targets[k], single.targets, rtol=0, atol=1e-9)
        np.testing.assert_allclose(batch.tool_position[k], single.tool_position, atol=1e-9)
        np.testing.assert_allclose(batch.tool_rotation[k], single.tool_rotation, atol=1e-9)
    assert np.all(batch.residual < 1e-12)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
@pytest.mark.parametrize("name", MACHINES)
def test_batch_equals_single_pose_solve(machines, name, compiled):
    mech, commands = machines[name]
    _assert_batch_equals_single(mech, commands, compiled=compiled)


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_elimination_is_used_on_the_parallel_machines(machines, name):
    mech, _ = machines[name]
    cs = fast_kinematics(mech).closure
    assert cs.eliminates and cs.square
    # every limb's passive joints private to its closure; the platform's shared
    expected = {"hexapod_rrrprr": (6, 5, 6), "polisher": (3, 5, 3)}[name]
    assert [(len(g.closures), g.k) for g in cs.groups] == [expected[:2]]
    assert len(cs.shared) == expected[2]


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_cold_start_predictor_changes_nothing(machines, monkeypatch, compiled):
    mech, commands = machines["hexapod_rrrprr"]
    predicted = forward_batch(mech, commands, compiled=compiled)
    monkeypatch.setattr(kinematics_fast, "PREDICT_MIN", 10**9)
    import twin.kinematics.batch as kb

    monkeypatch.setattr(kb, "PREDICT_MIN", 10**9)
    plain = forward_batch(mech, commands, compiled=compiled)
    np.testing.assert_allclose(predicted.targets, plain.targets, rtol=0, atol=1e-12)
    assert predicted.iterations <= plain.iterations


def test_a_model_edited_in_place_is_followed(machines):
    mech, commands = machines["polisher"]
    edited = mech.copy()
    forward_batch(edited, commands)  # numbers read and kept for this model ...
    edited.model.body_pos[edited.model.site_bodyid[edited.target_sites[0]]] += [1e-3, 0, 0]
    mujoco.mj_setConst(edited.model, mujoco.MjData(edited.model))
    _assert_batch_equals_single(edited, commands[:10])  # ... and read again after the edit
    moved = forward_batch(edited, commands[:10]).targets
    assert np.abs(moved - forward_batch(mech, commands[:10]).targets).max() > 1e-4


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_batch_with_every_static_pivot_refused(machines, name, monkeypatch):
    """Householder for every closure system (the rebuilt matrices) of the numpy path: the same
    solutions."""
    mech, commands = machines[name]
    refuse = lambda mat, k, threshold=0.1: np.zeros(mat.shape[-1], dtype=bool)  # noqa: E731
    monkeypatch.setattr(kinematics_reduced, "eliminate_static", refuse)
    _assert_batch_equals_single(mech, commands[:20], compiled=False)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_four_bar_least_squares_closure(compiled):
    mech = Mechanism.from_xml_string(FOUR_BAR)
    cs = fast_kinematics(mech).closure
    assert cs.eliminates and not cs.square  # 3 equations, 2 passive joints, none shared
    assert len(cs.shared) == 0
    commands = np.linspace(-0.4, 0.4, 24)[:, None]
    _assert_batch_equals_single(mech, commands, compiled=compiled)


def _system(name: str, machines, n: int):
    mech, commands = machines[name]
    sol = forward_batch(mech, commands[:n])
    fk = fast_kinematics(mech)
    q = np.ascontiguousarray(sol.qpos.T) + 0.01  # away from closure: a general Jacobian
    frames = tree_frames(fk.tree, mech.model, q, fk.numbers())
    pos = frames.site_positions(mech.model, fk.closure.sites)
    return fk.closure, frames, pos


@pytest.mark.parametrize("name", ["hexapod_rrrprr", "polisher"])
def test_elimination_and_adjoint_equal_dense_solves(machines, name, monkeypatch):
    cs, frames, pos = _system(name, machines, 20)
    dense = cs.dense(frames, pos)  # (N, nc, nf)
    rng = np.random.default_rng(4)
    rhs = rng.normal(size=(cs.n_closure, 3, 20))
    ref = np.linalg.solve(dense, rhs.transpose(2, 0, 1)).transpose(1, 2, 0)
    np.testing.assert_allclose(cs.solve(cs.matrices(frames, pos, rhs)), ref, atol=1e-9)
    b = rng.normal(size=(len(cs.free), 4, 20))
    ref_t = np.linalg.solve(np.swapaxes(dense, 1, 2), b.transpose(2, 0, 1)).transpose(1, 2, 0)
    np.testing.assert_allclose(adjoint_solve(cs, frames, pos, b), ref_t, atol=1e-9)
    # every static pivot refused: Householder for every system, the same solutions
    refuse = lambda mat, k, threshold=0.1: np.zeros(mat.shape[-1], dtype=bool)  # noqa: E731
    monkeypatch.setattr(kinematics_reduced, "eliminate_static", refuse)
    monkeypatch.setattr(small_systems, "eliminate_static", refuse)  # the square reduced solves
    np.testing.assert_allclose(cs.solve(cs.matrices(frames, pos, rhs)), ref, atol=1e-9)
    # ... also when the refused systems are rebuilt instead of copied beforehand
    rebuilt = cs.solve(cs.matrices(frames, pos, rhs), rebuild=lambda: cs.matrices(frames, pos, rhs))
    np.testing.assert_allclose(rebuilt, ref, atol=1e-9)
    np.testing.assert_allclose(adjoint_solve(cs, frames, pos, b), ref_t, atol=1e-9)
