"""vical.calib.solve.model_fit: the corner noise from neighbouring corners and the residual field."""

import numpy as np
import pytest

from vical.calib.solve.model_fit import neighbour_noise, residual_field
from vical.calib.synthetic import default_camera


def brute_force_noise(points, residuals, frame_of):
    """Every view's full distance matrix, each corner's nearest other corner (the definition, written plainly)."""
    differences = []
    for view in np.unique(frame_of):
        k = np.flatnonzero(frame_of == view)
        if len(k) < 2:
            continue
        distance = np.linalg.norm(points[k][:, None] - points[k][None, :], axis=2)
        np.fill_diagonal(distance, np.inf)
        differences.append(residuals[k] - residuals[k][np.argmin(distance, axis=1)])
    d = np.concatenate(differences)
    return np.sqrt(np.mean(np.sum(d * d, axis=1)) / 4.0)


def scattered_corners(rng, views=40, per_view=60):
    """Board points with no two pairs equally near (so the nearest corner is unique), views of varying size."""
    points, frame_of = [], []
    for view in rng.permutation(views):  # views interleaved, not sorted
        n = int(rng.integers(1, per_view))  # some views with a single corner: no pair
        points.append(rng.uniform(0.0, 0.8, (n, 3)) * [1, 1, 0])
        frame_of.append(np.full(n, view))
    return np.concatenate(points), np.concatenate(frame_of)


def test_neighbour_noise_pairs_each_corner_with_its_nearest_in_its_own_view():
    rng = np.random.default_rng(3)
    points, frame_of = scattered_corners(rng)
    residuals = rng.normal(0.0, 0.3, (len(points), 2))
    assert neighbour_noise(points, residuals, frame_of) == pytest.approx(
        brute_force_noise(points, residuals, frame_of), rel=1e-12
    )


def test_neighbour_noise_measures_the_noise_and_not_a_field_shared_by_neighbours():
    rng = np.random.default_rng(4)
    points, frame_of = scattered_corners(rng, views=200)
    field = 2.0 * np.column_stack([np.sin(3 * points[:, 0]), np.cos(2 * points[:, 1])])  # smooth, px
    residuals = field + rng.normal(0.0, 0.3, (len(points), 2))
    assert abs(neighbour_noise(points, residuals, frame_of) - 0.3) < 0.03
    assert neighbour_noise(points[:10], residuals[:10], frame_of[:10]) is None  # under MIN_PAIRS pairs


def test_residual_field_is_zero_for_noise_and_the_offset_of_a_shared_error():
    rng = np.random.default_rng(5)
    camera = default_camera()
    uv = rng.uniform([0, 0], [camera.width, camera.height], (20000, 2))
    noise = rng.normal(0.0, 0.3, uv.shape)
    assert residual_field(camera, uv, noise) < 0.02
    assert abs(residual_field(camera, uv, noise + [0.4, -0.4]) - 0.4) < 0.02
