"""Coverage state: board features from detections vs analytic projection, and the range bookkeeping."""

import numpy as np
import pytest

from vical.data import Target
from vical.env.coverage import SKEW_HIGH, SKEW_LOW, Coverage, ViewFeatures, view_features
from vical.env.settings import Thresholds, Workspace
from vical.geometry import CameraModel, euler_to_matrix

W, H = 640, 480
TARGET = Target.checkerboard()
CAMERA = CameraModel.from_hfov(1.0, W, H)  # pinhole: a homography maps the board plane exactly (cv2 fits it to ~1e-7)


def project_board(R: np.ndarray, centre_cam: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixels of board points (N, 3) for a board rotated by R with its centre at ``centre_cam``."""
    p_cam = (points - TARGET.center) @ R.T + centre_cam
    uv, in_front = CAMERA.project(p_cam)
    assert in_front.all()
    return uv


def features_of(R, centre_cam, ids=None):
    ids = np.arange(TARGET.num_points) if ids is None else ids
    return view_features(project_board(R, centre_cam, TARGET.points[ids]), ids, TARGET, W, H)


def edge_angle(uv: np.ndarray) -> float:
    e1, e2 = uv[1] - uv[0], uv[3] - uv[0]
    return float(np.arccos(e1 @ e2 / np.linalg.norm(e1) / np.linalg.norm(e2)))


def test_fronto_parallel_board_features_match_the_projection():
    f = features_of(np.eye(3), np.array([0.1, -0.05, 1.5]))
    centre = project_board(np.eye(3), np.array([0.1, -0.05, 1.5]), TARGET.center[None])[0]
    np.testing.assert_allclose(f.center, centre / [W, H], atol=1e-7)
    width = CAMERA.fx * (TARGET.rows - 1) * TARGET.row_spacing / 1.5
    height = CAMERA.fy * (TARGET.cols - 1) * TARGET.col_spacing / 1.5
    assert f.area == pytest.approx(width * height / (W * H), rel=1e-6)
    assert f.skew == pytest.approx(0.5, abs=1e-7)


@pytest.mark.parametrize("rpy", [(0.5, 0.0, 0.0), (0.0, -0.6, 0.3), (0.4, 0.4, 1.0)])
def test_tilted_board_skew_and_area_match_the_projected_outline(rpy):
    R = euler_to_matrix(np.array(rpy))
    centre = np.array([-0.05, 0.08, 1.2])
    f = features_of(R, centre)
    outline = project_board(R, centre, TARGET.outline)
    expected_skew = (edge_angle(outline) - SKEW_LOW) / (SKEW_HIGH - SKEW_LOW)
    assert f.skew == pytest.approx(np.clip(expected_skew, 0, 1), abs=1e-6)
    assert abs(f.skew - 0.5) > 0.01  # the tilt is visible
    x, y = outline[:, 0], outline[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert f.area == pytest.approx(area / (W * H), rel=1e-6)


def test_partial_view_gives_the_features_of_the_full_view():
    R = euler_to_matrix(np.array([0.3, -0.2, 0.1]))
    centre = np.array([0.0, 0.0, 1.4])
    full = features_of(R, centre)
    part = features_of(R, centre, ids=np.array([8, 9, 10, 15, 16, 17, 22, 23]))
    np.testing.assert_allclose(part.vector, full.vector, atol=1e-6)


def test_too_few_corners_give_no_view():
    assert features_of(np.eye(3), np.array([0, 0, 1.5]), ids=np.array([0, 1, 2])) is None


def make_coverage(novelty=0.1, **thresholds):
    return Coverage(Workspace(), Thresholds(**thresholds), novelty)


def view(u, v, area=0.1, skew=0.5):
    return ViewFeatures(np.array([u, v]), area, skew)


def test_polygon_vertices_follow_the_quadrant_rules_and_only_grow():
    cov = make_coverage(novelty=0.0)
    for u, v in [(0.3, 0.4), (0.45, 0.2), (0.7, 0.45), (0.6, 0.9), (0.2, 0.6), (0.4, 0.3)]:
        cov.add_view(view(u, v))
    # V1 = [min u, min v] in R1, V2 = [max u, min v] in R2, V3 = [max u, max v] in R3, V4 = [min u, max v] in R4.
    np.testing.assert_allclose(cov.polygon, [[0.3, 0.2], [0.7, 0.45], [0.6, 0.9], [0.2, 0.6]])
    cov.add_view(view(0.49, 0.49))  # inside the polygon: nothing moves inward
    np.testing.assert_allclose(cov.polygon[0], [0.3, 0.2])


def test_a_view_close_to_a_stored_one_is_not_stored():
    cov = make_coverage(novelty=0.1)
    assert cov.add_view(view(0.3, 0.3, 0.10, 0.5))
    assert not cov.add_view(view(0.35, 0.3, 0.12, 0.52))  # L1 distance 0.09
    assert cov.add_view(view(0.35, 0.35, 0.12, 0.5))  # L1 distance 0.12
    assert cov.num_views == 2
    np.testing.assert_allclose(cov.area, [0.10, 0.12])


def test_vector_layout_and_first_view_ranges():
    cov = make_coverage()
    np.testing.assert_allclose(cov.vector(), np.r_[np.full(8, 0.5), 0.0, 0.0, 0.5, 0.5, np.zeros(6)])
    cov.add_view(view(0.4, 0.45, 0.08, 0.52))
    np.testing.assert_allclose(cov.vector()[8:12], [0.08, 0.08, 0.52, 0.52])


def test_motion_is_normalised_by_the_workspace_width_and_keeps_the_maximum():
    cov = make_coverage()
    ws = Workspace()
    cov.add_motion(np.r_[ws.position[0], 0.0, -3 * ws.position[2], 0.0, ws.orientation[1], 0.0])
    np.testing.assert_allclose(cov.motion, [0.5, 0.0, 1.0, 0.0, 0.5, 0.0])
    cov.add_motion(np.zeros(6))
    np.testing.assert_allclose(cov.motion, [0.5, 0.0, 1.0, 0.0, 0.5, 0.0])


def test_completion_needs_every_term_at_its_threshold():
    cov = make_coverage(novelty=0.0, polygon_low=0.45, polygon_high=0.55, area_range=0.02, skew_range=0.05, motion=0.3)
    for u, v, area, skew in [(0.44, 0.44, 0.10, 0.47), (0.56, 0.44, 0.13, 0.5), (0.56, 0.56, 0.1, 0.52)]:
        cov.add_view(view(u, v, area, skew))
    cov.add_motion(np.full(6, 1.0))
    progress = cov.progress()
    assert progress["area"] == 1.0 and progress["skew"] == 1.0 and progress["motion"] == 1.0
    assert progress["polygon"] == pytest.approx(0.0, abs=1e-12)  # V4 never left the centre
    assert not cov.complete()
    cov.add_view(view(0.44, 0.56))
    assert cov.progress()["polygon"] == pytest.approx(1.0)
    assert cov.complete()
