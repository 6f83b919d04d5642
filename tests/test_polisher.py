"""The hybrid polisher: model, source errors, two error models, identifiability, bad input."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from calib.analysis.identifiability import analyse
from calib.analysis.reconstruction import correlation_reconstruction, spectral_reconstruction
from calib.analysis.screw_polisher import PolisherScrewModel
from calib.exceptions import IdentifiabilityError
from calib.fit.model import CalibrationModel
from scenarios.studies.polisher_identifiability.study import fd_jacobian, group_relative_error
from twin.exceptions import WorkspaceError
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.sensitivity import target_jacobian, tool_twist_jacobian
from twin.kinematics.single_pose import forward, inverse
from twin.mechanism import Mechanism
from twin.rotations import rotvec_from_matrix
from twin.workspace import commands_for_poses, layer_poses

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def polisher() -> Mechanism:
    return Mechanism.from_xml(ROOT / "models/polisher.xml")


@pytest.fixture(scope="module")
def params(polisher):
    return load_parameter_set(ROOT / "models/polisher.params.toml", polisher.model)


@pytest.fixture(scope="module")
def fine_plan(polisher):
    poses = layer_poses(polisher, [0.06, -0.06], 7, (0.25, 0.25))
    return poses, commands_for_poses(polisher, poses)


def test_table1_dimensions(polisher):
    """Huang et al. 2018, Table 1: |A44 A64| = 345, |A44 A6i| = 135, |P0 P| = 250, |P0 Pi| = 200."""
    sol = forward(polisher, inverse(polisher, np.zeros(6)).actuators)
    d = polisher.data
    a44 = d.xpos[polisher.model.body("limb4_j4").id]
    a64 = d.xpos[polisher.model.body("limb4_j6").id]
    assert np.linalg.norm(a64 - a44) == pytest.approx(0.345, abs=1e-9)
    for i in (1, 2, 3):
        s = d.site_xpos[polisher.site_id(f"platform_S{i}")]
        assert np.linalg.norm(s - a44) == pytest.approx(0.135, abs=1e-9)
    p0 = d.site_xpos[polisher.site_id("P0")]
    assert np.linalg.norm(sol.tool_position - p0) == pytest.approx(0.250, abs=1e-9)
    for t in sol.targets:
        assert np.linalg.norm(t - p0) == pytest.approx(0.200, abs=1e-9)
        # the gauge triangle is normal to P0P
        assert (t - p0) @ (sol.tool_position - p0) == pytest.approx(0.0, abs=1e-12)
    # P2P3 along x and P0P1 along y at the reference pose
    t1, t2, t3 = sol.targets
    np.testing.assert_allclose((t3 - t2) / np.linalg.norm(t3 - t2), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose((t1 - p0) / np.linalg.norm(t1 - p0), [0, 1, 0], atol=1e-12)
    # the workpiece z axis makes beta = pi/6 with z0 (Eq. 8)
    z0 = d.xmat[polisher.model.body("base").id].reshape(3, 3)[:, 2]
    assert np.degrees(np.arccos(-z0[2])) == pytest.approx(30.0, abs=1e-9)


def test_task_workspace_reachable_in_pure_translation(polisher):
    """All corners of the 500 x 500 x 120 mm cuboid: limbs inside 628..1178 mm, FK round trip."""
    for corner in itertools.product([-0.25, 0.25], [-0.25, 0.25], [-0.06, 0.06]):
        pose = np.array([*corner, 0, 0, 0])
        sol = inverse(polisher, pose)
        assert np.all((sol.actuators[:3] > 0.628) & (sol.actuators[:3] < 1.178))
        fk = forward(polisher, sol.actuators)
        assert fk.residual < 1e-12
        np.testing.assert_allclose(fk.tool_position, pose[:3], atol=1e-11)
        assert np.linalg.norm(rotvec_from_matrix(fk.tool_rotation)) < 1e-11


def test_source_error_count(params):
    # 4 base frames x 6 + 24 joint frames x 5 + 6 encoder offsets (Appendix A's rule)
    assert len(params) == 4 * 6 + 24 * 5 + 6 == 150
    assert sum(n.endswith(".encoder") for n in params.names) == 6


def test_screw_model_equals_twin_jacobian(polisher, params, fine_plan):
    """Eqs. 1-9 + Appendix A against the implicit-function Jacobian, at random nodes."""
    _, commands = fine_plan
    screw = PolisherScrewModel(polisher.copy(), params)
    zero = np.zeros(len(params))
    for c in commands[[0, 17, 60, 97]]:
        sol = forward(polisher, c)
        h_twin = target_jacobian(polisher, params, zero, sol.qpos)
        h_screw = screw.target_matrix(sol.qpos)
        assert group_relative_error(h_twin, h_screw, params.is_angle) < 1e-9
        b_twin = tool_twist_jacobian(polisher, params, zero, sol.qpos)
        assert np.max(np.abs(b_twin - screw.pose_error_matrix(sol.qpos))) < 1e-9


def test_twin_jacobian_against_finite_differences(polisher, params, fine_plan):
    _, commands = fine_plan
    model = CalibrationModel(polisher, params)
    zero = np.zeros(len(params))
    cmds = commands[[5, 80]]
    h = model.jacobian(zero, model.predict(zero, cmds))
    h_fd = fd_jacobian(model, cmds)
    assert group_relative_error(h_fd, h, params.is_angle) < 1e-6


def test_reconstructions_agree_and_are_deterministic(polisher, params, fine_plan):
    _, commands = fine_plan
    model = CalibrationModel(polisher, params)
    zero = np.zeros(len(params))
    h = model.jacobian(zero, model.predict(zero, commands))
    xi = np.array([n.endswith(".encoder") for n in params.names])
    kept = correlation_reconstruction(h, params.names, xi)
    assert len(kept) == spectral_reconstruction(h).rank == analyse(h, params.names).rank == 51
    assert set(np.flatnonzero(xi)) <= set(kept)  # H = [H_xi H_eta] keeps the encoders
    # same selection when the rows come in another order (a different platform's round-off)
    perm = np.random.default_rng(3).permutation(h.shape[0])
    assert correlation_reconstruction(h[perm], params.names, xi) == kept
    # limbs 2 and 3 are mirror images: the same components are kept
    names = [params.names[k] for k in kept]
    two = sorted(n.split(".", 1)[1] for n in names if n.startswith("limb2."))
    three = sorted(n.split(".", 1)[1] for n in names if n.startswith("limb3."))
    assert two == three


def test_node_outside_workspace_raises(polisher):
    with pytest.raises(WorkspaceError, match="outside the workspace"):
        commands_for_poses(polisher, np.array([[0.30, 0.0, 0.0, 0, 0, 0]]))
    with pytest.raises(WorkspaceError, match="rx"):
        commands_for_poses(polisher, np.array([[0.0, 0.0, 0.0, 0.1, 0, 0]]))


def test_node_beyond_stroke_raises(polisher):
    """Inside the box of a wider plan but beyond a UPS limb's stroke: named by the IK."""
    with pytest.raises(WorkspaceError, match="stroke"):
        inverse(polisher, np.array([0.45, -0.45, -0.2, 0, 0, 0]))


def test_wrist_angle_past_range_raises(polisher):
    # a head yaw of 100 deg needs theta4 beyond its +-90 deg range
    with pytest.raises(WorkspaceError, match=r"theta4.*range"):
        inverse(polisher, np.array([0.0, 0.0, 0.0, 0.0, 0.0, np.radians(100)]))
    commands = inverse(polisher, np.zeros(6)).actuators.copy()
    commands[4] = np.radians(100)
    with pytest.raises(WorkspaceError, match=r"theta5.*range"):
        forward(polisher, commands)


def _plan_jacobian(polisher, params, poses):
    model = CalibrationModel(polisher, params)
    zero = np.zeros(len(params))
    return model.jacobian(zero, model.predict(zero, commands_for_poses(polisher, poses)))


def test_rank_deficient_h_xi_raises(polisher, params):
    """One node seen through one target gives 3 equations for 6 encoder offsets."""
    h = _plan_jacobian(polisher, params, np.zeros((1, 6)))[:3]
    xi = np.array([n.endswith(".encoder") for n in params.names])
    with pytest.raises(IdentifiabilityError, match="H_xi has rank 3 for 6"):
        correlation_reconstruction(h, params.names, xi)


def test_one_node_identifies_only_the_encoders(polisher, params):
    """Three targets give the full pose, so H_xi has full rank even at one node (the paper:
    rank(H_xi) = f at nonsingular configurations); the structural errors are what is lost,
    and fine calibration refuses such a plan."""
    from calib.two_step.fine import fine_problem

    model = CalibrationModel(polisher, params)
    xi = np.array([n.endswith(".encoder") for n in params.names])
    h = _plan_jacobian(polisher, params, np.zeros((1, 6)))
    assert sorted(correlation_reconstruction(h, params.names, xi)) == list(np.flatnonzero(xi))

    def measure(commands):
        return forward(polisher, commands[0]).targets[None]

    with pytest.raises(IdentifiabilityError, match="only the 6 encoder offsets"):
        fine_problem(model, np.zeros(len(params)), xi, np.zeros((1, 6)), measure)


def test_collinear_nodes_lose_structural_errors(polisher, params):
    """One layer of nodes on one line identifies far fewer errors than the paper's plan."""
    poses = np.array([[x, 0.0, 0.0, 0, 0, 0] for x in np.linspace(-0.25, 0.25, 7)])
    h = _plan_jacobian(polisher, params, poses)
    report = analyse(h, params.names)
    assert report.rank == 29 < 51
    assert len(report.unidentifiable) == len(params) - 29


def test_null_space_groups_of_a_known_matrix():
    """Columns c0, c1, c0 again, zero, c0 + c1, c2: c0, its copy and c0 + c1 and c1 are coupled
    (2 directions unseen among 4, 2 combinations read), c2 alone, the zero column no effect;
    the rank 3 = 1 alone + 2 read."""
    from scenarios.studies.polisher_identifiability.null_space import null_space

    rng = np.random.default_rng(0)
    c = rng.normal(size=(12, 3))
    h = np.column_stack([c[:, 0], c[:, 1], c[:, 0], np.zeros(12), c[:, 0] + c[:, 1], c[:, 2]])
    names = ["a.x", "a.y", "b.x", "b.y", "b.z", "c.x"]
    seen = null_space(h, names)
    assert seen.rank == 3
    assert seen.no_effect == ("b.y",) and seen.alone == ("c.x",)
    (group,) = seen.mixed
    assert set(group.members) == {"a.x", "a.y", "b.x", "b.z"}
    assert (group.unseen, group.read) == (2, 2)
    assert seen.share[3] == pytest.approx(1.0) and seen.share[5] == pytest.approx(0.0, abs=1e-12)
    rows = seen.rows(names)
    assert rows["a + b"] == {"alone": 0, "read": 2, "unseen": 2, "no_effect": 0}
    assert rows["b"]["no_effect"] == 1 and rows["c"]["alone"] == 1
    n = seen.summary(names)
    assert n["alone"] + n["read_in_combinations"] == n["rank"]
    assert n["no_effect"] + n["unseen_in_combinations"] == len(names) - n["rank"]


def test_null_space_of_the_fine_plan_adds_up(polisher, params, fine_plan):
    """On the paper's plan: one by one + combinations read = the rank of the reconstructions
    (51); no effect = the zero columns analyse names; every parameter in one row."""
    from scenarios.studies.polisher_identifiability.null_space import COUPLED, null_space
    from scenarios.studies.polisher_identifiability.report import null_space_sentence

    model = CalibrationModel(polisher, params)
    x0 = np.zeros(len(params))
    h = model.jacobian(x0, model.predict(x0, fine_plan[1]))
    seen = null_space(h, list(params.names))
    n = seen.summary(list(params.names))
    rank = spectral_reconstruction(h).rank
    assert n["rank"] == rank == n["alone"] + n["read_in_combinations"]
    no_effect = [
        k for k, why in analyse(h, list(params.names)).unidentifiable.items() if "no effect" in why
    ]
    assert sorted(seen.no_effect) == sorted(no_effect)
    assert sum(sum(r.values()) for r in n["by_part"].values()) == len(params)
    # the projector's blocks are projectors: their traces (the unseen counts) are integers,
    # so no coupling above COUPLED was cut and none below it joined two groups
    from calib.analysis import scaled_jacobian

    vt = np.linalg.svd(scaled_jacobian(h)[0])[2]
    p = vt[rank:].T @ vt[rank:]
    index = {name: i for i, name in enumerate(params.names)}
    for g in seen.mixed:
        k = [index[m] for m in g.members]
        assert np.trace(p[np.ix_(k, k)]) == pytest.approx(g.unseen, abs=1e-9)
        rest = np.setdiff1d(np.arange(len(params)), k)
        assert np.max(np.abs(p[np.ix_(k, rest)])) < COUPLED
    text = null_space_sentence(n)
    assert f"{n['no_effect']} move no target" in text and f"The rank, {rank}," in text
    other = {**n, "no_effect": 7, "rank": 12}
    assert "7 move no target" in null_space_sentence(other)
    assert "The rank, 12," in null_space_sentence(other)
