"""The offset kinds of the error model (twin.offset_kinds, calib.fit.kinds): periodic errors,
backlash, drift, thermal growth and expansion in the calibration model.

The checks: the full Jacobian (geometry, a gain, every offset kind) against central
differences of the prediction on the closed-chain hexapod and on a serial arm; noise-free
exact recovery of geometry plus offsets from twin readings whose truth carries the twin's own
effects (lead error; thermal growth then backlash), the calibration seeing only the dataset;
the kinds' entries through the error-model file and the diagnosis file, the Dataset's new
columns through its file; refusal of a dataset lacking the column a kind reads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fd_support import central_differences

from calib.data import Dataset, DatasetError, read_dataset, write_dataset
from calib.fit.identification import identify
from calib.fit.kinds import PoseState, approach_directions
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations, bind_dataset
from calib.loop.effect_kinds import _parameter, parameter_entry
from twin.effects import (
    Backlash,
    EncoderEccentricity,
    LeadError,
    ThermalGrowth,
    ThermalWarmup,
    ZeroDrift,
)
from twin.exceptions import ParameterError
from twin.formats.parameter_file import load_parameter_set
from twin.measurement import measure
from twin.mechanism import Mechanism
from twin.parameters import Parameter, ParameterSet
from twin.tracker import Tracker, TrackerNoise
from twin.workspace import random_poses

MODELS = Path(__file__).resolve().parents[1] / "models"
EXACT = Tracker(noise=TrackerNoise.none())


@pytest.fixture(scope="module")
def hexapod() -> Mechanism:
    return Mechanism.from_xml(MODELS / "hexapod_rrrprr.xml")


@pytest.fixture(scope="module")
def arm() -> Mechanism:
    return Mechanism.from_xml(MODELS / "arm6r.xml")


def _every_kind(mech: Mechanism) -> list[Parameter]:
    a = mech.actuator_names
    return [
        Parameter(f"{a[0]}.gain", "actuator_gain", a[0]),
        Parameter(f"{a[0]}.s", "periodic_error", a[0], constants={"phase": "sin", "period_mm": 4}),
        Parameter(f"{a[1]}.c", "periodic_error", a[1], constants={"phase": "cos", "period_mm": 5}),
        Parameter(f"{a[0]}.bl", "backlash", a[0]),
        Parameter(f"{a[2]}.bl", "backlash", a[2]),
        Parameter(
            f"{a[3]}.dr", "drift", a[3], constants={"clock": "time_s", "time_constant": 600.0}
        ),
        Parameter(f"{a[4]}.tg", "thermal_growth", a[4], constants={"clock": "order"}),
        Parameter(f"{a[5]}.te", "thermal_expansion", a[5], constants={"origin": 20.0}),
    ]


def _state(n: int, n_act: int, rng: np.random.Generator) -> PoseState:
    return PoseState(
        n,
        direction=rng.choice([-1.0, 1.0], (n, n_act)),
        time_s=rng.uniform(0.0, 3000.0, n),
        order=np.arange(float(n)),
        temperature_c=rng.uniform(18.0, 25.0, n),
    )


def _fd_steps(params: ParameterSet) -> np.ndarray:
    """1e-6 (m, rad) and 10 ppm as for the gains; a time kind's per-second value moves the
    joint by step x h(t) (h up to 600 s here): 1e-9 per second keeps that near 1e-6."""
    steps = np.where(params.is_gain, 1e-5, 1e-6)
    drift = np.array([p.kind == "drift" for p in params.parameters])
    return np.where(drift, 1e-9, steps)


def test_jacobian_of_every_offset_kind_against_finite_differences(hexapod):
    base = load_parameter_set(MODELS / "hexapod_rrrprr.params.toml", hexapod.model)
    params = ParameterSet([*base.parameters, *_every_kind(hexapod)], hexapod.model)
    model = CalibrationModel(hexapod, params)
    rng = np.random.default_rng(1)
    c = random_poses(hexapod, 4, rng)[1]
    model.bind_state(_state(4, hexapod.n_actuators, rng))
    x = rng.uniform(-1, 1, len(params)) * np.where(params.is_angle, 1e-3, 2e-4)
    x[params.is_gain] = 3e-4
    x[params.is_offset] = 1e-5 * rng.uniform(-1, 1, int(params.is_offset.sum()))
    x[params.index("leg4.dr")] = 1e-8  # m/s: 6 um over the time constant
    jac = model.jacobian(x, model.predict(x, c))
    fd = central_differences(model, x, c, _fd_steps(params))
    rel = np.abs(fd - jac).max(axis=0) / np.linalg.norm(jac, axis=0)
    assert np.all(np.linalg.norm(jac[:, params.is_offset], axis=0) > 1e-3)
    # central differences of a smooth prediction: error ~ step^2 x curvature, 1e-8 of the
    # column at these steps; the closure solves to 1e-13 m
    assert np.max(rel) < 1e-6, params.names[int(np.argmax(rel))]


def test_jacobian_on_a_serial_arm_with_harmonics_and_backlash(arm):
    base = load_parameter_set(MODELS / "arm6r.params.toml", arm.model)
    extra = [
        Parameter(f"{a}.{ph}", "periodic_error", a, constants={"phase": ph, "harmonic": h})
        for a, h in zip(arm.actuator_names[:3], (1, 2, 1), strict=True)
        for ph in ("sin", "cos")
    ] + [Parameter(f"{a}.bl", "backlash", a) for a in arm.actuator_names]
    params = ParameterSet([*base.parameters, *extra], arm.model)
    model = CalibrationModel(arm, params)
    rng = np.random.default_rng(4)
    lo, hi = arm.actuator_range.T
    c = rng.uniform(0.7 * lo, 0.7 * hi, (4, arm.n_actuators))
    model.bind_state(_state(4, arm.n_actuators, rng))
    x = rng.uniform(-1, 1, len(params)) * np.where(params.is_angle, 1e-3, 2e-4)
    jac = model.jacobian(x, model.predict(x, c))
    fd = central_differences(model, x, c, np.full(len(params), 1e-6))
    rel = np.abs(fd - jac).max(axis=0) / np.linalg.norm(jac, axis=0)
    assert np.max(rel[params.is_offset]) < 1e-6
    assert np.max(rel) < 1e-6, params.names[int(np.argmax(rel))]


def _recover(
    mech, extra, effects, n=60, seed=3, errors="hexapod_rrrprr", temperature=None, full=False
):
    """Geometry plus ``extra`` identified from noise-free readings of a truth with geometric
    errors and the twin's ``effects``, measured in one sequence from the model's home, 30 s
    per pose (``temperature``: a function of the order giving each reading's deg C)."""
    base = load_parameter_set(MODELS / f"{errors}.params.toml", mech.model)
    params = ParameterSet([*base.parameters, *extra], mech.model)
    rng = np.random.default_rng(seed)
    if mech.workspace_min is not None:
        commands = random_poses(mech, n, rng)[1]
    else:  # a serial arm: joints anywhere in 70 % of their ranges
        lo, hi = mech.actuator_range.T
        commands = rng.uniform(0.7 * lo, 0.7 * hi, (n, mech.n_actuators))
    geo = rng.uniform(-1, 1, len(base)) * np.where(base.is_angle, np.radians(0.05), 2e-4)
    truth = mech.with_model(base.inject(mech.model, geo))
    order = np.arange(n)
    m = measure(truth, commands, EXACT, np.random.default_rng(0), effects=effects, order=order)
    home = mech.home_qpos[mech.actuator_qpos]
    state = PoseState(
        n,
        approach_directions(commands, order, home),
        30.0 * order,
        order.astype(float),
        None if temperature is None else temperature(order),
    )
    obs = Observations(commands, m.readings.mean(axis=2), state=state)
    model = CalibrationModel(mech, params)
    res = identify(model, obs, unidentifiable="fix")
    return (params, res, model, obs, truth) if full else (params, res)


def test_noise_free_recovery_of_a_lead_error(hexapod):
    """The twin's lead error A sin(2 pi c / p + phi) is A cos(phi) sin + A sin(phi) cos: the
    periodic_error kind at the same pitch recovers both amplitudes to round-off."""
    a, p = 5e-6, 4e-3
    phases = np.linspace(0, 2 * np.pi, 6, endpoint=False) + 0.3
    extra = [
        Parameter(f"{n}.{ph}", "periodic_error", n, constants={"phase": ph, "period_mm": 4.0})
        for ph in ("sin", "cos")
        for n in hexapod.actuator_names
    ]
    params, res = _recover(hexapod, extra, [LeadError(a, p, tuple(phases))])
    assert res.converged and res.residual_rms < 1e-12
    want = np.concatenate([a * np.cos(phases), a * np.sin(phases)])
    got = res.values[params.is_offset]
    assert np.max(np.abs(got - want)) < 1e-12  # m, of 5e-6


def test_noise_free_recovery_of_thermal_growth_and_backlash(hexapod):
    """The twin grows each leg by alpha x rate x order (its ThermalGrowth from 0 K), then stops
    each short by half its play in the approach direction: thermal_growth on the order clock
    (no time constant: linear) and backlash give both back."""
    alpha, rate, play = 11.5e-6, 0.05, 12e-6
    names = hexapod.actuator_names
    extra = [
        Parameter(f"{n}.growth", "thermal_growth", n, constants={"clock": "order"}) for n in names
    ]
    extra += [Parameter(f"{n}.half_play", "backlash", n) for n in names]
    effects = [ThermalGrowth(0.0, rate, alpha), Backlash(play_m=play)]
    params, res = _recover(hexapod, extra, effects)
    assert res.converged and res.residual_rms < 1e-12
    got = res.values[params.is_offset]
    assert np.max(np.abs(got[:6] - alpha * rate)) < 1e-12  # strain per pose, of 5.8e-7
    assert np.max(np.abs(got[6:] - play / 2)) < 1e-12  # m, of 6e-6


def test_noise_free_recovery_of_a_zero_drift(hexapod):
    """The twin's zero drift r h(t) (its ZeroDrift, tau 20 min, 30 s per pose) is the drift
    kind on the time_s clock with the same time constant: the rates come back."""
    rates = np.array([4.0, -3.0, 2.0, 5.0, -1.0, 3.5]) * 1e-9  # m/s: up to 4.7 um in 30 min
    extra = [
        Parameter(
            f"{n}.drift_rate", "drift", n, constants={"clock": "time_s", "time_constant": 1200.0}
        )
        for n in hexapod.actuator_names
    ]
    effects = [ZeroDrift(rates=tuple(rates), tau_s=1200.0, seconds_per_pose=30.0)]
    params, res = _recover(hexapod, extra, effects)
    assert res.converged and res.residual_rms < 1e-12
    # readings exact to ~1e-13 m, the drift's h(t) of several hundred seconds: the rates
    # to 1e-15 m/s (of 1e-9 to 5e-9)
    assert np.max(np.abs(res.values[params.is_offset] - rates)) < 1e-15


def test_noise_free_recovery_of_a_thermal_expansion(hexapod):
    """The twin's warm-up of the leg rods (its ThermalWarmup on leg*_rod: rod and screw grow
    by alpha dT) makes each leg (c + d) (1 + alpha dT), d its length error; with the legs'
    temperature 20 + dT in the temperature_c column, thermal_expansion (origin 20 C) recovers
    alpha, steel's 11.5e-6, to the d alpha dT it does not model."""
    warm = ThermalWarmup(delta_K=8.0, tau_s=1200.0, seconds_per_pose=30.0, bodies="leg*_rod")
    extra = [
        Parameter(f"{n}.expansion", "thermal_expansion", n, constants={"origin": 20.0})
        for n in hexapod.actuator_names
    ]
    params, res = _recover(
        hexapod, extra, [warm], temperature=lambda k: 20.0 + warm.temperature_K(warm.time_s(k))
    )
    got = res.values[params.is_offset]
    # the twin grows the whole rod, its length error d (up to 0.2 mm here) with it: the kind,
    # a strain of the travel c, leaves d alpha dT (< 0.2 mm x 8.3e-5 = 1.7e-8 m) and takes
    # alpha to a relative d / c (0.2 / 195 mm, 1e-3)
    assert res.converged and res.residual_rms < 1.7e-8
    assert np.max(np.abs(got - 11.5e-6)) < 1e-3 * 11.5e-6, got


def test_noise_free_recovery_of_an_encoder_eccentricity(arm):
    """The twin's eccentric encoder disc (e = 10 um at R = 30 mm, phase phi per joint) makes
    the joint stand at theta = c - (e/R) sin(c + phi) + O((e/R)^3) (the second harmonic of
    the reading cancels in the inversion to second order): periodic_error at harmonic 1
    recovers -(e/R) cos(phi) (sin) and -(e/R) sin(phi) (cos) on every joint of the 6R arm."""
    ecc = EncoderEccentricity(eccentricity_m=10e-6, radius_m=0.03, seed=5)
    phi = ecc.phases(arm)[:, 0]
    eps = ecc.eccentricity_m / ecc.radius_m
    names = arm.actuator_names
    extra = [
        Parameter(f"{n}.ecc_{ph}", "periodic_error", n, constants={"phase": ph, "harmonic": 1})
        for ph in ("sin", "cos")
        for n in names
    ]
    params, res, model, obs, truth = _recover(arm, extra, [ecc], n=80, errors="arm6r", full=True)
    # the disc turns with the joint from the truth's joint zero (its zero errors z included):
    # -(e/R) sin(c - z + phi)
    phi = phi - truth.model.qpos0[truth.actuator_qpos]
    want = np.concatenate([-eps * np.cos(phi), -eps * np.sin(phi)])
    got = res.values[params.is_offset]
    # what the model leaves is the third order, (e/R)^3 = 3.7e-11 rad on the arm's ~1 m
    assert res.converged and res.residual_rms < 1e-10
    # readings that differ from the model's by r move an exact least-squares fit by at most
    # |r| / s_min (s_min: the Jacobian's smallest singular value over the estimated
    # parameters): on the arm some geometry nearly mimics a joint's first harmonic (s_min
    # small), so the values come back to that bound, not to round-off
    jac = model.jacobian(res.values, model.predict(res.values, obs.commands))
    jac = jac.reshape(-1, len(params))[:, res.estimated]
    s_min = np.linalg.svd(jac, compute_uv=False)[-1]
    r_norm = res.residual_rms * np.sqrt(jac.shape[0])
    assert np.max(np.abs(got - want)) <= r_norm / s_min, (
        np.max(np.abs(got - want)),
        r_norm / s_min,
    )
    assert np.max(np.abs(got - want)) < 1e-3 * eps  # and within a thousandth of e/R


def test_offset_kinds_through_the_files(hexapod, tmp_path):
    text = (MODELS / "hexapod_rrrprr.params.toml").read_text() + (
        '\n[[parameter]]\nname = "leg1.lead_sin"\nkind = "periodic_error"\nelement = "leg1"\n'
        'phase = "sin"\nperiod_mm = 4.0\n'
        '\n[[parameter]]\nname = "leg2.growth"\nkind = "thermal_growth"\nelement = "leg2"\n'
        'clock = "time_s"\ntime_constant = 1200.0\norigin = 30.0\n'
        '\n[[parameter]]\nname = "leg3.half_play"\nkind = "backlash"\nelement = "leg3"\n'
    )
    path = tmp_path / "e.params.toml"
    path.write_text(text)
    params = load_parameter_set(path, hexapod.model)
    added = params.parameters[-3:]
    assert added[0].constants_dict == {"phase": "sin", "period_mm": 4.0}
    assert [_parameter(parameter_entry(p), "x") for p in added] == list(added)
    assert params.display_units()[-3:] == ["mm", "ppm/s", "mm"]
    np.testing.assert_allclose(
        params.from_display(params.to_display(np.arange(len(params)) * 1e-7)),
        np.arange(len(params)) * 1e-7,
        rtol=1e-12,
    )
    bad = text.replace("period_mm = 4.0", "harmonic = 1")
    path.write_text(bad)
    with pytest.raises(ParameterError, match="prismatic, so its periodic_error takes period_mm"):
        load_parameter_set(path, hexapod.model)
    with pytest.raises(ParameterError, match="clock"):
        Parameter("x", "drift", "leg1", constants={"time_constant": 3.0})
    with pytest.raises(ParameterError, match="belongs to a periodic_error"):
        Parameter("x", "backlash", "leg1", constants={"phase": "sin"})


def _dataset(mech, n=5, **kw) -> Dataset:
    rng = np.random.default_rng(2)
    commands = random_poses(mech, n, rng)[1]
    m = measure(mech, commands, EXACT, rng)
    return Dataset(
        model=mech.name,
        frame="base",
        actuator_names=mech.actuator_names,
        actuator_units=("mm",) * mech.n_actuators,
        target_names=mech.target_names,
        pose_ids=np.arange(n),
        sets=np.array(["calibration"] * n),
        commands=commands,
        readings=m.readings,
        **kw,
    )


def test_dataset_direction_and_temperature_columns(hexapod, tmp_path):
    d = np.where(np.arange(30).reshape(5, 6) % 3 == 0, -1.0, 1.0)
    ds = _dataset(hexapod, direction=d, temperature_c=np.linspace(20, 22, 5))
    path = write_dataset(ds, tmp_path / "d.csv")
    back = read_dataset(path)
    np.testing.assert_array_equal(back.direction, d)
    np.testing.assert_array_equal(back.temperature_c, ds.temperature_c)
    state = bind_dataset(hexapod, back).state
    np.testing.assert_array_equal(state.direction, d)
    with pytest.raises(DatasetError, match=r"\+1 or -1"):
        _dataset(hexapod, direction=d * 2)
    text = path.read_text().replace(",dir:leg6", "").splitlines()
    text = [text[0]] + [",".join(r.split(",")[:13] + r.split(",")[14:]) for r in text[1:]]
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DatasetError, match="dir:<actuator> for every actuator"):
        read_dataset(path)


def test_a_dataset_lacking_the_column_a_kind_reads_is_refused(hexapod):
    names = hexapod.actuator_names
    ds = _dataset(hexapod)  # no order, time, temperature or directions
    obs = bind_dataset(hexapod, ds)
    for p, column in (
        (Parameter("g", "thermal_growth", names[0], constants={"clock": "time_s"}), "time_s"),
        (Parameter("d", "drift", names[0], constants={"clock": "order"}), "order"),
        (Parameter("t", "thermal_expansion", names[0]), "temperature_c"),
        (Parameter("b", "backlash", names[0]), "dir:<actuator> columns"),
    ):
        model = CalibrationModel(hexapod, ParameterSet([p], hexapod.model))
        model.bind_state(obs.state)
        with pytest.raises(DatasetError, match=column):
            model.predict(np.zeros(1), obs.commands)
