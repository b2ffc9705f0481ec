"""The paper's three calibration tasks (``conf/task/``): which solve runs and which error scores it.

A task turns a recording into a ``CalibrationResult`` and a single score, the error the paper's
tables report (``error_metric``). The calibration environment calls it once per finished episode
and ``vical-evaluate`` once per evaluated sensor; both pass recordings, so real recordings
calibrate the same way.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from vical.calib.metrics import CalibrationErrors, calibration_errors
from vical.calib.result import CalibrationResult
from vical.calib.solve.pipeline import calibrate_rig
from vical.calib.solve.visual_inertial import ViOptions
from vical.config_checks import ConfigError, from_mapping, require
from vical.data import CameraFrames, Recording
from vical.geometry import CAMERA_MODELS

SOLVES = ("intrinsic", "extrinsic", "joint", "two_stage")
ERROR_METRICS = ("intrinsic_relative", "extrinsic_relative")
SENSOR_MODEL = "sensor"  # task.camera_model: the recording's own lens model


@dataclass(frozen=True)
class CalibrationTask:
    """One calibration task (``conf/task/<name>.yaml``); the defaults are the joint task's (``conf/task/joint.yaml``).

    Attributes:
        name: the task's name (``intrinsic``, ``extrinsic``, ``joint``).
        calibrate: the solve: ``intrinsic``; ``extrinsic`` (intrinsics known: the truth's);
            ``joint`` (one graph); ``two_stage`` (intrinsics first, then the extrinsic).
        camera_model: lens model estimated: one of ``vical.geometry.CAMERA_MODELS`` (``radtan``, ``equidistant``,
            ``ds``, ``eucm``, ``omni``, ``omni-radtan``), or ``sensor``: the recording's own lens model (a user knows
            their lens family; the practitioner's sensors draw one per episode, ``sensor.products.lenses``).
        estimate_time_offset: estimate the camera-IMU time offset (camera-IMU solves).
        error_metric: the paper's score, ``intrinsic_relative`` or ``extrinsic_relative`` [%].
        asymmetric_distortion: the sensor's distortion centre is drawn away from the principal
            point (read by the simulator's sensor sampling).
    """

    name: str = "joint"
    calibrate: str = "joint"
    camera_model: str = "radtan"
    estimate_time_offset: bool = True
    error_metric: str = "extrinsic_relative"
    asymmetric_distortion: bool = True

    def __post_init__(self) -> None:
        require(self.calibrate in SOLVES, "task.calibrate", f"one of {SOLVES}", self.calibrate)
        require(self.camera_model in (*CAMERA_MODELS, SENSOR_MODEL), "task.camera_model",
                f"one of {[*CAMERA_MODELS, SENSOR_MODEL]}", self.camera_model)  # fmt: skip
        require(self.error_metric in ERROR_METRICS, "task.error_metric", f"one of {ERROR_METRICS}", self.error_metric)
        if self.error_metric == "extrinsic_relative" and self.calibrate == "intrinsic":
            raise ConfigError(
                "task.error_metric=extrinsic_relative needs a camera-IMU solve, but task.calibrate=intrinsic "
                "estimates no extrinsic; use error_metric=intrinsic_relative"
            )

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> CalibrationTask:
        return from_mapping(cls, cfg, "task")

    def model_of(self, recording: Recording) -> str:
        """The lens model to estimate for ``recording`` (``sensor``: its truth's model, which a user knows)."""
        if self.camera_model != SENSOR_MODEL:
            return self.camera_model
        if recording.truth is None:
            raise ConfigError(f"task.camera_model={SENSOR_MODEL} takes the recording's lens model, but it carries "
                              "no sensor truth; name the model (e.g. task.camera_model=radtan)")  # fmt: skip
        return recording.truth.camera.distortion


@dataclass(frozen=True)
class TaskOutcome:
    """A task's calibration of one recording, its errors against the truth and its score.

    Attributes:
        result: the calibration.
        errors: relative and absolute errors against the recording's truth.
        score: the task's ``error_metric`` [%] (the paper's tables).
    """

    result: CalibrationResult
    errors: CalibrationErrors
    score: float


def calibrate_task(
    task: CalibrationTask,
    recording: Recording,
    intrinsic_frames: CameraFrames | None = None,
    options: ViOptions | None = None,
) -> CalibrationResult:
    """Run ``task``'s solve on ``recording``.

    Args:
        task: the task.
        recording: frames, IMU and target; its ``truth`` supplies the known intrinsics of the
            ``extrinsic`` solve and the IMU noise densities and grade of the camera-IMU solves.
        intrinsic_frames: frames of another recording of the same camera for the intrinsic
            stage of ``two_stage`` (the paper's baselines run an intrinsic trajectory, then an
            extrinsic one); None uses the recording's own frames.
        options: camera-IMU solver settings (``estimate_time_offset`` comes from the task).

    Raises:
        CalibrationError: the data cannot be calibrated (too few views, degenerate motion, ...).
        ConfigError: the solve needs the truth or IMU data that the recording lacks.
    """
    truth = recording.truth
    opts = replace(options or ViOptions(), estimate_time_offset=task.estimate_time_offset)
    opts = opts.with_default_grade(truth.imu_grade if truth is not None else None)
    size = (truth.camera.width, truth.camera.height) if truth else None
    if task.calibrate != "intrinsic" and truth is None:
        raise ConfigError(f"task {task.name}: the recording carries no sensor truth (known intrinsics, IMU noise)")
    known = {"cam0": truth.camera} if task.calibrate == "extrinsic" else None
    return calibrate_rig(
        {"cam0": recording.frames}, recording.imu, recording.target, task.calibrate, task.model_of(recording),
        {"cam0": size}, truth.imu_noise if truth else None, known, options=opts,
        intrinsic_frames=None if intrinsic_frames is None else {"cam0": intrinsic_frames},
    ).results["cam0"]  # fmt: skip


def task_score(task: CalibrationTask, errors: CalibrationErrors) -> float:
    """The task's ``error_metric`` [%] from ``errors``."""
    if task.error_metric == "intrinsic_relative":
        return float(errors.intrinsic_pct)
    return float(errors.extrinsic_pct)


def run_task(
    task: CalibrationTask,
    recording: Recording,
    intrinsic_frames: CameraFrames | None = None,
    options: ViOptions | None = None,
) -> TaskOutcome:
    """Calibrate ``recording`` as ``task`` says and score it against the recording's truth."""
    if recording.truth is None:
        raise ConfigError(f"task {task.name}: scoring needs the recording's sensor truth, and it has none")
    result = calibrate_task(task, recording, intrinsic_frames, options)
    errors = calibration_errors(result, recording.truth)
    return TaskOutcome(result, errors, task_score(task, errors))
