"""Which calibration target for the practitioner's workspace: detections and intrinsic errors per board.

Runs the short expert trajectory and the random moving policy of the intrinsic task in the
practitioner's workspace (``conf/workspace/practitioner.yaml``) with several boards in its place,
on sensor seeds disjoint from every evaluation seed, and prints per board: the fraction of frames
with a detection, the mean number of corners per detected frame, and the median intrinsics error
||[fx, fy, cx, cy] - truth|| [px] of each policy. A checkerboard is detected all-or-none (the
project backend reports it only when the whole grid and a margin are in the image), an aprilgrid
per tag. The table is in docs/workspace.md.

Usage:
    python experiments/choose_target.py [--seeds 3000 3001 ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.evaluation.harness import PolicyEvaluator, PolicySpec

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
BOARDS = {
    "aprilgrid 6x6, 6 cm tags (0.52 m)": {"kind": "aprilgrid", "rows": 6, "cols": 6, "square": 0.06},
    "aprilgrid 6x6, 8.8 cm tags (0.76 m, Kalibr's A0)": {"kind": "aprilgrid", "rows": 6, "cols": 6, "square": 0.088},
    "aprilgrid 4x5, 6 cm tags (0.35 x 0.28 m)": {"kind": "aprilgrid", "rows": 4, "cols": 5, "square": 0.06},
    "checkerboard 7x6 inner, 7 cm (the paper's, 0.63 m)": {
        "kind": "checkerboard",
        "rows": 6,
        "cols": 7,
        "square": 0.07,
    },
    "checkerboard 9x6 inner, 4 cm (0.44 m)": {"kind": "checkerboard", "rows": 6, "cols": 9, "square": 0.04},
}
POLICIES = {
    "expert (short)": {"_target_": "vical.policies.expert.expert_policy", "task": "intrinsic", "length": "short"},
    "random moving": {"_target_": "vical.policies.random_policy.RandomMovingPolicy"},
}


def env_config(board: dict) -> dict:
    """The practitioner's intrinsic-task env with ``board`` in place of its aprilgrid."""
    overrides = ["task=intrinsic", "workspace=practitioner"]
    overrides += [f"sim.board.{key}={value}" for key, value in board.items()]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=overrides)
    return OmegaConf.to_container(cfg.env, resolve=True)


def measure(board: dict, seeds: list[int]) -> dict[str, tuple[float, float, float, int]]:
    """Per policy: (detected frame fraction, corners per detected frame, median px error, failures)."""
    out = {}
    for name, spec in POLICIES.items():
        evaluator = PolicyEvaluator(PolicySpec(name, spec, None, spec), env_config(board))
        detected, corners, errors, failures = [], [], [], 0
        try:
            for seed in seeds:
                (row,) = evaluator.episode(seed)
                counts = evaluator.envs[0].recording().frames.num_detections
                detected.append(np.mean(counts > 0))
                corners.append(counts[counts > 0].mean() if np.any(counts > 0) else 0.0)
                failures += row.failed
                if not row.failed:
                    errors.append(row.intrinsic_px)
        finally:
            evaluator.close()
        median = float(np.median(errors)) if errors else float("nan")
        out[name] = (float(np.mean(detected)), float(np.mean(corners)), median, failures)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(3000, 3008)))
    args = parser.parse_args()
    print(f"sensors: seeds {args.seeds}; intrinsic task, practitioner's workspace, whole episodes\n")
    print("| board | policy | frames detected | corners / frame | median intrinsics [px] | failed |")
    print("|---|---|---|---|---|---|")
    for label, board in BOARDS.items():
        for policy, (detected, corners, median, failures) in measure(board, args.seeds).items():
            print(f"| {label} | {policy} | {detected:.0%} | {corners:.0f} | {median:.2f} | {failures} |", flush=True)


if __name__ == "__main__":
    main()
