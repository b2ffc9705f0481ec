"""The calibration pipeline: every task, one camera or a rig, through one dispatcher (``calibrate_rig``).

Each camera's detections are collected once; the intrinsic stage (the intrinsic task, the joint task's start,
the two-stage task's first stage) and the camera-IMU graph (``vical.calib.solve.visual_inertial``) work on them. A
one-camera calibration is a rig of one: ``calibrate_extrinsics``, ``calibrate_joint`` and ``calibrate_two_stage``
are ``calibrate_rig`` on ``{"cam0": frames}``, and ``vical-calibrate``, the tasks of the environment and the
evaluation (``vical.calib.tasks``) and ``vical-collect`` all call it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.result import CalibrationResult, FramePoses
from vical.calib.solve.checks import image_coverage_warnings
from vical.calib.solve.imu_integration import interpolate
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.model_fit import is_model_warning
from vical.calib.solve.observations import FrameObservation, collect_observations
from vical.calib.solve.uncertainty import assess, principal_point_frame_warning
from vical.calib.solve.visual_inertial import CameraInput, ViOptions, run_visual_inertial
from vical.data import CameraFrames, ImuNoise, ImuSamples, Target, seconds_since
from vical.geometry import CameraModel, invert_transform

TASKS = ("intrinsic", "extrinsic", "joint", "two_stage")
JOINT_START_VIEWS = 100  # views (at most, spread over the recording) of the intrinsic stage that starts a joint solve
# With a rolling shutter the joint task's start (a camera-only calibration, every row at one time) is also calibrated
# on the views taken while the gyro turned slowest, this fraction of them (its readout bends them least), and that
# start replaces the every-view one where their focal lengths differ by more than ROLLING_START_DISAGREEMENT.
# Measured on rendered 20 and 40 us/row recordings of fast steps: fx 184 and 14600 px from every view, 563 and 546
# from the slowest 40 % (truth 574 and 581). Where both agree the every-view start is kept: on the real recording
# the slow one moved the joint extrinsic by 0.036 deg, away from the published calibration.
ROLLING_START_FRACTION = 0.4
ROLLING_START_MIN_VIEWS = 10  # fewer slow views than this: the every-view start
ROLLING_START_DISAGREEMENT = 0.05


@dataclass(frozen=True)
class RigCalibration:
    """A camera rig + IMU calibrated in one graph: each camera's result, by Kalibr name, the first camera first.

    Each result holds its camera's intrinsics, ``T_cam_imu``, time offset and their covariance with the
    shared IMU biases; the relative poses follow (``T_cn_cnm1``).
    """

    results: dict[str, CalibrationResult]

    @property
    def names(self) -> list[str]:
        return list(self.results)

    def T_cn_cnm1(self, name: str) -> np.ndarray | None:
        """(4, 4) Kalibr's ``T_cn_cnm1`` of camera ``name``: previous camera's points into its frame (None: first)."""
        index = self.names.index(name)
        if index == 0:
            return None
        previous = self.results[self.names[index - 1]].T_cam_imu
        return self.results[name].T_cam_imu @ invert_transform(previous)


def calibrate_rig(
    frames: dict[str, CameraFrames],
    imu: ImuSamples | None,
    target: Target,
    task: str = "joint",
    model: str = "radtan",
    image_sizes: dict[str, tuple[int, int] | None] | None = None,
    imu_noise: ImuNoise | None = None,
    cameras: dict[str, CameraModel] | None = None,
    initial_T_cam_imu: dict[str, np.ndarray] | None = None,
    initial_time_offsets: dict[str, float] | None = None,
    options: ViOptions | None = None,
    intrinsic_frames: dict[str, CameraFrames] | None = None,
    line_delays: dict[str, float] | None = None,
) -> RigCalibration:
    """Calibrate every camera of ``frames`` as ``task`` says (``"intrinsic"``, ``"extrinsic"``, ``"joint"`` or
    ``"two_stage"``); the camera-IMU tasks put every camera and the IMU in one factor graph.

    ``"intrinsic"`` calibrates each camera alone. ``"two_stage"`` calibrates each camera's intrinsics on its own
    frames first (or on ``intrinsic_frames``: the paper's baselines run an intrinsic trajectory, then an
    extrinsic one), then the rig's extrinsics with those intrinsics fixed; its covariance is block-diagonal (the
    stages' uncertainties are not propagated into each other, which is what the two-stage method does).

    Args:
        frames: each camera's frames by name, the first camera (its frames set the IMU states) first;
            the others' views join the first camera's simultaneous ones (within 5 ms: one trigger).
        imu: the IMU samples (None: the intrinsic task only).
        cameras: known intrinsics by name (needed by ``"extrinsic"``; the starting guess of ``"joint"`` and
            ``"intrinsic"``).
        image_sizes: (W, H) [px] by name, for the intrinsic stage.
        imu_noise: the IMU's noise densities (the paper's values if None).
        initial_T_cam_imu, initial_time_offsets: guesses by name (the translation is used; the rotation
            and offset come in closed form); a camera without one takes its translation from the first
            camera's guess through their simultaneous views.
        options: solver settings (``ViOptions()`` if None); the intrinsic stage uses its ``pixel_sigma``,
            ``huber_k`` and ``frame_stride``.
        line_delays: [s/row] known rolling-shutter line delays by name (0: a global shutter), the prior's centre
            with ``options.rolling_shutter`` (row 0 exposed at the timestamp, ``docs/formats.md``).
    """
    start = time.perf_counter()
    if task not in TASKS:
        raise CalibrationError(f"the calibration task must be one of {TASKS}, not {task!r}")
    opts = options or ViOptions()
    observations = {name: collect_observations(f, target) for name, f in frames.items()}
    known, sizes, other_frames = cameras or {}, image_sizes or {}, intrinsic_frames or {}
    stage = {
        n: _intrinsic_stage(
            task, model, n, known.get(n), sizes.get(n), frames[n], observations[n], target, opts, other_frames.get(n)
        )
        for n in frames
    }
    if task == "joint" and opts.rolling_shutter:
        for n in frames:  # each camera's start calibrated again on its slow views where the readout bent it
            restart = partial(_intrinsic_stage, task, model, n, known.get(n), sizes.get(n), frames[n], target=target,
                              opts=opts)  # fmt: skip
            stage[n] = _slow_start(stage[n], imu, observations[n], restart)
    if task == "intrinsic":
        return RigCalibration(stage)
    models = {n: known[n] if r is None else r.camera for n, r in stage.items()}
    guesses, offsets = initial_T_cam_imu or {}, initial_time_offsets or {}
    posed = {n: _start_poses(stage[n], task) for n in frames}
    delays = line_delays or {}
    inputs = [
        CameraInput(
            n, observations[n], models[n], guesses.get(n), offsets.get(n, 0.0), frames[n], posed[n], delays.get(n, 0.0)
        )
        for n in frames
    ]
    solved = run_visual_inertial(
        "joint" if task == "joint" else "extrinsic", inputs[0], imu, target, imu_noise or ImuNoise(), opts, start,
        inputs[1:],
    )  # fmt: skip
    results = dict(zip(frames, solved, strict=True))
    if task == "two_stage":
        elapsed = time.perf_counter() - start
        return RigCalibration({n: _combine(stage[n], r, elapsed) for n, r in results.items()})
    if task == "joint":
        results = {n: _with_joint_warnings(r, observations[n], stage[n]) for n, r in results.items()}
    return RigCalibration(results)


def _intrinsic_stage(
    task: str,
    model: str,
    name: str,
    known: CameraModel | None,
    size: tuple[int, int] | None,
    frames: CameraFrames,
    observations: list[FrameObservation],
    target: Target,
    opts: ViOptions,
    other_frames: CameraFrames | None = None,
) -> CalibrationResult | None:
    """A camera's intrinsic calibration: the intrinsic task's result, the joint task's start, the two-stage task's
    first stage; None for the extrinsic task, which needs its known intrinsics."""
    if task == "extrinsic":
        if known is None:
            raise CalibrationError(f"the extrinsic task needs the intrinsics of every camera; {name} has none")
        return None
    if task == "two_stage":  # the two-stage method calibrates the camera alone, from its own start
        stage_frames = other_frames or frames
        return calibrate_intrinsics(
            stage_frames, target, model, size, None, opts.pixel_sigma, opts.huber_k, frame_stride=opts.frame_stride,
            observations=None if other_frames is not None else observations,
        )  # fmt: skip
    if task == "intrinsic":
        return calibrate_intrinsics(
            frames, target, model, size, known, opts.pixel_sigma, opts.huber_k, frame_stride=opts.frame_stride,
            observations=observations,
        )  # fmt: skip
    # The joint task's start: a hundred views spread over the recording are plenty (a real 30 s recording has
    # 600, whose own solve and outlier screen took 1.9 s of the joint task's 3.6 s). The joint graph starts from
    # the poses it solves (each view posed once), screens every view for outliers once and judges the image
    # coverage on all of them; the other models are fitted on these views only where the model does not fit.
    stride = max(opts.frame_stride, len(frames) // JOINT_START_VIEWS)
    return calibrate_intrinsics(
        frames, target, model, size, known, opts.pixel_sigma, opts.huber_k, frame_stride=stride,
        observations=observations, joint_start=True,
    )  # fmt: skip


def _slow_start(
    start: CalibrationResult,
    imu: ImuSamples | None,
    observations: list[FrameObservation],
    restart: Callable[[list[FrameObservation]], CalibrationResult],
) -> CalibrationResult:
    """A rolling shutter's joint start: the camera-only calibration of the ``ROLLING_START_FRACTION`` of the views
    taken while the gyro turned slowest (at their stamps; the time offset hardly matters here) where its focal length
    differs from the every-view ``start``'s by more than ``ROLLING_START_DISAGREEMENT``: the readout has bent the
    fast views; else ``start`` (a global shutter's, or a mild readout's, start is kept as it was)."""
    if imu is None or len(imu) < 2:
        return start
    t = np.array([o.t_ns for o in observations], dtype=np.int64)
    rates = np.linalg.norm(interpolate(seconds_since(imu.t, imu.t[0]), imu.gyro, seconds_since(t, imu.t[0])), axis=1)
    limit = np.quantile(rates, ROLLING_START_FRACTION)
    slow = [o for o, rate in zip(observations, rates, strict=True) if rate <= limit]
    if len(slow) < ROLLING_START_MIN_VIEWS:
        return start
    slow_start = restart(slow)
    return slow_start if abs(start.camera.fx / slow_start.camera.fx - 1.0) > ROLLING_START_DISAGREEMENT else start


def _start_poses(stage: CalibrationResult | None, task: str) -> FramePoses | None:
    """The joint task's intrinsic start posed its views with the camera the joint graph starts from: the graph
    starts from those poses instead of posing the views again."""
    return stage.frame_poses if task == "joint" and stage is not None else None


def _with_joint_warnings(
    result: CalibrationResult, observations: list[FrameObservation], start: CalibrationResult
) -> CalibrationResult:
    """The joint result with the image coverage of every view and the start's warning that the lens model does not
    fit (if any, with the other models' fit) before its own warnings, and after them the note that its rotation is
    relative to its principal point."""
    coverage = image_coverage_warnings(observations, (result.camera.width, result.camera.height))
    lens = [w for w in start.warnings if is_model_warning(w)]
    frame = principal_point_frame_warning(result.camera, result.parameter_names, result.covariance)
    return replace(result, warnings=coverage + lens + result.warnings + [frame], model_fits=start.model_fits)


def _combine(intrinsic: CalibrationResult, extrinsic: CalibrationResult, elapsed: float) -> CalibrationResult:
    """The two-stage result: both stages' parameters, their covariance block-diagonal."""
    if intrinsic.camera != extrinsic.camera:
        raise CalibrationError("internal: the extrinsic stage did not use the intrinsic stage's camera")
    n_i, n_e = len(intrinsic.estimate), len(extrinsic.estimate)
    covariance = np.zeros((n_i + n_e, n_i + n_e))
    covariance[:n_i, :n_i] = intrinsic.covariance
    covariance[n_i:, n_i:] = extrinsic.covariance
    names = intrinsic.parameter_names + extrinsic.parameter_names
    estimate = np.concatenate([intrinsic.estimate, extrinsic.estimate])
    imu_terms = [replace(t, effect=np.vstack([np.zeros((n_i, t.effect.shape[1])), t.effect]))
                 for t in extrinsic.unmodelled_imu]  # fmt: skip
    assessment = assess(names, covariance, extrinsic.camera)  # its warnings: each stage's, below
    return replace(
        extrinsic,
        task="two_stage",
        parameter_names=names,
        estimate=estimate,
        covariance=covariance,
        unmodelled_imu=imu_terms,
        weak_parameters=assessment.weak_parameters,
        correlations=assessment.correlations,
        iterations=intrinsic.iterations + extrinsic.iterations,
        solve_time=elapsed,
        warnings=intrinsic.warnings + extrinsic.warnings,
    )


# ---------------------------------------------------------------------------------------- one camera
def calibrate_extrinsics(
    frames: CameraFrames,
    imu: ImuSamples,
    target: Target,
    camera: CameraModel,
    imu_noise: ImuNoise | None = None,
    initial_T_cam_imu: np.ndarray | None = None,
    initial_time_offset: float = 0.0,
    options: ViOptions | None = None,
) -> CalibrationResult:
    """Camera-IMU extrinsic ``T_cam_imu``, time offset and IMU biases with known intrinsics.

    Args:
        frames: camera frames with target detections (camera clock).
        imu: IMU samples (IMU clock).
        target: the calibration target.
        camera: the camera's (known) intrinsics.
        imu_noise: IMU noise densities (the paper's values if None).
        initial_T_cam_imu: (4, 4) guess (``nominal_T_cam_imu()`` if None); only its translation is
            used, the rotation comes in closed form from the gyro.
        initial_time_offset: [s] centre of the time-offset scan.
        options: solver settings (``ViOptions()`` if None).
    """
    return _one_camera(frames, imu, target, "extrinsic", "radtan", None, imu_noise, camera, initial_T_cam_imu,
                       initial_time_offset, options)  # fmt: skip


def calibrate_joint(
    frames: CameraFrames,
    imu: ImuSamples,
    target: Target,
    model: str = "radtan",
    image_size_px: tuple[int, int] | None = None,
    imu_noise: ImuNoise | None = None,
    initial_camera: CameraModel | None = None,
    initial_T_cam_imu: np.ndarray | None = None,
    initial_time_offset: float = 0.0,
    options: ViOptions | None = None,
) -> CalibrationResult:
    """Intrinsics, distortion, ``T_cam_imu``, time offset and biases in one factor graph.

    Initialised by ``calibrate_intrinsics`` on the same frames (whose warning that the model does not fit
    the lens, if any, the result carries); arguments as in ``calibrate_intrinsics`` and ``calibrate_extrinsics``.
    """
    return _one_camera(frames, imu, target, "joint", model, image_size_px, imu_noise, initial_camera,
                       initial_T_cam_imu, initial_time_offset, options)  # fmt: skip


def calibrate_two_stage(
    frames: CameraFrames,
    imu: ImuSamples,
    target: Target,
    model: str = "radtan",
    image_size_px: tuple[int, int] | None = None,
    imu_noise: ImuNoise | None = None,
    initial_T_cam_imu: np.ndarray | None = None,
    initial_time_offset: float = 0.0,
    options: ViOptions | None = None,
    intrinsic_frames: CameraFrames | None = None,
) -> CalibrationResult:
    """The paper's two-stage mode: intrinsics first (optionally from other frames), then the extrinsic
    (``calibrate_rig``'s ``"two_stage"``)."""
    return _one_camera(frames, imu, target, "two_stage", model, image_size_px, imu_noise, None, initial_T_cam_imu,
                       initial_time_offset, options, intrinsic_frames)  # fmt: skip


def _one_camera(
    frames, imu, target, task, model, size, imu_noise, camera, T_guess, offset, options, intrinsic_frames=None
) -> CalibrationResult:
    """``calibrate_rig`` on a rig of one camera (``cam0``)."""
    return calibrate_rig(
        {"cam0": frames}, imu, target, task, model, {"cam0": size}, imu_noise,
        None if camera is None else {"cam0": camera},
        None if T_guess is None else {"cam0": T_guess}, {"cam0": offset}, options,
        None if intrinsic_frames is None else {"cam0": intrinsic_frames},
    ).results["cam0"]  # fmt: skip
