"""Per-frame target observations: the corners a frame saw and the board points they belong to."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.calib.errors import CalibrationError, CalibrationSettingError
from vical.data import CameraFrames, Target
from vical.geometry import CameraModel

MIN_CORNERS = 4  # a frame needs at least 4 corners to constrain its 6-DoF pose
# Corners just outside the image (pixel noise, a rolling shutter's shift in simulated data) are not a wrong
# image size; corners beyond this fraction of it are.
OUTSIDE_TOLERANCE = 0.02


@dataclass(frozen=True)
class FrameObservation:
    """The target corners seen in one camera frame.

    Attributes:
        index: index of the frame in the recording's ``CameraFrames``.
        t_ns: int64 [ns] frame timestamp (camera clock).
        uv: (K, 2) [px] corner pixels.
        ids: (K,) int64 target point ids.
        points: (K, 3) [m] the corners' board-frame positions.
        name: the frame's image file name, or None (``CameraFrames.names``).
    """

    index: int
    t_ns: int
    uv: np.ndarray
    ids: np.ndarray
    points: np.ndarray
    name: str | None = None

    @property
    def label(self) -> str:
        """How messages name the frame: its image file name, else its index in the recording."""
        return self.name if self.name is not None else str(self.index)

    def residuals(self, camera: CameraModel, T_cam_target: np.ndarray) -> np.ndarray:
        """Measured minus predicted corner pixels (K, 2) [px] with the target at ``T_cam_target`` (4, 4)."""
        uv, _ = camera.project(self.points @ T_cam_target[:3, :3].T + T_cam_target[:3, 3])
        return self.uv - uv


def collect_observations(
    frames: CameraFrames, target: Target, min_corners: int = MIN_CORNERS
) -> list[FrameObservation]:
    """Frames with at least ``min_corners`` valid detections, in time order.

    Raises:
        CalibrationError: when no frame has enough corners, or ids are outside the target.
    """
    if len(frames) == 0:
        raise CalibrationError("the recording has no camera frames; record the target with the camera first")
    points = target.points
    out = []
    for k in range(len(frames)):
        ids = frames.ids[k]
        if ids.size and (ids.min() < 0 or ids.max() >= target.num_points):
            raise CalibrationError(
                f"frame {k} has corner ids outside 0..{target.num_points - 1}; "
                f"the target ({target.rows} x {target.cols} points) does not match the detections"
            )
        if len(ids) >= min_corners:
            name = None if frames.names is None else frames.names[k]
            out.append(FrameObservation(k, int(frames.t[k]), frames.corners[k], ids, points[ids], name))
    if not out:
        counts = frames.num_detections
        raise CalibrationError(
            f"no camera frame has at least {min_corners} target corners (most in one frame: {int(counts.max())} "
            f"of {len(frames)} frames); check the target definition and that the board is in view"
        )
    return out


def image_size(frames: CameraFrames, image_size: tuple[int, int] | None) -> tuple[int, int]:
    """``(width, height)`` [px] from the argument or, failing that, from the frames' images.

    A given size must hold every detected corner: a smaller one is a wrong size, not a camera.
    """
    if image_size is not None:
        w, h = (int(v) for v in image_size)
        if w <= 0 or h <= 0:
            raise CalibrationError(f"image_size_px must be positive (width, height) [px], got {image_size}")
        _check_corners_inside(frames, w, h)
        return w, h
    if frames.images is not None:
        return int(frames.images.shape[2]), int(frames.images.shape[1])
    raise CalibrationSettingError(
        "the image size is unknown (no images came with the frames): give it as {fix}",
        "image_size_px",
        "(width, height)",
        "W H",
    )


def _check_corners_inside(frames: CameraFrames, width: int, height: int) -> None:
    corners = [c for c in frames.corners if len(c)]
    if not corners:
        return
    u, v = np.concatenate(corners).max(axis=0)
    if u > (1 + OUTSIDE_TOLERANCE) * width or v > (1 + OUTSIDE_TOLERANCE) * height:
        raise CalibrationSettingError(
            f"corners were detected up to u = {u:.0f} px, v = {v:.0f} px, outside the image size {width} x {height} px "
            "given as {fix}; give the size of the images the corners were detected in",
            "image_size_px", f"({width}, {height})", f"{width} {height}",
        )  # fmt: skip
