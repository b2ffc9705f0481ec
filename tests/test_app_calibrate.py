"""vical-calibrate end to end on saved synthetic recordings: files written, numbers right, errors clear."""

import numpy as np
import pytest

from vical.apps.calibrate import main
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise
from vical.geometry import transform_error
from vical.io.kalibr import read_camchain, read_imu_yaml, write_camchain_imucam
from vical.io.recording import save_recording


@pytest.fixture(scope="module")
def recording_dir(tmp_path_factory):
    rec = make_recording(duration=8.0, time_offset=0.012, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=21)
    path = tmp_path_factory.mktemp("rec") / "rec0"
    save_recording(rec, path)
    return path, rec


def test_joint_writes_kalibr_files_results_and_report(recording_dir, tmp_path, capsys):
    path, rec = recording_dir
    out = tmp_path / "joint"
    assert main([str(path), "--task", "joint", "--out", str(out)]) == 0
    camera, T_cam_imu, shift = read_camchain(out / "camchain-imucam.yaml")
    assert np.abs(camera.intrinsics - rec.truth.camera.intrinsics).max() < 3.0
    rot, trans = transform_error(T_cam_imu, rec.truth.T_cam_imu)
    assert np.rad2deg(rot) < 0.5 and trans < 0.01
    assert abs(shift - 0.012) < 0.001
    assert read_imu_yaml(out / "imu.yaml") == rec.truth.imu_noise
    text = (out / "results.txt").read_text()
    assert "time offset" in text and "errors against the truth" in text
    for name in ("reprojection.png", "imu.png", "report.pdf"):
        assert (out / name).stat().st_size > 1000
    assert (out / "report.pdf").read_bytes().startswith(b"%PDF")
    printed = capsys.readouterr().out
    assert "extrinsic error [%]" in printed and "solve time [s]" in printed


def test_intrinsic_then_extrinsic_with_the_written_camchain(recording_dir, tmp_path):
    path, rec = recording_dir
    assert main([str(path), "--task", "intrinsic", "--out", str(tmp_path / "a"), "--no-report"]) == 0
    camera, T, shift = read_camchain(tmp_path / "a" / "camchain.yaml")
    assert T is None and shift is None
    assert np.abs(camera.intrinsics - rec.truth.camera.intrinsics).max() < 3.0
    known = tmp_path / "known.yaml"
    write_camchain_imucam(known, rec.truth.camera, None, None)
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(known), "--out", str(tmp_path / "b"), "--no-report"]
    assert main(argv) == 0
    _, T_cam_imu, shift = read_camchain(tmp_path / "b" / "camchain-imucam.yaml")
    assert np.rad2deg(transform_error(T_cam_imu, rec.truth.T_cam_imu)[0]) < 0.5
    assert abs(shift - 0.012) < 0.001


def test_errors_exit_with_status_2_and_a_message(recording_dir, tmp_path, capsys):
    path, _ = recording_dir
    assert main([str(tmp_path / "missing"), "--out", str(tmp_path / "x")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main([str(path), "--task", "extrinsic", "--out", str(tmp_path / "y")]) == 2
    assert "--intrinsics" in capsys.readouterr().err
    assert main([str(path), "--max-time-offset", "-0.1", "--out", str(tmp_path / "z")]) == 2
    assert "max_time_offset must be a number >= 0" in capsys.readouterr().err
    (tmp_path / "taken").write_text("a file where the output folder should go")
    assert main([str(path), "--task", "intrinsic", "--out", str(tmp_path / "taken")]) == 2
    assert "vical-calibrate: error:" in capsys.readouterr().err
