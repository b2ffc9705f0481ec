"""Policies on the real calibration env: random moving, hand-crafted trajectories, waypoints, learned SAC runs."""

from functools import partial
from pathlib import Path

import hydra.utils
import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.config_checks import ConfigError, from_mapping
from vical.env.settings import InformationSettings, Workspace
from vical.evaluation.harness import run_trajectory
from vical.policies.base import WaypointPolicy
from vical.policies.handcrafted import LENGTHS, TASKS, handcrafted_fractions, handcrafted_policy, handcrafted_waypoints
from vical.policies.learned import (
    INFORMATION_POLICY_DIR,
    PAPER_POLICY_DIR,
    LearnedPolicy,
    learned_policy,
    shipped_policy_dir,
)
from vical.policies.random_policy import RandomMovingPolicy
from vical.rl.checkpoint import AGENT, flatten, load_checkpoint, save_checkpoint
from vical.rl.trainer import train

CONF = Path(__file__).resolve().parents[1] / "conf"


def env_config(task: str = "intrinsic") -> dict:
    """The resolved calibration env config of vical-evaluate for ``task`` in the authors' box."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"task={task}", "workspace=paper"])
    return OmegaConf.to_container(cfg.env, resolve=True)


def composed(config_name: str, overrides: list[str]) -> dict:
    """``conf/<config_name>.yaml`` with ``overrides``, resolved to plain containers."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return OmegaConf.to_container(compose(config_name=config_name, overrides=overrides), resolve=True)


@pytest.fixture(scope="module")
def env():
    """One intrinsic-task env in the authors' box with room for the longest trajectory, never ending at coverage."""
    env = hydra.utils.instantiate(env_config(), max_steps=200, terminate_on_coverage=False)
    yield env
    env.close()


def test_random_policy_acts_within_the_action_box_and_is_seeded(env):
    policy = RandomMovingPolicy()
    with pytest.raises(RuntimeError, match="before reset"):
        policy.act(np.zeros(24), env)

    def actions(seed: int) -> np.ndarray:
        policy.reset(env, np.random.default_rng(seed))
        return np.array([policy.act(np.zeros(24), env) for _ in range(200)])

    first, again, other = actions(3), actions(3), actions(4)
    scale = np.asarray(env.config.action_scale)
    assert first.shape == (200, 6)
    assert np.all(np.abs(first) <= scale + 1e-6)
    # Uniform over the whole box: both signs reach beyond half the scale on every component.
    assert np.all(first.max(axis=0) > 0.5 * scale) and np.all(first.min(axis=0) < -0.5 * scale)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first, other)
    assert policy.stop_at_coverage and policy.name == "random moving policy"


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("length", LENGTHS)
def test_handcrafted_waypoints_lie_in_the_workspace_and_use_both_directions_of_every_axis(task, length):
    workspace = Workspace()
    bound = np.r_[workspace.position, workspace.orientation]
    waypoints = handcrafted_waypoints(task, length, workspace)
    assert np.all(np.abs(waypoints) <= bound + 1e-12)
    assert np.all(waypoints.max(axis=0) > 0.5 * bound) and np.all(waypoints.min(axis=0) < -0.5 * bound)
    np.testing.assert_allclose(waypoints, handcrafted_fractions(task, length) * bound)


def test_handcrafted_trajectories_refuse_unknown_tasks_and_lengths():
    with pytest.raises(ValueError, match="tasks"):
        handcrafted_policy("joint", "long")
    with pytest.raises(ValueError, match="lengths"):
        handcrafted_policy("intrinsic", "medium")


@pytest.mark.parametrize("task", TASKS)
def test_long_handcrafted_path_is_at_least_twice_the_short_one_on_the_env(env, task):
    paths = {}
    for length in LENGTHS:
        policy = handcrafted_policy(task, length)
        run = run_trajectory(env, policy, seed=0)
        assert policy.finished
        assert run.steps <= policy.max_steps
        paths[length] = run.recording.path_length
    assert paths["short"] > 0.3
    assert paths["long"] >= 2.0 * paths["short"]


def test_waypoint_policy_reaches_its_waypoints_and_then_holds_still(env):
    waypoints = np.array([[0.05, 0.0, 0.0, 0.0, 0.1, 0.0], [0.0, -0.06, 0.04, 0.1, 0.0, -0.08], np.zeros(6)])
    policy = WaypointPolicy(waypoints, tolerance=(2e-3, 2e-3))
    obs, _ = env.reset(seed=1)
    policy.reset(env, np.random.default_rng(1))
    for waypoint in waypoints:
        obs, *_ = env.step(policy.act(obs, env))
        offset = env.pose_offset
        assert np.linalg.norm(offset[:3] - waypoint[:3]) < 2e-3
        assert np.max(np.abs(offset[3:] - waypoint[3:])) < 2e-3
    action = policy.act(obs, env)
    assert policy.finished
    np.testing.assert_array_equal(action, np.zeros(6))
    before = env.pose_offset
    env.step(action)
    assert np.max(np.abs(env.pose_offset - before)) < 1e-3


def tiny_run(run_dir: Path, env_cfg: dict) -> dict:
    """A vical-train config of 40 steps (20 of warm-up) with 16-unit networks."""
    return {
        "seed": 0,
        "torch_threads": 1,
        "run_dir": str(run_dir),
        "resume": None,
        "agent": {"hidden_sizes": [16, 16], "batch_size": 8},
        "env": env_cfg,
        "train": {
            "total_steps": 40,
            "warmup_steps": 20,
            "eval_every": 0,
            "log_every": 0,
            "plot_every_episodes": 0,
            "checkpoint_every": 0,
            "progress": False,
        },
    }


@pytest.fixture(scope="module")
def calibration_run(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("calibration_run")
    result = train(tiny_run(run_dir, env_config()))
    return run_dir, result.agent


def test_learned_policy_acts_with_the_agents_mean_action_in_env_units(env, calibration_run):
    run_dir, trained = calibration_run
    policy = LearnedPolicy.from_run(run_dir)
    for key, value in trained.state_dict().items():
        assert torch.equal(policy.agent.state_dict()[key], value), key
    obs, _ = env.reset(seed=2)
    policy.reset(env, np.random.default_rng(0))
    action = policy.act(obs, env)
    # The trainer's map: [-1, 1] -> [-scale, scale], applied to tanh of the policy's Gaussian mean.
    with torch.no_grad():
        mean = trained.policy.distribution(torch.as_tensor(obs)[None])[0][0].numpy()
    scale = np.asarray(env.config.action_scale)
    np.testing.assert_allclose(action, -scale + (np.tanh(mean) + 1.0) * scale, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(action, policy.act(obs, env))  # deterministic
    assert policy.stop_at_coverage


def test_learned_policy_refuses_another_action_scale(env, calibration_run):
    policy = LearnedPolicy.from_run(calibration_run[0])
    policy.action_scale = policy.action_scale * 2
    with pytest.raises(ConfigError, match="action_scale"):
        policy.reset(env, np.random.default_rng(0))


def test_learned_policy_refuses_a_pendulum_run_and_a_missing_run(tmp_path):
    pendulum = {"_target_": "gymnasium.make", "id": "Pendulum-v1", "max_episode_steps": 50}
    train(tiny_run(tmp_path / "pendulum", pendulum))
    with pytest.raises(ConfigError, match=r"agent\.pt was trained on gymnasium\.make Pendulum-v1, not the calibration"):
        LearnedPolicy.from_run(tmp_path / "pendulum")
    with pytest.raises(ConfigError, match=r"no trained agent at .*missing/agent\.pt"):
        LearnedPolicy.from_run(tmp_path / "missing")


def test_a_policy_of_the_sensor_context_reads_it_and_is_refused_by_a_state_without_it(tmp_path):
    cfg = composed("train", ["env=information", "task=intrinsic", "env.information.sensor_context=true"])["env"]
    train(tiny_run(tmp_path / "context", {**cfg, "max_steps": 10}))
    policy = LearnedPolicy.from_run(tmp_path / "context")
    assert policy.env_settings["information"]["sensor_context"] is True  # carried to the env it is evaluated in
    with_context = hydra.utils.instantiate({**cfg, **policy.env_settings})
    without = hydra.utils.instantiate({**cfg, "information": {**cfg["information"], "sensor_context": False}})
    try:
        obs, _ = with_context.reset(seed=1)
        policy.reset(with_context, np.random.default_rng(0))
        assert obs.shape == (19,) and with_context.action_space.contains(policy.act(obs, with_context))
        refused = r"reads a 19-D state, but the env's has env\.information\.sensor_context=false"
        with pytest.raises(ConfigError, match=refused):
            policy.reset(without, np.random.default_rng(0))
    finally:
        with_context.close()
        without.close()
    # An agent whose config says the plain information state while its network reads 19 numbers is no run of it.
    state = load_checkpoint(tmp_path / "context" / AGENT)
    state["config"]["env"]["information"]["sensor_context"] = False
    save_checkpoint(state, tmp_path / "context" / AGENT)
    described = r"has a 19-D observation / 6-D action policy; .*\(information state\) needs 13"
    with pytest.raises(ConfigError, match=described):
        LearnedPolicy.from_run(tmp_path / "context")


def test_without_a_run_the_paper_workspace_gets_the_shipped_paper_policy(env):
    policy = learned_policy(None, workspace="paper")
    assert policy.source == PAPER_POLICY_DIR / "agent.pt"
    obs, _ = env.reset(seed=0)
    policy.reset(env, np.random.default_rng(0))  # refuses an env with another action scale
    action = policy.act(obs, env)
    assert env.action_space.contains(action.astype(np.float32))
    assert np.abs(action).max() > 0.01  # a trained policy moves


def test_without_a_run_the_practitioners_workspace_gets_the_shipped_information_policy():
    cfg = composed("evaluate", ["policy=learned", "task=joint"])  # the default workspace: practitioner
    policy = hydra.utils.instantiate(cfg["policy"]["joint"])
    assert policy.source == INFORMATION_POLICY_DIR / "agent.pt" and policy.workspace.name == "practitioner"
    assert policy.env_settings["state"] == "information"
    # It carries the information MDP it was trained with: the one its experiment configures (settings it
    # predates read as their defaults).
    trained = composed("train", ["+experiment=train_information_policy"])["env"]["information"]
    parse = partial(from_mapping, InformationSettings, key="env.information")
    assert parse(policy.env_settings["information"]) == parse(trained)
    env = hydra.utils.instantiate({**cfg["env"], **policy.env_settings})
    try:
        obs, _ = env.reset(seed=7)
        policy.reset(env, np.random.default_rng(0))
        for _ in range(2):
            action = policy.act(obs, env)
            assert env.action_space.contains(action.astype(np.float32)) and np.abs(action).max() > 0.01
            obs, _, terminated, truncated, _ = env.step(action)
            assert not (terminated or truncated)
    finally:
        env.close()


def test_the_shipped_information_policy_was_trained_with_what_its_experiment_composes():
    """``vical-train +experiment=train_information_policy seed=<its seed>`` retrains the shipped policy."""
    shipped = flatten(OmegaConf.to_container(OmegaConf.load(INFORMATION_POLICY_DIR / "config.yaml")))
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("train", overrides=["+experiment=train_information_policy", f"seed={shipped['seed']}"])
    composed_cfg = flatten(OmegaConf.to_container(cfg, resolve=True))
    where_it_ran = {"run_dir", "train.progress"}  # the training machine's, not the policy's
    differing = {
        key: (value, composed_cfg.get(key, "<absent>"))
        for key, value in shipped.items()
        if key not in where_it_ran and composed_cfg.get(key, "<absent>") != value
    }
    assert differing == {}


def test_no_policy_is_shipped_for_an_unknown_workspace():
    assert composed("evaluate", ["policy=learned", "workspace=paper"])["policy"]["workspace"] == "paper"
    with pytest.raises(ConfigError, match=r"no learned policy for workspace 'lab'.*workspace=lab"):
        shipped_policy_dir("lab")


def test_the_paper_policy_refuses_the_practitioners_workspace_by_name():
    env = hydra.utils.instantiate(env_config("intrinsic") | {"workspace": {"name": "practitioner", "frame": "board"}})
    try:
        with pytest.raises(ConfigError, match=r"trained in workspace 'paper' .* evaluate it with workspace=paper"):
            learned_policy(None, workspace="paper").check(env)
    finally:
        env.close()
