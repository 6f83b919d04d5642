"""The twin's encoder effect against its geometry: an eccentric disc read by one head, an
oval disc; the joint stands where the read angle is the command."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.effects.encoder_eccentricity import EncoderEccentricity
from twin.exceptions import ModelError
from twin.mechanism import Mechanism

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def arm() -> Mechanism:
    return Mechanism.from_xml(ROOT / "models/arm6r.xml")


def _commands(mech: Mechanism, n: int = 200) -> np.ndarray:
    lo, hi = mech.actuator_range.T
    return np.random.default_rng(2).uniform(lo, hi, (n, mech.n_actuators))


def test_the_joint_stands_where_the_read_angle_is_the_command(arm):
    effect = EncoderEccentricity(eccentricity_m=20e-6, radius_m=0.02, ovality=5e-4, seed=3)
    c = _commands(arm)
    joints = effect.apply(arm, c, np.arange(len(c)))
    assert np.max(np.abs(joints - c)) > 1e-4  # it moves the joints (e / R = 1e-3)
    zero = arm.model.qpos0[arm.actuator_qpos]
    np.testing.assert_allclose(effect.read(arm, joints - zero) + zero, c, rtol=0, atol=1e-14)


def test_eccentric_disc_read_by_one_head_is_the_plane_geometry(arm):
    e, r = 15e-6, 0.025
    effect = EncoderEccentricity(eccentricity_m=e, radius_m=r, seed=5)
    phi = effect.phases(arm)[:, 0]
    theta = np.linspace(-np.pi, np.pi, 37)[:, None] * np.ones(arm.n_actuators)
    # the disc's centre at e exp(i (theta + phi)); the head at R: the graduation under the
    # head, in the disc's frame, is at arg(R - centre) - theta; it counts -(that) as the angle
    centre = e * np.exp(1j * (theta + phi[None, :]))
    expected = -(np.angle(r - centre) - theta)
    np.testing.assert_allclose(effect.read(arm, theta), expected, rtol=0, atol=1e-15)
    # once per revolution with amplitude e / R, the second harmonic (e / R)^2 / 2 smaller
    err = effect.read(arm, theta) - theta
    first = (e / r) * np.sin(theta + phi[None, :])
    assert np.max(np.abs(err - first)) <= 0.5 * (e / r) ** 2 * 1.01


def test_oval_disc_errs_twice_per_revolution(arm):
    o = 4e-4
    effect = EncoderEccentricity(eccentricity_m=0.0, ovality=o, seed=7)
    psi = effect.phases(arm)[:, 1]
    theta = np.linspace(-3.0, 3.0, 61)[:, None] * np.ones(arm.n_actuators)
    err = effect.read(arm, theta) - theta
    second = -(o / 2) * np.sin(2 * (theta - psi[None, :]))
    # tan(read - psi) = (1 - o) tan(theta - psi): 2x per revolution, then O(o^2) at 4x
    assert np.max(np.abs(err - second)) < o**2
    np.testing.assert_allclose(
        np.tan(effect.read(arm, theta) - psi), (1 - o) * np.tan(theta - psi), rtol=1e-9
    )


def test_zero_magnitude_prismatic_actuators_and_bad_values():
    polisher = Mechanism.from_xml(ROOT / "models/polisher.xml")
    c = np.tile(polisher.home_qpos[polisher.actuator_qpos], (5, 1))
    c[:, 3:] += np.linspace(-0.5, 0.5, 5)[:, None]
    moved = EncoderEccentricity(seed=1).apply(polisher, c, np.arange(5))
    assert np.array_equal(moved[:, :3], c[:, :3])  # the screw legs are not read by a disc
    assert np.all(moved[:, 3:] != c[:, 3:])
    none = EncoderEccentricity(eccentricity_m=0.0)
    assert none.apply(polisher, c, np.arange(5)) is c
    hexapod = Mechanism.from_xml(ROOT / "models/hexapod_rrrprr.xml")
    with pytest.raises(ModelError, match="no revolute actuator"):
        EncoderEccentricity().apply(hexapod, np.zeros((1, 6)), np.arange(1))
    with pytest.raises(ValueError, match="no encoder"):
        EncoderEccentricity(eccentricity_m=5e-3, radius_m=0.03)
    with pytest.raises(ModelError, match="phases"):
        EncoderEccentricity(phases_rad=(0.0, 1.0)).phases(polisher)
