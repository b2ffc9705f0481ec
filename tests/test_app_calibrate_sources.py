"""vical-calibrate on exported real-recording formats: EuRoC folder, ROS1 and ROS 2 bags, image folder, corner CSV.

One rendered simulator recording (MuJoCo images, lens warp, ``detect_checkerboard``; about 5 s,
49 frames) is exported with vical's writers and calibrated from each export by ``main([...])``,
which detects the corners in the exported images itself. PNG and ``mono8`` are lossless and the
detector is deterministic, so the detections must be bit-identical to those made while recording,
and the IMU round-trips exactly (shortest-repr decimal text in the CSV, float64 in the bags): the
results came out equal to the last bit. The tolerance is a hundredth of each parameter's 1-sigma
(fx 1.9 px, t_x 2.2 mm, time offset 0.085 ms here), room for a different summation order on
another platform, far below the detection noise that would show if a reader altered the images. A ROS 2 bag that
another tool writes from the same data (rosbags' ROS1-to-ROS2 converter, both storages) is read bit for bit and
calibrated in-process to the in-memory result within 1e-9.
"""

from dataclasses import replace

import cv2
import numpy as np
import pytest
from rosbags.convert import convert
from test_sim_calib_integration import excitation

from vical.apps.calibrate import main
from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.pipeline import calibrate_joint
from vical.geometry import transform_error
from vical.io import (
    open_recording,
    read_camchain,
    save_recording,
    write_bag,
    write_corners_csv,
    write_euroc,
    write_imu_csv,
    write_imu_yaml,
    write_target_yaml,
)
from vical.sim import PandaSim
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, sample_sensor


def record_rendered(seed: int = 7, time_offset: float = 0.012):
    """A rendered recording with its images kept: one excitation cycle (6 moves, ~5 s, ~49 frames)."""
    sampling = replace(SensorSampling(), backend="render")
    truth = replace(sample_sensor(sampling, np.random.default_rng(seed)), time_offset=time_offset)
    sim = PandaSim()
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling, detect_checkerboard, keep_images=True)
    try:
        sim.reset()
        recorder.start(truth, np.random.default_rng(seed))
        T_home = sim.ee_pose()
        for goal in excitation(1):
            recorder.add_motion(sim.move_to(T_home @ goal, observer=recorder))
        return recorder.recording()
    finally:
        recorder.close()


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    rec = record_rendered()
    root = tmp_path_factory.mktemp("exports")
    write_euroc(rec, root / "euroc")
    write_bag(rec, root / "data.bag")
    write_bag(rec, root / "ros2_db3", bag_format="db3")
    write_bag(rec, root / "ros2_mcap", bag_format="mcap")
    save_recording(rec, root / "rec")
    write_target_yaml(root / "target.yaml", rec.target)
    write_imu_yaml(root / "imu.yaml", rec.truth.imu_noise)
    write_corners_csv(rec.frames, root / "corners.csv")
    write_imu_csv(rec.imu, root / "imu.csv")
    (root / "images").mkdir()
    for k, image in enumerate(rec.frames.images):
        cv2.imwrite(str(root / "images" / f"frame{k:03d}.png"), image)
    return rec, root


@pytest.fixture(scope="module")
def in_memory(exports):
    rec, _ = exports
    return calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), rec.truth.imu_noise)


def _calibrate(argv: list[str], out) -> tuple:
    assert main([*argv, "--out", str(out), "--no-report"]) == 0
    return read_camchain(out / ("camchain.yaml" if "intrinsic" in argv else "camchain-imucam.yaml"))


def assert_same_joint_result(camchain: tuple, reference) -> None:
    camera, T_cam_imu, shift = camchain
    sig = reference.sigmas
    for k, name in enumerate(["fx", "fy", "cx", "cy"]):
        assert abs(camera.intrinsics[k] - reference.camera.intrinsics[k]) < 0.01 * sig[name], name
    assert np.allclose(camera.dist, reference.camera.dist, atol=1e-5)
    rot, trans = transform_error(T_cam_imu, reference.T_cam_imu)
    assert np.rad2deg(rot) < 1e-3 and trans < 0.01 * min(sig[f"t_{a}"] for a in "xyz")
    assert abs(shift - reference.time_offset) < 0.01 * sig["time_offset"]


@pytest.mark.parametrize("source", ["euroc", "data.bag", "ros2_db3", "ros2_mcap/ros2_mcap.mcap"])
def test_joint_from_euroc_and_bag_equals_in_memory_calibration(exports, in_memory, source, tmp_path, capsys):
    rec, root = exports
    opened = open_recording(root / source, rec.target, detector=lambda im: detect_checkerboard(im, rec.target))
    assert len(opened.frames) == len(rec.frames) == 49
    assert all(np.array_equal(a, b) for a, b in zip(opened.frames.corners, rec.frames.corners, strict=True))

    argv = [str(root / source), "--target", str(root / "target.yaml"), "--imu-yaml", str(root / "imu.yaml")]
    assert_same_joint_result(_calibrate(argv, tmp_path), in_memory)
    # ... and that result is right: the recording's truth within the simulator's tolerances.
    rot, trans = transform_error(in_memory.T_cam_imu, rec.truth.T_cam_imu)
    assert np.rad2deg(rot) < 0.2 and trans < 0.015
    assert abs(in_memory.time_offset - 0.012) < 5e-4
    assert "outputs written to" in capsys.readouterr().out


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_ros2_bag_rosbags_converts_from_the_ros1_bag_calibrates_identically(exports, in_memory, storage, tmp_path):
    """A ROS 2 bag written by another tool from the same data: rosbags' own ROS1-to-ROS2 converter (what a ROS 2
    user without vical runs on a Kalibr bag). Its images and IMU samples are read bit for bit, and the calibration
    from them equals the in-memory one within 1e-9."""
    rec, root = exports
    convert([root / "data.bag"], tmp_path / "converted", dst_storage=storage, dst_version=9, compress=None,
            compress_mode="file", default_typestore=None, typestore=None, exclude_topics=(), include_topics=(),
            exclude_msgtypes=(), include_msgtypes=())  # fmt: skip
    opened = open_recording(tmp_path / "converted", rec.target, detector=lambda im: detect_checkerboard(im, rec.target))
    np.testing.assert_array_equal(opened.frames.t, rec.frames.t)
    assert all(np.array_equal(a, b) for a, b in zip(opened.frames.corners, rec.frames.corners, strict=True))
    for field in ("t", "gyro", "accel"):
        np.testing.assert_array_equal(getattr(opened.imu, field), getattr(rec.imu, field))
    result = calibrate_joint(opened.frames, opened.imu, rec.target, "radtan", (640, 480), rec.truth.imu_noise)
    np.testing.assert_allclose(result.estimate, in_memory.estimate, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.T_cam_imu, in_memory.T_cam_imu, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.camera.intrinsics, in_memory.camera.intrinsics, rtol=0, atol=1e-9)


def test_joint_from_corner_csv_with_imu_csv_equals_in_memory(exports, in_memory, tmp_path):
    _, root = exports
    argv = [str(root / "corners.csv"), "--imu-csv", str(root / "imu.csv"), "--target", str(root / "target.yaml")]
    argv += ["--imu-yaml", str(root / "imu.yaml"), "--image-size", "640", "480"]
    assert_same_joint_result(_calibrate(argv, tmp_path), in_memory)


def test_intrinsic_from_image_folder_equals_in_memory(exports, tmp_path):
    rec, root = exports
    reference = calibrate_intrinsics(rec.frames, rec.target, "radtan", (640, 480))
    camera, T, shift = _calibrate(
        [str(root / "images"), "--target", str(root / "target.yaml"), "--task", "intrinsic"], tmp_path
    )
    assert T is None and shift is None
    assert (camera.width, camera.height) == (640, 480)  # the size of the images the detector saw
    assert np.allclose(camera.intrinsics, reference.camera.intrinsics, atol=1e-6)
    assert np.abs(camera.intrinsics - rec.truth.camera.intrinsics).max() < 4.0


def test_sources_without_imu_or_target_fail_with_the_fix(exports, tmp_path, capsys):
    _, root = exports
    target = ["--target", str(root / "target.yaml")]
    assert main([str(root / "images"), *target, "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "joint task needs IMU data" in err and "image folder holds no IMU data" in err and "--task intrinsic" in err
    assert main([str(root / "corners.csv"), *target, "--out", str(tmp_path / "b")]) == 2
    assert "--imu-csv" in capsys.readouterr().err
    assert main([str(root / "data.bag"), *target, "--imu-topic", "/imu1", "--out", str(tmp_path / "c")]) == 2
    assert "topic /imu1 is missing; the bag has: " in (err := capsys.readouterr().err)
    assert "Choose the topic (--imu-topic)" in err
    assert main([str(root / "euroc"), "--out", str(tmp_path / "d")]) == 2
    assert "give the calibration target as --target target.yaml (a Kalibr target YAML)" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "d").exists()


def test_a_joint_calibration_detects_poses_and_screens_each_frame_once(exports, tmp_path, monkeypatch):
    """From images to the joint result: the detector, PnP and the outlier screen each run once per frame (the joint
    graph starts from the poses its intrinsic start solved, and screens every view once)."""
    from vical.apps import calibrate as app
    from vical.calib.solve import initialization, intrinsics, rig, vi_problem

    rec, root = exports
    detected, posed, screened = [], [], []

    def detector(image, target):
        detected.append(id(image))
        return detect_checkerboard(image, target)

    def pnp(camera, obs, *args, **kwargs):
        posed.append(obs.t_ns)
        return real_pnp(camera, obs, *args, **kwargs)

    def screen(camera, observations, *args, **kwargs):
        screened.extend(o.t_ns for o in observations)
        return real_screen(camera, observations, *args, **kwargs)

    real_pnp, real_screen = initialization.pnp, vi_problem.reject_outliers
    monkeypatch.setattr(app, "detect_checkerboard", detector)
    monkeypatch.setattr(initialization, "pnp", pnp)  # the poses' PnP (the screen's refits are its own)
    for module in (intrinsics, vi_problem, rig):
        monkeypatch.setattr(module, "reject_outliers", screen)
    argv = [str(root / "euroc"), "--target", str(root / "target.yaml"), "--imu-yaml", str(root / "imu.yaml")]
    _calibrate([*argv, "--task", "joint"], tmp_path)
    views = int(np.count_nonzero(rec.frames.num_detections))
    assert len(detected) == len(rec.frames) == 49
    assert len(posed) == len(set(posed)) == views
    assert len(screened) == len(set(screened)) == views
