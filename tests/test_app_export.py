"""vical-export: a recording with images becomes Kalibr's inputs that read back to the same data; an export
killed mid-write (SIGKILL of a real subprocess) does not block the next one."""

import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from test_io_samples import make_recording

from vical.apps.export import kalibr_commands, main
from vical.data import CameraFrames, ImuIntrinsics
from vical.io import open_recording, read_camchain, read_imu_yaml, read_target_yaml, save_recording
from vical.io.kalibr import read_imu_intrinsics


def test_export_writes_kalibr_inputs_that_read_back(tmp_path, capsys):
    rec = make_recording()
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "kalibr_in"
    assert main([str(tmp_path / "rec"), "--out", str(out)]) == 0

    assert read_target_yaml(out / "target.yaml") == rec.target
    assert read_imu_yaml(out / "imu.yaml") == rec.truth.imu_noise
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
    commands = kalibr_commands(tmp_path, True, "/camera/image", "equidistant")
    assert "--topics /camera/image " in commands[0] and "--models pinhole-equi " in commands[0]
    assert "--models pinhole-radtan " in kalibr_commands(tmp_path, True)[0]
    assert "--models ds-none " in kalibr_commands(tmp_path, True, distortion="ds")[0]
    assert "--models eucm-none " in kalibr_commands(tmp_path, True, distortion="eucm")[0]


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
    while not (out.is_dir() and any(".tmp-" in p.name for p in out.iterdir())):
        assert proc.poll() is None, "the export ended before it was killed"
        assert time.monotonic() < deadline
        time.sleep(0.001)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert any(".tmp-" in p.name for p in out.iterdir())  # killed mid-write: a hidden temporary is left

    again = subprocess.run([*command, "--overwrite"], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert not [p for p in out.rglob("*") if ".tmp-" in p.name]
    back = open_recording(out / "data.bag", rec.target, keep_images=True)
    assert np.array_equal(back.frames.images, images)
