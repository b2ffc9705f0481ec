"""Recordings with the flaws real ones have still calibrate, and the flaws are reported.

One simulator recording (project backend, 12 moves, 8.8 s, 89 frames at 10 Hz) is damaged as
real recordings are: a 1.2 s stretch without detections, an IMU stream that starts 0.6 s after
the first frame, five corners shifted by ~25 px in each of three frames, and one frame whose ids
are scrambled. Undamaged, the joint solve of this recording is within 0.13 deg / 6.3 mm / 0.05 ms
of the truth (damaged: 0.07 deg / 2.9 mm / 0.06 ms); without the outlier rejection the extrinsic
solve's corner noise estimate grew from 0.25 to 1.7 px and the joint solve's focal-length
initialisation failed.
"""

import re
from dataclasses import replace

import numpy as np
import pytest
from test_sim_calib_integration import record

from vical.apps.calibrate import main
from vical.calib.metrics import calibration_errors
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint
from vical.data import NS_PER_S, CameraFrames, ImuSamples, Recording
from vical.io import save_recording
from vical.sim.sampling import SensorSampling, sample_sensor

GAP_S = (4.0, 5.2)  # [s] after the first frame: no detections
IMU_START_S = 0.6  # [s] after the first frame: the first IMU sample


def damage(rec: Recording, rng: np.random.Generator) -> tuple[Recording, list[int], int]:
    """The recording with the four flaws; returns it, the frames with shifted corners and the scrambled frame."""
    f = rec.frames
    t_s = (f.t - f.t[0]) / NS_PER_S
    corners, ids = [c.copy() for c in f.corners], [i.copy() for i in f.ids]
    for k in np.flatnonzero((t_s > GAP_S[0]) & (t_s < GAP_S[1])):
        corners[k], ids[k] = np.zeros((0, 2)), np.zeros(0, np.int64)
    seen = [k for k in range(len(f)) if len(ids[k]) and t_s[k] > IMU_START_S + 0.2]
    shifted, scrambled = seen[10:13], seen[30]
    for k in shifted:
        pick = rng.choice(len(ids[k]), 5, replace=False)
        corners[k][pick] += rng.normal(0.0, 25.0, (5, 2))
    ids[scrambled] = rng.permutation(ids[scrambled])
    keep = rec.imu.t >= f.t[0] + round(IMU_START_S * NS_PER_S)
    imu = ImuSamples(rec.imu.t[keep], rec.imu.gyro[keep], rec.imu.accel[keep])
    return replace(rec, frames=CameraFrames(f.t, corners, ids), imu=imu), shifted, scrambled


@pytest.fixture(scope="module")
def flawed():
    sampling = SensorSampling()
    truth = replace(sample_sensor(sampling, np.random.default_rng(11)), time_offset=0.008)
    rec = record(sampling, truth, cycles=2, seed=4)
    assert len(rec.frames) == 89
    return damage(rec, np.random.default_rng(0))


def assert_flaws_reported(warnings: list[str], shifted: list[int], scrambled: int) -> None:
    text = "\n".join(warnings)
    assert f"were dropped: frames {scrambled}\n" in text + "\n"
    assert re.search(r"\b15 of \d+ corners \([\d.]+ %\) in 3 frames are outliers", text), text
    assert f"frames {', '.join(map(str, shifted))}" in text
    assert "outside the IMU samples' time span" in text
    assert "no usable target view for 1.2" in text and "IMU factor bridges the gap" in text


@pytest.mark.parametrize("task", ["extrinsic", "joint"])
def test_flawed_recording_calibrates_and_reports_its_flaws(flawed, task):
    rec, shifted, scrambled = flawed
    truth = rec.truth
    if task == "joint":
        result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), truth.imu_noise)
    else:
        result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, truth.camera, truth.imu_noise)

    assert_flaws_reported(result.warnings, shifted, scrambled)
    assert result.pixel_sigma < 0.3  # the simulated 0.25 px; with the wrong corners kept: 1.7 px
    assert result.reprojection.max < 2.0
    errors = calibration_errors(result, truth)
    assert errors.rotation_deg < 0.2 and errors.translation_mm < 15.0 and errors.time_offset_ms < 0.5
    assert errors.intrinsic_pct < 1.0


def test_intrinsic_calibration_rejects_wrong_corners(flawed):
    rec, shifted, scrambled = flawed
    result = calibrate_intrinsics(rec.frames, rec.target, "radtan", (640, 480))
    text = "\n".join(result.warnings)
    # The 15 shifted corners, and a few neighbours whose residual the damaged first solve inflated.
    assert re.search(r"\b1[5-9] of \d+ corners \([\d.]+ %\) in 3 frames are outliers", text), text
    assert f"frames {', '.join(map(str, shifted))}" in text and f"were dropped: frames {scrambled}" in text
    assert result.reprojection.max < 2.0 and result.pixel_sigma < 0.35
    err = np.abs(result.camera.intrinsics - rec.truth.camera.intrinsics)
    assert np.all(err < 3 * np.sqrt(np.diag(result.covariance))[:4])


def test_cli_prints_and_writes_the_flaws(flawed, tmp_path, capsys):
    rec, shifted, scrambled = flawed
    save_recording(rec, tmp_path / "rec")
    assert main([str(tmp_path / "rec"), "--task", "joint", "--out", str(tmp_path / "out"), "--no-report"]) == 0
    printed = [line.removeprefix("warning: ") for line in capsys.readouterr().out.splitlines()]
    assert_flaws_reported([w for w in printed], shifted, scrambled)
    written = (tmp_path / "out" / "results.txt").read_text()
    assert (
        "warnings:" in written
        and "IMU factor bridges the gap" in written
        and "are outliers and were left out" in written
    )


def test_the_frame_log_gives_each_damaged_frame_its_reason(flawed):
    """Every frame is accounted for: the gap's frames saw no board, the frames before the IMU started lie outside
    its span, the scrambled frame is an outlier, the shifted frames lost exactly their five corners."""
    rec, shifted, scrambled = flawed
    result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, rec.truth.imu_noise)
    log = result.frame_log
    assert [r.index for r in log.records] == list(range(len(rec.frames)))
    reasons = [r.reason for r in log.records]
    t_s = (rec.frames.t - rec.frames.t[0]) / NS_PER_S
    in_gap = np.flatnonzero((t_s > GAP_S[0]) & (t_s < GAP_S[1]))
    assert len(in_gap) >= 11 and all(reasons[k] == "no_board" for k in in_gap)
    seen = rec.frames.num_detections > 0
    early = np.flatnonzero(seen & (t_s < IMU_START_S - 0.05))  # well before the IMU's first sample (offset 8 ms)
    assert len(early) >= 4 and all(reasons[k] == "outside_imu" for k in early)
    assert reasons[scrambled] == "outlier" and log.records[scrambled].used == 0
    for k in shifted:
        assert reasons[k] == "outlier_corners" and log.records[k].used == log.records[k].found - 5
    assert len(log.used) == result.num_frames and log.corners_used == len(result.reprojection_residuals)
    assert log.corners_found == int(rec.frames.num_detections.sum())
    used_frames = {r.index for r in log.used}
    assert used_frames == set(result.reprojection_frames.tolist())
    assert all(reasons[k] in ("", "outlier_corners") for k in used_frames)
