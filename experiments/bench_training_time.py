"""Benchmark of the shipped information policy's training time: where an env step goes, and one whole training.

1. Env steps of the information MDP as it is trained (practitioner's workspace, the joint and the
   intrinsic task drawn per episode, random actions, reset seeds 32000..): wall time per step and
   the share of its parts (IK, collision checks, physics with the recorder following it, camera
   observations, the recorder's catch-up: IMU readings, truth and path, the coverage + information
   state), side by side with the same steps when every motion runs one physics step at a time in
   Python (a step callback that does nothing; motions rolled out in MuJoCo are the shipped way):
   the ratio, and whether both give the same observations and rewards to the last bit. Alternated
   episode by episode so both see the same machine load.
2. ``vical-train +experiment=train_information_policy`` for ``--steps`` steps (default: the
   experiment's ``train.total_steps``, the training as shipped; ~27 min) in a temporary run
   directory: wall time, steps/s, and the whole training's time against the limit of 30 minutes
   for one seed on this 2-core machine (projected when ``--steps`` is shorter).

    .venv/bin/python experiments/bench_training_time.py [--episodes 6] [--steps 50000] [--seed 3]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import os
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.env.state import EpisodeState
from vical.rl.envs import make_env
from vical.rl.trainer import train
from vical.sim.kinematics import PandaIK
from vical.sim.panda import PandaSim
from vical.sim.recorder import SensorRecorder

CONF = Path(__file__).resolve().parents[1] / "conf"
EXPERIMENT = "+experiment=train_information_policy"
FIRST_SEED = 32_000  # sensors of no fit, training, tuning, held-out set or test
LIMIT_MIN = 30.0
PARTS = {
    "IK": (PandaIK, "solve"),
    "collision checks": (PandaSim, "first_collision"),
    "physics": (PandaSim, "_execute"),
    "camera observations": (SensorRecorder, "_observe"),
    "recorder catch-up": (SensorRecorder, "_catch_up"),
    "coverage + information state": (EpisodeState, "add_frames"),
}


def _config(overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="train", overrides=[EXPERIMENT, *overrides])


@contextlib.contextmanager
def timed_parts(totals: collections.Counter) -> Iterator[None]:
    """Add the wall time of every call of each part in ``PARTS`` to ``totals`` (nested calls count in both)."""
    originals = {name: getattr(cls, method) for name, (cls, method) in PARTS.items()}

    def timer(name, function):
        def wrapper(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                totals[name] += time.perf_counter() - start

        return wrapper

    for name, (cls, method) in PARTS.items():
        setattr(cls, method, timer(name, originals[name]))
    try:
        yield
    finally:
        for name, (cls, method) in PARTS.items():
            setattr(cls, method, originals[name])


@contextlib.contextmanager
def stepped_in_python() -> Iterator[None]:
    """Every motion stepped one physics step at a time in Python (a step callback that does nothing)."""
    execute = PandaSim._execute

    def step_by_step(self, plan, on_step, observer):
        return execute(self, plan, on_step or (lambda sim, t_ns: None), observer)

    PandaSim._execute = step_by_step
    try:
        yield
    finally:
        PandaSim._execute = execute


def episode(env, seed: int, totals: collections.Counter) -> tuple[float, int, list[np.ndarray]]:
    """Wall time, steps and (observation, reward) sequence of one random-action episode."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    trace, steps, done = [obs], 0, False
    start = time.perf_counter()
    with timed_parts(totals):
        while not done:
            obs, reward, terminated, truncated, _ = env.step(rng.uniform(env.action_space.low, env.action_space.high))
            trace += [obs, np.array([reward])]
            steps, done = steps + 1, terminated or truncated
    return time.perf_counter() - start, steps, trace


def bench_env_step(episodes: int) -> list[str]:
    env = make_env(OmegaConf.to_container(_config([]).env, resolve=True))
    modes = {"rollout (shipped)": contextlib.nullcontext, "stepped in Python": stepped_in_python}
    wall, steps = collections.Counter(), collections.Counter()
    parts = {mode: collections.Counter() for mode in modes}
    same = True
    try:
        for k in range(episodes):
            traces = []
            for mode, context in modes.items():
                with context():
                    seconds, count, trace = episode(env, FIRST_SEED + k, parts[mode])
                wall[mode] += seconds
                steps[mode] += count
                traces.append(trace)
            same &= len(traces[0]) == len(traces[1]) and all(map(np.array_equal, *traces))
    finally:
        env.close()
    base = "rollout (shipped)"
    lines = [
        f"env step of the information MDP (both tasks, random actions, {episodes} episodes, {steps[base]} steps):",
        f"  {'motions':<18} {'ms/step':>8} {'ratio':>6}  " + "  ".join(f"{name} [ms]" for name in PARTS),
    ]
    for mode in modes:
        per_step = 1e3 * wall[mode] / steps[mode]
        shares = "  ".join(f"{1e3 * parts[mode][name] / steps[mode]:{len(name) + 5}.1f}" for name in PARTS)
        lines.append(f"  {mode:<18} {per_step:8.1f} {wall[mode] / wall[base]:6.2f}  {shares}")
    lines.append(f"  same observations and rewards to the last bit: {same}")
    return lines


def bench_training(steps: int | None, seed: int) -> list[str]:
    total = int(_config([]).train.total_steps)
    steps = steps or total
    with tempfile.TemporaryDirectory() as tmp:
        cfg = _config([f"seed={seed}", f"train.total_steps={steps}", "train.progress=false", f"run_dir={tmp}/run"])
        start = time.perf_counter()
        result = train(cfg)
        wall = time.perf_counter() - start
    rate = result.steps / wall
    whole = total / rate / 60.0 if steps < total else wall / 60.0
    kind = "projected from the rate" if steps < total else "measured"
    return [
        f"vical-train {EXPERIMENT} seed={seed}, {result.steps} steps, {result.updates} updates:",
        f"  wall {wall / 60.0:.1f} min, {rate:.1f} steps/s",
        f"  the whole training ({total} steps), {kind}: {whole:.1f} min; limit {LIMIT_MIN:.0f} min "
        f"({whole / LIMIT_MIN:.2f} of it)",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=6, help="env-step episodes per mode")
    parser.add_argument("--steps", type=int, default=None, help="training steps (default: the experiment's)")
    parser.add_argument("--seed", type=int, default=3, help="the training seed (3: the shipped policy)")
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    print("\n".join(bench_env_step(args.episodes)), flush=True)
    print("\n".join(bench_training(args.steps, args.seed)))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
