"""Rolling shutters: the simulated rows' times, the corner factors' Jacobians, the line delay estimated with the
camera-IMU extrinsic and time offset (and left at its prior when the motion does not tell it), the evidence a
global-shutter solve gives, and the line delay in camchain files.

The acceptance runs over 20 seeds per line delay are ``experiments/rolling_shutter.py`` (docs/calibration.md).
"""

import subprocess
import sys
from pathlib import Path

import gtsam
import numpy as np
import pytest

from vical.apps.calibrate import main
from vical.calib.solve.corner_factors import CornerFactors, CornerKeys
from vical.calib.solve.corner_noise import _readout_fit, corner_noise
from vical.calib.solve.initialization import starting_poses
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.observations import collect_observations
from vical.calib.solve.outliers import reject_outliers
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint, calibrate_rig
from vical.calib.solve.vi_problem import ViOptions
from vical.calib.synthetic import Excitation, RigCamera, default_camera, imu_kinematics, make_recording
from vical.data import ImuNoise, Target
from vical.geometry import make_transform, so3_exp, so3_log
from vical.io.errors import KalibrFormatError
from vical.io.kalibr import LINE_DELAY_KEY, read_line_delay, write_camchain_imucam
from vical.io.kalibr_chain import read_chain, write_chain
from vical.io.recording import load_recording, save_recording

US = 1e-6  # [s] per microsecond


def recording(line_delay: float, seed: int = 0, duration: float = 12.0, **kwargs):
    return make_recording(
        duration=duration, camera_rate_hz=20.0, target=Target.aprilgrid(), seed=seed, time_offset=0.01,
        pixel_sigma=0.3, imu_noise=ImuNoise(), line_delay=line_delay, **kwargs,
    )  # fmt: skip


def errors(result, truth) -> dict[str, float]:
    rotation = np.rad2deg(np.linalg.norm(so3_log(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)))
    return {
        "rotation_deg": float(rotation),
        "translation_mm": float(np.linalg.norm(result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3]) * 1e3),
        "time_offset_ms": float(abs(result.time_offset - truth.time_offset) * 1e3),
    }


# ---------------------------------------------------------------------------------------- simulation
def test_each_row_is_exposed_its_line_delay_after_the_timestamp():
    """Row 0 at the timestamp: every corner is where the pose at ``t + time_offset + line_delay * v`` puts it."""
    rec = make_recording(duration=2.0, target=Target.aprilgrid(), time_offset=0.004, line_delay=40 * US)
    truth, target = rec.truth, rec.target
    T_imu_cam = np.linalg.inv(truth.T_cam_imu)
    frame = 7
    uv, ids = rec.frames.corners[frame], rec.frames.ids[frame]
    t = (rec.frames.t[frame] - rec.imu.t[0]) / 1e9 + truth.time_offset + truth.line_delay * uv[:, 1]  # (K,)
    T_world_cam = imu_kinematics(Excitation(), target, truth.T_cam_imu, t)[0] @ T_imu_cam
    T_cam_target = np.linalg.inv(T_world_cam) @ rec.T_world_target
    p = np.einsum("kij,kj->ki", T_cam_target[:, :3, :3], target.points[ids]) + T_cam_target[:, :3, 3]
    expected = truth.camera.project(p)[0]
    assert np.max(np.abs(expected - uv)) < 1e-5
    # ... and the readout matters: a global shutter (every row at row 0's time) puts the lower rows pixels away
    row_0 = (rec.frames.t[frame] - rec.imu.t[0]) / 1e9 + truth.time_offset
    still = imu_kinematics(Excitation(), target, truth.T_cam_imu, np.array([row_0]))[0][0] @ T_imu_cam
    T_still = np.linalg.inv(still) @ rec.T_world_target
    global_uv = truth.camera.project(target.points[ids] @ T_still[:3, :3].T + T_still[:3, 3])[0]
    assert np.max(np.abs(global_uv - uv)) > 1.0


# ---------------------------------------------------------------------------------------- factors
def _factor_setup(readout_key: bool):
    rec = make_recording(duration=1.0, target=Target.aprilgrid(), line_delay=30 * US)
    observations = collect_observations(rec.frames, rec.target)[:3]
    rng = np.random.default_rng(4)
    values, poses, velocities = gtsam.Values(), [], []
    for n, o in enumerate(observations):
        t = (o.t_ns - rec.imu.t[0]) / 1e9
        T_world_imu = imu_kinematics(Excitation(), rec.target, rec.truth.T_cam_imu, np.array([t]))[0][0]
        T = np.linalg.inv(rec.T_world_target) @ T_world_imu
        values.insert(gtsam.symbol("x", n), gtsam.Pose3(T @ make_transform(so3_exp(rng.normal(0, 0.01, 3)), [0, 0, 0])))
        values.insert(gtsam.symbol("v", n), rng.normal(0, 0.5, 3))
        poses.append(gtsam.symbol("x", n))
        velocities.append(gtsam.symbol("v", n))
    values.insert(gtsam.symbol("e", 0), gtsam.Pose3(np.linalg.inv(rec.truth.T_cam_imu)))
    values.insert(gtsam.symbol("d", 0), np.array([0.0003]))
    values.insert(gtsam.symbol("k", 0), rec.truth.camera.parameters)
    if readout_key:
        values.insert(gtsam.symbol("l", 0), np.array([0.002]))
    keys = CornerKeys(
        poses=poses, velocities=velocities, omegas=rng.normal(0, 1.0, (3, 3)), extrinsic=gtsam.symbol("e", 0),
        delta=gtsam.symbol("d", 0), camera=gtsam.symbol("k", 0), shifts=np.array([0.0001, -0.0002, 0.0]),
        readout=gtsam.symbol("l", 0) if readout_key else None,
    )  # fmt: skip
    corners = CornerFactors(observations, rec.truth.camera, keys, 0.3, huber_k=2.0, readout=0.0, row_centre=0.5)
    return corners, values


def _perturbed(values: gtsam.Values, key: int, dim: int, h: float) -> gtsam.Values:
    out = gtsam.Values(values)
    step = np.zeros(6 if gtsam.Symbol(key).chr() in (ord("x"), ord("e")) else len(values.atVector(key)))
    step[dim] = h
    if len(step) == 6:
        out.update(key, values.atPose3(key).retract(step))
    else:
        out.update(key, values.atVector(key) + step)
    return out


@pytest.mark.parametrize("rolling", [True, False], ids=["rolling shutter", "global shutter"])
def test_the_corner_factors_jacobians_are_their_errors_derivatives(rolling):
    """To first order in the motion over each exposure's time from its state (``corner_factors``: the exposure shift's
    SE(3) Jacobian is taken as the identity, a relative error of about |twist| dt / 2, ~0.1 % here)."""
    corners, values = _factor_setup(rolling)
    for factor in corners.factors()[:2]:
        analytic = factor.linearize(values).jacobian()[0]
        numeric = []
        for key in list(factor.keys()):
            dims = 6 if gtsam.Symbol(key).chr() in (ord("x"), ord("e")) else len(values.atVector(key))
            for dim in range(dims):
                h = 1e-7 if gtsam.Symbol(key).chr() in (ord("d"), ord("l")) else 1e-6
                plus = factor.unwhitenedError(_perturbed(values, key, dim, h))
                minus = factor.unwhitenedError(_perturbed(values, key, dim, -h))
                numeric.append((plus - minus) / (2 * h))
        numeric = np.array(numeric).T
        scale = np.abs(numeric).max(axis=0) + 1e-3
        assert np.max(np.abs(analytic - numeric) / scale) < 2e-3


# ---------------------------------------------------------------------------------------- the solve
@pytest.mark.parametrize("line_delay_us", [0.0, 40.0])
def test_the_line_delay_is_recovered_with_the_extrinsic_and_time_offset(line_delay_us):
    rec = recording(line_delay_us * US, seed=3)
    result = calibrate_extrinsics(
        rec.frames, rec.imu, rec.target, rec.truth.camera, ImuNoise(), options=ViOptions(rolling_shutter=True)
    )
    sigma = result.sigma("line_delay")
    assert abs(result.line_delay - rec.truth.line_delay) <= max(0.05 * rec.truth.line_delay, 0.5 * US)
    assert abs(result.line_delay - rec.truth.line_delay) <= 3 * sigma
    e = errors(result, rec.truth)
    assert e["rotation_deg"] <= 0.1 and e["translation_mm"] <= 2.0 and e["time_offset_ms"] <= 0.5
    assert abs(result.time_offset - rec.truth.time_offset) <= 3 * result.sigma("time_offset")
    assert not [w for w in result.warnings if "rolling shutter" in w]


def test_a_global_shutter_model_of_a_rolling_shutter_is_told_and_off():
    rec = recording(40 * US, seed=3)
    plain = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, ImuNoise())
    (note,) = [w for w in plain.warnings if "as a rolling shutter's do" in w]
    assert "--rolling-shutter" in note
    assert plain.line_delay is None and "line_delay" not in plain.parameter_names
    # its time offset is the middle row's, 9.6 ms from the timestamp's (row 0's)
    assert errors(plain, rec.truth)["time_offset_ms"] > 5.0


def test_global_shutter_data_give_no_rolling_shutter_warning():
    rec = recording(0.0, seed=4)
    plain = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, ImuNoise())
    assert not [w for w in plain.warnings if "rolling shutter" in w]


def _pnp_views(rec):
    """The views the camera-IMU solve starts from: PnP poses with the true camera, outliers screened."""
    camera = rec.truth.camera
    observations = collect_observations(rec.frames, rec.target)
    screened = reject_outliers(camera, observations, starting_poses(camera, observations, 12, None), 12)
    return [(screened.observations[k], screened.poses[k]) for k in sorted(screened.poses)]


@pytest.mark.parametrize("line_delay_us", [0.0, 40.0])
def test_the_starting_corner_noise_is_not_inflated_by_the_readout(line_delay_us):
    """The PnP residuals of a 40 us/row recording read 0.48 px for 0.3 px of noise; with the views' poses moving
    through one readout they read the noise, and that readout is the truth's. On a global shutter: as PnP's."""
    rec = recording(line_delay_us * US, seed=6)
    views = _pnp_views(rec)
    global_noise = corner_noise(rec.truth.camera, views, rolling_shutter=False)
    rolling_noise = corner_noise(rec.truth.camera, views, rolling_shutter=True)
    assert rolling_noise == pytest.approx(0.3, rel=0.03)
    _, _, readout = _readout_fit(rec.truth.camera, views)
    truth = rec.truth.line_delay * rec.truth.camera.height
    assert readout == pytest.approx(truth, rel=0.02, abs=0.2e-3)
    if line_delay_us:
        assert global_noise > 1.4 * rolling_noise
    else:
        assert rolling_noise == pytest.approx(global_noise, rel=0.005)


@pytest.mark.integration
def test_a_strong_rolling_shutter_is_solved_without_reweighting_its_corners():
    """The joint solve of a 40 us/row recording starts from the right corner noise, so it is not solved again with
    the corners reweighted: at most one iteration (the readout's) more than the global-shutter solve of the same
    data (10 for 3 when it started from the PnP residuals' 0.48 px)."""
    rec = recording(40 * US, seed=7)
    solves = {
        rolling: calibrate_joint(
            rec.frames,
            rec.imu,
            rec.target,
            "radtan",
            (640, 480),
            ImuNoise(),
            options=ViOptions(rolling_shutter=rolling),
        )
        for rolling in (False, True)
    }
    assert solves[True].iterations <= solves[False].iterations + 1
    assert solves[True].pixel_sigma == pytest.approx(0.3, rel=0.05)
    assert solves[False].pixel_sigma > 0.4


@pytest.mark.integration
def test_a_rigs_cameras_get_their_own_line_delays_in_the_joint_task():
    T_cam1_cam0 = make_transform(np.eye(3), [-0.11, 0.0, 0.0])
    cam1 = RigCamera(default_camera(), T_cam1_cam0 @ nominal_T_cam_imu(), 0.0, 20 * US)
    rec = recording(40 * US, seed=5, duration=10.0, other_cameras={"cam1": cam1})
    rig = calibrate_rig(
        {"cam0": rec.frames, "cam1": rec.other_frames["cam1"]}, rec.imu, rec.target, "joint", "radtan",
        {"cam0": (640, 480), "cam1": (640, 480)}, ImuNoise(), options=ViOptions(rolling_shutter=True),
    )  # fmt: skip
    for name, truth in (("cam0", rec.truth), ("cam1", rec.other_truths["cam1"])):
        result = rig.results[name]
        assert abs(result.line_delay - truth.line_delay) <= max(0.05 * truth.line_delay, 0.5 * US), name
        assert abs(result.time_offset - truth.time_offset) <= 0.5e-3, name


def test_a_line_delay_the_motion_does_not_tell_stays_at_its_prior_with_a_warning():
    # A 0.42 m board 4 m away spans 60 rows: the rows' times hardly differ where it is seen (1-sigma 12 ms of readout).
    far = Excitation(distance=4.0, angle_amplitudes=Excitation().angle_amplitudes * 0.3,
                     offset_amplitudes=Excitation().offset_amplitudes * 0.2)  # fmt: skip
    rec = make_recording(
        duration=12.0, camera_rate_hz=20.0, target=Target.checkerboard(), seed=6, time_offset=0.01, pixel_sigma=0.3,
        imu_noise=ImuNoise(), line_delay=20 * US, excitation=far,
    )  # fmt: skip
    result = calibrate_extrinsics(
        rec.frames, rec.imu, rec.target, rec.truth.camera, ImuNoise(), options=ViOptions(rolling_shutter=True)
    )
    (note,) = [w for w in result.warnings if "could not be told" in w]
    assert "cam0" in note and "pan and tilt fast" in note
    assert result.line_delay is None and "line_delay" not in result.parameter_names


@pytest.mark.integration
def test_a_known_line_delay_is_used_with_a_held_time_offset():
    rec = recording(30 * US, seed=7)
    result = calibrate_rig(
        {"cam0": rec.frames}, rec.imu, rec.target, "extrinsic", cameras={"cam0": rec.truth.camera},
        initial_time_offsets={"cam0": rec.truth.time_offset}, imu_noise=ImuNoise(),
        options=ViOptions(estimate_time_offset=False), line_delays={"cam0": rec.truth.line_delay},
    ).results["cam0"]  # fmt: skip
    assert result.line_delay == pytest.approx(rec.truth.line_delay, rel=1e-12)
    assert result.time_offset == rec.truth.time_offset
    assert "line_delay" not in result.parameter_names
    e = errors(result, rec.truth)
    assert e["rotation_deg"] <= 0.1 and e["translation_mm"] <= 2.0


# ---------------------------------------------------------------------------------------- files
def test_the_line_delay_goes_into_the_camchain_and_back(tmp_path):
    camera = default_camera()
    path = tmp_path / "camchain-imucam.yaml"
    write_camchain_imucam(path, camera, np.eye(4), 0.002, line_delay=27.5 * US)
    assert f"{LINE_DELAY_KEY}: 27500.0\n" in path.read_text()
    assert read_line_delay(path) == pytest.approx(27.5 * US, rel=1e-12)
    chain = read_chain(path)
    assert chain["cam0"].line_delay == pytest.approx(27.5 * US, rel=1e-12)
    again = tmp_path / "again.yaml"
    write_chain(again, chain)
    assert path.read_text().count(LINE_DELAY_KEY) == again.read_text().count(LINE_DELAY_KEY) == 1
    assert read_line_delay(again) == read_line_delay(path)


def test_a_negative_line_delay_in_a_camchain_is_refused_naming_the_key(tmp_path):
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, default_camera(), None, None, line_delay=-1 * US)
    with pytest.raises(KalibrFormatError, match=f"{LINE_DELAY_KEY} must be >= 0"):
        read_line_delay(path)


def test_without_the_key_a_camera_has_a_global_shutter(tmp_path):
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, default_camera(), None, None)
    assert read_line_delay(path) is None and LINE_DELAY_KEY not in path.read_text()


def test_joint_task_recovers_the_line_delay():
    rec = recording(20 * US, seed=8)
    result = calibrate_joint(
        rec.frames, rec.imu, rec.target, "radtan", (640, 480), ImuNoise(), options=ViOptions(rolling_shutter=True)
    )
    assert abs(result.line_delay - rec.truth.line_delay) <= max(0.05 * rec.truth.line_delay, 0.5 * US)
    assert errors(result, rec.truth)["time_offset_ms"] <= 0.5


# ---------------------------------------------------------------------------------------- vical-calibrate
@pytest.fixture(scope="module")
def rolling_dir(tmp_path_factory):
    rec = recording(30 * US, seed=9, duration=10.0)
    path = tmp_path_factory.mktemp("rs") / "rec"
    save_recording(rec, path)
    known = path.parent / "known.yaml"
    write_camchain_imucam(known, rec.truth.camera, None, None)
    return path, known, rec


def test_vical_calibrate_estimates_the_line_delay_and_writes_it(rolling_dir, tmp_path, capsys):
    path, known, rec = rolling_dir
    out = tmp_path / "out"
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(known), "--rolling-shutter", "--out", str(out)]
    assert main([*argv, "--no-report"]) == 0
    written = read_line_delay(out / "camchain-imucam.yaml")
    assert abs(written - rec.truth.line_delay) <= 0.05 * rec.truth.line_delay
    assert "line delay" in (out / "results.txt").read_text()
    assert "line delay [us/row]" in capsys.readouterr().out
    # the written camchain given back: its line delay is the one used (no --rolling-shutter), digit for digit
    again = tmp_path / "again"
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(out / "camchain-imucam.yaml"), "--out", str(again)]
    assert main([*argv, "--no-report"]) == 0
    assert read_line_delay(again / "camchain-imucam.yaml") == pytest.approx(written, rel=1e-9)


def test_vical_calibrate_without_the_option_warns_on_a_rolling_shutter(rolling_dir, tmp_path, capsys):
    path, known, _ = rolling_dir
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(known), "--out", str(tmp_path / "o"), "--no-report"]
    assert main(argv) == 0
    (line,) = [x for x in capsys.readouterr().out.splitlines() if "as a rolling shutter's do" in x]
    assert line.startswith("warning: ") and "--rolling-shutter" in line


def test_an_absurd_line_delay_in_the_camchain_is_one_line_naming_the_key(rolling_dir, tmp_path, capsys):
    path, _, rec = rolling_dir
    absurd = tmp_path / "absurd.yaml"
    write_camchain_imucam(absurd, rec.truth.camera, None, None, line_delay=30e-3)  # given in us, not ns: 14 s
    argv = [str(path), "--task", "extrinsic", "--intrinsics", str(absurd), "--out", str(tmp_path / "o"), "--no-report"]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert LINE_DELAY_KEY in line and "longer than the" in line and "nanoseconds per row" in line
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------- rendered
STEPS = (
    "[[0.0,0.08,0.0,0.0,0.0,0.25],[0.0,-0.16,0.05,0.2,-0.1,-0.5],[0.1,0.08,-0.08,-0.35,0.2,0.25],"
    "[-0.1,0.0,0.03,0.15,-0.1,0.0],[0.0,0.08,0.0,0.2,0.2,0.25],[0.05,-0.16,0.0,-0.3,-0.2,-0.4],"
    "[-0.05,0.08,0.05,0.25,0.1,0.3],[0.0,0.0,-0.05,-0.2,0.0,-0.15]]"
)


@pytest.mark.integration
def test_a_strong_rolling_shutter_in_fast_rendered_steps_starts_the_joint_task_from_its_slow_views(tmp_path):
    """40 us/row, 4 s of fast steps, rendered in row bands and detected: every view together calibrates the camera to
    fx 14600 px (truth 581), which no joint solve comes back from; the start from the slowest 40 % of the views
    (``vical.calib.solve.pipeline.ROLLING_START_FRACTION``) recovers everything."""
    out = tmp_path / "rs40"
    record = Path(sys.executable).parent / "vical-record"
    args = [str(record), "sensor=rolling_shutter", "sensor.backend=render", "seed=0", f"out={out}",
            "sensor.camera.line_delay.std=0", "sensor.camera.line_delay.mean=4e-05", "progress=false",
            "settle_time=0", f"steps={STEPS}"]  # fmt: skip
    subprocess.run(args, check=True, capture_output=True, text=True)
    rec = load_recording(out)
    options = ViOptions(rolling_shutter=True)
    noise = rec.truth.imu_noise
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), noise, options=options)
    assert abs(result.line_delay - rec.truth.line_delay) <= 0.05 * rec.truth.line_delay
    e = errors(result, rec.truth)
    assert e["rotation_deg"] <= 0.1 and e["translation_mm"] <= 5.0 and e["time_offset_ms"] <= 0.5
