"""The marginal covariance of chosen keys equals gtsam.Marginals; singular problems become CalibrationError."""

import gtsam
import numpy as np
import pytest

from vical.calib.errors import CalibrationError
from vical.calib.solve import intrinsics
from vical.calib.solve.initialization import frame_poses, initial_camera
from vical.calib.solve.observations import collect_observations
from vical.calib.solve.solver import covariance_or_unobservable, linear_covariance, optimize
from vical.calib.synthetic import make_recording


@pytest.fixture(scope="module")
def solved_intrinsic_graph():
    rec = make_recording(duration=4.0, pixel_sigma=0.3, seed=9)
    obs = collect_observations(rec.frames, rec.target)
    camera = initial_camera(obs, "radtan", (640, 480))
    poses = {k: T for k, (T, _) in frame_poses(camera, obs).items()}
    graph, values = intrinsics._build_graph(camera, obs, poses, 1.0, None)
    return graph, optimize(graph, values).values, sorted(poses)


@pytest.mark.parametrize("with_pose", [False, True])  # the root clique's block; keys split over cliques
def test_joint_covariance_matches_gtsam_marginals(solved_intrinsic_graph, with_pose):
    graph, values, frames = solved_intrinsic_graph
    keys = [intrinsics.K_KEY] + ([intrinsics.pose_key(frames[3])] if with_pose else [])
    ours = linear_covariance(graph.linearize(values), values, keys)
    reference = gtsam.Marginals(graph, values).jointMarginalCovariance(keys).fullMatrix()
    assert np.allclose(ours, reference, rtol=1e-6, atol=1e-12 * np.abs(reference).max())


def test_singular_graph_is_a_calibration_error():
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(0, gtsam.Pose3())
    values.insert(1, gtsam.Pose3())
    noise = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)
    graph.add(gtsam.BetweenFactorPose3(0, 1, gtsam.Pose3(), noise))  # no prior: the gauge is free
    solution = optimize(graph, values)  # Levenberg-Marquardt's damping still finds a point
    with pytest.raises(CalibrationError, match="singular"):
        linear_covariance(graph.linearize(solution.values), solution.values, [1])


def test_unobservable_directions_become_nan_and_the_rest_keeps_its_covariance():
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(0, gtsam.Pose3())
    values.insert(1, gtsam.Pose3())
    values.insert(2, np.array([1.0, 2.0, 3.0]))
    graph.add(gtsam.BetweenFactorPose3(0, 1, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 0.1)))  # no gauge
    graph.add(gtsam.PriorFactorVector(2, np.array([1.0, 2.0, 3.0]), gtsam.noiseModel.Isotropic.Sigma(3, 0.5)))
    linear = graph.linearize(values)
    with pytest.raises(CalibrationError, match="singular"):
        linear_covariance(linear, values, [2, 1])
    covariance = covariance_or_unobservable(linear, values, [2, 1])
    assert np.allclose(covariance[:3, :3], 0.25 * np.eye(3), rtol=1e-5)  # the prior's variance, undamped
    assert np.all(np.isnan(covariance[3:, :])) and np.all(np.isnan(covariance[:, 3:]))


def test_a_result_with_unobservable_parameters_keeps_its_estimates_and_writes_every_file(tmp_path):
    """What a singular information leaves (NaN rows for the free parameters, a warning naming them) is written."""
    from dataclasses import replace

    from vical.calib.report.writers import summary_table, write_report, write_results_text
    from vical.calib.solve.pipeline import calibrate_joint
    from vical.calib.solve.uncertainty import unobservable_warnings
    from vical.data import ImuNoise
    from vical.io.kalibr import read_camchain, write_camchain_imucam

    rec = make_recording(duration=8.0, pixel_sigma=0.3, seed=9, imu_noise=ImuNoise())
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), rec.truth.imu_noise)
    covariance = result.covariance.copy()
    free = [result.parameter_names.index(n) for n in ("t_z", "time_offset")]
    covariance[free, :] = np.nan
    covariance[:, free] = np.nan
    warnings = unobservable_warnings(result.parameter_names, covariance)
    assert len(warnings) == 1 and "t_z, time_offset" in warnings[0]
    broken = replace(result, covariance=covariance, warnings=result.warnings + warnings)
    write_results_text(tmp_path / "results.txt", broken)
    written = write_report(tmp_path, broken)
    write_camchain_imucam(tmp_path / "camchain-imucam.yaml", broken.camera, broken.T_cam_imu, broken.time_offset)
    text = (tmp_path / "results.txt").read_text()
    assert "the data do not determine t_z, time_offset" in text and "nan" in text
    assert all(p.stat().st_size > 0 for p in written)
    camera, T_cam_imu, _ = read_camchain(tmp_path / "camchain-imucam.yaml")
    assert np.allclose(T_cam_imu, result.T_cam_imu) and camera.intrinsics == pytest.approx(result.camera.intrinsics)
    assert "+- nan" in summary_table(broken)  # the printed summary shows the unknown 1-sigma as such
