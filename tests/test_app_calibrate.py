"""vical-calibrate end to end on saved synthetic recordings: files written, numbers right, errors clear; a result
the data do not support (a gyro logged in deg/s) fails with its cause; --out is never overwritten silently."""

import json
import re
from dataclasses import replace

import numpy as np
import pytest
import yaml
from test_io_kalibr_chain import OPENVINS_IMU_CHAIN

from vical.apps.calibrate import build_parser, main, run
from vical.calib.errors import CalibrationSettingError
from vical.calib.solve.checks import check_memory
from vical.calib.synthetic import Excitation, make_recording
from vical.data import ImuIntrinsics, ImuNoise, ImuSamples, Target
from vical.data.imu_grade import GRADES
from vical.geometry import CameraModel, transform_error
from vical.io.csvfiles import write_corners_csv, write_imu_csv
from vical.io.kalibr import (
    read_camchain,
    read_imu_intrinsics,
    read_imu_yaml,
    write_camchain_imucam,
    write_imu_yaml,
    write_target_yaml,
)
from vical.io.recording import save_recording
from vical.io.sample_checks import MAX_GYRO_RAD_S


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
    kalibr = (out / "results-imucam.txt").read_text()  # Kalibr's layout (tests/test_calib_kalibr_results.py)
    assert kalibr.startswith("Calibration results") and "[ok] IMU noise measured from its residuals" in kalibr
    for name in ("reprojection.png", "imu.png", "report.pdf"):
        assert (out / name).stat().st_size > 1000
    assert (out / "report.pdf").read_bytes().startswith(b"%PDF")
    printed = capsys.readouterr().out
    assert "extrinsic error [%]" in printed and "solve time [s]" in printed


def test_intrinsic_then_extrinsic_with_the_written_camchain(recording_dir, tmp_path):
    path, rec = recording_dir
    assert main([str(path), "--task", "intrinsic", "--out", str(tmp_path / "a"), "--no-report"]) == 0
    camera, T, shift = read_camchain(tmp_path / "a" / "camchain.yaml")
    assert T is None and shift is None and not (tmp_path / "a" / "results-imucam.txt").exists()  # no IMU
    assert np.abs(camera.intrinsics - rec.truth.camera.intrinsics).max() < 3.0
    known = tmp_path / "known.yaml"
    write_camchain_imucam(known, rec.truth.camera, None, None)
    # keys vical does not interpret, in the camera's section and beside it, come through to the result
    given = yaml.safe_load(known.read_text())
    given["cam0"].update(camera_name="left", rostopic="/left/image_raw")
    known.write_text(yaml.safe_dump({**given, "rig_serial": "B-0042"}, sort_keys=False))
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(known), "--out", str(tmp_path / "b"), "--no-report"]
    assert main(argv) == 0
    _, T_cam_imu, shift = read_camchain(tmp_path / "b" / "camchain-imucam.yaml")
    assert np.rad2deg(transform_error(T_cam_imu, rec.truth.T_cam_imu)[0]) < 0.5
    assert abs(shift - 0.012) < 0.001
    written = yaml.safe_load((tmp_path / "b" / "camchain-imucam.yaml").read_text())
    assert written["rig_serial"] == "B-0042" and written["cam0"]["camera_name"] == "left"
    assert written["cam0"]["rostopic"] == "/left/image_raw"


def test_errors_exit_with_status_2_and_a_message(recording_dir, tmp_path, capsys):
    path, _ = recording_dir
    assert main([str(tmp_path / "missing"), "--out", str(tmp_path / "x")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main([str(path), "--task", "extrinsic", "--out", str(tmp_path / "y")]) == 2
    assert "--intrinsics" in capsys.readouterr().err
    assert main([str(path), "--max-time-offset", "-0.1", "--out", str(tmp_path / "z")]) == 2
    assert "argument --max-time-offset: must be a number >= 0, got '-0.1'" in capsys.readouterr().err
    (tmp_path / "taken").write_text("a file where the output folder should go")
    assert main([str(path), "--task", "intrinsic", "--out", str(tmp_path / "taken")]) == 2
    assert "vical-calibrate: error:" in capsys.readouterr().err


@pytest.fixture(scope="module")
def slow_deg_per_s_csvs(tmp_path_factory):
    """Corner and IMU CSVs of a slow motion whose gyro is logged in deg/s (peak under the readers' 35 rad/s)."""
    rec = make_recording(
        duration=5.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=3, excitation=Excitation().scaled(rotation=0.3)
    )
    folder = tmp_path_factory.mktemp("deg")
    imu = ImuSamples(rec.imu.t, np.degrees(rec.imu.gyro), rec.imu.accel)
    assert 10.0 < np.abs(imu.gyro).max() < MAX_GYRO_RAD_S
    write_imu_csv(imu, folder / "imu.csv")
    write_corners_csv(rec.frames, folder / "corners.csv")
    write_target_yaml(folder / "target.yaml", rec.target)
    write_imu_yaml(folder / "imu.yaml", rec.truth.imu_noise)
    args = ["corners.csv", "--imu-csv", "imu.csv", "--target", "target.yaml", "--imu-yaml", "imu.yaml"]
    return folder, [str(folder / a) if a.endswith((".csv", ".yaml")) else a for a in args], rec


def test_a_gyro_logged_in_deg_per_s_fails_naming_the_flag_and_keeps_its_files_marked(
    slow_deg_per_s_csvs, tmp_path, capsys
):
    _, args, rec = slow_deg_per_s_csvs
    out = tmp_path / "out"
    assert main([*args, "--image-size", "640", "480", "--out", str(out), "--no-report"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("vical-calibrate: error: the calibration failed: the gyro reads 5")
    assert "x the rotation the camera sees: it logs deg/s; pass --gyro-unit deg/s" in line
    assert sorted(p.name for p in out.iterdir()) == [
        "camchain-imucam.failed.yaml", "frames.csv", "imu.yaml", "results.txt"
    ]  # fmt: skip
    assert (out / "results.txt").read_text().startswith("FAILED: the calibration failed: the gyro reads 5")

    fixed = tmp_path / "fixed"
    argv = [*args, "--image-size", "640", "480", "--gyro-unit", "deg/s", "--out", str(fixed), "--no-report"]
    assert main(argv) == 0
    _, T_cam_imu, shift = read_camchain(fixed / "camchain-imucam.yaml")
    assert np.rad2deg(transform_error(T_cam_imu, rec.truth.T_cam_imu)[0]) < 1.0 and abs(shift) < 0.002


def _csv_inputs(folder, rec, imu, target):
    write_imu_csv(imu, folder / "imu.csv")
    write_corners_csv(rec.frames, folder / "corners.csv")
    write_target_yaml(folder / "target.yaml", target)
    write_imu_yaml(folder / "imu.yaml", rec.truth.imu_noise)
    args = ["corners.csv", "--imu-csv", "imu.csv", "--target", "target.yaml", "--imu-yaml", "imu.yaml"]
    return [str(folder / a) if a.endswith((".csv", ".yaml")) else a for a in args] + ["--image-size", "640", "480"]


@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    """6 s of motion in front of the paper's checkerboard, its IMU as recorded."""
    return make_recording(duration=6.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=4), tmp_path_factory


def test_an_accelerometer_in_g_fails_naming_the_flag_where_no_reader_checked_it(moving, tmp_path, capsys):
    """A recording directory keeps its samples as saved: the calibrator's own evidence (gravity reads 1) names it."""
    rec, _ = moving
    save_recording(replace(rec, imu=ImuSamples(rec.imu.t, rec.imu.gyro, rec.imu.accel / 9.81)), tmp_path / "rec")
    assert main([str(tmp_path / "rec"), "--out", str(tmp_path / "out"), "--no-report"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("vical-calibrate: error: the calibration failed: the accelerometer reads 1")
    assert "it logs g; pass --accel-unit g" in line


def test_a_board_given_too_large_fails_naming_its_true_size(moving, tmp_path, capsys):
    rec, _ = moving
    true = rec.target
    wrong = Target.checkerboard(true.rows, true.cols, 2 * true.row_spacing)  # 14 cm squares for 7 cm ones
    args = _csv_inputs(tmp_path, rec, rec.imu, wrong)
    assert main([*args, "--out", str(tmp_path / "out"), "--no-report"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    found = re.search(
        r"the board is ([\d.]+)x smaller than --target says \(0.14 m; the data suggest ([\d.]+) m\)", line
    )
    assert found and 1.8 < float(found.group(1)) < 2.2 and 0.063 < float(found.group(2)) < 0.077


def test_imu_noise_ten_times_the_declared_is_a_warning_with_matching_values_not_a_failure(tmp_path, capsys):
    noisy = make_recording(duration=6.0, imu_noise=ImuNoise().scaled(10.0), pixel_sigma=0.3, seed=4)
    args = _csv_inputs(tmp_path, noisy, noisy.imu, noisy.target)  # imu.yaml: the paper's densities, a tenth of it
    args[args.index("--imu-yaml") + 1] = str(tmp_path / "declared.yaml")
    write_imu_yaml(tmp_path / "declared.yaml", ImuNoise())
    assert main([*args, "--out", str(tmp_path / "out"), "--no-report"]) == 0
    text = capsys.readouterr().out
    warning = next(line for line in text.splitlines() if "IMU residuals show a noise" in line)
    assert "imu.yaml values that match the residuals" in warning and "gyroscope_noise_density" in warning
    _, T_cam_imu, _ = read_camchain(tmp_path / "out" / "camchain-imucam.yaml")
    rotation, translation = transform_error(T_cam_imu, noisy.truth.T_cam_imu)
    assert np.rad2deg(rotation) < 1.0 and translation < 0.05  # 6 s of a noisy IMU: usable, not precise


def test_an_out_with_files_is_refused_and_replaced_whole_with_overwrite(recording_dir, tmp_path, capsys):
    path, _ = recording_dir
    out = tmp_path / "calib"
    assert main([str(path), "--task", "intrinsic", "--out", str(out)]) == 0
    (out / "mine.txt").write_text("another run's file")
    argv = [str(path), "--task", "intrinsic", "--out", str(out), "--no-report"]
    assert main(argv) == 2
    assert f"--out {out} already holds files; choose another directory or pass --overwrite" in capsys.readouterr().err
    assert (out / "reprojection.png").exists() and (out / "mine.txt").exists()
    assert main([*argv, "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["camchain.yaml", "frames.csv", "results.txt"]  # no plots
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib"]  # no temporary left beside it
    assert main([*argv, "--overwrite", "--out", str(path.parent)]) == 2  # never replaces its input
    assert "holds the input" in capsys.readouterr().err and path.is_dir()


def test_intrinsics_of_another_resolution_are_refused(recording_dir, tmp_path, capsys):
    path, rec = recording_dir
    camera = rec.truth.camera
    doubled = CameraModel(camera.distortion, 2 * camera.width, 2 * camera.height, *(2 * camera.intrinsics), camera.dist)
    write_camchain_imucam(tmp_path / "big.yaml", doubled, None, None)
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(tmp_path / "big.yaml"), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert f"--intrinsics {tmp_path / 'big.yaml'} calibrates 1280 x 960 px images, but the images are 640 x 480" in line
    assert not (tmp_path / "o").exists()


def test_messages_spell_the_library_parameters_as_flags(recording_dir, tmp_path, capsys):
    """The calibrator names its parameters (frame_stride=18, memory_limit_mb), vical-calibrate its flags."""
    path, rec = recording_dir
    with pytest.raises(CalibrationSettingError) as refused:
        check_memory(66, 2772, 0.5, 1)
    assert "keep one frame in 18 (frame_stride=18) or raise the limit (memory_limit_mb)" in str(refused.value)
    assert main([str(path), "--memory-limit", "0.5", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "keep one frame in 18 (--frame-stride 18) or raise the limit (--memory-limit)" in err
    assert "frame_stride" not in err and "memory_limit_mb" not in err

    write_corners_csv(rec.frames, tmp_path / "corners.csv")
    assert main([str(tmp_path / "corners.csv"), "--task", "intrinsic", "--out", str(tmp_path / "b")]) == 2
    assert "give the calibration target as --target target.yaml" in capsys.readouterr().err
    write_target_yaml(tmp_path / "target.yaml", rec.target)
    argv = [str(tmp_path / "corners.csv"), "--target", str(tmp_path / "target.yaml"), "--task", "intrinsic"]
    assert main([*argv, "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "the image size is unknown (no images came with the frames): give it as --image-size W H" in err
    assert "image_size" not in err


def test_imu_intrinsics_are_estimated_and_written_in_kalibrs_keys(tmp_path, capsys):
    scales_and_angles = np.r_[0.008, -0.006, 0.004, np.radians([0.3, -0.2, 0.4]), -0.005, 0.007, 0.003,
                              np.radians([-0.3, 0.2, 0.1, 0.2, -0.4, 0.3])]  # fmt: skip
    truth = ImuIntrinsics.from_vector(scales_and_angles)
    rec = make_recording(duration=20, imu_noise=ImuNoise(), pixel_sigma=0.2, seed=3, imu_intrinsics=truth)
    save_recording(rec, tmp_path / "rec")
    known = tmp_path / "known.yaml"
    write_camchain_imucam(known, rec.truth.camera, None, None)
    imu_chain = tmp_path / "kalibr_imu_chain.yaml"  # OpenVINS's, an ideal IMU, with the recording's noise
    noise = {"2.0000e-3": 0.004, "3.0000e-3": 0.006, "1.6968e-04": 0.0003394, "1.9393e-05": 3.8785e-05}
    text = OPENVINS_IMU_CHAIN.replace("rostopic: /imu0", "rostopic: /imu/data")
    for given, value in noise.items():
        text = text.replace(given, repr(value))
    imu_chain.write_text(text)
    argv = [str(tmp_path / "rec"), "--task", "extrinsic", "--intrinsics", str(known), "--no-report"]
    argv += ["--imu-yaml", str(imu_chain)]
    assert main([*argv, "--imu-model", "scale-misalignment", "--out", str(tmp_path / "out")]) == 0
    written = (tmp_path / "out" / "imu.yaml").read_text()
    imu0 = opencv_yaml(tmp_path / "out" / "imu.yaml")["imu0"]
    assert written.startswith("%YAML:1.0") and imu0["rostopic"] == "/imu/data" and imu0["time_offset"] == 0.0
    assert imu0["T_i_b"] == np.eye(4).tolist() and imu0["model"] == "scale-misalignment"
    assert not {"Tw", "Ta", "Tg", "R_IMUtoGYRO", "R_IMUtoACC"} & set(imu0)  # OpenVINS's identities give way
    assert read_imu_yaml(tmp_path / "out" / "imu.yaml") == ImuNoise()
    found = read_imu_intrinsics(tmp_path / "out" / "imu.yaml")
    # 0.5 % and 0.3 deg: the 3-sigma checks are in tests/test_calib_imu_intrinsics.py; this one checks the file
    np.testing.assert_allclose(found.M_accel, truth.M_accel, atol=0.005)
    np.testing.assert_allclose(found.M_gyro @ found.C_gyro_i, truth.M_gyro @ truth.C_gyro_i, atol=0.005)
    text = (tmp_path / "out" / "results.txt").read_text()
    assert "IMU intrinsics (Kalibr's scale-misalignment model" in text and "gyro_scale_z" in text
    assert main([*argv, "--g-sensitivity", "--out", str(tmp_path / "g")]) == 2
    assert "--g-sensitivity needs --imu-model scale-misalignment" in capsys.readouterr().err


def test_too_little_motion_for_the_imu_intrinsics_names_the_flag(tmp_path, capsys):
    no_yaw = Excitation(angle_amplitudes=np.array([[0.35, 0.10], [0.40, 0.10], [0.0, 0.0]]))
    save_recording(make_recording(duration=8, excitation=no_yaw), tmp_path / "rec")
    argv = [str(tmp_path / "rec"), "--imu-model", "scale-misalignment", "--out", str(tmp_path / "o"), "--no-report"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "too little motion to estimate the IMU intrinsics" in err and err.rstrip().endswith(
        "or leave --imu-model calibrated"
    )


def opencv_yaml(path) -> dict:
    """The mapping of a YAML file that starts with OpenCV's ``%YAML:1.0`` line (which PyYAML refuses)."""
    return yaml.safe_load(path.read_text().split("\n", 1)[1])


def test_an_openvins_imu_chain_with_an_ideal_imu_is_accepted_and_one_with_intrinsics_refused_by_key(
    recording_dir, tmp_path, capsys
):
    path, _ = recording_dir
    imu_chain = tmp_path / "kalibr_imu_chain.yaml"
    # model "kalibr", identity Tw, Ta, R_IMUtoGYRO, R_IMUtoACC, zero Tg; the topic a real driver publishes
    imu_chain.write_text(OPENVINS_IMU_CHAIN.replace("rostopic: /imu0", "rostopic: /imu/data"))
    argv = [str(path), "--imu-yaml", str(imu_chain), "--no-report"]
    assert main([*argv, "--out", str(tmp_path / "ok")]) == 0
    written = tmp_path / "ok" / "imu.yaml"
    assert read_imu_yaml(written) == read_imu_yaml(imu_chain)
    # kept whole for OpenVINS: its header, rostopic, T_i_b, time_offset, model and matrices
    assert written.read_text().startswith("%YAML:1.0")
    assert opencv_yaml(written) == opencv_yaml(imu_chain)
    capsys.readouterr()
    imu_chain.write_text(OPENVINS_IMU_CHAIN.replace("Ta:\n    - [ 1.0", "Ta:\n    - [ 1.01"))
    assert main([*argv, "--out", str(tmp_path / "scaled")]) == 2
    err = capsys.readouterr().err
    assert f"{imu_chain} [imu0]: Ta differs from an ideal IMU's (identity)" in err
    assert not (tmp_path / "scaled").exists()


def test_flags_the_task_ignores_or_a_given_file_overrides_are_named_in_a_warning(recording_dir, tmp_path, capsys):
    """An IMU flag given to the camera-only task, and --model where the extrinsic task keeps the --intrinsics
    camera, change nothing: each is named in a warning (the run still succeeds)."""
    path, _ = recording_dir
    imu_flags = ["--imu-model", "scale-misalignment", "--fixed-time-offset", "--max-time-offset", "0.05"]
    assert main([str(path), "--task", "intrinsic", *imu_flags, "--out", str(tmp_path / "a"), "--no-report"]) == 0
    printed = capsys.readouterr().out
    for flag in ("--imu-model scale-misalignment", "--fixed-time-offset", "--max-time-offset 0.05"):
        assert f"warning: {flag} is ignored: the intrinsic task calibrates the camera alone" in printed, flag
    assert "ignored" in (tmp_path / "a" / "results.txt").read_text()
    written = tmp_path / "a" / "camchain.yaml"
    args = ["--task", "extrinsic", "--intrinsics", str(written), "--model", "eucm", "--no-report"]
    assert main([str(path), *args, "--out", str(tmp_path / "b")]) == 0
    assert (
        "warning: --model eucm is ignored: the extrinsic task keeps the --intrinsics camera (radtan); "
        "calibrate it with --task joint to fit another model"
    ) in capsys.readouterr().out
    assert main([str(path), "--task", "joint", "--out", str(tmp_path / "c"), "--no-report"]) == 0
    assert "is ignored" not in capsys.readouterr().out  # nothing to say where every flag counts


def test_an_imu_yaml_rate_that_is_not_the_datas_is_named_and_the_datas_rate_written(recording_dir, tmp_path, capsys):
    """A 50 Hz imu.yaml (the tutorial's file) given for 200 Hz data: a warning with both rates, and the output
    imu.yaml says 200 Hz (the noise densities are the file's)."""
    path, rec = recording_dir
    write_imu_yaml(tmp_path / "imu.yaml", replace(rec.truth.imu_noise, rate_hz=50.0))
    argv = [str(path), "--task", "joint", "--imu-yaml", str(tmp_path / "imu.yaml"), "--no-report"]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 0
    assert (
        f"warning: --imu-yaml {tmp_path / 'imu.yaml'} says update_rate 50 Hz, but the IMU samples come at 200 Hz; "
        "the output imu.yaml says 200 Hz"
    ) in capsys.readouterr().out
    written = yaml.safe_load((tmp_path / "out" / "imu.yaml").read_text())
    assert written["update_rate"] == pytest.approx(200.0)
    assert written["gyroscope_noise_density"] == pytest.approx(rec.truth.imu_noise.gyro_noise_density)


def test_a_failed_solve_with_overwrite_never_replaces_a_good_result(slow_deg_per_s_csvs, tmp_path, capsys):
    """--overwrite over a good result whose new solve fails: the good result stays, the failed one is written
    beside it (``<out>.failed``) and the error line says both."""
    _, args, _ = slow_deg_per_s_csvs
    out = tmp_path / "out"
    good = [*args, "--image-size", "640", "480", "--gyro-unit", "deg/s", "--no-report"]
    assert main([*good, "--out", str(out)]) == 0
    before = (out / "camchain-imucam.yaml").read_text()
    capsys.readouterr()
    argv = [*args, "--image-size", "640", "480", "--no-report", "--out", str(out), "--overwrite"]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("vical-calibrate: error: the calibration failed: the gyro reads 5")
    assert line.endswith(f"the outputs in {out}.failed are marked as failed; {out} keeps the result it held")
    assert (out / "camchain-imucam.yaml").read_text() == before and not (out / "camchain-imucam.failed.yaml").exists()
    assert (tmp_path / "out.failed" / "camchain-imucam.failed.yaml").is_file()


def test_a_lens_model_that_does_not_fit_is_named_with_the_one_that_does_in_the_failure(tmp_path, capsys):
    """--model ds on an ordinary ~60 deg lens (the joint task), and the extrinsic task with a ds camchain of it: the
    failure names a model that fits these corners (as the intrinsic task's comparison does) and the option."""
    rec = make_recording(duration=12.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=4)
    path = save_recording(rec, tmp_path / "rec")
    status = main([str(path), "--task", "joint", "--model", "ds", "--out", str(tmp_path / "joint"), "--no-report"])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("vical-calibrate: error")]
    assert status == 2 and len(lines) == 1
    # Of the models that fit equally well (radtan, equidistant, omni: a pinhole lens) the comparison names the one
    # with the fewest coefficients (vical.calib.solve.intrinsics.best_model)
    found = re.search(r"likely cause: the lens model: ([\w-]+) fits these corners with 0\.\d+ px rms against ds's "
                      r"[\d.]+ px: pass --model ([\w-]+)", lines[0])  # fmt: skip
    assert found and found[1] == found[2] and found[1] in ("radtan", "equidistant", "omni", "omni-radtan"), lines[0]

    ds = CameraModel.from_hfov(1.0, rec.truth.camera.width, rec.truth.camera.height, [-0.2, 0.6], "ds")
    chain = tmp_path / "ds.yaml"
    write_camchain_imucam(chain, ds, rec.truth.T_cam_imu, 0.0)
    status = main([str(path), "--task", "extrinsic", "--intrinsics", str(chain), "--out", str(tmp_path / "extrinsic"),
                   "--no-report"])  # fmt: skip
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("vical-calibrate: error")]
    assert status == 2 and len(lines) == 1
    cause = (r"likely cause: the lens model: ([\w-]+) fits these corners .* against ds's [\d.]+ px: calibrate the "
             r"intrinsics with --task intrinsic --model ([\w-]+) and give them as --intrinsics")  # fmt: skip
    found = re.search(cause, lines[0])
    assert found and found[1] == found[2] and found[1] != "ds", lines[0]


def test_export_writes_what_vins_fusion_and_basalt_read_from_the_calibration(tmp_path, capsys):
    """``--export``: the calibration's own numbers (camchain-imucam.yaml's) in VINS-Fusion's and basalt's files, read
    as they read them (``tests/test_io_vio_exports.py`` checks the formats themselves)."""
    import cv2

    from vical.calib.synthetic import default_camera

    rec = make_recording(duration=8.0, camera=default_camera("equidistant"), time_offset=0.012,
                         imu_noise=ImuNoise(), pixel_sigma=0.3, seed=22)  # fmt: skip
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "out"
    argv = [str(tmp_path / "rec"), "--model", "equidistant", "--export", "vins-fusion", "basalt", "--no-report"]
    assert main([*argv, "--out", str(out)]) == 0
    camera, T_cam_imu, shift = read_camchain(out / "camchain-imucam.yaml")
    config = cv2.FileStorage(str(out / "vins-fusion" / "config.yaml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(config.getNode("body_T_cam0").mat(), np.linalg.inv(T_cam_imu), atol=1e-9)
    assert abs(config.getNode("td").real() - shift) < 1e-12 and abs(shift - 0.012) < 0.001
    camodocal = cv2.FileStorage(str(out / "vins-fusion" / "cam0.yaml"), cv2.FILE_STORAGE_READ)  # kept: its nodes
    lens = camodocal.getNode("projection_parameters")
    np.testing.assert_allclose([lens.getNode(k).real() for k in ("mu", "mv", "u0", "v0", "k2", "k3", "k4", "k5")],
                               [*camera.intrinsics, *camera.dist], rtol=1e-9)  # fmt: skip
    basalt = json.loads((out / "basalt" / "calibration.json").read_text())["value0"]
    assert basalt["intrinsics"][0]["camera_type"] == "kb4"
    assert abs(basalt["intrinsics"][0]["intrinsics"]["fx"] - camera.fx) < 1e-6 * camera.fx
    assert basalt["cam_time_offset_ns"] == round(shift * 1e9)
    assert f"for VIO systems: {out / 'vins-fusion' / 'config.yaml'}" in capsys.readouterr().out


def test_an_export_the_format_cannot_hold_is_refused_before_the_solve(recording_dir, tmp_path, capsys):
    path, _ = recording_dir
    out = tmp_path / "out"
    assert main([str(path), "--export", "basalt", "--out", str(out)]) == 2  # the default radtan lens
    err = capsys.readouterr().err.strip()
    assert err.startswith("vical-calibrate: error: --export basalt: basalt has no radtan model: calibrate with --model")
    assert len(err.splitlines()) == 1 and not out.exists()
    assert main([str(path), "--task", "intrinsic", "--export", "vins-fusion", "--out", str(out)]) == 2
    assert "vins-fusion needs the camera-IMU calibration" in capsys.readouterr().err and not out.exists()


@pytest.fixture(scope="module")
def real_like_csvs(recording_dir, tmp_path_factory):
    """The recording as a user's real files give it: corner and IMU CSVs (no truth), target, imu.yaml, camchain."""
    _, rec = recording_dir
    folder = tmp_path_factory.mktemp("real")
    write_imu_csv(rec.imu, folder / "imu.csv")
    write_corners_csv(rec.frames, folder / "corners.csv")
    write_target_yaml(folder / "target.yaml", rec.target)
    write_imu_yaml(folder / "imu.yaml", rec.truth.imu_noise)
    write_camchain_imucam(folder / "known.yaml", rec.truth.camera, None, None)
    argv = [str(folder / "corners.csv"), "--imu-csv", str(folder / "imu.csv"), "--target", str(folder / "target.yaml"),
            "--imu-yaml", str(folder / "imu.yaml"), "--task", "extrinsic", "--intrinsics", str(folder / "known.yaml"),
            "--no-report"]  # fmt: skip
    return folder, argv


def test_a_real_imu_counts_its_grade_in_the_sigmas_the_declared_one_or_the_real_data_default(
    real_like_csvs, tmp_path, capsys
):
    folder, argv = real_like_csvs

    def calibrated(*flags, imu_yaml=None):
        given = argv if imu_yaml is None else [*argv, "--imu-yaml", str(imu_yaml)]
        return run(build_parser().parse_args([*given, *flags, "--out", str(tmp_path / "o"), "--overwrite"]))

    default, perfect = calibrated(), calibrated("--imu-grade", "calibrated")
    assert [t.sensor for t in default.unmodelled_imu] == ["gyro", "accelerometer"]
    assert not any(np.any(t.covariance()) for t in perfect.unmodelled_imu)
    np.testing.assert_allclose(default.T_cam_imu, perfect.T_cam_imu)  # the grade moves the sigmas, not the estimate
    added = sum(t.covariance() for t in default.unmodelled_imu)
    np.testing.assert_allclose(default.covariance, perfect.covariance + added, rtol=1e-9, atol=1e-18)
    assert default.sigma("rot_x") > perfect.sigma("rot_x")
    consumer = folder / "consumer.yaml"
    write_imu_yaml(consumer, ImuNoise(), grade=GRADES["consumer"])
    assert calibrated(imu_yaml=consumer).sigma("t_z") > default.sigma("t_z")
    capsys.readouterr()


def test_a_grade_that_contradicts_the_imu_model_or_a_bad_grade_key_is_one_line_and_exit_2(
    real_like_csvs, tmp_path, capsys
):
    folder, argv = real_like_csvs
    flags = ["--imu-grade", "calibrated", "--imu-model", "scale-misalignment", "--out", str(tmp_path / "a")]
    assert main([*argv, *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        "the IMU grade 'calibrated' says the IMU has no scale or misalignment, but --imu-model scale-misalignment"
        in err
    )
    assert "(--imu-grade industrial, or consumer)" in err and len(err.splitlines()) == 1
    bad = folder / "bad.yaml"
    bad.write_text((folder / "imu.yaml").read_text() + "gyroscope_scale_sigma: 0.3\n")
    assert main([*argv, "--imu-yaml", str(bad), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{bad}: gyroscope_scale_sigma: IMU grade gyro_scale must be a 1-sigma from 0 to 0.1" in err
    assert len(err.splitlines()) == 1 and not (tmp_path / "b").exists()
    assert main([*argv, "--imu-grade", "tactical", "--out", str(tmp_path / "c")]) == 2
    assert "invalid choice: 'tactical'" in capsys.readouterr().err
