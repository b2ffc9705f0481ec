"""Is the information state honest? Its predicted 1-sigma at an episode's end against the final calibration's errors.

Runs a policy (``--policy``, a conf/policy name: the random moving policy unless told; ``learned``:
the shipped information policy, which stops where its own state says so) on the information MDP
(``env=information``; the joint task unless ``--task``) for ``--sensors`` sensors (reset seeds
``--seed``.., 30000.. unless told: used by no fit, training, choice or evaluation), each episode
until the state says every group is within tolerance or the step limit, then
calibrates the recording with the task's solve and compares, parameter by parameter (fx, fy, cx,
cy; the extrinsic rotation and translation per axis; the time offset), the true error with the
information state's predicted 1-sigma (``vical.env.information``: linearised at the sensor
distribution's means, never at the truth). Prints the fraction within 1, 2 and 3 predicted sigma
(a Gaussian: 68, 95, 99.7 %), the worst parameters, the time per step, and whether the stopping
decisions were right (every error the task is scored by within its tolerance when it stopped, as
the evaluation judges it) with the rate's exact 95 % interval.

    .venv/bin/python experiments/information_honesty.py [--sensors 50] [--task joint] [--policy learned]
    .venv/bin/python experiments/information_honesty.py --policy learned policy.run_dir=runs/<a vical-train run>
    .venv/bin/python experiments/information_honesty.py env.information.center_offset_std=null  # a decentred lens

A learned policy runs in the MDP it was trained in: its ``env.information`` replaces the command
line's, so measure another information setting with a baseline or with a policy trained with it.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from hydra.errors import MissingConfigException
from omegaconf import OmegaConf

from vical.calib import CalibrationError
from vical.calib.tasks import run_task
from vical.config_checks import ConfigError
from vical.env.information import TASK_GROUPS
from vical.evaluation.harness import EpisodeRow, build_env, fill_outcome, instantiate_policy, run_trajectory
from vical.evaluation.intervals import Interval, proportion
from vical.evaluation.seed_choice import stopped_right
from vical.geometry import skew, so3_log

CONF = Path(__file__).resolve().parents[1] / "conf"
FIRST_SEED = 30_000
EXTRINSIC = ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z"]


def predicted(env) -> tuple[list[str], np.ndarray]:
    """Parameter names and 1-sigma of the env's information state, in the calibrator's parameters."""
    names, cov = env.state.information.covariance()
    out_names, sigmas = [], []
    idx = {n: [i for i, m in enumerate(names) if m == n] for n in set(names)}
    if "K" in idx:
        out_names += ["fx", "fy", "cx", "cy"]
        sigmas += list(np.sqrt(np.diag(cov)[idx["K"][:4]]))
    if "E" in idx:
        # The tracker's E is T_imu_cam (right perturbation); the calibrator's rot_*/t_* are the
        # rotation error of R_cam_imu (camera frame) and t_cam_imu: the calibrator's own map.
        t = env.state.information.guess.T_cam_imu[:3, 3]
        J = np.zeros((6, 6))
        J[:3, :3], J[3:, :3], J[3:, 3:] = -np.eye(3), skew(t), -np.eye(3)
        E = J @ cov[np.ix_(idx["E"], idx["E"])] @ J.T
        out_names += EXTRINSIC + ["time_offset"]
        sigmas += list(np.sqrt(np.diag(E))) + [float(np.sqrt(cov[idx["D"][0], idx["D"][0]]))]
    return out_names, np.array(sigmas)


def true_errors(result, truth, names: list[str]) -> np.ndarray:
    values = {}
    if "fx" in names:
        values.update(zip(["fx", "fy", "cx", "cy"], result.camera.intrinsics - truth.camera.intrinsics, strict=True))
    if "rot_x" in names:
        rotation = so3_log(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)
        values.update(zip(EXTRINSIC, np.r_[rotation, result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3]], strict=True))
        values["time_offset"] = result.time_offset - truth.time_offset
    return np.array([values[n] for n in names])


def run(sensors: int, task: str, policy_name: str, first_seed: int, overrides: list[str]) -> None:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        base = ["env=information", f"task={task}", f"policy={policy_name}"]
        cfg = compose(config_name="evaluate", overrides=[*base, *overrides])
    policy = instantiate_policy(OmegaConf.to_container(cfg.policy, resolve=True)[task], "policy")
    env = build_env(OmegaConf.to_container(cfg.env, resolve=True), policy)
    tolerances = dataclasses.asdict(env.config.information.tolerances)
    z_all, step_times, stopped, right, failed = [], [], 0, 0, []
    for seed in range(first_seed, first_seed + sensors):
        start = time.perf_counter()
        trajectory = run_trajectory(env, policy, seed)
        step_times.append((time.perf_counter() - start) / max(trajectory.steps, 1))
        names, sigma = predicted(env)
        ending = "stopped" if trajectory.coverage_reached else "step limit"
        stopped += trajectory.coverage_reached
        try:
            outcome = run_task(env.task, trajectory.recording)
        except CalibrationError as err:  # counted as evaluation.calibrate_row does: no errors, not a right stop
            failed.append(seed)
            print(f"sensor {seed}: {ending} after {trajectory.steps} steps, calibration failed: {err}", flush=True)
            continue
        z_all.append(true_errors(outcome.result, trajectory.recording.truth, names) / sigma)
        if trajectory.coverage_reached:
            row = EpisodeRow(policy.name, seed)
            fill_outcome(row, outcome, trajectory.recording.truth.camera)
            right += stopped_right(row, task, tolerances)
        print(f"sensor {seed}: {ending} after {trajectory.steps} steps, max |z| {np.abs(z_all[-1]).max():.2f}",
              flush=True)  # fmt: skip
    if not z_all:
        raise SystemExit(f"error: every calibration failed (sensors {failed}); nothing to compare the predictions with")
    if failed:
        print(f"\ncalibration failed on {len(failed)} of {sensors} sensors ({failed}): left out of the sigma counts")
    z = np.abs(np.array(z_all))
    within = " / ".join(f"{np.mean(z <= k):.1%}" for k in (1, 2, 3))
    print(f"\n{policy.name}, {task} task, sensors {first_seed}-{first_seed + sensors - 1}, {z.size} parameters: "
          f"within 1 / 2 / 3 predicted sigma: {within} (a Gaussian: 68.3 / 95.4 / 99.7 %)")  # fmt: skip
    for j, name in enumerate(names):
        c = z[:, j]
        print(f"  {name:12s} median |z| {np.median(c):.2f}  max {c.max():.2f}  within 3: {np.mean(c <= 3):.0%}")
    print(f"stopped {stopped} of {sensors}; tolerances met when stopped: {right} of {stopped}"
          + (f" ({rate_text(proportion(right, stopped))})" if stopped else ""))  # fmt: skip
    print(f"environment step (simulation, information state, the policy's action): median "
          f"{1e3 * np.median(step_times):.0f} ms (the episode's mean per sensor)")  # fmt: skip


def rate_text(rate: Interval) -> str:
    return f"{rate.estimate:.0%}, 95 % interval {rate.low:.0%} to {rate.high:.0%}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sensors", type=int, default=50)
    parser.add_argument("--task", choices=sorted(TASK_GROUPS), default="joint")
    parser.add_argument("--policy", default="random_moving", help="a conf/policy name (learned: the shipped policy)")
    parser.add_argument("--seed", type=int, default=FIRST_SEED, help="the first sensor's reset seed")
    parser.add_argument(
        "overrides", nargs="*", help="vical-evaluate overrides (policy.run_dir=runs/..., workspace=...)"
    )
    args = parser.parse_args()
    if args.sensors < 1:
        parser.error(f"--sensors must be at least 1, got {args.sensors}")
    try:
        run(args.sensors, args.task, args.policy, args.seed, args.overrides)
    except MissingConfigException as err:  # --policy or an override names no file of its conf/ group
        raise SystemExit(f"error: {str(err).splitlines()[0]}: the choices are the files of conf/<group>/") from None
    except ConfigError as err:  # a policy trained on another state, workspace or action scale
        raise SystemExit(f"error: {err}") from None


if __name__ == "__main__":
    main()
