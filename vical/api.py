"""The public API's own functions: ``vical.calibrate`` (a recording, as ``vical-calibrate`` calibrates it) and
``vical.collect_in_simulation`` (a policy's collection on a simulated sensor). ``vical.PUBLIC`` lists the API."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from omegaconf import OmegaConf

from vical.calib.solve.pipeline import RigCalibration, calibrate_rig
from vical.data import ImuNoise, Recording
from vical.env.reachability import OutOfReach
from vical.evaluation.harness import PolicyEvaluator, PolicySpec, run_trajectory
from vical.geometry import CameraModel
from vical.policies.stopping import StopRule

CONF_DIR = Path(__file__).resolve().parents[1] / "conf"


def calibrate(
    recording: Recording,
    task: str = "joint",
    model: str = "radtan",
    imu_noise: ImuNoise | None = None,
    cameras: dict[str, CameraModel] | None = None,
    image_sizes: dict[str, tuple[int, int]] | None = None,
) -> RigCalibration:
    """Calibrate every camera of ``recording`` (``cam0`` and a rig's others) as ``task`` says: ``intrinsic``,
    ``extrinsic`` (``cameras``: the known intrinsics), ``joint`` or ``two_stage``, with the lens ``model``, as
    ``vical-calibrate`` does. ``imu_noise``: the IMU's noise densities (None: the paper's values, or a simulated
    recording's truth); ``image_sizes``: (W, H) [px] by camera (None: from the images or a simulated truth)."""
    truth = recording.truth
    if imu_noise is None and truth is not None:
        imu_noise = truth.imu_noise
    if image_sizes is None and truth is not None:
        image_sizes = {"cam0": (truth.camera.width, truth.camera.height)}
    frames = {name: recording.frames_of(name) for name in recording.camera_names}
    imu = None if task == "intrinsic" else recording.imu
    return calibrate_rig(frames, imu, recording.target, task, model, image_sizes, imu_noise, cameras)


@dataclass(frozen=True)
class SimulatedCollection:
    """A policy's collection on a simulated sensor (``collect_in_simulation``).

    Attributes:
        recording: what the sensor recorded, up to the stop (with the sensor's truth: ``recording.truth``).
        reached_s: [s] of recording when every goal group was within its tolerance (None: not by the stop).
        out_of_reach: the verdict of a collection stopped because a tolerance is out of reach within the horizon
            (``out_of_reach.line``: what to tell the user), or None.
        steps: the policy's steps.
    """

    recording: Recording
    reached_s: float | None
    out_of_reach: OutOfReach | None
    steps: int


def collect_in_simulation(
    policy: str = "rate_planner", task: str = "joint", seed: int = 40000, overrides: Sequence[str] = ()
) -> SimulatedCollection:
    """Run ``policy`` (a ``conf/policy`` name) on the simulated Panda and sensor of ``seed`` until every goal group
    is within the shipped tolerances, a tolerance is out of reach, or the 45 s horizon (the time-to-tolerance
    yardstick's stop: ``stop=information``), on a practitioner's sensor. ``overrides`` are ``vical-evaluate``'s
    (``sensor=paper``, ``stop.horizon_s=60``, ``policy.run_dir=<a vical-train run>``, ...)."""
    from hydra import compose, initialize_config_dir  # only a collection composes the configs

    defaults = [
        "sensor=practitioner",
        "workspace=practitioner",
        "stop=information",
        "stop.max_steps=200",
        "stop.horizon_s=45",
        "task.camera_model=sensor",
    ]  # the yardstick's (time_to_tolerance_<task>)
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose("evaluate", [*defaults, f"policy={policy}", f"task={task}", *overrides])
    spec = PolicySpec.from_config(OmegaConf.to_container(cfg.policy, resolve=True))
    spec = dataclasses.replace(spec, stop=StopRule.from_config(OmegaConf.to_container(cfg.stop, resolve=True)))
    evaluator = PolicyEvaluator(spec, OmegaConf.to_container(cfg.env, resolve=True))
    try:
        env, chosen = evaluator.envs[0], evaluator.policies[0]
        run = run_trajectory(env, chosen, seed, 0, evaluator.horizon_s, evaluator.out_of_reach)
    finally:
        evaluator.close()
    return SimulatedCollection(run.used, run.reached_s, run.out_of_reach, run.steps)
