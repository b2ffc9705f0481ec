"""An independent camera-IMU extrinsic calibration: a plain GTSAM graph with the declared IMU noise.

The peer that ``bench_realdata.py`` measures vical against. It imports nothing from vical: GTSAM's default
factors (``ProjectionFactorPPPCal3DS2`` per corner, ``CombinedImuFactor`` between consecutive frames) and its
Levenberg-Marquardt solver, OpenCV's ``solvePnP`` for the initial poses. The navigation frame is the board's;
gravity's direction comes from the mean specific force and is refined once by solving again. The time offset is
not estimated (the rig it is meant for is hardware-synchronised).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import gtsam
import gtsam_unstable
import numpy as np

GRAVITY = 9.81  # [m/s^2]


@dataclass
class Frames:
    """One camera's views: stamps (F,) int64 [ns], per frame the pixels (K, 2) and board points (K, 3) [m]."""

    t_ns: np.ndarray
    pixels: list[np.ndarray]
    points: list[np.ndarray]


@dataclass
class PlainResult:
    T_cam_imu: np.ndarray  # (4, 4)
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    iterations: int


def _pnp(K: np.ndarray, dist: np.ndarray, pixels: np.ndarray, points: np.ndarray) -> np.ndarray | None:
    """T_cam_board of one view, or None."""
    ok, rvec, tvec = cv2.solvePnP(np.ascontiguousarray(points), np.ascontiguousarray(pixels), K, dist)
    if not ok:
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T


def _hand_eye_rotation(T_board_cam: np.ndarray, times: np.ndarray, t_imu: np.ndarray, gyro: np.ndarray) -> np.ndarray:
    """R_cam_imu aligning the cameras' rotation increments (camera frame) with the gyro's mean rate (Kabsch)."""
    cam, imu = [], []
    for n in range(len(times) - 1):
        dR = T_board_cam[n, :3, :3].T @ T_board_cam[n + 1, :3, :3]
        inside = (t_imu >= times[n]) & (t_imu < times[n + 1])
        if inside.any():
            cam.append(cv2.Rodrigues(dR)[0].ravel())
            imu.append(gyro[inside].mean(axis=0) * (times[n + 1] - times[n]))
    U, _, Vt = np.linalg.svd(np.array(cam).T @ np.array(imu))
    D = np.diag([1.0, 1.0, np.linalg.det(U @ Vt)])
    return U @ D @ Vt


def _preintegrate(params, t_imu, gyro, accel, ta: float, tb: float, bias) -> gtsam.PreintegratedCombinedMeasurements:
    """Samples between two frame instants, each held until the next sample (clipped to [ta, tb])."""
    pim = gtsam.PreintegratedCombinedMeasurements(params, bias)
    k = max(int(np.searchsorted(t_imu, ta, side="right")) - 1, 0)  # the sample held at ta
    t = ta
    while t < tb and k < len(t_imu):
        t_next = min(t_imu[k + 1] if k + 1 < len(t_imu) else tb, tb)
        dt = t_next - t
        if dt > 0:
            pim.integrateMeasurement(accel[k], gyro[k], dt)
        t, k = t_next, k + 1
    return pim


def calibrate(
    frames: Frames,
    t_imu_ns: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    K: np.ndarray,
    dist: np.ndarray,
    noise: dict,
    pixel_sigma: float = 0.5,
    min_corners: int = 12,
) -> PlainResult:
    """Camera-IMU extrinsic and biases.

    Args:
        frames: the camera's views; t_imu_ns, gyro, accel: the IMU samples (rad/s, m/s^2).
        K, dist: the known intrinsics (OpenCV's radtan [k1, k2, p1, p2]).
        noise: Kalibr's imu.yaml densities (``gyroscope_noise_density``, ...), continuous time.
        pixel_sigma: [px] corner noise.
    """
    t0 = min(int(t_imu_ns[0]), int(frames.t_ns[0]))
    t_imu = (t_imu_ns - t0) / 1e9
    used, T_board_cam = [], []
    for k in range(len(frames.t_ns)):
        tk = (frames.t_ns[k] - t0) / 1e9
        if len(frames.pixels[k]) < min_corners or not (t_imu[0] <= tk < t_imu[-1]):
            continue
        T = _pnp(K, dist, frames.pixels[k], frames.points[k])
        if T is not None:
            used.append(k)
            T_board_cam.append(np.linalg.inv(T))
    times = (frames.t_ns[used] - t0) / 1e9
    T_cam_imu_guess = np.eye(4)
    T_cam_imu_guess[:3, :3] = _hand_eye_rotation(np.array(T_board_cam), times, t_imu, gyro)
    T_board_imu = np.array(T_board_cam) @ T_cam_imu_guess
    f_board = np.array([T[:3, :3] @ accel[np.searchsorted(t_imu, t)] for T, t in zip(T_board_imu, times, strict=True)])
    gravity = -f_board.mean(axis=0)
    gravity *= GRAVITY / np.linalg.norm(gravity)
    for _ in range(2):  # the second pass with gravity refined from the first's states
        result, values = _solve(frames, used, times, T_board_imu, t_imu, gyro, accel, K, dist, T_cam_imu_guess,
                                noise, pixel_sigma, gravity)  # fmt: skip
        gravity = _refined_gravity(values, len(used), times, t_imu, accel)
        T_board_imu = np.array([values.atPose3(gtsam.symbol("x", n)).matrix() for n in range(len(used))])
        T_cam_imu_guess = result.T_cam_imu
    return result


def _refined_gravity(values: gtsam.Values, n: int, times: np.ndarray, t_imu: np.ndarray, accel: np.ndarray):
    """Gravity (board frame, magnitude GRAVITY) from the solved states: the mean acceleration (velocity change over
    the time) minus the mean specific force rotated into the board frame, bias-corrected."""
    ba = np.asarray(values.atConstantBias(gtsam.symbol("b", 0)).accelerometer())
    v0, v1 = values.atVector(gtsam.symbol("v", 0)), values.atVector(gtsam.symbol("v", n - 1))
    forces = [values.atPose3(gtsam.symbol("x", i)).rotation().matrix() @ (accel[np.searchsorted(t_imu, t)] - ba)
              for i, t in enumerate(times)]  # fmt: skip
    g = (v1 - v0) / (times[-1] - times[0]) - np.mean(forces, axis=0)
    return g * GRAVITY / np.linalg.norm(g)


def _solve(frames, used, times, T_board_imu, t_imu, gyro, accel, K, dist, T_cam_imu, noise, pixel_sigma, gravity):
    X, V, B, E = (lambda i, c=c: gtsam.symbol(c, i) for c in "xvbe")
    L = lambda j: gtsam.symbol("l", j)  # noqa: E731
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    cal = gtsam.Cal3DS2(K[0, 0], K[1, 1], 0.0, K[0, 2], K[1, 2], *dist[:4])
    pixel = gtsam.noiseModel.Isotropic.Sigma(2, pixel_sigma)
    values.insert(E(0), gtsam.Pose3(np.linalg.inv(T_cam_imu)))  # T_imu_cam
    points = np.unique(np.concatenate([frames.points[k] for k in used]), axis=0)
    for j, p in enumerate(points):
        values.insert(L(j), gtsam.Point3(*p))
        graph.add(gtsam.PriorFactorPoint3(L(j), gtsam.Point3(*p), gtsam.noiseModel.Isotropic.Sigma(3, 1e-6)))
    lookup = {tuple(p): j for j, p in enumerate(points)}
    vel = np.gradient(T_board_imu[:, :3, 3], times, axis=0)
    for n, k in enumerate(used):
        values.insert(X(n), gtsam.Pose3(T_board_imu[n]))
        values.insert(V(n), vel[n])
        values.insert(B(n), gtsam.imuBias.ConstantBias())
        for uv, p in zip(frames.pixels[k], frames.points[k], strict=True):
            landmark = L(lookup[tuple(p)])
            graph.add(gtsam_unstable.ProjectionFactorPPPCal3DS2(gtsam.Point2(*uv), pixel, X(n), E(0), landmark,
                                                                cal))  # fmt: skip
    params = gtsam.PreintegrationCombinedParams(gtsam.Point3(*gravity))
    params.setGyroscopeCovariance(noise["gyroscope_noise_density"] ** 2 * np.eye(3))
    params.setAccelerometerCovariance(noise["accelerometer_noise_density"] ** 2 * np.eye(3))
    params.setIntegrationCovariance(1e-8 * np.eye(3))
    params.setBiasOmegaCovariance(noise["gyroscope_random_walk"] ** 2 * np.eye(3))
    params.setBiasAccCovariance(noise["accelerometer_random_walk"] ** 2 * np.eye(3))
    zero = gtsam.imuBias.ConstantBias()
    for n in range(len(used) - 1):
        pim = _preintegrate(params, t_imu, gyro, accel, times[n], times[n + 1], zero)
        graph.add(gtsam.CombinedImuFactor(X(n), V(n), X(n + 1), V(n + 1), B(n), B(n + 1), pim))
    graph.add(
        gtsam.PriorFactorConstantBias(B(0), zero, gtsam.noiseModel.Diagonal.Sigmas(np.r_[np.ones(3), 0.1 * np.ones(3)]))
    )
    lm = gtsam.LevenbergMarquardtParams()
    lm.setMaxIterations(50)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, lm)
    solution = optimizer.optimize()
    bias = solution.atConstantBias(B(0))
    T_cam_imu = np.linalg.inv(solution.atPose3(E(0)).matrix())
    result = PlainResult(
        T_cam_imu, np.asarray(bias.gyroscope()), np.asarray(bias.accelerometer()), optimizer.iterations()
    )
    return result, solution
