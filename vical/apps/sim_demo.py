"""``vical-sim-demo``: move the simulated Panda through a few pose steps and print what it did.

Each step is an action of the paper's form (translation length, azimuth, polar angle, Euler
increments) applied to the current end-effector pose; the last one asks for an unreachable pose
to show how the simulator clamps. Usage: ``vical-sim-demo [--seed 0] [--config conf/sim/default.yaml]``.
A missing or malformed ``--config`` and a bad value in it are one line ``vical-sim-demo: error: ...``
with exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from vical.apps.cli import ArgumentParser, one_line_warnings, report_error
from vical.apps.entry import run as run_command
from vical.config_checks import ConfigError
from vical.geometry import make_transform, matrix_to_euler, step_pose
from vical.io.errors import FormatError
from vical.io.yamlfile import load_mapping
from vical.sim import MotionResult, PandaSim, SimConfig

DEFAULT_CONFIG = Path(__file__).resolve().parents[2] / "conf" / "sim" / "default.yaml"


def pose_step(T_world_ee: np.ndarray, rho: float, theta: float, phi: float, dpsi: np.ndarray) -> np.ndarray:
    """``T_world_ee`` (4, 4) moved by ``rho`` [m] along azimuth ``theta`` / polar angle ``phi`` [rad]
    and rotated by Euler increments ``dpsi`` (3,) [rad] (world frame)."""
    direction = np.array([np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta), np.cos(phi)])
    return step_pose(T_world_ee, rho * direction, dpsi)


def describe(i: int, result: MotionResult) -> str:
    p = result.T_final[:3, 3]
    rpy = np.degrees(matrix_to_euler(result.T_final[:3, :3]))
    status = "reached" if result.reached else f"CLAMPED: {result.message}"
    return (
        f"step {i}: {result.duration:5.3f} s, path {result.path_length:5.3f} m, "
        f"rotation {np.degrees(result.rotation_length):5.1f} deg, tracking error {result.max_tracking_error:.1e} rad, "
        f"joint margins {result.position_margin:.2f} rad / {result.velocity_margin:.2f} rad/s\n"
        f"        ee at [{p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}] m, rpy [{rpy[0]:+.1f} {rpy[1]:+.1f} {rpy[2]:+.1f}] deg; "
        f"{status}"
    )


def _count(text: str) -> int:
    """An argparse type: an integer >= 0."""
    if not text.isdigit():
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return int(text)


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input)."""
    one_line_warnings()
    parser = ArgumentParser(prog="vical-sim-demo", description="Move the simulated Panda through a few pose steps.")
    parser.add_argument("--seed", type=_count, default=0, help="seed of the action sampler and the simulator")
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="sim config YAML (the sim/ group)")
    parser.add_argument("--steps", type=_count, default=5, help="random pose steps before the unreachable one")
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help (0), or a bad argument whose line argparse printed (2)
        return int(done.code or 0)
    try:
        sim = PandaSim(SimConfig.from_mapping({**load_mapping(args.config, FormatError), "seed": args.seed}))
    except (FormatError, ConfigError) as err:
        return report_error("vical-sim-demo", f"--config {args.config}: {err}")
    rng = np.random.default_rng(args.seed)
    p0 = sim.ee_pose()[:3, 3]
    print(
        f"Panda at home: camera at [{p0[0]:.3f} {p0[1]:.3f} {p0[2]:.3f}] m, board centre "
        f"{sim.cfg.board.distance:.2f} m ahead; physics step {sim.model.opt.timestep * 1e3:.1f} ms"
    )
    total = 0.0
    for i in range(args.steps):
        T = pose_step(
            sim.ee_pose(),
            rng.uniform(0.05, 0.2),
            rng.uniform(-np.pi, np.pi),
            rng.uniform(0.0, np.pi),
            rng.uniform(-0.2, 0.2, 3),
        )
        result = sim.move_to(T, settle_time=0.1)
        total += result.path_length
        print(describe(i, result))
    result = sim.move_to(make_transform(np.eye(3), [2.0, 0.0, 0.5]))
    total += result.path_length
    print(describe(args.steps, result) + "  (asked for a pose 2 m away)")
    print(
        f"total path {total:.3f} m in {sim.time_ns / 1e9:.3f} s simulated; MuJoCo warnings: "
        f"{int(sim.data.warning.number.sum())}"
    )
    return 0


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command("vical-sim-demo", main)
