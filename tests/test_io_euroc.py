"""EuRoC folders and CSV files: lossless round trips, detection hook, bad input named by file and line."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
import yaml
from test_io_samples import T0_NS, assert_frames_equal, make_recording

from vical.geometry import CameraModel
from vical.io.csvfiles import IMU_HEADER, read_corners_csv, read_imu_csv, write_corners_csv, write_imu_csv
from vical.io.errors import CsvFormatError, FormatError, UnitError
from vical.io.euroc import read_euroc, write_euroc
from vical.io.sample_checks import FormatWarning


def test_euroc_round_trip_is_lossless(tmp_path):
    rec = make_recording()
    write_euroc(rec, tmp_path / "seq")
    assert (tmp_path / "seq" / "mav0" / "cam0" / "data" / f"{rec.frames.t[0]}.png").is_file()
    header = (tmp_path / "seq" / "mav0" / "imu0" / "data.csv").read_text().splitlines()[0]
    assert header == IMU_HEADER
    back = read_euroc(tmp_path / "seq", rec.target)
    assert np.array_equal(back.imu.t, rec.imu.t)
    assert np.array_equal(back.imu.gyro, rec.imu.gyro) and np.array_equal(back.imu.accel, rec.imu.accel)
    assert_frames_equal(back.frames, rec.frames)
    assert back.truth.camera == rec.truth.camera
    assert np.allclose(back.truth.T_cam_imu, rec.truth.T_cam_imu, atol=1e-15)
    assert back.truth.time_offset == rec.truth.time_offset and back.truth.imu_noise == rec.truth.imu_noise


def test_euroc_sensor_yaml_holds_a_rolling_shutters_line_delay(tmp_path):
    rec = make_recording()
    rec = replace(rec, truth=replace(rec.truth, line_delay=27.5e-6))
    write_euroc(rec, tmp_path / "seq")
    sensor = yaml.safe_load((tmp_path / "seq" / "mav0" / "cam0" / "sensor.yaml").read_text())
    assert sensor["line_delay_nanoseconds"] == 27500.0
    assert read_euroc(tmp_path / "seq", rec.target).truth.line_delay == pytest.approx(27.5e-6, rel=1e-12)
    write_euroc(replace(rec, truth=replace(rec.truth, line_delay=0.0)), tmp_path / "global")
    assert "line_delay" not in (tmp_path / "global" / "mav0" / "cam0" / "sensor.yaml").read_text()


def test_euroc_sensor_yaml_holds_a_double_sphere_camera_as_kalibr_names_it(tmp_path):
    rec = make_recording()
    camera = CameraModel("ds", 64, 48, 20.5, 20.4, 31.7, 24.1, [-0.21, 0.59])
    rec = replace(rec, truth=replace(rec.truth, camera=camera))
    write_euroc(rec, tmp_path / "seq")
    sensor = yaml.safe_load((tmp_path / "seq" / "mav0" / "cam0" / "sensor.yaml").read_text())
    assert sensor["camera_model"] == "ds" and sensor["intrinsics"] == [-0.21, 0.59, 20.5, 20.4, 31.7, 24.1]
    assert sensor["distortion_model"] == "none" and sensor["distortion_coefficients"] == []
    assert read_euroc(tmp_path / "seq", rec.target).truth.camera == camera


def test_euroc_detector_replaces_stored_corners(tmp_path):
    rec = make_recording()
    write_euroc(rec, tmp_path / "seq")

    def detector(image):
        # A deterministic function of the pixels: proves each frame's own image reached the detector.
        return np.array([[float(image[0, 0]), float(image[1, 1])]]), np.array([int(image[2, 2]) % 20])

    back = read_euroc(tmp_path / "seq" / "mav0", rec.target, detector=detector, keep_images=False)
    assert back.frames.images is None
    for k, image in enumerate(rec.frames.images):
        assert np.array_equal(back.frames.corners[k], [[image[0, 0], image[1, 1]]])
        assert back.frames.ids[k][0] == image[2, 2] % 20


def test_euroc_without_images_is_refused(tmp_path):
    with pytest.raises(FormatError, match="has none"):
        write_euroc(make_recording(images=False), tmp_path / "seq")
    assert not (tmp_path / "seq").exists()


def test_euroc_wrong_image_size_names_the_file(tmp_path):
    rec = make_recording()
    write_euroc(rec, tmp_path / "seq")
    bad = tmp_path / "seq" / "mav0" / "cam0" / "data" / f"{rec.frames.t[3]}.png"
    cv2.imwrite(str(bad), np.zeros((10, 12), np.uint8))
    with pytest.raises(FormatError, match=rf"{rec.frames.t[3]}\.png: image is 12 x 10 px.*64 x 48"):
        read_euroc(tmp_path / "seq", rec.target)


def test_euroc_missing_and_corrupt_images(tmp_path):
    rec = make_recording()
    write_euroc(rec, tmp_path / "seq")
    data = tmp_path / "seq" / "mav0" / "cam0" / "data"
    (data / f"{rec.frames.t[1]}.png").write_bytes(b"\x89PNG\r\n\x1a\n trunc")
    with pytest.raises(FormatError, match=rf"{rec.frames.t[1]}\.png: cannot decode"):
        read_euroc(tmp_path / "seq", rec.target)
    (data / f"{rec.frames.t[1]}.png").unlink()
    with pytest.raises(FormatError, match=rf"{rec.frames.t[1]}\.png: image file is missing"):
        read_euroc(tmp_path / "seq", rec.target)


def test_not_an_euroc_folder(tmp_path):
    with pytest.raises(FormatError, match="not an EuRoC folder"):
        read_euroc(tmp_path, make_recording().target)


def _imu_csv(tmp_path, rows):
    path = tmp_path / "data.csv"
    path.write_text(IMU_HEADER + "\n" + "".join(r + "\n" for r in rows))
    return path


def _imu_rows(n=20, gyro=0.1, t0=T0_NS, step="5000000"):
    return [f"{t0 + k * int(step)},{gyro},0,0,0,0,9.81" for k in range(n)]


def test_imu_csv_round_trip_exact(tmp_path):
    imu = make_recording().imu
    write_imu_csv(imu, tmp_path / "imu.csv")
    back = read_imu_csv(tmp_path / "imu.csv")
    assert np.array_equal(back.t, imu.t) and np.array_equal(back.gyro, imu.gyro)


def test_imu_csv_unsorted_rows_are_sorted_with_warning(tmp_path):
    rows = _imu_rows()
    rows[5], rows[6] = rows[6], rows[5]
    with pytest.warns(FormatWarning, match="line 8 is earlier than line 7"):
        imu = read_imu_csv(_imu_csv(tmp_path, rows))
    assert np.all(np.diff(imu.t) > 0) and len(imu) == 20


def test_imu_csv_duplicates(tmp_path):
    rows = _imu_rows()
    with pytest.warns(FormatWarning, match="1 duplicated rows"):
        assert len(read_imu_csv(_imu_csv(tmp_path, [*rows[:5], rows[4], *rows[5:]]))) == 20
    conflicting = rows[4].replace(",0.1,", ",0.2,")
    with pytest.raises(CsvFormatError, match="lines 6 and 7 share timestamp"):
        read_imu_csv(_imu_csv(tmp_path, [*rows[:5], conflicting, *rows[5:]]))


def test_imu_csv_seconds_are_converted_exactly(tmp_path):
    rows = [f"1403636579.{763555584 + k * 5000000:09d},0.1,0,0,0,0,9.81" for k in range(20)]
    with pytest.warns(FormatWarning, match="decimal seconds"):
        imu = read_imu_csv(_imu_csv(tmp_path, rows))
    assert imu.t[0] == 1403636579763555584 and imu.t[-1] - imu.t[0] == 19 * 5_000_000


def test_imu_csv_implausible_units(tmp_path):
    with pytest.raises(CsvFormatError, match="look like seconds"):
        read_imu_csv(_imu_csv(tmp_path, _imu_rows(t0=1403636579, step="1")))
    with pytest.raises(UnitError, match="gyro_unit='deg/s'") as err:
        read_imu_csv(_imu_csv(tmp_path, _imu_rows(gyro=120.0)))
    assert err.value.spelled("--gyro-unit deg/s").endswith("convert to rad/s or pass --gyro-unit deg/s")
    imu = read_imu_csv(_imu_csv(tmp_path, _imu_rows(gyro=120.0)), gyro_unit="deg/s")
    assert imu.gyro[0, 0] == pytest.approx(120.0 * np.pi / 180)
    with pytest.raises(FormatError, match="beyond any MEMS gyro's range even in deg/s"):
        read_imu_csv(_imu_csv(tmp_path, _imu_rows(gyro=3000.0)), gyro_unit="deg/s")
    # rad/s data declared as deg/s: 2 rad/s is a calibration motion, 2 deg/s is not
    with pytest.raises(UnitError, match=r"peaks at 2 deg/s, too slow .* look like rad/s; pass gyro_unit='rad/s'"):
        read_imu_csv(_imu_csv(tmp_path, _imu_rows(gyro=2.0)), gyro_unit="deg/s")
    g_rows = [r.replace(",9.81", ",1.0") for r in _imu_rows()]
    with pytest.raises(UnitError, match="accel_unit='g'"):
        read_imu_csv(_imu_csv(tmp_path, g_rows))
    with pytest.raises(UnitError, match=r"96.2 m/s\^2 \(read as g\).*look like m/s\^2: pass accel_unit='m/s\^2'"):
        read_imu_csv(_imu_csv(tmp_path, _imu_rows()), accel_unit="g")


def test_imu_csv_malformed_lines(tmp_path):
    rows = _imu_rows()
    rows[3] = rows[3].replace("0.1", "abc")
    with pytest.raises(CsvFormatError, match=r"data\.csv, line 5: could not convert"):
        read_imu_csv(_imu_csv(tmp_path, rows))
    with pytest.raises(CsvFormatError, match="line 3: expected 7 comma-separated fields, got 4"):
        read_imu_csv(_imu_csv(tmp_path, [_imu_rows()[0], "1,2,3,4"]))


def test_corner_csv_round_trip_keeps_empty_frames(tmp_path):
    rec = make_recording()
    write_corners_csv(rec.frames, tmp_path / "corners.csv")
    back = read_corners_csv(tmp_path / "corners.csv", rec.target)
    assert_frames_equal(back, rec.frames, images=False)
    assert back.num_detections[2] == 0


def test_corner_csv_bad_rows(tmp_path):
    target = make_recording().target
    path = tmp_path / "corners.csv"
    header = "#timestamp [ns],point_id,u [px],v [px]\n"
    path.write_text(header + f"{T0_NS},0,1.5,2.5\n{T0_NS},20,1.5,2.5\n")
    with pytest.raises(CsvFormatError, match=r"line 3: point id 20 is outside the target's ids 0\.\.19"):
        read_corners_csv(path, target)
    path.write_text(header + f"{T0_NS},4,1.5,2.5\n{T0_NS},4,3.5,2.5\n")
    with pytest.raises(CsvFormatError, match="lines 2 and 3 list point 4 twice"):
        read_corners_csv(path, target)
    path.write_text(header + f"{T0_NS},x,1.5,2.5\n")
    with pytest.raises(CsvFormatError, match="line 2: point id 'x' is not an integer"):
        read_corners_csv(path, target)


@pytest.mark.parametrize("content", ["", IMU_HEADER + "\n"])
def test_csv_files_without_rows_are_named_and_an_euroc_imu_without_samples_is_no_imu(tmp_path, content):
    rec = make_recording()
    write_euroc(rec, tmp_path / "seq")
    imu_csv = tmp_path / "seq" / "mav0" / "imu0" / "data.csv"
    imu_csv.write_text(content)
    with pytest.raises(
        CsvFormatError, match=f"{imu_csv} holds no IMU samples \\(the file is empty or has only a header"
    ):
        read_imu_csv(imu_csv)
    corners_csv = tmp_path / "corners.csv"
    corners_csv.write_text(content and "#timestamp [ns],point_id,u [px],v [px]\n")
    with pytest.raises(CsvFormatError, match=f"{corners_csv} holds no corner rows"):
        read_corners_csv(corners_csv, rec.target)
    with pytest.warns(FormatWarning, match="holds no samples: the recording has no IMU data"):
        back = read_euroc(tmp_path / "seq", rec.target)
    assert len(back.imu) == 0 and len(back.frames) == len(rec.frames)
