"""Wide-angle camera models (double sphere, extended unified): projection, unprojection, Jacobians, bad input."""

import numpy as np
import pytest

from vical.geometry import CameraModel, CameraModelError
from vical.geometry import wide_angle as wa

# Coefficients on both sides of alpha = 0.5 (where the domain's boundary changes from a vanishing
# denominator to a fold), as CameraModel(model, ..., dist=coeffs) with a 180 deg field of view.
LENSES = [("ds", [-0.2, 0.6]), ("ds", [0.3, 0.4]), ("ds", [0.0, 0.5]), ("eucm", [0.6, 1.1]), ("eucm", [0.4, 0.8])]
IDS = [f"{m}{c}" for m, c in LENSES]


def _camera(model, coeffs, hfov_deg=180.0):
    cam = CameraModel.from_hfov(np.deg2rad(hfov_deg), 640, 480, dist=coeffs, distortion=model)
    return cam.with_intrinsics(cam.fx * 1.02, cam.fy, cam.cx + 5.0, cam.cy - 4.0, cam.dist)


def _directions(n, max_angle_deg, seed=0):
    """(n, 3) points at random azimuths, up to ``max_angle_deg`` from the optical axis, 0.2-3 m away."""
    rng = np.random.default_rng(seed)
    theta = np.deg2rad(max_angle_deg) * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    unit = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    return unit * rng.uniform(0.2, 3.0, (n, 1))


@pytest.mark.parametrize(("model", "coeffs"), LENSES, ids=IDS)
def test_bearings_invert_projection_up_to_110_deg(model, coeffs):
    cam = _camera(model, coeffs)
    p = _directions(2000, 110.0)
    uv, ok = cam.project(p)
    assert ok.all()
    rays, seen = cam.bearings(uv)
    assert seen.all()
    assert np.abs(rays - p / np.linalg.norm(p, axis=1, keepdims=True)).max() < 1e-12


@pytest.mark.parametrize(("model", "coeffs"), LENSES, ids=IDS)
def test_projection_inverts_unprojection_over_the_image(model, coeffs):
    cam = _camera(model, coeffs)
    uv = np.random.default_rng(1).uniform([0, 0], [639, 479], (2000, 2))
    rays, seen = cam.bearings(uv)
    back, ok = cam.project(rays[seen])
    assert ok.all()
    assert np.abs(back - uv[seen]).max() < 1e-9
    # Rays in front of the camera also come back through the unit-depth unprojection.
    front = rays[:, 2] > 0.05
    unit_depth = cam.unproject(uv[front])
    assert np.abs(unit_depth - rays[front] / rays[front, 2:]).max() < 1e-9


def _numeric_jacobian(f, x, eps=1e-6):
    cols = []
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = eps
        cols.append((f(x + e) - f(x - e)) / (2 * eps))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize(("model", "coeffs"), LENSES, ids=IDS)
def test_analytic_jacobians_match_finite_differences(model, coeffs):
    cam = _camera(model, coeffs)
    points = _directions(40, 115.0, seed=2)
    uv, d_point, d_params = cam.project_jacobians(points)
    assert np.abs(uv - cam.project(points)[0]).max() < 1e-9
    numeric_params = _numeric_jacobian(lambda q: cam.with_parameters(q).project(points)[0], cam.parameters, 1e-7)
    assert np.abs(d_params - numeric_params).max() < 1e-5
    for n in range(len(points)):
        numeric = _numeric_jacobian(lambda p, n=n: cam.project(p[None])[0][0], points[n], 1e-7)
        assert np.abs(d_point[n] - numeric).max() < 1e-4 * max(1.0, np.abs(numeric).max())


def _radial_map(model, coeffs, theta):
    """``m(theta)`` of rays at angle ``theta`` (N,) from the axis, and the denominator (N,)."""
    p = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=1)
    den = wa.denominator(model, np.asarray(coeffs, float), p)
    return np.sin(theta) / den, den


@pytest.mark.parametrize(("model", "coeffs"), LENSES, ids=IDS)
def test_valid_domain_ends_where_the_projection_folds_or_diverges(model, coeffs):
    # Along a meridian the image radius grows with the angle while the projection is one-to-one; it stops
    # where it folds back (alpha > 0.5) or its denominator reaches zero (alpha <= 0.5).
    theta = np.linspace(0.0, np.pi * 0.9999, 400_001)
    m, den = _radial_map(model, coeffs, theta)
    p = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=1)
    valid = wa.valid(model, np.asarray(coeffs, float), p)
    limit = theta[valid].max()
    breaks = np.flatnonzero((np.diff(m) <= 0) | (den[1:] <= 0))
    end = theta[breaks[0]] if len(breaks) else theta[-1]
    assert limit == pytest.approx(end, abs=2e-4)
    assert valid[: np.argmax(~valid)].all() and not valid[theta > end + 1e-3].any()


@pytest.mark.parametrize(("model", "coeffs"), [("ds", [-0.2, 0.6]), ("eucm", [0.6, 1.1])])
def test_points_outside_the_domain_are_not_projected_and_dark_pixels_not_unprojected(model, coeffs):
    cam = _camera(model, coeffs)
    behind = np.array([[0.0, 0.0, -1.0], [0.1, 0.0, -1.0], [0.0, 0.0, 0.0]])
    uv, ok = cam.project(behind)
    assert not ok.any() and np.isnan(uv).all()
    # Beyond the fold radius (alpha > 0.5) no ray reaches the image: those pixels have no bearing.
    alpha, beta = (coeffs[1], 1.0) if model == "ds" else coeffs
    m_max = np.sqrt(1.0 / (beta * (2 * alpha - 1)))
    far = np.array([[cam.cx + 1.01 * m_max * cam.fx, cam.cy], [cam.cx + 0.99 * m_max * cam.fx, cam.cy]])
    rays, seen = cam.bearings(far)
    assert seen.tolist() == [False, True] and np.isnan(rays[0]).all()


def test_special_cases_are_the_pinhole_stereographic_and_unified_models():
    p = _directions(500, 80.0, seed=4)
    pinhole = CameraModel("radtan", 640, 480, 300.0, 310.0, 320.0, 240.0)
    for cam in (CameraModel("ds", 640, 480, 300.0, 310.0, 320.0, 240.0, [0.0, 0.0]),
                CameraModel("eucm", 640, 480, 300.0, 310.0, 320.0, 240.0, [0.0, 2.0])):  # fmt: skip
        assert np.abs(cam.project(p)[0] - pinhole.project(p)[0]).max() < 1e-9
    # ds with xi = 0, alpha = 0.5: r = 2 f tan(theta / 2).
    stereo = CameraModel("ds", 640, 480, 300.0, 300.0, 320.0, 240.0, [0.0, 0.5])
    theta = np.arccos(p[:, 2] / np.linalg.norm(p, axis=1))
    radius = np.linalg.norm(stereo.project(p)[0] - [320.0, 240.0], axis=1)
    assert np.abs(radius - 2 * 300.0 * np.tan(theta / 2)).max() < 1e-9
    # Both contain the unified model (Mei): ds with alpha = 0 and xi, eucm with beta = 1 and
    # alpha = xi / (1 + xi) at the focal length times (1 - alpha).
    xi = 0.8
    ds = CameraModel("ds", 640, 480, 300.0, 300.0, 320.0, 240.0, [xi, 0.0])
    a = xi / (1 + xi)
    eucm = CameraModel("eucm", 640, 480, 300.0 * (1 - a), 300.0 * (1 - a), 320.0, 240.0, [a, 1.0])
    assert np.abs(ds.project(p)[0] - eucm.project(p)[0]).max() < 1e-9


@pytest.mark.parametrize("model", ["ds", "eucm"])
def test_from_hfov_puts_the_edge_ray_on_the_image_edge(model):
    for hfov_deg in (90.0, 180.0, 200.0):
        coeffs = [-0.2, 0.6] if model == "ds" else [0.6, 1.1]
        cam = CameraModel.from_hfov(np.deg2rad(hfov_deg), 640, 480, dist=coeffs, distortion=model)
        half = np.deg2rad(hfov_deg / 2)
        uv, ok = cam.project(np.array([[np.sin(half), 0.0, np.cos(half)], [-np.sin(half), 0.0, np.cos(half)]]))
        assert ok.all()
        assert uv[:, 0] == pytest.approx([cam.cx + 320.0, cam.cx - 320.0])


def test_camera_dict_round_trip_keeps_the_model():
    cam = _camera("eucm", [0.6, 1.1])
    again = CameraModel.from_dict(cam.to_dict())
    assert again == cam and again.parameter_names == ["fx", "fy", "cx", "cy", "alpha", "beta"]
    assert np.array_equal(again.parameters, cam.parameters)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"distortion": "fov"},
            r"camera model 'fov' unknown; use one of \['radtan', 'equidistant', 'ds', 'eucm', 'omni', 'omni-radtan'\]",
        ),
        ({"distortion": "ds", "dist": [0.1, 1.2]}, r"ds parameter alpha must be in \[0, 1\], got 1.2"),
        ({"distortion": "ds", "dist": [-1.5, 0.5]}, r"ds parameter xi must be in \[-1, 1\], got -1.5"),
        ({"distortion": "eucm", "dist": [-0.1, 1.0]}, r"eucm parameter alpha must be in \[0, 1\], got -0.1"),
        ({"distortion": "eucm", "dist": [0.6, 0.0]}, r"eucm parameter beta must be > 0, got 0.0"),
        ({"distortion": "eucm", "dist": [0.6, -1.0]}, r"eucm parameter beta must be > 0, got -1.0"),
        ({"distortion": "ds", "dist": [0.1, 0.5, 0.0, 0.0]}, r"ds needs 2 coefficients \['xi', 'alpha'\]"),
        ({"distortion": "ds", "dist": [0.0, 0.5], "distortion_center_offset": [3.0, 0.0]}, "pinhole models only"),
    ],
)
def test_bad_parameters_are_refused_naming_them(kwargs, message):
    with pytest.raises(CameraModelError, match=message):
        CameraModel(width=640, height=480, fx=300.0, fy=300.0, cx=320.0, cy=240.0, **kwargs)


def test_a_field_of_view_the_model_cannot_project_is_refused():
    with pytest.raises(CameraModelError, match="horizontal FOV must be in"):
        CameraModel.from_hfov(np.deg2rad(190.0), distortion="radtan")
    # ds [-0.2, 0.6] folds 123 deg off its axis: a 260 deg field of view does not exist for it.
    with pytest.raises(CameraModelError, match="does not project rays"):
        CameraModel.from_hfov(np.deg2rad(260.0), dist=[-0.2, 0.6], distortion="ds")
