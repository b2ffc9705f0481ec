"""Benchmark of the information-greedy planner: its decision time per step beside the step it plans, and how soon
it reaches the tolerances beside the learned policy and the baselines given the same stopping rule.

On the tuning sensors (reset seeds 40000.., used by no held-out evaluation) of the practitioner's workspace, each
policy runs one episode per sensor until the information state says every goal group is within tolerance (the
shipped policy's tolerances, confidence and step limit; the baselines with ``stop=information``):

1. decision time per step: the planner's (its 24 predictions), the critic-scored planner's (the same and their
   values, ``vical.policies.critic_planner`` with the shipped policy's value), the learned policy's network, and
   the simulated step itself (the Panda's motion, the recording and the state's update), median and largest, in
   the same run;
   the planner's share of a step is the ratio. Target: the planner decides within 0.5 s a step on this machine
   (what ``vical-collect`` can afford between motions).
2. time to the tolerances: recording time and path at the stop, how many stopped within the step limit, and the
   paired difference of each policy's recording time to the planner's with its 95 % bootstrap interval (a run
   that never stops counts at its end).

    .venv/bin/python experiments/bench_greedy.py [--episodes 10] [--tasks joint intrinsic]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.evaluation.harness import build_env, instantiate_policy
from vical.evaluation.intervals import paired_difference
from vical.policies.critic_planner import critic_planner_policy
from vical.policies.greedy import greedy_information_policy
from vical.policies.learned import learned_policy
from vical.policies.stopping import StopRule, with_stop

CONF = Path(__file__).resolve().parents[1] / "conf"
FIRST_SEED = 40_000  # the tuning sensors (docs/results-log.md): no held-out evaluation uses them
STOP = StopRule("information")


def env_config(task: str) -> dict:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"task={task}", "workspace=practitioner"])
    return OmegaConf.to_container(cfg.env, resolve=True)


def policies(task: str) -> dict:
    """Fresh policies by table name (each keeps its own timings)."""
    expert = {"_target_": "vical.policies.expert.expert_policy", "task": task}
    return {
        "greedy planner": greedy_information_policy(),
        "critic-scored planner": critic_planner_policy(),
        "learned (shipped)": learned_policy(),
        "expert (long) + stop": with_stop(instantiate_policy({**expert, "length": "long"}, "expert"), STOP),
        "expert (short) + stop": with_stop(instantiate_policy({**expert, "length": "short"}, "expert"), STOP),
        "random moving + stop": with_stop(
            instantiate_policy({"_target_": "vical.policies.random_policy.RandomMovingPolicy"}, "random"), STOP
        ),
    }


def episode(env, policy, seed: int) -> dict:
    """One episode as ``vical.evaluation.harness.run_trajectory`` runs it, timing each decision and each step."""
    obs, _ = env.reset(seed=seed)
    policy.reset(env, np.random.default_rng(seed))
    decisions, steps = [], []
    for _ in range(env.config.max_steps):
        start = time.perf_counter()
        action = policy.act(obs, env)
        decisions.append(time.perf_counter() - start)
        if policy.finished:
            break
        start = time.perf_counter()
        obs, _, terminated, truncated, _ = env.step(action)
        steps.append(time.perf_counter() - start)
        if terminated or truncated:
            break
    recording = env.recording()
    return {"time": recording.duration, "path": recording.path_length, "stopped": env.goal_reached,
            "decisions": decisions, "steps": steps}  # fmt: skip


def run(task: str, seeds: list[int]) -> dict[str, list[dict]]:
    runs: dict[str, list[dict]] = {}
    env_cfg = env_config(task)
    for name, policy in policies(task).items():
        env = build_env(env_cfg, policy)
        try:
            runs[name] = [episode(env, policy, seed) for seed in seeds]
        finally:
            env.close()
        print(f"  {task}: {name} done", flush=True)
    return runs


def print_timing(task: str, runs: dict[str, list[dict]]) -> None:
    def decisions(name: str) -> np.ndarray:
        return np.concatenate([r["decisions"] for r in runs[name]])

    planner = decisions("greedy planner")
    steps = np.concatenate([r["steps"] for r in runs["greedy planner"]])
    print(f"\n{task} task: decision time per step (ms), {len(planner)} planner steps")
    print("| what | median | max | ratio to the step (median) |")
    print("|---|---|---|---|")
    for label, x in (("greedy planner: 24 predictions", planner),
                     ("critic-scored planner: 24 predictions, their values", decisions("critic-scored planner")),
                     ("learned policy: its network", decisions("learned (shipped)")),
                     ("the simulated step it plans", steps)):  # fmt: skip
        print(f"| {label} | {1e3 * np.median(x):.0f} | {1e3 * np.max(x):.0f} | {np.median(x) / np.median(steps):.2f} |")


def print_outcomes(task: str, runs: dict[str, list[dict]]) -> None:
    print(f"\n{task} task: time to the tolerances, {len(runs['greedy planner'])} sensors")
    print("| policy | stopped | time s (mean / median) | path m (mean) | time - planner's s (95 % CI) |")
    print("|---|---|---|---|---|")
    reference = np.array([r["time"] for r in runs["greedy planner"]])
    for name, rs in runs.items():
        t = np.array([r["time"] for r in rs])
        stopped = np.mean([r["stopped"] for r in rs])
        versus = (
            "-"
            if name == "greedy planner"
            else "{:+.1f} [{:+.1f}, {:+.1f}]".format(
                *(lambda i: (i.estimate, i.low, i.high))(paired_difference(t, reference))
            )
        )
        path = np.mean([r["path"] for r in rs])
        print(f"| {name} | {stopped:.0%} | {t.mean():.1f} / {np.median(t):.1f} | {path:.2f} | {versus} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--tasks", nargs="+", default=["joint", "intrinsic"])
    args = parser.parse_args(argv)
    seeds = list(range(FIRST_SEED, FIRST_SEED + args.episodes))
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) at the start; sensors {seeds[0]}..{seeds[-1]}")
    for task in args.tasks:
        runs = run(task, seeds)
        print_timing(task, runs)
        print_outcomes(task, runs)
    print(f"\nload average {os.getloadavg()[0]:.2f} (1 min) at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
