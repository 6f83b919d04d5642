"""The DH table of a model generated from one (``twin.formats.dh_table``), read back from its
bodies.

A model built by ``twin.formats.dh_mjcf`` keeps one DH row in two bodies per link (``link{i}_dh``
and ``link{i}``), so the table can be read back from any compiled model of it, in particular
from one with identified errors injected: that is the calibrated DH table a controller takes.
``dh_table_of`` checks that each body still has the DH form (a rotation about x or z only,
an offset along x or z only); an error model that moves a body in another direction (the
complete error model of ``twin.formats.error_model``, say) leaves a geometry no DH row can hold,
and the error names the body and the direction. ``format_dh_table`` writes the table in the
CSV format ``twin.formats.dh_table`` reads, every digit kept, so that the round trip is exact.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from twin.formats.dh import DHJoint, DHSite, DHTable, DHTableError
from twin.rotations import matrix_from_quat, rpy_from_matrix

TOL = 1e-12  # metres / quaternion components: what the DH form allows off its axes


class DHStructureError(DHTableError):
    """A model that is not, or no longer, of a DH table's form (the message says where)."""


def _body(model: mujoco.MjModel, name: str) -> int | None:
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    return None if i < 0 else int(i)


def _angle_about(model: mujoco.MjModel, b: int, axis: int, what: str) -> float:
    """The angle of body ``b``'s rotation, which must be about its parent's ``axis``."""
    q = np.array(model.body_quat[b], dtype=float)
    others = [k for k in (1, 2, 3) if k != axis + 1]
    off = max(abs(q[k]) for k in others)
    if off > TOL:
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
        raise DHStructureError(
            f"body '{name}' is turned about more than its {'xyz'[axis]} axis (by "
            f"{math.degrees(2 * math.asin(min(1.0, off))):.3g} deg or more): {what}"
        )
    return 2.0 * math.atan2(q[axis + 1], q[0])


def _offset_along(model: mujoco.MjModel, b: int, axes: tuple[int, ...], what: str) -> np.ndarray:
    """The body's offset, which must lie along its parent's ``axes`` only."""
    p = np.array(model.body_pos[b], dtype=float)
    for k in range(3):
        if k not in axes and abs(p[k]) > TOL:
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
            raise DHStructureError(
                f"body '{name}' is offset along {'xyz'[k]} by {p[k] * 1e3:.6g} mm: {what}"
            )
    return p


def _convention(model: mujoco.MjModel) -> str:
    base, dh1, link1 = (_body(model, n) for n in ("base", "link1_dh", "link1"))
    if base is None or dh1 is None or link1 is None:
        raise DHStructureError(
            "the model was not generated from a DH table (pkm-calib from-dh): it has no "
            "bodies 'base', 'link1_dh' and 'link1'"
        )
    if model.body_parentid[link1] == dh1 and model.body_parentid[dh1] == base:
        return "modified"
    if model.body_parentid[dh1] == link1 and model.body_parentid[link1] == base:
        return "standard"
    raise DHStructureError("bodies 'link1' and 'link1_dh' are not nested as a DH table's are")


def _joint_of(model: mujoco.MjModel, b: int, name: str):
    joints = [j for j in range(model.njnt) if model.jnt_bodyid[j] == b]
    if len(joints) != 1:
        raise DHStructureError(f"body '{name}' must hold exactly one joint, has {len(joints)}")
    j = joints[0]
    if not np.allclose(model.jnt_axis[j], [0, 0, 1], atol=TOL) or np.any(
        np.abs(model.jnt_pos[j]) > TOL
    ):
        raise DHStructureError(f"the joint of body '{name}' is not along its z axis at its origin")
    return j


def _site(model: mujoco.MjModel, s: int, flange: int) -> DHSite:
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s)
    if model.site_bodyid[s] != flange:
        raise DHStructureError(f"site '{name}' is not on the flange body")
    rpy = rpy_from_matrix(matrix_from_quat(model.site_quat[s]))
    return DHSite(name, tuple(model.site_pos[s].tolist()), tuple(rpy.tolist()))  # type: ignore[arg-type]


def dh_table_of(model: mujoco.MjModel, source: str = "<model>") -> DHTable:
    """The DH table whose MJCF (``twin.formats.dh_mjcf``) ``model`` is; raises DHStructureError
    naming the body when ``model`` does not have that form."""
    convention = _convention(model)
    modified = convention == "modified"
    joints, i = [], 1
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    why = "a DH row cannot hold it (the exported MJCF does)"
    while _body(model, f"link{i}") is not None:
        link, dh = _body(model, f"link{i}"), _body(model, f"link{i}_dh")
        if dh is None:
            raise DHStructureError(f"body 'link{i}' has no 'link{i}_dh' beside it")
        alpha = _angle_about(model, dh, 0, why)
        theta_body = _angle_about(model, link, 2, why)
        if modified:
            a = float(_offset_along(model, dh, (0,), why)[0])
            d_body = float(_offset_along(model, link, (2,), why)[2])
        else:
            _offset_along(model, link, (), why)
            a, _, d_body = _offset_along(model, dh, (0, 2), why).tolist()
        j = _joint_of(model, link, f"link{i}")
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        adr = model.jnt_qposadr[j]
        zero = float(model.qpos0[adr])  # the joint's zero: the physical value is q - zero
        revolute = int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE)
        theta, d = (theta_body - zero, d_body) if revolute else (theta_body, d_body - zero)
        if not model.jnt_limited[j]:
            raise DHStructureError(f"joint '{name}' has no range: a DH table needs one")
        lo, hi = model.jnt_range[j]
        home = float(model.key_qpos[key, adr]) if key >= 0 else 0.0
        kind = "R" if revolute else "P"
        joints.append(DHJoint(name, kind, alpha, a, d, theta, float(lo), float(hi), home))
        i += 1
    n = len(joints)
    flange = _body(model, f"link{n}" if modified else f"link{n}_dh")
    sites = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s): s for s in range(model.nsite)}
    if "tool" not in sites:
        raise DHStructureError("the model has no 'tool' site")
    targets = tuple(
        _site(model, s, flange) for name, s in sites.items() if name.startswith("target_")
    )
    base = _body(model, "base")
    base_rpy = rpy_from_matrix(matrix_from_quat(model.body_quat[base]))
    return DHTable(
        convention,
        tuple(joints),
        _site(model, sites["tool"], flange),
        tuple(DHSite(t.name, t.pos) for t in targets),
        DHSite("base", tuple(model.body_pos[base].tolist()), tuple(base_rpy.tolist())),  # type: ignore[arg-type]
        source,
    )


def _num(x: float) -> str:
    x = 0.0 if abs(x) < 1e-15 else float(x)
    return repr(x) if x else "0"


def _limit(x: float) -> str:
    """A joint limit or home to 1e-9 (deg or mm): the MJCF stores a range in radians with the
    digits it was written with, and +-360 deg came back as 360.0000000000237; a limit is no
    kinematics, and the geometry keeps every digit."""
    return _num(round(float(x), 9))


def format_dh_table(table: DHTable, comments: tuple[str, ...] = ()) -> str:
    """The CSV text of ``table`` in ``twin.formats.dh_table``'s format (mm, deg; every digit)."""
    deg, mm = math.degrees, (lambda v: v * 1e3)
    lines = [f"# {c}" for c in comments]
    lines.append(f"# convention: {table.convention}")
    lines.append(
        "joint,alpha_deg,a_mm,d_mm,theta_deg,min_deg,max_deg,type,home_deg,min_mm,max_mm,home_mm"
    )
    for j in table.joints:
        geometry = [_num(deg(j.alpha)), _num(mm(j.a)), _num(mm(j.d)), _num(deg(j.theta))]
        if j.type == "R":
            limits = [_limit(deg(j.lower)), _limit(deg(j.upper)), "R", _limit(deg(j.home))]
            limits += ["", "", ""]
        else:
            limits = ["", "", "P", "", _limit(mm(j.lower)), _limit(mm(j.upper)), _limit(mm(j.home))]
        lines.append(",".join([j.name, *geometry, *limits]))
    lines.append("site,x_mm,y_mm,z_mm,rx_deg,ry_deg,rz_deg")
    for s in (table.base, table.tool):
        if s.name == "base" and not (any(s.pos) or any(s.rpy)):
            continue
        cells = [_num(mm(v)) for v in s.pos] + [_num(deg(v)) for v in s.rpy]
        lines.append(",".join([s.name, *cells]))
    for t in table.targets:
        lines.append(",".join([t.name, *(_num(mm(v)) for v in t.pos), "", "", ""]))
    return "\n".join(lines) + "\n"
