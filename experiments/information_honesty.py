"""Is the information state honest? Its predicted 1-sigma at an episode's end against the final calibration's errors.

Runs the random moving policy on the information MDP (``env=information``; the joint task unless
``--task``) for ``--sensors`` sensors (reset seeds 30000.., used by no fit, training or evaluation),
each episode until the state says every group is within tolerance or the step limit, then
calibrates the recording with the task's solve and compares, parameter by parameter (fx, fy, cx,
cy; the extrinsic rotation and translation per axis; the time offset), the true error with the
information state's predicted 1-sigma (``vical.env.information``: linearised at the sensor
distribution's means, never at the truth). Prints the fraction within 1, 2 and 3 predicted sigma
(a Gaussian: 68, 95, 99.7 %), the worst parameters, the state's time per step, and whether the
stopping decisions were right (every group of the task within its tolerance when it stopped).

    .venv/bin/python experiments/information_honesty.py [--sensors 50] [--task joint]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.calib.metrics import calibration_errors
from vical.calib.tasks import run_task
from vical.env.information import TASK_GROUPS
from vical.geometry import skew, so3_log
from vical.rl.trainer import make_env

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


def run(sensors: int, task: str) -> None:
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="train", overrides=["env=information", f"task={task}"])
    env = make_env(OmegaConf.to_container(cfg.env, resolve=True))
    z_all, names, step_times, stopped, right = [], None, [], 0, 0
    rng = np.random.default_rng(0)
    for k in range(sensors):
        env.reset(seed=FIRST_SEED + k)
        terminated = truncated = False
        while not (terminated or truncated):
            start = time.perf_counter()
            _, _, terminated, truncated, _ = env.step(rng.uniform(env.action_space.low, env.action_space.high))
            step_times.append(time.perf_counter() - start)
        names, sigma = predicted(env)
        recording = env.recording()
        outcome = run_task(env.task, recording)
        z_all.append(true_errors(outcome.result, recording.truth, names) / sigma)
        if terminated:
            stopped += 1
            right += met_tolerances(outcome, recording.truth, env.config.information.tolerances, task)
        print(f"sensor {k:3d}: {'stopped' if terminated else 'step limit'} after {env.steps} steps, "
              f"max |z| {np.abs(z_all[-1]).max():.2f}", flush=True)  # fmt: skip
    z = np.abs(np.array(z_all))
    within = " / ".join(f"{np.mean(z <= k):.1%}" for k in (1, 2, 3))
    print(f"\n{task} task, {sensors} sensors, {z.size} parameters: within 1 / 2 / 3 predicted sigma: {within} "
          "(a Gaussian: 68.3 / 95.4 / 99.7 %)")  # fmt: skip
    for j, name in enumerate(names):
        c = z[:, j]
        print(f"  {name:12s} median |z| {np.median(c):.2f}  max {c.max():.2f}  within 3: {np.mean(c <= 3):.0%}")
    print(f"stopped {stopped} of {sensors}; tolerances met when stopped: {right} of {stopped}")
    print(f"environment step (simulation + information state): median {1e3 * np.median(step_times):.0f} ms")


def met_tolerances(outcome, truth, tolerances, task: str) -> bool:
    """Every group the task judges within its tolerance (the joint task: the extrinsic groups; see docs)."""
    e = calibration_errors(outcome.result, truth)
    checks = []
    if task == "intrinsic":
        d = np.abs(outcome.result.camera.intrinsics - truth.camera.intrinsics)
        checks += [np.hypot(d[0], d[1]) <= tolerances.focal_px, np.hypot(d[2], d[3]) <= tolerances.principal_point_px]
    else:
        checks += [e.rotation_deg <= tolerances.rotation_deg, e.translation_mm <= tolerances.translation_mm,
                   e.time_offset_ms <= tolerances.time_offset_ms]  # fmt: skip
    return bool(all(checks))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sensors", type=int, default=50)
    parser.add_argument("--task", choices=sorted(TASK_GROUPS), default="joint")
    args = parser.parse_args()
    run(args.sensors, args.task)


if __name__ == "__main__":
    main()
