"""Recordings of camera rigs (cam0 + cam1 + ...): the container, recording directories, EuRoC folders, bags."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_io_samples import make_camera, make_recording, make_truth

from vical.data import CameraFrames, DataError
from vical.geometry.transforms import make_transform
from vical.io import FormatError, FormatWarning, load_recording, read_bag, read_euroc, save_recording
from vical.io.bag import write_bag
from vical.io.errors import BagFormatError
from vical.io.euroc import write_euroc


def second_camera(frames: CameraFrames, seed: int, step: int = 1) -> CameraFrames:
    """Another camera's frames: every ``step``-th stamp of ``frames`` (2 us later), its own detections and images."""
    rng = np.random.default_rng(seed)
    t = frames.t[::step] + 2_000
    corners = [c[::-1] + rng.normal(0, 1, c.shape) for c in frames.corners[::step]]
    ids = [i[::-1].copy() for i in frames.ids[::step]]
    images = None if frames.images is None else 255 - frames.images[::step]
    return CameraFrames(t, corners, ids, images)


def make_rig(images: bool = True, cameras: int = 2, step: int = 1):
    rec = make_recording(images=images)
    others = {f"cam{n}": second_camera(rec.frames, n, step) for n in range(1, cameras)}
    baseline = make_transform(np.eye(3), [-0.11, 0.0, 0.0])
    truths = {
        name: replace(make_truth(), T_cam_imu=baseline @ make_truth().T_cam_imu, camera=make_camera("equidistant"))
        for name in others
    }
    return replace(rec, other_frames=others, other_truths=truths)


def assert_same_frames(a: CameraFrames, b: CameraFrames, images: bool = True) -> None:
    assert np.array_equal(a.t, b.t) and a.t.dtype == np.int64
    for x, y in zip(a.corners + a.ids, b.corners + b.ids, strict=True):
        assert np.array_equal(x, y)
    if images:
        assert np.array_equal(a.images, b.images)


def test_a_rig_recording_names_its_cameras_and_is_cut_whole():
    rec = make_rig(cameras=3)
    assert rec.camera_names == ["cam0", "cam1", "cam2"]
    assert rec.frames_of("cam0") is rec.frames and rec.truth_of("cam2").camera.distortion == "equidistant"
    cut = rec.until(int(rec.frames.t[2]))
    assert [len(cut.frames_of(n)) for n in cut.camera_names] == [3, 2, 2]  # cam1/cam2 are 2 us later
    with pytest.raises(DataError, match=r"has no camera 'cam5'; it has \['cam0', 'cam1', 'cam2'\]"):
        rec.frames_of("cam5")
    with pytest.raises(DataError, match=r"named cam1, cam2, \.\.\. without gaps"):
        replace(rec, other_frames={"cam2": rec.frames})
    with pytest.raises(DataError, match="other_truths names cam3, which has no frames"):
        replace(rec, other_truths={"cam3": rec.truth})


def test_a_rig_recording_directory_round_trips_exactly(tmp_path):
    rec = make_rig(cameras=3)
    back = load_recording(save_recording(rec, tmp_path / "rec"))
    assert back.camera_names == rec.camera_names
    for name in rec.camera_names:
        assert_same_frames(back.frames_of(name), rec.frames_of(name))
        assert np.array_equal(back.truth_of(name).T_cam_imu, rec.truth_of(name).T_cam_imu)
        assert back.truth_of(name).camera == rec.truth_of(name).camera


def test_euroc_folder_with_cam0_and_cam1_round_trips(tmp_path):
    rec = make_rig()
    write_euroc(rec, tmp_path / "euroc")
    assert (tmp_path / "euroc" / "mav0" / "cam1" / "data.csv").is_file()
    back = read_euroc(tmp_path / "euroc", rec.target)
    assert back.camera_names == ["cam0", "cam1"]
    for name in rec.camera_names:
        assert_same_frames(back.frames_of(name), rec.frames_of(name))
        assert back.truth_of(name).camera == rec.truth_of(name).camera
        np.testing.assert_allclose(back.truth_of(name).T_cam_imu, rec.truth_of(name).T_cam_imu, atol=1e-15)
    assert back.metadata["image_sizes"] == {"cam0": [64, 48], "cam1": [64, 48]}


def test_euroc_cameras_at_different_rates_are_named_in_a_warning(tmp_path):
    rec = make_rig(step=2)  # cam1 at half cam0's rate
    write_euroc(rec, tmp_path / "euroc")
    with pytest.warns(FormatWarning, match=r"mav0: cam1 runs at 10 Hz but cam0 at 20 Hz"):
        read_euroc(tmp_path / "euroc", rec.target)


def test_euroc_camera_folders_must_not_skip_a_number(tmp_path):
    rec = make_rig(cameras=3)
    write_euroc(rec, tmp_path / "euroc")
    (tmp_path / "euroc" / "mav0" / "cam1" / "data.csv").unlink()
    with pytest.raises(FormatError, match=r"mav0: camera folders cam0, cam2 but no cam1/data\.csv"):
        read_euroc(tmp_path / "euroc", rec.target)


def test_euroc_image_of_another_size_than_its_cameras_sensor_yaml_names_the_image(tmp_path):
    rec = make_rig()
    write_euroc(rec, tmp_path / "euroc")
    cam1 = tmp_path / "euroc" / "mav0" / "cam1"
    text = (cam1 / "sensor.yaml").read_text()
    (cam1 / "sensor.yaml").write_text(text.replace("resolution: [64, 48]", "resolution: [640, 480]"))
    with pytest.raises(FormatError, match=r"cam1/data/\d+\.png: image is 64 x 48 px"):
        read_euroc(tmp_path / "euroc", rec.target)


def test_bag_with_two_image_topics_round_trips(tmp_path):
    rec = make_rig()
    path = write_bag(rec, tmp_path / "rig.bag", image_topic=["/left/image_raw", "/right/image_raw"])
    back = read_bag(path, rec.target, image_topic=["/left/image_raw", "/right/image_raw"])
    assert back.camera_names == ["cam0", "cam1"]
    assert back.metadata["image_topics"] == {"cam0": "/left/image_raw", "cam1": "/right/image_raw"}
    for name in rec.camera_names:
        assert np.array_equal(back.frames_of(name).t, rec.frames_of(name).t)
        assert np.array_equal(back.frames_of(name).images, rec.frames_of(name).images)
    with pytest.raises(BagFormatError, match=r"rig\.bag: topic /cam1/image_raw is missing; the bag has: /left/"):
        read_bag(path, rec.target, image_topic=["/left/image_raw", "/cam1/image_raw"])


def test_bag_cameras_at_different_rates_are_named_in_a_warning(tmp_path):
    rec = make_rig(step=2)
    path = write_bag(rec, tmp_path / "rig.bag")
    with pytest.warns(FormatWarning, match=r"/cam0/image_raw, /cam1/image_raw\): cam1 runs at 10 Hz but cam0 at 20"):
        read_bag(path, rec.target, image_topic=["/cam0/image_raw", "/cam1/image_raw"])


def test_a_camchain_must_fit_the_recordings_cameras(tmp_path):
    from test_io_kalibr_chain import kalibr_camchain

    from vical.io.kalibr_chain import check_chain_fits, read_chain

    rec = make_rig()
    path = tmp_path / "camchain.yaml"
    path.write_text(kalibr_camchain(2).replace("[752, 480]", "[64, 48]"))
    check_chain_fits(read_chain(path), path, rec)
    path.write_text(kalibr_camchain(3).replace("[752, 480]", "[64, 48]"))
    with pytest.raises(FormatError, match=r"camchain\.yaml names cam2, but the recording has only cam0, cam1"):
        check_chain_fits(read_chain(path), path, rec)
    path.write_text(kalibr_camchain(2).replace("[752, 480]", "[64, 48]", 1))
    with pytest.raises(
        FormatError, match=r"camchain\.yaml \[cam1\]: resolution 752 x 480 px, but cam1's images are 64"
    ):
        check_chain_fits(read_chain(path), path, rec)
