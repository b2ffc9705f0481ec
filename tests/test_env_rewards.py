"""Reward terms of the calibration MDP."""

from types import SimpleNamespace

import numpy as np
import pytest

from vical.env.rewards import accuracy_reward, step_reward_terms, terminal_reward_terms
from vical.env.settings import RewardWeights


def test_step_terms_are_weighted_l1_gain_and_executed_motion():
    w = RewardWeights(coverage_weight=100.0, path_weight=5.0, rotation_weight=2.0)
    before = np.zeros(18)
    after = np.zeros(18)
    after[[0, 9, 17]] = [-0.1, 0.02, 0.3]  # a vertex moving outward counts as much as one moving up
    motion = SimpleNamespace(path_length=0.25, rotation_length=0.5)
    terms = step_reward_terms(before, after, motion, w)
    assert terms == pytest.approx({"coverage": 100 * 0.42, "path": -1.25, "rotation": -1.0})


def test_accuracy_reward_is_the_authors_inverse_error_capped_at_the_floor():
    w = RewardWeights(accuracy_weight=100.0, accuracy_error_floor=0.1)
    assert accuracy_reward(1.0, w) == pytest.approx(10.0)  # the authors' 0.1 / 0.01
    assert accuracy_reward(0.2, w) == pytest.approx(50.0)
    assert accuracy_reward(0.01, w) == pytest.approx(100.0)  # capped
    assert accuracy_reward(0.0, w) == pytest.approx(100.0)
    assert accuracy_reward(None, w) == 0.0
    assert accuracy_reward(float("nan"), w) == 0.0


def test_terminal_terms_pay_the_bonus_even_when_calibration_failed():
    w = RewardWeights(terminal_bonus=100.0, accuracy_weight=100.0, accuracy_error_floor=0.1)
    assert terminal_reward_terms(0.5, w) == pytest.approx({"terminal": 100.0, "accuracy": 20.0})
    assert terminal_reward_terms(None, w) == {"terminal": 100.0, "accuracy": 0.0}
