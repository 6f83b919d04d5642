"""Geometric parameters: injection equals a recompiled XML, screw derivatives equal finite
differences (explicit, and through the closed-chain solve)."""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from twin.exceptions import ParameterError
from twin.formats.parameter_file import load_parameter_set, load_values
from twin.kinematics.batch import forward_batch
from twin.kinematics.sensitivity import target_jacobian, tool_twist_jacobian
from twin.kinematics.single_pose import forward
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.rotations import matrix_from_rotvec, quat_from_rotvec, quat_multiply, rotvec_from_matrix
from twin.workspace import random_poses

ROOT = Path(__file__).resolve().parent.parent
HEXAPOD_XML = ROOT / "models" / "hexapod_rrrprr.xml"
EPS = 1e-7  # metres or radians, central differences


@pytest.fixture(scope="module")
def commands(hexapod):
    return random_poses(hexapod, 5, np.random.default_rng(2019))[1]


def _edit_attr(xml: str, tag: str, name: str, attr: str, value) -> str:
    """Set ``attr`` of the one element ``<tag name="name" ...>`` to ``value`` (full precision)."""
    matches = list(re.finditer(rf'<{tag} name="{re.escape(name)}"[^>]*>', xml))
    assert len(matches) == 1, (tag, name)
    m = matches[0]
    element = m.group(0)
    text = " ".join(repr(float(x)) for x in np.atleast_1d(value))
    old = re.search(rf' {attr}="[^"]*"', element)
    if old:
        new_element = element.replace(old.group(0), f' {attr}="{text}"')
    else:
        head = f'<{tag} name="{name}"'
        new_element = element.replace(head, f'{head} {attr}="{text}"', 1)
    return xml[: m.start()] + new_element + xml[m.end() :]


def _compile(xml: str) -> Mechanism:
    return Mechanism.from_xml_string(xml)


def _site_frames(model: mujoco.MjModel, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = mujoco.MjData(model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(model, d)
    return d.site_xpos.copy(), d.site_xmat.reshape(-1, 3, 3).copy()


def _targets(mech: Mechanism, commands: np.ndarray) -> np.ndarray:
    return np.array([forward(mech, c).targets for c in commands])


# ----------------------------------------------------------------------------- injection
def test_injection_equals_recompiled_xml(hexapod, hexapod_params, commands):
    params = hexapod_params
    values = np.zeros(len(params))
    values[params.index("leg2.base.dy")] = 0.3e-3
    values[params.index("leg4.platform.dz")] = -0.2e-3
    injected = Mechanism(params.inject(hexapod.model, values))

    m = hexapod.model
    xml = HEXAPOD_XML.read_text()
    xml = _edit_attr(
        xml, "body", "leg2_base", "pos", m.body("leg2_base").pos + np.array([0, 0.3e-3, 0])
    )
    xml = _edit_attr(
        xml, "site", "platform_P4", "pos", m.site("platform_P4").pos + np.array([0, 0, -0.2e-3])
    )
    recompiled = _compile(xml)

    np.testing.assert_allclose(injected.model.body_pos, recompiled.model.body_pos, atol=1e-15)
    np.testing.assert_allclose(injected.model.site_pos, recompiled.model.site_pos, atol=1e-15)
    moved = _targets(injected, commands)
    np.testing.assert_allclose(moved, _targets(recompiled, commands), rtol=0, atol=1e-12)
    # the edit is not a no-op: targets move by a good fraction of the injected errors
    assert np.max(np.abs(moved - _targets(hexapod, commands))) > 1e-4
    # and the nominal model is untouched
    np.testing.assert_array_equal(hexapod.model.body("leg2_base").pos, m.body("leg2_base").pos)


def test_body_rot_equals_recompiled_xml_and_is_a_rigid_rotation(hexapod, commands):
    params = ParameterSet(
        [
            Parameter("leg3.base.rz", "body_rot", "leg3_base", (0.0, 0.0, 1.0)),
            Parameter("leg3.base.rx", "body_rot", "leg3_base", (1.0, 0.0, 0.0)),
        ],
        hexapod.model,
    )
    values = np.array([0.01, -0.004])
    w = np.array([-0.004, 0.0, 0.01])  # one rotation vector, parent (= base) frame
    injected = Mechanism(params.inject(hexapod.model, values))

    quat = quat_multiply(quat_from_rotvec(w), hexapod.model.body("leg3_base").quat)
    recompiled = _compile(_edit_attr(HEXAPOD_XML.read_text(), "body", "leg3_base", "quat", quat))
    np.testing.assert_allclose(injected.model.body_quat, recompiled.model.body_quat, atol=1e-15)
    np.testing.assert_allclose(
        _targets(injected, commands), _targets(recompiled, commands), rtol=0, atol=1e-12
    )

    # expected rigid motion: with every joint held, leg 3 turns by exp(w) about B_3
    q = forward(hexapod, commands[0]).qpos
    p_nom, r_nom = _site_frames(hexapod.model, q)
    p_inj, r_inj = _site_frames(injected.model, q)
    rot = matrix_from_rotvec(w)
    b3 = hexapod.model.body("leg3_base").pos
    leg3_end = hexapod.site_id("leg3_end")
    np.testing.assert_allclose(p_inj[leg3_end], b3 + rot @ (p_nom[leg3_end] - b3), atol=1e-15)
    np.testing.assert_allclose(r_inj[leg3_end], rot @ r_nom[leg3_end], atol=1e-15)
    others = [s for s in range(hexapod.model.nsite) if s != leg3_end]
    np.testing.assert_array_equal(p_inj[others], p_nom[others])


def test_passive_joint_zero_equals_ref_edit(hexapod, commands):
    """An encoder offset on a passive hinge: true angle = reading + offset (ref = -offset)."""
    params = ParameterSet([Parameter("leg1.roll.zero", "joint_zero", "leg1_roll")], hexapod.model)
    v = 0.02
    injected = Mechanism(params.inject(hexapod.model, np.array([v])))
    recompiled = _compile(_edit_attr(HEXAPOD_XML.read_text(), "joint", "leg1_roll", "ref", -v))
    np.testing.assert_array_equal(injected.model.qpos0, recompiled.model.qpos0)

    q = forward(hexapod, commands[1]).qpos
    p_inj, r_inj = _site_frames(injected.model, q)
    p_xml, r_xml = _site_frames(recompiled.model, q)
    np.testing.assert_allclose(p_inj, p_xml, rtol=0, atol=1e-15)
    np.testing.assert_allclose(r_inj, r_xml, rtol=0, atol=1e-15)
    # the same reading now means a joint turned by v: leg 1's end moves, nothing else
    p_nom, _ = _site_frames(hexapod.model, q)
    leg1_end = hexapod.site_id("leg1_end")
    assert np.linalg.norm(p_inj[leg1_end] - p_nom[leg1_end]) > 1e-6
    others = [s for s in range(hexapod.model.nsite) if s != leg1_end]
    np.testing.assert_array_equal(p_inj[others], p_nom[others])

    # in the closed chain a passive offset changes only that joint's reading, by -v
    for c in commands[:3]:
        nominal, shifted = forward(hexapod, c), forward(injected, c)
        np.testing.assert_allclose(shifted.targets, nominal.targets, rtol=0, atol=1e-12)
        roll = hexapod.model.jnt_qposadr[hexapod.model.joint("leg1_roll").id]
        assert shifted.qpos[roll] - nominal.qpos[roll] == pytest.approx(-v, abs=1e-11)


def test_actuator_joint_zero_is_command_plus_offset(hexapod, hexapod_params, commands):
    params = ParameterSet([Parameter("leg1.zero", "joint_zero", "leg1_slide")], hexapod.model)
    v = 0.4e-3
    injected = Mechanism(params.inject(hexapod.model, np.array([v])))
    slide = hexapod.model.joint("leg1_slide")
    ref = float(hexapod.model.qpos0[slide.qposadr[0]])
    recompiled = _compile(
        _edit_attr(HEXAPOD_XML.read_text(), "joint", "leg1_slide", "ref", ref - v)
    )
    by_length = np.zeros(len(hexapod_params))
    by_length[hexapod_params.index("leg1.length")] = v
    lengthened = Mechanism(hexapod_params.inject(hexapod.model, by_length))

    offset = np.array([v, 0, 0, 0, 0, 0])
    for c in commands:
        got = forward(injected, c).targets
        np.testing.assert_allclose(got, forward(recompiled, c).targets, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got, forward(hexapod, c + offset).targets, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got, forward(lengthened, c).targets, rtol=0, atol=1e-12)
        assert np.max(np.abs(got - forward(hexapod, c).targets)) > 1e-5


def test_injection_leaves_the_nominal_model_alone(hexapod, hexapod_params, table2_values):
    before = (hexapod.model.body_pos.copy(), hexapod.model.site_pos.copy())
    model = hexapod_params.inject(hexapod.model, table2_values)
    assert model is not hexapod.model
    np.testing.assert_array_equal(hexapod.model.body_pos, before[0])
    np.testing.assert_array_equal(hexapod.model.site_pos, before[1])
    k = hexapod_params.index("leg2.base.dy")
    b = hexapod.model.body("leg2_base").id
    assert model.body_pos[b, 1] - before[0][b, 1] == pytest.approx(table2_values[k], abs=1e-15)


# ----------------------------------------------------------------------------- derivatives
EXTRA = (
    Parameter("leg3.base.rz", "body_rot", "leg3_base", (0.0, 0.0, 1.0)),
    Parameter("leg3.base.rx", "body_rot", "leg3_base", (1.0, 0.0, 0.0)),
    Parameter("leg2.lower.rx", "body_rot", "leg2_lower", (1.0, 0.0, 0.0)),
    Parameter("leg1.roll.zero", "joint_zero", "leg1_roll"),
    Parameter("leg2.slide.zero", "joint_zero", "leg2_slide"),
)
EXTRA_VALUES = np.array([0.01, -0.004, 0.02, 0.02, 0.4e-3])


@pytest.mark.parametrize("at", ["zero", "table2"])
def test_site_derivatives_against_finite_differences(hexapod, hexapod_params, table2_values, at):
    params = ParameterSet(hexapod_params.parameters + EXTRA, hexapod.model)
    assert len(params) == 59
    base = np.zeros(54) if at == "zero" else table2_values
    values = np.concatenate([base, EXTRA_VALUES])
    model = params.inject(hexapod.model, values)
    qpos = forward(Mechanism(model), hexapod.home_qpos[hexapod.actuator_qpos] + 0.004).qpos
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    sites = np.arange(model.nsite)
    dp, dw = params.site_derivatives(model, data, values, sites)
    assert dp.shape == dw.shape == (model.nsite, 3, len(params))

    fd_p = np.zeros_like(dp)
    fd_w = np.zeros_like(dw)
    for k in range(len(params)):
        dv = np.zeros(len(params))
        dv[k] = EPS
        p_plus, r_plus = _site_frames(params.inject(hexapod.model, values + dv), qpos)
        p_minus, r_minus = _site_frames(params.inject(hexapod.model, values - dv), qpos)
        fd_p[:, :, k] = (p_plus - p_minus) / (2 * EPS)
        fd_w[:, :, k] = rotvec_from_matrix(r_plus @ np.swapaxes(r_minus, 1, 2)) / (2 * EPS)
    scale = np.maximum(
        np.linalg.norm(dp, axis=(0, 1)), np.linalg.norm(dw, axis=(0, 1))
    )  # per parameter
    assert np.all(scale > 0.5)  # every parameter moves some site
    assert np.max(np.abs(fd_p - dp).max(axis=(0, 1)) / scale) < 1e-6
    assert np.max(np.abs(fd_w - dw).max(axis=(0, 1)) / scale) < 1e-6


@pytest.mark.parametrize("at", ["zero", "table2"])
def test_target_jacobian_against_closed_chain_finite_differences(
    hexapod, hexapod_params, table2_values, commands, at
):
    params = hexapod_params
    values = np.zeros(len(params)) if at == "zero" else np.array(table2_values)
    cmds = commands[:3]
    mech = Mechanism(params.inject(hexapod.model, values))
    sol = forward_batch(mech, cmds)
    jac = np.vstack([target_jacobian(mech, params, values, q) for q in sol.qpos])
    assert jac.shape == (3 * 3 * 3, 54)

    fd = np.zeros_like(jac)
    for k in range(len(params)):
        dv = np.zeros(len(params))
        dv[k] = EPS
        plus = forward_batch(Mechanism(params.inject(hexapod.model, values + dv)), cmds)
        minus = forward_batch(Mechanism(params.inject(hexapod.model, values - dv)), cmds)
        fd[:, k] = (plus.targets - minus.targets).reshape(-1) / (2 * EPS)
    scale = np.linalg.norm(jac, axis=0)
    assert np.all(scale > 0.1)
    assert np.max(np.abs(fd - jac).max(axis=0) / scale) < 1e-6


def test_tool_twist_jacobian_against_finite_differences(
    hexapod, hexapod_params, table2_values, commands
):
    params = hexapod_params
    values = np.array(table2_values)
    mech = Mechanism(params.inject(hexapod.model, values))
    sol = forward(mech, commands[4])
    jac = tool_twist_jacobian(mech, params, values, sol.qpos)
    assert jac.shape == (6, 54)
    fd = np.zeros_like(jac)
    for k in range(len(params)):
        dv = np.zeros(len(params))
        dv[k] = EPS
        plus = forward(Mechanism(params.inject(hexapod.model, values + dv)), commands[4])
        minus = forward(Mechanism(params.inject(hexapod.model, values - dv)), commands[4])
        fd[:3, k] = (plus.tool_position - minus.tool_position) / (2 * EPS)
        fd[3:, k] = rotvec_from_matrix(plus.tool_rotation @ minus.tool_rotation.T) / (2 * EPS)
    scale = np.linalg.norm(jac, axis=0)
    assert np.max(np.abs(fd - jac).max(axis=0) / scale) < 1e-6


def test_display_units_round_trip(hexapod_params, table2_values):
    shown = hexapod_params.to_display(table2_values)
    k = hexapod_params.index("leg1.length")
    assert shown[k] == pytest.approx(-0.274, abs=1e-12)  # Han et al. 2019, Table 2 - Table 1
    np.testing.assert_allclose(hexapod_params.from_display(shown), table2_values, atol=1e-18)
    assert hexapod_params.units() == ["m"] * 54


# ----------------------------------------------------------------------------- bad parameters
def test_unknown_element(hexapod):
    with pytest.raises(ParameterError, match=r"'p': the model has no body named 'leg7_base'"):
        ParameterSet([Parameter("p", "body_pos", "leg7_base", (1.0, 0.0, 0.0))], hexapod.model)
    with pytest.raises(ParameterError, match=r"no site named 'platform_P9'"):
        ParameterSet([Parameter("p", "site_pos", "platform_P9", (1.0, 0.0, 0.0))], hexapod.model)
    with pytest.raises(ParameterError, match=r"no joint named 'leg1_twist'"):
        ParameterSet([Parameter("p", "joint_zero", "leg1_twist")], hexapod.model)


def test_elements_that_cannot_carry_the_parameter(hexapod):
    with pytest.raises(ParameterError, match=r"joint 'platform_free' is not 1-DOF"):
        ParameterSet([Parameter("p", "joint_zero", "platform_free")], hexapod.model)
    with pytest.raises(ParameterError, match=r"the world body cannot move"):
        ParameterSet([Parameter("p", "body_pos", "world", (1.0, 0.0, 0.0))], hexapod.model)


@pytest.mark.parametrize("axis", [(1.0, 1.0, 0.0), (0.0, 0.0, 0.0), (np.nan, 0.0, 0.0)])
def test_non_unit_axis(axis):
    with pytest.raises(ParameterError, match=r"'p': axis .* is not a unit vector"):
        Parameter("p", "body_pos", "leg1_base", axis)


def test_unknown_kind():
    with pytest.raises(ParameterError, match=r"kind 'body_scale' not in"):
        Parameter("p", "body_scale", "leg1_base", (1.0, 0.0, 0.0))


def test_duplicate_names(hexapod):
    dup = [
        Parameter("p", "body_pos", "leg1_base", (1.0, 0.0, 0.0)),
        Parameter("q", "body_pos", "leg1_base", (0.0, 1.0, 0.0)),
        Parameter("p", "body_pos", "leg2_base", (1.0, 0.0, 0.0)),
    ]
    with pytest.raises(ParameterError, match=r"duplicate parameter names: \['p'\]"):
        ParameterSet(dup, hexapod.model)


def test_wrong_length_values(hexapod, hexapod_params):
    with pytest.raises(ParameterError, match=r"expected 54 parameter values, got shape \(53,\)"):
        hexapod_params.inject(hexapod.model, np.zeros(53))


def test_non_finite_values(hexapod, hexapod_params):
    values = np.zeros(54)
    values[hexapod_params.index("leg5.base_offset")] = np.nan
    with pytest.raises(ParameterError, match=r"non-finite parameter values for \['leg5.base_off"):
        hexapod_params.inject(hexapod.model, values)


def test_unknown_parameter_name(hexapod_params):
    with pytest.raises(ParameterError, match=r"unknown parameter 'leg7.length'"):
        hexapod_params.index("leg7.length")


def test_axis_with_wrong_length(hexapod):
    with pytest.raises(ParameterError, match=r"axis"):
        ParameterSet([Parameter("p", "body_pos", "leg1_base", (1.0, 0.0))], hexapod.model)


# ----------------------------------------------------------------------------- files
def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_missing_files(tmp_path, hexapod, hexapod_params):
    with pytest.raises(ParameterError, match=r"parameter file not found: .*nope.toml"):
        load_parameter_set(tmp_path / "nope.toml", hexapod.model)
    with pytest.raises(ParameterError, match=r"parameter file not found: .*nope.toml"):
        load_values(tmp_path / "nope.toml", hexapod_params)


def test_parameter_file_errors(tmp_path, hexapod):
    bad_toml = _write(tmp_path, "a.toml", "[[parameter]\nname = 1\n")
    with pytest.raises(ParameterError, match=r"a.toml is not valid TOML"):
        load_parameter_set(bad_toml, hexapod.model)
    empty = _write(tmp_path, "b.toml", 'model = "hexapod_rrrprr"\n')
    with pytest.raises(ParameterError, match=r"b.toml has no \[\[parameter\]\] entries"):
        load_parameter_set(empty, hexapod.model)
    lacking = _write(tmp_path, "c.toml", '[[parameter]]\nname = "p"\nkind = "body_pos"\n')
    with pytest.raises(ParameterError, match=r"parameter #1 lacks \['element'\]"):
        load_parameter_set(lacking, hexapod.model)
    short_axis = _write(
        tmp_path,
        "d.toml",
        '[[parameter]]\nname = "p"\nkind = "body_pos"\nelement = "leg1_base"\naxis = [1, 0]\n',
    )
    with pytest.raises(ParameterError, match=r"'p' axis must have 3 components"):
        load_parameter_set(short_axis, hexapod.model)
    unknown_body = _write(
        tmp_path,
        "e.toml",
        '[[parameter]]\nname = "p"\nkind = "body_pos"\nelement = "legX"\naxis = [1, 0, 0]\n',
    )
    with pytest.raises(ParameterError, match=r"no body named 'legX'"):
        load_parameter_set(unknown_body, hexapod.model)


def test_values_file_errors(tmp_path, hexapod_params):
    unknown = _write(tmp_path, "u.toml", 'unit = "mm"\n[values]\n"leg7.length" = 0.1\n')
    with pytest.raises(ParameterError, match=r"unknown parameter names \['leg7.length'\]"):
        load_values(unknown, hexapod_params)
    metres = _write(tmp_path, "m.toml", 'unit = "m"\n[values]\n"leg1.length" = 0.1\n')
    with pytest.raises(ParameterError, match=r"unit must be 'mm'.*got 'm'"):
        load_values(metres, hexapod_params)
    no_table = _write(tmp_path, "n.toml", 'unit = "mm"\n')
    with pytest.raises(ParameterError, match=r"has no \[values\] table"):
        load_values(no_table, hexapod_params)
    nan = _write(tmp_path, "x.toml", '[values]\n"leg1.length" = nan\n')
    with pytest.raises(ParameterError, match=r"value of 'leg1.length' is not finite"):
        load_values(nan, hexapod_params)


def test_values_file_converts_mm_to_metres(tmp_path, hexapod_params):
    path = _write(tmp_path, "v.toml", '[values]\n"leg2.base.dy" = 0.571\n')
    values = load_values(path, hexapod_params)
    k = hexapod_params.index("leg2.base.dy")
    assert values[k] == pytest.approx(0.571e-3, abs=1e-18)
    assert np.count_nonzero(values) == 1


def test_non_numeric_value_names_the_parameter(tmp_path, hexapod_params):
    path = _write(tmp_path, "s.toml", '[values]\n"leg1.length" = "abc"\n')
    with pytest.raises(ParameterError, match=r"leg1.length"):
        load_values(path, hexapod_params)


def test_non_numeric_axis_names_the_parameter(tmp_path, hexapod):
    path = _write(
        tmp_path,
        "s.toml",
        '[[parameter]]\nname = "p"\nkind = "body_pos"\nelement = "leg1_base"\naxis = ["x", 0, 0]\n',
    )
    with pytest.raises(ParameterError, match=r"'p'"):
        load_parameter_set(path, hexapod.model)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((5, "body_pos", "leg1_base", (1.0, 0.0, 0.0)), r"parameter name must be a non-empty"),
        (("p", "body_pos", None, (1.0, 0.0, 0.0)), r"'p': element must be a non-empty string"),
        (("p", "body_rott", "leg1_base", (1.0, 0.0, 0.0)), r"did you mean 'body_rot'\?"),
        (("p", "body_pos", "leg1_base", ("1", 0.0, 0.0)), r"'p': axis .* must be 3 numbers"),
        (("p", "body_pos", "leg1_base", (True, 0.0, 0.0)), r"'p': axis .* must be 3 numbers"),
        (("p", "body_pos", "leg1_base", 1.0), r"'p': axis 1.0 must be 3 numbers"),
    ],
)
def test_parameter_fields_of_the_wrong_type(args, match):
    with pytest.raises(ParameterError, match=match):
        Parameter(*args)


def test_numpy_axis_is_accepted():
    assert Parameter("p", "body_pos", "leg1_base", tuple(np.eye(3)[0])).axis == (1.0, 0.0, 0.0)


def test_inject_with_a_reused_scratch_equals_a_fresh_one():
    """mj_setConst's scratch MjData is kept between injections: every array of the injected
    model is bitwise what a fresh MjData gives."""
    nominal = Mechanism.from_xml(HEXAPOD_XML)
    params = load_parameter_set(ROOT / "models/hexapod_rrrprr.params.toml", nominal.model)
    rng = np.random.default_rng(0)

    def arrays(model):
        return {
            k: np.array(getattr(model, k))
            for k in dir(model)
            if not k.startswith("_") and isinstance(getattr(model, k, None), np.ndarray)
        }

    params.inject(nominal.model, rng.uniform(-2e-3, 2e-3, len(params)))  # scratch now used
    values = rng.uniform(-2e-3, 2e-3, len(params))
    reused = arrays(params.inject(nominal.model, values))
    params._local.scratch = None  # a fresh MjData
    fresh = arrays(params.inject(nominal.model, values))
    assert reused.keys() == fresh.keys() and len(fresh) > 100
    for k, v in fresh.items():
        np.testing.assert_array_equal(reused[k], v, err_msg=k)


def test_parameter_set_copies_and_pickles():
    """The per-thread scratch of injection stays behind: copies and pickles inject alike."""
    import copy
    import pickle

    nominal = Mechanism.from_xml(HEXAPOD_XML)
    params = load_parameter_set(ROOT / "models/hexapod_rrrprr.params.toml", nominal.model)
    values = np.random.default_rng(1).uniform(-1e-3, 1e-3, len(params))
    ref = params.inject(nominal.model, values).body_pos.copy()
    for other in (copy.deepcopy(params), pickle.loads(pickle.dumps(params))):
        np.testing.assert_array_equal(other.inject(nominal.model, values).body_pos, ref)


def _inject_one_by_one(params: ParameterSet, nominal: mujoco.MjModel, values: np.ndarray):
    """The reference injection: one parameter after the other, one rotated body after the
    other (what ParameterSet.inject does on whole arrays)."""
    import copy

    model = copy.deepcopy(nominal)
    rotvecs: dict[int, np.ndarray] = {}
    for k in range(len(params)):
        kind, i, v = params.kind[k], params.element[k], values[k]
        if kind == 0:
            model.body_pos[i] += params.axis[k] * v
        elif kind == 1:
            b = int(params.body[k])
            rotvecs[b] = rotvecs.get(b, np.zeros(3)) + params.axis[k] * v
        elif kind == 2:
            model.site_pos[i] += params.axis[k] * v
        else:
            model.qpos0[model.jnt_qposadr[i]] -= v
    for b, w in rotvecs.items():
        model.body_quat[b] = quat_multiply(quat_from_rotvec(w), nominal.body_quat[b])
    mujoco.mj_setConst(model, mujoco.MjData(model))
    return model, rotvecs


@pytest.mark.parametrize("machine", ["hexapod_rrrprr", "polisher", "arm6r"])
def test_inject_on_whole_arrays_equals_one_parameter_after_the_other(machine):
    """Bitwise: several parameters of one body, site or joint add up in parameter order."""
    nominal = Mechanism.from_xml(ROOT / "models" / f"{machine}.xml")
    params = load_parameter_set(ROOT / "models" / f"{machine}.params.toml", nominal.model)
    values = np.random.default_rng(5).uniform(-2e-3, 2e-3, len(params))
    model = params.inject(nominal.model, values)
    ref, rotvecs = _inject_one_by_one(params, nominal.model, values)
    for field in ("body_pos", "body_quat", "site_pos", "qpos0", "body_ipos", "site_quat"):
        np.testing.assert_array_equal(getattr(model, field), getattr(ref, field), err_msg=field)
    got = params.rotation_vectors(values)
    assert got.keys() == rotvecs.keys()
    for b, w in rotvecs.items():
        np.testing.assert_array_equal(got[b], w)
