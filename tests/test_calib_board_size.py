"""A board given with the wrong corner count: the hint names the size the images show, vical-calibrate the key to set.

Images of a board with 6 x 8 inner corners (7 x 9 squares) are rendered from the printed pattern
(``test_calib_detection``'s renderer); OpenCV's detector finds no 6 x 7 or 7 x 8 board in them.
"""

import cv2
import numpy as np
import pytest
from test_calib_detection import K, _homography, _render

from vical.apps.calibrate import main
from vical.calib.detection.board_size import board_size_hint
from vical.calib.detection.checkerboard import detect_checkerboard
from vical.data import Target
from vical.io.kalibr import write_target_yaml

BOARD = Target.checkerboard(rows=6, cols=8, square=0.05)
VIEWS = [(0, 20, 0.8), (30, -25, 0.9), (-20, 35, 0.7), (60, 10, 1.0), (170, 30, 0.8), (-100, -20, 0.9)]


def _view(target: Target, roll_deg: float, tilt_deg: float, distance: float) -> np.ndarray:
    """Homography of the board facing the camera, rolled about the optical axis and tilted."""
    rz, tx = np.deg2rad(roll_deg), np.deg2rad(tilt_deg)
    R_facing = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    Rz = np.array([[np.cos(rz), -np.sin(rz), 0], [np.sin(rz), np.cos(rz), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, np.cos(tx), -np.sin(tx)], [0, np.sin(tx), np.cos(tx)]])
    R = Rz @ Rx @ R_facing
    return _homography(K, R, np.array([0.0, 0.0, distance]) - R @ target.center)


@pytest.fixture(scope="module")
def images():
    return [_render(BOARD, _view(BOARD, *v)) for v in VIEWS]


@pytest.mark.parametrize("rows, cols", [(6, 7), (7, 8), (5, 7), (7, 9)])
def test_a_wrong_corner_count_gets_the_size_the_images_show(images, rows, cols):
    given = Target.checkerboard(rows=rows, cols=cols, square=0.05)
    assert all(len(detect_checkerboard(im, given)[0]) == 0 for im in images)  # every view is lost
    hint = board_size_hint(images, given)
    assert (hint.rows, hint.cols) == (6, 8) and (hint.found, hint.given_found, hint.sampled) == (6, 0, 6)
    assert "set targetRows: 6 and targetCols: 8 in the target YAML" in hint.message()


def test_the_right_size_and_aprilgrids_get_no_hint(images):
    assert board_size_hint(images, BOARD) is None
    assert board_size_hint(images, Target.aprilgrid()) is None
    assert board_size_hint([np.full((480, 640), 128, np.uint8)] * 3, Target.checkerboard(6, 7, 0.05)) is None


def test_vical_calibrate_names_the_size_and_the_target_file(images, tmp_path, capsys):
    folder = tmp_path / "images"
    folder.mkdir()
    for k, image in enumerate(images):
        cv2.imwrite(str(folder / f"img{k}.png"), image)
    wrong = tmp_path / "target.yaml"
    write_target_yaml(wrong, Target.checkerboard(rows=6, cols=7, square=0.05))
    assert main([str(folder), "--target", str(wrong), "--task", "intrinsic", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert (
        "vical-calibrate: error: the board was found in 0 of 6 images: the images look like a checkerboard of 6 x 8 "
        "inner corners (rows x cols), not the 6 x 7 given" in err
    )
    assert f"set targetRows: 6 and targetCols: 8 in --target {wrong}" in err


def test_a_sub_grid_found_in_some_images_calibrates_with_the_hint_as_a_warning(images, tmp_path, capsys):
    """Three views show only 6 x 7 of the board's corners (its last column covered), six the whole 6 x 8 board:
    the three calibrate, and the warning says that the six others were lost to the corner count."""
    given = Target.checkerboard(rows=6, cols=7, square=0.05)
    part = [_render(given, _view(given, *v)) for v in [(10, 30, 0.8), (-30, -30, 0.9), (80, 25, 0.75)]]
    folder = tmp_path / "images"
    folder.mkdir()
    for k, image in enumerate(images + part):
        cv2.imwrite(str(folder / f"img{k}.png"), image)
    target = tmp_path / "target.yaml"
    write_target_yaml(target, given)
    out = tmp_path / "out"
    assert main([str(folder), "--target", str(target), "--task", "intrinsic", "--out", str(out), "--no-report"]) == 0
    printed = capsys.readouterr().out
    summary = "frames: 9 frames, the board detected in 3, 3 used (126 of 126 corners); not used: 6 no board detected"
    assert summary in printed
    warning = next(line for line in printed.splitlines() if line.startswith("warning: the images look like"))
    assert "6 x 8 was found in 5 of 8 sampled images, 6 x 7 in 3" in warning
    text = (out / "results.txt").read_text()
    assert "no board detected (6): img0.png, img1.png, img2.png, img3.png, img4.png, img5.png" in text
    assert "the images look like a checkerboard of 6 x 8" in text
