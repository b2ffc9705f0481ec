"""IMU simulation: window averaging, Kalibr noise statistics, streaming, physics readings vs kinematics."""

import numpy as np
import pytest

from vical.data import ImuNoise
from vical.sim.imu import ImuNoiseProcess, ImuSimulationError, ImuSimulator, discrete_sigmas, window_weights

STEP_NS = 1_000_000  # 1 ms physics step


@pytest.mark.parametrize("n", [1, 2, 4, 5, 10])
def test_average_window_integrates_the_sample_interval(n):
    offsets, weights = window_weights(n, "average")
    assert weights.sum() == pytest.approx(1.0)
    # Symmetric about the sample instant: no group delay.
    np.testing.assert_array_equal(offsets, -offsets[::-1])
    np.testing.assert_allclose(weights, weights[::-1])
    # Exact for a line; the quadratic's window mean (t^2 over [-n/2, n/2] -> n^2/12) within the rule's error.
    assert weights @ (3.0 * offsets + 1.0) == pytest.approx(1.0)
    rule_error = (1.0 / 6.0 if n % 2 == 0 else -1.0 / 12.0) if n > 1 else -n * n / 12.0
    assert weights @ offsets.astype(float) ** 2 == pytest.approx(n * n / 12.0 + rule_error)


def test_instant_window_is_one_reading():
    offsets, weights = window_weights(5, "instant")
    assert offsets.tolist() == [0] and weights.tolist() == [1.0]


def test_discrete_sigmas_follow_kalibr():
    sig = discrete_sigmas(ImuNoise(rate_hz=200.0))
    assert sig["accel_white"] == pytest.approx(0.004 * np.sqrt(200.0))
    assert sig["gyro_white"] == pytest.approx(0.0003394 * np.sqrt(200.0))
    assert sig["accel_walk"] == pytest.approx(0.006 / np.sqrt(200.0))
    assert sig["gyro_walk"] == pytest.approx(0.000038785 / np.sqrt(200.0))


def test_noise_statistics_match_the_densities():
    noise = ImuNoise(rate_hz=200.0)
    bias0_gyro, bias0_accel = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.2, -0.3])
    process = ImuNoiseProcess(noise, np.random.default_rng(11), bias0_gyro, bias0_accel)
    n = 200_000
    gyro, accel, biases = process.apply(np.zeros((n, 3)), np.zeros((n, 3)))
    np.testing.assert_array_equal(biases[0], np.concatenate([bias0_gyro, bias0_accel]))
    sig = discrete_sigmas(noise)
    white = np.hstack([gyro, accel]) - biases
    increments = np.diff(biases, axis=0)
    expected_white = [sig["gyro_white"]] * 3 + [sig["accel_white"]] * 3
    expected_walk = [sig["gyro_walk"]] * 3 + [sig["accel_walk"]] * 3
    # Variance within 10 % (its relative sigma over 2e5 samples is 0.3 %).
    np.testing.assert_allclose(white.var(axis=0), np.square(expected_white), rtol=0.1)
    np.testing.assert_allclose(increments.var(axis=0), np.square(expected_walk), rtol=0.1)
    # White noise is uncorrelated from sample to sample; the walk's increments too.
    assert abs(np.corrcoef(white[:-1, 0], white[1:, 0])[0, 1]) < 0.01
    assert abs(np.corrcoef(increments[:-1, 3], increments[1:, 3])[0, 1]) < 0.01


def test_bias_walk_grows_like_sqrt_time():
    noise = ImuNoise(rate_hz=200.0)
    runs = [ImuNoiseProcess(noise, np.random.default_rng(s), np.zeros(3), np.zeros(3)) for s in range(400)]
    final = np.array([r.apply(np.zeros((2001, 3)), np.zeros((2001, 3)))[2][-1] for r in runs])
    seconds = 2000 / 200.0
    np.testing.assert_allclose(final[:, 3:].std(axis=0), 0.006 * np.sqrt(seconds), rtol=0.15)


def test_noise_does_not_depend_on_chunking():
    noise = ImuNoise(rate_hz=200.0)
    whole = ImuNoiseProcess(noise, np.random.default_rng(5), np.zeros(3), np.zeros(3))
    parts = ImuNoiseProcess(noise, np.random.default_rng(5), np.zeros(3), np.zeros(3))
    truth = np.arange(60.0).reshape(20, 3)
    g_whole, a_whole, _ = whole.apply(truth, truth)
    pieces = [parts.apply(truth[i:j], truth[i:j]) for i, j in [(0, 3), (3, 4), (4, 20)]]
    np.testing.assert_array_equal(np.vstack([p[0] for p in pieces]), g_whole)
    np.testing.assert_array_equal(np.vstack([p[1] for p in pieces]), a_whole)


def _feed(sim, steps, signal):
    for k in steps:
        t = k * STEP_NS
        sim.add_reading(t, signal(t), 2.0 * signal(t))


def test_streaming_average_of_a_known_signal():
    # A cubic in time: the centred average of 5 readings is the value at the centre plus a known term.
    def signal(t_ns):
        s = t_ns * 1e-9
        return np.array([s, s**2, s**3])

    sim = ImuSimulator(STEP_NS, 5, "average")
    _feed(sim, range(3, 40), signal)
    samples = sim.samples()
    # First sample whose window [t-2, t+2] ms lies inside the readings from 3 ms: t = 5 ms; last: t = 35 ms.
    assert samples.t.tolist() == [5_000_000 * k for k in range(1, 8)]
    s = samples.t * 1e-9
    mean_sq = 2.0 * (1e-3) ** 2  # mean of (k dt)^2, k = -2..2
    np.testing.assert_allclose(samples.gyro[:, 0], s, atol=1e-15)
    np.testing.assert_allclose(samples.gyro[:, 1], s**2 + mean_sq, atol=1e-15)
    np.testing.assert_allclose(samples.gyro[:, 2], s**3 + 3 * s * mean_sq, atol=1e-15)
    np.testing.assert_allclose(samples.accel, 2.0 * samples.gyro, atol=1e-15)


def test_instant_samples_are_the_readings_on_the_imu_grid():
    sim = ImuSimulator(STEP_NS, 5, "instant")
    _feed(sim, range(0, 23), lambda t: np.full(3, t * 1e-9))
    samples = sim.samples()
    assert samples.t.tolist() == [0, 5_000_000, 10_000_000, 15_000_000, 20_000_000]
    np.testing.assert_allclose(samples.gyro[:, 0], samples.t * 1e-9)


def test_streaming_equals_one_batch_and_noise_is_seeded():
    def make():
        return ImuSimulator(STEP_NS, 5, "average", ImuNoise(), np.random.default_rng(2), np.ones(3), np.zeros(3))

    a, b = make(), make()
    signal = lambda t: np.sin(np.arange(3) + t * 1e-8)  # noqa: E731
    _feed(a, range(100), signal)
    _feed(b, range(50), signal)
    b.samples()  # a query in the middle changes nothing
    _feed(b, range(50, 100), signal)
    np.testing.assert_array_equal(a.samples().gyro, b.samples().gyro)
    np.testing.assert_array_equal(a.samples().accel, b.samples().accel)


def test_missing_physics_step_is_an_error():
    sim = ImuSimulator(STEP_NS, 5, "average")
    sim.add_reading(0, np.zeros(3), np.zeros(3))
    with pytest.raises(ImuSimulationError, match="every physics step: expected t = 1000000 ns, got 2000000 ns"):
        sim.add_reading(2 * STEP_NS, np.zeros(3), np.zeros(3))
    with pytest.raises(ImuSimulationError, match="not on the physics grid"):
        sim.add_reading(STEP_NS + 7, np.zeros(3), np.zeros(3))


def test_noise_needs_a_generator():
    with pytest.raises(ValueError, match="seeded numpy Generator"):
        ImuSimulator(STEP_NS, 5, "average", ImuNoise())
