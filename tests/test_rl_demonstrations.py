"""Demonstrations in vical-train: a demonstrator's warm-up (one env and env workers), exact resume through it, the
cloning of its actions, and bad settings refused by key."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from test_rl_trainer import assert_same_parameters, parameters, tiny_config

from vical.config_checks import ConfigError
from vical.rl.buffer import Batch
from vical.rl.checkpoint import CHECKPOINT, load_checkpoint
from vical.rl.envs import BoxActions
from vical.rl.networks import TanhGaussianPolicy
from vical.rl.sac import SAC, SACConfig
from vical.rl.single_env_trainer import Trainer
from vical.rl.trainer import train

WARMUP = 150


class DampingDemonstrator:
    """Pendulum-v1's torque against the angular rate, with noise from the episode's generator (a function of the
    episode's reset seed, as the planner's candidates are)."""

    def __init__(self, gain: float = 0.8, noise: float = 0.3) -> None:
        self.gain, self.noise = gain, noise
        self.rng = np.random.default_rng(0)

    def reset(self, env, rng: np.random.Generator) -> None:
        assert not isinstance(env, gym.Wrapper)  # the demonstrator is handed the unwrapped env
        self.rng = rng

    def act(self, obs: np.ndarray, env) -> np.ndarray:
        return np.clip([-self.gain * obs[2] + self.noise * self.rng.normal()], -2.0, 2.0)


QUIET = {"_target_": f"{__name__}.DampingDemonstrator", "noise": 0.0}
NOISY = {"_target_": f"{__name__}.DampingDemonstrator"}


def demonstrated(run_dir, **settings) -> dict:
    return tiny_config(run_dir, **{"warmup_steps": WARMUP, "eval_every": 0, **settings})


def test_to_policy_inverts_to_env_and_clips_into_the_box():
    actions = BoxActions(gym.spaces.Box(np.array([-2.0, 0.0]), np.array([2.0, 1.0])))
    policy = np.random.default_rng(0).uniform(-1, 1, (20, 2)).astype(np.float32)
    np.testing.assert_allclose([actions.to_policy(actions.to_env(a)) for a in policy], policy, atol=1e-6)
    np.testing.assert_array_equal(actions.to_policy(np.array([3.0, -0.5])), [1.0, -1.0])


def test_the_log_likelihood_of_an_action_is_the_log_density_its_sample_had():
    policy = TanhGaussianPolicy(3, 2, [16], -20.0, 2.0, torch.Generator().manual_seed(0))
    obs = torch.randn(64, 3, generator=torch.Generator().manual_seed(1))
    actions, log_prob = policy.sample(obs, torch.Generator().manual_seed(2))
    inside = actions.abs().max(1).values < 0.99  # the clip at the box's edge changes the others
    torch.testing.assert_close(policy.log_prob(obs, actions)[inside], log_prob[inside], rtol=1e-4, atol=1e-4)


def test_cloning_updates_make_the_policys_mean_the_demonstrated_action():
    """Demonstrations a = tanh(W s): SAC's cloning updates fit them (the value losses run too); SAC's own do not."""
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(256, 4)).astype(np.float32)
    demos = np.tanh(obs @ rng.normal(size=(4, 2))).astype(np.float32)
    columns = (obs, demos, np.zeros(256), obs, np.zeros(256), np.ones(256))
    batch = Batch(*(torch.tensor(x, dtype=torch.float32) for x in columns))
    errors = {}
    for clone in (True, False):
        agent = SAC(4, 2, SACConfig(hidden_sizes=[32, 32], lr=1e-3), seed=0)
        for _ in range(400):
            agent.update(batch, clone=clone)
        with torch.no_grad():
            errors[clone] = float((agent.policy.deterministic(batch.obs) - batch.actions).abs().mean())
    assert errors[True] < 0.08 < 0.3 < errors[False]


def test_the_warm_up_is_the_demonstrators_and_the_rest_the_agents(tmp_path):
    trainer = Trainer(demonstrated(tmp_path, total_steps=WARMUP + 50, demonstrator=QUIET))
    trainer.run()
    b, demo = trainer.buffer, DampingDemonstrator(noise=0.0)
    expected = np.array([trainer.actions.to_policy(demo.act(o, None)) for o in b.obs[: WARMUP + 50]])
    np.testing.assert_array_equal(b.actions[:WARMUP], expected[:WARMUP])
    assert not np.allclose(b.actions[WARMUP : WARMUP + 50], expected[WARMUP:], atol=0.05)


def test_cloned_after_the_warm_up_the_agent_acts_as_the_demonstrator(tmp_path):
    """`clone_updates` updates at the end of the warm-up: the agent's mean action is the demonstrator's on the states
    it demonstrated (a random warm-up's agent is not)."""
    errors = {}
    for clone_updates, demonstrator in ((800, QUIET), (0, None)):
        cfg = demonstrated(tmp_path / str(clone_updates), total_steps=WARMUP + 1, demonstrator=demonstrator,
                           clone_updates=clone_updates)  # fmt: skip
        cfg["agent"]["lr"] = 1e-3
        trainer = Trainer(cfg)
        result = trainer.run()
        assert result.updates == clone_updates + 1
        states = trainer.buffer.obs[:WARMUP]
        acted = np.array([trainer.actions.to_env(result.agent.act(s, deterministic=True)) for s in states])[:, 0]
        errors[clone_updates] = np.mean(np.abs(acted - np.clip(-0.8 * states[:, 2], -2.0, 2.0)))
    assert errors[800] < 0.1 < 0.3 < errors[0]


@pytest.mark.integration
def test_env_workers_take_the_demonstrators_steps_and_a_run_resumed_in_its_warm_up_is_exact(tmp_path):
    """num_envs=2: the workers' demonstrators act in the warm-up; a checkpoint inside it (mid-episode) resumes to the
    same run bit for bit (the demonstrators replay their episodes), cloning included."""
    settings = {"num_envs": 2, "total_steps": 300, "demonstrator": NOISY, "clone_updates": 50, "checkpoint_every": 70}
    full = train(demonstrated(tmp_path / "full", **settings))
    part = train(demonstrated(tmp_path / "part", **{**settings, "total_steps": 80}))
    saved = load_checkpoint(tmp_path / "part" / CHECKPOINT)
    assert part.steps == 80 and saved["counters"]["step"] == 70
    assert [len(e["env_actions"]) for e in saved["episodes"]] == [35, 35]  # mid-episode, in the warm-up
    resumed = train(demonstrated(tmp_path / "x", **settings) | {"resume": str(tmp_path / "part")})
    assert (resumed.steps, resumed.updates) == (full.steps, full.updates) == (300, 50 + 300 - WARMUP)
    assert_same_parameters(parameters(full.agent), parameters(resumed.agent))
    random_warm_up = train(demonstrated(tmp_path / "r", **{**settings, "demonstrator": None, "clone_updates": 0}))
    with pytest.raises(AssertionError):
        assert_same_parameters(parameters(full.agent), parameters(random_warm_up.agent))


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"clone_updates": 10}, r"train\.clone_updates must be 0 without train\.demonstrator"),
        ({"demonstrator": QUIET, "clone_updates": 10, "warmup_steps": 0}, r"train\.warmup_steps must be at least 1"),
        ({"demonstrator": {"gain": 1.0}}, r"train\.demonstrator must be .*_target_"),
        ({"demonstrator": {"_target_": "numpy.zeros", "shape": 3}}, r"train\.demonstrator: numpy\.zeros built .*act"),
        ({"demonstrator": {"_target_": f"{__name__}.DampingDemonstrator", "gian": 1}}, r"train\.demonstrator: .*gian"),
        ({"clone_updates": -1, "demonstrator": QUIET}, r"train\.clone_updates"),
    ],
)
def test_bad_demonstration_settings_are_refused_by_key(tmp_path, settings, message):
    with pytest.raises(ConfigError, match=message):
        train(demonstrated(tmp_path / "run", **settings))
    assert not (tmp_path / "run").exists()
