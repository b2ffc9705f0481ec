"""Trainer: determinism, exact resume, refusal of incompatible checkpoints, NaN handling, logging, config errors."""

import logging
import os
from pathlib import Path
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from vical.config_checks import ConfigError
from vical.rl.checkpoint import AGENT, CHECKPOINT, LAST_GOOD, IncompatibleCheckpointError, load_checkpoint
from vical.rl.single_env_trainer import Trainer, TrainingDivergedError
from vical.rl.trainer import train
from vical.rl.vector_trainer import VectorTrainer

PENDULUM_50 = {"_target_": "gymnasium.make", "id": "Pendulum-v1", "max_episode_steps": 50}


def tiny_config(run_dir: Path, env: dict | None = None, seed: int = 0, **train_settings) -> dict:
    """A complete vical-train config shrunk for speed: 16-unit nets, 50-step Pendulum episodes, 600 steps."""
    settings = {
        "total_steps": 600,
        "warmup_steps": 100,
        "eval_every": 200,
        "eval_episodes": 1,
        "log_every": 50,
        "plot_every_episodes": 4,
        "checkpoint_every": 100,
        "progress": False,
        **train_settings,
    }
    return {
        "seed": seed,
        "torch_threads": 1,
        "run_dir": str(run_dir),
        "resume": None,
        "agent": {"hidden_sizes": [16, 16], "batch_size": 32},
        "env": dict(env or PENDULUM_50),
        "train": settings,
    }


def parameters(agent) -> dict[str, torch.Tensor]:
    return {k: v.clone() for k, v in agent.state_dict().items()}


def assert_same_parameters(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


@pytest.mark.integration
def test_same_seed_gives_identical_parameters_and_another_seed_does_not(tmp_path):
    first = train(tiny_config(tmp_path / "a"))
    second = train(tiny_config(tmp_path / "b"))
    other = train(tiny_config(tmp_path / "c", seed=1))
    assert (first.steps, first.episodes, first.updates) == (600, 12, 500)
    assert_same_parameters(parameters(first.agent), parameters(second.agent))
    assert not torch.equal(
        first.agent.state_dict()["policy.mlp.weights.0"], other.agent.state_dict()["policy.mlp.weights.0"]
    )
    assert not any(".tmp" in p.name for p in (tmp_path / "a").iterdir())  # atomic writes leave no temp files
    umask = os.umask(0o022)
    os.umask(umask)
    for name in (CHECKPOINT, AGENT, "config.yaml"):  # the permissions open() gives, not a temp file's private 0600
        assert (tmp_path / "a" / name).stat().st_mode & 0o777 == 0o666 & ~umask, name


def scalars(run_dir: Path, tag: str) -> list[tuple[int, float]]:
    events = EventAccumulator(str(run_dir / "tb"), size_guidance={"scalars": 0}).Reload()
    return [(e.step, e.value) for e in events.Scalars(tag)]


@pytest.mark.integration
def test_resumed_run_continues_exactly_as_the_uninterrupted_run(tmp_path):
    full = train(tiny_config(tmp_path / "full"))
    # checkpoints at steps 150 and 300; the run goes on to 400, logging past its last checkpoint (a killed run)
    part = train(tiny_config(tmp_path / "part", total_steps=400, checkpoint_every=150))
    assert load_checkpoint(tmp_path / "part" / CHECKPOINT)["counters"]["step"] == 300
    # logging, evaluation and checkpoint cadence may change on resume: they never touch the training numbers
    cadence = {"log_every": 10, "eval_every": 100, "plot_every_episodes": 1, "checkpoint_every": 250}
    resumed_cfg = tiny_config(tmp_path / "ignored", total_steps=600, **cadence) | {"resume": str(tmp_path / "part")}
    resumed = train(resumed_cfg)
    assert part.steps == 400 and resumed.resumed_from == 300
    assert (resumed.steps, resumed.episodes, resumed.updates) == (full.steps, full.episodes, full.updates)
    assert_same_parameters(parameters(full.agent), parameters(resumed.agent))
    # TensorBoard: the checkpoint step's records (written before the checkpoint) are kept, what the interrupted
    # run logged after it (steps 301-400) is purged, so each step appears once with the uninterrupted values
    returns = scalars(tmp_path / "part", "charts/episodic_return")
    assert returns == scalars(tmp_path / "full", "charts/episodic_return")
    assert [step for step, _ in returns] == list(range(50, 601, 50))
    # evaluations: 200 from the first process; 400, 500, 600 from the resumed one (the first's 400 was purged)
    assert [step for step, _ in scalars(tmp_path / "part", "charts/eval_return_mean")] == [200, 400, 500, 600]
    losses = [step for step, _ in scalars(tmp_path / "part", "losses/q_loss")]
    assert losses == [150, 200, 250, 300, *range(310, 601, 10)]


def test_checkpoint_from_an_incompatible_config_is_refused_listing_the_keys(tmp_path):
    train(tiny_config(tmp_path / "run", total_steps=200))
    cfg = tiny_config(tmp_path / "run", total_steps=400) | {"resume": str(tmp_path / "run")}
    cfg["agent"] = {"hidden_sizes": [16, 16], "batch_size": 32, "gamma": 0.9}
    cfg["train"]["warmup_steps"] = 50
    with pytest.raises(IncompatibleCheckpointError) as err:
        train(cfg)
    message = str(err.value)
    assert "agent.gamma: 0.99 (checkpoint) vs 0.9 (now)" in message
    assert "train.warmup_steps: 100 (checkpoint) vs 50 (now)" in message
    assert "total_steps" not in message.split("only")[0]  # a longer run is a legitimate resume


class NonFiniteAt(gym.Wrapper):
    """Pendulum whose observation or reward becomes ``value`` from env step ``at`` on (1-based, over episodes)."""

    def __init__(self, env: gym.Env, at: int, value: float, where: str) -> None:
        super().__init__(env)
        self.at, self.value, self.where, self.count = at, value, where, 0

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.count += 1
        if self.count >= self.at:
            obs = obs.copy()
            if self.where == "obs":
                obs[1] = self.value
            else:
                reward = self.value
        return obs, reward, terminated, truncated, info


def non_finite_pendulum(at: int, value: float, where: str) -> gym.Env:
    return NonFiniteAt(gym.make("Pendulum-v1", max_episode_steps=50), at, value, where)


def bad_env(at: int, value: float, where: str) -> dict:
    return {"_target_": f"{__name__}.non_finite_pendulum", "at": at, "value": value, "where": where}


def test_nan_observation_stops_training_naming_step_and_term_after_saving_the_last_good_state(tmp_path):
    with pytest.raises(TrainingDivergedError, match=r"step 137: observation \(components \[1\]\) is nan"):
        train(tiny_config(tmp_path, env=bad_env(137, float("nan"), "obs")))
    last_good = load_checkpoint(tmp_path / LAST_GOOD)
    assert last_good["counters"]["step"] == 136
    assert all(torch.isfinite(v).all() for v in last_good["agent"]["model"].values())
    assert load_checkpoint(tmp_path / CHECKPOINT)["counters"]["step"] == 100  # the resumable episode boundary


def test_infinite_loss_stops_training_naming_the_loss(tmp_path):
    # a finite but huge reward overflows the squared Q error in float32 once a batch draws such a transition
    with pytest.raises(TrainingDivergedError, match=r"step (\d+): losses/q_loss is inf") as err:
        train(tiny_config(tmp_path, env=bad_env(120, 1e30, "reward")))
    step = int(err.value.args[0].split("step ")[1].split(":")[0])
    state = load_checkpoint(tmp_path / LAST_GOOD)
    assert step >= 120 and state["counters"]["step"] == step
    assert all(torch.isfinite(v).all() for v in state["agent"]["model"].values())


class Reach1D(gym.Env):
    """x' = x + 0.2 a, reward -x^2, 20 steps; reports calib/ and coverage/ terms and draws its own trajectory."""

    observation_space = gym.spaces.Box(-10.0, 10.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    figures_drawn: ClassVar[list[tuple[int, int]]] = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.t = float(self.np_random.uniform(-1, 1)), 0
        return np.array([self.x], np.float32), {}

    def step(self, action):
        self.x += 0.2 * float(action[0])
        self.t += 1
        info = {"coverage/progress": self.t / 20, "calib/error_pct": abs(self.x), "debug/ignored": 1.0}
        return np.array([self.x], np.float32), -(self.x**2), False, self.t >= 20, info

    def trajectory_figure(self, observations, actions):
        import matplotlib.pyplot as plt

        Reach1D.figures_drawn.append((observations.shape[0], actions.shape[0]))
        fig, ax = plt.subplots()
        ax.plot(observations[:, 0])
        return fig


class Reach1DWall(Reach1D):
    """Reach1D that also terminates (a real end of the MDP) when |x| reaches 1; records every step's flags."""

    flags: ClassVar[list[tuple[bool, bool]]] = []

    def step(self, action):
        obs, reward, _, truncated, info = super().step(action)
        terminated = abs(self.x) >= 1.0
        Reach1DWall.flags.append((terminated, truncated))
        return obs, reward, terminated, truncated, info


def test_trainer_stores_truncations_as_non_terminal_and_terminations_as_terminal(tmp_path):
    Reach1DWall.flags.clear()
    env = {"_target_": f"{__name__}.Reach1DWall"}
    trainer = Trainer(tiny_config(tmp_path, env=env, total_steps=300, eval_every=0, plot_every_episodes=0))
    trainer.run()
    terminated, truncated = np.array(Reach1DWall.flags).T  # training steps only: no evaluation env ran
    assert len(terminated) == len(trainer.buffer) == 300
    assert (truncated & ~terminated).sum() >= 3 and terminated.sum() >= 3  # both kinds of episode end occurred
    stored = trainer.buffer.terminated[:300]
    assert (stored[truncated & ~terminated] == 0).all()  # time limit: the critic bootstraps through it
    assert (stored == terminated).all()


class Reach1DDiscounted(Reach1D):
    """Reach1D whose steps report their own discount (a semi-MDP's): 0.5 + 0.5 exp(-|x'|)."""

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, {**info, "discount": 0.5 + 0.5 * np.exp(-abs(self.x))}


@pytest.mark.parametrize("num_envs", [1, 2])
def test_trainer_stores_the_discount_each_step_reports(tmp_path, num_envs):
    env = {"_target_": f"{__name__}.Reach1DDiscounted"}
    config = tiny_config(tmp_path, env=env, total_steps=200, eval_every=0, plot_every_episodes=0, num_envs=num_envs)
    trainer = Trainer(config) if num_envs == 1 else VectorTrainer(config)
    trainer.run()
    buffer = trainer.buffer
    x_next = buffer.next_obs[:200, 0].astype(float)
    np.testing.assert_allclose(buffer.discounts[:200], 0.5 + 0.5 * np.exp(-np.abs(x_next)), rtol=1e-5)
    assert buffer.discounts[:200].min() < 0.9  # the episodes moved away from 0


def test_tensorboard_gets_namespaced_scalars_env_terms_hyperparameters_and_trajectory_images(tmp_path):
    Reach1D.figures_drawn.clear()
    train(tiny_config(tmp_path, env={"_target_": f"{__name__}.Reach1D"}, total_steps=200, plot_every_episodes=5))
    events = EventAccumulator(str(tmp_path / "tb"), size_guidance={"images": 0, "scalars": 0}).Reload()
    tags = set(events.Tags()["scalars"])
    expected = {
        "charts/episodic_return", "charts/episodic_length", "charts/eval_return_mean", "losses/q_loss",
        "losses/v_loss", "losses/policy_loss", "losses/alpha", "time/updates_per_second",
        "coverage/progress", "calib/error_pct",
    }  # fmt: skip
    assert expected <= tags and "debug/ignored" not in tags
    assert [e.value for e in events.Scalars("coverage/progress")][:3] == pytest.approx([0.05, 0.10, 0.15])
    assert [e.step for e in events.Images("charts/trajectory")] == [100, 200]  # episodes 5 and 10 of 20 steps
    assert Reach1D.figures_drawn == [(21, 20), (21, 20)]  # the env's own hook drew them
    assert "hyperparameters/text_summary" in events.Tags()["tensors"]


@pytest.mark.parametrize("num_envs", [1, 2])
def test_the_log_tells_the_run_its_evaluations_checkpoints_and_end(tmp_path, num_envs, caplog):
    """What vical-train's train.log holds (Hydra writes the vical loggers' records there): the run's start, every
    evaluation, every checkpoint and the end, with their steps."""
    caplog.set_level(logging.INFO, logger="vical")
    train(tiny_config(tmp_path, total_steps=400, eval_every=200, checkpoint_every=100, num_envs=num_envs))
    lines = [r.getMessage() for r in caplog.records if r.name.startswith("vical.rl")]
    assert lines[0].startswith(f"training 400 steps in {tmp_path}")
    evaluations = [line for line in lines if line.startswith("step ") and "evaluation return" in line]
    assert [line.split()[1] for line in evaluations] == ["200:", "400:"]
    checkpoints = [
        line
        for line in lines
        if line.startswith("step ") and line.endswith(f"checkpoint written: {tmp_path / CHECKPOINT}")
    ]
    assert len(checkpoints) >= 2
    assert lines[-1].startswith("trained 400 steps") and str(tmp_path / AGENT) in lines[-1]


@pytest.mark.parametrize(
    "change, message",
    [
        ({"train": {"total_steps": 0}}, r"train\.total_steps must be a number in \[1, inf\), got 0"),
        ({"train": {"warmup_steps": 1.5}}, r"train\.warmup_steps must be an integer, got 1\.5"),
        ({"train": {"evaluate_every": 5}}, r"train: unknown setting\(s\) \['evaluate_every'\]"),
        ({"torch_threads": 0}, r"torch_threads must be a number in \[1, inf\), got 0"),
        ({"seed": -1}, r"seed must be a number in \[0, inf\), got -1"),
        ({"env": {"id": "Pendulum-v1"}}, r"env must be a mapping with a _target_"),
        ({"env": {"_target_": "gymnasium.make", "id": "CartPole-v1"}}, r"env action space must be a 1-D gymnasium Box"),
    ],
)
def test_bad_config_fails_at_start_naming_the_key(tmp_path, change, message):
    cfg = tiny_config(tmp_path)
    for key, value in change.items():
        cfg[key] = cfg[key] | value if key == "train" else value
    with pytest.raises(ConfigError, match=message):
        train(cfg)


def test_resume_of_a_directory_without_checkpoint_says_what_to_do(tmp_path):
    with pytest.raises(FileNotFoundError, match="resume=<run dir> must name a run directory"):
        train(tiny_config(tmp_path) | {"resume": str(tmp_path / "nothing")})


@pytest.mark.integration
def test_default_agent_learns_pendulum_swing_up(tmp_path):
    cfg = tiny_config(tmp_path, env={"_target_": "gymnasium.make", "id": "Pendulum-v1"}, total_steps=6000)
    cfg["agent"] = {}
    cfg["train"] |= {"warmup_steps": 1000, "eval_every": 6000, "eval_episodes": 10, "checkpoint_every": 0}
    result = train(cfg)
    assert result.last_eval_return > -300  # random policy: about -1200; swing-up solved: about -150
