"""Aprilgrid detection on images warped from the printed grid with a known homography."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vical.calib.detection.aprilgrid import detect_aprilgrid
from vical.calib.errors import CalibrationError
from vical.data import Target

PX_PER_BIT = 10
SUPERSAMPLE = 4


def _pattern_coords(target: Target, height: int) -> np.ndarray:
    """(N, 2) pattern-image pixel coordinates (column, row) of the target points (see ``aprilgrid_image``)."""
    s = target.row_spacing / (10 * PX_PER_BIT)
    margin = 2 * round(target.tag_spacing * 10 * PX_PER_BIT)
    p = target.points
    return np.stack([p[:, 0] / s + margin - 0.5, height - p[:, 1] / s - margin - 0.5], axis=1)


def _view(target: Target, H: np.ndarray, size=(640, 480)) -> tuple[np.ndarray, np.ndarray]:
    """Grey image of the grid seen through homography ``H`` (pattern px -> image px), anti-aliased by
    supersampling, and the exact image positions (N, 2) of every target point."""
    pattern = target.aprilgrid_image(PX_PER_BIT)
    # Output pixel x covers supersampled pixels [k x, k x + k): its centre is at k x + (k - 1) / 2.
    k = SUPERSAMPLE
    S = np.array([[k, 0, (k - 1) / 2], [0, k, (k - 1) / 2], [0, 0, 1]])
    big = cv2.warpPerspective(pattern, S @ H, (size[0] * k, size[1] * k), flags=cv2.INTER_LINEAR, borderValue=128)
    image = cv2.resize(big, size, interpolation=cv2.INTER_AREA)
    truth = cv2.perspectiveTransform(_pattern_coords(target, pattern.shape[0]).reshape(-1, 1, 2), H).reshape(-1, 2)
    return image, truth


def _homography(target: Target, quad_image: np.ndarray) -> np.ndarray:
    """Homography mapping the pattern image's corners to the image quad (4, 2) (TL, TR, BR, BL)."""
    h, w = target.aprilgrid_image(PX_PER_BIT).shape
    src = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float32) - 0.5
    return cv2.getPerspectiveTransform(src, np.asarray(quad_image, dtype=np.float32))


@pytest.fixture(scope="module")
def target():
    return Target.aprilgrid(tag_rows=3, tag_cols=4, tag_size=0.05, tag_spacing=0.3)


def test_full_oblique_view_matches_the_homography(target):
    H = _homography(target, [[90, 70], [560, 40], [600, 430], [60, 400]])
    image, truth = _view(target, H)
    corners, ids = detect_aprilgrid(image, target)
    assert np.array_equal(ids, np.arange(target.num_points))
    err = np.linalg.norm(corners - truth[ids], axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.15 and err.max() < 0.4


def test_upside_down_view_keeps_kalibr_ids(target):
    # Pattern turned by a half-turn in the image: ids must follow the tags, not the image axes.
    H = _homography(target, [[580, 420], [70, 440], [50, 60], [600, 50]])
    image, truth = _view(target, H)
    corners, ids = detect_aprilgrid(image, target)
    assert len(ids) == target.num_points
    assert np.sqrt(np.mean(np.sum((corners - truth[ids]) ** 2, axis=1))) < 0.15
    # Point 0 (board origin, bottom-left as printed) is now near the image's top-right.
    assert corners[0, 0] > 450 and corners[0, 1] < 120


def test_partial_view_gives_the_visible_tags_only(target):
    # The grid hangs over the right and bottom edges: only tags fully inside (with margin) count.
    H = _homography(target, [[250, 200], [900, 190], [920, 700], [240, 690]])
    image, truth = _view(target, H)
    corners, ids = detect_aprilgrid(image, target)
    inside = np.all((truth >= 4) & (truth <= [635, 475]), axis=1)
    tags_inside = np.all(inside[target.tag_corner_ids(np.arange(target.num_tags))], axis=1)
    expected = np.sort(target.tag_corner_ids(np.flatnonzero(tags_inside)).reshape(-1))
    assert 0 < len(expected) < target.num_points
    assert np.array_equal(ids, expected)
    assert np.sqrt(np.mean(np.sum((corners - truth[ids]) ** 2, axis=1))) < 0.15


def test_stray_duplicate_tag_is_dropped(target):
    H = _homography(target, [[90, 70], [460, 60], [470, 340], [80, 330]])
    image, _ = _view(target, H)
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    stray = cv2.aruco.generateImageMarker(dictionary, 5, 60, borderBits=2)
    image[380:440, 540:600] = stray  # a second tag 5, on white paper
    image[370:380, 530:610] = image[440:450, 530:610] = 255
    _, ids = detect_aprilgrid(image, target)
    assert not np.any(np.isin(target.tag_corner_ids([5]), ids))
    assert len(ids) == target.num_points - 4


def test_nothing_to_see_and_wrong_inputs(target):
    corners, ids = detect_aprilgrid(np.full((48, 64), 200, np.uint8), target)
    assert corners.shape == (0, 2) and ids.shape == (0,)
    with pytest.raises(CalibrationError, match="aprilgrid target"):
        detect_aprilgrid(np.zeros((48, 64), np.uint8), Target.checkerboard())
    with pytest.raises(CalibrationError, match="uint8 grey"):
        detect_aprilgrid(np.zeros((48, 64, 3), np.uint8), target)
