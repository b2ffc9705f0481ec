"""Environments in worker processes for ``vical-train`` (``train.num_envs > 1``): gymnasium's vector API.

Every sub-environment runs in its own process, on this machine (gymnasium's ``AsyncVectorEnv``,
spawned) or as a Ray actor (``RayVectorEnv``, ``parallel.backend=ray``); an env's terminal work
(the calibration env's solve) happens there, while the learner goes on in the main process. The
trainer resets each sub-environment itself (autoreset off), with a seed it draws, so a run is a
function of its seed and ``num_envs``. ``GuardedEnv`` wraps every sub-environment:

- an exception in ``step`` ends the episode (truncated, reward 0) and is reported in the info
  (``worker/error`` with the episode's reset seed) instead of ending the run;
- ``replay()`` resets to a seed and repeats a list of actions: a checkpoint stores each running
  episode's seed and actions, and a resumed run replays them to the exact mid-episode state.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AsyncVectorEnv, AutoresetMode

from vical.parallel import ParallelConfig, connect_ray, single_threaded_children

ERROR_KEY = "worker/error"  # info key of an exception caught in a sub-environment's step
SEED_KEY = "worker/episode_seed"  # ... and the reset seed of the episode it ended


class GuardedEnv(gym.Wrapper):
    """A sub-environment that reports a failing step instead of raising, and can replay an episode."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.episode_seed: int | None = None
        self.last_obs: Any = None
        self.replay_script: tuple[int, list[np.ndarray]] | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self.episode_seed = seed
        obs, info = self.env.reset(seed=seed, options=options)
        self.last_obs = obs
        return obs, info

    def step(self, action):
        try:
            obs, reward, terminated, truncated, info = self.env.step(action)
        except Exception as err:  # the run goes on; the trainer reports it with the episode's seed
            message = f"{type(err).__name__}: {err}"
            return self.last_obs, 0.0, False, True, {ERROR_KEY: message, SEED_KEY: self.episode_seed}
        self.last_obs = obs
        return obs, reward, terminated, truncated, info

    def replay(self) -> Any:
        """Reset to ``replay_script``'s seed and take its actions; the observation reached."""
        seed, actions = self.replay_script
        obs, _ = self.reset(seed=seed)
        for action in actions:
            obs, *_ = self.env.step(action)
        self.last_obs = obs
        return obs


def _guarded(make_env: Callable[[Mapping[str, Any]], gym.Env], env_cfg: Mapping[str, Any]) -> GuardedEnv:
    return GuardedEnv(make_env(env_cfg))


def make_vector_env(
    make_env: Callable[[Mapping[str, Any]], gym.Env],
    env_cfg: Mapping[str, Any],
    num_envs: int,
    parallel: ParallelConfig,
):
    """``num_envs`` guarded copies of the env, each in its own process (local or Ray actors), autoreset off.

    ``make_env`` must be a module-level function (it is sent to the workers).
    """
    factory = functools.partial(_guarded, make_env, dict(env_cfg))
    if parallel.backend == "ray":
        return RayVectorEnv(factory, num_envs, parallel)
    with single_threaded_children():
        return AsyncVectorEnv(
            [factory] * num_envs, context="spawn", shared_memory=False, autoreset_mode=AutoresetMode.DISABLED
        )


def per_env_infos(infos: Mapping[str, Any], num_envs: int) -> list[dict[str, Any]]:
    """The vector API's info (arrays with ``_key`` masks) as one dict per sub-environment."""
    out: list[dict[str, Any]] = [{} for _ in range(num_envs)]
    for key, values in infos.items():
        if key.startswith("_"):
            continue
        mask = infos.get(f"_{key}", np.ones(num_envs, dtype=bool))
        for i in np.flatnonzero(mask):
            out[i][key] = values[i]
    return out


class RayVectorEnv:
    """The subset of gymnasium's vector API the trainer uses, over Ray actors (one sub-environment each)."""

    def __init__(self, factory: Callable[[], GuardedEnv], num_envs: int, parallel: ParallelConfig) -> None:
        ray = self._ray = connect_ray(parallel)
        actor = ray.remote(num_cpus=1)(_EnvActor)
        self.actors = [actor.remote(factory) for _ in range(num_envs)]
        self.num_envs = num_envs
        self._pending: list | None = None
        self.single_observation_space, self.single_action_space = ray.get(self.actors[0].spaces.remote())

    def reset(self, seed: Sequence[int] | None = None, options: dict | None = None):
        options = dict(options or {})
        mask = options.pop("reset_mask", np.ones(self.num_envs, dtype=bool))
        seeds = list(seed) if seed is not None else [None] * self.num_envs
        refs = {i: a.reset.remote(seeds[i], options or None) for i, a in enumerate(self.actors) if mask[i]}
        results = {i: self._ray.get(ref) for i, ref in refs.items()}
        obs = np.stack([results[i][0] if i in results else self._ray.get(self.actors[i].last.remote())
                        for i in range(self.num_envs)])  # fmt: skip
        return obs, _stack_infos([results[i][1] if i in results else {} for i in range(self.num_envs)])

    def step_async(self, actions: np.ndarray) -> None:
        self._pending = [a.step.remote(act) for a, act in zip(self.actors, actions, strict=True)]

    def step_wait(self):
        results, self._pending = self._ray.get(self._pending), None
        obs, rewards, terminated, truncated, infos = zip(*results, strict=True)
        return (np.stack(obs), np.array(rewards), np.array(terminated), np.array(truncated), _stack_infos(infos))

    def set_attr(self, name: str, values: Sequence[Any]) -> None:
        self._ray.get([a.set_attr.remote(name, v) for a, v in zip(self.actors, values, strict=True)])

    def call(self, name: str) -> tuple[Any, ...]:
        return tuple(self._ray.get([a.call.remote(name) for a in self.actors]))

    def close(self, terminate: bool = False) -> None:
        """Kill the actors (an actor holds nothing that needs closing beyond its process)."""
        for a in self.actors:
            self._ray.kill(a)


class _EnvActor:
    """One guarded sub-environment in a Ray actor."""

    def __init__(self, factory: Callable[[], GuardedEnv]) -> None:
        self.env = factory()

    def spaces(self):
        return self.env.observation_space, self.env.action_space

    def reset(self, seed, options):
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        return self.env.step(action)

    def last(self):
        return self.env.last_obs

    def set_attr(self, name, value):
        setattr(self.env, name, value)

    def call(self, name):
        return getattr(self.env, name)()


def _stack_infos(infos: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per-env info dicts as the vector API's (an object array per key and its ``_key`` mask)."""
    n, out = len(infos), {}
    for key in dict.fromkeys(k for info in infos for k in info):
        values, mask = np.empty(n, dtype=object), np.zeros(n, dtype=bool)
        for i, info in enumerate(infos):
            if key in info:
                values[i], mask[i] = info[key], True
        out[key], out[f"_{key}"] = values, mask
    return out
