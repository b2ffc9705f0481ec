"""The image-coverage warning: a board seen in one part of the image leaves the lens model extrapolated elsewhere."""

import numpy as np

from vical.calib.solve.checks import image_coverage_warnings
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.observations import FrameObservation, collect_observations
from vical.calib.solve.pipeline import calibrate_joint
from vical.calib.synthetic import make_recording
from vical.data import CameraFrames, ImuNoise

SIZE = (640, 480)


def observation(uv: np.ndarray) -> FrameObservation:
    ids = np.arange(len(uv))
    return FrameObservation(0, 0, uv, ids, np.zeros((len(uv), 3)))


def test_corners_in_one_quarter_name_the_regions_no_corner_reached():
    rng = np.random.default_rng(0)
    quarter = [observation(rng.uniform([0, 0], [320, 240], (40, 2))) for _ in range(5)]
    (warning,) = image_coverage_warnings(quarter, SIZE)
    assert "covered only 2" in warning  # at most a quarter of the image
    for region in ("right edge", "bottom edge", "bottom-right corner", "top-right corner", "bottom-left corner"):
        assert region in warning
    assert "top-left corner" not in warning
    everywhere = [observation(rng.uniform([0, 0], SIZE, (40, 2))) for _ in range(5)]
    assert image_coverage_warnings(everywhere, SIZE) == []


def test_regions_reached_by_a_few_stray_corners_and_empty_borders_are_named():
    rng = np.random.default_rng(1)
    board = [observation(rng.uniform([0, 0], [400, 300], (400, 2))) for _ in range(5)]  # 39 % of the image
    stray = observation(np.array([[430.0, 150.0], [435.0, 180.0], [440.0, 200.0]]))  # 3 of 2003 in the right edge
    (warning,) = image_coverage_warnings([*board, stray], SIZE)
    assert "covered only 4" in warning
    sparse = warning.split("under 1% of the corners in the ")[1].split(";")[0]
    assert sparse.split(", ") == [
        "top-right corner", "right edge", "bottom-left corner", "bottom edge", "bottom-right corner"
    ]  # fmt: skip
    assert "no corner in the outer 10% along the bottom and right borders" in warning  # v > 432, u > 576 px: none
    assert "()" not in warning


def in_quadrant(frames: CameraFrames, width: int, height: int) -> CameraFrames:
    """The frames' detections restricted to the top-left quarter of the image (the rest of the board unseen)."""
    keep = [(c[:, 0] < width / 2) & (c[:, 1] < height / 2) for c in frames.corners]
    corners = [c[k] for c, k in zip(frames.corners, keep, strict=True)]
    return CameraFrames(frames.t, corners, [i[k] for i, k in zip(frames.ids, keep, strict=True)])


def test_the_intrinsic_and_joint_calibrations_warn_when_the_board_covered_a_quarter_of_the_image():
    rec = make_recording(duration=12.0, imu_noise=ImuNoise(), pixel_sigma=0.3, seed=4)
    camera = rec.truth.camera
    size = (camera.width, camera.height)
    full = calibrate_intrinsics(rec.frames, rec.target, "radtan", size, pixel_sigma=0.3)
    assert not any("covered only" in w for w in full.warnings), image_coverage_warnings(
        collect_observations(rec.frames, rec.target), size
    )
    quarter = in_quadrant(rec.frames, *size)
    part = calibrate_intrinsics(quarter, rec.target, "radtan", size, pixel_sigma=0.3)
    assert any("covered only" in w and "bottom-right corner" in w for w in part.warnings)
    joint = calibrate_joint(quarter, rec.imu, rec.target, "radtan", size, rec.truth.imu_noise)
    assert any("covered only" in w for w in joint.warnings)
