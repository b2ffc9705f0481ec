"""Fit the "model-based learned trajectory" baseline: a 36-coefficient Fourier loop per workspace and task (PSO).

For each task a particle swarm (``vical.policies.pso``) searches the coefficients in [-1, 1]^36
(units of the workspace bound, ``vical.policies.fourier``). One objective evaluation runs the
loop's waypoints on the calibration env of ``--workspace`` (``conf/workspace/``) for each training
sensor (env seeds ``--seeds``, disjoint from every evaluation seed: the paper's tables use 0..19,
the yardstick 10000..10049), calibrates each recording with the task and returns

    mean task error [%] + path_weight [%/m] x mean executed path length [m]

where a failed calibration counts as ``--failure-error`` percent. The best coefficients, with the
objective, the training errors, the PSO settings, the seeds and the date, are written atomically
to ``vical/policies/params/model_based.yaml`` under the workspace's name (other entries are kept),
after each task.

Usage:
    python experiments/fit_model_based_trajectory.py --workspace paper                # the paper's two fits
    python experiments/fit_model_based_trajectory.py --workspace practitioner --tasks intrinsic joint
    python experiments/fit_model_based_trajectory.py --tasks intrinsic --particles 12 --iterations 10
    python experiments/fit_model_based_trajectory.py --measure           # time one objective evaluation
    python experiments/fit_model_based_trajectory.py --check             # fitted vs random on held-out sensors
"""

from __future__ import annotations

import argparse
import datetime
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.calib.errors import CalibrationError
from vical.calib.tasks import run_task
from vical.env.calibration import CalibrationEnv
from vical.io.atomic import write_text_atomic
from vical.policies.fourier import (
    DEFAULT_PARAMS_FILE,
    DEFAULT_WAYPOINTS,
    HARMONICS,
    NUM_COEFFICIENTS,
    SHAPE,
    TASKS,
    FourierTrajectory,
    FourierTrajectoryPolicy,
    model_based_policy,
    random_trajectory_policy,
)
from vical.policies.pso import PsoProgress, PsoSettings, minimize

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"

# Default budget, measured on the 2-core development machine (--measure): one objective evaluation
# (3 sensors x one 21-waypoint episode + calibration) takes ~1.9-2.3 s (intrinsic) and ~1.3-2.7 s
# (extrinsic), so 16 particles x (1 + 14) iterations = 240 evaluations fit in ~8-10 min per task.
DEFAULT_PARTICLES = 16
DEFAULT_ITERATIONS = 14
DEFAULT_SEEDS = (1000, 1001, 1002)
CHECK_SEEDS = tuple(range(2000, 2010))  # held-out sensors for --check, disjoint from training and evaluation
EVALUATION_SEEDS = {*range(20), *range(10_000, 10_050)}  # the paper's tables and the yardstick (docs/results.md)
# [%/m]: what 1 m of extra path costs, per workspace. In the authors' box errors are ~0.2-2 % over ~1 m loops;
# in the practitioner's workspace ~0.01-0.1 % over ~5-10 m loops, so the same trade-off is 100x smaller.
PATH_WEIGHTS = {"paper": 0.5, "practitioner": 0.005}
FAILURE_ERROR = 100.0  # [%] charged for a calibration that fails


def env_config(workspace: str, task: str) -> dict[str, Any]:
    """The resolved calibration env config of ``vical-evaluate`` for ``workspace`` and ``task``."""
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"task={task}", f"workspace={workspace}"])
    return OmegaConf.to_container(cfg.env, resolve=True)


def make_env(workspace: str, task: str, num_waypoints: int) -> CalibrationEnv:
    """The calibration env of ``conf/`` for ``workspace`` and ``task``, running all steps of a fixed trajectory."""
    cfg = env_config(workspace, task)
    mdp = {k: v for k, v in cfg.items() if k not in ("_target_", "sim", "sensor", "task")}
    mdp.update(max_steps=FourierTrajectoryPolicy.STEPS_PER_WAYPOINT * num_waypoints, terminate_on_coverage=False)
    return CalibrationEnv(cfg["sim"], cfg["sensor"], cfg["task"], **mdp)


@dataclass
class Evaluation:
    """One objective evaluation: the objective and its parts (means over the training sensors)."""

    objective: float
    error_pct: float  # mean task error [%], failures counted as FAILURE_ERROR
    path_m: float  # mean executed path length [m]
    failures: int
    seconds: float


class Objective:
    """Objective of a coefficient vector (36,) on fixed training sensors; remembers every evaluation."""

    def __init__(
        self, workspace: str, task: str, seeds: tuple[int, ...], num_waypoints: int, path_weight: float, failure: float
    ):
        self.env = make_env(workspace, task, num_waypoints)
        self.task = self.env.task
        self.seeds, self.num_waypoints = seeds, num_waypoints
        self.path_weight, self.failure = path_weight, failure
        self.evaluations: list[Evaluation] = []

    def episode(self, policy: FourierTrajectoryPolicy, seed: int) -> tuple[float | None, float]:
        """(task error [%] or None when the calibration failed, path length [m]) of one sensor."""
        obs, _ = self.env.reset(seed=seed)
        policy.reset(self.env, np.random.default_rng(seed))
        while not policy.finished and self.env.steps < policy.max_steps:
            obs, *_ = self.env.step(policy.act(obs, self.env))
        recording = self.env.recording()
        try:
            return run_task(self.task, recording).score, recording.path_length
        except CalibrationError:
            return None, recording.path_length

    def evaluate(self, coefficients: np.ndarray) -> Evaluation:
        start = time.perf_counter()
        policy = FourierTrajectoryPolicy(FourierTrajectory(coefficients), self.num_waypoints)
        errors, paths, failures = [], [], 0
        for seed in self.seeds:
            error, path = self.episode(policy, seed)
            failed = error is None or not np.isfinite(error)
            failures += failed
            errors.append(self.failure if failed else error)
            paths.append(path)
        error, path = float(np.mean(errors)), float(np.mean(paths))
        evaluation = Evaluation(error + self.path_weight * path, error, path, failures, time.perf_counter() - start)
        self.evaluations.append(evaluation)
        return evaluation

    def __call__(self, coefficients: np.ndarray) -> float:
        return self.evaluate(coefficients).objective


def progress_printer(objective: Objective, particles: int):
    """Callback printing one table row per PSO iteration."""
    print(f"{'iter':>4} {'evals':>5} {'best obj':>9} {'best err%':>9} {'mean obj':>9} {'fails':>5} {'time s':>7}")

    def report(p: PsoProgress) -> None:
        batch = objective.evaluations[-particles:]
        best = min(objective.evaluations, key=lambda e: e.objective)
        finite = p.values[np.isfinite(p.values)]
        mean = float(finite.mean()) if finite.size else float("nan")
        fails = sum(e.failures for e in batch)
        print(
            f"{p.iteration:>4} {p.evaluations:>5} {p.best_value:>9.3f} {best.error_pct:>9.3f} {mean:>9.3f} "
            f"{fails:>5} {p.elapsed:>7.1f}",
            flush=True,
        )

    return report


def summary(evaluations: list[Evaluation]) -> dict[str, float]:
    """Mean objective, error and path of a set of evaluations (the random initial swarm)."""
    return {
        "objective": round(float(np.mean([e.objective for e in evaluations])), 4),
        "error_pct": round(float(np.mean([e.error_pct for e in evaluations])), 4),
        "path_m": round(float(np.mean([e.path_m for e in evaluations])), 4),
        "failures": int(sum(e.failures for e in evaluations)),
    }


def fit_task(task: str, args: argparse.Namespace) -> dict[str, Any]:
    """Run the PSO for ``task``; the params-file entry."""
    objective = Objective(args.workspace, task, tuple(args.seeds), args.waypoints, args.path_weight, args.failure_error)
    settings = PsoSettings(
        particles=args.particles, iterations=args.iterations, patience=args.patience, tolerance=1e-3, seed=args.seed
    )
    budget = settings.particles * (settings.iterations + 1)
    print(
        f"\n== {args.workspace} / {task}: {budget} evaluations max ({settings.particles} particles x "
        f"(1 + {settings.iterations}) iterations) x {len(args.seeds)} sensors {list(args.seeds)}, "
        f"{args.waypoints} waypoints",
        flush=True,
    )
    start = time.perf_counter()
    result = minimize(
        objective,
        -np.ones(NUM_COEFFICIENTS),
        np.ones(NUM_COEFFICIENTS),
        settings,
        progress_printer(objective, settings.particles),
    )
    wall = time.perf_counter() - start
    initial = objective.evaluations[: settings.particles]  # uniform coefficients: random trajectories
    best = min(objective.evaluations, key=lambda e: e.objective)
    coefficients = FourierTrajectory(result.position).coefficients  # fitted into the workspace (sum <= 1)
    print(
        f"== {task}: best objective {best.objective:.3f} (error {best.error_pct:.3f} %, path {best.path_m:.3f} m); "
        f"random trajectories (initial swarm): error {summary(initial)['error_pct']:.3f} %, "
        f"path {summary(initial)['path_m']:.3f} m; {result.evaluations} evaluations in {wall:.0f} s",
        flush=True,
    )
    return {
        "coefficients": np.round(coefficients, 6).tolist(),
        "coefficient_layout": f"[dof x y z roll pitch yaw][cos, sin][harmonic {list(HARMONICS)}], "
        "units of the workspace bound",
        "num_waypoints": args.waypoints,
        "objective": round(best.objective, 4),
        "training_error_pct": round(best.error_pct, 4),
        "training_path_m": round(best.path_m, 4),
        "training_failures": best.failures,
        "random_initial_swarm": summary(initial),
        "training_seeds": list(args.seeds),
        "path_weight_pct_per_m": args.path_weight,
        "failure_error_pct": args.failure_error,
        "pso": {**asdict(settings), "iterations_run": result.iterations, "evaluations": result.evaluations},
        "seconds_per_evaluation": round(wall / result.evaluations, 3),
        "wall_s": round(wall, 1),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }


def write_params(path: Path, workspace: str, task: str, entry: dict[str, Any]) -> None:
    """Set ``workspace`` / ``task``'s entry in the params file, keeping the other entries."""
    data = yaml.safe_load(path.read_text(encoding="utf-8")) if path.is_file() else None
    data = data if isinstance(data, dict) else {}
    data.setdefault(workspace, {})[task] = entry
    header = (
        "# Model-based learned trajectory (Chen et al. 2020): PSO-fitted Fourier coefficients per workspace and task.\n"
        "# Written by experiments/fit_model_based_trajectory.py; read by vical.policies.fourier.model_based_policy.\n"
        "# See docs/baselines.md. Rerun the script to refit; do not edit by hand.\n"
    )
    write_text_atomic(path, header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120))
    print(f"wrote {workspace} / {task} to {path}", flush=True)


def measure(args: argparse.Namespace) -> None:
    """Time a few objective evaluations of random coefficients per task (for choosing the budget)."""
    rng = np.random.default_rng(args.seed)
    for task in args.tasks:
        objective = Objective(
            args.workspace, task, tuple(args.seeds), args.waypoints, args.path_weight, args.failure_error
        )
        for _ in range(3):
            e = objective.evaluate(rng.uniform(-1, 1, SHAPE))
            print(
                f"{task}: {e.seconds:.2f} s per evaluation ({len(args.seeds)} sensors), objective {e.objective:.3f}, "
                f"error {e.error_pct:.3f} %, path {e.path_m:.3f} m, failures {e.failures}",
                flush=True,
            )


def check(args: argparse.Namespace) -> None:
    """Fitted loop vs a random loop per sensor on held-out sensors: error [%], path [m], failures."""
    print(f"held-out sensors {list(CHECK_SEEDS)}, failures counted as {args.failure_error} %")
    print(f"{'task':<10} {'policy':<8} {'mean err%':>9} {'median%':>8} {'ok mean%':>8} {'path m':>7} {'fails':>5}")
    for task in args.tasks:
        objective = Objective(args.workspace, task, CHECK_SEEDS, args.waypoints, args.path_weight, args.failure_error)
        policies = {
            "fitted": model_based_policy(task, args.workspace, args.out),
            "random": random_trajectory_policy(),
        }
        for label, policy in policies.items():
            runs = [objective.episode(policy, seed) for seed in CHECK_SEEDS]
            errors = [args.failure_error if e is None else e for e, _ in runs]
            ok = [e for e, _ in runs if e is not None]
            ok_mean = float(np.mean(ok)) if ok else float("nan")  # the calibrations that succeeded
            path = float(np.mean([p for _, p in runs]))
            print(
                f"{task:<10} {label:<8} {np.mean(errors):>9.3f} {np.median(errors):>8.3f} {ok_mean:>8.3f} "
                f"{path:>7.3f} {len(runs) - len(ok):>5}",
                flush=True,
            )


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workspace", default="paper", help="conf/workspace/<name>.yaml (default: paper)")
    parser.add_argument("--tasks", nargs="+", choices=TASKS, default=None, help="default: the workspace's tasks")
    parser.add_argument("--particles", type=int, default=DEFAULT_PARTICLES)
    parser.add_argument("--iterations", type=int, default=DEFAULT_ITERATIONS)
    parser.add_argument("--patience", type=int, default=6, help="stop after this many iterations without gain")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(DEFAULT_SEEDS), help="training sensor seeds")
    parser.add_argument("--waypoints", type=int, default=DEFAULT_WAYPOINTS)
    parser.add_argument("--path-weight", type=float, default=None, help="[%%/m] (default: PATH_WEIGHTS[workspace])")
    parser.add_argument("--failure-error", type=float, default=FAILURE_ERROR, help="[%%] of a failed calibration")
    parser.add_argument("--seed", type=int, default=0, help="PSO seed")
    parser.add_argument("--out", type=Path, default=DEFAULT_PARAMS_FILE)
    parser.add_argument("--measure", action="store_true", help="only time objective evaluations")
    parser.add_argument("--check", action="store_true", help="only compare the fitted and random loops, held out")
    args = parser.parse_args(argv)
    if set(args.seeds) & EVALUATION_SEEDS or set(CHECK_SEEDS) & EVALUATION_SEEDS:
        parser.error("training seeds must be disjoint from the evaluation seeds (0..19 and 10000..10049)")
    if not (CONF_DIR / "workspace" / f"{args.workspace}.yaml").is_file():
        parser.error(f"--workspace {args.workspace}: no conf/workspace/{args.workspace}.yaml")
    if args.tasks is None:  # the paper's joint task runs the two others; a practitioner's runs one joint loop
        args.tasks = ["intrinsic", "extrinsic"] if args.workspace == "paper" else list(TASKS)
    if args.path_weight is None:
        args.path_weight = PATH_WEIGHTS.get(args.workspace, PATH_WEIGHTS["paper"])
    return args


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.measure or args.check:
        (measure if args.measure else check)(args)
        return
    for task in args.tasks:
        write_params(args.out, args.workspace, task, fit_task(task, args))


if __name__ == "__main__":
    main()
