"""A planned program respects limits, collisions, the floor and the tracker's line of sight:
every pose checked independently of the planner (MuJoCo's signed geom distances for
collisions and the floor, a ray cast against each geom on its own for the line of sight, the
incidence angle from the site frame), and the poses it refused fail the same checks."""

from __future__ import annotations

import csv
import math

import mujoco
import numpy as np
import pytest

from calib.cli.commands import main
from calib.exceptions import IdentifiabilityError
from calib.fit import model_from_files
from calib.plan import Rules, check_poses, make_plan, workspace_candidates
from calib.plan.collisions import CollisionChecker
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism

FLOOR_Z = 0.25  # m: an arm6r floor high enough that some random poses reach below it


def _arm_on_floor(tmp_path) -> str:
    """arm6r with a plane geom at FLOOR_Z in its world (the model's own floor)."""
    text = open("models/arm6r.xml").read()
    floor = f'<geom name="floor" type="plane" size="2 2 0.1" pos="0 0 {FLOOR_Z}"/>'
    path = tmp_path / "arm6r_floor.xml"
    path.write_text(text.replace("<worldbody>", "<worldbody>" + floor, 1))
    return str(path)


def _checker(mech: Mechanism, floor_z=None) -> CollisionChecker:
    home = forward_batch(mech, mech.home_commands[None]).qpos[0]
    return CollisionChecker.of(mech, home, floor_z)


def _smallest_distance(ch: CollisionChecker, qpos: np.ndarray) -> float:
    """The smallest signed distance between geoms of bodies allowed to be apart (MuJoCo's
    narrow phase, pair by pair: not the contact list the planner reads)."""
    m, d = ch.model, ch.data
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    best = math.inf
    for g1 in range(m.ngeom):
        for g2 in range(g1 + 1, m.ngeom):
            pair = tuple(sorted((int(ch.weld[g1]), int(ch.weld[g2]))))
            planes = mujoco.mjtGeom.mjGEOM_PLANE in (m.geom_type[g1], m.geom_type[g2])
            if planes or pair[0] == pair[1] or pair in ch.allowed:
                continue
            best = min(best, mujoco.mj_geomDistance(m, d, g1, g2, 1.0, None))
    return best


def _floor_distance(ch: CollisionChecker, qpos: np.ndarray) -> float:
    """Signed distance of the moving geoms to the model's plane (MuJoCo's narrow phase)."""
    m, d = ch.model, ch.data
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    plane = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    moving = np.flatnonzero(ch.weld != 0)
    return min(mujoco.mj_geomDistance(m, d, plane, int(g), 10.0, None) for g in moving)


def test_lowest_point_of_each_geom_is_its_distance_to_a_floor_plane(tmp_path):
    mech = Mechanism.from_xml(_arm_on_floor(tmp_path))
    ch = _checker(mech)
    assert ch.floor_z == pytest.approx(FLOOR_Z)  # the model's plane is its floor
    m, d = ch.model, ch.data
    plane = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    rng = np.random.default_rng(3)
    lo, hi = mech.actuator_range.T
    q = forward_batch(mech, rng.uniform(lo, hi, size=(20, 6))).qpos
    from calib.plan.collisions import _geom_bottom

    for qpos in q:
        d.qpos[:] = qpos
        mujoco.mj_kinematics(m, d)
        for g in np.flatnonzero(ch.weld != 0):  # capsules: exact (analytic lowest point)
            dist = mujoco.mj_geomDistance(m, d, plane, int(g), 10.0, None)
            assert _geom_bottom(m, d, int(g)) - FLOOR_Z == pytest.approx(dist, abs=1e-9)


def test_arm_program_keeps_limits_links_apart_and_above_the_floor(tmp_path, capsys):
    xml = _arm_on_floor(tmp_path)
    out = tmp_path / "program.csv"
    args = ["plan", "--model", xml, "--errors", "models/arm6r.params.toml", "--n", "30"]
    args += ["--n-test", "10", "--n-candidates", "600", "--margin", "0.05", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert f"floor: z = {FLOOR_Z * 1e3:.1f} mm" in printed
    mech = Mechanism.from_xml(xml)
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 40 and sum(r["set"] == "test" for r in rows) == 10
    cmds = np.radians([[float(r[f"cmd:A{k}"]) for k in range(1, 7)] for r in rows])
    lo, hi = mech.actuator_range.T
    pad = 0.05 * (hi - lo)
    assert np.all((cmds >= lo + pad) & (cmds <= hi - pad))
    ch = _checker(mech)
    for qpos in forward_batch(mech, cmds).qpos:
        assert _smallest_distance(ch, qpos) >= 0.0
        assert _floor_distance(ch, qpos) >= 0.0
    # the poses refused for a collision or the floor do collide (both directions of the check)
    cands = workspace_candidates(mech, 600, np.random.default_rng(0))
    feas = check_poses(mech, cands.commands, Rules(margin=0.05))
    refused = [k for k, r in enumerate(feas.reasons) if r and r.startswith("collision")]
    assert len(refused) > 20  # the floor at 250 mm cuts the reach: many refusals to check
    for k in refused:
        q = feas.qpos[k]
        assert min(_smallest_distance(ch, q), _floor_distance(ch, q)) < 0.0


def _ray_hit(m, d, tracker, site) -> int | None:
    """The body of the nearest geom between the tracker and the site, by a ray cast against
    each geom alone (mju_rayGeom), geoms of the site's own body aside."""
    target = d.site_xpos[site]
    vec = target - tracker
    best, body = 1.0 - 1e-9, None
    for g in range(m.ngeom):
        if m.geom_bodyid[g] == m.site_bodyid[site] or m.geom_rgba[g][3] == 0:
            continue
        x = mujoco.mju_rayGeom(
            d.geom_xpos[g], d.geom_xmat[g], m.geom_size[g], tracker, vec, int(m.geom_type[g])
        )
        if 0 <= x < best:
            best, body = x, int(m.geom_bodyid[g])
    return body


def _seen(mech, ch, qpos, tracker, acceptance) -> bool:
    m, d = ch.model, ch.data
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    for site in mech.target_sites:
        normal = d.site_xmat[site].reshape(3, 3)[:, 2]
        to = tracker - d.site_xpos[site]
        angle = math.degrees(math.acos(np.clip(normal @ to / np.linalg.norm(to), -1, 1)))
        if _ray_hit(m, d, tracker, int(site)) is not None or angle > acceptance:
            return False
    return True


def test_polisher_program_sees_every_reflector_and_refused_poses_do_not():
    model = model_from_files("models/polisher.xml", "models/polisher.params.toml")
    mech = model.nominal
    tracker = np.array([0.0, 0.0, 2.5])  # above the head: the limbs hide some reflectors
    rules = Rules(tracker_m=tracker, acceptance_deg=30.0)
    cands = workspace_candidates(mech, 300, np.random.default_rng(0))
    plan = make_plan(model, cands, rules, 25, 8)
    ch = _checker(mech)
    qpos = forward_batch(mech, plan.commands).qpos
    assert all(_seen(mech, ch, q, tracker, 30.0) for q in qpos)
    hidden = [k for k, r in enumerate(plan.feasibility.reasons) if r and "visibility" in r]
    assert len(hidden) > 10  # measured: 41 of 300
    for k in hidden:
        assert not _seen(mech, ch, plan.feasibility.qpos[k], tracker, 30.0)
    # a tracker under the worktable sees nothing: the plan says so
    low = Rules(tracker_m=np.array([0.0, 0.0, -1.0]), acceptance_deg=30.0)
    with pytest.raises(IdentifiabilityError, match="0 of 300 candidate poses feasible"):
        make_plan(model, cands, low, 25, 8)


def test_floor_option_refuses_what_the_models_own_floor_refuses(tmp_path):
    plain = Mechanism.from_xml("models/arm6r.xml")
    floored = Mechanism.from_xml(_arm_on_floor(tmp_path))
    cands = workspace_candidates(plain, 300, np.random.default_rng(1))
    by_option = check_poses(plain, cands.commands, Rules(floor_z_m=FLOOR_Z))
    by_plane = check_poses(floored, cands.commands, Rules())
    assert by_option.floor_z_m == by_plane.floor_z_m == pytest.approx(FLOOR_Z)
    assert np.array_equal(by_option.ok, by_plane.ok)
    assert any(r and "below the floor" in r for r in by_option.reasons)
    no_floor = check_poses(plain, cands.commands, Rules())
    assert no_floor.ok.sum() > by_option.ok.sum()
