"""vical-calibrate on a stereo rig: a simulated cam0 + cam1 + IMU written as an EuRoC folder, calibrated end to
end by ``main([...])``, the camchain read back and compared with the truth; ``--cameras``, Kalibr camchains kept
whole, bag topics, and the bad inputs refused in one line naming the file, flag and camera.

The EuRoC folder's images are blank: its corners come from ``camN/corners.csv`` (``--stored-corners``), the
synthetic projections with 0.2 px noise, so no image is rendered (detection is tested in
``tests/test_app_calibrate_sources.py``). Tolerances are 4 of the 1-sigma that the same calibration reports
(run in memory on the same corners); the relative pose ``T_cn_cnm1`` is bounded by the two cameras' sigmas
combined (its errors are those of the two ``T_cam_imu``, partly cancelling: the IMU's errors are common).
"""

from __future__ import annotations

import csv
import shutil
from dataclasses import replace

import numpy as np
import pytest
from test_calib_report import pdf_pages_and_text

from vical.apps.calibrate import main
from vical.apps.calibrate_rig import camera_list, image_topics, topic_list
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.pipeline import calibrate_rig
from vical.calib.synthetic import Excitation, RigCamera, default_camera, make_recording
from vical.data import CameraFrames, ImuNoise, ImuSamples
from vical.geometry import euler_to_matrix, make_transform, transform_error
from vical.io import save_recording, write_bag, write_euroc, write_imu_yaml, write_target_yaml
from vical.io.errors import FormatError
from vical.io.kalibr_chain import CameraChain, ChainCamera, read_chain, write_chain
from vical.io.sources import open_recording
from vical.io.yamlfile import dump_yaml, load_mapping

T_C1_C0 = make_transform(euler_to_matrix([0.02, -0.03, 0.01]), [-0.06, 0.002, 0.001])  # a 6 cm stereo baseline
CAM1 = default_camera().with_intrinsics(470.0, 468.0, 325.0, 236.0, [-0.04, 0.015, 0.0005, 0.0002])


def stereo_recording(duration: float):
    """A stereo rig + IMU (cam1 2 ms later than cam0), with blank images so that it can be written as EuRoC."""
    rig = {"cam1": RigCamera(CAM1, T_C1_C0 @ nominal_T_cam_imu(), 0.006)}
    rec = make_recording(duration, time_offset=0.004, imu_noise=ImuNoise(), pixel_sigma=0.2, other_cameras=rig, seed=3)

    def blank(frames):
        return replace(frames, images=np.zeros((len(frames), 480, 640), np.uint8))

    return replace(rec, frames=blank(rec.frames), other_frames={n: blank(f) for n, f in rec.other_frames.items()})


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    rec = stereo_recording(8.0)
    root = tmp_path_factory.mktemp("rig")
    write_euroc(rec, root / "euroc")
    write_target_yaml(root / "target.yaml", rec.target)
    write_imu_yaml(root / "imu.yaml", rec.truth.imu_noise, rostopic="/imu/data", comment="the bench IMU")
    argv = [str(root / "euroc"), "--target", str(root / "target.yaml"), "--imu-yaml", str(root / "imu.yaml")]
    return rec, root, [*argv, "--stored-corners"]


@pytest.fixture(scope="module")
def in_memory(rig):
    rec = rig[0]
    frames = {name: rec.frames_of(name) for name in rec.camera_names}
    sizes = dict.fromkeys(rec.camera_names, (640, 480))
    return calibrate_rig(frames, rec.imu, rec.target, "joint", image_sizes=sizes, imu_noise=rec.truth.imu_noise)


def errors(stderr: str) -> list[str]:
    """The error lines on stderr (without the progress bars of the image decoding)."""
    return [line for line in stderr.replace("\r", "\n").splitlines() if line.startswith("vical-calibrate: error")]


def rotation_deg(T, T_true) -> float:
    return float(np.rad2deg(transform_error(T, T_true)[0]))


def translation_error(T, T_true) -> np.ndarray:
    return np.abs(T[:3, 3] - T_true[:3, 3])


def test_stereo_rig_joint_from_euroc_matches_the_truth(rig, in_memory, tmp_path, capsys):
    rec, _, argv = rig
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 0
    chain = read_chain(out / "camchain-imucam.yaml")
    assert chain.names == ["cam0", "cam1"]
    for name in ("cam0", "cam1"):
        written, truth, reported = chain[name], rec.truth_of(name), in_memory.results[name]
        t_sigma = np.array([reported.sigma(f"t_{a}") for a in "xyz"])
        rot_sigma = np.rad2deg(np.linalg.norm([reported.sigma(f"rot_{a}") for a in "xyz"]))
        # measured 0.04 deg, up to 1.0 mm (cam0) / 0.5 mm (cam1), 0.10 / 0.06 ms; 1-sigma 0.06 deg, 0.85-0.98 mm, 0.1 ms
        assert rotation_deg(written.T_cam_imu, truth.T_cam_imu) < 4 * rot_sigma, name
        assert np.all(translation_error(written.T_cam_imu, truth.T_cam_imu) < 4 * t_sigma), name
        assert abs(written.timeshift_cam_imu - truth.time_offset) < 4 * reported.sigma("time_offset"), name
        intrinsic_sigma = np.array([reported.sigma(k) for k in ("fx", "fy", "cx", "cy")])
        assert np.all(np.abs(written.camera.intrinsics - truth.camera.intrinsics) < 4 * intrinsic_sigma), name
        assert written.rostopic == f"/{name}/image_raw"
    assert chain["cam0"].cam_overlaps == (1,) and chain["cam1"].cam_overlaps == (0,)  # they saw the board together

    sigma0, sigma1 = in_memory.results["cam0"], in_memory.results["cam1"]
    combined_t = np.hypot([sigma0.sigma(f"t_{a}") for a in "xyz"], [sigma1.sigma(f"t_{a}") for a in "xyz"])
    combined_rot = np.rad2deg(
        np.linalg.norm([np.hypot(sigma0.sigma(k), sigma1.sigma(k)) for k in ("rot_x", "rot_y", "rot_z")])
    )
    # measured 0.075 deg, up to 0.39 mm; combined 1-sigma 0.094 deg, 1.2-1.35 mm per axis
    assert rotation_deg(chain["cam1"].T_cn_cnm1, T_C1_C0) < 4 * combined_rot
    assert np.all(translation_error(chain["cam1"].T_cn_cnm1, T_C1_C0) < 4 * combined_t)

    text = (out / "results.txt").read_text()
    assert text.startswith("vical rig calibration results: task joint, cameras cam0, cam1")
    assert "==== cam0 ====" in text and "==== cam1 ====" in text and "  cam1 <- cam0:" in text
    assert "time offset cam1 - cam0 [ms]: 1.9" in text  # the truth: 2 ms
    for name in ("cam0", "cam1"):
        assert (out / name / "report.pdf").read_bytes().startswith(b"%PDF")
        assert (out / name / "reprojection.png").stat().st_size > 1000
    printed = capsys.readouterr().out
    assert "== cam0 ==" in printed and "== cam1 ==" in printed and "T_cn_cnm1 cam1 <- cam0: translation" in printed
    assert "baseline 60.0" in printed  # 6 cm, to 0.1 mm


def test_a_rig_writes_each_cameras_frames_and_its_errors_against_the_truth_in_its_report(rig, tmp_path, capsys):
    rec, root, argv = rig
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 0
    assert load_mapping(out / "imu.yaml", ValueError) == load_mapping(root / "imu.yaml", ValueError)  # its rostopic
    printed = capsys.readouterr().out
    text = (out / "results.txt").read_text()
    for name in ("cam0", "cam1"):
        frames = rec.frames_of(name)
        with open(out / name / "frames.csv") as f:
            rows = list(csv.DictReader(f))
        assert [int(r["timestamp_ns"]) for r in rows] == frames.t.tolist(), name
        assert [int(r["corners_found"]) for r in rows] == frames.num_detections.tolist(), name
        used = sum(int(r["corners_used"]) for r in rows)
        assert f"frames: {len(frames)} frames, the board detected in" in printed
        assert f"({used} of {frames.num_detections.sum()} corners)" in printed
        assert f"(every frame with its reason: {out / name / 'frames.csv'})" in printed
        # the report's first page has the errors that results.txt gives ("ff" is one glyph in the PDF: left out)
        section = text.split(f"==================== {name} ====================\n")[1]
        truth = section.split("errors against the truth:\n")[1].splitlines()[:2]  # intrinsic, extrinsic
        _, shown = pdf_pages_and_text(out / name / "report.pdf")
        shown = " ".join(shown.split())
        assert "errors against the truth" in shown
        for line in truth:
            assert " ".join(line.split()) in shown, (name, line)


def test_one_named_camera_is_calibrated_alone_as_the_chains_first(rig, tmp_path):
    rec, _, argv = rig
    out = tmp_path / "out"
    assert main([*argv, "--cameras", "cam1", "--out", str(out), "--no-report"]) == 0
    chain = read_chain(out / "camchain-imucam.yaml")
    assert chain.names == ["cam0"]  # Kalibr numbers the calibrated cameras; the rostopic names which it is
    (written,) = chain.cameras
    assert written.rostopic == "/cam1/image_raw"
    assert written.camera.fx == pytest.approx(470.0, abs=1.5)  # cam1's, not cam0's 600
    truth = rec.truth_of("cam1")
    assert rotation_deg(written.T_cam_imu, truth.T_cam_imu) < 0.2  # measured 0.04 deg, 0.3 mm, 0.12 ms (1-sigma 0.1 ms)
    assert np.all(translation_error(written.T_cam_imu, truth.T_cam_imu) < 0.004)
    assert written.timeshift_cam_imu == pytest.approx(0.006, abs=4e-4)
    text = (out / "results.txt").read_text()
    assert "cameras cam1" in text and "written to the camchain as cam0" in text and "==== cam0" not in text


def test_a_chain_of_more_cameras_gives_the_chosen_camera_its_section(rig, tmp_path):
    """--cameras cam0 with a stereo camchain: cam0's section is used, cam1's neither read nor looked for (its
    resolution, which cam1's images contradict here, is not checked)."""
    rec, _, argv = rig
    chain = tmp_path / "stereo.yaml"
    kalibr_camchain(rec, chain, T_C1_C0, sizes=((640, 480), (1280, 960)))
    out = tmp_path / "out"
    assert main([*argv, "--cameras", "cam0", "--task", "extrinsic", "--intrinsics", str(chain), "--out", str(out),
                 "--no-report"]) == 0  # fmt: skip
    (written,) = read_chain(out / "camchain-imucam.yaml").cameras
    assert written.camera.fx == pytest.approx(rec.truth.camera.fx, rel=1e-12)  # the given intrinsics, kept
    assert rotation_deg(written.T_cam_imu, rec.truth.T_cam_imu) < 0.2


def kalibr_camchain(rec, path, T_cn_cnm1, sizes=((640, 480), (640, 480))) -> None:
    """A Kalibr ``kalibr_calibrate_cameras`` camchain of the rig's true intrinsics (the layout Kalibr documents),
    with a key vical does not know per camera and at the top."""
    data = {}
    for k, name in enumerate(rec.camera_names):
        camera = rec.truth_of(name).camera
        data[name] = {
            "camera_model": "pinhole",
            "intrinsics": camera.intrinsics.tolist(),
            "distortion_model": "radtan",
            "distortion_coeffs": camera.dist.tolist(),
            "resolution": list(sizes[k]),
            "rostopic": f"/stereo/{'left' if k == 0 else 'right'}/image_raw",
            "cam_overlaps": [1 - k],
            "exposure_group": "front",
        }
    data["cam1"]["T_cn_cnm1"] = T_cn_cnm1.tolist()
    data["rig_name"] = "bench stereo"
    dump_yaml(path, data)


def test_extrinsic_with_a_kalibr_stereo_camchain_keeps_every_key_and_recomputes_T_cn_cnm1(rig, tmp_path):
    rec, root, argv = rig
    given = root / "kalibr-camchain.yaml"
    off_by_a_cm = make_transform(T_C1_C0[:3, :3], T_C1_C0[:3, 3] + [0.01, 0.0, 0.0])
    kalibr_camchain(rec, given, off_by_a_cm)
    out = tmp_path / "out"
    assert main([*argv, "--task", "extrinsic", "--intrinsics", str(given), "--out", str(out), "--no-report"]) == 0
    data = load_mapping(out / "camchain-imucam.yaml", ValueError)
    assert data["rig_name"] == "bench stereo"
    for k, name in enumerate(("cam0", "cam1")):
        assert data[name]["exposure_group"] == "front" and data[name]["cam_overlaps"] == [1 - k]
        assert data[name]["rostopic"] == f"/stereo/{'left' if k == 0 else 'right'}/image_raw"
        assert data[name]["intrinsics"] == rec.truth_of(name).camera.intrinsics.tolist()  # known, kept exactly
    chain = read_chain(out / "camchain-imucam.yaml")  # its T_cn_cnm1 agrees with the T_cam_imu (read_chain checks)
    # the calibrated relative pose, not the given one 10 mm off: measured 0.12 mm from the truth
    assert np.all(translation_error(chain["cam1"].T_cn_cnm1, T_C1_C0) < 0.002)
    for name in ("cam0", "cam1"):
        assert rotation_deg(chain[name].T_cam_imu, rec.truth_of(name).T_cam_imu) < 0.2, name


def test_intrinsic_task_calibrates_each_camera_and_keeps_the_given_relative_pose(rig, tmp_path):
    rec, root, argv = rig
    given = root / "kalibr-intrinsic.yaml"
    kalibr_camchain(rec, given, T_C1_C0)
    out = tmp_path / "out"
    assert main([*argv, "--task", "intrinsic", "--intrinsics", str(given), "--out", str(out), "--no-report"]) == 0
    chain = read_chain(out / "camchain.yaml")
    for name in ("cam0", "cam1"):
        # measured 0.2-0.5 px from the truth (1-sigma 0.26-0.4 px)
        assert np.abs(chain[name].camera.intrinsics - rec.truth_of(name).camera.intrinsics).max() < 2.0, name
        assert chain[name].T_cam_imu is None
    np.testing.assert_allclose(chain["cam1"].T_cn_cnm1, T_C1_C0, atol=1e-12)  # not estimated: kept as given
    assert "relative poses" in (out / "results.txt").read_text()


def test_an_euroc_folder_read_for_some_cameras_decodes_only_theirs(rig, tmp_path):
    """cam0 (the recording's first camera) and those named: cam1's images are never opened (a broken one would
    fail the read)."""
    rec, root, _ = rig
    copy = tmp_path / "euroc"
    shutil.copytree(root / "euroc", copy)
    image = next((copy / "mav0" / "cam1" / "data").glob("*.png"))
    image.write_bytes(b"not an image")
    read = open_recording(copy, rec.target, cameras=["cam0"])
    assert read.camera_names == ["cam0"] and len(read.frames) == len(rec.frames)
    with pytest.raises(FormatError, match=image.name):
        open_recording(copy, rec.target, cameras=["cam1"])


def test_bad_rig_inputs_fail_in_one_line_naming_the_file_and_camera(rig, tmp_path, capsys):
    rec, root, argv = rig

    def error(*extra: str) -> str:
        assert main([*argv, *extra, "--out", str(tmp_path / "out")]) == 2
        (line,) = errors(capsys.readouterr().err)
        assert not (tmp_path / "out").exists()
        return line

    assert f"--cameras names cam2, but {root / 'euroc'} has cam0, cam1 (its camN folders)" in error(
        "--cameras", "cam0,cam2"
    )
    assert "argument --cameras: must name cameras as Kalibr does, e.g. cam0,cam1; got 'left'" in error(
        "--cameras", "left"
    )
    assert "argument --cameras: names a camera twice" in error("--cameras", "cam1,cam1")

    three = root / "three.yaml"
    cameras = [ChainCamera(f"cam{k}", rec.truth.camera) for k in range(3)]
    write_chain(three, CameraChain(tuple(cameras)))
    assert f"{three} names cam2, but the recording has only cam0, cam1" in error("--intrinsics", str(three))

    big = root / "big.yaml"
    kalibr_camchain(rec, big, T_C1_C0, sizes=((640, 480), (1280, 960)))
    line = error("--task", "extrinsic", "--intrinsics", str(big))
    assert f"{big} [cam1]: resolution 1280 x 960 px, but cam1's images are 640 x 480 px" in line

    flat = root / "euroc" / "mav0" / "cam0" / "sensor.yaml"  # EuRoC's: one camera, no cam0 section
    line = error("--intrinsics", str(flat))
    assert f"--intrinsics {flat} describes one camera without a camN section; calibrating cam0, cam1 needs" in line

    one = root / "one.yaml"
    write_chain(one, CameraChain((ChainCamera("cam0", rec.truth.camera),)))
    line = error("--task", "extrinsic", "--intrinsics", str(one))
    assert (
        f"the extrinsic task needs the intrinsics of every camera it calibrates (cam0, cam1), but "
        f"--intrinsics {one} has no cam1" in line
    )
    assert "--cameras" in line


@pytest.fixture(scope="module")
def stereo_bag(tmp_path_factory):
    """A short stereo bag on /left/image_raw and /right/image_raw (blank images: only its topics are read here)."""
    rec = stereo_recording(1.0)
    root = tmp_path_factory.mktemp("bag")
    write_bag(rec, root / "rig.bag", image_topic=["/left/image_raw", "/right/image_raw"])
    write_target_yaml(root / "target.yaml", rec.target)
    return rec, root


def test_bag_topics_come_from_image_topic_or_the_camchain(stereo_bag, tmp_path, capsys):
    rec, root = stereo_bag
    bag, target = str(root / "rig.bag"), str(root / "target.yaml")
    given = root / "camchain.yaml"
    cameras = [
        ChainCamera(n, rec.truth_of(n).camera, rostopic=f"/{s}/image_raw")
        for n, s in (("cam0", "left"), ("cam1", "right"))
    ]
    write_chain(given, CameraChain(tuple(cameras)))
    # each way of naming the topics reads both cameras: the --cameras error then lists them
    for topics in (
        ["--image-topic", "/left/image_raw,/right/image_raw"],
        ["--image-topic", "/left/image_raw", "--image-topic", "/right/image_raw"],
        ["--intrinsics", str(given)],
    ):
        assert main([bag, "--target", target, *topics, "--cameras", "cam3", "--out", str(tmp_path / "o")]) == 2
        assert f"--cameras names cam3, but {bag} has cam0, cam1 (one per image topic" in capsys.readouterr().err

    wrong = root / "wrong.yaml"
    write_chain(wrong, CameraChain((cameras[0], replace(cameras[1], rostopic="/cam1/image_raw"))))
    assert main([bag, "--target", target, "--intrinsics", str(wrong), "--out", str(tmp_path / "o")]) == 2
    (line,) = errors(capsys.readouterr().err)
    assert f"--intrinsics {wrong} [cam1]: rostopic /cam1/image_raw is not an image topic of {bag}" in line
    assert "(it has /left/image_raw, /right/image_raw); give the bag's image topics with --image-topic" in line


def test_topics_and_camera_names_parse_as_documented():
    assert topic_list(["/a,/b", " /c "]) == ["/a", "/b", "/c"]
    assert topic_list(None) == []
    assert camera_list("cam2, cam0") == ["cam0", "cam2"]
    assert image_topics([], None, None) == ["/cam0/image_raw"]  # the one-camera default, as before
    assert image_topics([], None, ["cam1"]) == ["/cam0/image_raw", "/cam1/image_raw"]
    chain = CameraChain((ChainCamera("cam0", default_camera(), rostopic="/left"),))
    assert image_topics([], chain, ["cam0", "cam1"]) == ["/left"]  # the --cameras error then says cam1 is missing
    assert image_topics(["/x"], chain, None) == ["/x"]


def test_a_rig_whose_gyro_logs_deg_per_s_fails_naming_the_cameras_and_the_flag(tmp_path, capsys):
    rig = {"cam1": RigCamera(CAM1, T_C1_C0 @ nominal_T_cam_imu(), 0.006)}
    slow = Excitation().scaled(rotation=0.3)  # peaks under the readers' 35 rad/s check even in deg/s
    rec = make_recording(5.0, imu_noise=ImuNoise(), pixel_sigma=0.2, other_cameras=rig, excitation=slow, seed=3)
    rec = replace(rec, imu=ImuSamples(rec.imu.t, np.degrees(rec.imu.gyro), rec.imu.accel))
    save_recording(rec, tmp_path / "rec")
    out = tmp_path / "out"
    assert main([str(tmp_path / "rec"), "--out", str(out), "--no-report"]) == 2
    (line,) = errors(capsys.readouterr().err)
    assert line.startswith("vical-calibrate: error: the calibration failed: the gyro reads 5")
    assert line.count("the gyro reads") == 1 and "it logs deg/s; pass --gyro-unit deg/s" in line
    assert sorted(p.name for p in out.iterdir()) == [
        "cam0", "cam1", "camchain-imucam.failed.yaml", "imu.yaml", "results.txt"
    ]  # fmt: skip
    assert [p.name for p in (out / "cam1").iterdir()] == ["frames.csv"]  # --no-report: no plots
    assert (out / "results.txt").read_text().startswith("FAILED: the calibration failed: the gyro reads")


def cropped(frames: CameraFrames, u_max: float) -> CameraFrames:
    """The frames with their detections left of ``u_max`` [px] (the rest of the board unseen)."""
    keep = [c[:, 0] < u_max for c in frames.corners]
    corners = [c[k] for c, k in zip(frames.corners, keep, strict=True)]
    return CameraFrames(frames.t, corners, [i[k] for i, k in zip(frames.ids, keep, strict=True)], frames.images)


def test_a_first_camera_that_sees_fewer_corners_than_the_second_gets_each_its_own_report(tmp_path, capsys):
    rec = stereo_recording(6.0)
    save_recording(replace(rec, frames=cropped(rec.frames, 480.0)), tmp_path / "rec")  # cam0: fewer corners
    out = tmp_path / "out"
    assert main([str(tmp_path / "rec"), "--out", str(out)]) == 0
    for name in ("cam0", "cam1"):
        assert (out / name / "report.pdf").read_bytes().startswith(b"%PDF"), name
    capsys.readouterr()
