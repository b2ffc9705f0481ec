"""Measure a workspace: how much of it the Panda reaches, how far along each axis, and whether steps stay feasible.

For ``--workspace`` (``conf/workspace/<name>.yaml``) it prints

1. the reachable fraction of the box: offsets drawn uniformly in ``[-bound, bound]``, each reachable
   when IK converges within the joint limits (less the planning margin) and MuJoCo reports no
   contact there (arm, board, stand, floor), with the failure reasons;
2. per axis, the reachable extent from the start pose toward each end (the other offsets zero);
3. per step of the random moving policy (uniform actions in the action box, 20-step episodes):
   the fraction of steps whose target was clamped (unreachable or colliding), the executed path
   against the straight distance between the poses (a ratio near 1: no swings), and the duration.

Usage:
    python experiments/measure_workspace.py --workspace practitioner [--samples 300] [--episodes 10]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import hydra.utils
import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.env.workspace import AXES, UNITS, reachable_extent, reachable_fraction

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
SEEDS = range(4000, 4100)  # disjoint from every evaluation seed


def make_env(workspace: str):
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=["task=intrinsic", f"workspace={workspace}"])
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    return hydra.utils.instantiate({**env_cfg, "terminate_on_coverage": False, "calibrate_on_termination": False})


def print_reach(env, samples: int) -> None:
    bound = env.config.workspace.bound
    reach = reachable_fraction(env.sim, env.frame, bound, samples, seed=0)
    reasons = ", ".join(f"{k}: {v}" for k, v in sorted(reach.reasons.items(), key=lambda kv: -kv[1])) or "none"
    print(f"reachable: {reach.reachable:.1%} of {samples} uniform samples; unreachable: {reasons}\n")
    print("| axis | bound | reachable toward - | reachable toward + |")
    print("|---|---|---|---|")
    for axis, b in enumerate(bound):
        low = reachable_extent(env.sim, env.frame, axis, -b)
        high = reachable_extent(env.sim, env.frame, axis, b)
        print(f"| {AXES[axis]} | +-{b:g} {UNITS[axis]} | {low:+.3f} | {high:+.3f} |")


def print_steps(env, episodes: int) -> None:
    clamped, ratios, durations, paths = [], [], [], []
    for seed in list(SEEDS)[:episodes]:
        _, info = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        for _ in range(env.config.max_steps):
            before, path_before, t_before = env.sim.ee_pose()[:3, 3], info["coverage/path_length"], env.sim.time_ns
            _, _, _, _, info = env.step(rng.uniform(env.action_space.low, env.action_space.high))
            straight = float(np.linalg.norm(env.sim.ee_pose()[:3, 3] - before))
            path = info["coverage/path_length"] - path_before
            clamped.append(info["motion/clamped"])
            paths.append(path)
            if straight > 0.02:
                ratios.append(path / straight)
            durations.append((env.sim.time_ns - t_before) / 1e9)
    ratios = np.array(ratios)
    print(
        f"\nrandom moving policy, {len(clamped)} steps: clamped {np.mean(clamped):.1%}; path per step "
        f"median {np.median(paths):.3f} m (max {np.max(paths):.3f}); executed path / straight distance "
        f"median {np.median(ratios):.2f}, 95th percentile {np.percentile(ratios, 95):.2f}, max {ratios.max():.2f}; "
        f"step duration median {np.median(durations):.2f} s (max {np.max(durations):.2f})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workspace", default="practitioner")
    parser.add_argument("--samples", type=int, default=300)
    parser.add_argument("--episodes", type=int, default=10)
    args = parser.parse_args()
    env = make_env(args.workspace)
    print(
        f"workspace {args.workspace}: bound {env.config.workspace.bound.round(4).tolist()}, frame "
        f"{env.config.workspace.frame}, action scale {list(env.config.action_scale)}\n"
    )
    print_reach(env, args.samples)
    print_steps(env, args.episodes)
    env.close()


if __name__ == "__main__":
    main()
