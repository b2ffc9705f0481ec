"""The two-step planner: its second-step predictions against what the env then records, its choice, its settings."""

import hydra.utils
import numpy as np
import pytest
from configs import env_config
from scipy.stats import spearmanr

from vical.config_checks import ConfigError
from vical.env.lookahead import Lookahead
from vical.evaluation.harness import build_env
from vical.policies.greedy import axis_actions, candidate_actions, greedy_information_policy, predicted_moves
from vical.policies.two_step import DEFAULT_BRANCHES, two_step_planner_policy

STEPS = 4  # planned steps compared


def _planned(policy, seed: int, steps: int = STEPS) -> list[np.ndarray]:
    """``steps`` of ``policy``'s actions on the practitioner's sensor of ``seed`` (joint task)."""
    env = build_env(env_config("joint", "practitioner"), policy)
    try:
        obs, _ = env.reset(seed=seed)
        policy.reset(env, np.random.default_rng(seed))
        actions = []
        for _ in range(steps):
            actions.append(policy.act(obs, env))
            obs, *_ = env.step(actions[-1])
        return actions
    finally:
        env.close()


def test_a_second_predicted_step_sheds_the_excess_the_two_recorded_steps_then_shed():
    """Random pairs of steps: the second step predicted from the first's prediction (``Lookahead.following``) against
    the information state after both are recorded; the first prediction's fork is left as it was."""
    env = hydra.utils.instantiate(env_config("joint", "practitioner", "env=information"))
    rng = np.random.default_rng(8)
    predicted, recorded = [], []
    try:
        env.reset(seed=8)
        env.step(rng.uniform(env.action_space.low, env.action_space.high))  # a first frame poses the board
        for _ in range(8):
            first, second = rng.uniform(env.action_space.low, env.action_space.high, (2, 6))
            before = env.state.excess
            lookahead = Lookahead(env.state, env.frame, env.pose_offset, env.config, env.step_timing)
            prediction = lookahead.predict(first)
            information = prediction.tracker.information.copy()
            after = lookahead.following(prediction)
            np.testing.assert_array_equal(after.offset, prediction.goal)
            predicted.append(before - after.predict(second).excess)
            np.testing.assert_array_equal(prediction.tracker.information, information)
            env.step(first)
            env.step(second)
            recorded.append(before - env.state.excess)
    finally:
        env.close()
    predicted, recorded = np.array(predicted), np.array(recorded)
    assert spearmanr(predicted, recorded)[0] > 0.8, (predicted, recorded)
    assert np.mean(np.abs(predicted - recorded)) < 0.4 * np.mean(np.abs(recorded)), (predicted, recorded)


def test_a_fork_of_a_fork_weighs_its_frames_by_its_own_weight():
    env = hydra.utils.instantiate(env_config("joint", "practitioner", "env=information"))
    try:
        env.reset(seed=3)
        tracker = env.state.information
        sigma = tracker.pixel_sigma
        assert tracker.fork(4.0).pixel_sigma == pytest.approx(sigma / 2)
        assert tracker.fork(4.0).fork(9.0).pixel_sigma == pytest.approx(sigma / 3)
        assert tracker.fork(4.0).fork(1.0).pixel_sigma == pytest.approx(sigma)
    finally:
        env.close()


def test_it_takes_the_best_first_step_by_its_two_steps_reward():
    """Each decision of an episode recomputed from the lookahead's pieces: the branches are the best one-step scores,
    each valued with its best axis move after it; the planner takes the best valued."""
    planner = two_step_planner_policy()
    env = build_env(env_config("joint", "practitioner"), planner)
    generator = np.random.default_rng(6)
    try:
        obs, _ = env.reset(seed=6)
        planner.reset(env, generator)
        obs, *_ = env.step(planner.act(obs, env))  # a frame poses the board
        for _ in range(STEPS):
            rng = np.random.default_rng()
            rng.bit_generator.state = generator.bit_generator.state  # the draws the planner is about to make
            lookahead = Lookahead(env.state, env.frame, env.pose_offset, env.config, env.step_timing)
            actions, predictions = predicted_moves(lookahead, candidate_actions(env.action_space.high, 12, rng))
            first = np.array([planner.score(p, env.state.excess, env) for p in predictions])
            values = {}
            for i in np.argsort(-first)[:DEFAULT_BRANCHES]:
                _, after = predicted_moves(lookahead.following(predictions[i]), axis_actions(env.action_space.high))
                second = max(planner.score(p, predictions[i].excess, env) for p in after)
                values[i] = first[i] + (0.0 if predictions[i].goal_reached else second)
            expected = actions[max(values, key=values.get)]
            action = planner.act(obs, env)
            np.testing.assert_array_equal(action, expected)
            obs, *_ = env.step(action)
    finally:
        env.close()
    assert len(planner.decision_times) == STEPS + 1


def test_with_one_branch_it_is_the_greedy_planner():
    np.testing.assert_array_equal(
        _planned(two_step_planner_policy(branches=1), seed=5), _planned(greedy_information_policy(), seed=5)
    )


@pytest.mark.parametrize("branches", [0, 1.5, True, "2"])
def test_bad_branches_are_refused_by_key(branches):
    with pytest.raises(ConfigError, match=r"policy\.branches"):
        two_step_planner_policy(branches=branches)
