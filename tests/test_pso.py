"""The particle swarm optimiser: finds known minima, stays in its box, is deterministic per seed."""

import numpy as np
import pytest

from vical.policies.pso import PsoSettings, minimize


def sphere(center):
    return lambda x: float(np.sum((x - center) ** 2))


def rosenbrock(x):
    return float((1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2)


def test_finds_shifted_sphere_minimum():
    center = np.array([0.3, -1.2, 0.7, 2.1, -0.4])
    result = minimize(sphere(center), -3 * np.ones(5), 3 * np.ones(5), PsoSettings(particles=30, iterations=150))
    np.testing.assert_allclose(result.position, center, atol=1e-3)
    assert result.value < 1e-6


def test_finds_rosenbrock_minimum_in_2d():
    result = minimize(rosenbrock, [-2, -2], [2, 2], PsoSettings(particles=30, iterations=200, seed=1))
    np.testing.assert_allclose(result.position, [1.0, 1.0], atol=2e-2)
    assert result.value < 1e-3


def test_every_evaluated_point_lies_in_the_box_and_the_bound_is_found():
    lower, upper = np.array([-1.0, 0.0]), np.array([1.0, 0.5])
    seen = []

    def objective(x):
        seen.append(x.copy())
        return sphere(np.array([3.0, -2.0]))(x)  # minimum outside the box: at the corner (1, 0)

    result = minimize(objective, lower, upper, PsoSettings(particles=10, iterations=60))
    points = np.array(seen)
    assert len(points) == result.evaluations == 10 * 61
    assert np.all(points >= lower) and np.all(points <= upper)
    np.testing.assert_allclose(result.position, [1.0, 0.0], atol=1e-6)


def test_same_seed_same_run_other_seed_other_run():
    settings = PsoSettings(particles=8, iterations=10, seed=7)
    a = minimize(rosenbrock, [-2, -2], [2, 2], settings)
    b = minimize(rosenbrock, [-2, -2], [2, 2], settings)
    c = minimize(rosenbrock, [-2, -2], [2, 2], PsoSettings(particles=8, iterations=10, seed=8))
    np.testing.assert_array_equal(a.position, b.position)
    assert a.history == b.history
    assert a.history != c.history


def test_stops_early_without_improvement_and_reports_progress():
    calls = []
    result = minimize(lambda x: 1.0, [0, 0], [1, 1], PsoSettings(particles=4, iterations=50, patience=3), calls.append)
    assert result.stopped_early and result.iterations == 3
    assert [p.iteration for p in calls] == [0, 1, 2, 3]
    assert [p.evaluations for p in calls] == [4, 8, 12, 16]
    assert all(p.best_value == 1.0 and p.values.shape == (4,) for p in calls)


def test_failed_evaluations_never_become_the_best():
    result = minimize(lambda x: float("nan") if x[0] < 0 else x[0], [-1], [1], PsoSettings(particles=6, iterations=20))
    assert np.isfinite(result.value) and result.position[0] >= 0


@pytest.mark.parametrize(
    "lower, upper, match",
    [([0, 0], [1], "one shape"), ([0, 1], [1, 1], "upper > lower"), ([0, -np.inf], [1, 1], "finite")],
)
def test_bad_bounds_are_refused(lower, upper, match):
    with pytest.raises(ValueError, match=match):
        minimize(rosenbrock, lower, upper)


@pytest.mark.parametrize("kwargs", [{"particles": 1}, {"inertia": 1.2}, {"max_velocity": 0.0}, {"patience": -1}])
def test_bad_settings_are_refused(kwargs):
    with pytest.raises(ValueError, match="PSO needs"):
        PsoSettings(**kwargs)
