"""Small synthetic recordings for the file-format tests (random but valid data).

The other ``test_io_*`` modules import ``make_recording`` from here; the test below checks the
sample itself is what they rely on.
"""

from __future__ import annotations

import numpy as np

from vical.data import CameraFrames, ImuNoise, ImuSamples, PathProfile, Recording, SensorTruth, Target, Trajectory
from vical.geometry import CameraModel
from vical.geometry.transforms import euler_to_matrix, make_transform

T0_NS = 1_403_636_579_763_555_584  # an epoch time in ns beyond float64's integer precision


def make_camera(distortion: str = "radtan") -> CameraModel:
    dist = [-0.28, 0.07, 2e-4, -1.7e-5] if distortion == "radtan" else [0.01, -0.003, 1e-4, -2e-5]
    return CameraModel(distortion, 64, 48, 45.8, 45.9, 31.7, 24.1, dist)


def make_truth(distortion: str = "radtan") -> SensorTruth:
    T = make_transform(euler_to_matrix([0.1, -0.2, 1.57]), [0.06, -0.01, -0.1])
    return SensorTruth(
        make_camera(distortion),
        T,
        time_offset=0.0123,
        imu_noise=ImuNoise(),
        gyro_bias=[1e-3, -2e-3, 5e-4],
        accel_bias=[0.01, 0.02, -0.03],
    )


def make_recording(
    seed: int = 0, n_imu: int = 60, n_frames: int = 6, images: bool = True, with_truth: bool = True
) -> Recording:
    """A recording with IMU at 200 Hz, frames at 20 Hz (ragged detections, one empty), 64 x 48 images."""
    rng = np.random.default_rng(seed)
    target = Target.checkerboard(rows=4, cols=5, square=0.05)
    t_imu = T0_NS + np.arange(n_imu, dtype=np.int64) * 5_000_000 + rng.integers(0, 7, n_imu)
    imu = ImuSamples(t_imu, rng.normal(0.0, 0.5, (n_imu, 3)), rng.normal([0, 0, 9.81], 0.5, (n_imu, 3)))
    t_cam = T0_NS + 3 + np.arange(n_frames, dtype=np.int64) * 50_000_000
    corners, ids = [], []
    for k in range(n_frames):
        n = 0 if k == 2 else int(rng.integers(1, target.num_points + 1))
        ids.append(np.sort(rng.choice(target.num_points, n, replace=False)))
        corners.append(rng.uniform([0, 0], [63, 47], (n, 2)))
    imgs = rng.integers(0, 256, (n_frames, 48, 64), dtype=np.uint8) if images else None
    frames = CameraFrames(t_cam, corners, ids, imgs)
    n_traj = 10
    rots = [euler_to_matrix(rng.normal(0, 0.3, 3)) for _ in range(n_traj)]
    T_world_imu = np.stack([make_transform(R, rng.normal(0, 1, 3)) for R in rots])
    traj = Trajectory(t_imu[:n_traj], T_world_imu, rng.normal(0, 1, (n_traj, 3)), rng.normal(0, 1, (n_traj, 3)))
    return Recording(
        imu=imu,
        frames=frames,
        target=target,
        truth=make_truth() if with_truth else None,
        trajectory=traj if with_truth else None,
        T_world_target=make_transform(euler_to_matrix([0.3, 0.1, -0.2]), [1.5, 0.1, 0.4]) if with_truth else None,
        path_length=1.2345678901234567,
        duration=0.3 + 1e-17,
        metadata={"seed": seed, "source": "synthetic", "nested": {"rate_hz": [200, 20]}},
        path_profile=PathProfile(t_imu, np.cumsum(rng.uniform(0.0, 0.04, n_imu))) if with_truth else None,
    )


def assert_frames_equal(a: CameraFrames, b: CameraFrames, images: bool = True) -> None:
    """Exact equality of timestamps, detections and (optionally) images."""
    assert a.t.dtype == np.int64 and np.array_equal(a.t, b.t)
    assert len(a.corners) == len(b.corners)
    for ca, cb, ia, ib in zip(a.corners, b.corners, a.ids, b.ids, strict=True):
        assert np.array_equal(ca, cb) and np.array_equal(ia, ib)
    if images:
        assert a.images is not None and b.images is not None
        assert a.images.dtype == np.uint8 and np.array_equal(a.images, b.images)


def test_sample_recording_has_ragged_detections_and_ns_beyond_float_precision():
    rec = make_recording()
    assert list(rec.frames.num_detections).count(0) == 1
    assert len(set(rec.frames.num_detections.tolist())) > 1
    # The timestamps would not survive a float64 round trip: the lossless tests mean something.
    assert np.any(rec.imu.t.astype(np.float64).astype(np.int64) != rec.imu.t)
