"""The twin's physical effects against their physics, on the hexapod, the polisher and the
serial arm: analytic identities, zero magnitude = unperturbed, measurable at the defaults."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from twin.effects import (
    ActuatorGain,
    GravityCompliance,
    JointBacklash,
    JointCompliance,
    LeadErrorHarmonic,
    ReflectorOffset,
    ThermalWarmup,
    TrackerAirTemperature,
)
from twin.effects.gravity_compliance import actuator_forces
from twin.effects.joint_backlash import ARCSEC
from twin.exceptions import ClosureError, ModelError, WorkspaceError
from twin.kinematics.single_pose import forward
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.tracker import AirCompensation, PoseNoise, Tracker, TrackerNoise, air_refractive_index
from twin.workspace import commands_for_poses

ROOT = Path(__file__).resolve().parent.parent
HEAD = (4.0, 0.0, 0.5)  # a tracker 4 m from the machine (2-5 m is the usual stand-off)
EXACT = Tracker(position_m=HEAD, noise=TrackerNoise.none())
N_POSES = 24


def _parallel_commands(mech: Mechanism, n: int) -> np.ndarray:
    """Commands of random poses inside the box and the strokes (rejection sampling)."""
    lo, hi = mech.workspace_min, mech.workspace_max
    rng = np.random.default_rng(3)
    out: list[np.ndarray] = []
    while len(out) < n:
        pose = lo + (hi - lo) * (0.5 + 0.35 * rng.uniform(-1, 1, 6))
        try:
            out.append(commands_for_poses(mech, pose[None])[0])
        except (WorkspaceError, ClosureError):
            continue
    return np.array(out)


@pytest.fixture(scope="module")
def machines() -> dict[str, tuple[Mechanism, np.ndarray]]:
    out = {}
    for key in ("hexapod_rrrprr", "polisher", "arm6r"):
        mech = Mechanism.from_xml(ROOT / f"models/{key}.xml")
        if mech.is_serial:
            lo, hi = mech.actuator_range.T
            rng = np.random.default_rng(3)
            c = lo + (hi - lo) * (0.5 + 0.3 * rng.uniform(-1, 1, (N_POSES, mech.n_actuators)))
        else:
            c = _parallel_commands(mech, N_POSES)
        out[key] = (mech, c)
    return out


def _readings(mech, commands, effects=(), tracker=EXACT, order=None, pose_noise=None, seed=0):
    rng = np.random.default_rng(seed)
    m = measure(mech, commands, tracker, rng, pose_noise, effects=effects, order=order)
    return m.readings[:, :, 0]


def _rms_um(a: np.ndarray, b: np.ndarray) -> float:
    return 1e6 * float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


# ------------------------------------------------------------------ zero magnitude is nothing

ZERO = [
    ("hexapod_rrrprr", ThermalWarmup(delta_K=0.0)),
    ("arm6r", ThermalWarmup(delta_K=0.0)),
    ("hexapod_rrrprr", LeadErrorHarmonic(amplitudes_m=(0.0, 0.0), cumulative_m_per_300mm=0.0)),
    ("polisher", JointBacklash(play_rad=0.0)),
    ("arm6r", JointBacklash(play_rad=0.0)),
    ("hexapod_rrrprr", JointCompliance(stiffness_N_per_m=2e7, gravity=(0.0, 0.0, 0.0))),
    ("arm6r", JointCompliance(gravity=(0.0, 0.0, 0.0))),
    ("hexapod_rrrprr", ActuatorGain(magnitude_ppm=0.0)),
    ("arm6r", ActuatorGain(magnitude_ppm=0.0)),
    ("hexapod_rrrprr", ReflectorOffset(magnitude_m=0.0)),
    ("arm6r", ReflectorOffset(magnitude_m=0.0)),
    ("hexapod_rrrprr", TrackerAirTemperature(hall_C=20.0)),
    ("arm6r", TrackerAirTemperature(hall_C=20.0)),
]


@pytest.mark.parametrize("key, effect", ZERO, ids=[f"{k}-{e.name}" for k, e in ZERO])
def test_zero_magnitude_gives_exactly_the_unperturbed_readings(machines, key, effect):
    mech, c = machines[key]
    noisy = Tracker(position_m=HEAD, noise=TrackerNoise("gaussian", 5e-6, 1e-6))
    noise = PoseNoise()
    plain = _readings(mech, c, (), noisy, pose_noise=noise)
    np.testing.assert_array_equal(_readings(mech, c, [effect], noisy, pose_noise=noise), plain)


# ------------------------------------------------------------------ thermal warm-up


@pytest.mark.parametrize("key", ["hexapod_rrrprr", "arm6r"])
def test_warmup_scales_the_whole_machine_with_the_temperature_history(machines, key):
    """Every body grows by alpha dT(t): the machine is similar to the cold one, so each reading
    (world frame, origin the machine's base) scales by 1 + alpha dT(t): 63.2 % of the final
    growth at t = tau, 99.75 % at 6 tau."""
    mech, c = machines[key]
    c = c[:4]
    eff = ThermalWarmup(delta_K=4.0, tau_s=1200.0, seconds_per_pose=1200.0, alpha_per_K=23e-6)
    order = np.array([0, 1, 3, 6])  # t = 0, tau, 3 tau, 6 tau
    plain = _readings(mech, c)
    warm = _readings(mech, c, [eff], order=order)
    fraction = 1.0 - np.exp(-order.astype(float))
    np.testing.assert_allclose(fraction[1], 0.632, atol=1e-3)
    growth = 23e-6 * 4.0 * fraction
    np.testing.assert_allclose(warm, plain * (1.0 + growth)[:, None, None], atol=1e-12, rtol=0)


def test_warmup_grows_links_of_the_arm_and_the_base_circle_of_the_hexapod(machines):
    arm, _ = machines["arm6r"]
    eff = ThermalWarmup(delta_K=3.0, seconds_per_pose=1e6)  # fully warm at k = 1
    e = 11.5e-6 * 3.0
    warm = eff.model_at(arm, 1)
    assert warm is not arm and eff.model_at(arm, 0) is arm  # cold at t = 0
    np.testing.assert_allclose(warm.model.body_pos, arm.model.body_pos * (1 + e), rtol=1e-12)
    hexa, _ = machines["hexapod_rrrprr"]
    base_only = ThermalWarmup(delta_K=3.0, seconds_per_pose=1e6, bodies="leg*_base")
    grown = base_only.model_at(hexa, 1).model
    ids = base_only.grown_bodies(hexa)
    assert len(ids) == 6
    radius = np.linalg.norm(grown.body_pos[ids, :2], axis=1)
    np.testing.assert_allclose(radius, 0.18 * (1 + e), rtol=1e-9)  # the 180 mm base circle
    others = np.setdiff1d(np.arange(hexa.model.nbody), ids)
    np.testing.assert_array_equal(grown.body_pos[others], hexa.model.body_pos[others])
    with pytest.raises(ModelError, match="no body"):
        ThermalWarmup(bodies="nothing*").model_at(hexa, 5)


# ------------------------------------------------------------------ lead error


def test_lead_error_is_periodic_in_its_pitch_with_its_harmonics(machines):
    mech, c = machines["hexapod_rrrprr"]
    eff = LeadErrorHarmonic(pitch_m=4e-3, amplitudes_m=(3e-6, 1e-6), cumulative_m_per_300mm=0)
    dev = eff.deviation(mech, c)
    np.testing.assert_allclose(eff.deviation(mech, c + 4e-3), dev, atol=1e-15)
    assert not np.allclose(eff.deviation(mech, c + 2e-3), dev, atol=1e-7)  # not at half a lead
    # 1x and 2x per revolution: the spectrum over one lead holds exactly those amplitudes
    s = mech.model.qpos0[mech.actuator_qpos][0] + np.arange(64) / 64 * 4e-3
    grid = np.repeat(s[:, None], mech.n_actuators, axis=1)
    spectrum = np.abs(np.fft.rfft(eff.deviation(mech, grid)[:, 0])) / 32
    np.testing.assert_allclose(spectrum[1:4], [3e-6, 1e-6, 0.0], atol=1e-15)


def test_cumulative_lead_deviation_per_300mm(machines):
    mech, c = machines["polisher"]
    eff = LeadErrorHarmonic(amplitudes_m=(), cumulative_m_per_300mm=12e-6, seed=4)  # C3
    cum, _ = eff.draws(mech)
    assert np.all(np.abs(cum) <= 12e-6) and np.any(cum != 0)
    dev = eff.deviation(mech, c + 0.3) - eff.deviation(mech, c)  # 300 mm further
    slide = mech.actuator_is_slide
    np.testing.assert_allclose(dev[:, slide], np.broadcast_to(cum[slide], dev[:, slide].shape))
    assert np.all(dev[:, ~slide] == 0.0)  # no screw in the wrist's revolute joints
    with pytest.raises(ModelError, match="no prismatic actuator"):
        LeadErrorHarmonic().apply(machines["arm6r"][0], machines["arm6r"][1], np.arange(N_POSES))


# ------------------------------------------------------------------ gain


@pytest.mark.parametrize("key", ["hexapod_rrrprr", "arm6r"])
def test_gain_error_is_proportional_to_the_commanded_travel(machines, key):
    mech, c = machines[key]
    gains = tuple(np.linspace(-400, 400, mech.n_actuators))
    out = ActuatorGain(gains_ppm=gains).apply(mech, c, np.arange(len(c)))
    zero = mech.model.qpos0[mech.actuator_qpos]  # 0 on the arm: joint = command (1 + g)
    np.testing.assert_allclose(out - zero, (c - zero) * (1 + 1e-6 * np.array(gains)), atol=1e-15)
    drawn = ActuatorGain(magnitude_ppm=300.0, seed=2).gains(mech)
    assert np.all(np.abs(drawn) <= 300e-6)
    np.testing.assert_array_equal(drawn, ActuatorGain(magnitude_ppm=300.0, seed=2).gains(mech))


# ------------------------------------------------------------------ revolute backlash


def test_revolute_backlash_flips_sign_with_the_approach_direction(machines):
    arm, _ = machines["arm6r"]
    home = arm.home_qpos[arm.actuator_qpos]
    up = home + 0.1
    seq = np.vstack([up, home, up, up])  # up, down to home, up again, stay
    eff = JointBacklash(play_rad=60 * ARCSEC)
    err = eff.apply(arm, seq, np.arange(4)) - seq
    half = 30 * ARCSEC
    np.testing.assert_allclose(err, [[-half] * 6, [half] * 6, [-half] * 6, [-half] * 6], atol=1e-18)
    # between two others, a pose is approached from below one way and from above the other
    mid = np.vstack([home - 0.1, home + 0.05, home + 0.1])
    forward_ = eff.apply(arm, mid, np.array([0, 1, 2])) - mid
    reverse = eff.apply(arm, mid, np.array([2, 1, 0])) - mid
    np.testing.assert_allclose(forward_[1], -half, atol=1e-18)
    np.testing.assert_allclose(reverse[1], half, atol=1e-18)
    # on the polisher only its revolute wrist takes play_rad; its screws take play_m
    pol, c = machines["polisher"]
    out = JointBacklash(play_rad=half * 2).apply(pol, c, np.arange(len(c))) - c
    assert np.all(out[:, pol.actuator_is_slide] == 0)
    assert np.all(np.abs(out[1:, ~pol.actuator_is_slide]) == pytest.approx(half))
    hexa, hc = machines["hexapod_rrrprr"]
    with pytest.raises(ModelError, match="no revolute actuator"):
        JointBacklash().apply(hexa, hc, np.arange(len(hc)))
    prism = JointBacklash(play_m=10e-6).apply(hexa, hc, np.arange(len(hc))) - hc
    np.testing.assert_allclose(np.abs(prism), 5e-6, rtol=1e-6)


# ------------------------------------------------------------------ joint compliance


def test_payload_torque_on_the_arm_is_the_lever_of_its_weight(machines):
    """Masses defaulted: the payload alone loads the arm, at the tool point; qfrc_bias equals
    -(r_tool - anchor_j) x m g . axis_j for each joint."""
    arm, c = machines["arm6r"]
    assert arm.masses_defaulted
    heavy = JointCompliance(payload_kg=5.0).loaded(arm)
    sol = forward(heavy, c[0])
    tau = actuator_forces(heavy, sol.qpos)
    d = heavy.data
    lever = d.site_xpos[arm.tool_site] - d.xanchor[arm.actuator_joints]
    weight = np.array([0.0, 0.0, -9.81 * 5.0])
    expected = -np.einsum("ji,ji->j", np.cross(lever, weight), d.xaxis[arm.actuator_joints])
    np.testing.assert_allclose(tau, expected, atol=1e-9)


def test_compliance_doubles_when_the_stiffness_halves(machines):
    arm, c = machines["arm6r"]
    c = c[:3]
    order = np.arange(3)
    stiff = JointCompliance(stiffness_Nm_per_rad=1e5).apply(arm, c, order) - c
    soft = JointCompliance(stiffness_Nm_per_rad=5e4).apply(arm, c, order) - c
    np.testing.assert_allclose(soft, 2 * stiff, rtol=2e-2, atol=1e-9)
    assert np.max(np.abs(soft)) > 2e-4  # 5 kg at ~1 m on 5e4 N m/rad: almost a milliradian
    hexa, hc = machines["hexapod_rrrprr"]
    k1 = JointCompliance(stiffness_N_per_m=2e7).apply(hexa, hc[:1], [0]) - hc[:1]
    k2 = JointCompliance(stiffness_N_per_m=1e7).apply(hexa, hc[:1], [0]) - hc[:1]
    np.testing.assert_allclose(k2, 2 * k1, rtol=1e-3)


def test_gravity_on_defaulted_masses_needs_a_payload(machines):
    arm, c = machines["arm6r"]
    for eff in (JointCompliance(payload_kg=0.0), GravityCompliance(payload_kg=0.0)):
        with pytest.raises(ModelError, match="defaulted"):
            eff.apply(arm, c[:1], [0])
    sag = GravityCompliance(payload_kg=5.0, stiffness_Nm_per_rad=5e4).apply(arm, c[:1], [0])
    assert np.max(np.abs(sag - c[:1])) > 1e-4  # payload only, on a revolute arm
    hexa, hc = machines["hexapod_rrrprr"]
    with pytest.raises(ModelError, match="no revolute actuator"):
        JointCompliance().apply(hexa, hc, np.arange(len(hc)))


# ------------------------------------------------------------------ reflector offsets


@pytest.mark.parametrize("key", ["hexapod_rrrprr", "arm6r"])
def test_reflector_offsets_move_readings_by_the_offset_rotated_into_the_world(machines, key):
    mech, c = machines[key]
    eff = ReflectorOffset(magnitude_m=50e-6, seed=1)
    off = eff.target_offsets(mech)
    np.testing.assert_allclose(np.linalg.norm(off, axis=1), 50e-6, rtol=1e-12)
    m = measure(mech, c, EXACT, np.random.default_rng(0), effects=[eff])
    plain = _readings(mech, c)
    moved = np.einsum("nij,tj->nti", m.true_rotation, off)
    np.testing.assert_allclose(m.readings[:, :, 0] - plain, moved, atol=1e-15)
    explicit = ReflectorOffset(offsets_m=tuple(off.ravel()))
    np.testing.assert_array_equal(explicit.target_offsets(mech), off)


# ------------------------------------------------------------------ air temperature


def test_air_index_and_its_temperature_coefficient():
    n20 = air_refractive_index(20.0, 101325.0, 0.0)
    assert 2.70e-4 < n20 - 1 < 2.73e-4  # about 271 ppm at 633 nm (Edlen)
    slope = air_refractive_index(21.0) - air_refractive_index(20.0)
    assert slope == pytest.approx(-0.93e-6, rel=1e-2)


@pytest.mark.parametrize("key", ["hexapod_rrrprr", "arm6r"])
def test_air_temperature_scales_distances_by_093_ppm_per_kelvin(machines, key):
    mech, c = machines[key]
    plain = _readings(mech, c)
    eff = TrackerAirTemperature(hall_C=23.0, set_C=20.0)
    warm = _readings(mech, c, [eff])
    head = np.array(HEAD)
    scale = np.linalg.norm(warm - head, axis=-1) / np.linalg.norm(plain - head, axis=-1) - 1
    np.testing.assert_allclose(scale, -0.93e-6 * 3.0, rtol=2e-2)
    np.testing.assert_allclose(scale, AirCompensation().scale_error, rtol=1e-9)
    same = _readings(
        mech, c, tracker=Tracker(position_m=HEAD, noise=TrackerNoise.none(), air=AirCompensation())
    )
    np.testing.assert_array_equal(same, warm)


# ------------------------------------------------------------------ measurable at the defaults

SCAN = [
    ("arm6r", lambda s: ThermalWarmup(delta_K=3.0 * s)),
    (
        "polisher",
        lambda s: LeadErrorHarmonic(
            amplitudes_m=(2.5e-6 * s, 1e-6 * s), cumulative_m_per_300mm=23e-6 * s
        ),
    ),
    ("arm6r", lambda s: JointBacklash(play_rad=30 * ARCSEC * s)),
    ("polisher", lambda s: JointBacklash(play_rad=30 * ARCSEC * s)),
    ("arm6r", lambda s: JointCompliance(gravity=(0.0, 0.0, -9.81 * s))),
    ("polisher", lambda s: JointCompliance(payload_kg=5.0, gravity=(0.0, 0.0, -9.81 * s))),
    ("arm6r", lambda s: ActuatorGain(magnitude_ppm=200.0 * s)),
    ("polisher", lambda s: ActuatorGain(magnitude_ppm=200.0 * s)),
    ("hexapod_rrrprr", lambda s: ReflectorOffset(magnitude_m=30e-6 * s)),
    ("hexapod_rrrprr", lambda s: TrackerAirTemperature(hall_C=20.0 + 3.0 * s)),
]


@pytest.mark.parametrize("key, make", SCAN, ids=[f"{k}-{m(1).name}" for k, m in SCAN])
def test_each_effect_is_measurable_at_its_default_magnitude(machines, key, make):
    """RMS change of the readings over a scan of magnitudes (x 0, 0.5, 1, 2 of the default):
    exactly zero at zero, growing with the magnitude, well above 5 um (tracker noise) at the
    default (the constructor's), measured along an 80-pose sequence (40 min at 30 s a pose)."""
    mech, c = machines[key]
    assert make(1) == type(make(1))()  # the scan is around the constructor's defaults
    order = np.arange(len(c)) * 80 // len(c)  # spread over an 80-pose calibration sequence
    plain = _readings(mech, c, order=order)
    rms = [_rms_um(_readings(mech, c, [make(s)], order=order), plain) for s in (0.0, 0.5, 1.0, 2.0)]
    assert rms[0] == 0.0
    assert rms[1] < rms[2] < rms[3]
    assert rms[2] > 10.0, f"{make(1).name} on {key}: {rms[2]:.2f} um RMS"
    assert math.isfinite(rms[3])


# ------------------------------------------------------------------ scenario files


def test_every_effect_kind_is_switched_on_by_name_in_a_scenario_file():
    from scenarios.config import _check_effects
    from scenarios.machine_setup import EFFECTS

    for kind in (
        "thermal_warmup",
        "lead_error_harmonic",
        "joint_backlash",
        "joint_compliance",
        "actuator_gain",
        "reflector_offset",
        "tracker_air_temperature",
    ):
        assert kind in EFFECTS
        assert _check_effects([{"kind": kind}], "truth.effects") == []
        assert EFFECTS[kind]().name == kind
    entries = [
        {"kind": "thermal_warmup", "delta_K": 4.0, "tau_s": 2400.0, "bodies": "leg*,platform"},
        {"kind": "lead_error_harmonic", "pitch_m": 10e-3, "amplitudes_m": [2e-6, 0.5e-6]},
        {"kind": "actuator_gain", "gains_ppm": [100, -200, 300, 0, 50, -50]},
        {"kind": "tracker_air_temperature", "hall_C": 25.0},
    ]
    assert _check_effects(entries, "truth.effects") == []
    bad = _check_effects([{"kind": "thermal_warmup", "tau_s": -1.0}], "truth.effects")
    assert len(bad) == 1 and "tau_s" in bad[0]


def test_measure_refuses_what_is_not_an_effect(machines):
    mech, c = machines["arm6r"]
    with pytest.raises(TypeError, match="not an effect"):
        measure(mech, c, EXACT, np.random.default_rng(0), effects=[object()])
