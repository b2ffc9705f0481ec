"""The frame log: every input frame with its corners found and used, and the reason a frame was not used."""

import numpy as np

from vical.calib.frame_log import REASONS, build_frame_log
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.observations import collect_observations
from vical.calib.solve.outliers import rejection_warnings
from vical.calib.synthetic import make_recording
from vical.data import CameraFrames, Target


def _frames(counts: list[int], names: list[str] | None = None) -> CameraFrames:
    t = 1_000_000_000 + 100_000_000 * np.arange(len(counts), dtype=np.int64)
    corners = [np.zeros((n, 2)) for n in counts]
    ids = [np.arange(n) for n in counts]
    return CameraFrames(t, corners, ids, names=names)


def test_reasons_follow_the_detections_and_the_pipeline_decisions():
    frames = _frames([0, 3, 9, 42, 42, 42, 42, 42], [f"img{k}.png" for k in range(8)])
    # Corners in the final solve: frame 3 all 42, frame 4 only 40; frames 5, 6 left out by the pipeline.
    used = np.repeat([3, 4], [42, 40])
    log = build_frame_log(frames, used, 12, {5: "outlier", 6: "outside_imu"})
    reasons = [r.reason for r in log.records]
    assert reasons == ["no_board", "too_few_corners", "too_few_corners", "", "outlier_corners", "outlier",
                       "outside_imu", "no_pose"]  # fmt: skip
    assert [r.used for r in log.records] == [0, 0, 0, 42, 40, 0, 0, 0]
    assert (log.corners_found, log.corners_used) == (3 + 9 + 5 * 42, 82)
    assert [r.label for r in log.rejected] == ["img1.png", "img2.png", "img5.png", "img6.png", "img7.png"]
    assert log.summary() == (
        "8 frames, the board detected in 7, 2 used (82 of 222 corners); not used: 1 no board detected, 2 too few "
        "corners for a target pose, 1 no target pose fits its corners, 1 outlier, 1 outside the IMU's time span; "
        "1 used frames lost 2 outlier corners"
    )
    assert set(log.counts()) <= set(REASONS)


def test_frames_without_files_are_named_by_their_timestamp():
    log = build_frame_log(_frames([0, 42]), np.full(42, 1), 12, {})
    assert [r.label for r in log.records] == ["1000000000", "1100000000"]


def test_a_frame_stride_marks_the_frames_it_left_out():
    rec = make_recording(duration=6.0, pixel_sigma=0.3, seed=5)
    result = calibrate_intrinsics(rec.frames, rec.target, "radtan", (640, 480), frame_stride=3)
    log = result.frame_log
    seen = [o.index for o in collect_observations(rec.frames, rec.target)]
    thinned = [r.index for r in log.records if r.reason == "thinned"]
    assert thinned == [k for n, k in enumerate(seen) if n % 3]
    assert [r.index for r in log.used] == seen[::3]
    assert all(r.reason == "no_board" for r in log.records if r.index not in seen)


def test_outlier_warnings_name_frames_by_their_image_file():
    frames = _frames([6, 6, 6], ["a.png", "b.png", "c.png"])
    observations = collect_observations(frames, Target.checkerboard())
    notes = rejection_warnings(observations, [1], {2: 1}, 1.5, 0.3)
    assert notes[0].endswith("frames c.png") and notes[1].endswith("were dropped: frames b.png")
