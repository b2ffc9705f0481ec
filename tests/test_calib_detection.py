"""Checkerboard detection: corners and Kalibr ids on images warped from the printed pattern."""

import cv2
import numpy as np
import pytest

from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.data import Target

SUPERSAMPLE = 4  # render at 4x and area-average down, so edges are anti-aliased like a real lens


def _board_to_pattern_px(target: Target, px_per_square: int, border_squares: float) -> np.ndarray:
    """(3, 3) affine map from board (x, y) [m] to pattern-image pixels (u = column, v = row)."""
    s_r, s_c = px_per_square / target.row_spacing, px_per_square / target.col_spacing
    off = (1.0 + border_squares) * px_per_square - 0.5
    return np.array([[0.0, s_c, off], [s_r, 0.0, off], [0.0, 0.0, 1.0]])


def _render(target: Target, H_img_board: np.ndarray, size=(640, 480)) -> np.ndarray:
    """Grey image of the board seen through the homography ``H_img_board`` (board metres -> px)."""
    pps, border = 80, 1.0
    pattern = target.pattern_image(px_per_square=pps, border_squares=border)
    k = SUPERSAMPLE
    S = np.array([[k, 0.0, (k - 1) / 2.0], [0.0, k, (k - 1) / 2.0], [0.0, 0.0, 1.0]])  # output px -> super px
    H = S @ H_img_board @ np.linalg.inv(_board_to_pattern_px(target, pps, border))
    big = cv2.warpPerspective(pattern, H, (size[0] * k, size[1] * k), flags=cv2.INTER_LINEAR, borderValue=128)
    return cv2.resize(big, size, interpolation=cv2.INTER_AREA)


def _homography(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Board-plane homography of a pinhole camera: ``K [r1 r2 t]``."""
    return K @ np.column_stack([R[:, 0], R[:, 1], t])


def _project(H: np.ndarray, target: Target) -> np.ndarray:
    p = np.column_stack([target.points[:, :2], np.ones(target.num_points)]) @ H.T
    return p[:, :2] / p[:, 2:]


K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
TARGET = Target.checkerboard(rows=6, cols=7, square=0.07)


def _view(roll_deg: float, tilt_deg: float = 20.0, distance: float = 1.0) -> np.ndarray:
    """Homography of the board facing the camera (rows down, cols right), rolled about the optical axis."""
    rz, tx = np.deg2rad(roll_deg), np.deg2rad(tilt_deg)
    R_facing = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # board x -> down, y -> right
    Rz = np.array([[np.cos(rz), -np.sin(rz), 0], [np.sin(rz), np.cos(rz), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, np.cos(tx), -np.sin(tx)], [0, np.sin(tx), np.cos(tx)]])
    R = Rz @ Rx @ R_facing
    t = np.array([0.0, 0.0, distance]) - R @ TARGET.center
    return _homography(K, R, t)


@pytest.mark.parametrize("roll_deg", [0.0, 30.0, 90.0, 180.0, -150.0])
def test_detects_corners_with_kalibr_ids(roll_deg):
    H = _view(roll_deg)
    corners, ids = detect_checkerboard(_render(TARGET, H), TARGET)
    assert ids.dtype == np.int64 and corners.dtype == np.float64
    assert np.array_equal(ids, np.arange(TARGET.num_points))
    err = np.linalg.norm(corners - _project(H, TARGET)[ids], axis=1)
    assert err.max() < 0.15, f"corner error {err.max():.3f} px"


def test_board_seen_half_turned_keeps_id_zero_on_the_black_corner():
    upright = detect_checkerboard(_render(TARGET, _view(0.0)), TARGET)[0]
    turned = detect_checkerboard(_render(TARGET, _view(180.0)), TARGET)[0]
    # Half a turn about the image centre moves id 0 to the opposite side of the image.
    centre = np.array([319.5, 239.5])
    assert np.allclose(turned[0] - centre, -(upright[0] - centre), atol=0.3)


@pytest.mark.parametrize("distance", [3.5, 4.5])
def test_a_far_board_with_squares_of_about_ten_pixels_is_found(distance):
    # OpenCV's fast check erodes such squares away (it found nothing from 3 m on, squares 12 px).
    H = _view(20.0, distance=distance)
    truth = _project(H, TARGET)
    square_px = np.linalg.norm(truth[1] - truth[0])
    corners, ids = detect_checkerboard(_render(TARGET, H), TARGET)
    assert 7.5 < square_px < 10.5 and np.array_equal(ids, np.arange(TARGET.num_points))
    err = np.linalg.norm(corners - truth[ids], axis=1)
    assert err.max() < 0.15, f"corner error {err.max():.3f} px"


def test_partial_board_gives_empty_arrays():
    image = _render(TARGET, _view(0.0, distance=0.3))  # board larger than the image
    corners, ids = detect_checkerboard(image, TARGET)
    assert corners.shape == (0, 2) and ids.shape == (0,)
    blank = np.full((480, 640), 200, np.uint8)
    assert detect_checkerboard(blank, TARGET)[1].size == 0


def test_rejects_colour_images():
    with pytest.raises(CalibrationError, match="uint8 grey"):
        detect_checkerboard(np.zeros((480, 640, 3), np.uint8), TARGET)
