import math

import numpy as np
import pytest

from twin.rotations import matrix_from_rpy, rotvec_from_matrix
from twin.tracker import PoseNoise, Tracker, TrackerNoise

HEAD = np.array([1.2, 0.0, 0.3])
N_SAMPLES = 200_000


def _point_at(distance: float) -> np.ndarray:
    direction = np.array([-2.0, 1.0, 0.5])
    return HEAD + distance * direction / np.linalg.norm(direction)


def test_gaussian_std_at_two_metres() -> None:
    tracker = Tracker(tuple(HEAD), TrackerNoise.from_spec("10 um + 5 um/m"))
    point = _point_at(2.0)
    points = np.broadcast_to(point, (N_SAMPLES, 3))
    readings = tracker.measure(points, np.random.default_rng(0))
    assert readings.shape == (N_SAMPLES, 1, 3)
    err = readings[:, 0, :] - point
    assert np.std(err) == pytest.approx(20e-6, rel=0.02)
    assert np.all(np.abs(np.mean(err, axis=0)) < 5 * 20e-6 / math.sqrt(N_SAMPLES))
    assert tracker.noise_sigma(point) == pytest.approx(20e-6, rel=1e-12)


def test_uniform_bounds_and_std() -> None:
    noise = TrackerNoise.from_spec("uniform 10 um + 5 um/m")
    tracker = Tracker(tuple(HEAD), noise)
    point = _point_at(2.0)
    half_width = 20e-6
    err = tracker.measure(np.broadcast_to(point, (N_SAMPLES, 3)), np.random.default_rng(1)) - point
    assert np.max(np.abs(err)) <= half_width * (1 + 1e-12)
    assert np.max(np.abs(err)) > 0.99 * half_width
    assert np.std(err) == pytest.approx(half_width / math.sqrt(3), rel=0.02)
    assert tracker.noise_sigma(point) == pytest.approx(half_width / math.sqrt(3), rel=1e-12)


@pytest.mark.parametrize("kind", ["gaussian", "uniform"])
def test_averaging_repeats(kind: str) -> None:
    repeats = 4
    noise = TrackerNoise(kind, 10e-6, 5e-6)
    tracker = Tracker(tuple(HEAD), noise, repeats=repeats)
    point = _point_at(2.0)
    points = np.broadcast_to(point, (N_SAMPLES, 3))
    raw = tracker.measure(points, np.random.default_rng(2))
    assert raw.shape == (N_SAMPLES, repeats, 3)
    single_std = np.std(raw - point)
    avg = tracker.measure_averaged(points, np.random.default_rng(3))
    assert avg.shape == (N_SAMPLES, 3)
    avg_std = np.std(avg - point)
    assert single_std / avg_std == pytest.approx(math.sqrt(repeats), rel=0.03)
    expected = tracker.noise_sigma(point, averaged=True)
    assert avg_std == pytest.approx(expected, rel=0.03)
    assert expected == pytest.approx(tracker.noise_sigma(point) / 2, rel=1e-12)


def test_scale_error_changes_distance_exactly() -> None:
    tracker = Tracker(tuple(HEAD), TrackerNoise.none(), scale_error=1e-5)
    point = _point_at(3.0)
    reading = tracker.measure_averaged(point, np.random.default_rng(4))
    d_true = np.linalg.norm(point - HEAD)
    d_meas = np.linalg.norm(reading - HEAD)
    assert d_meas - d_true == pytest.approx(30e-6, abs=1e-12)
    # the direction from the head is unchanged
    np.testing.assert_allclose((reading - HEAD) / d_meas, (point - HEAD) / d_true, atol=1e-15)


def test_none_gives_exact_points() -> None:
    tracker = Tracker(noise=TrackerNoise.none(), repeats=3)
    points = np.random.default_rng(5).uniform(-1.0, 1.0, size=(4, 5, 3))
    readings = tracker.measure(points, np.random.default_rng(6))
    assert readings.shape == (4, 5, 3, 3)
    assert np.array_equal(readings, np.broadcast_to(points[..., None, :], readings.shape))
    assert np.array_equal(tracker.measure_averaged(points, np.random.default_rng(6)), points)
    assert np.array_equal(tracker.noise_sigma(points), np.zeros((4, 5)))


def test_noise_sigma_shape_and_values() -> None:
    tracker = Tracker(noise=TrackerNoise("gaussian", 10e-6, 5e-6))
    points = np.stack([_point_at(0.0), _point_at(1.0), _point_at(4.0)])
    np.testing.assert_allclose(tracker.noise_sigma(points), [10e-6, 15e-6, 30e-6], rtol=1e-12)
    assert tracker.position_m == (1.2, 0.0, 0.3)


def test_measure_validation() -> None:
    tracker = Tracker()
    bad = np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    with pytest.raises(ValueError, match="non-finite"):
        tracker.measure(bad, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        tracker.measure(np.zeros((2, 2)), np.random.default_rng(0))
    with pytest.raises(ValueError, match="repeats"):
        Tracker(repeats=0)
    with pytest.raises(ValueError, match="scale_error"):
        Tracker(scale_error=-1.0)
    with pytest.raises(ValueError, match="kind"):
        TrackerNoise("laplace", 1e-6, 0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="constant_m"):
        TrackerNoise("gaussian", -1e-6, 0.0)


@pytest.mark.parametrize(
    ("spec", "kind", "constant", "per_metre"),
    [
        ("10 um + 5 um/m", "gaussian", 10e-6, 5e-6),
        ("0.005 mm", "gaussian", 5e-6, 0.0),
        ("gaussian 10um+5um/m", "gaussian", 10e-6, 5e-6),
        ("uniform 0.02 mm", "uniform", 20e-6, 0.0),
        ("Uniform 5 um/m + 0.01 mm", "uniform", 10e-6, 5e-6),
        ("15 µm + 6 ppm", "gaussian", 15e-6, 6e-6),
        ("1e-5 m", "gaussian", 10e-6, 0.0),
        ("none", "none", 0.0, 0.0),
    ],
)
def test_from_spec(spec: str, kind: str, constant: float, per_metre: float) -> None:
    noise = TrackerNoise.from_spec(spec)
    assert noise.kind == kind
    assert noise.constant_m == pytest.approx(constant, rel=1e-12, abs=0.0)
    assert noise.per_metre == pytest.approx(per_metre, rel=1e-12, abs=0.0)
    again = TrackerNoise.from_spec(noise.describe())
    assert again.kind == noise.kind
    assert again.constant_m == pytest.approx(noise.constant_m, rel=1e-12, abs=0.0)
    assert again.per_metre == pytest.approx(noise.per_metre, rel=1e-12, abs=0.0)


@pytest.mark.parametrize(
    "spec",
    [
        "",
        "   ",
        "garbage",
        "10",
        "10 furlongs",
        "10 um +",
        "10 um 5 um/m",
        "10 um + 5 um",
        "5 um/m + 1 ppm",
        "-10 um",
        "gaussian",
        "none 10 um",
        "poisson 10 um",
        "10 um * 2",
    ],
)
def test_from_spec_rejects_garbage(spec: str) -> None:
    with pytest.raises(ValueError, match=r"noise spec|empty"):
        TrackerNoise.from_spec(spec)


def test_describe() -> None:
    assert TrackerNoise("gaussian", 10e-6, 5e-6).describe() == "gaussian 10 um + 5 um/m"
    assert TrackerNoise("uniform", 20e-6, 0.0).describe() == "uniform 20 um"
    assert TrackerNoise.none().describe() == "none"


def test_pose_noise_uniform_bounds() -> None:
    rng = np.random.default_rng(8)
    noise = PoseNoise("uniform", 0.02e-3, math.radians(0.004))
    n = 50_000
    R = matrix_from_rpy(rng.uniform(-1.0, 1.0, size=(n, 3)))
    p = rng.uniform(-0.5, 0.5, size=(n, 3))
    R_noisy, p_noisy = noise.perturb(R, p, rng)
    assert R_noisy.shape == (n, 3, 3) and p_noisy.shape == (n, 3)
    dp = p_noisy - p
    dtheta = rotvec_from_matrix(R_noisy @ np.swapaxes(R, -1, -2))
    tiny = 1e-12
    assert np.all(np.abs(dp) <= 0.02e-3 + tiny)
    assert np.all(np.abs(dtheta) <= math.radians(0.004) + tiny)
    # every axis spans its full range and has the uniform standard deviation
    np.testing.assert_array_less(0.98 * 0.02e-3, np.max(np.abs(dp), axis=0))
    np.testing.assert_array_less(0.98 * math.radians(0.004), np.max(np.abs(dtheta), axis=0))
    np.testing.assert_allclose(np.std(dp, axis=0), 0.02e-3 / math.sqrt(3), rtol=0.03)
    np.testing.assert_allclose(
        np.std(dtheta, axis=0), math.radians(0.004) / math.sqrt(3), rtol=0.03
    )
    np.testing.assert_allclose(
        R_noisy @ np.swapaxes(R_noisy, -1, -2), np.broadcast_to(np.eye(3), (n, 3, 3)), atol=1e-14
    )


def test_pose_noise_gaussian_and_batching() -> None:
    rng = np.random.default_rng(9)
    noise = PoseNoise("gaussian", 1e-5, 1e-4)
    R = np.broadcast_to(np.eye(3), (200, 100, 3, 3))
    p = np.zeros((200, 100, 3))
    R_noisy, p_noisy = noise.perturb(R, p, rng)
    assert R_noisy.shape == (200, 100, 3, 3)
    assert np.std(p_noisy) == pytest.approx(1e-5, rel=0.02)
    assert np.std(rotvec_from_matrix(R_noisy)) == pytest.approx(1e-4, rel=0.02)
    with pytest.raises(ValueError, match="p must have shape"):
        noise.perturb(R, np.zeros((200, 3)), rng)
    with pytest.raises(ValueError, match="kind"):
        PoseNoise("none", 0.0, 0.0)  # type: ignore[arg-type]
