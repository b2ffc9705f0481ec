"""vical-guide: settings refused by key, the page's state, image and files over HTTP, and a headless guided run with a
simulated person that records and calibrates. The page in a real browser: tests/test_guide_page.py."""

import json
import logging
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hydra import compose, initialize_config_dir
from stopped_collections import calibrate_joint, default_sigint, file_size_limit, kill_if_running

from vical.apps.cli import plain
from vical.apps.collect import build_robot, configured_policy, nominal_sensor
from vical.apps.guide import CONF_DIR, build_guide, check_settings, guide, guided_mdp
from vical.collection import page as page_module
from vical.collection.page import GuidePage, PageSettings
from vical.config_checks import ConfigError
from vical.data import Target
from vical.env.lookahead import ReachTiming
from vical.evaluation.harness import instantiate_policy
from vical.geometry import T_CAM_BODY, CameraModel, make_transform
from vical.io.bag import write_bag
from vical.io.euroc import read_euroc
from vical.io.kalibr import read_camchain, read_target_yaml
from vical.policies.learned import PAPER_POLICY_DIR
from vical.robot import CameraDetections, CameraImage, Guidance


def config(*overrides: str):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(config_name="guide", overrides=list(overrides))


def test_bad_settings_are_refused_by_key(tmp_path, monkeypatch):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    out = f"out={tmp_path / 'o'}"
    with pytest.raises(FileExistsError, match="already exists"):
        check_settings(config(f"out={tmp_path / 'full'}"))
    # the planners' model of a step: the person's reach, then the arrival's still window
    assert check_settings(config(out, "arrival.still_s=0.7")).reach == ReachTiming(rest=0.7)
    for override, message in [
        ("start.distance=0", r"start\.distance must be a number in \(0"),
        ("arrival.patience_s=0", r"arrival\.patience_s must be a number in \(0"),
        ("reach.max_rate=0", r"reach\.max_rate must be a number in \(0"),
        ("+reach.pace=1", r"reach: unknown setting\(s\) \['pace'\]"),
        ("limits.max_steps=0", r"limits\.max_steps must be >= 1"),
        ("page.port=70000", r"page\.port must be a port 0-65535"),
        ("page.linger=-1", r"page\.linger must be a number in \[0"),
        ("+page.colour=red", r"page: unknown setting\(s\) \['colour'\]"),
    ]:
        with pytest.raises(ConfigError, match=message):
            check_settings(config(out, override))
    with pytest.raises(ConfigError, match=r"^person: person\.placement_sigma_m must be a number in \[0"):
        guide(config(out, "person.placement_sigma_m=-1"))
    with pytest.raises(ConfigError, match=r"^person: RealSenseSensor needs the pyrealsense2 package"):
        guide(config(out, "person=realsense", "guess.camchain=null"))
    with monkeypatch.context() as without_roslibpy:
        without_roslibpy.setitem(sys.modules, "roslibpy", None)  # as where it is not installed
        with pytest.raises(ConfigError, match=r"^person: .*roslibpy package: pip install 'vical\[ros\]'"):
            guide(config(out, "person=ros", "guess.camchain=null"))
    with socket.socket() as unserved:  # a port nothing listens on: no rosbridge there
        unserved.bind(("127.0.0.1", 0))
        port = unserved.getsockname()[1]
    with pytest.raises(
        ConfigError, match=rf"^person: no rosbridge at ws://localhost:{port} within 1 s: is rosbridge_server running\?$"
    ):
        guide(config(out, "person=ros", f"person.port={port}", "person.timeout=1", "guess.camchain=null"))
    held = r"\['imu_gap', 'camera_gap', 'lens_covered'\]"
    with pytest.raises(ConfigError, match=rf"^person: faults: a held sensor's faults are {held}"):
        guide(config(out, "+person.faults.latency=0.1"))
    # A policy trained for another state layout and workspace (the paper's coverage state): refused before it runs,
    # as the learned policy and as the state the default planner would plan on.
    with pytest.raises(ConfigError) as refused:
        guide(config(out, "policy=learned_person", f"policy.run_dir={PAPER_POLICY_DIR}"))
    assert "\n" not in str(refused.value) and "trained in workspace 'paper'" in str(refused.value)
    with pytest.raises(ConfigError, match=r"trained on the coverage state: name one with policy\.run_dir="):
        guide(config(out, f"policy.run_dir={PAPER_POLICY_DIR}"))
    assert not (tmp_path / "o").exists()


def test_a_guided_step_is_one_reach_of_a_person_and_a_learned_policy_keeps_its_trained_box():
    cfg = config("out=unused")
    reach, box = check_settings(cfg).reach, np.asarray(cfg.workspace.action_scale, dtype=float)
    for axis in (0, 3, 4, 5):  # each of the box's steps takes the reach's least time ...
        step = np.zeros(6)
        step[axis] = box[axis]
        assert reach.motion_time(step) == pytest.approx(reach.min_s)
        if axis in (0, 3):  # ... and a longer move or roll more
            assert reach.motion_time(1.2 * step) > reach.min_s + 0.1
    assert box[4:] == pytest.approx(2 * np.asarray(cfg.workspace.orientation[1:]))  # pitch, yaw: bound to bound
    planner = instantiate_policy(plain(cfg.policy)["joint"], "planner")
    assert guided_mdp(cfg, planner).action_scale == pytest.approx(box)
    learned_cfg = config("out=unused", "policy=learned_person")
    learned = instantiate_policy(plain(learned_cfg.policy)["joint"], "learned")
    trained = guided_mdp(learned_cfg, learned).action_scale
    assert trained == pytest.approx(learned.action_scale) and trained[0] == pytest.approx(0.3)


def test_a_port_in_use_is_one_line_naming_the_key(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError, match=rf"^page\.port={port}: cannot serve on 127\.0\.0\.1 .*page\.port=0"):
            guide(config(f"out={tmp_path / 'o'}", f"page.port={port}", "person.images=false"))
    assert not (tmp_path / "o").exists()


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=5) as response:
        return response.read()


def test_the_page_serves_the_guidance_the_live_image_with_the_outline_and_the_result(tmp_path, caplog):
    """The state as the guide showed it; the frame with the detected corners and the board's outline where the shown
    pose puts it (straight ahead at 1.2 m: a rectangle about the principal point, fx * width / 1.2 wide); the
    calibration's files, and nothing outside them; Close ends the wait; requests are not logged."""
    caplog.set_level(logging.INFO)
    camera, target = CameraModel.from_hfov(1.0, 640, 480), Target.aprilgrid()  # a pinhole without distortion
    page = GuidePage(camera, target, PageSettings(port=0))
    try:
        board_centre = target.center
        T_board_cam = make_transform(np.diag([1.0, -1.0, -1.0]), board_centre + [0.0, 0.0, 1.2])  # facing the board
        page.show(Guidance(T_board_cam @ T_CAM_BODY, "move 20 cm closer", {"intrinsics": 2.5, "distortion": 0.8}, 3.2))
        image = np.full((camera.height, camera.width), 200, np.uint8)
        page.view(CameraImage(1, image), np.array([[100.0, 120.0]]), np.array([0]))
        state = json.loads(_get(page.url + "/state.json"))
        assert state["words"] == "move 20 cm closer" and state["history"] == ["move 20 cm closer"]
        assert state["ratios"] == {"intrinsics": 2.5, "distortion": 0.8} and state["elapsed_s"] == 3.2
        assert state["frames"] == 1 and not state["done"] and state["result"] is None
        frame = cv2.imdecode(np.frombuffer(_get(page.url + "/frame.jpg"), np.uint8), cv2.IMREAD_COLOR)
        assert frame.shape == (camera.height, camera.width, 3)
        orange = (frame[:, :, 2] > 200) & (frame[:, :, 1] > 90) & (frame[:, :, 1] < 190) & (frame[:, :, 0] < 80)
        rows, cols = np.nonzero(orange)
        extent = np.ptp(target.points[:, :2], axis=0)
        expected = camera.fx * extent[0] / 1.2
        assert cols.max() - cols.min() == pytest.approx(expected, abs=6)
        assert (cols.max() + cols.min()) / 2 == pytest.approx(camera.cx, abs=4)
        assert (rows.max() + rows.min()) / 2 == pytest.approx(camera.cy, abs=4)
        green = frame[119:122, 99:102]
        assert green[:, :, 1].min() > 150 and green[:, :, 0].max() < 120  # the detected corner
        # A corner-level frame (no image): the corners on a plain background.
        page.view(CameraDetections(2, np.array([[50.0, 60.0]]), np.array([3])), np.array([[50.0, 60.0]]), [3])
        assert json.loads(_get(page.url + "/state.json"))["frames"] == 2
        files = tmp_path / "calibration"
        files.mkdir()
        (files / "results.txt").write_text("fx 458.7\n")
        (tmp_path / "secret.txt").write_text("no")
        page.finish({"steps": 4}, files)
        state = json.loads(_get(page.url + "/state.json"))
        assert state["result"] == {"steps": 4} and state["results_text"] == "fx 458.7\n"
        assert state["files"] == ["results.txt"]
        assert _get(page.url + "/files/results.txt") == b"fx 458.7\n"
        for name in ("../secret.txt", "nothing.txt"):
            with pytest.raises(urllib.error.HTTPError, match="404"):
                _get(page.url + "/files/" + name)
        assert b"vical-guide" in _get(page.url + "/")
        assert not page.wait_closed(0.05)
        _post(page.url + "/close")
        assert page.wait_closed(1.0)
    finally:
        page.close()
    with pytest.raises(urllib.error.URLError):
        _get(page.url + "/state.json")
    assert not [r for r in caplog.records if "GET /" in r.getMessage()]  # no line per request (the guide prints)


def _post(url: str) -> None:
    urllib.request.urlopen(urllib.request.Request(url, method="POST"), timeout=5).close()


def test_a_closed_tab_is_gone_and_a_reloaded_one_is_not(monkeypatch):
    """A load of the page's ``pagehide`` beacon (``POST /left``) followed by another load's poll is a reload: the person
    still sees the page; followed by silence for ``RELOAD_GRACE_S``, the tab was closed: ``gone`` says so and ends
    ``wait_closed``. A poll of the closed load that reaches the server after its beacon (in flight when the tab
    closed) does not bring it back."""
    monkeypatch.setattr(page_module, "RELOAD_GRACE_S", 0.3)
    page = GuidePage(CameraModel.from_hfov(1.0, 640, 480), Target.aprilgrid(), PageSettings(port=0))
    try:
        _get(page.url + "/state.json?page=a")
        assert page.gone() is None
        _post(page.url + "/left?page=a")
        _get(page.url + "/state.json?page=b")  # the reloaded page polls
        time.sleep(0.4)
        assert page.gone() is None and not page.wait_closed(0.1)
        _post(page.url + "/left?page=b")
        _get(page.url + "/state.json?page=b")  # its last poll, in flight as the tab closed
        assert page.gone() is None  # within the grace: it may still be reloading
        started = time.monotonic()
        assert page.wait_closed(5.0) and time.monotonic() - started < 2.0
        assert page.gone() == "the guide's page was closed"
    finally:
        page.close()


def test_a_tab_closed_beside_another_open_one_leaves_the_person_watching(monkeypatch):
    monkeypatch.setattr(page_module, "RELOAD_GRACE_S", 0.1)
    page = GuidePage(CameraModel.from_hfov(1.0, 640, 480), Target.aprilgrid(), PageSettings(port=0))
    try:
        for load in ("a", "b"):
            _get(page.url + f"/state.json?page={load}")
        _post(page.url + "/left?page=a")
        time.sleep(0.2)
        assert page.gone() is None
        _post(page.url + "/left?page=b")
        time.sleep(0.2)
        assert page.gone() == "the guide's page was closed"
    finally:
        page.close()


@pytest.mark.parametrize("viewed", [True, False])
def test_while_the_planner_decides_a_viewed_sensor_streams_on_and_an_unviewed_simulation_waits(viewed):
    """The guide's planner decides in a worker thread while the loop reads the sensor for a viewer (the page's live
    image): frames are shown during every decision and the simulated person's clock moves on (holding still while
    the guide thinks). Without a viewer a simulated sensor is not read while the planner decides: its clock stands,
    so a comparison's result does not depend on how fast the machine decides."""
    cfg = config("out=unused", "person.images=false", "page.enabled=false", "progress=false", "limits.max_steps=2",
                 "seed=3")  # fmt: skip
    s = check_settings(cfg)
    policy = configured_policy(cfg, "joint", "planner")
    mdp = guided_mdp(cfg, policy)
    rig = build_robot(cfg.person, "person")
    decisions, shown = [], []
    act = policy.act

    def timed_act(observation, episode):
        started, sim_before = time.perf_counter(), rig.sim.time_ns
        action = act(observation, episode)
        decisions.append((started, time.perf_counter(), sim_before, rig.sim.time_ns))
        return action

    policy.act = timed_act
    try:
        guide_ = build_guide(cfg, s, rig, policy, mdp, nominal_sensor(s, rig), None, None, lambda line: None)
        if viewed:
            guide_.stream.viewer = lambda frame, corners, ids: shown.append(time.perf_counter())
        result = guide_.run(3)
    finally:
        rig.close()
    assert result.steps == 2 and len(decisions) == 2
    for started, ended, sim_before, sim_after in decisions:
        if viewed:
            assert sum(started <= t <= ended for t in shown) >= 1 and sim_after > sim_before
        else:
            assert sim_after == sim_before
    assert result.decision_s >= sum(ended - started for started, ended, _, _ in decisions)


@pytest.mark.integration
def test_the_guide_runs_headless_records_and_calibrates(tmp_path, capsys):
    """A simulated person guided by the default policy for 6 poses, without the page: the instructions as lines, the
    recording as EuRoC (images and IMU), the summary, and the calibration of the recording."""
    out = tmp_path / "out"
    status = guide(config(f"out={out}", "page.enabled=false", "limits.max_steps=6", "report=false", "seed=3"))
    lines = capsys.readouterr().out
    assert status == 0
    assert lines.count("next: ") == 7  # the start pose and six steps
    assert "started 0.72 m before the board" in lines and "calibrating the recording" in lines
    target = read_target_yaml(out / "target.yaml")
    rec = read_euroc(out / "recording", target)
    assert len(rec.frames) > 100 and len(rec.imu) > 1000 and rec.frames.images is not None
    summary = (out / "collect.yaml").read_text()
    assert "steps: 6" in summary and "done: the step limit" in summary
    camera, T_cam_imu, _ = read_camchain(out / "calibration" / "camchain-imucam.yaml")
    assert T_cam_imu is not None and camera.width == rec.frames.images.shape[2]


@pytest.mark.integration
def test_a_disk_that_takes_no_more_stops_the_guide_with_one_line_and_a_calibratable_recording(tmp_path):
    """No file may grow past 450 kB (the detections' CSV reaches it first, at ~10 s): the guide stops with status 1
    and one line that says so, and what it recorded before calibrates."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "vical.apps.guide", f"out={out}", "page.enabled=false", "limits.max_steps=20",
           "report=false", "seed=3"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, preexec_fn=file_size_limit(450_000))
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    (line,) = [line for line in done.stderr.splitlines() if line.startswith("vical-guide")]
    assert line.startswith(f"vical-guide: error: stopped: {out / 'recording'}: the disk took no more (")
    assert "File too large; is it full?)" in line and "the recording so far is in" in line
    assert "stopped: " in (out / "collect.yaml").read_text()
    assert len(read_euroc(out / "recording", read_target_yaml(out / "target.yaml")).frames) >= 80
    assert calibrate_joint(out, tmp_path / "cal") == 0


@pytest.mark.integration
@pytest.mark.parametrize(
    ("fault", "stopped"),
    [
        (["person.faults.imu_gap=[20.0,1000.0]", "limits.wait_timeout=1"],
         "stopped: no IMU samples for 1 s while the camera streams"),
        (["person.faults.lens_covered=[20.0,1000.0]", "limits.lost_frames=10"],
         "stopped: the board was out of view for 10 frames in a row; check the lighting"),
    ],
    ids=["lost sensor", "lost board"],
)  # fmt: skip
def test_a_sensor_or_board_lost_during_the_guidance_stops_it_with_one_line_and_a_calibratable_recording(
    tmp_path, capsys, fault, stopped
):
    """20 s after the simulated sensor started, its IMU stops (a pulled cable), or its frames come dark (a finger on
    the lens): the guide stops once it has heard no IMU for ``limits.wait_timeout`` (1 s here), or seen no board in
    ``limits.lost_frames`` frames (10 here), with status 1 and one line saying which, and the recording so far
    calibrates."""
    out = tmp_path / "out"
    status = guide(config(f"out={out}", "page.enabled=false", "report=false", "seed=3", *fault))
    err = capsys.readouterr().err
    assert status == 1
    (line,) = [line for line in err.splitlines() if line.startswith("vical-guide")]
    assert line.startswith(f"vical-guide: error: {stopped}")
    assert f"the recording so far is in {out / 'recording'}" in line
    assert yaml.safe_load((out / "collect.yaml").read_text())["outcome"].startswith(stopped)
    assert len(read_euroc(out / "recording", read_target_yaml(out / "target.yaml")).frames) >= 80
    assert calibrate_joint(out, tmp_path / "cal") == 0


def test_a_board_never_seen_stops_the_guide_before_it_records_in_one_line(tmp_path, capsys):
    """The lens is covered from the start: the guide cannot find the board in its first rest, says so in one line with
    what to do, records nothing and says that too."""
    out = tmp_path / "out"
    status = guide(config(f"out={out}", "page.enabled=false", "seed=3", "person.faults.lens_covered=[0.0,1000.0]"))
    err = capsys.readouterr().err
    assert status == 1
    (line,) = [line for line in err.splitlines() if line.startswith("vical-guide")]
    assert line == (
        "vical-guide: error: stopped: the board was not seen in the first 1 s; hold the sensor so that the whole "
        f"board is in view, then start again; no frame was recorded ({out / 'recording'}): nothing to calibrate"
    )


@pytest.mark.parametrize(
    ("fault", "stopped"),
    [
        ("person.faults.camera_gap=[0.0,1000.0]",
         "no camera images in the first 1 s while the IMU streams; check that the sensor's camera is enabled and "
         "publishes (ROS: the image topic)"),
        ("person.faults.imu_gap=[0.0,1000.0]",
         "no IMU samples for 1 s while the camera streams (limits.wait_timeout); check that the sensor's IMU is "
         "enabled and publishes (RealSense: a model with an IMU; ROS: the IMU topic)"),
    ],
    ids=["no images", "no IMU"],
)  # fmt: skip
def test_a_sensor_that_delivers_no_images_or_no_imu_stops_the_guide_before_it_records_naming_the_stream(
    tmp_path, capsys, fault, stopped
):
    """A camera that sends nothing is not a board out of view: the line names the silent stream and what to check."""
    out = tmp_path / "out"
    status = guide(config(f"out={out}", "page.enabled=false", "seed=3", "limits.wait_timeout=1", fault))
    err = capsys.readouterr().err
    assert status == 1
    (line,) = [line for line in err.splitlines() if line.startswith("vical-guide")]
    assert line == (
        f"vical-guide: error: stopped: {stopped}; no frame was recorded ({out / 'recording'}): nothing to calibrate"
    )
    assert yaml.safe_load((out / "collect.yaml").read_text())["outcome"] == f"stopped: {stopped}"


@pytest.mark.integration
@pytest.mark.parametrize(("sig", "status", "name"), [(signal.SIGINT, 130, "Ctrl-C"), (signal.SIGTERM, 143, "SIGTERM")])
def test_an_interrupted_guide_says_so_in_one_line_and_keeps_a_calibratable_recording(tmp_path, sig, status, name):
    """A real signal after the third pose, with the page on (the planner decides in a worker thread while the guide
    reads): status 130 / 143, one line saying where the recording is, and the recording so far calibrates."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "vical.apps.guide", f"out={out}", "page.port=0", "page.linger=0", "seed=3"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)
    try:
        for line in proc.stdout:
            if line.startswith("step 3:"):
                break
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        kill_if_running(proc)
    assert proc.returncode == status, err
    (line,) = [line for line in err.splitlines() if line.startswith("vical-guide")]
    assert line.startswith(f"vical-guide: interrupted ({name}): the recording so far is in {out / 'recording'} ("), line
    assert "Traceback" not in err and f"interrupted ({name})" in (out / "collect.yaml").read_text()
    assert len(read_euroc(out / "recording", read_target_yaml(out / "target.yaml")).frames) >= 80
    assert calibrate_joint(out, tmp_path / "cal") == 0


@pytest.fixture
def rosbridge_replay():
    """``tests/rosbridge_replay.py`` serving a bag: a function of the bag's path that returns the port it listens on."""
    servers = []

    def serve(bag):
        script = Path(__file__).with_name("rosbridge_replay.py")
        server = subprocess.Popen([sys.executable, str(script), str(bag)], stdout=subprocess.PIPE, text=True)
        servers.append(server)
        first = server.stdout.readline()
        assert first.startswith("port "), first
        return int(first.split()[1])

    yield serve
    for server in servers:
        server.terminate()
        server.wait(timeout=10)


@pytest.mark.integration
def test_the_guide_reads_a_recorded_sensor_stream_over_ros(tmp_path, capsys, rosbridge_replay):
    """``person=ros`` against a recorded stream: a simulated person's guided recording (rendered images, IMU) as a
    ROS1 bag, played in real time by a rosbridge server, read by the ROS adapter through roslibpy. The guide starts
    on it, gives its instructions (the recording does not follow them: each pose is taken where the sensor rests),
    records what it reads (every image and IMU sample as the bag holds them) and calibrates, with the first
    recording's calibration as the nominal values a user would pass. Both runs use the learned person's policy: it
    decides at once, so what the guide reads of the real-time replay does not depend on a planner's decision time."""
    first = tmp_path / "first"
    policy = "policy=learned_person"
    first_run = [f"out={first}", policy, "page.enabled=false", "limits.max_steps=10", "report=false", "seed=3"]
    assert guide(config(*first_run)) == 0
    recorded = read_euroc(first / "recording", read_target_yaml(first / "target.yaml"))
    bag = write_bag(recorded, tmp_path / "sensor.bag")
    port = rosbridge_replay(bag)
    capsys.readouterr()

    out = tmp_path / "ros"
    status = guide(config(
        f"out={out}", "person=ros", f"person.port={port}", "person.sensor.image_topic=/cam0/image_raw",
        "person.sensor.imu_topic=/imu0", "person.sensor.camera_rate_hz=10", "limits.max_steps=3", "report=false",
        f"guess.camchain={first / 'calibration' / 'camchain-imucam.yaml'}", f"guess.imu_yaml={first / 'imu.yaml'}",
        "page.enabled=false", policy))  # fmt: skip
    lines = capsys.readouterr().out
    assert status == 0, lines
    assert "started 0." in lines and lines.count("next: ") == 4  # the start pose and three steps
    assert "steps: 3" in (out / "collect.yaml").read_text()
    read = read_euroc(out / "recording", read_target_yaml(out / "target.yaml"))
    assert len(read.frames) >= 30 and len(read.imu) >= 600
    # What the guide recorded is the bag's stream, unchanged: the same stamps, images and IMU readings.
    frame_at = {int(t): k for k, t in enumerate(recorded.frames.t)}
    for k in range(0, len(read.frames), 7):
        np.testing.assert_array_equal(read.frames.images[k], recorded.frames.images[frame_at[int(read.frames.t[k])]])
    imu_at = np.searchsorted(recorded.imu.t, read.imu.t)
    np.testing.assert_array_equal(recorded.imu.t[imu_at], read.imu.t)
    np.testing.assert_allclose(read.imu.gyro, recorded.imu.gyro[imu_at], atol=1e-12)
    np.testing.assert_allclose(read.imu.accel, recorded.imu.accel[imu_at], atol=1e-12)
    # Its calibration of the part it read agrees with the whole recording's within a few of its sigma.
    _, T_first, _ = read_camchain(first / "calibration" / "camchain-imucam.yaml")
    _, T_ros, _ = read_camchain(out / "calibration" / "camchain-imucam.yaml")
    assert np.linalg.norm(T_ros[:3, 3] - T_first[:3, 3]) < 0.01


@pytest.mark.integration
def test_a_tolerance_out_of_reach_within_the_time_limit_stops_the_guide_saying_which_group_and_why(tmp_path, capsys):
    """A tuning sensor with a 5.3x-noise IMU (sensor=practitioner, seed 40000) held by the simulated person: its time
    offset cannot reach 0.1 ms within 40 s; the person is told to stop, and why, instead of holding on to the limit."""
    out = tmp_path / "out"
    args = [f"out={out}", "page.enabled=false", "sensor=practitioner", "seed=40000", "limits.time_limit=40",
            "calibrate=false"]  # fmt: skip
    assert guide(config(*args)) == 0
    summary = yaml.safe_load((out / "collect.yaml").read_text())
    verdict = summary["out_of_reach"]
    assert not summary["goal_reached"] and summary["duration_s"] < 40 and verdict["horizon_s"] == 40
    assert summary["outcome"] == f"done: out of reach: {verdict['reason']}"
    captured = capsys.readouterr()
    assert f"stopped at out of reach: {verdict['reason']}: " in captured.out
    assert "goal at ~" in captured.out  # each step's line: when the goal is due at this rate
    assert f"vical-guide: out of reach: {verdict['reason']} (collect.yaml: out_of_reach)" in captured.err
