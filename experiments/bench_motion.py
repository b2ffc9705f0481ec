"""Cost of executing one end-effector pose step, next to MuJoCo's raw physics for the same steps.

For each of a few pose steps (0.1-0.3 m, ~0.2 rad) from the home pose, it measures the wall time of
``PandaSim.move_to`` (IK + collision check + plan + inverse dynamics + physics) and, in the same
run, the wall time of bare ``mj_step`` calls on the same model for the same number of steps. The
ratio is vical's overhead; the target is at most 3x. Each figure is the median of ``--repeats``
runs, interleaving the two measurements so that load from other processes hits both alike.

Usage: python experiments/bench_motion.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

from vical.geometry import euler_to_matrix, make_transform
from vical.sim import PandaSim, SimConfig

STEPS = [  # (translation [m], Euler increments [rad]) applied to the home pose in the world frame
    ([0.10, 0.00, 0.00], [0.0, 0.2, 0.0]),
    ([0.10, 0.15, -0.05], [0.1, 0.1, 0.1]),
    ([-0.15, 0.20, 0.10], [0.0, -0.1, 0.2]),
    ([0.20, -0.20, -0.10], [0.15, 0.1, -0.1]),
]


def time_move(sim: PandaSim, T_target: np.ndarray) -> tuple[float, int, float]:
    """Wall time [s] of one ``move_to`` from home, its physics steps and simulated duration [s]."""
    sim.reset()
    start = time.perf_counter()
    result = sim.move_to(T_target)
    wall = time.perf_counter() - start
    return wall, result.num_steps, result.duration


def time_raw_physics(sim: PandaSim, steps: int) -> float:
    """Wall time [s] of ``steps`` bare ``mj_step`` calls from home with constant controls."""
    sim.reset()
    model, data = sim.model, sim.data
    start = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    sim = PandaSim(SimConfig())
    home = sim.ee_pose()
    print(f"timestep {sim.model.opt.timestep * 1e3:.1f} ms, median of {args.repeats} runs\n")
    header = (
        f"{'step':<34} {'T [s]':>6} {'steps':>6} {'move [ms]':>10} {'raw [ms]':>9} {'ratio':>6} {'sim s/wall s':>13}"
    )
    print(header)
    print("-" * len(header))
    ratios = []
    for dp, drpy in STEPS:
        T_target = make_transform(euler_to_matrix(drpy) @ home[:3, :3], home[:3, 3] + np.asarray(dp))
        moves, raws = [], []
        for _ in range(args.repeats):
            wall, steps, duration = time_move(sim, T_target)
            moves.append(wall)
            raws.append(time_raw_physics(sim, steps))
        move, raw = float(np.median(moves)), float(np.median(raws))
        ratios.append(move / raw)
        label = f"{np.linalg.norm(dp):.2f} m, {np.linalg.norm(drpy):.2f} rad (Euler)"
        print(
            f"{label:<34} {duration:>6.3f} {steps:>6} {1e3 * move:>10.2f} {1e3 * raw:>9.2f} {move / raw:>6.2f} "
            f"{steps * sim.model.opt.timestep / move:>13.1f}"
        )
    raw_rate = steps / raw
    print(f"\nraw mj_step rate: {raw_rate:,.0f} steps/s ({raw_rate * sim.model.opt.timestep:.1f} sim s/wall s)")
    print(f"worst ratio move_to / raw physics: {max(ratios):.2f} (target <= 3)")


if __name__ == "__main__":
    main()
