"""The critic-scored planner: the planner's predictions in the agent's observation layout, its backup, its checks."""

import dataclasses

import numpy as np
import pytest
import torch
from configs import env_config

from vical.config_checks import ConfigError
from vical.env.lookahead import Lookahead, Prediction
from vical.evaluation.harness import build_env
from vical.policies.critic_planner import critic_planner_policy
from vical.policies.greedy import greedy_information_policy
from vical.policies.learned import load_run, shipped_policy_dir

POSE = slice(-7, -1)  # the information observation: a value per group, the normalised pose, the step fraction


def _zero_value(planner) -> None:
    """Make the planner's value network return 0 everywhere (its last layer's weights and bias)."""
    params = dict(planner.critic.agent.v.named_parameters())
    last = max(int(name.rsplit(".", 1)[1]) for name in params if name.startswith("mlp.weights."))
    with torch.no_grad():
        params[f"mlp.weights.{last}"].zero_()
        params[f"mlp.biases.{last}"].zero_()


def test_a_predicted_state_is_the_observation_the_agent_then_sees():
    """The value is read at the observation the step is predicted to leave: the layout of the env's own (the
    pose the step heads for, the next step's fraction, each group's feature), checked against the env after it.
    Measured (sensor seeds 11-13): pose within 1e-6, features within 0.008 on average."""
    planner = critic_planner_policy()
    env = build_env(env_config("joint", "practitioner"), planner)
    rng = np.random.default_rng(11)
    try:
        env.reset(seed=11)
        planner.reset(env, rng)
        for _ in range(3):
            env.step(planner.act(None, env))
        action = rng.uniform(env.action_space.low, env.action_space.high)
        prediction = Lookahead(env.state, env.frame, env.pose_offset, env.config, env.step_timing).predict(action)
        fraction = (env.steps + 1) / planner.trained_steps
        predicted = env.state.information_observation(prediction.ratios, prediction.goal, fraction)
        observed, *_ = env.step(action)
    finally:
        env.close()
    assert predicted.shape == observed.shape
    assert predicted[-1] == pytest.approx(observed[-1])
    np.testing.assert_allclose(predicted[POSE], observed[POSE], atol=1e-3)
    assert np.mean(np.abs(predicted[:-7] - observed[:-7])) < 0.05


def test_the_observation_of_the_states_own_ratios_is_the_envs_observation():
    env = build_env(env_config("joint", "practitioner"), greedy_information_policy())
    try:
        observed, _ = env.reset(seed=2)
        fraction = env.steps / env.config.max_steps
        np.testing.assert_array_equal(env.state.information_observation(env.state.ratios, env.pose_offset, fraction),
                                      observed)  # fmt: skip
    finally:
        env.close()


@pytest.mark.integration
def test_with_no_value_after_the_step_it_decides_as_the_planner_and_with_its_value_otherwise():
    """The backup r + gamma d V(s'): V = 0 leaves the planner's own choices, step for step; the trained V changes
    some of them (the value is read, not ignored)."""
    planner, hybrid, zeroed = greedy_information_policy(), critic_planner_policy(), critic_planner_policy()
    _zero_value(zeroed)
    actions = {}
    for name, policy in (("planner", planner), ("hybrid", hybrid), ("zeroed", zeroed)):
        env = build_env(env_config("joint", "practitioner"), policy)
        try:
            env.reset(seed=4)
            policy.reset(env, np.random.default_rng(4))
            actions[name] = [policy.act(None, env)]
            for _ in range(5):
                env.step(actions[name][-1])
                actions[name].append(policy.act(None, env))
        finally:
            env.close()
    np.testing.assert_array_equal(np.array(actions["zeroed"]), np.array(actions["planner"]))
    assert not np.array_equal(np.array(actions["hybrid"]), np.array(actions["planner"]))


def test_the_backup_discounts_by_the_runs_gamma_and_path_and_values_nothing_after_the_goal():
    hybrid = critic_planner_policy()
    env = build_env(env_config("joint", "practitioner"), hybrid)
    try:
        env.reset(seed=6)
        hybrid.reset(env, np.random.default_rng(6))
        ratios = dict(env.state.ratios)
        going = Prediction(np.zeros(6), 1.0, 0.4, 3, ratios, env.state.excess, False)
        done = dataclasses.replace(going, goal_reached=True)
        scores = hybrid.scores([going, done], env)
        rewards = super(type(hybrid), hybrid).scores([going, done], env)
        obs = env.state.information_observation(ratios, np.zeros(6), (env.steps + 1) / hybrid.trained_steps)
        with torch.no_grad():
            value = float(hybrid.critic.agent.v(torch.as_tensor(obs[None]))[0])
    finally:
        env.close()
    reward = load_run(shipped_policy_dir())[1]["config"]["env"]["reward"]
    assert scores[1] == pytest.approx(rewards[1])  # the goal ends the episode: its bonus, no value after it
    assert scores[0] - rewards[0] == pytest.approx(0.95 * reward["path_discount"] ** 0.4 * value, rel=1e-5)
    assert hybrid.gamma == 0.95 and reward["path_discount"] == 0.25  # the shipped run's, as it trained


def test_the_hybrid_refuses_an_env_its_critic_did_not_train_in():
    hybrid = critic_planner_policy()
    env = build_env(env_config("joint", "practitioner", "env.action_scale=[0.2,1.57,1.57,0.6,0.3,0.3]"), hybrid)
    try:
        with pytest.raises(ConfigError, match=r"trained with env\.action_scale"):
            hybrid.reset(env, np.random.default_rng(0))
    finally:
        env.close()
    with pytest.raises(ConfigError, match=r"policy\.samples must be an integer >= 0"):
        critic_planner_policy(samples=-1)
