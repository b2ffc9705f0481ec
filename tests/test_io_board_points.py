"""Detections named by their board coordinates (YAC's per-frame files, named-column CSVs), and calibrating a window."""

from pathlib import Path

import numpy as np
import pytest

from vical.apps.calibrate import time_window
from vical.calib.errors import CalibrationError
from vical.calib.synthetic import RigCamera, make_recording
from vical.data import Target
from vical.io.csvfiles import write_imu_csv
from vical.io.errors import CsvFormatError, SourceSettingError
from vical.io.sources import detect_source, open_recording

REALDATA = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "euroc_imu_april_0-36s"
HEADER = "#ts,tag_rows,tag_cols,tag_size,tag_spacing,kp_x,kp_y,p_x,p_y,p_z,tag_id,corner_idx\n"


@pytest.fixture(scope="module")
def rig():
    """A 3 s aprilgrid recording with two cameras."""
    rec = make_recording(duration=3.0, target=Target.aprilgrid(), seed=3, pixel_sigma=0.2)
    T = rec.truth.T_cam_imu.copy()
    T[0, 3] += 0.11
    other = RigCamera(rec.truth.camera, T, 0.0)
    return make_recording(duration=3.0, target=Target.aprilgrid(), seed=3, pixel_sigma=0.2,
                          other_cameras={"cam1": other})  # fmt: skip


def write_yac_folder(rec, root: Path, tag_size: float | None = None) -> Path:
    """The recording as YAC lays out detections: camN/<t_ns>.csv with board coordinates, and imu0.csv."""
    target = rec.target
    for name in rec.camera_names:
        folder = root / name
        folder.mkdir(parents=True)
        frames = rec.frames_of(name)
        for t, uv, ids in zip(frames.t.tolist(), frames.corners, frames.ids, strict=True):
            rows = [
                f"{t},{target.rows},{target.cols},{tag_size or target.row_spacing:f},{target.tag_spacing:f},"
                f"{u:.10f},{v:.10f},{x:f},{y:f},{z:f},{i // 4},{i % 4}\n"
                for (u, v), (x, y, z), i in zip(uv.tolist(), target.points[ids].tolist(), ids.tolist(), strict=True)
            ]
            (folder / f"{t}.csv").write_text(HEADER + "".join(rows[::-1]))  # any row order
    write_imu_csv(rec.imu, root / "imu0.csv")
    return root


def test_a_yac_corner_folder_reads_as_the_recording_it_was_written_from(rig, tmp_path):
    root = write_yac_folder(rig, tmp_path / "yac")
    assert detect_source(root) == "corner_folder"
    rec = open_recording(root, rig.target)
    assert rec.camera_names == ["cam0", "cam1"]
    for name in rec.camera_names:
        got, want = rec.frames_of(name), rig.frames_of(name)
        np.testing.assert_array_equal(got.t, want.t)
        for a, b, ia, ib in zip(got.corners, want.corners, got.ids, want.ids, strict=True):
            np.testing.assert_array_equal(ia, ib)
            np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_array_equal(rec.imu.t, rig.imu.t)


def test_a_corner_folder_reads_only_the_cameras_asked_for(rig, tmp_path):
    """cam0 (the recording's first camera) and those named; cam1's files unread (a broken one would say so)."""
    root = write_yac_folder(rig, tmp_path / "yac")
    next((root / "cam1").glob("*.csv")).write_text("not a corner file\n1,2\n")
    rec = open_recording(root, rig.target, cameras=["cam0"])
    assert rec.camera_names == ["cam0"] and len(rec.frames) == len(rig.frames)
    with pytest.raises(CsvFormatError):
        open_recording(root, rig.target, cameras=["cam0", "cam1"])
    with pytest.raises(SourceSettingError, match=r"^cameras names cam2, but .*yac has cam0, cam1 \(its camN folders"):
        open_recording(root, rig.target, cameras=["cam2"])


def test_a_board_of_another_size_is_named_in_one_line(rig, tmp_path):
    root = write_yac_folder(rig, tmp_path / "yac", tag_size=0.06)
    with pytest.raises(CsvFormatError, match=r"tag_size 0.06, but the target is aprilgrid 6 x 6, tag size 0.088 m"):
        open_recording(root, rig.target)
    path = tmp_path / "corners.csv"  # no grid columns: the board points themselves give it away
    path.write_text("ts,kp_x,kp_y,p_x,p_y,p_z\n1700000000000000000,10.5,20.5,0.088,0,0\n")
    with pytest.raises(CsvFormatError, match=r"board point \(0.088, 0, 0\) m is no point of the target \(aprilgrid"):
        open_recording(path, Target.aprilgrid(tag_size=0.1))


@pytest.mark.parametrize(
    "row, message",
    [
        ("1700000000000000000,6,6,0.088,0.3,12.5,abc,0,0,0,0,0", r"1700000000000000000.csv, line 2: could not convert"),
        ("1700000000000000000,6,6,0.088,0.3,12.5,20.5,0,0,0,0", r"line 2: expected 12 comma-separated fields"),
        ("1700000000000000001,6,6,0.088,0.3,12.5,20.5,0,0,0,0,0", r"rows are stamped 1700000000000000001 ns, its name"),
        ("1700000000000000000,6,6,0.088,0.3,12.5,nan,0,0,0,0,0", r"NaN or inf in a corner's pixel"),
    ],
)
def test_a_malformed_frame_file_is_named_with_its_line(tmp_path, row, message):
    (tmp_path / "cam0").mkdir()
    (tmp_path / "cam0" / "1700000000000000000.csv").write_text(HEADER + row + "\n")
    with pytest.raises(CsvFormatError, match=message):
        open_recording(tmp_path, Target.aprilgrid())


def test_a_named_column_corner_csv_reads_like_a_point_id_one(rig, tmp_path):
    target, frames = rig.target, rig.frames
    lines = ["timestamp [ns],u [px],v [px],p_x [m],p_y [m],p_z [m]\n"]
    for t, uv, ids in zip(frames.t.tolist(), frames.corners, frames.ids, strict=True):
        lines += [f"{t},{u!r},{v!r},{x!r},{y!r},{z!r}\n" for (u, v), (x, y, z) in
                  zip(uv.tolist(), target.points[ids].tolist(), strict=True)]  # fmt: skip
    path = tmp_path / "corners.csv"
    path.write_text("".join(lines))
    rec = open_recording(path, target)
    seen = frames.num_detections > 0
    np.testing.assert_array_equal(rec.frames.t, frames.t[seen])
    for a, b in zip(rec.frames.ids, [i for i, s in zip(frames.ids, seen, strict=True) if s], strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_window_keeps_every_cameras_frames_and_the_imu_inside_it(rig):
    cut = time_window(rig, 1.0, 1.5)
    t0, t1 = rig.t0 + 1_000_000_000, rig.t0 + 2_500_000_000
    for name in rig.camera_names:
        frames = cut.frames_of(name)
        assert len(frames) and frames.t.min() >= t0 and frames.t.max() <= t1
        assert len(frames) == np.count_nonzero((rig.frames_of(name).t >= t0) & (rig.frames_of(name).t <= t1))
    assert cut.imu.t.min() >= t0 and cut.imu.t.max() <= t1
    assert time_window(rig, 0.0, None) is rig
    with pytest.raises(CalibrationError, match=r"--start 9 s holds no camera frame: the recording spans 0..3.\d+ s"):
        time_window(rig, 9.0, None)


@pytest.mark.skipif(not REALDATA.is_dir(), reason=f"the real dev set is not at {REALDATA}")
def test_the_real_dev_set_reads_as_a_stereo_recording_with_its_imu():
    rec = open_recording(REALDATA, Target.aprilgrid(6, 6, 0.088, 0.3))
    assert rec.camera_names == ["cam0", "cam1"] and len(rec.frames) == 720 and len(rec.frames_of("cam1")) == 720
    assert len(rec.imu) > 7000 and 190 < 1e9 / np.median(np.diff(rec.imu.t)) < 210
    corners = sum(len(i) for i in rec.frames.ids)
    assert corners > 90_000  # ~130 corners in each of ~700 views


def test_a_corner_folder_without_imu_says_where_the_imu_goes(rig, tmp_path, capsys):
    from vical.apps.calibrate import main
    from vical.io.kalibr import write_target_yaml

    root = write_yac_folder(rig, tmp_path / "yac")
    (root / "imu0.csv").unlink()
    write_target_yaml(tmp_path / "target.yaml", rig.target)
    argv = [
        str(root),
        "--target",
        str(tmp_path / "target.yaml"),
        "--image-size",
        "640",
        "480",
        "--out",
        str(tmp_path / "o"),
    ]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "the joint task needs IMU data, but it holds no imu0.csv (or imu0/data.csv)" in line
    assert main([*argv[:-1], str(tmp_path / "o2"), "--cameras", "cam2", "--task", "intrinsic"]) == 2
    assert "has cam0, cam1 (its camN folders of per-frame corner files)" in capsys.readouterr().err
