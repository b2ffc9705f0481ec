"""open_recording recognises every source; image folders: natural order, timestamps from the rate, bad images;
open_imu reads IMU-only recordings."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from imu_streams import static_stream
from test_io_samples import assert_frames_equal, make_recording

from vical.data import ImuSamples, Target
from vical.io import (
    FormatError,
    FormatWarning,
    detect_source,
    open_imu,
    open_recording,
    read_image_folder,
    read_imu_csv,
    save_recording,
    write_bag,
    write_corners_csv,
    write_euroc,
    write_imu_csv,
)
from vical.io.errors import UnitError


def _first_pixel_detector(image):
    return np.array([[float(image[0, 0]), 0.0]]), np.array([0])


def test_open_recording_sniffs_every_source(tmp_path):
    rec = make_recording()
    save_recording(rec, tmp_path / "rec")
    write_euroc(rec, tmp_path / "euroc")
    write_bag(rec, tmp_path / "data.bag")
    write_corners_csv(rec.frames, tmp_path / "corners.csv")
    write_imu_csv(rec.imu, tmp_path / "imu.csv")
    (tmp_path / "images").mkdir()
    for k, image in enumerate(rec.frames.images):
        cv2.imwrite(str(tmp_path / "images" / f"frame{k}.png"), image)

    kinds = {n: detect_source(tmp_path / n) for n in ("rec", "euroc", "data.bag", "corners.csv", "images")}
    assert kinds == {
        "rec": "recording",
        "euroc": "euroc",
        "data.bag": "bag",
        "corners.csv": "corners_csv",
        "images": "image_folder",
    }
    assert_frames_equal(open_recording(tmp_path / "rec").frames, rec.frames)
    assert_frames_equal(open_recording(tmp_path / "euroc", rec.target, keep_images=True).frames, rec.frames)
    from_csv = open_recording(tmp_path / "corners.csv", rec.target, imu_csv=tmp_path / "imu.csv")
    assert_frames_equal(from_csv.frames, rec.frames, images=False)
    assert np.array_equal(from_csv.imu.gyro, rec.imu.gyro)
    from_bag = open_recording(tmp_path / "data.bag", rec.target, detector=_first_pixel_detector)
    assert [c[0, 0] for c in from_bag.frames.corners] == [float(im[0, 0]) for im in rec.frames.images]
    folder = open_recording(tmp_path / "images", rec.target, detector=_first_pixel_detector, rate_hz=20.0)
    assert len(folder.imu) == 0 and np.array_equal(folder.frames.t, np.arange(6) * 50_000_000)


def test_open_recording_needs_a_target_and_a_known_source(tmp_path):
    rec = make_recording()
    write_bag(rec, tmp_path / "data.bag")
    with pytest.raises(FormatError, match="is a bag: give the calibration target"):
        open_recording(tmp_path / "data.bag")
    save_recording(rec, tmp_path / "rec")
    with pytest.raises(FormatError, match="was recorded with target"):
        open_recording(tmp_path / "rec", Target.checkerboard(6, 7, 0.07))
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(FormatError, match=r"notes\.txt is none of"):
        open_recording(tmp_path / "notes.txt", rec.target)
    with pytest.raises(FormatError, match="does not exist"):
        open_recording(tmp_path / "nothing", rec.target)


def test_image_folder_natural_order_colour_and_bad_files(tmp_path):
    rng = np.random.default_rng(5)
    grey = rng.integers(0, 256, (3, 24, 32), dtype=np.uint8)
    for k, name in enumerate(["img2.png", "img10.png", "img1.jpg"]):
        image = cv2.cvtColor(grey[k], cv2.COLOR_GRAY2BGR) if name == "img10.png" else grey[k]
        cv2.imwrite(str(tmp_path / name), image, [cv2.IMWRITE_JPEG_QUALITY, 100])
    (tmp_path / "readme.md").write_text("board pictures")
    target = Target.checkerboard(4, 5, 0.05)
    with pytest.warns(FormatWarning, match="1 files that are not images"):
        frames = read_image_folder(tmp_path, target, rate_hz=4.0, t0_ns=7)
    assert np.array_equal(frames.t, [7, 250_000_007, 500_000_007])
    assert np.array_equal(frames.images[1], grey[0]) and np.array_equal(frames.images[2], grey[1])
    (tmp_path / "readme.md").unlink()
    cv2.imwrite(str(tmp_path / "img3.png"), np.zeros((10, 10), np.uint8))
    with pytest.raises(FormatError, match=r"img3\.png: image is 10 x 10 px"):
        read_image_folder(tmp_path, target)
    (tmp_path / "img3.png").write_bytes(b"broken")
    with pytest.raises(FormatError, match=r"img3\.png: cannot decode"):
        read_image_folder(tmp_path, target)


def test_open_imu_reads_a_resting_gyro_logged_in_deg_per_s(tmp_path):
    imu = static_stream(60, 0)
    write_imu_csv(ImuSamples(imu.t, np.degrees(imu.gyro), imu.accel), tmp_path / "static" / "imu0" / "data.csv")
    read = open_imu(tmp_path / "static", gyro_unit="deg/s")
    np.testing.assert_allclose(read.gyro, imu.gyro, rtol=1e-12)
    np.testing.assert_array_equal(read.t, imu.t)
    # The calibration readers' unit check expects a calibration motion: it takes this gyro for rad/s.
    with pytest.raises(UnitError, match="the data look like rad/s"):
        read_imu_csv(tmp_path / "static" / "imu0" / "data.csv", gyro_unit="deg/s")
    with pytest.raises(FormatError, match="holds no IMU CSV"):
        open_imu(tmp_path)
