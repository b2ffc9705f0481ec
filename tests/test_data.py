"""Shared data containers: validation, target geometry in Kalibr's numbering."""

import numpy as np
import pytest

from vical.data import CameraFrames, DataError, ImuSamples, PathProfile, SensorTruth, Target, TargetError, seconds_since
from vical.data.target import KALIBR_TAG36H11_ID0, kalibr_tag_bits
from vical.geometry import CameraModel


def test_checkerboard_points_follow_kalibr_numbering():
    t = Target.checkerboard(rows=6, cols=7, square=0.07)
    p = t.points
    assert p.shape == (42, 3)
    # id = r * cols + c at (r * row_spacing, c * col_spacing, 0)
    assert np.allclose(p[7 * 2 + 3], [0.14, 0.21, 0.0])
    assert np.allclose(t.center, [0.175, 0.21, 0.0])
    assert np.allclose(t.outline[2], p[-1])


def test_target_rejects_bad_geometry():
    with pytest.raises(TargetError, match="spacing"):
        Target.checkerboard(6, 7, -0.07)
    with pytest.raises(TargetError, match="2 x 2"):
        Target.checkerboard(1, 7, 0.07)


def test_imu_samples_validate_time_and_shape():
    t = np.arange(5, dtype=np.int64) * 5_000_000
    ImuSamples(t, np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(DataError, match="strictly increasing"):
        ImuSamples(t[::-1], np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(DataError, match="integer nanoseconds"):
        ImuSamples(t.astype(float), np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(DataError, match="shape"):
        ImuSamples(t, np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(DataError, match="NaN"):
        ImuSamples(t, np.full((5, 3), np.nan), np.zeros((5, 3)))


def test_camera_frames_ragged_detections():
    f = CameraFrames(np.array([0, 100], dtype=np.int64), [np.zeros((3, 2)), np.zeros((0, 2))], [[0, 1, 2], []])
    assert f.num_detections.tolist() == [3, 0]
    assert len(f.select(f.num_detections > 0)) == 1
    with pytest.raises(DataError, match="ids"):
        CameraFrames(np.array([0], dtype=np.int64), [np.zeros((3, 2))], [[0, 1]])


def test_seconds_since_keeps_nanoseconds_on_epoch_times():
    t0 = 1_700_000_000_123_456_789
    assert seconds_since(np.array([t0 + 1]), t0)[0] == pytest.approx(1e-9, abs=1e-18)


def test_sensor_truth_dict_roundtrip_and_rotation_check():
    cam = CameraModel.from_hfov(1.0, dist=[0.01, -0.02, 0, 0])
    truth = SensorTruth(cam, np.eye(4), time_offset=0.0123)
    back = SensorTruth.from_dict(truth.to_dict())
    assert back.camera == cam and back.time_offset == 0.0123
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(DataError, match="rotation"):
        SensorTruth(cam, bad)


def test_pattern_image_colours_follow_square_convention():
    t = Target.checkerboard(rows=6, cols=7, square=0.07)
    img = t.pattern_image(px_per_square=10, border_squares=1.0)
    assert img.shape == ((6 + 1 + 2) * 10, (7 + 1 + 2) * 10)
    assert img[0, 0] == 255  # border
    assert img[15, 15] == 0  # square (0, 0), diagonally outside point id 0, is black
    assert img[15, 25] == 255  # square (0, 1)
    assert img[25, 25] == 0  # square (1, 1)
    # The board is not half-turn symmetric: the last square (rows, cols) = (6, 7) is white.
    assert img[-15, -15] == 255


def test_aprilgrid_points_follow_kalibr_numbering():
    # Kalibr's GridCalibrationTargetAprilgrid, 2 x 2 tags: ids 0-1-5-4 around tag 0, 10-11-15-14 around tag 3,
    # x along the columns, y along the rows, pitch (1 + tagSpacing) tagSize.
    t = Target.aprilgrid(tag_rows=2, tag_cols=2, tag_size=0.1, tag_spacing=0.3)
    assert t.grid_shape == (4, 4) and t.num_points == 16 and t.num_tags == 4
    assert np.array_equal(t.tag_corner_ids([0, 3]), [[0, 1, 5, 4], [10, 11, 15, 14]])
    p = t.points
    assert np.allclose(p[[0, 1, 2, 4, 15]], [[0, 0, 0], [0.1, 0, 0], [0.13, 0, 0], [0, 0.1, 0], [0.23, 0.23, 0]])
    assert np.allclose(t.center, [0.115, 0.115, 0.0])
    assert np.array_equal(t.outline, p[[0, 3, 15, 12]])
    with pytest.raises(TargetError, match="tag ids"):
        t.tag_corner_ids([4])
    with pytest.raises(TargetError, match="tag_spacing > 0"):
        Target("aprilgrid", 2, 2, 0.1, 0.1, 0.0)


def test_aprilgrid_image_layout():
    t = Target.aprilgrid(tag_rows=2, tag_cols=3, tag_size=0.088, tag_spacing=0.3)
    image = t.aprilgrid_image(px_per_bit=4)  # 40 px tags, 12 px gaps, 24 px margin
    assert image.shape == (2 * 24 + 2 * 52 - 12, 2 * 24 + 3 * 52 - 12)
    h = image.shape[0]
    # Tag 0 sits bottom-left with its 2-bit (8 px) black border; corner squares fill the gap crossings.
    assert np.all(image[h - 24 - 40 : h - 24, 24 : 24 + 8] == 0)
    assert np.all(image[h - 24 : h - 12, 12:24] == 0)
    assert np.all(image[h - 12 :, :] == 255) and np.all(image[:, :12] == 255)
    with pytest.raises(TargetError, match="whole number of pixels"):
        Target.aprilgrid(2, 2, 0.1, 0.33).aprilgrid_image(px_per_bit=1)


def test_aprilgrid_image_prints_tags_as_kalibr_does():
    """Data bits of tags 0-3 equal Kalibr's print of its tag36h11 codes (kalibr_create_target_pdf).

    Tag 0's code fixes OpenCV's turn (``opencv_tag_turns``); tags 1-3 check it independently.
    """
    kalibr_codes = [KALIBR_TAG36H11_ID0, 0xD97F18B49, 0xDD280910E, 0xE479E9C98]
    t = Target.aprilgrid(tag_rows=2, tag_cols=2, tag_size=0.1, tag_spacing=0.3)
    image = t.aprilgrid_image(px_per_bit=10)  # 100 px tags, 30 px gaps, 60 px margin
    h = image.shape[0]
    for k, code in enumerate(kalibr_codes):
        top, left = h - 60 - (k // 2) * 130 - 100, 60 + (k % 2) * 130
        cells = image[top + 25 : top + 80 : 10, left + 25 : left + 80 : 10] < 128  # 6 x 6 data cell centres
        assert np.array_equal(cells, kalibr_tag_bits(code)), k
    assert not np.array_equal(kalibr_tag_bits(kalibr_codes[1]), np.rot90(kalibr_tag_bits(kalibr_codes[1]), 2))


def test_path_profile_validates_and_answers_time_and_length():
    t = np.arange(5, dtype=np.int64) * 10
    profile = PathProfile(t, [0.0, 0.1, 0.1, 0.4, 1.0])
    assert profile.time_at(0.1) == 10 and profile.time_at(0.35) == 30 and profile.time_at(5.0) == 40
    assert profile.length_at(25) == 0.1 and profile.length_at(-1) == 0.0 and profile.length_at(99) == 1.0
    with pytest.raises(DataError, match="non-decreasing"):
        PathProfile(t, [0.0, 0.2, 0.1, 0.4, 1.0])
    with pytest.raises(DataError, match="strictly increasing"):
        PathProfile(np.array([0, 10, 10, 20, 30]), np.zeros(5))


def test_a_recording_until_a_time_or_a_path_keeps_exactly_what_came_before():
    from test_io_samples import make_recording

    rec = make_recording()
    profile = rec.path_profile
    budget = float(profile.length[30])
    cut = rec.until_path(budget)
    t_cut = int(profile.t[np.searchsorted(profile.length, budget)])
    assert cut.imu.t[-1] == t_cut and np.all(cut.frames.t <= t_cut) and np.all(cut.trajectory.t <= t_cut)
    assert len(cut.imu) == 31 and len(cut.frames) == np.sum(rec.frames.t <= t_cut)
    assert cut.path_length == budget and cut.path_profile.t[-1] == t_cut
    assert cut.duration == pytest.approx(min(rec.duration, (t_cut - rec.t0) / 1e9))
    assert cut.truth is rec.truth and cut.target == rec.target
    assert rec.until_path(10 * float(profile.length[-1])) is rec  # never that far: the whole recording
    with pytest.raises(DataError, match="no path profile"):
        make_recording(with_truth=False).until_path(1.0)
