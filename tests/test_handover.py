"""The learned policy, then the planner: the learned steps as in its own episodes, the planner's after the handover."""

import numpy as np
import pytest
from configs import env_config

from vical.config_checks import ConfigError
from vical.evaluation.harness import build_env
from vical.policies.greedy import greedy_information_policy
from vical.policies.handover import DEFAULT_STEPS, handover_policy
from vical.policies.learned import learned_policy

STEPS = 4  # steps of each part compared


def _actions(policy, env_cfg: dict, seed: int, steps: int = STEPS, replay: list[np.ndarray] = ()) -> list[np.ndarray]:
    """``replay``'s actions, then ``steps`` of ``policy``'s, on the sensor of ``seed`` in ``policy``'s env."""
    env = build_env(env_cfg, policy)
    try:
        obs, _ = env.reset(seed=seed)
        policy.reset(env, np.random.default_rng(seed))
        actions = []
        for action in [*replay, *[None] * steps]:
            action = policy.act(obs, env) if action is None else action
            actions.append(action)
            obs, *_ = env.step(action)
        return actions
    finally:
        env.close()


def test_it_acts_as_the_learned_policy_in_its_own_episode_and_then_as_the_planner_from_where_it_handed_over():
    env_cfg = env_config("joint", "practitioner")
    hybrid = handover_policy()  # the shipped policy (40 steps), then the planner, 120 steps in all
    assert (hybrid.handover, hybrid.max_steps) == (40, DEFAULT_STEPS)
    # The learned steps: the shipped policy's in its own 40-step episode, though the hybrid's env has 120 steps (the
    # observation's step fraction is of the run's limit).
    own = _actions(learned_policy(), env_cfg, seed=5)
    np.testing.assert_array_equal(_actions(hybrid, env_cfg, seed=5), own)
    # After the handover (made early here): the planner's decisions from the state the learned steps left.
    hybrid = handover_policy()
    hybrid.handover = STEPS
    acted = _actions(hybrid, env_cfg, seed=5, steps=2 * STEPS)
    np.testing.assert_array_equal(acted[:STEPS], own)
    planner = greedy_information_policy(max_steps=DEFAULT_STEPS)
    planned = _actions(planner, env_cfg, seed=5, replay=own)
    np.testing.assert_array_equal(acted[STEPS:], planned[STEPS:])
    assert len(hybrid.decision_times) == STEPS  # the planner's steps only


def test_the_hybrid_refuses_an_env_its_learned_run_did_not_train_in():
    hybrid = handover_policy()
    env = build_env(env_config("joint", "paper"), greedy_information_policy())  # another workspace and action box
    try:
        with pytest.raises(ConfigError, match="trained in workspace 'practitioner'"):
            hybrid.reset(env, np.random.default_rng(0))
    finally:
        env.close()
