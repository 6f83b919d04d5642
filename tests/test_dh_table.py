"""DH tables to MJCF: the generated model is the textbook product of DH matrices, and each
error-model entry is exactly its DH parameter.

The reference kinematics here is written from the textbook formulas (Craig's eq. 3.6 for the
modified convention, the classic DH matrix for the standard one), not from twin.formats.dh_mjcf. The
random tables are written with every digit (``number=exact``): the files' 12 significant
digits quantise a generic quaternion by up to 5e-13, which is checked separately.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest
from test_generated_models import toml_differences, xml_differences

from twin.formats.dh_mjcf import build_parameters, build_xml, exact
from twin.formats.dh_table import DHSite, DHTable, DHTableError, main, parse_dh_table, read_dh_table
from twin.formats.parameter_file import load_parameter_set
from twin.mechanism import Mechanism
from twin.rotations import matrix_from_rotvec, rpy_from_matrix

ROOT = Path(__file__).resolve().parent.parent
TABLE = ROOT / "models" / "arm6r.mdh.csv"
TOL = 1e-12


# ----------------------------------------------------------------- textbook kinematics
def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _frame(rot: np.ndarray, pos) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = rot, pos
    return t


def dh_standard(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


def dh_modified(alpha: float, a: float, theta: float, d: float) -> np.ndarray:
    """Craig (3.6): Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st, 0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0, 0, 0, 1],
        ]
    )


def site_frame(s: DHSite) -> np.ndarray:
    return _frame(_rz(s.rpy[2]) @ _ry(s.rpy[1]) @ _rx(s.rpy[0]), s.pos)


def flange_pose(table: DHTable, q: np.ndarray) -> np.ndarray:
    t = site_frame(table.base)
    for j, qi in zip(table.joints, q, strict=True):
        theta = j.theta + (qi if j.type == "R" else 0.0)
        d = j.d + (qi if j.type == "P" else 0.0)
        if table.convention == "modified":
            t = t @ dh_modified(j.alpha, j.a, theta, d)
        else:
            t = t @ dh_standard(theta, d, j.a, j.alpha)
    return t


# ----------------------------------------------------------------- helpers
def compile_xml(xml: str) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_string(xml)
    spec.compiler.boundmass = 1e-3
    spec.compiler.boundinertia = 1e-6
    return spec.compile()


def site_poses(model: mujoco.MjModel, q: np.ndarray, names: list[str]) -> list[np.ndarray]:
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    out = []
    for n in names:
        i = model.site(n).id
        out.append(_frame(data.site_xmat[i].reshape(3, 3), data.site_xpos[i]))
    return out


def pose_error(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Position (m) and rotation angle (rad, accurate near 0) between two frames."""
    r = a[:3, :3].T @ b[:3, :3]
    sin = 0.5 * np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    angle = np.arctan2(sin, (np.trace(r) - 1) / 2)
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])), float(angle)


def random_table_csv(convention: str, rng: np.random.Generator, types: str = "RRRRRR") -> str:
    lines = [
        f"# convention: {convention}",
        "joint,type,alpha_deg,a_mm,d_mm,theta_deg,min_deg,max_deg,min_mm,max_mm",
    ]
    for k, t in enumerate(types, start=1):
        al, th = (float(x) for x in rng.uniform(-180, 180, 2))
        a, d = (float(x) for x in rng.uniform(-300, 500, 2))
        lim = "-170,170,," if t == "R" else ",,-200,300"
        lines.append(f"J{k},{t},{al!r},{a!r},{d!r},{th!r},{lim}")
    rx, ry, rz = (float(x) for x in rng.uniform(-180, 180, 3))
    tx, ty = (float(x) for x in rng.uniform(-50, 50, 2))
    lines += [
        "site,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg",
        f"tool,{tx!r},{ty!r},130,{rx!r},{ry!r},{rz!r}",
        "target_1,40,-20,110",
        "target_2,-30,35,100",
        "base,100,-50,250,5,-10,30",
    ]
    return "\n".join(lines) + "\n"


def random_q(table: DHTable, rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(j.lower, j.upper) for j in table.joints])


# ----------------------------------------------------------------- kinematics
@pytest.mark.parametrize("types", ["RRRRRR", "RPRRPR", "PRR"])
@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_model_equals_textbook_product_of_dh_matrices(convention, types):
    """Tool site pose from mj_kinematics = base * prod T_i * tool, to 1e-12 m and rad."""
    rng = np.random.default_rng(11 + len(types))
    table = parse_dh_table(random_table_csv(convention, rng, types))
    model = compile_xml(build_xml(table, "arm", number=exact))
    tool = site_frame(table.tool)
    worst = [0.0, 0.0]
    for _ in range(20):
        q = random_q(table, rng)
        flange = flange_pose(table, q)
        got = site_poses(model, q, ["tool", "target_1", "target_2"])
        dp, dr = pose_error(got[0], flange @ tool)
        worst = [max(worst[0], dp), max(worst[1], dr)]
        for t, g in zip(table.targets, got[1:], strict=True):
            assert np.linalg.norm(g[:3, 3] - (flange @ site_frame(t))[:3, 3]) < TOL
    assert worst[0] < TOL and worst[1] < TOL, worst


def test_twelve_digit_files_quantise_below_1e_10():
    """The files' 12 significant digits move a generic arm's tool by far less than 1e-10."""
    rng = np.random.default_rng(5)
    table = parse_dh_table(random_table_csv("modified", rng))
    model = compile_xml(build_xml(table, "arm"))
    for _ in range(10):
        q = random_q(table, rng)
        dp, dr = pose_error(
            site_poses(model, q, ["tool"])[0], flange_pose(table, q) @ site_frame(table.tool)
        )
        assert dp < 1e-10 and dr < 1e-10


# ----------------------------------------------------------------- error model
def _perturbed(table: DHTable, name: str, v: float) -> DHTable:
    """The table with parameter ``name`` changed by ``v`` (SI), written the table's way."""
    owner, what = name.split(".")
    if owner.startswith("link"):
        i = int(owner[4:]) - 1
        j = table.joints[i]
        joints = list(table.joints)
        joints[i] = dataclasses.replace(j, **{what: getattr(j, what) + v})
        return dataclasses.replace(table, joints=tuple(joints))
    if owner.startswith("target_"):
        axis = "xyz".index(what[1])
        targets = []
        for t in table.targets:
            pos = list(t.pos)
            if t.name == owner:
                pos[axis] += v
            targets.append(dataclasses.replace(t, pos=tuple(pos)))
        return dataclasses.replace(table, targets=tuple(targets))
    b = table.base
    if what[0] == "d":
        pos = list(b.pos)
        pos["xyz".index(what[1])] += v
        return dataclasses.replace(table, base=dataclasses.replace(b, pos=tuple(pos)))
    w = np.zeros(3)
    w["xyz".index(what[1])] = v  # body_rot: about the world (parent) axis
    rpy = rpy_from_matrix(matrix_from_rotvec(w) @ site_frame(b)[:3, :3])
    return dataclasses.replace(table, base=dataclasses.replace(b, rpy=tuple(rpy)))


@pytest.mark.parametrize("types", ["RRRRRR", "RPRRPR"])
@pytest.mark.parametrize("convention", ["modified", "standard"])
def test_each_error_entry_is_its_dh_parameter(tmp_path, convention, types):
    """Changing a DH value in the table and regenerating = injecting it on the nominal model."""
    rng = np.random.default_rng(7)
    table = parse_dh_table(random_table_csv(convention, rng, types))
    nominal = compile_xml(build_xml(table, "arm", number=exact))
    path = tmp_path / "arm.params.toml"
    path.write_text(build_parameters(table, "arm", base_errors=True))
    params = load_parameter_set(path, nominal)
    assert len(params) == 6 + 4 * len(types) + 3 * len(table.targets)
    sites = ["tool", "target_1", "target_2"]
    qs = [random_q(table, rng) for _ in range(3)]
    for k, name in enumerate(params.names):
        v = 1e-3 * (1 + k % 5) * (-1) ** k  # mm-sized and mrad-sized, all different
        values = np.zeros(len(params))
        values[k] = v
        injected = params.inject(nominal, values)
        regenerated = compile_xml(build_xml(_perturbed(table, name, v), "arm", number=exact))
        moved = 0.0
        for q in qs:
            before = site_poses(nominal, q, sites)
            for a, b, c in zip(
                site_poses(injected, q, sites),
                site_poses(regenerated, q, sites),
                before,
                strict=True,
            ):
                dp, dr = pose_error(a, b)
                assert dp < TOL and dr < TOL, (name, dp, dr)
                moved = max(moved, *pose_error(a, c))
        assert moved > 1e-5, f"{name} moves nothing"  # the check is not vacuous


def test_all_errors_at_once(tmp_path):
    rng = np.random.default_rng(3)
    table = parse_dh_table(random_table_csv("modified", rng))
    nominal = compile_xml(build_xml(table, "arm", number=exact))
    path = tmp_path / "arm.params.toml"
    path.write_text(build_parameters(table, "arm", base_errors=True))
    params = load_parameter_set(path, nominal)
    values = rng.uniform(-2e-3, 2e-3, len(params))
    perturbed = table
    for name, v in zip(params.names, values, strict=True):
        if not name.startswith("base.r"):
            perturbed = _perturbed(perturbed, name, v)
    w = values[[params.index(f"base.r{c}") for c in "xyz"]]  # one rotation vector
    rot = matrix_from_rotvec(w) @ site_frame(table.base)[:3, :3]
    perturbed = dataclasses.replace(
        perturbed, base=dataclasses.replace(perturbed.base, rpy=tuple(rpy_from_matrix(rot)))
    )
    injected = params.inject(nominal, values)
    regenerated = compile_xml(build_xml(perturbed, "arm", number=exact))
    for _ in range(5):
        q = random_q(table, rng)
        for a, b in zip(
            site_poses(injected, q, ["tool", "target_1"]),
            site_poses(regenerated, q, ["tool", "target_1"]),
            strict=True,
        ):
            assert max(pose_error(a, b)) < TOL


# ----------------------------------------------------------------- the committed arm
def _arm6r() -> DHTable:
    return read_dh_table(TABLE).with_targets(["target_1"])


def test_committed_arm6r_equals_regeneration():
    table = _arm6r()
    xml = (ROOT / "models" / "arm6r.xml").read_text()
    assert xml_differences(xml, build_xml(table, "arm6r")) == []
    toml = (ROOT / "models" / "arm6r.params.toml").read_text()
    # generated before the base's placement was in the default error model
    assert toml_differences(toml, build_parameters(table, "arm6r", base_errors=False)) == []
    assert xml_differences(xml, xml.replace('pos="0 0 0.43"', 'pos="0 0 0.430001"'))


def test_committed_three_reflector_arm_equals_regeneration():
    table = read_dh_table(TABLE)
    xml = (ROOT / "models" / "arm6r_3targets.xml").read_text()
    assert xml_differences(xml, build_xml(table, "arm6r_3targets")) == []
    toml = (ROOT / "models" / "arm6r_3targets.params.toml").read_text()
    assert (
        toml_differences(toml, build_parameters(table, "arm6r_3targets", base_errors=False)) == []
    )


def test_committed_arm6r_kinematics_and_home():
    """The 12-digit file is exact here (angles of 0, 90, 180 deg); home is not singular."""
    table = _arm6r()
    model = compile_xml((ROOT / "models" / "arm6r.xml").read_text())
    rng = np.random.default_rng(1)
    for q in [np.zeros(6), model.key_qpos[0], *(random_q(table, rng) for _ in range(20))]:
        got = site_poses(model, q, ["tool"])[0]
        assert max(pose_error(got, flange_pose(table, q) @ site_frame(table.tool))) < TOL
    home = model.key_qpos[0]
    np.testing.assert_allclose(np.degrees(home), [0, 10, 20, 0, 45, 0], atol=1e-9)
    data = mujoco.MjData(model)
    data.qpos[:] = home
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    jp, jr = np.zeros((3, 6)), np.zeros((3, 6))
    mujoco.mj_jacSite(model, data, jp, jr, model.site("tool").id)
    sv = np.linalg.svd(np.vstack([jp, jr]), compute_uv=False)
    assert sv[-1] > 0.2, sv  # well away from a singularity
    # reach about 1 m: arm stretched forward (upper arm and forearm in line)
    stretched = np.radians([0, 90, np.degrees(np.arctan2(40, 430)) - 90, 0, 0, 0])
    flange = flange_pose(table, stretched)
    wrist = flange[:3, 3] - 0.08 * flange[:3, 2]
    np.testing.assert_allclose(wrist, [0.03 + 0.45 + np.hypot(0.04, 0.43), 0, 0.4], atol=1e-12)
    assert 0.95 < np.hypot(flange[0, 3], flange[1, 3]) < 1.05


def test_committed_arm6r_has_no_mass_and_is_a_mechanism():
    path = ROOT / "models" / "arm6r.xml"
    root = ET.fromstring(path.read_text())
    assert not list(root.iter("inertial"))
    assert all(g.get("density") in (None, "0") for g in root.iter("geom"))
    with pytest.raises(ValueError, match="mass and inertia"):
        mujoco.MjModel.from_xml_path(str(path))  # nothing invented: no mass anywhere
    model = compile_xml(path.read_text())
    np.testing.assert_allclose(model.body_mass[1:], 1e-3)  # boundmass, nothing else
    quats = [np.array(e.get("quat").split(), dtype=float) for e in root.iter() if e.get("quat")]
    for q in quats:
        assert q[np.flatnonzero(q)[0]] > 0 and np.all((q == 0) | (np.abs(q) >= 1e-12))
    mech = Mechanism.from_xml(path)
    assert mech.actuator_names == ("A1", "A2", "A3", "A4", "A5", "A6")
    assert mech.target_names == ("target_1",)
    assert mech.n_closure == 0
    np.testing.assert_allclose(mech.target_local(), [[0.05, 0, -0.01]], atol=1e-15)


def test_three_reflector_variant(tmp_path):
    assert main([str(TABLE), "--name", "arm6r_3targets", "--out-dir", str(tmp_path)]) == 0
    mech = Mechanism.from_xml(tmp_path / "arm6r_3targets.xml")
    assert mech.target_names == ("target_1", "target_2", "target_3")
    params = load_parameter_set(tmp_path / "arm6r_3targets.params.toml", mech.model)
    # the base's placement (6, by default), 4 DH errors x 6 rows, 3 reflectors x 3 offsets
    assert len(params) == 6 + 24 + 9 and params.names[-1] == "target_3.dz"
    local = mech.target_local()
    np.testing.assert_allclose(np.linalg.norm(local[:, :2], axis=1), 0.05, atol=1e-8)


def test_command_line_writes_what_the_functions_build(tmp_path):
    cmd = [sys.executable, "-m", "twin.formats.dh_table", str(TABLE), "--name", "arm6r"]
    cmd += ["--out-dir", str(tmp_path), "--targets", "target_1"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    table = _arm6r()
    assert (tmp_path / "arm6r.xml").read_text() == build_xml(table, "arm6r")
    assert (tmp_path / "arm6r.params.toml").read_text() == build_parameters(table, "arm6r")
    assert (tmp_path / "arm6r.xml").stat().st_mode & 0o777 != 0o600  # not mkstemp's mode
    # the files there are a user's: replaced only with --force, untouched without
    before = (tmp_path / "arm6r.xml").read_bytes()
    assert subprocess.run(cmd, cwd=ROOT, capture_output=True, timeout=60).returncode == 2
    assert (tmp_path / "arm6r.xml").read_bytes() == before
    args = [str(TABLE), "--name", "x", "--out-dir", str(tmp_path), "--no-target-errors"]
    args.append("--force")
    for flags, n_base in (([], 6), (["--base-errors"], 6), (["--no-base-errors"], 0)):
        assert main([*args, *flags]) == 0
        text = (tmp_path / "x.params.toml").read_text()
        names = [e for e in text.split("\n") if "name =" in e]
        assert len(names) == n_base + 24  # 4 DH errors x 6 rows, no reflector offsets
        assert ("base.rz" in names[5]) == (n_base == 6)


# ----------------------------------------------------------------- bad input
GOOD = """# convention: modified
joint,alpha_deg,a_mm,d_mm,theta_deg,min_deg,max_deg
A1,0,0,400,0,-170,170
A2,-90,30,0,-90,-90,150
site,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg
tool,0,0,120
target_1,50,0,110
"""


@pytest.mark.parametrize(
    "old, new, expected",
    [
        ("modified", "modifed", ["line 1", "unknown convention 'modifed'", "'modified'"]),
        ("# convention: modified\n", "", ["line 1", "no '# convention"]),
        ("A2,-90,30,0", "A2,-90,3O,0", ["line 4", "column 'a_mm'", "'3O' is not a number"]),
        ("A2,-90,30,0,-90", "A2,-90,30,nan,-90", ["line 4", "column 'd_mm'", "not a finite"]),
        ("a_mm,d_mm,", "a_mm,", ["line 2", "missing column(s) ['d_mm']"]),
        ("theta_deg,", "theta,", ["line 2", "unknown column 'theta'", "'theta_deg'"]),
        ("-90,150", "150,150", ["line 4", "column 'max_deg'", "must be below max"]),
        ("A2,-90", "A1,-90", ["line 4", "column 'joint'", "duplicate joint name 'A1'"]),
        ("A2,-90,30,0,-90,-90,150", "A2,-90,30,0,-90,-90,150,7", ["line 4", "8 cells"]),
        ("A2,-90,30,0,-90,-90,150", "A2,-90,30,0,-90,,150", ["line 4", "'min_deg'", "empty"]),
        ("target_1,50,0,110", "target_1,50,0,110,0,5", ["line 7", "'ry_deg'", "a point"]),
        ("target_1,50", "reflector,50", ["line 7", "unknown site 'reflector'"]),
        ("tool,0,0,120\n", "", ["no 'tool' row"]),
        ("target_1,50,0,110\n", "", ["no reflector row"]),
        ("tool,0,0,120\n", "tool,0,0,120\ntool,0,0,1\n", ["line 7", "duplicate site 'tool'"]),
        ("A1,0", "# convention: standard\nA1,0", ["line 3", "before the joint header"]),
        (GOOD.splitlines()[1] + "\n", "", ["line 2", "expected the joint header"]),
    ],
)
def test_bad_tables_name_file_line_and_column(tmp_path, old, new, expected):
    text = GOOD.replace(old, new, 1)
    assert text != GOOD
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(DHTableError) as info:
        read_dh_table(path)
    assert isinstance(info.value, ValueError)
    message = str(info.value)
    assert message.startswith(str(path))
    for part in expected:
        assert part in message, message


def test_prismatic_rows_and_defaults():
    text = GOOD.replace(
        "min_deg,max_deg\n", "min_deg,max_deg,type,min_mm,max_mm,home_mm\n"
    ).replace("A2,-90,30,0,-90,-90,150", "A2,-90,30,0,-90,,,P,-100,250,50")
    table = parse_dh_table(text)
    a1, a2 = table.joints
    assert (a1.type, a1.home, a1.alpha) == ("R", 0.0, 0.0)
    assert a1.upper == pytest.approx(np.radians(170), abs=1e-15)
    assert (a2.type, a2.lower, a2.upper, a2.home) == ("P", -0.1, 0.25, 0.05)
    bad = text.replace("A2,-90,30,0,-90,,,P", "A2,-90,30,0,-90,-90,,P")
    with pytest.raises(DHTableError, match=r"line 4, column 'min_deg'.*min_mm"):
        parse_dh_table(bad)
    with pytest.raises(DHTableError, match="home lies outside"):
        parse_dh_table(text.replace(",250,50", ",250,300"))
    with pytest.raises(DHTableError, match="no reflector 'target_9'"):
        table.with_targets(["target_9"])


def test_command_line_reports_a_bad_table(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text(GOOD.replace("modified", "craig"))
    assert main([str(path), "--name", "x", "--out-dir", str(tmp_path)]) == 2
    assert "unknown convention 'craig'" in capsys.readouterr().err
    assert not (tmp_path / "x.xml").exists()
