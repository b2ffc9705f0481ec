"""A rig's other cameras in the camera-IMU graph: their views, how they join the first camera's states, their guesses.

The first camera (``cam0``) sets the IMU states (one per frame with a target pose). Another
camera's frame joins the state of the first camera's frame taken within ``PAIR_TOLERANCE`` of it
(cameras on one trigger: the same instant up to their time offsets); its corner factor projects
from the pose at its own exposure instant, ``shift + delta_c`` after the state
(``vical.calib.solve.corner_factors``, ``shift`` the known part). Frames without such a partner are not
used (a warning counts them). Each camera has its own ``T_cam_imu``, time offset and, in the joint
task, intrinsics; the relative poses ``T_cn_cnm1`` follow from the ``T_cam_imu``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.result import FramePoses
from vical.calib.solve.corner_noise import corner_noise
from vical.calib.solve.initialization import MIN_INIT_CORNERS, starting_poses
from vical.calib.solve.observations import FrameObservation
from vical.calib.solve.outliers import reject_outliers
from vical.calib.solve.time_alignment import align, rotation_increments
from vical.data import Target, seconds_since
from vical.geometry import CameraModel, invert_transform, make_transform

PAIR_TOLERANCE = 0.005  # [s] a frame joins the first camera's frame taken this close (first-order exposure shift)


@dataclass
class OtherCamera:
    """Another camera of the rig, as the graph uses it (times in seconds since the recording start).

    Attributes:
        name: its Kalibr name (``cam1``, ...); index: 1, 2, ... (its variables' keys).
        camera: its model (the intrinsics are variables in the joint task).
        observations: its frames with a usable target pose; frame_times (F,) [s] their stamps (camera clock).
        T_target_cam: (F, 4, 4) their PnP poses.
        sigma_px: [px] its corner noise.
        T_cam_imu: (4, 4) and tau0 [s]: the current extrinsic and time-offset estimates.
        initial_T_cam_imu: (4, 4) guess whose translation is used, or None (from the first camera's).
        readout: [s] its current readout time (line delay times image height); readout_given: its given one.
    """

    name: str
    index: int
    camera: CameraModel
    observations: list[FrameObservation]
    frame_times: np.ndarray
    T_target_cam: np.ndarray
    sigma_px: float
    T_cam_imu: np.ndarray = field(default_factory=lambda: np.eye(4))
    tau0: float = 0.0
    initial_T_cam_imu: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)
    outliers: list[int] = field(default_factory=list)  # frame indices of its frames dropped as outliers
    readout: float = 0.0
    readout_given: float = 0.0


def prepare_other(
    name: str,
    index: int,
    observations: list[FrameObservation],
    camera: CameraModel,
    target: Target,
    t0_ns: int,
    pixel_sigma: float | None,
    initial_T_cam_imu: np.ndarray | None,
    start_poses: FramePoses | None = None,
    rolling_shutter: bool = False,
) -> OtherCamera:
    """Starting poses (``starting_poses``; outliers rejected) and the corner noise of another camera's frames
    (``corner_noise``: ``rolling_shutter`` when its line delay is estimated)."""
    min_corners = min(MIN_INIT_CORNERS, target.num_points)
    initial = starting_poses(camera, observations, min_corners, start_poses)
    rejection = reject_outliers(camera, observations, initial, min_corners)
    poses = rejection.poses
    if len(poses) < 3:
        raise CalibrationError(
            f"{name}: only {len(poses)} frames have a usable target pose; it needs a sequence of views"
        )
    ids = sorted(poses)
    used = [rejection.observations[k] for k in ids]
    views = [(o, poses[k]) for o, k in zip(used, ids, strict=True)]
    sigma = pixel_sigma or corner_noise(camera, views, rolling_shutter)
    t_ns = np.array([o.t_ns for o in used], dtype=np.int64)
    T_target_cam = np.array([invert_transform(poses[k]) for k in ids])
    warnings = [f"{name}: {w}" for w in rejection.warnings]
    return OtherCamera(
        name, index, camera, used, seconds_since(t_ns, t0_ns), T_target_cam, float(sigma),
        initial_T_cam_imu=initial_T_cam_imu, warnings=warnings, outliers=list(rejection.dropped),
    )  # fmt: skip


def pair(first_times: np.ndarray, other_times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices (P,) into ``first_times`` and (P,) into ``other_times`` [s] of frames taken within ``PAIR_TOLERANCE``."""
    if not len(first_times) or not len(other_times):
        return np.zeros(0, int), np.zeros(0, int)
    nearest = np.clip(np.searchsorted(first_times, other_times), 1, len(first_times) - 1)
    left = np.abs(other_times - first_times[nearest - 1]) <= np.abs(other_times - first_times[nearest])
    nearest = np.where(left, nearest - 1, nearest)
    close = np.abs(other_times - first_times[nearest]) <= PAIR_TOLERANCE
    return nearest[close], np.flatnonzero(close)


def initialise_other(
    other: OtherCamera,
    first_times: np.ndarray,
    first_T_target_cam: np.ndarray,
    first_T_cam_imu: np.ndarray,
    imu: tuple[np.ndarray, np.ndarray],
    max_time_offset: float,
    tau_guess: float,
    estimate_time_offset: bool,
) -> None:
    """Closed-form time offset and rotation from the camera's own views and the gyro (as the first camera's);
    translation from the guess, else from the first camera's through their simultaneous views."""
    t_imu, gyro = imu
    increments = rotation_increments(other.frame_times, other.T_target_cam[:, :3, :3])
    alignment = align(t_imu, gyro, increments, max_time_offset, tau_guess, estimate_time_offset)
    if other.initial_T_cam_imu is not None:
        translation = np.asarray(other.initial_T_cam_imu, float)[:3, 3]
    else:
        translation = (relative_pose(other, first_times, first_T_target_cam) @ first_T_cam_imu)[:3, 3]
    other.T_cam_imu = make_transform(alignment.R_cam_imu, translation)
    other.tau0 = alignment.time_offset


def relative_pose(other: OtherCamera, first_times: np.ndarray, first_T_target_cam: np.ndarray) -> np.ndarray:
    """(4, 4) ``T_other_first`` from simultaneous PnP poses (rotation by SVD of their sum, median translation)."""
    i, j = pair(first_times, other.frame_times)
    if not len(i):
        raise CalibrationError(
            f"{other.name} has no view within {PAIR_TOLERANCE * 1e3:.0f} ms of a view of the first camera; the cameras "
            "of a rig are calibrated together when they are triggered together"
        )
    relative = np.array(
        [invert_transform(other.T_target_cam[b]) @ first_T_target_cam[a] for a, b in zip(i, j, strict=True)]
    )
    U, _, Vt = np.linalg.svd(relative[:, :3, :3].sum(axis=0))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return make_transform(R, np.median(relative[:, :3, 3], axis=0))
