"""Recording save/load: lossless round trip, atomic writes, clear errors on damaged directories."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from test_io_samples import assert_frames_equal, make_recording

import vical.io.recording as recording_module
from vical.io import RecordingFormatError, load_recording, save_recording
from vical.io.atomic import atomic_file


def test_round_trip_is_bit_exact(tmp_path):
    rec = make_recording()
    save_recording(rec, tmp_path / "rec")
    back = load_recording(tmp_path / "rec")
    assert np.array_equal(back.imu.t, rec.imu.t) and back.imu.t.dtype == np.int64
    assert np.array_equal(back.imu.gyro, rec.imu.gyro) and np.array_equal(back.imu.accel, rec.imu.accel)
    assert_frames_equal(back.frames, rec.frames)
    assert back.target == rec.target
    assert back.truth.camera == rec.truth.camera
    assert np.array_equal(back.truth.T_cam_imu, rec.truth.T_cam_imu)
    assert back.truth.time_offset == rec.truth.time_offset
    assert back.truth.imu_noise == rec.truth.imu_noise
    assert np.array_equal(back.truth.accel_bias, rec.truth.accel_bias)
    for name in ("t", "T_world_imu", "v_world", "omega_imu"):
        assert np.array_equal(getattr(back.trajectory, name), getattr(rec.trajectory, name))
    assert np.array_equal(back.T_world_target, rec.T_world_target)
    assert back.path_length == rec.path_length and back.duration == rec.duration
    assert back.metadata == rec.metadata
    assert np.array_equal(back.path_profile.t, rec.path_profile.t)
    assert np.array_equal(back.path_profile.length, rec.path_profile.length)


def test_round_trip_without_optional_parts(tmp_path):
    rec = make_recording(images=False, with_truth=False)
    back = load_recording(save_recording(rec, tmp_path / "rec"))
    assert back.truth is None and back.trajectory is None and back.T_world_target is None
    assert back.path_profile is None
    assert back.frames.images is None
    assert_frames_equal(back.frames, rec.frames, images=False)


def test_overwrite_must_be_explicit(tmp_path):
    path = tmp_path / "rec"
    save_recording(make_recording(seed=1), path)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_recording(make_recording(seed=2), path)
    assert load_recording(path).metadata["seed"] == 1
    save_recording(make_recording(seed=2), path, overwrite=True)
    assert load_recording(path).metadata["seed"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def test_failure_mid_write_leaves_nothing_at_the_final_path(tmp_path, monkeypatch):
    real_write = recording_module._write_npz
    written = []

    def write_then_fail(path, arrays, compress):
        if written:
            raise OSError("disk full")
        written.append(path)
        return real_write(path, arrays, compress)

    monkeypatch.setattr(recording_module, "_write_npz", write_then_fail)
    with pytest.raises(OSError, match="disk full"):
        save_recording(make_recording(), tmp_path / "rec")
    assert written, "the failure must happen after a file was written"
    assert list(tmp_path.iterdir()) == []


def test_failed_overwrite_keeps_the_old_recording(tmp_path, monkeypatch):
    save_recording(make_recording(seed=1), tmp_path / "rec")

    def fail(path, arrays, compress):
        raise OSError("disk full")

    monkeypatch.setattr(recording_module, "_write_npz", fail)
    with pytest.raises(OSError):
        save_recording(make_recording(seed=2), tmp_path / "rec", overwrite=True)
    assert load_recording(tmp_path / "rec").metadata["seed"] == 1
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]


@pytest.mark.parametrize("name", ["imu.npz", "frames.npz", "images.npz", "recording.yaml"])
def test_missing_file_is_named(tmp_path, name):
    path = save_recording(make_recording(), tmp_path / "rec")
    (path / name).unlink()
    with pytest.raises(RecordingFormatError, match=name.replace(".", r"\.")):
        load_recording(path)


@pytest.mark.parametrize("name", ["imu.npz", "images.npz", "trajectory.npz"])
def test_truncated_file_is_named(tmp_path, name):
    path = save_recording(make_recording(), tmp_path / "rec")
    data = (path / name).read_bytes()
    (path / name).write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingFormatError, match=rf"{name.replace('.', '[.]')}.*truncated"):
        load_recording(path)


def test_corrupt_file_is_named(tmp_path):
    path = save_recording(make_recording(), tmp_path / "rec")
    data = bytearray((path / "frames.npz").read_bytes())
    data[200] ^= 0xFF
    (path / "frames.npz").write_bytes(bytes(data))
    with pytest.raises(RecordingFormatError, match=r"frames\.npz.*corrupt"):
        load_recording(path)


def test_truncated_manifest_is_named(tmp_path):
    path = save_recording(make_recording(), tmp_path / "rec")
    text = (path / "recording.yaml").read_text()
    (path / "recording.yaml").write_text(text[:40])
    with pytest.raises(RecordingFormatError, match=r"recording\.yaml"):
        load_recording(path)


def test_malformed_file_entry_in_manifest_is_named(tmp_path):
    path = save_recording(make_recording(), tmp_path / "rec")
    manifest = yaml.safe_load((path / "recording.yaml").read_text())
    manifest["files"]["imu.npz"] = "imu.npz"
    (path / "recording.yaml").write_text(yaml.safe_dump(manifest))
    with pytest.raises(RecordingFormatError, match=r"files\.imu\.npz must give the file's bytes and sha256"):
        load_recording(path)


def test_not_a_recording(tmp_path):
    with pytest.raises(RecordingFormatError, match=r"recording\.yaml is missing"):
        load_recording(tmp_path)
    with pytest.raises(RecordingFormatError, match="not a directory"):
        load_recording(tmp_path / "nothing")


def test_atomic_file_keeps_the_old_file_on_failure(tmp_path):
    path = tmp_path / "camchain.yaml"
    path.write_text("old")
    with pytest.raises(RuntimeError, match="interrupted"), atomic_file(path) as tmp:
        tmp.write_text("half of the new")
        raise RuntimeError("interrupted")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["camchain.yaml"]
    with atomic_file(path) as tmp:
        tmp.write_text("new")
    assert path.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["camchain.yaml"]
