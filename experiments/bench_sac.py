"""vical's SAC vs stable-baselines3's SAC on Pendulum-v1, measured side by side in one process.

Both agents get the same settings (2 x 256 MLPs, batch 256, lr 3e-4, gamma 0.99, tau 0.005, automatic
temperature, clipped double-Q, 100 random warm-up steps, one update per env step, 2 torch threads unless
``--threads``), the same number of env steps and the same seeds; runs alternate per seed so both see the same machine
load. Printed per agent: the final deterministic return (mean over ``--eval-episodes`` fixed-seed
episodes, then mean +- std over seeds) and gradient updates per second of training wall time
(env interaction included, for both; both timers start after the agent is built and time only SB3's
``learn`` and vical's ``Trainer.run``, which also writes its TensorBoard scalars and the final ``agent.pt``,
a few ms). vical runs three times: float32 throughout, with its hidden-to-hidden matmuls in bfloat16
(``agent.hidden_precision=bfloat16``), and with only the backward pass's hidden matmuls in bfloat16
(``agent.hidden_precision=bfloat16_backward``). ``--authors`` adds vical's SAC with the calibration paper's
authors' settings (``conf/agent/sac_authors.yaml``).

    .venv/bin/python experiments/bench_sac.py                      # 6000 steps, seeds 0 1 2
    .venv/bin/python experiments/bench_sac.py --steps 2000 --seeds 0
    .venv/bin/python experiments/bench_sac.py --threads 1          # both agents at 1 torch thread

On a 2-core machine shared with other busy processes, 2 threads can collapse (OpenMP threads waiting for a
descheduled peer, docs/rl.md): use ``--threads 1`` there (vical's returns on seeds 0-2 were the same at
1 and 2 threads).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

from vical.rl.buffer import ReplayBuffer
from vical.rl.envs import BoxActions
from vical.rl.sac import SAC
from vical.rl.single_env_trainer import Trainer

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
EVAL_SEED = 10_000  # evaluation episode i starts from reset(seed=EVAL_SEED + i), for every agent
WARMUP = 100  # stable-baselines3's default learning_starts
THREADS = 2


def evaluate(act: Callable[[np.ndarray], np.ndarray], episodes: int) -> float:
    """Mean undiscounted return of the deterministic policy ``act(obs) -> env action`` over fixed-seed episodes."""
    env = gym.make("Pendulum-v1")
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + i)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(act(obs))
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def run_sb3(seed: int, steps: int, episodes: int) -> tuple[float, float, Any]:
    """(final return, updates/s, the trained model) of stable-baselines3 SAC with the shared settings."""
    from stable_baselines3 import SAC as SB3SAC

    model = SB3SAC(
        "MlpPolicy",
        gym.make("Pendulum-v1"),
        learning_rate=3e-4,
        buffer_size=1_000_000,
        learning_starts=WARMUP,
        batch_size=256,
        tau=0.005,
        gamma=0.99,
        train_freq=1,
        gradient_steps=1,
        ent_coef="auto",
        policy_kwargs={"net_arch": [256, 256]},
        seed=seed,
        device="cpu",
    )
    torch.set_num_threads(THREADS)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    elapsed = time.perf_counter() - start
    final = evaluate(lambda obs: model.predict(obs, deterministic=True)[0], episodes)
    return final, model._n_updates / elapsed, model


def vical_config(agent_overrides: list[str], run_dir: str, seed: int, steps: int) -> DictConfig:
    """conf/train.yaml composed with the benchmark's shared settings and ``agent_overrides``."""
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        overrides = [
            *agent_overrides,
            f"seed={seed}",
            f"torch_threads={THREADS}",
            f"run_dir={run_dir}",
            f"train.total_steps={steps}",
            f"train.warmup_steps={WARMUP}",
            "train.eval_every=0",
            "train.plot_every_episodes=0",
            "train.checkpoint_every=0",
            "train.progress=false",
        ]
        return compose("train", overrides=overrides)


def run_vical(seed: int, steps: int, episodes: int, agent_overrides: list[str]) -> tuple[float, float, SAC]:
    """(final return, updates/s, the trained agent) of vical's SAC with ``agent_overrides``."""
    with tempfile.TemporaryDirectory() as run_dir:
        cfg = vical_config(agent_overrides, run_dir, seed, steps)
        trainer = Trainer(cfg)  # setup (env, networks, buffer, config.yaml, TensorBoard writer) outside the timer,
        start = time.perf_counter()  # as SB3's model construction
        result = trainer.run()  # still timed: TensorBoard scalars every log_every steps and the final agent.pt
        elapsed = time.perf_counter() - start
    actions = BoxActions(gym.make("Pendulum-v1").action_space)
    final = evaluate(lambda obs: actions.to_env(result.agent.act(obs, deterministic=True)), episodes)
    return final, result.updates / elapsed, result.agent


def buffer_from_sb3(model: Any) -> ReplayBuffer:
    """vical's replay buffer holding the transitions of an SB3 model's buffer (actions in [-1, 1] in both)."""
    sb3, n = model.replay_buffer, model.replay_buffer.pos
    buffer = ReplayBuffer(n, sb3.observations.shape[-1], sb3.actions.shape[-1])
    for i in range(n):
        terminated = bool(sb3.dones[i, 0]) and not bool(sb3.timeouts[i, 0])
        buffer.add(
            sb3.observations[i, 0], sb3.actions[i, 0], sb3.rewards[i, 0], sb3.next_observations[i, 0], terminated
        )
    return buffer


def interleaved_update_rates(model: Any, agents: dict[str, SAC], chunks: int, per_chunk: int) -> dict[str, float]:
    """Median updates/s of each agent over ``chunks`` alternating rounds of ``per_chunk`` updates on the same data.

    Alternating short rounds exposes every agent to the same machine load, unlike whole training runs.
    """
    buffer, rng = buffer_from_sb3(model), np.random.default_rng(0)

    def ours(agent: SAC) -> None:
        for _ in range(per_chunk):
            agent.update(buffer.sample(agent.config.batch_size, rng))

    runners = {"stable-baselines3 SAC": lambda: model.train(gradient_steps=per_chunk, batch_size=256)}
    runners.update({name: (lambda a=agent: ours(a)) for name, agent in agents.items()})
    rates: dict[str, list[float]] = {name: [] for name in runners}
    for _ in range(chunks):
        for name, run in runners.items():
            start = time.perf_counter()
            run()
            rates[name].append(per_chunk / (time.perf_counter() - start))
    return {name: float(np.median(r)) for name, r in rates.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=6000, help="env steps per training run")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--authors", action="store_true", help="also run agent=sac_authors")
    parser.add_argument("--chunks", type=int, default=10, help="rounds of the interleaved update-only measurement")
    parser.add_argument(
        "--threads", type=int, default=2, help="torch threads of both agents (1 on a machine shared with busy jobs)"
    )
    args = parser.parse_args()
    global THREADS
    THREADS = args.threads

    variants = {
        "vical SAC (agent=sac)": ["agent=sac"],
        "vical SAC (agent=sac, bfloat16 hidden)": ["agent=sac", "agent.hidden_precision=bfloat16"],
        "vical SAC (agent=sac, bfloat16 gradients)": ["agent=sac", "agent.hidden_precision=bfloat16_backward"],
    }
    if args.authors:
        variants["vical SAC (agent=sac_authors)"] = ["agent=sac_authors"]
    runs = {"stable-baselines3 SAC": lambda s: run_sb3(s, args.steps, args.eval_episodes)}
    for name, overrides in variants.items():
        runs[name] = lambda s, o=overrides: run_vical(s, args.steps, args.eval_episodes, o)
    results: dict[str, list[tuple[float, float]]] = {name: [] for name in runs}
    trained: dict[str, Any] = {}
    load_start = os.getloadavg()
    for seed in args.seeds:
        for name, run in runs.items():
            final, rate, trained[name] = run(seed)
            results[name].append((final, rate))
            print(f"seed {seed}  {name:42s} final return {final:8.1f}  updates/s {rate:6.1f}", flush=True)
    sb3_model = trained.pop("stable-baselines3 SAC")
    update_rates = interleaved_update_rates(sb3_model, trained, args.chunks, per_chunk=50)
    print_table(args, results, update_rates, load_start, os.getloadavg())


def print_table(
    args: argparse.Namespace, results: dict, update_rates: dict[str, float], load_start: tuple, load_end: tuple
) -> None:
    print(
        f"\nPendulum-v1, {args.steps} env steps, seeds {args.seeds}, {args.eval_episodes} deterministic eval episodes"
        f" per seed; load average (1 min) {load_start[0]:.2f} at start, {load_end[0]:.2f} at end;"
        f" {os.cpu_count()} CPUs, {THREADS} torch thread(s)"
    )
    print(
        "| agent | final return (mean +- std over seeds) | updates/s, whole runs (mean +- std) | ratio to SB3 "
        f"| updates/s, interleaved update-only (median of {args.chunks}) | ratio to SB3 |"
    )
    print("|---|---|---|---|---|---|")
    sb3_rate = np.mean([rate for _, rate in results["stable-baselines3 SAC"]])
    sb3_update_rate = update_rates["stable-baselines3 SAC"]
    for name, rows in results.items():
        finals, rates = np.array(rows).T
        print(
            f"| {name} | {finals.mean():.1f} +- {finals.std():.1f} | {rates.mean():.1f} +- {rates.std():.1f} "
            f"| {rates.mean() / sb3_rate:.2f} | {update_rates[name]:.1f} | {update_rates[name] / sb3_update_rate:.2f} |"
        )


if __name__ == "__main__":
    main()
