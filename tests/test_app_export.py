"""vical-export: a recording with images becomes Kalibr's inputs that read back to the same data; an export
killed mid-write (SIGKILL of a real subprocess) does not block the next one."""

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_io_rig import make_rig
from test_io_samples import make_recording

from vical.apps.export import KALIBR_MODELS, kalibr_commands, main
from vical.data import CameraFrames, ImuIntrinsics
from vical.geometry import CAMERA_MODELS
from vical.geometry.transforms import invert_transform
from vical.io import open_recording, read_camchain, read_chain, read_imu_yaml, read_target_yaml, save_recording
from vical.io.bag import bag_image_topics
from vical.io.kalibr import read_imu_grade, read_imu_intrinsics


def test_export_writes_kalibr_inputs_that_read_back(tmp_path, capsys):
    rec = make_recording()
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out)]) == 0

    assert read_target_yaml(out / "target.yaml") == rec.target
    assert read_imu_yaml(out / "imu.yaml") == rec.truth.imu_noise
    assert read_imu_grade(out / "imu.yaml") == rec.truth.imu_grade  # declared as its noise: calibrated
    camera, T, shift = read_camchain(out / "camchain.yaml")
    assert camera == rec.truth.camera and T is None and shift is None
    _, T_truth, shift_truth = read_camchain(out / "camchain-imucam-truth.yaml")
    assert np.allclose(T_truth, rec.truth.T_cam_imu) and shift_truth == rec.truth.time_offset
    for source in ("data.bag", "euroc"):
        back = open_recording(out / source, rec.target, keep_images=True)
        assert np.array_equal(back.frames.t, rec.frames.t) and np.array_equal(back.frames.images, rec.frames.images)
        assert np.array_equal(back.imu.t, rec.imu.t) and np.array_equal(back.imu.gyro, rec.imu.gyro)
    printed = capsys.readouterr().out
    assert f"kalibr_calibrate_imu_camera --bag {out / 'data.bag'} --cams {out / 'camchain.yaml'}" in printed
    assert "--time-calibration" in printed and "--imu-models" not in printed
    assert not (out / "imu-truth.yaml").exists()  # an exact IMU: nothing more to compare


@pytest.mark.parametrize("bags", [["db3", "mcap"], ["ros1", "mcap"]])
def test_export_writes_ros2_bags_that_read_back(bags, tmp_path, capsys):
    """``--bag``: ROS 2 bags (SQLite, MCAP) instead of or beside the ROS1 one; Kalibr's commands need the ROS1 one."""
    rec = make_recording(seed=2)
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "out"
    assert main([str(tmp_path / "rec"), "--out", str(out), "--bag", *bags]) == 0
    names = {"ros1": "data.bag", "db3": "ros2_db3", "mcap": "ros2_mcap"}
    assert sorted(p.name for p in out.iterdir() if "bag" in p.name or "ros2" in p.name) == sorted(
        names[b] for b in bags
    )
    for bag in bags:
        back = open_recording(out / names[bag], rec.target, keep_images=True)
        assert np.array_equal(back.frames.t, rec.frames.t) and np.array_equal(back.frames.images, rec.frames.images)
        assert np.array_equal(back.imu.t, rec.imu.t) and np.array_equal(back.imu.accel, rec.imu.accel)
    printed = capsys.readouterr().out
    assert ("kalibr_calibrate_cameras --bag" in printed) == ("ros1" in bags)
    assert ("Kalibr reads ROS1 bags only: add --bag ros1" in printed) == ("ros1" not in bags)


def test_an_imu_with_intrinsics_exports_their_truth_and_has_kalibr_estimate_them(tmp_path, capsys):
    rec = make_recording()
    intrinsics = ImuIntrinsics.from_vector(np.r_[0.01, -0.005, 0.002, np.radians([0.3, -0.2, 0.1]), np.zeros(9)])
    rec = replace(rec, truth=replace(rec.truth, imu_intrinsics=intrinsics))
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out)]) == 0
    assert read_imu_yaml(out / "imu.yaml") == rec.truth.imu_noise  # Kalibr's input: the noise only
    assert read_imu_intrinsics(out / "imu.yaml") is None
    np.testing.assert_array_equal(read_imu_intrinsics(out / "imu-truth.yaml").M_accel, intrinsics.M_accel)
    assert "--time-calibration --imu-models scale-misalignment" in capsys.readouterr().out


def test_export_refuses_recordings_without_images_and_full_outputs(tmp_path, capsys):
    save_recording(make_recording(images=False), tmp_path / "rec")
    assert main([str(tmp_path / "rec"), "--out", str(tmp_path / "a")]) == 2
    assert "no images" in capsys.readouterr().err
    save_recording(make_recording(), tmp_path / "rec2")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "keep.txt").write_text("mine")
    assert main([str(tmp_path / "rec2"), "--out", str(tmp_path / "b")]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main([str(tmp_path / "b"), "--out", str(tmp_path / "c")]) == 2
    assert "not a vical recording directory" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert main([str(tmp_path / "rec2"), "--out", str(tmp_path / "file")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_kalibr_commands_follow_the_topic_and_the_lens_model(tmp_path):
    commands = kalibr_commands(tmp_path, True, ["/camera/image"], ["equidistant"])
    assert "--topics /camera/image " in commands[0] and "--models pinhole-equi " in commands[0]
    assert "--models pinhole-radtan " in kalibr_commands(tmp_path, True)[0]
    assert "--models ds-none " in kalibr_commands(tmp_path, True, distortions=["ds"])[0]
    assert "--models eucm-none " in kalibr_commands(tmp_path, True, distortions=["eucm"])[0]
    rig = kalibr_commands(tmp_path, True, ["/left", "/right"], ["radtan", "ds"])[0]
    assert "--topics /left /right --models pinhole-radtan ds-none " in rig


def test_every_camera_model_has_a_kalibr_name():
    assert set(KALIBR_MODELS) == set(CAMERA_MODELS)  # an export never meets a lens it cannot name


# ------------------------------------------------------------------------------- rigs
def test_a_rig_exports_every_camera(tmp_path, capsys):
    rec = make_rig(cameras=2)  # cam0 radtan, cam1 equidistant 11 cm beside it, both with images and truth
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out)]) == 0

    assert bag_image_topics(out / "data.bag") == ["/cam0/image_raw", "/cam1/image_raw"]
    for source in ("euroc", "data.bag"):
        topics = ["/cam0/image_raw", "/cam1/image_raw"]  # a bag's; an EuRoC folder's camN folders are all read
        back = open_recording(out / source, rec.target, image_topic=topics, keep_images=True)
        assert back.camera_names == ["cam0", "cam1"]
        for name in rec.camera_names:
            assert np.array_equal(back.frames_of(name).t, rec.frames_of(name).t)
            assert np.array_equal(back.frames_of(name).images, rec.frames_of(name).images)

    T_c1_c0 = rec.truth_of("cam1").T_cam_imu @ invert_transform(rec.truth_of("cam0").T_cam_imu)
    cameras = read_chain(out / "camchain.yaml")
    assert cameras.names == ["cam0", "cam1"]
    for camera in cameras.cameras:
        assert camera.camera == rec.truth_of(camera.name).camera and camera.T_cam_imu is None
        assert camera.rostopic == f"/{camera.name}/image_raw"
    np.testing.assert_array_equal(cameras["cam1"].T_cn_cnm1, T_c1_c0)
    assert cameras["cam0"].cam_overlaps == (1,) and cameras["cam1"].cam_overlaps == (0,)  # 2 us apart
    truth = read_chain(out / "camchain-imucam-truth.yaml")
    for name in rec.camera_names:
        np.testing.assert_array_equal(truth[name].T_cam_imu, rec.truth_of(name).T_cam_imu)
        assert truth[name].timeshift_cam_imu == rec.truth_of(name).time_offset
    np.testing.assert_allclose(truth.relative_pose("cam1"), T_c1_c0, atol=1e-15)

    printed = capsys.readouterr().out
    assert (
        f"kalibr_calibrate_cameras --bag {out / 'data.bag'} --topics /cam0/image_raw /cam1/image_raw "
        f"--models pinhole-radtan pinhole-equi --target {out / 'target.yaml'}"
    ) in printed
    assert f"--cams {out / 'camchain.yaml'}" in printed


def test_a_rigs_topics_are_given_per_camera(tmp_path, capsys):
    save_recording(make_rig(cameras=3), tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out), "--image-topic", "/left", "/right"]) == 0
    assert bag_image_topics(out / "data.bag") == ["/left", "/right", "/cam2/image_raw"]
    assert [c.rostopic for c in read_chain(out / "camchain.yaml").cameras] == ["/left", "/right", "/cam2/image_raw"]
    assert "--topics /left /right /cam2/image_raw --models" in capsys.readouterr().out


def test_a_rig_with_a_camera_of_unknown_truth_gets_no_true_camchain(tmp_path, capsys):
    rec = make_rig(cameras=2)
    save_recording(replace(rec, other_truths={}), tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out)]) == 0
    assert not (out / "camchain.yaml").exists() and not (out / "camchain-imucam-truth.yaml").exists()
    assert bag_image_topics(out / "data.bag") == ["/cam0/image_raw", "/cam1/image_raw"]
    printed = capsys.readouterr().out
    assert "note: the recording has no truth of cam1: no camchain.yaml (the true chain is written for every " in printed
    assert "--topics /cam0/image_raw /cam1/image_raw --models pinhole-radtan pinhole-radtan " in printed
    assert "--cams camchain-" in printed  # Kalibr's camera calibration's result


@pytest.mark.parametrize(
    ("edit", "topics", "message"),
    [
        (
            lambda rec: replace(rec, other_frames={"cam1": replace(rec.other_frames["cam1"], images=None)}),
            [],
            r"the recording has no images of cam1; record it with images \(vical-record images=true\)",
        ),
        (
            lambda rec: rec,
            ["--image-topic", "/a", "/b", "/c"],
            r"--image-topic gives 3 topics, but the recording has 2 camera\(s\) \(cam0, cam1\); give "
            "one topic per camera, cam0's first",
        ),
        (
            lambda rec: rec,
            ["--image-topic", "/cam1/image_raw"],
            r"image topics \['/cam1/image_raw', '/cam1/image_raw'\] repeat a topic; give each camera "
            "its own",
        ),
    ],
    ids=["camera-without-images", "more-topics-than-cameras", "repeated-topic"],
)
def test_a_rig_that_cannot_be_written_whole_is_refused_before_anything_is_written(
    tmp_path, capsys, edit, topics, message
):
    save_recording(edit(make_rig(cameras=2)), tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out), *topics]) == 2
    assert re.fullmatch("vical-export: error: " + message, capsys.readouterr().err.strip())  # one line
    assert not out.exists()


@pytest.mark.integration
def test_an_export_killed_mid_write_leaves_nothing_that_blocks_the_next_one(tmp_path):
    rec = make_recording(n_frames=150)
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (150, 480, 640), dtype=np.uint8)  # slow to encode: the kill lands mid-write
    save_recording(
        replace(rec, frames=CameraFrames(rec.frames.t, rec.frames.corners, rec.frames.ids, images)), tmp_path / "rec"
    )
    out = tmp_path / "kalibr_in"
    command = [str(Path(sys.executable).parent / "vical-export"), str(tmp_path / "rec"), "--out", str(out)]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    # A new --out is built aside, as a hidden temporary sibling, and renamed into place whole.
    while not any(p.name.startswith(".kalibr_in.tmp-") for p in tmp_path.iterdir()):
        assert proc.poll() is None, "the export ended before it was killed"
        assert time.monotonic() < deadline
        time.sleep(0.001)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists()  # killed mid-write: no --out, a hidden temporary is left beside it
    assert any(p.name.startswith(".kalibr_in.tmp-") for p in tmp_path.iterdir())

    again = subprocess.run([*command, "--overwrite"], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert not [p for p in tmp_path.rglob("*") if ".tmp-" in p.name]
    back = open_recording(out / "data.bag", rec.target, keep_images=True)
    assert np.array_equal(back.frames.images, images)
