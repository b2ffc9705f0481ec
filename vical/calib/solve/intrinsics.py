"""Intrinsic calibration (pinhole + radtan or equidistant, double sphere, extended unified, omni with or without
radtan) from target observations.

Graph: one ``Pose3`` per frame (the camera pose in the target frame, ``T_target_cam``), the camera
parameters ``[fx, fy, cx, cy, *coefficients]`` (4 + the model's coefficients, no skew, as Kalibr's models) and
one corner factor per frame (``vical.calib.solve.corner_factors``: the target points are constants).
Initialisation: Zhang's focal lengths from plane homographies (principal point at the image centre,
no distortion; wide-angle models from the focal length that best straightens the views), then PnP
per frame. A radtan solve that this start leaves unconverged or with its principal point outside the
image is solved again from OpenCV's ``calibrateCamera`` (``initialization.opencv_camera``), and the
better of the two kept.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.frame_log import build_frame_log, left_out
from vical.calib.result import CalibrationResult, FramePoses, ResidualStats
from vical.calib.solve.checks import image_coverage_warnings
from vical.calib.solve.corner_factors import CornerFactors, CornerKeys
from vical.calib.solve.initialization import (
    MIN_INIT_CORNERS,
    frame_poses,
    initial_camera,
    opencv_camera,
    starting_camera,
)
from vical.calib.solve.model_fit import COMPARISON, lens_misfit, misfit_warnings
from vical.calib.solve.observations import FrameObservation, collect_observations, image_size
from vical.calib.solve.outliers import Rejection, reject_outliers
from vical.calib.solve.solver import covariance_or_unobservable, optimize
from vical.calib.solve.uncertainty import assess
from vical.data import CameraFrames, Target
from vical.geometry import (
    CAMERA_MODELS,
    COEFFICIENT_NAMES,
    DISTORTION_MODELS,
    CameraModel,
    CameraModelError,
    invert_transform,
)

MIN_VIEWS = 3  # intrinsics with a free principal point need three views of a plane (Zhang)
SAME_FIT = 0.02  # models whose reprojection rms lie within 2 % of each other fit alike
MODELS = CAMERA_MODELS

K_KEY = gtsam.symbol("k", 0)


def pose_key(k: int) -> int:
    return gtsam.symbol("x", k)


def distortion_names(model: str) -> list[str]:
    """Names of the coefficients of ``model`` beside focal length and principal point."""
    return list(COEFFICIENT_NAMES[model])


def intrinsic_names(model: str) -> list[str]:
    return ["fx", "fy", "cx", "cy", *distortion_names(model)]


def check_model(model: str) -> None:
    if model not in MODELS:
        raise CalibrationError(f"camera model {model!r} is not supported; use one of {list(MODELS)}")


def _build_graph(
    camera: CameraModel,
    observations: list[FrameObservation],
    poses: dict[int, np.ndarray],
    sigma_px: float,
    huber_k: float | None,
) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    keys = CornerKeys(poses=[pose_key(k) for k in poses], camera=K_KEY)
    corners = CornerFactors([observations[k] for k in poses], camera, keys, sigma_px, huber_k)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for factor in corners.factors():
        graph.add(factor)
    values.insert(K_KEY, camera.parameters)
    for k, T_cam_target in poses.items():
        values.insert(pose_key(k), gtsam.Pose3(invert_transform(T_cam_target)))
    return graph, values


@dataclass
class _Solve:
    """One intrinsic solve over fixed observations: ``solve(camera0, poses)`` from a starting point.

    Returns the calibrated camera, ``{observation index: T_cam_target}``, the graph and the solution.
    """

    observations: list[FrameObservation]
    sigma_px: float
    huber_k: float | None
    max_iterations: int

    def __call__(self, camera0: CameraModel, poses: dict[int, np.ndarray]):
        graph, values = _build_graph(camera0, self.observations, poses, self.sigma_px, self.huber_k)
        solution = optimize(graph, values, self.max_iterations, "intrinsic calibration")
        camera = camera0.with_parameters(solution.values.atVector(K_KEY))
        T_cam_target = {k: invert_transform(solution.values.atPose3(pose_key(k)).matrix()) for k in poses}
        return camera, T_cam_target, graph, solution


def reprojection_residuals(
    camera: CameraModel, observations: list[FrameObservation], T_cam_target: dict[int, np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measured minus predicted pixels (N, 2) [px], the frame index (N,) and measured pixel (N, 2) of each corner."""
    res, frame = [], []
    for k, T in T_cam_target.items():
        obs = observations[k]
        res.append(obs.residuals(camera, T))
        frame.append(np.full(len(obs.ids), obs.index))
    pixels = np.concatenate([observations[k].uv for k in T_cam_target])
    return np.concatenate(res), np.concatenate(frame), pixels


def estimated_pixel_sigma(residuals: np.ndarray, num_params: int) -> float:
    """A-posteriori corner noise [px]: ``sqrt(sum r^2 / (2 N - num_params))`` (per image axis)."""
    dof = residuals.size - num_params
    if dof <= 0:
        raise CalibrationError(f"too few corners ({len(residuals)}) for {num_params} parameters")
    return float(np.sqrt(np.sum(residuals**2) / dof))


def calibrate_intrinsics(
    frames: CameraFrames,
    target: Target,
    model: str = "radtan",
    image_size_px: tuple[int, int] | None = None,
    initial_camera_guess: CameraModel | None = None,
    pixel_sigma: float | None = None,
    huber_k: float | None = None,
    max_iterations: int = 50,
    frame_stride: int = 1,
    compare_models: bool = True,
    observations: list[FrameObservation] | None = None,
    joint_start: bool = False,
) -> CalibrationResult:
    """Calibrate the camera's intrinsics and distortion from target observations.

    When the residuals show that the model does not fit the lens (``vical.calib.solve.model_fit``), the
    result warns, and (``compare_models``) the other models are calibrated on the same corners and
    their fit is listed in the warnings.

    Args:
        frames: camera frames with corner detections.
        target: the calibration target.
        model: ``"radtan"`` (as GTSAM's ``Cal3DS2``), ``"equidistant"`` (``Cal3Fisheye``), or a wide-angle
            model (``"ds"``, ``"eucm"``, ``"omni"``, ``"omni-radtan"``: ``vical.geometry.wide_angle``).
        image_size_px: ``(width, height)`` [px]; taken from ``frames.images`` or the initial guess if None.
        initial_camera_guess: starting intrinsics (Zhang's closed form if None).
        pixel_sigma: [px] corner noise; None estimates it from the residuals and scales the covariance.
        huber_k: Huber kernel width in sigmas (None: plain least squares).
        max_iterations: Levenberg-Marquardt iterations.
        frame_stride: use every ``frame_stride``-th frame with a target view (1: all).
        compare_models: calibrate the other models when this one does not fit.
        observations: the frames' detections (``collect_observations(frames, target)``), when the caller has
            them already.
        joint_start: only the start of a joint solve, which screens every view for outliers once and judges the image
            coverage on all of them: no outlier screen and no coverage warnings here, no other models fitted.
    """
    start = time.perf_counter()
    check_model(model)
    if not (isinstance(frame_stride, int) and frame_stride >= 1):
        raise CalibrationError(f"frame_stride must be an integer >= 1, got {frame_stride!r}")
    every = collect_observations(frames, target) if observations is None else observations
    observations = every[::frame_stride]
    if image_size_px is None and initial_camera_guess is not None:
        image_size_px = (initial_camera_guess.width, initial_camera_guess.height)
    size = image_size(frames, image_size_px)
    camera0 = initial_camera_guess or _start(observations, model, size)
    if camera0.distortion != model:  # keep the guessed focal length and principal point, start undistorted
        camera0 = starting_camera(model, camera0)
    # Unrefined planar poses: the joint solve refines them, and outliers are judged after it.
    poses = frame_poses(camera0, observations, min(MIN_INIT_CORNERS, target.num_points), refine=False)
    if len(poses) < MIN_VIEWS:
        raise CalibrationError(
            f"intrinsic calibration needs at least {MIN_VIEWS} frames with a usable target view, got {len(poses)} "
            f"(of {len(frames)} frames); collect more views of the whole target"
        )
    sigma_graph = 1.0 if pixel_sigma is None else float(pixel_sigma)
    solve = _Solve(observations, sigma_graph, huber_k, max_iterations)
    camera, T_cam_target, graph, solution = _add_unplaced_frames(
        solve, *solve(camera0, {k: T for k, (T, _) in poses.items()}), min(MIN_INIT_CORNERS, target.num_points)
    )
    if not _settled(camera, solution) and initial_camera_guess is None:
        found = _from_opencv_start(solve, model, size, min(MIN_INIT_CORNERS, target.num_points))
        if found is not None and _better(found[3], solution):
            camera, T_cam_target, graph, solution = found
    # Wrong detections pull the least-squares fit: drop them and solve again from this solution.
    rejection = _screen(camera, observations, T_cam_target, min(MIN_INIT_CORNERS, target.num_points), joint_start)
    if rejection.changed:
        solve.observations = observations = rejection.observations
        camera, T_cam_target, graph, solution = solve(camera, rejection.poses)
    poses = T_cam_target
    residuals, frame_index, pixels = reprojection_residuals(camera, observations, T_cam_target)
    covariance = covariance_or_unobservable(graph.linearize(solution.values), solution.values, [K_KEY])
    if pixel_sigma is None:
        sigma_px = estimated_pixel_sigma(residuals, 6 * len(poses) + len(camera.parameters))
        covariance = covariance * (sigma_px / sigma_graph) ** 2
    else:
        sigma_px = float(pixel_sigma)
    names = intrinsic_names(model)
    assessment = assess(names, covariance, camera)
    decided = left_out(every, observations, rejection.dropped)
    min_corners = min(MIN_INIT_CORNERS, target.num_points)
    comparison = None
    if compare_models:  # (only calibrated where the model does not fit: a joint start's too, for its failure)
        comparison = {"frames": frames, "target": target, "image_size_px": size, "pixel_sigma": pixel_sigma,
                      "huber_k": huber_k, "max_iterations": max_iterations, "frame_stride": frame_stride}  # fmt: skip
    estimate = np.concatenate([camera.intrinsics, camera.dist])
    points = np.concatenate([observations[k].points for k in T_cam_target])
    misfit = lens_misfit(camera, points, pixels, residuals, frame_index)
    model_notes, model_fits = _model_warnings(camera, misfit, residuals, comparison)
    return CalibrationResult(
        task="intrinsic",
        camera=camera,
        T_cam_imu=None,
        time_offset=None,
        gyro_bias=None,
        accel_bias=None,
        gravity_target=None,
        parameter_names=names,
        estimate=estimate,
        covariance=covariance,
        weak_parameters=assessment.weak_parameters,
        correlations=assessment.correlations,
        reprojection=ResidualStats.of(residuals),
        reprojection_residuals=residuals,
        reprojection_frames=frame_index,
        imu_residuals=None,
        pixel_sigma=sigma_px,
        iterations=solution.iterations,
        solve_time=time.perf_counter() - start,
        status=solution.status,
        num_frames=len(poses),
        warnings=rejection.warnings
        + ([] if joint_start else image_coverage_warnings(observations, size))
        + assessment.warnings
        + model_notes,
        frame_log=build_frame_log(frames, frame_index, min_corners, decided),
        reprojection_pixels=pixels,
        frame_poses=FramePoses(
            np.array([observations[k].t_ns for k in T_cam_target], dtype=np.int64),
            np.array(list(T_cam_target.values())),
        ),
        model_fits=model_fits,
        lens_misfit=misfit,
    )


def _screen(camera, observations: list[FrameObservation], T_cam_target: dict, min_corners: int, joint_start: bool):
    """The outlier screen (``reject_outliers``); for a joint solve's start, none: the joint graph screens every view."""
    if joint_start:
        return Rejection(list(observations), dict(T_cam_target), [], 0.0)
    return reject_outliers(camera, observations, T_cam_target, min_corners)


def _start(observations: list[FrameObservation], model: str, size: tuple[int, int]) -> CameraModel:
    """The closed-form start (``initial_camera``); where its homographies cannot give a focal length (views
    nearly head-on), OpenCV's for radtan, whose distortion terms can still pin it."""
    try:
        return initial_camera(observations, model, size)
    except CalibrationError:
        fallback = opencv_camera(observations, size) if model == "radtan" else None
        if fallback is None:
            raise
        return fallback


def _settled(camera: CameraModel, solution) -> bool:
    """A solve that converged to a camera whose principal point lies in its image."""
    return solution.status == "converged" and camera.principal_point_in_image


def _from_opencv_start(solve: _Solve, model: str, size: tuple[int, int], min_corners: int):
    """The solve from OpenCV's start (``initialization.opencv_camera``; radtan only), or None without one."""
    camera0 = opencv_camera(solve.observations, size) if model == "radtan" else None
    if camera0 is None:
        return None
    poses = frame_poses(camera0, solve.observations, min_corners, refine=False)
    if len(poses) < MIN_VIEWS:
        return None
    return solve(camera0, {k: T for k, (T, _) in poses.items()})


def _better(candidate, current) -> bool:
    """Whether the solution ``candidate`` beats ``current``: converged over not, then the lower error."""
    return (candidate.status == "converged", -candidate.error) > (current.status == "converged", -current.error)


def _add_unplaced_frames(solve: _Solve, camera, T_cam_target, graph, solution, min_corners: int):
    """Frames the starting camera could not place (a fisheye's border, far from its starting model) join once the
    solved camera places them: the solve's outputs, solved again with them if any."""
    missing = [k for k in range(len(solve.observations)) if k not in T_cam_target]
    placed = frame_poses(camera, solve.observations, min_corners, refine=False, only=missing)
    if not placed:
        return camera, T_cam_target, graph, solution
    return solve(camera, T_cam_target | {k: T for k, (T, _) in placed.items()})


def best_model(rms: dict[str, float]) -> str:
    """The model that fits best: of those within ``SAME_FIT`` of the lowest rms, the one with the fewest coefficients
    (a model that nests another, omni-radtan in omni, fits the same corners a hair better by its extra terms)."""
    finite = {m: v for m, v in rms.items() if np.isfinite(v)}
    if not finite:
        return next(iter(rms))
    lowest = min(finite.values())
    close = [m for m, v in finite.items() if v <= lowest * (1 + SAME_FIT)]
    return min(close, key=lambda m: (DISTORTION_MODELS[m], finite[m]))


def _model_warnings(camera, misfit, residuals, compare) -> tuple[list[str], dict | None]:
    """``model_fit.misfit_warnings`` of the corners' ``lens_misfit`` and, where the model does not fit and ``compare``
    holds the calibration's settings, the other models' fit on the same corners: the notes, and the models'
    reprojection rms [px] (None where nothing was compared)."""
    notes = misfit_warnings(camera, misfit)
    if not notes or not compare:
        return notes, None
    rms = {camera.distortion: ResidualStats.of(residuals).rms}
    for other in (m for m in MODELS if m != camera.distortion):
        try:
            rms[other] = calibrate_intrinsics(**compare, model=other, compare_models=False).reprojection.rms
        except (CalibrationError, CameraModelError):
            rms[other] = np.nan
    best = best_model(rms)
    listed = ", ".join(f"{m} {v:.3f} px" + (" (used)" if m == camera.distortion else "") for m, v in rms.items())
    return [*notes, f"{COMPARISON}, reprojection rms: {listed}; {best} fits best"], rms
