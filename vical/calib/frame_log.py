"""Which frames and corners a calibration used, and why it left the others out.

Every frame of the input gets one ``FrameRecord``: how many corners were detected in it, how many
entered the final solve, and, when not all of them did, the reason (``REASONS``). The pipeline
knows the reasons it decides (thinned by the frame stride, dropped as an outlier, outside the
IMU's time span, a rig camera's view without a simultaneous view of the first camera); the others
follow from the detections (no board, too few corners for a pose).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from vical.calib.solve.observations import FrameObservation
from vical.data import CameraFrames

# Reason codes (the ``reason`` column of frames.csv) and what they mean, in the order a reader meets them.
REASONS = {
    "no_board": "no board detected",
    "too_few_corners": "too few corners for a target pose",
    "thinned": "left out by the frame stride",
    "no_pose": "no target pose fits its corners",
    "outlier": "outlier: fits no target pose even without its worst corners",
    "outside_imu": "outside the IMU's time span",
    "unpaired": "no view of the first camera taken with it (within 5 ms) entered the solve",
    "outlier_corners": "used; some of its corners were left out as outliers",
}


@dataclass(frozen=True)
class FrameRecord:
    """What the calibration did with one frame.

    Attributes:
        index: the frame's index in the input ``CameraFrames``.
        t_ns: int [ns] its timestamp (camera clock).
        name: its image file name, or None (bags, simulations: the timestamp names it).
        found: corners detected in it.
        used: corners of it in the final solve (0: the frame was not used).
        reason: a key of ``REASONS``, or ``""`` for a frame used with all its corners.
    """

    index: int
    t_ns: int
    name: str | None
    found: int
    used: int
    reason: str

    @property
    def label(self) -> str:
        """The image file name, else the timestamp [ns]."""
        return self.name if self.name is not None else str(self.t_ns)


@dataclass(frozen=True)
class FrameLog:
    """One ``FrameRecord`` per input frame, in input order, and counts over them.

    Attributes:
        records: the frames.
        min_corners: the fewest corners a frame needed for a target pose.
    """

    records: list[FrameRecord]
    min_corners: int

    @property
    def used(self) -> list[FrameRecord]:
        return [r for r in self.records if r.used > 0]

    @property
    def rejected(self) -> list[FrameRecord]:
        """Frames with detections that the solve did not use."""
        return [r for r in self.records if r.used == 0 and r.found > 0]

    @property
    def corners_found(self) -> int:
        return sum(r.found for r in self.records)

    @property
    def corners_used(self) -> int:
        return sum(r.used for r in self.records)

    def counts(self) -> dict[str, int]:
        """Frames per reason (``REASONS`` order), ``outlier_corners`` included; reasons without frames left out."""
        found = Counter(r.reason for r in self.records if r.reason)
        return {reason: found[reason] for reason in REASONS if found[reason]}

    def summary(self) -> str:
        """One line: frames and corners found and used, the frames not used by reason, the corners trimmed."""
        with_board = sum(r.found > 0 for r in self.records)
        line = (
            f"{len(self.records)} frames, the board detected in {with_board}, {len(self.used)} used "
            f"({self.corners_used} of {self.corners_found} corners)"
        )
        counts = self.counts()
        trimmed = counts.pop("outlier_corners", 0)
        if counts:
            line += "; not used: " + ", ".join(f"{n} {short_reason(reason)}" for reason, n in counts.items())
        if trimmed:
            lost = sum(r.found - r.used for r in self.used)
            line += f"; {trimmed} used frames lost {lost} outlier corners"
        return line


def short_reason(reason: str) -> str:
    """``REASONS[reason]`` up to its first colon or semicolon."""
    return REASONS[reason].split(":")[0].split(";")[0]


def build_frame_log(
    frames: CameraFrames, used_frames: np.ndarray, min_corners: int, decided: dict[int, str]
) -> FrameLog:
    """The ``FrameLog`` of a solve.

    Args:
        frames: the input frames.
        used_frames: (N,) int frame index of every corner in the final solve (``reprojection_frames``).
        min_corners: the fewest corners a frame needed for a target pose.
        decided: ``{frame index: reason}`` for the frames the pipeline left out (``thinned``,
            ``outlier``, ``outside_imu``).
    """
    indices, counts = np.unique(np.asarray(used_frames, dtype=np.int64), return_counts=True)
    used = dict(zip(indices.tolist(), counts.tolist(), strict=True))
    found = frames.num_detections
    records = []
    for k in range(len(frames)):
        n_used, n_found = used.get(k, 0), int(found[k])
        if n_used:
            reason = "outlier_corners" if n_used < n_found else ""
        elif n_found == 0:
            reason = "no_board"
        elif k in decided:
            reason = decided[k]
        else:
            reason = "too_few_corners" if n_found < min_corners else "no_pose"
        name = None if frames.names is None else frames.names[k]
        records.append(FrameRecord(k, int(frames.t[k]), name, n_found, n_used, reason))
    return FrameLog(records, min_corners)


def left_out(every: list[FrameObservation], strided: list[FrameObservation], outliers: list[int]) -> dict[int, str]:
    """``{frame index: reason}`` of the frames with detections that the frame stride thinned out
    (in ``every``, not in ``strided``) and of the ``outliers`` (frame indices) the solve dropped."""
    kept = {o.index for o in strided}
    decided = {o.index: "thinned" for o in every if o.index not in kept}
    return decided | {k: "outlier" for k in outliers}
