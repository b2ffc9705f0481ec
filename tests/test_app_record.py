"""vical-record: composes from conf/record.yaml, writes a loadable recording and PNG frames, refuses bad input,
warns about a step the arm cannot execute and about too few board views, renders a 180 deg fisheye whose small
squares are found, and a run killed while writing (SIGKILL of a real subprocess) leaves nothing that blocks the
next one."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from vical.apps.record import ClampedStepWarning, FewViewsWarning, record, square_px
from vical.config_checks import ConfigError
from vical.io.kalibr import read_imu_yaml
from vical.io.recording import load_recording
from vical.sim.settings import BoardConfig

CONF = Path(__file__).resolve().parents[1] / "conf"
SHORT = ["steps=[[0.0,0.04,0.0,0.0,0.0,0.1]]", "settle_time=0.05", "progress=false"]


def _cfg(*overrides):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        return compose(config_name="record", overrides=list(overrides))


def test_record_writes_recording_and_png_frames(tmp_path):
    out = tmp_path / "rec"
    assert record(_cfg(f"out={out}", "images=true", "seed=4", "task=joint", *SHORT)) == out
    rec = load_recording(out)
    assert len(rec.frames) >= 3 and rec.frames.num_detections.min() == rec.target.num_points
    assert len(rec.imu) > 50 and rec.path_length > 0.03
    assert np.any(rec.truth.camera.distortion_center_offset != 0)  # the joint task draws the centre
    assert rec.metadata["seed"] == 4 and rec.metadata["config"]["task"]["name"] == "joint"
    pngs = sorted((out / "images").glob("*.png"), key=lambda p: int(p.stem))
    assert [int(p.stem) for p in pngs] == rec.frames.t.tolist()
    np.testing.assert_array_equal(cv2.imread(str(pngs[-1]), cv2.IMREAD_GRAYSCALE), rec.frames.images[-1])


def test_same_seed_same_sensor_and_data(tmp_path):
    a = load_recording(record(_cfg(f"out={tmp_path / 'a'}", "seed=2", *SHORT)))
    b = load_recording(record(_cfg(f"out={tmp_path / 'b'}", "seed=2", *SHORT)))
    assert a.truth.to_dict() == b.truth.to_dict()
    np.testing.assert_array_equal(a.imu.gyro, b.imu.gyro)
    assert np.all(a.truth.camera.distortion_center_offset == 0)  # intrinsic task: centred distortion


def test_existing_output_is_refused(tmp_path):
    out = tmp_path / "rec"
    out.mkdir()
    with pytest.raises(FileExistsError, match="overwrite=true"):
        record(_cfg(f"out={out}", *SHORT))


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ("steps=[[0.1,0.0]]", r"steps\[0\] must be 6 finite numbers"),
        ("steps=[]", r"steps must be a non-empty list"),
        ("sensor.imu.rate_hz=300.0", r"sensor\.imu\.rate_hz"),
        ("sensor.camera.hfov.mean=3.5", r"sensor\.camera\.hfov\.mean"),
        ("sensor.camera.distortion=eucm sensor.camera.beta.mean=-1", r"sensor\.camera\.beta\.mean must be > 0"),
    ],
)
def test_bad_config_names_the_key(tmp_path, override, match):
    with pytest.raises(ConfigError, match=match):
        record(_cfg(f"out={tmp_path / 'rec'}", *SHORT, *override.split()))
    assert not (tmp_path / "rec").exists()


def test_an_unreachable_step_is_executed_as_far_as_it_goes_with_a_warning(tmp_path):
    unreachable = "steps=[[0.0,0.04,0.0,0.0,0.0,0.1],[0.0,0.0,2.0,0.0,0.0,0.0]]"
    with pytest.warns(ClampedStepWarning) as caught:
        record(_cfg(f"out={tmp_path / 'rec'}", *SHORT, unreachable))
    (warning,) = caught
    message = str(warning.message)
    assert message.startswith("steps[1] was not executed as requested (target unreachable")
    asked, moved = (float(part.split(" m,")[0]) for part in message.split("asked for ")[1].split("the arm moved "))
    assert asked == pytest.approx(2.0) and 0.0 < moved < 1.0
    assert load_recording(tmp_path / "rec").path_length < 1.0  # the executed motion, not the requested one


def test_a_180_deg_fisheye_render_finds_the_small_squares_in_every_frame(tmp_path):
    fisheye = ["sensor.camera.distortion=ds", "sensor.camera.hfov.mean=3.14", "sensor.backend=render"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", FewViewsWarning)
        record(_cfg(f"out={tmp_path / 'rec'}", *SHORT, *fisheye))
    rec = load_recording(tmp_path / "rec")
    assert square_px(rec.truth.camera, BoardConfig()) == pytest.approx(10.4, abs=0.5)  # the 1.5 m board's squares
    assert len(rec.frames) == 3 and rec.frames.num_detections.tolist() == [42, 42, 42]


FEW_VIEWS = "0 of 3 frames hold board corners, fewer than the 3 views a calibration needs: "


@pytest.mark.parametrize(
    ("overrides", "advice"),
    [
        (
            ["sim.board.offset=[-0.75,0.0]"],
            "keep the board in view (steps, sim.board.offset; its squares are about 27 px wide)",
        ),
        (
            ["sim.board.distance=5.0", "sensor.camera.distortion=ds", "sensor.camera.hfov.mean=3.14"],
            "the board's squares are about 3.1 px wide at the start pose, below the 8 px the detector resolves; "
            "bring the board closer (sim.board.distance, now 5 m) or enlarge it (sim.board.square, now 0.07 m)",
        ),
    ],
    ids=["out of view", "too small"],
)
def test_a_recording_with_too_few_board_views_warns_what_to_change(tmp_path, overrides, advice):
    with pytest.warns(FewViewsWarning) as caught:
        record(_cfg(f"out={tmp_path / 'rec'}", *SHORT, *overrides))
    (warning,) = caught
    assert str(warning.message) == FEW_VIEWS + advice
    assert load_recording(tmp_path / "rec").frames.num_detections.max() == 0  # written all the same


@pytest.mark.integration
def test_a_recording_killed_while_written_leaves_nothing_that_blocks_the_next_one(tmp_path):
    out = tmp_path / "rec"
    command = [str(Path(sys.executable).parent / "vical-record"), f"out={out}", "images=true", "progress=false"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not any(p.name.startswith(".rec.tmp-") for p in tmp_path.iterdir()):
        assert proc.poll() is None, "vical-record ended before it was killed"
        assert time.monotonic() < deadline
        time.sleep(0.001)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".rec.tmp-")]

    again = subprocess.run([*command, "overwrite=true"], capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]
    rec = load_recording(out)
    assert sorted(int(p.stem) for p in (out / "images").glob("*.png")) == rec.frames.t.tolist()


# The tutorial's deliberately noisy IMU at 50 Hz (tests/imu_streams.py's NOISE): 30 min suffice for its Allan
# deviation (docs/tutorial-calibrate-your-recording.md).
NOISY_IMU = [
    "sensor.imu.rate_hz=50.0", "sensor.imu.accel_noise=0.02", "sensor.imu.accel_random_walk=0.07",
    "sensor.imu.gyro_noise=0.002", "sensor.imu.gyro_random_walk=0.007",
]  # fmt: skip


def test_a_static_imu_recording_gives_vical_imu_noise_the_sensors_noise(tmp_path, capsys):
    """mode=static_imu: the drawn sensor's IMU lying still, as an EuRoC folder (imu0 alone) that vical-imu-noise
    reads; the densities it measures are the sensor's within its 10 % (the Allan fit's accuracy on 30 min)."""
    from vical.apps import imu_noise
    from vical.io.sources import open_imu

    out = tmp_path / "static_imu"
    record(_cfg("mode=static_imu", "static_duration=1800", f"out={out}", "progress=false", *NOISY_IMU))
    imu = open_imu(out)
    assert len(imu) == 1800 * 50 and np.all(np.diff(imu.t) == 20_000_000)
    # Lying still, z up: the first half second reads gravity (its bias walks away by ~0.07 sqrt(t) m/s^2 after)
    np.testing.assert_allclose(np.mean(imu.accel[:25], axis=0), [0.0, 0.0, 9.81], atol=0.15)
    np.testing.assert_allclose(np.mean(imu.gyro[:25], axis=0), 0.0, atol=0.015)
    assert imu_noise.main([str(out), "--out", str(tmp_path / "noise")]) == 0
    measured = read_imu_yaml(tmp_path / "noise" / "imu.yaml")
    assert measured.gyro_noise_density == pytest.approx(0.002, rel=0.10)
    assert measured.gyro_random_walk == pytest.approx(0.007, rel=0.10)
    assert measured.accel_noise_density == pytest.approx(0.02, rel=0.10)
    assert measured.accel_random_walk == pytest.approx(0.07, rel=0.10)
    assert measured.rate_hz == 50.0
    assert "recording written to" not in capsys.readouterr().out  # record() returns; the console script prints


@pytest.mark.parametrize("backend", ["project", "render"])
def test_a_stereo_rig_records_each_camera_from_its_own_pose_on_one_trigger(tmp_path, backend):
    """sensor=stereo: two cameras 11 cm apart, each with its own lens, stamped together (rendered: each through its
    own renderer, its PNGs in images_cam1/); calibrated as the README says (vical-calibrate --cameras cam0,cam1),
    the rig's relative pose and lenses come back (seeds 0-2 measured: 0.02-0.05 deg, 0.4-1.2 mm, focal lengths
    within 0.11 %)."""
    from vical.apps import calibrate
    from vical.io.kalibr_chain import read_chain

    out = tmp_path / "stereo"
    rendered = [f"sensor.backend={backend}", f"images={str(backend == 'render').lower()}"]
    record(_cfg("sensor=stereo", "task=joint", "workspace=practitioner", f"out={out}", "progress=false", *rendered))
    rec = load_recording(out)
    if backend == "render":
        assert len(list((out / "images_cam1").glob("*.png"))) == len(rec.frames_of("cam1")) > 20
    assert rec.camera_names == ["cam0", "cam1"]
    np.testing.assert_array_equal(rec.frames_of("cam1").t, rec.frames.t)  # one trigger
    first, second = rec.truth, rec.truth_of("cam1")
    assert first.camera != second.camera  # each its own lens
    T_c1_c0 = second.T_cam_imu @ np.linalg.inv(first.T_cam_imu)
    assert np.linalg.norm(T_c1_c0[:3, 3]) == pytest.approx(0.11, abs=0.01)
    assert min(rec.frames_of(n).num_detections.astype(bool).sum() for n in rec.camera_names) >= 20
    calib = tmp_path / "calib"
    assert calibrate.main([str(out), "--cameras", "cam0,cam1", "--out", str(calib), "--no-report"]) == 0
    chain = read_chain(calib / "camchain-imucam.yaml")
    found = chain["cam1"].T_cn_cnm1
    assert np.degrees(np.arccos(np.clip((np.trace(found[:3, :3] @ T_c1_c0[:3, :3].T) - 1) / 2, -1, 1))) < 0.1
    assert np.linalg.norm(found[:3, 3] - T_c1_c0[:3, 3]) < 0.002
    for name, truth in (("cam0", first), ("cam1", second)):
        assert chain[name].camera.fx == pytest.approx(truth.camera.fx, rel=0.005)
