"""A stereo rig + IMU calibrated in one graph against the simulated truth (``vical.calib.synthetic``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vical.calib.errors import CalibrationError
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.pipeline import calibrate_rig
from vical.calib.synthetic import RigCamera, default_camera, make_recording
from vical.data import CameraFrames, ImuNoise
from vical.geometry import euler_to_matrix, invert_transform, make_transform

T_C1_C0 = make_transform(euler_to_matrix([0.02, -0.03, 0.01]), [-0.06, 0.002, 0.001])  # a 6 cm stereo baseline
CAM1 = default_camera().with_intrinsics(470.0, 468.0, 325.0, 236.0, [-0.04, 0.015, 0.0005, 0.0002])


def stereo(pixel_sigma: float, noise: ImuNoise | None, seed: int = 3):
    rig = {"cam1": RigCamera(CAM1, T_C1_C0 @ nominal_T_cam_imu(), 0.006)}
    return make_recording(
        12.0, time_offset=0.004, imu_noise=noise, pixel_sigma=pixel_sigma, other_cameras=rig, seed=seed
    )


def errors(T: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """Rotation [deg] and translation [mm] between two transforms."""
    dR = T[:3, :3] @ T_true[:3, :3].T
    angle = np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1.0, 1.0)))
    return float(angle), float(1e3 * np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


def frames_of(rec) -> dict[str, CameraFrames]:
    return {name: rec.frames_of(name) for name in rec.camera_names}


def test_noise_free_stereo_rig_is_recovered_exactly_with_known_intrinsics():
    rec = stereo(0.0, None)
    cameras = {name: rec.truth_of(name).camera for name in rec.camera_names}
    rig = calibrate_rig(frames_of(rec), rec.imu, rec.target, "extrinsic", cameras=cameras, imu_noise=ImuNoise())
    for name in rec.camera_names:
        rotation, translation = errors(rig.results[name].T_cam_imu, rec.truth_of(name).T_cam_imu)
        # measured 0.0013 deg, 0.098 mm, 0.003 ms: the IMU preintegration's discretisation, as with one camera
        assert rotation < 0.005 and translation < 0.2, name
        assert rig.results[name].time_offset == pytest.approx(rec.truth_of(name).time_offset, abs=1e-5)
        assert rig.results[name].reprojection.rms < 1e-3
    rotation, translation = errors(rig.T_cn_cnm1("cam1"), T_C1_C0)
    assert rotation < 1e-3 and translation < 0.005  # measured 3e-5 deg, 0.0006 mm: the IMU's errors cancel
    assert rig.T_cn_cnm1("cam0") is None


def test_noisy_stereo_rig_joint_calibration_is_within_its_sigmas():
    rec = stereo(0.2, ImuNoise())
    sizes = {name: (640, 480) for name in rec.camera_names}
    rig = calibrate_rig(frames_of(rec), rec.imu, rec.target, "joint", image_sizes=sizes, imu_noise=ImuNoise())
    for name in rec.camera_names:
        result, truth = rig.results[name], rec.truth_of(name)
        rotation, translation = errors(result.T_cam_imu, truth.T_cam_imu)
        assert rotation < 0.1 and translation < 1.5, name  # measured 0.03-0.04 deg, 0.42 mm
        t_error = result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3]
        assert np.all(np.abs(t_error) < 4 * np.array([result.sigma(k) for k in ("t_x", "t_y", "t_z")])), name
        assert abs(result.time_offset - truth.time_offset) < 4 * result.sigma("time_offset"), name
        intrinsics = np.abs(result.camera.intrinsics - truth.camera.intrinsics)
        assert np.all(intrinsics < 4 * np.array([result.sigma(k) for k in ("fx", "fy", "cx", "cy")])), name
    assert rig.results["cam1"].time_offset - rig.results["cam0"].time_offset == pytest.approx(0.002, abs=3e-4)
    rotation, translation = errors(rig.T_cn_cnm1("cam1"), T_C1_C0)
    assert rotation < 0.05 and translation < 0.5  # measured 0.09 mm
    assert rig.results["cam1"].camera.fx == pytest.approx(470.0, abs=1.5)


def test_two_stage_rig_calibrates_each_camera_alone_then_the_rig_with_those_intrinsics():
    rec = stereo(0.2, ImuNoise())
    sizes = {name: (640, 480) for name in rec.camera_names}
    rig = calibrate_rig(frames_of(rec), rec.imu, rec.target, "two_stage", image_sizes=sizes, imu_noise=ImuNoise())
    for name in rec.camera_names:
        result, truth = rig.results[name], rec.truth_of(name)
        assert result.camera == calibrate_intrinsics(rec.frames_of(name), rec.target, "radtan", (640, 480)).camera
        assert result.task == "two_stage" and {"fx", "p2", "t_x", "time_offset"} <= set(result.parameter_names)
        rotation, translation = errors(result.T_cam_imu, truth.T_cam_imu)
        assert rotation < 0.1 and translation < 1.5, name  # measured 0.03-0.05 deg, 0.44-0.47 mm, 0.11 ms
        t_error = result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3]
        assert np.all(np.abs(t_error) < 4 * np.array([result.sigma(k) for k in ("t_x", "t_y", "t_z")])), name
        assert abs(result.time_offset - truth.time_offset) < 4 * result.sigma("time_offset"), name


def test_cameras_not_triggered_together_are_refused():
    rec = stereo(0.0, None)
    late = rec.frames_of("cam1")
    late = CameraFrames(late.t + 20_000_000, late.corners, late.ids)  # 20 ms after cam0's frames
    rec = replace(rec, other_frames={"cam1": late})
    cameras = {name: rec.truth_of(name).camera for name in rec.camera_names}
    with pytest.raises(CalibrationError, match=r"cam1 has no view within 5 ms of a view of the first camera"):
        calibrate_rig(frames_of(rec), rec.imu, rec.target, "extrinsic", cameras=cameras)


def test_the_extrinsic_task_needs_every_cameras_intrinsics():
    rec = stereo(0.0, None)
    with pytest.raises(CalibrationError, match="needs the intrinsics of every camera; cam1 has none"):
        calibrate_rig(frames_of(rec), rec.imu, rec.target, "extrinsic", cameras={"cam0": rec.truth.camera})


def test_the_relative_pose_follows_kalibrs_convention():
    rec = stereo(0.0, None)
    T_c1_imu, T_c0_imu = rec.truth_of("cam1").T_cam_imu, rec.truth_of("cam0").T_cam_imu
    np.testing.assert_allclose(T_c1_imu @ invert_transform(T_c0_imu), T_C1_C0, atol=1e-12)  # cam0 -> cam1


def cropped(frames: CameraFrames, u_max: float) -> CameraFrames:
    """The frames' detections left of ``u_max`` [px] (the rest of the board unseen)."""
    keep = [c[:, 0] < u_max for c in frames.corners]
    corners = [c[k] for c, k in zip(frames.corners, keep, strict=True)]
    return CameraFrames(frames.t, corners, [i[k] for i, k in zip(frames.ids, keep, strict=True)])


def test_each_camera_of_a_rig_reports_its_own_corners_frames_and_time_offset_evidence():
    rec = stereo(0.2, ImuNoise())
    frames = frames_of(rec)
    frames["cam0"] = cropped(frames["cam0"], 480.0)  # cam0 sees fewer corners than cam1, in fewer frames
    cameras = {name: rec.truth_of(name).camera for name in rec.camera_names}
    rig = calibrate_rig(frames, rec.imu, rec.target, "extrinsic", cameras=cameras, imu_noise=ImuNoise())
    for name, result in rig.results.items():
        own, pixels, log = frames[name], result.reprojection_pixels, result.frame_log
        assert len(pixels) == len(result.reprojection_residuals) == log.corners_used, name
        for k in np.unique(result.reprojection_frames):  # every pixel is one of the camera's own detections
            seen = pixels[result.reprojection_frames == k]
            assert np.abs(seen[:, None, :] - own.corners[k][None]).sum(axis=2).min(axis=1).max() == 0.0, (name, k)
        assert [r.found for r in log.records] == own.num_detections.tolist(), name
        assert [r.t_ns for r in log.records] == own.t.tolist(), name
        trace = result.time_offset_trace
        assert trace.shifts[len(trace.shifts) // 2] == pytest.approx(result.time_offset), name
        # measured within 0.3 ms of the camera's own estimate (cam0 4 ms, cam1 6 ms)
        assert trace.shifts[np.argmin(trace.mismatch)] == pytest.approx(result.time_offset, abs=1e-3), name
    log1 = rig.results["cam1"].frame_log
    unpaired = [r for r in log1.records if r.reason == "unpaired"]
    assert unpaired and all(r.found > 0 for r in unpaired)  # cam1 saw the board where cam0 had too few corners
    note = f"cam1: {len(unpaired)} views without a simultaneous view of the first camera were not used"
    assert note in rig.results["cam1"].warnings
    assert log1.corners_found > rig.results["cam0"].frame_log.corners_found
