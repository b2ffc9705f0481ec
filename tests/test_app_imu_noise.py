"""vical-imu-noise end to end: a static EuRoC folder and a ROS1 bag in, Kalibr imu.yaml files and the Allan plot out;
bad inputs refused in one line."""

import re

import cv2
import numpy as np
import pytest
import yaml
from imu_streams import NOISE, static_stream, truths
from rosbags.rosbag1 import Writer

from vical.apps import imu_noise
from vical.io.bag import IMU_TYPE, _imu_msg, ros1_typestore
from vical.io.csvfiles import write_imu_csv
from vical.io.kalibr import read_imu_yaml


@pytest.fixture(scope="module")
def euroc(tmp_path_factory):
    """A 30 min static recording at 50 Hz as an EuRoC folder (imu0 only)."""
    root = tmp_path_factory.mktemp("static")
    write_imu_csv(static_stream(1800, 4), root / "mav0" / "imu0" / "data.csv")
    return root


def run(argv, capsys) -> tuple[int, str, str]:
    status = imu_noise.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def test_a_static_euroc_folder_gives_kalibr_files_with_the_simulated_noise(euroc, tmp_path, capsys):
    out = tmp_path / "noise"
    status, printed, _ = run([euroc, "--out", out, "--rate", 50], capsys)
    assert status == 0, printed
    measured = read_imu_yaml(out / "imu.yaml")
    assert measured.gyro_noise_density == pytest.approx(NOISE.gyro_noise_density, rel=0.10)
    assert measured.gyro_random_walk == pytest.approx(NOISE.gyro_random_walk, rel=0.10)
    assert measured.accel_noise_density == pytest.approx(NOISE.accel_noise_density, rel=0.10)
    assert measured.accel_random_walk == pytest.approx(NOISE.accel_random_walk, rel=0.10)
    assert measured.rate_hz == 50.0
    raw = yaml.safe_load((out / "imu.yaml").read_text())
    assert raw["rostopic"] == "/imu0" and (out / "imu.yaml").read_text().startswith("# vical-imu-noise")
    inflated = read_imu_yaml(out / "imu-inflated.yaml")
    assert inflated.gyro_noise_density == pytest.approx(10 * measured.gyro_noise_density)
    assert inflated.accel_random_walk == pytest.approx(20 * measured.accel_random_walk)
    assert "noise densities x10, random walks x20" in (out / "imu-inflated.yaml").read_text()
    report = yaml.safe_load((out / "allan.yaml").read_text())
    density, walk = truths(NOISE)
    for (name, axis), n, k in zip(report["axes"].items(), density, walk, strict=True):
        assert axis["noise_density"] == pytest.approx(n, rel=0.10), name
        assert axis["random_walk"] == pytest.approx(k, rel=0.10), name
        assert len(axis["tau"]) == len(axis["allan_deviation"]) > 50
    image = cv2.imread(str(out / "allan.png"))
    assert image is not None and image.shape[0] > 300 and image.shape[1] > 600 and image.std() > 10
    assert "gyro x" in printed and "imu-inflated.yaml" in printed and f"outputs written to {out}" in printed


def test_the_written_files_are_the_only_entries_of_out(euroc, tmp_path, capsys):
    out = tmp_path / "noise"
    assert run([euroc, "--out", out], capsys)[0] == 0
    assert sorted(p.name for p in out.iterdir()) == ["allan.png", "allan.yaml", "imu-inflated.yaml", "imu.yaml"]
    status, _, err = run([euroc, "--out", out], capsys)
    assert status == 2 and "already holds files" in err and "--overwrite" in err


def write_imu_bag(path, imu, topic="/imu0") -> None:
    with Writer(path) as writer:
        connection = writer.add_connection(topic, IMU_TYPE, typestore=ros1_typestore())
        for k, t in enumerate(imu.t.tolist()):
            message = _imu_msg(t, k, imu.gyro[k], imu.accel[k])
            writer.write(connection, t, ros1_typestore().serialize_ros1(message, IMU_TYPE))


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory):
    """60 s of a static IMU in a bag without images (too short for the random walk)."""
    path = tmp_path_factory.mktemp("bag") / "static.bag"
    write_imu_bag(path, static_stream(60, 0))
    return path


def test_a_bag_is_read_on_its_imu_topic_and_a_short_one_refused_with_the_duration_needed(short_bag, tmp_path, capsys):
    status, _, err = run([short_bag, "--out", tmp_path / "o"], capsys)
    assert status == 2
    line = err.strip().splitlines()[-1]
    assert line.startswith(f"vical-imu-noise: error: {short_bag}: 60 s is too short to measure the bias random walk")
    assert "record the IMU lying still for about" in line
    assert not (tmp_path / "o").exists()


def test_a_missing_topic_lists_the_bag_topics(short_bag, tmp_path, capsys):
    status, _, err = run([short_bag, "--imu-topic", "/imu1", "--out", tmp_path / "o"], capsys)
    assert status == 2
    assert "topic /imu1 is missing; the bag has: /imu0 (sensor_msgs/msg/Imu)" in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["{missing}"], "does not exist"),
        (["{euroc}", "--rate", "200"], "--rate 200 Hz disagrees with the timestamps of"),
        (["{euroc}", "--start", "2000"], "--start 2000 s leaves nothing of the 1800.0 s recording"),
        (["{empty}"], "holds no IMU CSV: neither"),
        (["{euroc}", "--inflate-walk", "0.5"], "argument --inflate-walk: must be a number >= 1, got '0.5'"),
        # One row: no --start was given, so the message must not blame it.
        (["{one_row}"], "holds one IMU sample: the noise identification needs hours of a resting IMU"),
    ],
)
def test_bad_inputs_are_refused_in_one_line(argv, message, euroc, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    imu = static_stream(1, 0)
    write_imu_csv(type(imu)(imu.t[:1], imu.gyro[:1], imu.accel[:1]), tmp_path / "one.csv")
    paths = {
        "missing": tmp_path / "nothing.csv",
        "euroc": euroc,
        "empty": tmp_path / "empty",
        "one_row": tmp_path / "one.csv",
    }
    status, _, err = run([a.format(**paths) for a in argv] + ["--out", tmp_path / "o"], capsys)
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.startswith("vical-imu-noise")]
    assert status == 2 and len(lines) == 1 and message in lines[0], err


def test_a_moving_recording_is_refused_with_the_span(tmp_path, capsys):
    imu = static_stream(600, 0)
    gyro = imu.gyro.copy()
    gyro[(imu.t - imu.t[0]) // 10**9 == 100, 2] += 1.0  # a turn at 1 rad/s during one second
    moving = tmp_path / "moving.csv"
    write_imu_csv(type(imu)(imu.t, gyro, imu.accel), moving)
    status, _, err = run([moving, "--out", tmp_path / "o"], capsys)
    assert status == 2 and "the IMU moves between 100.0 s and 101.0 s: gyro z changes by 1" in err


@pytest.mark.parametrize(
    ("scale", "unit", "message"),
    [
        # The test stream's gyro (0.002 rad/s/sqrt(Hz), a noisy MEMS) logged in deg/s and read as rad/s: ~0.115.
        (180 / np.pi, None, r"gyroscope_noise_density 0\.11\d rad/s/sqrt\(Hz\) is above any real gyro"),
        # A quiet gyro (2e-5 rad/s/sqrt(Hz)) logged in rad/s and read with --gyro-unit deg/s: ~3.5e-7.
        (0.01, "deg/s", r"gyroscope_noise_density 3\.\d\de-07 rad/s/sqrt\(Hz\) is below any real gyro"),
    ],
)
def test_a_gyro_density_no_real_gyro_has_names_the_likely_unit(scale, unit, message, tmp_path, capsys):
    imu = static_stream(1800, 4)
    path = tmp_path / "static.csv"
    write_imu_csv(type(imu)(imu.t, imu.gyro * scale, imu.accel), path)
    argv = [path, "--out", tmp_path / "o"] + (["--gyro-unit", unit] if unit else [])
    status, printed, _ = run(argv, capsys)
    assert status == 0
    fix = "pass --gyro-unit deg/s" if unit is None else "leave out --gyro-unit deg/s"
    warning = next(line for line in printed.splitlines() if line.startswith("warning:"))
    assert re.search(message, warning) and fix in warning, warning
    assert "navigation grade" in warning


def test_a_gyro_in_the_range_of_real_gyros_gets_no_unit_warning(euroc, tmp_path, capsys):
    status, printed, _ = run([euroc, "--out", tmp_path / "o"], capsys)
    assert status == 0 and "warning:" not in printed
