"""Public entry points: intrinsic, extrinsic (known intrinsics), joint and two-stage calibration."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from vical.calib.checks import image_coverage_warnings
from vical.calib.errors import CalibrationError
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.model_fit import is_model_warning
from vical.calib.observations import collect_observations
from vical.calib.result import CalibrationResult
from vical.calib.uncertainty import correlations, weak_parameters
from vical.calib.visual_inertial import CameraInput, ViOptions, run_visual_inertial
from vical.data import CameraFrames, ImuNoise, ImuSamples, Target
from vical.geometry import CameraModel, invert_transform

JOINT_START_VIEWS = 100  # views (at most, spread over the recording) of the intrinsic stage that starts a joint solve


def _start_stride(frames: CameraFrames, opts: ViOptions) -> int:
    """The frame stride of the intrinsic stage that starts a joint solve.

    That stage only gives the start: a hundred views spread over the recording are plenty (a real 30 s
    recording has 600, whose own solve and outlier screen took 1.9 s of the joint task's 3.6 s); recordings of
    up to 199 frames keep every one.
    """
    return max(opts.frame_stride, len(frames) // JOINT_START_VIEWS)


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
    start = time.perf_counter()
    return run_visual_inertial(
        "extrinsic", frames, imu, target, camera, imu_noise or ImuNoise(), initial_T_cam_imu,
        initial_time_offset, options or ViOptions(), start,
    )[0]  # fmt: skip


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
    start = time.perf_counter()
    opts = options or ViOptions()
    intrinsic = calibrate_intrinsics(
        frames, target, model, image_size_px, initial_camera, opts.pixel_sigma, opts.huber_k,
        frame_stride=_start_stride(frames, opts), compare_models=False,
    )  # fmt: skip
    result = run_visual_inertial(
        "joint", frames, imu, target, intrinsic.camera, imu_noise or ImuNoise(), initial_T_cam_imu,
        initial_time_offset, opts, start,
    )[0]  # fmt: skip
    size = (intrinsic.camera.width, intrinsic.camera.height)
    coverage = image_coverage_warnings(collect_observations(frames, target), size)
    lens = [w for w in intrinsic.warnings if is_model_warning(w)]
    return replace(result, warnings=coverage + lens + result.warnings)


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
    """The paper's two-stage mode: intrinsics first (optionally from other frames), then the extrinsic.

    The covariance is block-diagonal: the stages' uncertainties are not propagated into each
    other (the extrinsic block assumes the intrinsics exact), which is what the two-stage method does.
    """
    start = time.perf_counter()
    opts = options or ViOptions()
    intrinsic = calibrate_intrinsics(
        intrinsic_frames or frames, target, model, image_size_px, None, opts.pixel_sigma, opts.huber_k,
        frame_stride=opts.frame_stride,
    )  # fmt: skip
    extrinsic = calibrate_extrinsics(
        frames, imu, target, intrinsic.camera, imu_noise, initial_T_cam_imu, initial_time_offset, opts
    )
    return _combine(intrinsic, extrinsic, time.perf_counter() - start)


def _combine(intrinsic: CalibrationResult, extrinsic: CalibrationResult, elapsed: float) -> CalibrationResult:
    if intrinsic.camera != extrinsic.camera:
        raise CalibrationError("internal: the extrinsic stage did not use the intrinsic stage's camera")
    n_i, n_e = len(intrinsic.estimate), len(extrinsic.estimate)
    covariance = np.zeros((n_i + n_e, n_i + n_e))
    covariance[:n_i, :n_i] = intrinsic.covariance
    covariance[n_i:, n_i:] = extrinsic.covariance
    names = intrinsic.parameter_names + extrinsic.parameter_names
    estimate = np.concatenate([intrinsic.estimate, extrinsic.estimate])
    return replace(
        extrinsic,
        task="two_stage",
        parameter_names=names,
        estimate=estimate,
        covariance=covariance,
        weak_parameters=weak_parameters(names, covariance, extrinsic.camera),
        correlations=correlations(names, covariance),
        iterations=intrinsic.iterations + extrinsic.iterations,
        solve_time=elapsed,
        warnings=intrinsic.warnings + extrinsic.warnings,
    )


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
    imu: ImuSamples,
    target: Target,
    task: str = "joint",
    model: str = "radtan",
    image_sizes: dict[str, tuple[int, int]] | None = None,
    imu_noise: ImuNoise | None = None,
    cameras: dict[str, CameraModel] | None = None,
    initial_T_cam_imu: dict[str, np.ndarray] | None = None,
    initial_time_offsets: dict[str, float] | None = None,
    options: ViOptions | None = None,
) -> RigCalibration:
    """Every camera of a rig and the IMU in one factor graph (``task`` ``"joint"``, ``"extrinsic"`` or ``"two_stage"``).

    ``"two_stage"`` calibrates each camera's intrinsics on its own frames first, then the rig's
    extrinsics with those intrinsics fixed (per camera, the covariance as ``calibrate_two_stage``'s).

    Args:
        frames: each camera's frames by name, the first camera (its frames set the IMU states) first;
            the others' views join the first camera's simultaneous ones (within 5 ms: one trigger).
        cameras: known intrinsics by name (needed by ``"extrinsic"``; the joint task's initial guess).
        image_sizes: (W, H) [px] by name, for the joint task's intrinsic initialisation.
        initial_T_cam_imu, initial_time_offsets: guesses by name (the translation is used; the rotation
            and offset come in closed form); a camera without one takes its translation from the first
            camera's guess through their simultaneous views.
        Other arguments as in ``calibrate_joint``.
    """
    start = time.perf_counter()
    opts = options or ViOptions()
    if task not in ("joint", "extrinsic", "two_stage"):
        raise CalibrationError(f"a rig is calibrated by the joint, the extrinsic or the two-stage task, not {task!r}")
    intrinsic = {
        name: _rig_intrinsics(name, frames[name], target, task, model, image_sizes, cameras, opts) for name in frames
    }
    models = {name: (cameras or {})[name] if r is None else r.camera for name, r in intrinsic.items()}
    observations = {name: collect_observations(f, target) for name, f in frames.items()}
    guesses, offsets = initial_T_cam_imu or {}, initial_time_offsets or {}
    first, *rest = frames
    others = [CameraInput(n, observations[n], models[n], guesses.get(n), offsets.get(n, 0.0), frames[n]) for n in rest]
    results = run_visual_inertial(
        "joint" if task == "joint" else "extrinsic", frames[first], imu, target, models[first],
        imu_noise or ImuNoise(), guesses.get(first), offsets.get(first, 0.0), opts, start, others,
    )  # fmt: skip
    if task == "two_stage":
        elapsed = time.perf_counter() - start
        results = [_combine(intrinsic[n], r, elapsed) for n, r in zip(frames, results, strict=True)]
    if task == "joint":
        results = [
            replace(
                r, warnings=image_coverage_warnings(observations[n], (r.camera.width, r.camera.height)) + r.warnings
            )
            for n, r in zip(frames, results, strict=True)
        ]
    return RigCalibration(dict(zip(frames, results, strict=True)))


def _rig_intrinsics(name, frames, target, task, model, image_sizes, cameras, opts) -> CalibrationResult | None:
    """A camera's intrinsic calibration (the joint task's start, the two-stage task's first stage); None for the
    extrinsic task, which needs its known intrinsics."""
    known = (cameras or {}).get(name)
    if task == "extrinsic":
        if known is None:
            raise CalibrationError(f"the extrinsic task needs the intrinsics of every camera; {name} has none")
        return None
    size = (image_sizes or {}).get(name)
    initial = known if task == "joint" else None  # the two-stage method calibrates the camera alone
    stride = _start_stride(frames, opts) if task == "joint" else opts.frame_stride
    return calibrate_intrinsics(
        frames, target, model, size, initial, opts.pixel_sigma, opts.huber_k, frame_stride=stride
    )
