"""Synthetic camera + IMU recordings from a smooth analytic motion in front of a checkerboard or aprilgrid.

The calibrator is developed and tested on these recordings: everything is exact (the IMU is
computed from analytic derivatives of the motion), so any error the calibrator makes on
noise-free data is its own. The module depends on geometry and data only, never on the
simulator.

Motion model (all in the world frame, z up, gravity ``[0, 0, -9.81]`` m/s^2):

- camera orientation ``R_world_cam(t) = R_nominal @ euler_to_matrix(e(t))`` where ``e(t)`` is a
  sum of sinusoids per angle (roll tilts the view up/down, pitch pans, yaw turns about the
  optical axis);
- the target centre stays at camera-frame point ``q(t) = [qx(t), qy(t), d(t)]`` (sinusoids), so
  the board is always in view while the camera orbits it: ``p_cam = c - R_world_cam q``;
- the IMU rides on the camera: ``T_world_imu = T_world_cam @ T_cam_imu``.

The IMU reads ``gyro = R_imu_cam omega_cam`` and ``accel = R_world_imu^T (a_imu - g)`` exactly
(Kalibr's specific force), plus optional white noise and bias random walks from ``ImuNoise``.
A frame stamped ``t_cam`` shows the scene at IMU time ``t_cam + time_offset`` (Kalibr's sign).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.data import (
    NS_PER_S,
    CameraFrames,
    ImuIntrinsics,
    ImuNoise,
    ImuSamples,
    Recording,
    SensorTruth,
    Target,
    Trajectory,
)
from vical.geometry import CameraModel, euler_to_matrix, make_transform, so3_exp
from vical.geometry.rolling_shutter import exposed_rows

GRAVITY = np.array([0.0, 0.0, -9.81])  # [m/s^2] world frame, z up
EPOCH_NS = 1_700_000_000 * NS_PER_S  # a realistic epoch so int64 ns handling is exercised

# The nominal camera looks along world +x (optical z = world x, image x = world -y, image y = world -z).
R_WORLD_CAM_NOMINAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
# The board hangs on a wall facing the camera: rows go down (world -z), columns go right (world -y).
R_WORLD_TARGET = np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class Excitation:
    """Sum-of-sinusoids motion: ``x(t) = sum_k a_k sin(2 pi f_k t + phi_k)`` per degree of freedom.

    Attributes:
        angle_amplitudes: (3, K) [rad] amplitudes of roll (view up/down), pitch (pan), yaw (about
            the optical axis) of the camera relative to the nominal view.
        offset_amplitudes: (3, K) [m] amplitudes of the target centre's camera-frame position.
        frequencies: (3, K) [Hz] frequencies, shared by angles and offsets of each axis.
        distance: [m] mean distance from the camera to the target centre.
        phase_seed: seed of the random phases (deterministic).
    """

    angle_amplitudes: np.ndarray = field(default_factory=lambda: np.array([[0.35, 0.10], [0.40, 0.10], [0.60, 0.15]]))
    offset_amplitudes: np.ndarray = field(default_factory=lambda: np.array([[0.06, 0.02], [0.05, 0.02], [0.20, 0.05]]))
    frequencies: np.ndarray = field(default_factory=lambda: np.array([[0.23, 0.71], [0.31, 0.89], [0.17, 0.53]]))
    distance: float = 0.8
    phase_seed: int = 0

    def scaled(self, rotation: float = 1.0, translation: float = 1.0) -> Excitation:
        """The same motion with angle amplitudes times ``rotation`` and offsets times ``translation``."""
        return Excitation(
            self.angle_amplitudes * rotation,
            self.offset_amplitudes * translation,
            self.frequencies,
            self.distance,
            self.phase_seed,
        )


def _sinusoids(amp: np.ndarray, freq: np.ndarray, phase: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Value, first and second derivative (each (N, 3)) of the per-axis sums of sinusoids at times ``t`` (N,) [s]."""
    w = 2.0 * np.pi * freq  # (3, K) [rad/s]
    arg = w[None] * t[:, None, None] + phase[None]  # (N, 3, K)
    x = np.sum(amp * np.sin(arg), axis=2)
    dx = np.sum(amp * w * np.cos(arg), axis=2)
    ddx = -np.sum(amp * w * w * np.sin(arg), axis=2)
    return x, dx, ddx


def euler_body_rates(e: np.ndarray, de: np.ndarray, dde: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body angular velocity and acceleration of ``R = euler_to_matrix(e)``.

    Args:
        e, de, dde: (N, 3) Euler angles ``[roll, pitch, yaw]`` [rad] and their first and second
            time derivatives [rad/s], [rad/s^2].

    Returns:
        omega (N, 3) [rad/s] and its derivative (N, 3) [rad/s^2], both in the rotated (body) frame.
    """
    r, p = e[:, 0], e[:, 1]
    dr, dp, dy = de.T
    ddr, ddp, ddy = dde.T
    sr, cr, sp, cp = np.sin(r), np.cos(r), np.sin(p), np.cos(p)
    omega = np.stack([dr - dy * sp, dp * cr + dy * sr * cp, -dp * sr + dy * cr * cp], axis=1)
    domega = np.stack(
        [
            ddr - ddy * sp - dy * dp * cp,
            ddp * cr - dp * dr * sr + ddy * sr * cp + dy * (dr * cr * cp - dp * sr * sp),
            -ddp * sr - dp * dr * cr + ddy * cr * cp - dy * (dr * sr * cp + dp * cr * sp),
        ],
        axis=1,
    )
    return omega, domega


@dataclass(frozen=True)
class _Motion:
    """Camera motion samples at N times: orientation, orbit offset and their derivatives."""

    R_world_cam: np.ndarray  # (N, 3, 3)
    omega_cam: np.ndarray  # (N, 3) [rad/s] camera frame
    domega_cam: np.ndarray  # (N, 3) [rad/s^2] camera frame
    q: np.ndarray  # (N, 3) [m] target centre in the camera frame
    dq: np.ndarray  # (N, 3) [m/s]
    ddq: np.ndarray  # (N, 3) [m/s^2]


def _motion(excitation: Excitation, t: np.ndarray) -> _Motion:
    phases = np.random.default_rng(excitation.phase_seed).uniform(0, 2 * np.pi, size=(2, *excitation.frequencies.shape))
    e, de, dde = _sinusoids(excitation.angle_amplitudes, excitation.frequencies, phases[0], t)
    q, dq, ddq = _sinusoids(excitation.offset_amplitudes, excitation.frequencies, phases[1], t)
    q = q + np.array([0.0, 0.0, excitation.distance])
    R = np.einsum("ij,njk->nik", R_WORLD_CAM_NOMINAL, np.array([euler_to_matrix(x) for x in e]))
    omega, domega = euler_body_rates(e, de, dde)
    return _Motion(R, omega, domega, q, dq, ddq)


def _target_centre_world(target: Target) -> np.ndarray:
    """(3,) [m] world position of the target centre (the orbit centre, 1 m in front of the origin)."""
    return np.array([1.0, 0.0, 0.0])


def _T_world_target(target: Target) -> np.ndarray:
    c = _target_centre_world(target)
    return make_transform(R_WORLD_TARGET, c - R_WORLD_TARGET @ target.center)


def imu_kinematics(excitation: Excitation, target: Target, T_cam_imu: np.ndarray, t: np.ndarray):
    """Exact IMU pose, velocity, angular rate and specific force at IMU times ``t`` (N,) [s].

    Returns:
        T_world_imu (N, 4, 4), v_world (N, 3) [m/s], gyro (N, 3) [rad/s] and accel (N, 3) [m/s^2]
        (both in the IMU frame, noise-free and bias-free).
    """
    m = _motion(excitation, t)
    R_cam_imu, t_cam_imu = T_cam_imu[:3, :3], T_cam_imu[:3, 3]
    u, du, ddu = m.q - t_cam_imu, m.dq, m.ddq  # IMU-to-centre vector in the camera frame
    w, dw = m.omega_cam, m.domega_cam
    p_imu = _target_centre_world(target) - np.einsum("nij,nj->ni", m.R_world_cam, u)
    # d/dt (R u) = R (w x u + du);  d2/dt2 (R u) = R (dw x u + w x (w x u) + 2 w x du + ddu)
    v_cam = np.cross(w, u) + du
    a_cam = np.cross(dw, u) + np.cross(w, np.cross(w, u)) + 2.0 * np.cross(w, du) + ddu
    v_world = -np.einsum("nij,nj->ni", m.R_world_cam, v_cam)
    a_world = -np.einsum("nij,nj->ni", m.R_world_cam, a_cam)
    specific_force_cam = np.einsum("nji,nj->ni", m.R_world_cam, a_world - GRAVITY)
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, :3] = m.R_world_cam @ R_cam_imu
    T[:, :3, 3] = p_imu
    return T, v_world, w @ R_cam_imu, specific_force_cam @ R_cam_imu


def _observe(camera: CameraModel, target: Target, T_world_cam: np.ndarray, T_world_target: np.ndarray):
    """Pixels (K, 2) and ids (K,) of the target seen from one camera pose.

    A checkerboard is seen whole or not at all; an aprilgrid reports every tag whose four corners
    are in front of the camera and inside the image (partial views), as its detector does.
    """
    T_cam_target = np.linalg.inv(T_world_cam) @ T_world_target
    p_cam = target.points @ T_cam_target[:3, :3].T + T_cam_target[:3, 3]
    uv, in_front = camera.project(p_cam)
    visible = in_front & camera.in_image(uv, border=2.0)
    if target.kind == "aprilgrid":
        tags = target.tag_corner_ids(np.arange(target.num_tags))  # (T, 4)
        ids = np.sort(tags[visible[tags].all(axis=1)].reshape(-1))
        return uv[ids], ids.astype(np.int64)
    if not visible.all():
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    return uv, np.arange(target.num_points, dtype=np.int64)


def _rolling_shutter(
    rig: RigCamera,
    target: Target,
    excitation: Excitation,
    T_rig_cam_imu: np.ndarray,
    T_world_target: np.ndarray,
    t: float,
    uv: np.ndarray,
    ids: np.ndarray,
) -> np.ndarray:
    """Pixels (K, 2) of corners ``ids``, each seen at its own row's time ``t + line_delay * v``
    (``vical.geometry.rolling_shutter``). ``T_rig_cam_imu`` is the extrinsic of the camera whose motion the
    excitation describes (the first one)."""
    T_imu_cam = np.linalg.inv(np.asarray(rig.T_cam_imu, float))

    def pose_at(dt: np.ndarray) -> np.ndarray:
        return imu_kinematics(excitation, target, T_rig_cam_imu, t + dt)[0] @ T_imu_cam

    points = target.points[ids] @ T_world_target[:3, :3].T + T_world_target[:3, 3]
    return exposed_rows(rig.camera, points, pose_at, rig.line_delay, uv)


def default_camera(distortion: str = "radtan") -> CameraModel:
    """The paper's 640 x 480 camera (1.0 rad horizontal FOV) with mild distortion."""
    dist = np.array([-0.05, 0.02, 0.001, -0.0005]) if distortion == "radtan" else np.array([0.01, -0.005, 0.002, 0.0])
    cam = CameraModel.from_hfov(1.0, 640, 480, dist=dist, distortion=distortion)
    return cam.with_intrinsics(cam.fx * 1.01, cam.fy, cam.cx + 4.0, cam.cy - 3.0, dist)


def wide_angle_camera(model: str = "ds", hfov_deg: float = 180.0) -> CameraModel:
    """A 640 x 480 fisheye lens of ``model`` (``ds``: ``xi = -0.2, alpha = 0.6``; ``eucm``: ``alpha = 0.6,
    beta = 1.1``, close to published calibrations of real fisheye lenses) with ``hfov_deg`` across the width."""
    coeffs = {"ds": [-0.2, 0.6], "eucm": [0.6, 1.1]}[model]
    cam = CameraModel.from_hfov(np.deg2rad(hfov_deg), 640, 480, dist=coeffs, distortion=model)
    return cam.with_intrinsics(cam.fx * 1.01, cam.fy, cam.cx + 4.0, cam.cy - 3.0, cam.dist)


def scattered_views(
    camera: CameraModel,
    target: Target,
    num_views: int = 40,
    pixel_sigma: float = 0.0,
    distance: tuple[float, float] = (0.25, 0.6),
    max_tilt: float = 0.8,
    seed: int = 0,
) -> tuple[CameraFrames, list[np.ndarray]]:
    """Views of a whole checkerboard spread over the image (a camera-only recording for intrinsics).

    Each view looks along the ray of a uniformly drawn image pixel: the board centre sits on it at
    a distance drawn from ``distance`` [m], its normal points back along the ray tilted by up to
    ``max_tilt`` [rad] about a random axis, rotated at random about the normal. Views whose corners
    do not all project 2 px inside the image are drawn again, so wide-angle lenses are seen up to
    their image border.

    Returns:
        frames at 10 Hz (corners with Gaussian noise of ``pixel_sigma`` [px]) and each view's
        ``T_cam_target`` (4, 4).
    """
    rng = np.random.default_rng(seed)
    corners, poses = [], []
    while len(poses) < num_views:
        T = _scattered_pose(camera, target, rng, distance, max_tilt)
        if T is None:
            continue
        uv, ok = camera.project(target.points @ T[:3, :3].T + T[:3, 3])
        if ok.all() and camera.in_image(uv, border=2.0).all():
            corners.append(uv + rng.normal(0.0, pixel_sigma, size=uv.shape) if pixel_sigma > 0 else uv)
            poses.append(T)
    t = EPOCH_NS + np.arange(num_views, dtype=np.int64) * (NS_PER_S // 10)
    ids = [np.arange(target.num_points, dtype=np.int64) for _ in poses]
    return CameraFrames(t, corners, ids), poses


def _scattered_pose(camera, target, rng, distance, max_tilt) -> np.ndarray | None:
    """``T_cam_target`` (4, 4) of one ``scattered_views`` draw, or None when the drawn pixel has no ray."""
    pixel = rng.uniform([0.0, 0.0], [camera.width - 1.0, camera.height - 1.0])
    ray, ok = camera.bearings(pixel[None])
    if not ok[0]:
        return None
    ray = ray[0]
    normal = -ray  # the printed side faces the camera
    axis = np.cross(normal, rng.normal(size=3))
    normal = so3_exp(axis / np.linalg.norm(axis) * rng.uniform(0.0, max_tilt)) @ normal
    x = np.cross(rng.normal(size=3), normal)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(normal, x), normal], axis=1)
    centre = ray * rng.uniform(*distance)
    return make_transform(R, centre - R @ target.center)


def _imu_noise_samples(noise: ImuNoise, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """White noise plus bias random walk (N, 3) for gyro and accel, Kalibr's discrete-time sigmas."""
    dt = 1.0 / noise.rate_hz
    out = []
    for density, walk in (
        (noise.gyro_noise_density, noise.gyro_random_walk),
        (noise.accel_noise_density, noise.accel_random_walk),
    ):
        white = rng.normal(0.0, density * np.sqrt(noise.rate_hz), size=(n, 3))  # [unit]
        drift = np.cumsum(rng.normal(0.0, walk * np.sqrt(dt), size=(n, 3)), axis=0)  # [unit]
        out.append(white + drift)
    return out[0], out[1]


def make_recording(
    duration: float = 20.0,
    camera: CameraModel | None = None,
    T_cam_imu: np.ndarray | None = None,
    time_offset: float = 0.0,
    imu_noise: ImuNoise | None = None,
    pixel_sigma: float = 0.0,
    gyro_bias: np.ndarray | None = None,
    accel_bias: np.ndarray | None = None,
    excitation: Excitation | None = None,
    target: Target | None = None,
    camera_rate_hz: float = 10.0,
    seed: int = 0,
    line_delay: float = 0.0,
    other_cameras: dict[str, RigCamera] | None = None,
    imu_intrinsics: ImuIntrinsics | None = None,
) -> Recording:
    """A camera + IMU recording of the analytic motion, optionally noisy.

    Args:
        duration: [s] length of the IMU stream; camera frames cover it with a 0.1 s margin at each end.
        camera: camera model (``default_camera()`` if None).
        T_cam_imu: (4, 4) true extrinsic (the nominal rig if None).
        time_offset: [s] Kalibr's ``timeshift_cam_imu`` (``t_imu = t_cam + time_offset``), |.| < 0.1 s.
        imu_noise: IMU noise densities; None gives noise-free IMU data (the rate is 200 Hz either way
            unless ``imu_noise.rate_hz`` says otherwise).
        pixel_sigma: [px] standard deviation of the corner noise.
        gyro_bias, accel_bias: (3,) constant bias offsets [rad/s], [m/s^2] added to the IMU.
        excitation: motion (``Excitation()`` if None).
        target: checkerboard (the paper's 7 x 6 inner corners, 7 cm) if None.
        camera_rate_hz: [Hz] frame rate.
        seed: seed of the noise generator.
        line_delay: [s/row] the camera's rolling shutter (0: global shutter): image row ``v`` (the corner's
            pixel row, 0 at the top) is exposed ``line_delay * v`` after the frame's timestamp (row 0 at the
            timestamp, ``docs/formats.md``).
        other_cameras: a rig's other cameras (``cam1``, ...) on the same trigger: each one's frames
            carry the same stamps and show the scene at IMU time ``t_cam + its time_offset`` (row 0; each
            its own ``line_delay``).
        imu_intrinsics: the IMU's scale, misalignment and g-sensitivity (None: exact axes), applied to
            the true readings before biases and noise.
    """
    if abs(time_offset) >= 0.1:
        raise ValueError(f"time_offset must be within +-0.1 s for this generator, got {time_offset}")
    camera = camera or default_camera()
    T_cam_imu = nominal_T_cam_imu() if T_cam_imu is None else np.asarray(T_cam_imu, float)
    excitation = excitation or Excitation()
    target = target or Target.checkerboard()
    noise = imu_noise or ImuNoise()
    rng = np.random.default_rng(seed)
    gb = np.zeros(3) if gyro_bias is None else np.asarray(gyro_bias, float)
    ab = np.zeros(3) if accel_bias is None else np.asarray(accel_bias, float)

    t_imu_ns = np.arange(0, round(duration * NS_PER_S) + 1, round(NS_PER_S / noise.rate_hz), dtype=np.int64)
    t_imu = t_imu_ns.astype(float) / NS_PER_S
    T_wi, v_w, gyro_true, accel_true = imu_kinematics(excitation, target, T_cam_imu, t_imu)
    intrinsics = imu_intrinsics or ImuIntrinsics()
    gyro, accel = intrinsics.distort(gyro_true, accel_true)
    gyro, accel = gyro + gb, accel + ab
    if imu_noise is not None:
        dg, da = _imu_noise_samples(noise, len(t_imu), rng)
        gyro, accel = gyro + dg, accel + da

    t_cam_ns = np.arange(
        int(0.1 * NS_PER_S), int((duration - 0.1) * NS_PER_S) + 1, round(NS_PER_S / camera_rate_hz), dtype=np.int64
    )
    T_world_target = _T_world_target(target)
    scene = (excitation, target, T_cam_imu, T_world_target, pixel_sigma, rng)
    corners, ids = _camera_frames(scene, RigCamera(camera, T_cam_imu, time_offset, line_delay), t_cam_ns)
    others = {name: _camera_frames(scene, rig, t_cam_ns) for name, rig in (other_cameras or {}).items()}
    truth = SensorTruth(camera, T_cam_imu, float(time_offset), noise, gb, ab, intrinsics, float(line_delay))
    trajectory = Trajectory(EPOCH_NS + t_imu_ns, T_wi, v_w, gyro_true)
    return Recording(
        imu=ImuSamples(EPOCH_NS + t_imu_ns, gyro, accel),
        frames=CameraFrames(EPOCH_NS + t_cam_ns, corners, ids),
        target=target,
        truth=truth,
        trajectory=trajectory,
        T_world_target=T_world_target,
        path_length=float(np.sum(np.linalg.norm(np.diff(T_wi[:, :3, 3], axis=0), axis=1))),
        duration=float(duration),
        metadata={"source": "vical.calib.synthetic", "seed": int(seed), "pixel_sigma": float(pixel_sigma)},
        other_frames={name: CameraFrames(EPOCH_NS + t_cam_ns, *frames) for name, frames in others.items()},
        other_truths={
            name: SensorTruth(
                rig.camera, rig.T_cam_imu, float(rig.time_offset), noise, gb, ab, line_delay=float(rig.line_delay)
            )
            for name, rig in (other_cameras or {}).items()
        },
    )


@dataclass(frozen=True)
class RigCamera:
    """One camera of a rig: its model, ``T_cam_imu`` (4, 4), time offset [s] (Kalibr's sign, |.| < 0.1 s) and line
    delay [s/row] (0: a global shutter)."""

    camera: CameraModel
    T_cam_imu: np.ndarray
    time_offset: float = 0.0
    line_delay: float = 0.0


def _camera_frames(scene: tuple, rig: RigCamera, t_cam_ns: np.ndarray) -> tuple[list, list]:
    """Corners (K, 2) [px] and ids (K,) per frame of one camera at stamps ``t_cam_ns`` [ns since the start].

    The excitation moves the first camera (``T_rig_cam_imu``); every camera rides on the IMU pose it gives.
    """
    excitation, target, T_rig_cam_imu, T_world_target, pixel_sigma, rng = scene
    if abs(rig.time_offset) >= 0.1:
        raise ValueError(f"time_offset must be within +-0.1 s for this generator, got {rig.time_offset}")
    if not 0.0 <= rig.line_delay * rig.camera.height < 0.1:
        raise ValueError(f"line_delay must give a readout within [0, 0.1) s for this generator, got {rig.line_delay}")
    T_cam_imu = np.asarray(rig.T_cam_imu, float)
    t_exposure = t_cam_ns / NS_PER_S + rig.time_offset
    T_wi_exposure = imu_kinematics(excitation, target, T_rig_cam_imu, t_exposure)[0]
    T_imu_cam = np.linalg.inv(T_cam_imu)
    corners, ids = [], []
    for t, T in zip(t_exposure, T_wi_exposure, strict=True):
        uv, i = _observe(rig.camera, target, T @ T_imu_cam, T_world_target)
        if rig.line_delay and len(i):
            uv = _rolling_shutter(rig, target, excitation, T_rig_cam_imu, T_world_target, t, uv, i)
        corners.append(uv + rng.normal(0.0, pixel_sigma, size=uv.shape) if pixel_sigma > 0 else uv)
        ids.append(i)
    return corners, ids
