"""The stopping rule: each policy's own, or the learned policy's information state for every baseline."""

import dataclasses

import hydra.utils
import numpy as np
import pytest
from configs import env_config, resolved_policy

from vical.config_checks import ConfigError
from vical.evaluation.harness import (
    PolicyEvaluator,
    PolicySpec,
    build_env,
    instantiate_policy,
    policy_mdp,
    run_trajectory,
)
from vical.policies.learned import (
    INFORMATION_POLICY_DIR,
    PAPER_POLICY_DIR,
    carried_settings,
    learned_policy,
    load_run,
)
from vical.policies.stopping import InformationStop, StopRule, with_stop

INFORMATION = StopRule("information")
TASKS = ("intrinsic", "extrinsic", "joint")


def expert(task: str = "intrinsic", length: str = "long"):
    return instantiate_policy({"_target_": "vical.policies.expert.expert_policy", "task": task, "length": length}, "x")


def shipped_settings() -> dict:
    return carried_settings(load_run(INFORMATION_POLICY_DIR)[1]["config"]["env"])


def test_a_baseline_takes_the_shipped_policys_state_tolerances_and_step_limit_and_keeps_its_motion():
    trajectory = expert()
    stopped = with_stop(trajectory, INFORMATION)
    settings = shipped_settings()
    assert isinstance(stopped, InformationStop) and stopped.policy is trajectory
    assert stopped.stop_at_coverage and not trajectory.stop_at_coverage
    assert dict(stopped.env_settings) == {"state": "information", "information": settings["information"]}
    assert stopped.max_steps == trajectory.max_steps  # a trajectory's own length
    random = instantiate_policy({"_target_": "vical.policies.random_policy.RandomMovingPolicy"}, "random")
    assert with_stop(random, INFORMATION).max_steps == settings["max_steps"]  # no limit of its own: the learned run's
    assert with_stop(trajectory, StopRule()) is trajectory  # stop=policy: the policy's own rule


def test_the_rules_step_limit_reaches_every_policy_without_its_own_and_the_planner():
    rule = StopRule("information", max_steps=200, horizon_s=45.0)
    random = instantiate_policy({"_target_": "vical.policies.random_policy.RandomMovingPolicy"}, "random")
    assert with_stop(random, rule).max_steps == 200
    assert with_stop(expert(), rule).max_steps == expert().max_steps  # a trajectory keeps its own length
    planner = PolicySpec.from_config(resolved_policy("greedy_information", "stop=information", "stop.max_steps=200"))
    assert instantiate_policy(planner.joint, planner.name).max_steps == 200
    default = PolicySpec.from_config(resolved_policy("greedy_information"))
    assert instantiate_policy(default.joint, default.name).max_steps == shipped_settings()["max_steps"]


def test_a_learned_policy_keeps_its_own_information_rule_and_one_of_another_state_is_refused():
    learned = learned_policy()
    assert with_stop(learned, INFORMATION) is learned
    paper = learned_policy(workspace="paper")  # trained on the coverage state: its actions need it
    with pytest.raises(ConfigError, match=r"stop=information: policy .*\(coverage\).*stop=policy"):
        with_stop(paper, INFORMATION)


def test_the_rule_is_read_only_from_a_run_of_the_information_state():
    with pytest.raises(ConfigError, match=r"trained on the coverage state: name one with stop\.run_dir"):
        with_stop(expert(), StopRule("information", run_dir=str(PAPER_POLICY_DIR)))
    with pytest.raises(ConfigError, match="stop=information: vical ships no learned policy for workspace 'lab'"):
        with_stop(expert(), StopRule("information", workspace="lab"))
    with pytest.raises(ConfigError, match=r"stop\.rule"):
        StopRule("coverage")
    with pytest.raises(ConfigError, match=r"stop: unknown setting\(s\) \['tolerance'\]"):
        StopRule.from_config({"rule": "information", "tolerance": 1})


def test_an_episode_ends_at_the_first_step_after_which_every_group_is_predicted_within_tolerance():
    env_cfg = env_config("intrinsic", "practitioner")
    stopped = with_stop(expert(), INFORMATION)
    env = build_env(env_cfg, stopped)
    try:
        run = run_trajectory(env, stopped, seed=3)
    finally:
        env.close()
    # The same motion on the same sensor, the information state kept but the episode never ended by it.
    watched = with_stop(expert(), INFORMATION)
    env = hydra.utils.instantiate({**env_cfg, **policy_mdp(watched), "terminate_on_coverage": False})
    reached = []
    try:
        obs, _ = env.reset(seed=3)
        watched.reset(env, np.random.default_rng(3))
        while not watched.finished and env.steps < watched.max_steps:
            obs, *_ = env.step(watched.act(obs, env))
            reached.append(env.goal_reached)
    finally:
        env.close()
    assert run.coverage_reached
    assert reached.index(True) + 1 == run.steps  # the first step after which the goal holds
    assert run.steps < len(reached)  # the trajectory went on without the rule


def test_the_evaluation_runs_every_baseline_with_the_rule():
    specs = [{"_target_": "vical.policies.expert.expert_policy", "task": t, "length": "long"} for t in TASKS]
    spec = PolicySpec("expert (long)", *specs, stop=INFORMATION)
    evaluator = PolicyEvaluator(spec, env_config("intrinsic", "practitioner"))
    try:
        (policy,), (env,) = evaluator.policies, evaluator.envs
        assert isinstance(policy, InformationStop) and env.config.state == "information"
        (row,) = evaluator.episode(3)
    finally:
        evaluator.close()
    assert row.coverage_reached and not row.failed and row.recording_time_s < 40


def test_a_horizon_ends_each_episode_at_the_first_step_past_it():
    """What a run records past the time-to-tolerance horizon is never counted, so the evaluation stops there."""
    rule = StopRule("information", horizon_s=4.0)
    trajectory = with_stop(expert("joint"), rule)
    env = build_env(env_config("joint"), trajectory)
    try:
        whole = run_trajectory(env, trajectory, 3)
        cut = run_trajectory(env, trajectory, 3, horizon_s=4.0)
    finally:
        env.close()
    assert whole.recording.duration > 6.0  # the rule alone lets it run well past 4 s
    assert 4.0 <= cut.recording.duration < 4.0 + 2.5 and cut.steps < whole.steps  # one step (<= 2.5 s) past it
    spec = PolicySpec.from_config(resolved_policy("expert_long"))
    assert PolicyEvaluator(dataclasses.replace(spec, stop=rule), env_config("joint")).horizon_s == 4.0
