"""Camera frames with their target detections (``CameraFrames``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.data.errors import DataError
from vical.data.sample_arrays import as_timestamps


@dataclass(frozen=True)
class CameraFrames:
    """Camera frames with target detections.

    Attributes:
        t: (M,) int64 [ns] frame timestamps (camera clock, see ``SensorTruth.time_offset``).
        corners: M arrays (K_i, 2) float64 [px] detected corner positions (empty when the
            target was not detected in that frame).
        ids: M arrays (K_i,) int64 target point ids of those corners (see ``Target``).
        images: optional (M, H, W) uint8 grey images.
        names: optional M image file names (sources read from files), so that messages can name the
            image a frame came from; None when the frames have no files (bags, simulations).
    """

    t: np.ndarray
    corners: list[np.ndarray]
    ids: list[np.ndarray]
    images: np.ndarray | None = None
    names: list[str] | None = None

    def __post_init__(self) -> None:
        t = as_timestamps(self.t, "CameraFrames.t")
        object.__setattr__(self, "t", t)
        if len(self.corners) != len(t) or len(self.ids) != len(t):
            raise DataError(
                f"CameraFrames needs one corner and id array per frame: {len(t)} timestamps, "
                f"{len(self.corners)} corner arrays, {len(self.ids)} id arrays"
            )
        corners = [np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in self.corners]
        ids = [np.asarray(i, dtype=np.int64).reshape(-1) for i in self.ids]
        for k, (c, i) in enumerate(zip(corners, ids, strict=True)):
            if len(c) != len(i):
                raise DataError(f"frame {k}: {len(c)} corners but {len(i)} ids")
        object.__setattr__(self, "corners", corners)
        object.__setattr__(self, "ids", ids)
        if self.images is not None:
            images = np.asarray(self.images)
            if images.ndim != 3 or len(images) != len(t) or images.dtype != np.uint8:
                raise DataError(f"images must be (M, H, W) uint8 with M={len(t)}, got {images.shape} {images.dtype}")
            object.__setattr__(self, "images", images)
        if self.names is not None:
            if len(self.names) != len(t):
                raise DataError(f"CameraFrames needs one name per frame: {len(t)} timestamps, {len(self.names)} names")
            object.__setattr__(self, "names", [str(n) for n in self.names])

    def __len__(self) -> int:
        return len(self.t)

    def label(self, k: int) -> str:
        """How messages name frame ``k``: its image file name, else its timestamp [ns]."""
        return self.names[k] if self.names is not None else str(int(self.t[k]))

    @property
    def num_detections(self) -> np.ndarray:
        """(M,) number of detected corners per frame."""
        return np.array([len(i) for i in self.ids], dtype=np.int64)

    def select(self, mask: np.ndarray) -> CameraFrames:
        """Frames where the boolean ``mask`` (M,) is true."""
        idx = np.flatnonzero(mask)
        images = None if self.images is None else self.images[idx]
        names = None if self.names is None else [self.names[i] for i in idx]
        return CameraFrames(self.t[idx], [self.corners[i] for i in idx], [self.ids[i] for i in idx], images, names)
