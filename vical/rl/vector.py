"""Environments in worker processes for ``vical-train`` (``train.num_envs > 1``), each stepped on its own.

Every env runs in its own process, on this machine (spawned ``multiprocessing`` processes) or as a
Ray actor (``parallel.backend=ray``); an env's terminal work (the calibration env's solve) happens
there, while the learner goes on in the main process. Unlike a lockstep vector env, each worker takes
one command at a time and answers when it is done, so a fast env never waits for a slow one
(``vical.rl.vector_trainer`` keeps the run a function of its seed). ``GuardedEnv`` wraps every env:

- an exception in ``step`` ends the episode (truncated, reward 0) and is reported in the info
  (``worker/error`` with the episode's reset seed) instead of ending the run;
- ``replay`` resets to a seed and repeats a list of actions: a checkpoint stores each running
  episode's seed and actions, and a resumed run replays them to the exact mid-episode state;
- with a demonstrator (``vical.rl.demonstrations``), ``demonstrate`` steps the env with the demonstrator's
  action and answers it beside the step's results; a replay lets the demonstrator take its steps again.

Both kinds of workers offer ``send(i, command, *args)`` (``reset``, ``step``, ``demonstrate`` or ``replay``),
``receive()`` (the answers ready, waiting for at least one), the env's spaces and ``close``. A worker
that dies raises ``WorkerDied``; an exception outside ``step`` (building the env, a reset, a replay)
comes back as a ``Failure`` and raises ``WorkerError`` naming the env, the command and the episode's seed.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing.connection
import signal
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from vical.config_checks import ConfigError
from vical.parallel import ParallelConfig, connect_ray, single_threaded_children
from vical.rl.demonstrations import Demonstrator, demonstrated_action, make_demonstrator, start_demonstration

ERROR_KEY = "worker/error"  # info key of an exception caught in an env's step
SEED_KEY = "worker/episode_seed"  # ... and the reset seed of the episode it ended
CLOSE_TIMEOUT_S = 30.0  # a closing worker may finish its step in flight (a terminal solve) first
# Ray actors that have not all started by then wait for CPUs that other work holds: refused, never a hang.
# Generous: a fresh actor process imports vical, MuJoCo and GTSAM and builds its env (seconds each).
ACTOR_START_TIMEOUT_S = 120.0


class WorkerDied(RuntimeError):
    """A worker process ended (killed, out of memory) while the run needed it."""


class WorkersDidNotStart(ConfigError):
    """Ray actors of the envs did not all start in time: the cluster has no free CPU for some of them."""


@dataclass(frozen=True)
class Failure:
    """An exception in a worker, sent back as its answer: what it was doing, the episode's reset seed, the error."""

    command: str  # build, reset, replay or step
    seed: int | None  # the reset seed of the episode (None while building the env)
    error: str  # "<exception type>: <message>"
    traceback: str

    @classmethod
    def of(cls, command: str, seed: int | None, err: BaseException) -> Failure:
        return cls(command, seed, f"{type(err).__name__}: {err}", traceback.format_exc())


class WorkerError(RuntimeError):
    """A worker raised outside an env step; one line naming the env, the command, the episode's seed and the error.

    ``failure.traceback`` holds the worker's traceback.
    """

    def __init__(self, index: int, failure: Failure) -> None:
        self.index, self.failure = index, failure
        what = f"{failure.command} its episode of seed {failure.seed}"
        if failure.command == "build":
            what = "build its env"
        super().__init__(f"env worker {index} failed to {what} ({failure.error})")


class GuardedEnv(gym.Wrapper):
    """An env that reports a failing step instead of raising, and can replay an episode (and be demonstrated)."""

    def __init__(self, env: gym.Env, demonstrator: Demonstrator | None = None) -> None:
        super().__init__(env)
        self.demonstrator = demonstrator
        self.episode_seed: int | None = None
        self.last_obs: Any = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self.episode_seed = seed
        obs, info = self.env.reset(seed=seed, options=options)
        if self.demonstrator is not None:
            start_demonstration(self.demonstrator, self.env, seed)
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

    def demonstrate(self) -> tuple:
        """The demonstrator's action on the last observation, then ``step``'s answer to it."""
        action = demonstrated_action(self.demonstrator, self.env, self.last_obs)
        return (action, *self.step(action))

    def replay(self, seed: int, actions: list[np.ndarray], demonstrated: int = 0) -> Any:
        """Reset to ``seed`` and take ``actions``, the first ``demonstrated`` of them the demonstrator's (it takes
        them again, so that it is where it was); the observation reached."""
        obs, _ = self.reset(seed=seed)
        for k, action in enumerate(actions):
            if k < demonstrated and not np.array_equal(demonstrated_action(self.demonstrator, self.env, obs), action):
                raise ValueError(f"the demonstrator did not repeat its action {k} of the episode: it is not a "
                                 "function of the episode's seed")  # fmt: skip
            obs, *_ = self.env.step(action)
        self.last_obs = obs
        return obs

    def run(self, command: str, args: tuple) -> Any:
        """The command's answer, or a ``Failure`` (the worker stays up; the trainer decides what follows)."""
        try:
            if command == "reset":
                return self.reset(seed=args[0])
            return getattr(self, command)(*args)
        except Exception as err:
            return Failure.of(command, self.episode_seed, err)


def _guarded(
    make_env: Callable[[Mapping[str, Any]], gym.Env], env_cfg: Mapping[str, Any], demonstrator: Mapping | None
) -> GuardedEnv:
    return GuardedEnv(make_env(env_cfg), make_demonstrator(demonstrator))


def make_workers(
    make_env: Callable[[Mapping[str, Any]], gym.Env],
    env_cfg: Mapping[str, Any],
    num_envs: int,
    parallel: ParallelConfig,
    demonstrator: Mapping[str, Any] | None = None,
):
    """``num_envs`` guarded copies of the env, each in its own worker (local processes or Ray actors), each with
    its own demonstrator built from the ``demonstrator`` config (None: none).

    ``make_env`` must be a module-level function (it is sent to the workers).
    """
    factory = functools.partial(_guarded, make_env, dict(env_cfg), demonstrator)
    if parallel.backend == "ray":
        return RayWorkers(factory, num_envs, parallel)
    return ProcessWorkers(factory, num_envs)


# ----------------------------------------------------------------------------------- local processes
def _serve(connection, factory: Callable[[], GuardedEnv]) -> None:
    """A worker process: build the env, then answer commands until told to close (or the pipe closes)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's to handle (it closes us)
    try:
        env = factory()
    except Exception as err:
        connection.send(Failure.of("build", None, err))
        return
    connection.send((env.observation_space, env.action_space))
    while True:
        try:
            command, args = connection.recv()
        except EOFError:  # the main process is gone
            break
        if command == "close":
            break
        connection.send(env.run(command, args))
    env.close()


class ProcessWorkers:
    """One spawned process per env, each answering one command at a time over its pipe."""

    def __init__(self, factory: Callable[[], GuardedEnv], num_envs: int) -> None:
        context = multiprocessing.get_context("spawn")
        self.connections, self.processes = [], []
        with single_threaded_children():
            for _ in range(num_envs):
                parent, child = context.Pipe()
                process = context.Process(target=_serve, args=(child, factory), daemon=True)
                process.start()
                child.close()
                self.connections.append(parent)
                self.processes.append(process)
        try:
            spaces = [self._answer(i) for i in range(num_envs)]
        except BaseException:  # a worker that failed to build its env: the others end too
            self.close(kill=True)
            raise
        self.observation_space, self.action_space = spaces[0]

    def send(self, i: int, command: str, *args) -> None:
        try:
            self.connections[i].send((command, args))
        except (BrokenPipeError, ConnectionResetError, EOFError, OSError) as err:
            raise WorkerDied(f"env worker {i} died") from err

    def receive(self, timeout: float | None = None) -> list[tuple[int, Any]]:
        """``(env index, answer)`` of every worker whose answer is ready; waits up to ``timeout`` for one."""
        ready = multiprocessing.connection.wait(self.connections, timeout)
        return [(i, self._answer(i)) for i, c in enumerate(self.connections) if c in ready]

    def _answer(self, i: int) -> Any:
        try:
            answer = self.connections[i].recv()
        except (EOFError, ConnectionResetError, OSError) as err:
            raise WorkerDied(f"env worker {i} died (exit code {self.processes[i].exitcode})") from err
        return _checked(i, answer)

    def close(self, kill: bool = False) -> None:
        """Ask every worker to close its env and end (``kill``: terminate them at once).

        A worker finishes the command in flight first; one that takes longer than ``CLOSE_TIMEOUT_S``
        is terminated (never a hang).
        """
        for connection, process in zip(self.connections, self.processes, strict=True):
            if not kill and process.is_alive():
                with contextlib.suppress(OSError):
                    connection.send(("close", ()))
        for connection, process in zip(self.connections, self.processes, strict=True):
            process.join(timeout=0 if kill else CLOSE_TIMEOUT_S)
            if process.is_alive():
                process.terminate()
                process.join()
            connection.close()


# ----------------------------------------------------------------------------------------------- Ray
class RayWorkers:
    """One Ray actor per env (``parallel.backend=ray``), the same commands as ``ProcessWorkers``.

    Every actor holds one CPU of the cluster while it lives: a local instance (``ray_address: null``) is
    started with a CPU for each env, a cluster with fewer CPUs than envs is refused at once, and envs that
    do not all start within ``ACTOR_START_TIMEOUT_S`` (the cluster's CPUs are busy) stop the run with an
    error, never a hang.
    """

    def __init__(self, factory: Callable[[], GuardedEnv], num_envs: int, parallel: ParallelConfig) -> None:
        ray = self._ray = connect_ray(parallel, cpus=max(parallel.workers, num_envs))
        _check_cluster_cpus(ray, num_envs, parallel)
        actor = ray.remote(num_cpus=1, max_restarts=0)(_EnvActor)
        self.actors = [actor.remote(factory) for _ in range(num_envs)]
        self._pending: dict[Any, int] = {}
        try:
            spaces = self._started_spaces(parallel)
        except BaseException:
            self.close(kill=True)
            raise
        self.observation_space, self.action_space = spaces[0]

    def _started_spaces(self, parallel: ParallelConfig) -> list[Any]:
        """Every actor's env spaces, once all of them started; ``WorkersDidNotStart`` after the timeout."""
        refs = [a.spaces.remote() for a in self.actors]
        _, waiting = self._ray.wait(refs, num_returns=len(refs), timeout=ACTOR_START_TIMEOUT_S)
        if waiting:
            free = self._ray.available_resources().get("CPU", 0.0)
            raise WorkersDidNotStart(
                f"{len(waiting)} of {len(refs)} env workers did not start on the Ray cluster within "
                f"{ACTOR_START_TIMEOUT_S:g} s (each holds 1 CPU; {free:g} CPUs free now): lower train.num_envs or "
                f"free the cluster's CPUs (parallel.ray_address={parallel.ray_address})"
            )
        return [self._get(i, ref) for i, ref in enumerate(refs)]

    def send(self, i: int, command: str, *args) -> None:
        self._pending[self.actors[i].run.remote(command, args)] = i

    def receive(self, timeout: float | None = None) -> list[tuple[int, Any]]:
        if not self._pending:
            return []
        ready, _ = self._ray.wait(list(self._pending), num_returns=1, timeout=timeout)
        return [(i, self._get(i, ref)) for ref in ready for i in [self._pending.pop(ref)]]

    def _get(self, i: int, ref) -> Any:
        try:
            return _checked(i, self._ray.get(ref))
        except self._ray.exceptions.RayActorError as err:
            raise WorkerDied(f"env worker {i} (a Ray actor) died") from err

    def close(self, kill: bool = False) -> None:
        """Kill the actors (an actor holds nothing that needs closing beyond its process).

        Unless ``kill``, the commands still running are answered first (at most ``CLOSE_TIMEOUT_S``).
        """
        if self._pending and not kill:
            self._ray.wait(list(self._pending), num_returns=len(self._pending), timeout=CLOSE_TIMEOUT_S)
        for actor in self.actors:
            self._ray.kill(actor)


def _check_cluster_cpus(ray, num_envs: int, parallel: ParallelConfig) -> None:
    """Refuse more envs than the Ray cluster has CPUs (its actors would wait for a CPU forever)."""
    cpus = ray.cluster_resources().get("CPU", 0.0)
    if num_envs > cpus:
        where = "a local Ray instance" if parallel.ray_address is None else f"the Ray cluster at {parallel.ray_address}"
        raise ConfigError(
            f"train.num_envs={num_envs} needs {num_envs} CPUs of the Ray cluster (one per env worker), but "
            f"{where} has {cpus:g}: lower train.num_envs or use a larger cluster (parallel.ray_address)"
        )


def _checked(i: int, answer: Any) -> Any:
    """A worker's answer; ``WorkerError`` when it is a ``Failure``."""
    if isinstance(answer, Failure):
        raise WorkerError(i, answer)
    return answer


class _EnvActor:
    """One guarded env in a Ray actor (an env that fails to build is answered as a ``Failure``, as locally)."""

    def __init__(self, factory: Callable[[], GuardedEnv]) -> None:
        try:
            self.env, self.failure = factory(), None
        except Exception as err:
            self.env, self.failure = None, Failure.of("build", None, err)

    def spaces(self):
        return self.failure or (self.env.observation_space, self.env.action_space)

    def run(self, command: str, args: tuple):
        return self.env.run(command, args)
