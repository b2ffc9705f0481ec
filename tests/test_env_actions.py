"""The MDP's action parametrisation and its inverse."""

import numpy as np
import pytest

from vical.env.actions import action_to_step, direction, step_to_action


def test_direction_convention():
    np.testing.assert_allclose(direction(0.0, np.pi / 2), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(direction(np.pi / 2, np.pi / 2), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(direction(0.3, 0.0), [0, 0, 1], atol=1e-12)


def test_action_to_step_scales_direction_and_copies_euler():
    translation, euler = action_to_step(np.array([0.2, 0.0, np.pi / 2, 0.1, -0.2, 0.3]))
    np.testing.assert_allclose(translation, [0.2, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(euler, [0.1, -0.2, 0.3])
    translation, _ = action_to_step(np.array([-0.1, 0.0, 0.0, 0, 0, 0]))
    np.testing.assert_allclose(translation, [0.0, 0.0, -0.1], atol=1e-12)


def test_step_to_action_inverts_every_direction_within_the_authors_angle_range():
    rng = np.random.default_rng(0)
    for _ in range(500):
        translation = rng.normal(size=3) * rng.uniform(0.0, 0.3)
        euler = rng.uniform(-0.4, 0.4, 3)
        action = step_to_action(translation, euler)
        assert abs(action[0]) == pytest.approx(np.linalg.norm(translation))
        assert np.all(np.abs(action[1:3]) <= np.pi / 2 + 1e-12)
        back, back_euler = action_to_step(action)
        np.testing.assert_allclose(back, translation, atol=1e-12)
        np.testing.assert_allclose(back_euler, euler)


def test_zero_translation_gives_zero_length():
    np.testing.assert_array_equal(step_to_action(np.zeros(3), np.zeros(3)), np.zeros(6))


def test_bad_action_is_refused_with_its_layout():
    with pytest.raises(ValueError, match="rho"):
        action_to_step(np.array([0.1, np.nan, 0, 0, 0, 0]))
    with pytest.raises(ValueError, match="6 finite numbers"):
        action_to_step(np.zeros(5))
