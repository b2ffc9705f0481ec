"""How much of the information-rate planner's action is its own random candidates: the floor a distilled policy's fit
cannot go below.

Runs the planner (``rate_planner_demonstrator``, as ``train.distill`` teaches with it) on the env of a vical-train run
(``--run``: its config.yaml) and, at every ``--every``-th step, asks it again ``--draws`` times from the same state with
other random candidates. Prints, per task, the mean squared spread of those actions around their mean (summed over
the action's components, in the policy's [-1, 1] units: the fit loss a policy that knows the state exactly would
keep) beside the spread of every label around the mean of all (what a policy that ignores the state keeps).

    .venv/bin/python experiments/planner_label_spread.py --run runs/distill_seed0 --seeds 41000 41001 41002 41003
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from vical.policies.rate_planner import rate_planner_demonstrator
from vical.rl.envs import BoxActions, make_env


def spreads(run: Path, seeds: list[int], steps: int, every: int, draws: int) -> dict[str, tuple[float, float, int]]:
    """Per task: (the spread within a state, the spread over all labels, the states asked)."""
    env = make_env(OmegaConf.to_container(OmegaConf.load(run / "config.yaml").env, resolve=True))
    actions, teacher = BoxActions(env.action_space), rate_planner_demonstrator()
    within, labels = defaultdict(list), defaultdict(list)
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        teacher.reset(env.unwrapped, np.random.default_rng(seed))
        task = env.unwrapped.task.name
        for k in range(steps):
            action = teacher.act(obs, env.unwrapped)
            if k % every == every - 1:
                asked = []
                for d in range(draws):
                    teacher.current.reset(env.unwrapped, np.random.default_rng([seed, k, d]))
                    asked.append(actions.to_policy(teacher.current.act(obs, env.unwrapped)))
                asked = np.array(asked)
                within[task].append(((asked - asked.mean(0)) ** 2).sum(1).mean())
                labels[task].append(asked)
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    out = {}
    for task, values in within.items():
        every_label = np.concatenate(labels[task])
        out[task] = (
            float(np.mean(values)),
            float(((every_label - every_label.mean(0)) ** 2).sum(1).mean()),
            len(values),
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=Path, required=True, help="a vical-train run directory (its env)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[41000, 41001, 41002, 41003])
    parser.add_argument("--steps", type=int, default=15, help="planner steps per episode")
    parser.add_argument("--every", type=int, default=3, help="ask again at every this-many-th step")
    parser.add_argument("--draws", type=int, default=8, help="candidate draws per state asked")
    args = parser.parse_args()
    if not (args.run / "config.yaml").is_file():
        parser.error(f"--run {args.run}: no config.yaml there; name a vical-train run directory")
    print("| task | states | spread within a state | spread over all labels |\n|---|---|---|---|")
    for task, (within, total, n) in sorted(spreads(args.run, args.seeds, args.steps, args.every, args.draws).items()):
        print(f"| {task} | {n} | {within:.2f} | {total:.2f} |")


if __name__ == "__main__":
    main()
