"""vical-guide: settings refused by key, the page's state, image and files over HTTP, and a headless guided run with a
simulated person that records and calibrates. The page in a real browser: tests/test_guide_page.py."""

import json
import logging
import socket
import subprocess
import sys
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from stopped_collections import calibrate_joint, file_size_limit

from vical.apps.guide import CONF_DIR, check_settings, guide
from vical.collection.page import GuidePage, PageSettings
from vical.config_checks import ConfigError
from vical.data import Target
from vical.geometry import T_CAM_BODY, CameraModel, make_transform
from vical.io.euroc import read_euroc
from vical.io.kalibr import read_camchain, read_target_yaml
from vical.policies.learned import PAPER_POLICY_DIR
from vical.robot import CameraDetections, CameraImage, Guidance


def config(*overrides: str):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(config_name="guide", overrides=list(overrides))


def test_bad_settings_are_refused_by_key(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    out = f"out={tmp_path / 'o'}"
    with pytest.raises(FileExistsError, match="already exists"):
        check_settings(config(f"out={tmp_path / 'full'}"))
    for override, message in [
        ("start.distance=0", r"start\.distance must be a number in \(0"),
        ("arrival.patience_s=0", r"arrival\.patience_s must be a number in \(0"),
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
    with pytest.raises(ConfigError, match=r"^person: .*roslibpy package: pip install 'vical\[ros\]'"):
        guide(config(out, "person=ros", "guess.camchain=null"))
    with pytest.raises(ConfigError, match=r"^person: faults: a held sensor's faults are \['imu_gap', 'camera_gap'\]"):
        guide(config(out, "+person.faults.latency=0.1"))
    # A policy trained for another state layout and workspace (the paper's coverage state): refused before it runs.
    with pytest.raises(ConfigError) as refused:
        guide(config(out, f"policy.run_dir={PAPER_POLICY_DIR}"))
    assert "\n" not in str(refused.value) and "trained in workspace 'paper'" in str(refused.value)
    assert not (tmp_path / "o").exists()


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
        urllib.request.urlopen(urllib.request.Request(page.url + "/close", method="POST"), timeout=5).close()
        assert page.wait_closed(1.0)
    finally:
        page.close()
    with pytest.raises(urllib.error.URLError):
        _get(page.url + "/state.json")
    assert not [r for r in caplog.records if "GET /" in r.getMessage()]  # no line per request (the guide prints)


def test_the_guide_runs_headless_records_and_calibrates(tmp_path, capsys):
    """A simulated person guided by the shipped policy for 6 poses, without the page: the instructions as lines, the
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
def test_a_sensor_lost_during_the_guidance_stops_it_with_one_line_and_a_calibratable_recording(tmp_path, capsys):
    """The simulated sensor's IMU stops 20 s after it started (a pulled cable): the guide stops once it has heard
    nothing for ``limits.wait_timeout`` (1 s here), with status 1 and one line naming the silent stream, and the
    recording so far calibrates."""
    out = tmp_path / "out"
    status = guide(config(f"out={out}", "page.enabled=false", "report=false", "seed=3", "limits.wait_timeout=1",
                          "person.faults.imu_gap=[20.0,1000.0]"))  # fmt: skip
    err = capsys.readouterr().err
    assert status == 1
    (line,) = [line for line in err.splitlines() if line.startswith("vical-guide")]
    assert line.startswith("vical-guide: error: stopped: no IMU samples for 1 s while the camera streams")
    assert f"the recording so far is in {out / 'recording'}" in line
    assert "stopped: no IMU samples" in (out / "collect.yaml").read_text()
    assert len(read_euroc(out / "recording", read_target_yaml(out / "target.yaml")).frames) >= 80
    assert calibrate_joint(out, tmp_path / "cal") == 0
