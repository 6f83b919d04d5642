"""Identification: exact recovery from noise-free data, identifiability analysis, dataset binding.

The truth twin only produces readings; calibration sees the nominal model, the commands and
those readings (the Dataset channel), never the injected values.
"""

from __future__ import annotations

import numpy as np
import pytest

from calib.analysis.identifiability import analyse
from calib.data import Dataset, DatasetError
from calib.exceptions import IdentifiabilityError
from calib.fit.identification import identify
from calib.fit.model import CalibrationModel
from calib.fit.observations import Observations, bind_dataset
from twin.kinematics.batch import forward_batch
from twin.mechanism import Mechanism
from twin.workspace import random_poses


def _readings(hexapod, hexapod_params, table2_values, n_poses: int, seed: int) -> Observations:
    """Commands for random poses and the truth twin's (Table 2) noise-free target readings."""
    truth = Mechanism(hexapod_params.inject(hexapod.model, table2_values))
    _, commands = random_poses(hexapod, n_poses, np.random.default_rng(seed))
    return Observations(commands=commands, measured=forward_batch(truth, commands).targets)


# ----------------------------------------------------------------------------- recovery
@pytest.mark.parametrize(("n_poses", "seed"), [(9, 2), (29, 3)])
def test_noise_free_recovery_of_table2(hexapod, hexapod_params, table2_values, n_poses, seed):
    obs = _readings(hexapod, hexapod_params, table2_values, n_poses, seed)
    result = identify(CalibrationModel(hexapod, hexapod_params), obs)
    assert result.converged
    assert result.report.n_identifiable == 54
    assert result.estimated.all()
    assert result.residual_rms < 1e-12  # metres per coordinate
    assert result.rejected == ()  # round-off is no outlier (the threshold's floor)
    error_mm = np.abs(result.values - table2_values) * 1e3
    worst = result.names[int(np.argmax(error_mm))]
    assert error_mm.max() < 1e-6, f"{worst} off by {error_mm.max():.3g} mm"
    # the errors are not small compared with what was recovered (up to ~0.9 mm)
    assert np.max(np.abs(table2_values)) > 0.5e-3


def test_nominal_readings_identify_zero(hexapod, hexapod_params):
    _, commands = random_poses(hexapod, 9, np.random.default_rng(2))
    obs = Observations(commands, forward_batch(hexapod, commands).targets)
    result = identify(CalibrationModel(hexapod, hexapod_params), obs)
    assert result.iterations <= 2
    assert np.max(np.abs(result.values)) < 1e-12


# ----------------------------------------------------------------------------- analysis
@pytest.fixture(scope="module")
def synthetic():
    """Five columns: a, b, c = a (duplicate), d = 0 (no effect), e."""
    rng = np.random.default_rng(0)
    base = rng.normal(size=(20, 3))
    jac = np.column_stack([base[:, 0], base[:, 1], base[:, 0], np.zeros(20), base[:, 2]])
    return jac, ("a", "b", "c", "d", "e")


def test_analyse_reports_rank_and_reasons(synthetic):
    jac, names = synthetic
    report = analyse(jac, names)
    assert report.n_rows == 20
    assert report.n_parameters == 5
    assert report.rank == 3
    assert report.identifiable == ("a", "b", "e")
    assert report.n_identifiable == 3
    assert set(report.unidentifiable) == {"c", "d"}
    assert "no effect" in report.unidentifiable["d"]
    assert "zero Jacobian column" in report.unidentifiable["d"]
    assert "combination" in report.unidentifiable["c"]
    assert "1 a" in report.unidentifiable["c"]  # c = +1.00 a (scaled)
    assert len(report.singular_values) == 5
    assert report.singular_values[3] < 1e-12 * report.singular_values[0]
    summary = report.summary()
    assert summary.startswith("3 of 5 parameters identifiable (rank 3, 20 equations")
    assert "  c: " in summary and "  d: " in summary


def test_analyse_condition_number_is_that_of_scaled_identifiable_columns(synthetic):
    jac, names = synthetic
    sub = jac[:, [0, 1, 4]]
    expected = np.linalg.cond(sub / np.linalg.norm(sub, axis=0))
    assert analyse(jac, names).condition_number == pytest.approx(expected, rel=1e-12)
    assert 1.0 < expected < 10.0  # a real number, not a degenerate one


def test_analyse_ties_keep_the_earlier_name(synthetic):
    jac, names = synthetic
    # the duplicate pair swapped in position: whichever comes first is kept
    order = [2, 1, 0, 3, 4]
    swapped = analyse(jac[:, order], [names[k] for k in order])
    assert swapped.identifiable == ("c", "b", "e")
    assert set(swapped.unidentifiable) == {"a", "d"}
    assert "1 c" in swapped.unidentifiable["a"]
    # a duplicate scaled by 1000 (same effect, other unit) is still a tie
    scaled = jac.copy()
    scaled[:, 2] *= 1000.0
    assert analyse(scaled, names).identifiable == ("a", "b", "e")
    scaled = jac.copy()
    scaled[:, 0] *= 1000.0
    assert analyse(scaled, names).identifiable == ("a", "b", "e")
    # three identical columns: only the first survives
    triple = np.column_stack([jac[:, 1], jac[:, 0], jac[:, 0], jac[:, 0]])
    report = analyse(triple, ("w", "x", "y", "z"))
    assert report.identifiable == ("w", "x")
    assert set(report.unidentifiable) == {"y", "z"}


def test_analyse_is_deterministic(synthetic):
    jac, names = synthetic
    first, second = analyse(jac, names), analyse(jac.copy(), list(names))
    assert first.identifiable == second.identifiable
    assert first.unidentifiable == second.unidentifiable
    np.testing.assert_array_equal(first.singular_values, second.singular_values)


def test_analyse_is_unit_independent(synthetic):
    jac, names = synthetic
    reference = analyse(jac, names)
    rescaled = jac * np.array([1.0, 1000.0, 1.0, 1.0, 1e-3])
    report = analyse(rescaled, names)
    assert report.rank == reference.rank
    assert report.identifiable == reference.identifiable
    assert report.unidentifiable == reference.unidentifiable
    assert report.condition_number == pytest.approx(reference.condition_number, rel=1e-9)
    np.testing.assert_allclose(report.singular_values, reference.singular_values, atol=1e-9)


def test_analyse_with_fewer_rows_than_columns():
    rng = np.random.default_rng(1)
    report = analyse(rng.normal(size=(3, 5)), ("a", "b", "c", "d", "e"))
    assert report.rank == 3
    assert report.n_identifiable == 3
    assert len(report.unidentifiable) == 2
    for reason in report.unidentifiable.values():
        assert reason.endswith("; 3 equations for 5 parameters")


def test_analyse_rejects_mismatched_names(synthetic):
    jac, _ = synthetic
    with pytest.raises(ValueError, match=r"5 columns but 4 names"):
        analyse(jac, ("a", "b", "c", "d"))


# ----------------------------------------------------------------------------- too few poses
def test_too_few_poses_raise_and_fix(hexapod, hexapod_params, table2_values):
    obs = _readings(hexapod, hexapod_params, table2_values, 5, 4)
    model = CalibrationModel(hexapod, hexapod_params)
    with pytest.raises(IdentifiabilityError, match=r"5 poses cannot identify all 54") as info:
        identify(model, obs)
    result = identify(model, obs, unidentifiable="fix")
    report = result.report
    assert report.rank == report.n_identifiable == 30  # 5 poses x 6 platform DOF
    assert len(report.unidentifiable) == 24
    message = str(info.value)
    for name in report.unidentifiable:
        assert f"  {name}: " in message
    assert int(result.estimated.sum()) == report.n_identifiable
    fixed = ~result.estimated
    np.testing.assert_array_equal(result.values[fixed], 0.0)  # kept at the start value
    assert np.all(np.isnan(result.std_errors[fixed]))
    assert np.all(np.isfinite(result.std_errors[result.estimated]))
    # 30 parameters absorb the 5 poses exactly: the readings are reproduced
    assert result.residual_rms < 1e-12


def test_unknown_unidentifiable_policy(hexapod, hexapod_params):
    _, commands = random_poses(hexapod, 5, np.random.default_rng(4))
    obs = Observations(commands, forward_batch(hexapod, commands).targets)
    with pytest.raises(ValueError, match=r"'raise' or 'fix', got 'drop'"):
        identify(CalibrationModel(hexapod, hexapod_params), obs, unidentifiable="drop")


# ----------------------------------------------------------------------------- datasets
LEGS = tuple(f"leg{i}" for i in range(1, 7))
TARGETS = ("target_1", "target_2", "target_3")


def _dataset(
    actuators: tuple[str, ...] = LEGS,
    units: tuple[str, ...] | None = None,
    frame: str = "base",
    targets: tuple[str, ...] = TARGETS,
    model: str = "hexapod_rrrprr",
) -> Dataset:
    n = 2
    commands = 0.22 + 0.001 * np.arange(n * len(actuators)).reshape(n, len(actuators))
    readings = np.arange(n * len(targets) * 2 * 3, dtype=float).reshape(n, len(targets), 2, 3)
    return Dataset(
        model=model,
        frame=frame,
        actuator_names=actuators,
        actuator_units=units or ("mm",) * len(actuators),
        target_names=targets,
        pose_ids=np.array([17, 4]),
        sets=np.array(["calibration"] * n),
        commands=commands,
        readings=readings,
    )


def test_bind_dataset_orders_like_the_model(hexapod):
    ds = _dataset()
    obs = bind_dataset(hexapod, ds)
    np.testing.assert_array_equal(obs.commands, ds.commands)
    np.testing.assert_array_equal(obs.measured, ds.readings.mean(axis=2))
    assert obs.measured.shape == (2, 3, 3)

    shuffled = _dataset(actuators=LEGS[::-1], targets=TARGETS[::-1])
    obs = bind_dataset(hexapod, shuffled)
    np.testing.assert_array_equal(obs.commands, shuffled.commands[:, ::-1])
    np.testing.assert_array_equal(obs.measured, shuffled.readings.mean(axis=2)[:, ::-1])
    # the labels travel with the data, ordered like the commands and the model's targets
    assert obs.pose_ids == ("17", "4")
    assert obs.target_names == hexapod.target_names == TARGETS


def test_bind_dataset_rejects_another_models_dataset(hexapod):
    with pytest.raises(DatasetError, match=r"model 'delta', but the mechanism is 'hexapod_rrrprr'"):
        bind_dataset(hexapod, _dataset(model="delta"))


def test_observations_without_labels():
    obs = Observations(np.zeros((1, 6)), np.zeros((1, 3, 3)))
    assert obs.pose_ids is None and obs.target_names is None


def test_bind_dataset_rejects_degrees_for_a_prismatic_actuator(hexapod):
    units = ("mm", "mm", "deg", "mm", "mm", "mm")
    with pytest.raises(
        DatasetError, match=r"actuator 'leg3' is prismatic .* unit must be 'mm'.*declares 'deg'"
    ):
        bind_dataset(hexapod, _dataset(units=units))


def test_bind_dataset_takes_base_and_tracker_frames_only(hexapod):
    assert bind_dataset(hexapod, _dataset(frame="tracker")).frame == "tracker"
    assert bind_dataset(hexapod, _dataset(frame="base")).frame == "base"
    with pytest.raises(DatasetError, match=r"dataset frame is 'world'.*'base'.*'tracker'"):
        bind_dataset(hexapod, _dataset(frame="world"))


def test_bind_dataset_rejects_missing_and_unknown_names(hexapod):
    with pytest.raises(DatasetError, match=r"missing actuators \['leg6'\]"):
        bind_dataset(hexapod, _dataset(actuators=LEGS[:5]))
    with pytest.raises(DatasetError, match=r"unknown actuators \['leg7'\]"):
        bind_dataset(hexapod, _dataset(actuators=(*LEGS, "leg7")))
    with pytest.raises(DatasetError, match=r"missing targets \['target_3'\]"):
        bind_dataset(hexapod, _dataset(targets=TARGETS[:2]))


def test_stopping_on_the_predicted_decrease_changes_nothing(hexapod, hexapod_params, table2_values):
    """The Gauss-Newton stop (LMOptions.predicted_rtol) ends where the rejected trial steps
    it saves would have ended: the same estimate as without it, in fewer iterations."""
    from calib.estimators.levenberg_marquardt import LMOptions

    obs = _readings(hexapod, hexapod_params, table2_values, 40, 8)
    rng = np.random.default_rng(8)
    noisy = Observations(obs.commands, obs.measured + rng.normal(0.0, 5e-6, obs.measured.shape))
    model = CalibrationModel(hexapod, hexapod_params)
    fast = identify(model, noisy, robust=False)
    slow = identify(model, noisy, robust=False, options=LMOptions(predicted_rtol=0.0))
    assert fast.converged and slow.converged
    np.testing.assert_allclose(fast.values, slow.values, rtol=0, atol=1e-9)
    assert fast.iterations <= slow.iterations
