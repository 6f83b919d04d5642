"""The hexapod twin: Table 1 geometry, closed-chain kinematics, Jacobians, injection, errors."""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

import twin.kinematics.single_pose as kinematics
from calib.data import Dataset, DatasetError
from calib.exceptions import IdentifiabilityError
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations, bind_dataset
from twin.exceptions import ClosureError, ModelError, WorkspaceError
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.kinematics.closure import closure_jacobian, closure_residual, update_kinematics
from twin.kinematics.single_pose import forward, inverse
from twin.mechanism import Mechanism
from twin.rotations import rotvec_from_matrix
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
XML = ROOT / "models/hexapod_rrrprr.xml"


@pytest.fixture(scope="module")
def hexapod() -> Mechanism:
    return Mechanism.from_xml(XML)


@pytest.fixture(scope="module")
def params(hexapod):
    return load_parameter_set(ROOT / "models/hexapod_rrrprr.params.toml", hexapod.model)


@pytest.fixture(scope="module")
def table2(params):
    return load_values(ROOT / "scenarios/truth/hexapod_table2.toml", params)


@pytest.fixture(scope="module")
def poses(hexapod):
    return random_poses(hexapod, 12, np.random.default_rng(5))


def test_table1_geometry(hexapod):
    """Han et al. 2019, Table 1 (mm); Y_P2 printed as "5.9" is 115.911 by symmetry."""
    m = hexapod.model
    xb = [173.867, -46.587, -127.279, -127.279, -46.587, 173.867]
    yb = [46.587, 173.867, 127.279, -127.279, -173.867, -46.587]
    xp = [84.853, 31.058, -115.911, -115.911, 31.058, 84.853]
    yp = [84.853, 115.911, 31.058, -31.058, -115.911, -84.853]
    for i in range(6):
        np.testing.assert_allclose(
            m.body(f"leg{i + 1}_base").pos * 1e3, [xb[i], yb[i], 0], atol=1e-3
        )
        np.testing.assert_allclose(
            m.site(f"platform_P{i + 1}").pos * 1e3, [xp[i], yp[i], 0], atol=1e-3
        )
        assert np.linalg.norm(m.body(f"leg{i + 1}_lower").pos) == pytest.approx(0.005, abs=1e-12)
        assert np.linalg.norm(m.body(f"leg{i + 1}_end").pos) == pytest.approx(0.005, abs=1e-12)
    sol = inverse(hexapod, np.array([0, 0, 0.220, 0, 0, 0]))
    np.testing.assert_allclose(sol.actuators * 1e3, 230.715, atol=1e-3)
    # Table 3: stroke and workspace
    np.testing.assert_allclose(hexapod.actuator_range, [[0.195, 0.265]] * 6)
    np.testing.assert_allclose(hexapod.workspace_max[:3], [0.025, 0.025, 0.240])
    np.testing.assert_allclose(np.degrees(hexapod.workspace_max[3:]), [15, 15, 20])
    assert hexapod.actuator_names == tuple(f"leg{i}" for i in range(1, 7))
    assert hexapod.n_closure == 36 and m.nv == 42 and hexapod.n_targets == 3


def test_mujoco_own_weld_rows_close_at_our_solution(hexapod, poses):
    """MuJoCo's equality constraint violation is zero where our Newton says the loops close."""
    m = hexapod.model
    d = mujoco.MjData(m)
    sol = forward(hexapod, poses[1][3])
    d.qpos[:] = sol.qpos
    mujoco.mj_forward(m, d)
    eq_rows = d.efc_type[: d.nefc] == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    assert np.max(np.abs(d.efc_pos[: d.nefc][eq_rows])) < 1e-12


def test_closure_residual_and_round_trips(hexapod, poses):
    pose_list, commands = poses
    for pose, c in zip(pose_list, commands, strict=True):
        sol = forward(hexapod, c)
        assert sol.residual < 1e-12
        np.testing.assert_allclose(sol.tool_position, pose[:3], atol=1e-11)
        r_cmd = kinematics.pose_to_frame(pose)[0]
        assert np.linalg.norm(rotvec_from_matrix(sol.tool_rotation @ r_cmd.T)) < 1e-11
        back = inverse(hexapod, pose)
        np.testing.assert_allclose(back.actuators, c, atol=1e-11)


def test_batch_equals_single(hexapod, poses, monkeypatch):
    import twin.kinematics.batch as kb

    _, commands = poses
    monkeypatch.setattr(kb, "CHUNK", 5)  # several chunks, one of them partial
    for threads in (1, 2):
        batch = forward_batch(hexapod, commands, nthread=threads)
        for c, t in zip(commands, batch.targets, strict=True):
            np.testing.assert_allclose(forward(hexapod, c).targets, t, atol=1e-12)


def test_closure_jacobian_against_finite_differences(hexapod, poses):
    sol = forward(hexapod, poses[1][0])
    update_kinematics(hexapod, sol.qpos)
    jac = closure_jacobian(hexapod)
    fd = np.zeros_like(jac)
    eps = 1e-7
    for k in range(hexapod.model.nv):
        out = []
        for sign in (1.0, -1.0):
            q = sol.qpos.copy()
            dq = np.zeros(hexapod.model.nv)
            dq[k] = sign * eps
            mujoco.mj_integratePos(hexapod.model, q, dq, 1.0)
            update_kinematics(hexapod, q)
            out.append(closure_residual(hexapod))
        fd[:, k] = (out[0] - out[1]) / (2 * eps)
    assert np.max(np.abs(fd - jac)) < 1e-7 * np.max(np.abs(jac))


@pytest.mark.parametrize("at_truth", [False, True], ids=["nominal", "table2"])
def test_identification_jacobian_against_finite_differences(
    hexapod, params, table2, poses, at_truth
):
    values = table2 if at_truth else np.zeros(len(params))
    model = CalibrationModel(hexapod, params)
    commands = poses[1][:3]
    jac = model.jacobian(values, model.predict(values, commands))
    eps = 1e-6  # the closure solve stops near 1e-13 m: a smaller step would measure that
    fd = np.zeros_like(jac)
    for k in range(len(params)):
        dx = np.zeros(len(params))
        dx[k] = eps
        plus = model.predict(values + dx, commands).targets.reshape(-1)
        minus = model.predict(values - dx, commands).targets.reshape(-1)
        fd[:, k] = (plus - minus) / (2 * eps)
    scale = np.linalg.norm(jac, axis=0)
    assert np.max(np.abs(fd - jac).max(axis=0) / scale) < 1e-6


def test_injection_equals_recompiled_xml(hexapod, params, poses):
    values = np.zeros(len(params))
    values[params.index("leg2.base.dy")] = 0.3e-3
    values[params.index("leg4.platform.dz")] = -0.2e-3
    values[params.index("leg5.length")] = 0.4e-3
    injected = Mechanism(params.inject(hexapod.model, values))
    spec = mujoco.MjSpec.from_file(str(XML))
    spec.body("leg2_base").pos = spec.body("leg2_base").pos + np.array([0, 0.3e-3, 0])
    spec.site("platform_P4").pos = spec.site("platform_P4").pos + np.array([0, 0, -0.2e-3])
    spec.body("leg5_rod").pos = spec.body("leg5_rod").pos + np.array([0, 0, 0.4e-3])
    recompiled = Mechanism(spec.compile())
    for c in poses[1][:5]:
        np.testing.assert_allclose(
            forward(injected, c).targets, forward(recompiled, c).targets, atol=1e-12
        )


def test_noise_free_recovery_of_table2(hexapod, params, table2):
    truth = Mechanism(params.inject(hexapod.model, table2))
    _, commands = random_poses(hexapod, 29, np.random.default_rng(3))
    measured = forward_batch(truth, commands).targets
    res = identify(CalibrationModel(hexapod, params), Observations(commands, measured))
    assert res.converged
    assert np.max(np.abs(res.values - table2)) * 1e3 < 1e-6  # mm


def test_too_few_poses_cannot_identify(hexapod, params):
    _, commands = random_poses(hexapod, 5, np.random.default_rng(4))
    measured = forward_batch(hexapod, commands).targets
    model = CalibrationModel(hexapod, params)
    with pytest.raises(IdentifiabilityError, match="5 poses cannot identify all 54"):
        identify(model, Observations(commands, measured))
    res = identify(model, Observations(commands, measured), unidentifiable="fix")
    assert res.estimated.sum() == res.report.n_identifiable == 30  # 5 poses x 6 DOF


def test_pose_outside_the_stroke(hexapod):
    with pytest.raises(WorkspaceError, match=r"leg1.*outside its stroke"):
        forward(hexapod, np.array([0.30, 0.23, 0.23, 0.23, 0.23, 0.23]))
    with pytest.raises(WorkspaceError, match="not reachable"):
        inverse(hexapod, np.array([0, 0, 0.26, 0, 0, 0]))
    with pytest.raises(WorkspaceError, match="expected 6 actuator commands"):
        forward(hexapod, np.zeros(5))


def test_closure_solve_that_does_not_converge(hexapod, monkeypatch, poses):
    monkeypatch.setattr(kinematics, "MAX_ITER", 1)
    with pytest.raises(ClosureError, match="did not converge"):
        forward(hexapod, poses[1][0])


def _xml(replace: dict[str, str]) -> str:
    text = XML.read_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    return text


def test_bad_mjcf_is_named(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        Mechanism.from_xml(tmp_path / "missing.xml")
    with pytest.raises(ModelError, match="could not compile"):
        Mechanism.from_xml_string("<mujoco><worldbody><body></mujoco>")
    no_act = re.sub(r' ctrl="[^"]*"', "", _xml({"<actuator>": "<!--", "</actuator>": "-->"}))
    with pytest.raises(ModelError, match="no <actuator>"):
        Mechanism.from_xml_string(no_act)
    no_targets = XML.read_text().replace('name="target_', 'name="smr_')
    with pytest.raises(ModelError, match="no tracker target sites"):
        Mechanism.from_xml_string(no_targets)
    no_tool = _xml({'<site name="tool"': '<site name="tcp"'})
    with pytest.raises(ModelError, match="no 'tool' site"):
        Mechanism.from_xml_string(no_tool)
    body_weld = _xml({'site1="leg1_end" site2="platform_P1"': 'body1="leg1_end" body2="platform"'})
    with pytest.raises(ModelError, match="body-based"):
        Mechanism.from_xml_string(body_weld)


def _dataset(units=("mm",) * 6, frame="base", actuators=None) -> Dataset:
    names = actuators or tuple(f"leg{i}" for i in range(1, 7))
    return Dataset(
        model="hexapod_rrrprr",
        frame=frame,
        actuator_names=names,
        actuator_units=units,
        target_names=("target_1", "target_2", "target_3"),
        pose_ids=np.arange(2),
        sets=np.array(["c", "c"]),
        commands=np.full((2, len(names)), 0.23),
        readings=np.zeros((2, 3, 1, 3)),
    )


def test_dataset_must_match_the_model(hexapod):
    bind_dataset(hexapod, _dataset())
    with pytest.raises(DatasetError, match=r"actuator 'leg1' is prismatic.*'deg'"):
        bind_dataset(hexapod, _dataset(units=("deg",) + ("mm",) * 5))
    with pytest.raises(DatasetError, match="frame is 'lab'"):
        bind_dataset(hexapod, _dataset(frame="lab"))
    with pytest.raises(DatasetError, match="leg6"):
        bind_dataset(
            hexapod, _dataset(units=("mm",) * 5, actuators=tuple(f"leg{i}" for i in range(1, 6)))
        )
