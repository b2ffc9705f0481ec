"""Benchmark of scaling out: training with 1 vs 2 env workers, evaluation serial vs 2 workers, a 64-core projection.

Measured in one run on this machine, the same work each way:

1. ``vical-train`` on the calibration MDP (joint task, practitioner's workspace, default SAC):
   ``--train-steps`` transitions with ``train.num_envs`` 1, 2 and 4 (local processes), wall time and
   steps/s, and their ratio (target >= 1.5x on 2 cores). Env steps vary in length (a motion takes
   0.3-4 s of simulated time); the envs step independently, each up to ``train.policy_lag - 1``
   rounds ahead of the slowest, so a core waits for another env only when that env falls behind by
   more than that;
2. ``vical-evaluate``'s episodes (the yardstick's joint task, the random moving policy and the
   random Fourier loop on ``--sensors`` sensors, path budgets as the yardstick's) serially and on
   ``parallel.workers=2``: episodes/s and their ratio (target >= 1.7x), and whether the rows agree;
3. a projection to 64 cores from the measured costs: an env step with its share of the terminal
   calibration (``T_env``), one gradient update (``T_update``) and one evaluation episode
   (``T_episode``). With the learner overlapping the env workers, training runs
   ``N / max(T_env, N T_update)`` steps/s on N workers; evaluation ``N / T_episode`` episodes/s.
   A projection, not a measurement: it assumes one core per worker and no other limit.

    .venv/bin/python experiments/bench_scaling.py [--train-steps 300] [--sensors 6]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.evaluation.harness import PolicySpec, evaluate_policies
from vical.parallel import ParallelConfig
from vical.rl.buffer import ReplayBuffer
from vical.rl.envs import make_env
from vical.rl.sac import SAC, SACConfig
from vical.rl.trainer import train

CONF = Path(__file__).resolve().parents[1] / "conf"
PROJECTED_CORES = (2, 8, 16, 64)
TRAIN_ENVS = (1, 2, 4)


def _compose(config: str, overrides: list[str]):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name=config, overrides=overrides)


def train_config(run_dir: Path, num_envs: int, steps: int) -> dict:
    cfg = _compose("train", ["env=calibration", "task=joint", "torch_threads=1"])
    raw = OmegaConf.to_container(cfg, resolve=False)
    raw["env"] = OmegaConf.to_container(cfg.env, resolve=True)
    raw.update(run_dir=str(run_dir), resume=None)
    raw["train"].update(
        total_steps=steps, warmup_steps=steps // 4, num_envs=num_envs, eval_every=0, checkpoint_every=0,
        plot_every_episodes=0, progress=False,
    )  # fmt: skip
    raw.pop("hydra", None)
    return raw


def bench_training(steps: int) -> tuple[list[str], dict[int, float]]:
    header = (
        f"  {'num_envs':>8} {'steps':>6} {'episodes':>8} {'updates':>7} {'wall [s]':>9} {'steps/s':>8} {'ratio':>6}"
    )
    lines = ["vical-train, calibration MDP (joint task, practitioner's workspace), 1 torch thread:", header]
    base = None
    with tempfile.TemporaryDirectory() as tmp:
        ratios = {}
        for num_envs in TRAIN_ENVS:
            start = time.perf_counter()
            result = train(train_config(Path(tmp) / f"n{num_envs}", num_envs, steps))
            wall = time.perf_counter() - start
            rate = result.steps / wall
            base = base or rate
            ratios[num_envs] = rate / base
            lines.append(
                f"  {num_envs:8d} {result.steps:6d} {result.episodes:8d} {result.updates:7d} {wall:9.1f} {rate:8.2f} "
                f"{rate / base:6.2f}"
            )
    return lines, ratios


def bench_evaluation(sensors: int) -> tuple[list[str], float, float]:
    cfg = _compose("evaluate", ["+experiment=yardstick_joint"])
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    specs = [PolicySpec.from_config(OmegaConf.to_container(_policy(name), resolve=True)) for name in
             ("random_moving", "random_trajectory")]  # fmt: skip
    seeds = list(range(20_000, 20_000 + sensors))  # sensors of no fit, training or yardstick
    budgets = tuple(cfg.budgets)
    timings, rows = {}, {}
    for workers in (1, 2):
        start = time.perf_counter()
        evaluations = evaluate_policies(
            specs, env_cfg, seeds, budgets, parallel=ParallelConfig(workers), progress=False
        )
        timings[workers] = time.perf_counter() - start
        rows[workers] = [{k: v for k, v in vars(r).items() if k != "calib_time_s"} for e in evaluations for r in e.rows]
    episodes = len(specs) * len(seeds)
    lines = [f"vical-evaluate, yardstick joint task: {len(specs)} policies x {len(seeds)} sensors, budgets {budgets}:",
             f"  {'workers':>7} {'episodes':>8} {'wall [s]':>9} {'episodes/s':>10} {'ratio':>6}"]  # fmt: skip
    for workers, wall in timings.items():
        lines.append(f"  {workers:7d} {episodes:8d} {wall:9.1f} {episodes / wall:10.3f} {timings[1] / wall:6.2f}")
    lines.append(f"  rows identical to the serial run's (but the solves' wall time): {rows[1] == rows[2]}")
    return lines, timings[1] / timings[2], timings[1] / episodes


def _policy(name: str):
    return OmegaConf.load(CONF / "policy" / f"{name}.yaml")


def unit_costs(steps: int) -> tuple[float, float]:
    """(T_env: an env step with random actions, terminal calibrations included; T_update: one SAC update) [s]."""
    env_cfg = OmegaConf.to_container(_compose("train", ["env=calibration", "task=joint"]).env, resolve=True)
    env, rng = make_env(env_cfg), np.random.default_rng(0)
    start, done, count = time.perf_counter(), True, 0
    while count < steps:
        if done:
            env.reset(seed=int(rng.integers(2**31 - 1)))
        *_, terminated, truncated, _ = env.step(env.action_space.sample())
        done, count = terminated or truncated, count + 1
    t_env = (time.perf_counter() - start) / steps
    env.close()
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    agent, buffer = SAC(obs_dim, act_dim, SACConfig(), seed=0), ReplayBuffer(10_000, obs_dim, act_dim)
    for _ in range(1000):
        buffer.add(rng.normal(size=obs_dim), rng.uniform(-1, 1, act_dim), 0.0, rng.normal(size=obs_dim), False)
    agent.update(buffer.sample(agent.config.batch_size, rng))
    start = time.perf_counter()
    for _ in range(50):
        agent.update(buffer.sample(agent.config.batch_size, rng))
    return t_env, (time.perf_counter() - start) / 50


def projection(t_env: float, t_update: float, t_episode: float) -> list[str]:
    costs = f"T_env {1e3 * t_env:.0f} ms, T_update {1e3 * t_update:.1f} ms, T_episode {t_episode:.1f} s"
    lines = [
        f"projection (not measured): {costs}",
        f"  {'cores':>5} {'training steps/s':>17} {'evaluation episodes/s':>22}",
    ]
    for n in (1, *PROJECTED_CORES):
        train_rate = n / max(t_env, n * t_update)
        lines.append(f"  {n:5d} {train_rate:17.1f} {n / t_episode:22.2f}")
    lines.append(
        f"  training saturates at 1 / T_update = {1 / t_update:.0f} steps/s: one learner; more needs more learners"
    )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--train-steps", type=int, default=300)
    parser.add_argument("--sensors", type=int, default=6)
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    train_lines, train_ratio = bench_training(args.train_steps)
    print("\n".join(train_lines))
    eval_lines, eval_ratio, t_episode = bench_evaluation(args.sensors)
    print("\n".join(eval_lines))
    t_env, t_update = unit_costs(100)
    print("\n".join(projection(t_env, t_update, t_episode)))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    trained = ", ".join(f"{n} envs {r:.2f}x" for n, r in train_ratio.items() if n > 1)
    print(f"targets: training >= 1.5x on 2 cores (measured {trained}), evaluation >= 1.7x (measured {eval_ratio:.2f}x)")


if __name__ == "__main__":
    main()
