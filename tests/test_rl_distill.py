"""Distillation (DAgger, ``train.distill``): the teacher labels every state the policy visits, round 0 is the
teacher's own episodes, the policy's mean learns the teacher's actions, env workers give the serial run's rounds, an
interrupted run resumes at its round exactly, and bad settings are refused by key."""

import numpy as np
import pytest
import torch
from test_rl_demonstrations import QUIET, DampingDemonstrator
from test_rl_trainer import PENDULUM_50, assert_same_parameters, parameters, tiny_config

from vical.config_checks import ConfigError
from vical.rl.checkpoint import CHECKPOINT, load_checkpoint
from vical.rl.distill import DistillConfig, RolloutJob, fit_policy, mean_action, rollout
from vical.rl.envs import BoxActions, make_env
from vical.rl.networks import TanhGaussianPolicy
from vical.rl.single_env_trainer import Trainer
from vical.rl.trainer import train

DISTILL = {"rounds": 3, "episodes": 2, "beta": 0.5, "epochs": 60, "batch_size": 64, "lr": 3e-3}


def distilled(run_dir, **settings) -> dict:
    """A distillation-only run on 50-step Pendulum episodes, the damping controller teaching."""
    cfg = tiny_config(run_dir, **{"total_steps": 0, "warmup_steps": 0, "eval_every": 0, "demonstrator": QUIET,
                                  "distill": dict(DISTILL), **settings})  # fmt: skip
    cfg["agent"]["hidden_sizes"] = [32, 32]
    return cfg


def teachers_policy_action(obs: np.ndarray) -> np.ndarray:
    """The damping controller's torque in the policy's [-1, 1] (Pendulum's box is +-2)."""
    return np.clip(-0.8 * obs[..., 2:3], -2.0, 2.0) / 2.0


def job(policy: TanhGaussianPolicy, beta: float, seed: int = 7) -> RolloutJob:
    return RolloutJob(dict(PENDULUM_50), dict(QUIET), policy, seed, beta)


def untrained_policy() -> TanhGaussianPolicy:
    return TanhGaussianPolicy(3, 1, [16], -20.0, 2.0, torch.Generator().manual_seed(0))


def test_round_zero_executes_the_teachers_actions_and_the_policys_own_states_are_labelled_too():
    policy = untrained_policy()
    taught = rollout(job(policy, beta=1.0))
    assert len(taught.obs) == 50 and not taught.reached  # Pendulum ends at its time limit
    np.testing.assert_allclose(taught.labels, teachers_policy_action(taught.obs), atol=1e-6)
    np.testing.assert_array_equal(taught.actions, taught.labels)
    own = rollout(job(policy, beta=0.0))
    np.testing.assert_allclose(own.labels, teachers_policy_action(own.obs), atol=1e-6)
    np.testing.assert_allclose(own.actions, np.array([mean_action(policy, o) for o in own.obs]), atol=1e-6)
    assert np.abs(own.actions - own.labels).mean() > 0.05  # the untrained policy is not the teacher
    np.testing.assert_array_equal(own.obs[1:], own.next_obs[:-1])  # one episode, step after step
    half = rollout(job(policy, beta=0.5))
    teachers = np.isclose(half.actions, half.labels, atol=1e-6).all(1)
    assert 10 < teachers.sum() < 40  # about half the steps the teacher's


def test_the_fit_makes_the_policys_mean_the_labels():
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(512, 4)).astype(np.float32)
    labels = np.tanh(obs @ rng.normal(size=(4, 2)) * 0.5).astype(np.float32)
    policy = TanhGaussianPolicy(4, 2, [64, 64], -20.0, 2.0, torch.Generator().manual_seed(0))
    cfg = DistillConfig(epochs=150, batch_size=64, lr=3e-3)
    with torch.no_grad():
        before = float((policy.deterministic(torch.as_tensor(obs)) - torch.as_tensor(labels)).abs().mean())
    loss = fit_policy(policy, obs, labels, cfg, torch.Generator().manual_seed(1))
    with torch.no_grad():
        after = float((policy.deterministic(torch.as_tensor(obs)) - torch.as_tensor(labels)).abs().mean())
    assert after < 0.03 < 0.2 < before and loss < 2e-3


def test_distillation_learns_the_teacher_on_the_states_its_policy_reaches(tmp_path):
    trainer = Trainer(distilled(tmp_path / "run"))
    result = trainer.run()
    assert (result.steps, result.updates) == (0, 0)  # no SAC step: the distilled policy is the agent
    n = 3 * 2 * 50
    assert len(trainer.distill_labels) == len(trainer.buffer) == n  # every state labelled, every transition stored
    np.testing.assert_allclose(trainer.distill_labels, teachers_policy_action(trainer.distill_obs), atol=1e-6)
    env = make_env(PENDULUM_50)
    actions, errors = BoxActions(env.action_space), []
    for seed in range(3):  # new episodes of the distilled policy alone
        obs, _ = env.reset(seed=1000 + seed)
        for _ in range(50):
            action = result.agent.act(np.asarray(obs, np.float32), deterministic=True)
            errors.append(abs(float(action[0]) - float(teachers_policy_action(obs)[0])))
            obs, *_ = env.step(actions.to_env(action))
    assert np.mean(errors) < 0.05
    saved = load_checkpoint(tmp_path / "run" / CHECKPOINT)
    assert saved["distill"]["round"] == 3 and saved["distill"]["labels"].shape == (n, 1)


def test_an_interrupted_distillation_resumes_at_its_round_exactly(tmp_path):
    full = train(distilled(tmp_path / "full"))
    part = Trainer(distilled(tmp_path / "part"))
    part.settings.train.distill.rounds = 1  # stopped after its first round's checkpoint
    part.run()
    assert load_checkpoint(tmp_path / "part" / CHECKPOINT)["distill"]["round"] == 1
    resumed = Trainer(distilled(tmp_path / "x") | {"resume": str(tmp_path / "part")})
    assert resumed.distill_round == 1
    result = resumed.run()
    assert resumed.distill_round == 3 and len(resumed.distill_labels) == 300
    assert_same_parameters(parameters(full.agent), parameters(result.agent))


@pytest.mark.integration
def test_env_workers_roll_out_the_rounds_the_serial_run_does(tmp_path):
    serial = train(distilled(tmp_path / "serial"))
    workers = train(distilled(tmp_path / "workers", num_envs=2))
    assert_same_parameters(parameters(serial.agent), parameters(workers.agent))


def test_sac_fine_tunes_the_distilled_policy_after_it(tmp_path):
    trainer = Trainer(distilled(tmp_path / "run", total_steps=60))
    result = trainer.run()
    assert result.steps == 60 and result.updates == 60
    assert len(trainer.buffer) == 300 + 60  # SAC learns from the rounds' transitions and its own


def test_the_teacher_dispatches_the_candidates_by_the_episodes_task():
    from configs import env_config

    from vical.policies.rate_planner import rate_planner_demonstrator

    teacher = rate_planner_demonstrator(samples=5, intrinsic_samples=9)
    for task, samples in (("intrinsic", 9), ("joint", 5)):
        env = make_env(env_config(task, "practitioner", "env=information"))
        env.reset(seed=40000)
        teacher.reset(env, np.random.default_rng(0))
        assert teacher.current.samples == samples
        env.close()


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"demonstrator": None}, r"train\.distill must be null without train\.demonstrator"),
        ({"clone_updates": 10, "warmup_steps": 5}, r"train\.clone_updates must be 0 with train\.distill"),
        ({"distill": {**DISTILL, "rounds": 0}}, r"train\.distill\.rounds"),
        ({"distill": {**DISTILL, "beta": 1.5}}, r"train\.distill\.beta"),
        ({"distill": {**DISTILL, "lr": 0}}, r"train\.distill\.lr"),
        ({"distill": {**DISTILL, "epoch": 3}}, r"train\.distill: unknown setting.*epoch"),
        ({"distill": None}, r"train\.total_steps"),  # 0 SAC steps only after a distillation
    ],
)
def test_bad_distillation_settings_are_refused_by_key(tmp_path, settings, message):
    with pytest.raises(ConfigError, match=message):
        train(distilled(tmp_path / "run", **settings))
    assert not (tmp_path / "run").exists()


def test_the_damping_teacher_is_the_labels_reference():
    """The reference the tests compare labels with is the teacher's own action."""
    obs = np.array([1.0, 0.0, 1.7], np.float32)
    np.testing.assert_allclose(teachers_policy_action(obs), DampingDemonstrator(noise=0.0).act(obs, None) / 2.0)


def test_a_run_written_before_train_distill_existed_still_resumes():
    """A checkpoint whose config has no train.distill (runs before it) compares as one without a distillation."""
    from vical.rl.checkpoint import config_differences

    saved = {"train": {"total_steps": 10, "num_envs": 1, "policy_lag": 4}}
    assert config_differences(saved, {"train": {**saved["train"], "distill": None}}) == []
    assert config_differences(saved, {"train": {**saved["train"], "distill": DISTILL}})
