"""Data-acquisition status: how much of the image, board size, skew and motion range is covered.

The paper's state (Sec. III-B) summarises the data collected so far by its range, not its history:

- board-centre polygon ``V1..V4``: the image is split into quadrants R1..R4 (left-up, right-up,
  right-down, left-down); ``V1 = [min u, min v]`` over board centres seen in R1, ``V2 = [max u,
  min v]`` in R2, ``V3 = [max u, max v]`` in R3, ``V4 = [min u, max v]`` in R4. Coordinates are
  image fractions (u / W, v / H); a vertex with no centre in its quadrant stays at the image
  centre (0.5, 0.5), so coverage only ever grows outward.
- board area ``A_min, A_max``: the fraction of the image the board's corner grid covers.
- skew ``eta_min, eta_max``: the image angle between the grid's two edges leaving its first
  corner, mapped linearly from [pi/4, 3pi/4] onto [0, 1] and clipped (0.5 for a fronto-parallel
  board). Within the paper's workspace the angle stays within about 4 deg of pi/2, so dividing by
  pi would leave the authors' skew threshold (0.05) out of reach (largest range measured: 0.034).
- motion ``dp_max`` (3), ``dTheta_max`` (3): the largest per-step change of each position and
  Euler-angle component so far, divided by the workspace's width (twice its bound).

A view enters the coverage set only when it differs from every stored view by more than the
novelty distance (L1 in ``[x, y, area, skew]``), as the authors' code did; the ranges are taken
over the stored views. Board geometry in the image comes from a homography fitted to the
detected corners, so partial views (aprilgrid) give the same features as full ones.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vical.data import Target
from vical.env.settings import Thresholds, Workspace

# Corners needed for the homography that places the board in the image.
MIN_CORNERS = 4
POLYGON_START = 0.5
SKEW_LOW, SKEW_HIGH = np.pi / 4, 3 * np.pi / 4  # [rad] edge angles mapped onto skew 0 and 1
# Quadrant of each vertex: (u on the right?, v at the bottom?) and which way the vertex grows.
_QUADRANT_RIGHT = np.array([False, True, True, False])
_QUADRANT_BOTTOM = np.array([False, False, True, True])
_VERTEX_OF_QUADRANT = {(False, False): 0, (True, False): 1, (True, True): 2, (False, True): 3}


@dataclass(frozen=True)
class ViewFeatures:
    """The board as one image shows it (image fractions and normalised angles).

    Attributes:
        center: (2,) board-centre position ``[u / W, v / H]``.
        area: area of the corner grid's outline / image area.
        skew: angle between the grid's edges at its first corner, [pi/4, 3pi/4] -> [0, 1].
    """

    center: np.ndarray
    area: float
    skew: float

    @property
    def vector(self) -> np.ndarray:
        """(4,) ``[x, y, area, skew]``, the space of the novelty distance."""
        return np.array([self.center[0], self.center[1], self.area, self.skew])


def view_features(corners: np.ndarray, ids: np.ndarray, target: Target, width: int, height: int) -> ViewFeatures | None:
    """Features of one detection: corners (K, 2) [px] with target point ids (K,); None if under-determined.

    The board plane is mapped into the image by a least-squares homography of the detected
    corners; the target's centre and outline go through it.
    """
    if len(corners) < MIN_CORNERS:
        return None
    board_xy = target.points[np.asarray(ids, dtype=np.int64), :2]
    H, _ = cv2.findHomography(board_xy, np.asarray(corners, dtype=np.float64), 0)
    if H is None or not np.all(np.isfinite(H)):
        return None
    outline = _apply_homography(H, target.outline[:, :2])
    center = _apply_homography(H, target.center[None, :2])[0]
    e1, e2 = outline[1] - outline[0], outline[3] - outline[0]
    angle = np.arctan2(abs(e1[0] * e2[1] - e1[1] * e2[0]), float(e1 @ e2))
    area = _polygon_area(outline) / (width * height)
    skew = np.clip((angle - SKEW_LOW) / (SKEW_HIGH - SKEW_LOW), 0.0, 1.0)
    return ViewFeatures(center / np.array([width, height], dtype=float), float(area), float(skew))


def _apply_homography(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    h = np.c_[xy, np.ones(len(xy))] @ H.T
    return h[:, :2] / h[:, 2:3]


def _polygon_area(points: np.ndarray) -> float:
    x, y = points[:, 0], points[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


class Coverage:
    """The coverage state of one episode; ``vector()`` gives the state's first 18 terms.

    Args:
        workspace: normalises the motion terms (a step across the whole workspace is 1).
        thresholds: the terminal condition's thresholds.
        novelty: L1 distance a view must keep from every stored view to be stored.
    """

    def __init__(self, workspace: Workspace, thresholds: Thresholds, novelty: float) -> None:
        self.thresholds = thresholds
        self.novelty = float(novelty)
        self._pose_width = 2.0 * workspace.bound
        self.reset()

    def reset(self) -> None:
        self.polygon = np.full((4, 2), POLYGON_START)
        self.area = np.zeros(2)  # [min, max]; zeros until the first view
        self.skew = np.full(2, 0.5)
        self.motion = np.zeros(6)
        self._views: list[np.ndarray] = []

    @property
    def num_views(self) -> int:
        """Views stored in the coverage set."""
        return len(self._views)

    def add_view(self, view: ViewFeatures) -> bool:
        """Store ``view`` if it is novel and widen the ranges; True when it was stored."""
        vec = view.vector
        # One array operation over the stored views: the per-view L1 sums of a loop, without its cost.
        if self._views and np.abs(np.asarray(self._views) - vec).sum(axis=1).min() <= self.novelty:
            return False
        first = not self._views
        self._views.append(vec)
        self._widen_polygon(view.center)
        self.area = np.array([view.area, view.area]) if first else _widen(self.area, view.area)
        self.skew = np.array([view.skew, view.skew]) if first else _widen(self.skew, view.skew)
        return True

    def _widen_polygon(self, center: np.ndarray) -> None:
        right, bottom = bool(center[0] >= 0.5), bool(center[1] >= 0.5)
        i = _VERTEX_OF_QUADRANT[right, bottom]
        grow_u = max if right else min
        grow_v = max if bottom else min
        self.polygon[i] = [grow_u(self.polygon[i, 0], center[0]), grow_v(self.polygon[i, 1], center[1])]

    def add_motion(self, pose_change: np.ndarray) -> None:
        """Widen the motion range with one step's ``[dp (3) [m], dTheta (3) [rad]]`` change."""
        normalised = np.minimum(np.abs(np.asarray(pose_change, dtype=float)) / self._pose_width, 1.0)
        self.motion = np.maximum(self.motion, normalised)

    def vector(self) -> np.ndarray:
        """(18,) ``[V1..V4 (8), A_min, A_max, eta_min, eta_max, dp_max (3), dTheta_max (3)]`` in [0, 1]."""
        return np.concatenate([self.polygon.ravel(), self.area, self.skew, self.motion])

    def progress(self) -> dict[str, float]:
        """Each term group's progress toward its threshold (1 = reached), for logging and termination."""
        t = self.thresholds
        outward = np.where(_QUADRANT_RIGHT, self.polygon[:, 0] - 0.5, 0.5 - self.polygon[:, 0])
        downward = np.where(_QUADRANT_BOTTOM, self.polygon[:, 1] - 0.5, 0.5 - self.polygon[:, 1])
        need_u = np.where(_QUADRANT_RIGHT, t.polygon_high - 0.5, 0.5 - t.polygon_low)
        need_v = np.where(_QUADRANT_BOTTOM, t.polygon_high - 0.5, 0.5 - t.polygon_low)
        polygon = min(np.min(outward / need_u), np.min(downward / need_v))
        return {
            "polygon": float(np.clip(polygon, 0.0, 1.0)),
            "area": float(min((self.area[1] - self.area[0]) / t.area_range, 1.0)),
            "skew": float(min((self.skew[1] - self.skew[0]) / t.skew_range, 1.0)),
            "motion": float(min(np.min(self.motion) / t.motion, 1.0)),
        }

    def complete(self) -> bool:
        """Whether every coverage term has reached its threshold (the terminal condition)."""
        return all(v >= 1.0 for v in self.progress().values())


def _widen(bounds: np.ndarray, value: float) -> np.ndarray:
    return np.array([min(bounds[0], value), max(bounds[1], value)])
