"""Training with env workers: bit-identical runs per seed and num_envs, exact resume, errors and dead workers."""

import logging
import os
import random
import time

import gymnasium as gym
import numpy as np
import pytest
import torch
from test_rl_trainer import assert_same_parameters, parameters, tiny_config

from vical.config_checks import ConfigError
from vical.rl.checkpoint import CHECKPOINT, load_checkpoint
from vical.rl.trainer import train
from vical.rl.vector import WorkersDidNotStart
from vical.rl.vector_trainer import EnvWorkerError, WorkerDiedError

KILL_AFTER = "VICAL_TEST_KILL_WORKER_AFTER"  # steps after which a worker process ends itself (as kill -9 would)
FAIL_RESET = "VICAL_TEST_FAIL_RESET_SEED"  # a reset seed on which the env raises


def reset_seed(env: int, episode: int, run_seed: int = 0) -> int:
    """The seed that resets an env's episode: keyed by (run seed, the reset stream 3, env, episode)."""
    return int(np.random.SeedSequence([run_seed, 3, env, episode]).generate_state(1)[0] % (2**31 - 1))


class FragilePendulum(gym.Wrapper):
    """Pendulum-v1 (50-step episodes) that raises on a chosen step of every episode, or whose process dies.

    ``jitter_s``: each step also sleeps up to that long, at random (unseeded), so the envs answer in an
    order that changes from run to run.
    """

    def __init__(self, fail_on_step: int = 0, jitter_s: float = 0.0) -> None:
        super().__init__(gym.make("Pendulum-v1", max_episode_steps=50))
        self.fail_on_step, self.steps_in_episode, self.steps_in_process = fail_on_step, 0, 0
        self.jitter_s = jitter_s

    def reset(self, **kwargs):
        self.steps_in_episode = 0
        if os.environ.get(FAIL_RESET) == str(kwargs.get("seed")):
            raise RuntimeError("the simulator could not place its arm")
        return self.env.reset(**kwargs)

    def step(self, action):
        self.steps_in_episode += 1
        self.steps_in_process += 1
        if os.environ.get(KILL_AFTER) and self.steps_in_process > int(os.environ[KILL_AFTER]):
            os._exit(9)
        time.sleep(random.random() * self.jitter_s)
        if self.steps_in_episode == self.fail_on_step:
            raise RuntimeError("the simulator lost its arm")
        return self.env.step(action)


FRAGILE = {"_target_": "test_rl_vector.FragilePendulum"}
JITTERY = {**FRAGILE, "jitter_s": 0.004}


def vector_config(run_dir, env: dict = FRAGILE, **train_settings) -> dict:
    return tiny_config(run_dir, env=env, **{"num_envs": 2, "eval_every": 0, **train_settings})


@pytest.mark.integration
def test_same_seed_and_num_envs_give_identical_parameters(tmp_path):
    first = train(vector_config(tmp_path / "a"))
    second = train(vector_config(tmp_path / "b"))
    # 600 transitions from 2 envs of 50-step episodes; one update per transition once more than the 100 warm-up
    # transitions are stored, run while the envs make the next ones: 2 x 249 vector steps (pre-step 102 .. 598)
    assert (first.steps, first.episodes, first.updates) == (600, 12, 500)
    assert_same_parameters(parameters(first.agent), parameters(second.agent))
    other = train(vector_config(tmp_path / "c") | {"seed": 1})
    assert not torch.equal(
        first.agent.state_dict()["policy.mlp.weights.0"], other.agent.state_dict()["policy.mlp.weights.0"]
    )


@pytest.mark.integration
def test_the_order_in_which_the_envs_answer_changes_no_number(tmp_path):
    """Steps of random length (the envs run ahead of each other by up to policy_lag - 1 rounds): the same run."""
    first = train(vector_config(tmp_path / "a", env=JITTERY, total_steps=300, policy_lag=3))
    second = train(vector_config(tmp_path / "b", env=JITTERY, total_steps=300, policy_lag=3))
    assert_same_parameters(parameters(first.agent), parameters(second.agent))
    steady = train(vector_config(tmp_path / "c", total_steps=300, policy_lag=3))
    assert_same_parameters(parameters(first.agent), parameters(steady.agent))


@pytest.mark.integration
def test_a_run_resumed_from_a_mid_episode_checkpoint_equals_the_uninterrupted_run(tmp_path):
    full = train(vector_config(tmp_path / "full", env=JITTERY, checkpoint_every=130))
    # checkpoints at 130, 260 and 390 transitions (195 steps per env: 45 into their 4th episodes; an env may have run
    # ahead of them); the run goes on to 400 past its last checkpoint, as a killed run would
    part = train(vector_config(tmp_path / "part", env=JITTERY, total_steps=400, checkpoint_every=130))
    saved = load_checkpoint(tmp_path / "part" / CHECKPOINT)
    assert saved["counters"]["step"] == 390 and [len(e["env_actions"]) for e in saved["episodes"]] == [45, 45]
    resumed = train(
        vector_config(tmp_path / "x", env=JITTERY, checkpoint_every=130) | {"resume": str(tmp_path / "part")}
    )
    assert part.steps == 400 and resumed.resumed_from == 390
    assert (resumed.steps, resumed.episodes, resumed.updates) == (full.steps, full.episodes, full.updates)
    assert_same_parameters(parameters(full.agent), parameters(resumed.agent))


@pytest.mark.integration
def test_a_killed_worker_stops_the_run_with_a_resumable_checkpoint_and_the_resume_is_exact(tmp_path, monkeypatch):
    full = train(vector_config(tmp_path / "full", checkpoint_every=150))
    monkeypatch.setenv(KILL_AFTER, "120")  # each worker dies at its 121st step: after the checkpoint at 150 + 90
    with pytest.raises(WorkerDiedError, match=r"died .* at step \d+; resume from its checkpoint at step 150"):
        train(vector_config(tmp_path / "part", checkpoint_every=150))
    monkeypatch.delenv(KILL_AFTER)
    resumed = train(vector_config(tmp_path / "x", checkpoint_every=150) | {"resume": str(tmp_path / "part")})
    assert resumed.resumed_from == 150
    assert_same_parameters(parameters(full.agent), parameters(resumed.agent))


@pytest.mark.integration
def test_an_env_that_raises_ends_its_episode_with_a_warning_naming_the_seed_and_training_goes_on(tmp_path, caplog):
    env = {**FRAGILE, "fail_on_step": 30}
    with caplog.at_level(logging.WARNING, logger="vical.rl.vector_trainer"):
        result = train(vector_config(tmp_path / "run", env=env, total_steps=200))
    assert result.steps == 200 and result.episodes == 6  # every episode cut at its 30th step
    # in the order the rounds are stored: both envs' first episodes (round 29), their second (59), their third (89)
    assert [r.getMessage() for r in caplog.records] == [
        f"env {i}, episode seed {reset_seed(i, e)}: RuntimeError: the simulator lost its arm; the episode was cut short"
        for e in range(3)
        for i in range(2)
    ]


@pytest.mark.integration
def test_an_env_that_raises_in_its_reset_stops_the_run_naming_the_seed_and_the_checkpoint(tmp_path, monkeypatch):
    seed = reset_seed(env=1, episode=1)  # env 1's second episode: after the checkpoint at step 50 (round 24)
    monkeypatch.setenv(FAIL_RESET, str(seed))
    run = tmp_path / "run"
    message = (
        rf"env worker 1 failed to reset its episode of seed {seed} \(RuntimeError: the simulator could not place its "
        rf"arm\) at step \d+; resume from its checkpoint at step 50: vical-train resume={run}$"
    )
    with pytest.raises(EnvWorkerError, match=message):
        train(vector_config(run, total_steps=200, checkpoint_every=50))
    monkeypatch.delenv(FAIL_RESET)  # the env fixed: the run goes on from its checkpoint
    resumed = train(vector_config(tmp_path / "x", total_steps=200, checkpoint_every=50) | {"resume": str(run)})
    assert (resumed.resumed_from, resumed.steps) == (50, 200)


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_ray_actors_give_the_local_processes_parameters(tmp_path):
    """The same run with its env workers as Ray actors (a local Ray instance of 2 CPUs): the same numbers."""
    import ray  # a dev dependency: `make test` installs it, so this test never skips

    local = train(vector_config(tmp_path / "local", total_steps=300))
    try:
        on_ray = train(
            vector_config(tmp_path / "ray", total_steps=300) | {"parallel": {"workers": 2, "backend": "ray"}}
        )
    finally:
        ray.shutdown()
    assert_same_parameters(parameters(local.agent), parameters(on_ray.agent))


RAY = {"parallel": {"workers": 2, "backend": "ray"}}


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
@pytest.mark.timeout(180)  # a regression hangs: each env actor waits for a CPU
def test_more_envs_than_workers_get_a_cpu_each_on_a_local_ray_instance(tmp_path):
    """parallel.workers=2 and train.num_envs=3: the local Ray instance starts with 3 CPUs and the run finishes."""
    import ray  # a dev dependency: `make test` installs it, so this test never skips

    try:
        result = train(vector_config(tmp_path / "run", total_steps=150, num_envs=3) | RAY)
        assert ray.cluster_resources()["CPU"] == 3
    finally:
        ray.shutdown()
    assert (result.steps, result.episodes) == (150, 3)  # 3 envs x one 50-step episode


@pytest.fixture
def ray_of_two_cpus():
    """A local Ray instance of 2 CPUs, started here (a run finds it initialized and uses it as its cluster)."""
    import ray

    from vical.parallel import ParallelConfig, connect_ray

    connect_ray(ParallelConfig(workers=2, backend="ray"))
    yield ray
    ray.shutdown()


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_more_envs_than_the_ray_cluster_has_cpus_are_refused_at_once(tmp_path, ray_of_two_cpus):
    start = time.perf_counter()
    with pytest.raises(ConfigError, match=r"^train\.num_envs=3 needs 3 CPUs of the Ray cluster .* has 2: lower"):
        train(vector_config(tmp_path / "run", num_envs=3) | RAY)
    assert time.perf_counter() - start < 30 and not (tmp_path / "run").exists()


class Holder:
    """A Ray actor that holds a CPU of the cluster while it lives."""

    def ready(self) -> bool:
        return True


@pytest.mark.integration
@pytest.mark.xdist_group("ray")  # one local Ray instance at a time
def test_env_workers_that_find_no_free_cpu_stop_the_run_after_a_timeout(tmp_path, ray_of_two_cpus, monkeypatch):
    ray = ray_of_two_cpus
    holder = ray.remote(num_cpus=1)(Holder).remote()
    assert ray.get(holder.ready.remote())  # one of the 2 CPUs is busy: the second env actor cannot start
    # Long enough for the actor that has a CPU to import vical and build its env on a loaded machine (5 s was
    # not, beside two training runs: both actors were reported missing).
    monkeypatch.setattr("vical.rl.vector.ACTOR_START_TIMEOUT_S", 20.0)
    start = time.perf_counter()
    with pytest.raises(WorkersDidNotStart, match=r"^1 of 2 env workers did not start on the Ray cluster within 20 s"):
        train(vector_config(tmp_path / "run") | RAY)
    assert time.perf_counter() - start < 60 and not (tmp_path / "run").exists()
    ray.kill(holder)
    deadline = time.monotonic() + 30
    while ray.available_resources().get("CPU") != 2:  # the env actor that did start was killed too
        assert time.monotonic() < deadline, ray.available_resources()
        time.sleep(0.2)


def test_an_unreachable_ray_address_leaves_no_run_directory(tmp_path):
    unreachable = {"parallel": {"workers": 2, "backend": "ray", "ray_address": "127.0.0.1:9"}}
    with pytest.raises(ConfigError, match=r"nothing answers at 127\.0\.0\.1:9"):
        train(vector_config(tmp_path / "run") | unreachable)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("num_envs", [0, 2000, 1.5])
def test_bad_num_envs_is_refused_by_key(tmp_path, num_envs):
    with pytest.raises(ConfigError, match=rf"^train\.num_envs must be an integer from 1 to 1024 .*, got {num_envs}$"):
        train(vector_config(tmp_path / "run", num_envs=num_envs))


@pytest.mark.parametrize("policy_lag", [0, 65, 2.0])
def test_bad_policy_lag_is_refused_by_key(tmp_path, policy_lag):
    with pytest.raises(ConfigError, match=r"train\.policy_lag"):
        train(vector_config(tmp_path / "run", policy_lag=policy_lag))
