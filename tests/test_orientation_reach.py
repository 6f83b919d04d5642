"""Orientation per position reach of source errors: analytic levers on the polisher's wrist."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.analysis.orientation import deg_per_mm, orientation_reach
from twin.formats.parameter_file import load_parameter_set
from twin.kinematics.sensitivity import tool_twist_jacobian
from twin.kinematics.single_pose import inverse
from twin.mechanism import Mechanism
from twin.parameters import KINDS

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def reach_at_reference():
    mech = Mechanism.from_xml(ROOT / "models/polisher.xml")
    params = load_parameter_set(ROOT / "models/polisher.params.toml", mech.model)
    values = np.zeros(len(params))
    qpos = inverse(mech, np.zeros(6)).qpos  # the reference pose: P at the workspace centre
    twists = tool_twist_jacobian(mech, params, values, qpos)[None]
    joint = params.kind == KINDS.index("joint_zero")
    return orientation_reach(twists, list(params.names), joint)


def row(reach, name):
    (r,) = [r for r in reach.rows if r.name == name]
    return r


def test_wrist_levers_from_table1(reach_at_reference):
    """At the reference pose z6,4 is along x and z5,4 along y through A6,4, and P sits at
    (120, 0, -655) mm from A6,4 (Table 1: 405 + 250 down, 120 across): a turn about z6,4 moves
    P on a 655 mm lever, one about z5,4 on sqrt(120^2 + 655^2) mm."""
    j6 = row(reach_at_reference, "limb4.j6.encoder")
    j5 = row(reach_at_reference, "limb4.j5.encoder")
    assert j6.joint_motion and j5.joint_motion
    assert j6.median_deg_per_mm == pytest.approx(np.degrees(1 / 655.0), rel=1e-9)
    assert j5.median_deg_per_mm == pytest.approx(np.degrees(1 / np.hypot(120.0, 655.0)), rel=1e-9)


def test_largest_first_and_actuated_prismatic_far_smaller(reach_at_reference):
    medians = [r.median_deg_per_mm for r in reach_at_reference.rows]
    assert medians == sorted(medians, reverse=True)
    big = reach_at_reference.largest(joint_motion_only=True)
    # a UPS limb's length turns the platform about the base, metres from P
    assert (
        row(reach_at_reference, "limb1.j3.encoder").median_deg_per_mm < 0.2 * big.median_deg_per_mm
    )
    d = reach_at_reference.as_dict()
    assert d["largest_joint_motion"] == big.name
    assert set(d["joint_motions"]) == {r.name for r in reach_at_reference.rows if r.joint_motion}


def test_pure_rotation_lever_and_bad_shape():
    # a turn of 1 rad about an axis 0.5 m from the tool point moves it 0.5 m: 2 rad per metre
    twist = np.array([0.5, 0.0, 0.0, 0.0, 0.0, 1.0]).reshape(1, 6, 1)
    reach = orientation_reach(twist, ["a"], np.array([True]))
    assert reach.rows[0].median_deg_per_mm == pytest.approx(deg_per_mm(1.0, 0.5))
    assert reach.rows[0].median_deg_per_mm == pytest.approx(np.degrees(2.0) / 1e3)
    with pytest.raises(ValueError, match=r"\(N, 6, 2\)"):
        orientation_reach(twist, ["a", "b"], np.array([True, False]))
